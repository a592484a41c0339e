"""The optimizer protocol: what every registry entry provides and what the runner uses.

An optimizer is a frozen (hashable) dataclass holding its *static* configuration — the
population size ``n``, the iteration budget ``n_iters``, the bounds handling and any
string options (e.g. PSO's ``draws``) — plus three pure functions, in the manner of optax
(``GradientTransformation(init, update)``) and evosax (one file per algorithm, ``Params``
defaults on the class):

    state = opt.init(key, params, task)           # first population, evaluated
    state = opt.step(key, state, params, task)    # one iteration
    x, f, v = opt.best(state)                     # best design so far (Deb's rules)

``init`` and ``step`` are each an ask, one evaluation and a tell, as in evosax:

    X, pending = opt.ask(key, state, params, task)        # candidates (N, D), no evaluation
    f, v = task.evaluate(X, opt.eval_key(key))
    state = opt.tell(key, state, X, pending, f, v, params, task)

(``init_ask``/``init_tell`` likewise for the first population). The runner uses the
halves when it evaluates the objective as a program of its own (one compiled objective
for the first population, every iteration and the scoring after the run); an entry that
implements only ``init``/``step`` runs fused.

A multi-objective entry (``multi_objective = True``, e.g. NSGA-II) is given problems whose
objective is a vector: ``evaluate`` returns f (M, m), all minimised, and instead of
``best`` it implements ``front(state) -> Front(x, f, v, rank)``, its current population
with each member's non-dominated front index (0 = non-dominated). The runner records the
hypervolume of that population's feasible points after every iteration.

``params`` is the optimizer's ``Params`` NamedTuple of arrays (its numeric settings,
defaults on the class), so one compiled kernel serves a vmapped batch of settings;
``state`` is any pytree of arrays. ``task`` is the problem as the optimizer sees it: the
box and ``evaluate(X, key) -> (f, v)``, the objective and the total constraint violation
v = Σ max(g, 0) of each candidate, NaN cleaned to +inf. Candidates are compared by Deb's
feasibility rules (``better``, ``argbest``, ``order``): a feasible candidate (v = 0) beats
an infeasible one, two infeasible ones compare by v, two feasible ones by f.

The runner (runner.py) owns the PRNG key, the scan, the vmaps, progress and checkpoints,
and knows nothing else about an optimizer.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp

Array = jnp.ndarray
BOUNDS = ("clip", "reflect", "reinit")


class Task(NamedTuple):
    """The problem as an optimizer sees it (built by the runner inside the jitted code)."""

    evaluate: Callable[[Array, jax.Array], tuple[Array, Array]]  # X (M, D) → f (M,)|(M, m), v (M,)
    lower: Array  # (D,)
    upper: Array  # (D,)


class Best(NamedTuple):
    x: Array  # (D,)
    f: Array  # ()
    v: Array  # () total constraint violation (0 = feasible)


class Front(NamedTuple):
    """A multi-objective entry's population (per run; the runner adds leading axes)."""

    x: Array  # (P, D)
    f: Array  # (P, m) objectives, all minimised
    v: Array  # (P,) total constraint violation (0 = feasible)
    rank: Array  # (P,) int32 non-dominated front index (Deb's constrained domination)


def clean(f: Array) -> Array:
    """NaN → +inf (an unevaluable candidate is never the best)."""
    return jnp.where(jnp.isnan(f), jnp.inf, f)


def better(f1: Array, v1: Array, f2: Array, v2: Array) -> Array:
    """Deb's feasibility rules: is candidate 1 strictly better than candidate 2?"""
    return (v1 < v2) | ((v1 == v2) & (f1 < f2))


def argbest(f: Array, v: Array) -> Array:
    """Index of the best candidate by Deb's rules (least violation, then least f; the
    first on ties), as one reduction over (v, f, index) in that order.

    It gives the index that ``i = argmin(where(v == min(v), f, inf))``, falling back to
    ``argmin(v)`` where ``v[i] != min(v)``, gives (a NaN violation, then a NaN f among
    the least violations, counts as smallest, as jnp.argmin counts NaN; -0 equals 0), in
    one pass instead of two dependent ones: a GPU launches one kernel instead of two."""
    n = f.shape[0]

    def pick(a, b):
        (va, fa, ia), (vb, fb, ib) = a, b
        an, bn, fan, fbn = jnp.isnan(va), jnp.isnan(vb), jnp.isnan(fa), jnp.isnan(fb)
        first = ia < ib
        by_f = jnp.where(fan | fbn, jnp.where(fan & fbn, first, fan),
                         (fa < fb) | ((fa == fb) & first))  # fmt: skip
        wins = jnp.where(an | bn, jnp.where(an & bn, first, an), (va < vb) | ((va == vb) & by_f))
        return jnp.where(wins, va, vb), jnp.where(wins, fa, fb), jnp.where(wins, ia, ib)

    init = (jnp.asarray(jnp.inf, v.dtype), jnp.asarray(jnp.inf, f.dtype), jnp.int32(n))
    return jax.lax.reduce((v, f, jnp.arange(n, dtype=jnp.int32)), init, pick, (0,))[2]


def order(f: Array, v: Array) -> Array:
    """Indices sorting candidates best first by Deb's rules (ties keep their order)."""
    return jnp.lexsort((f, v))


def apply_bounds(
    x: Array, lower: Array, upper: Array, mode: str, fresh: Callable[[], Array]
) -> Array:
    """Bring positions back into the box: ``clip``, ``reflect`` (mirror at the faces) or
    ``reinit`` (out-of-box coordinates drawn anew by ``fresh()``, uniform in the box)."""
    if mode == "clip":
        return jnp.clip(x, lower, upper)
    if mode == "reflect":
        span = upper - lower
        y = jnp.mod(x - lower, 2 * span)
        return lower + jnp.where(y > span, 2 * span - y, y)
    if mode == "reinit":
        out = (x < lower) | (x > upper)
        return jnp.where(out, fresh(), x)
    raise ValueError(f"unknown bounds handling {mode!r}; one of {BOUNDS}")


@dataclass(frozen=True)
class Optimizer:
    """Base of every registry entry (see the module docstring).

    Subclasses set ``Params`` (a NamedTuple with defaults), ``options`` (static string
    options: name → allowed values, the first is the default), ``min_population`` and
    ``fixed`` (Params fields a preset sets but a user may not, e.g. PSO's inertia rule),
    and implement ``init``, ``step`` and ``best``. A multi-objective entry sets
    ``multi_objective = True`` and implements ``front`` instead of ``best``.
    """

    n: int  # population size
    n_iters: int  # iteration budget (schedules such as a decreasing inertia use it)
    bounds: str = "clip"

    Params: ClassVar[type] = NamedTuple
    options: ClassVar[dict[str, tuple[str, ...]]] = {}
    fixed: ClassVar[tuple[str, ...]] = ()
    min_population: ClassVar[int] = 2
    multi_objective: ClassVar[bool] = False  # True: f is (M, m) and ``front`` replaces best

    eval_slot: ClassVar[int] = 1
    """The objective's key is ``fold_in(key, eval_slot)`` of the init/step key."""

    def eval_key(self, key: jax.Array) -> jax.Array:
        return jax.random.fold_in(key, self.eval_slot)

    def init(self, key: jax.Array, params: Any, task: Task) -> Any:
        """The first population, evaluated: init_ask, evaluate, init_tell."""
        X, pending = self.init_ask(key, params, task)
        f, v = task.evaluate(X, self.eval_key(key))
        return self.init_tell(key, X, pending, f, v, params, task)

    def step(self, key: jax.Array, state: Any, params: Any, task: Task) -> Any:
        """One iteration: ask, evaluate, tell."""
        X, pending = self.ask(key, state, params, task)
        f, v = task.evaluate(X, self.eval_key(key))
        return self.tell(key, state, X, pending, f, v, params, task)

    def init_ask(self, key: jax.Array, params: Any, task: Task) -> tuple[Array, Any]:
        """The first candidates X (N, D) and what ``init_tell`` needs beside them."""
        raise NotImplementedError

    def init_tell(self, key: jax.Array, X: Array, pending: Any, f: Array, v: Array,
                  params: Any, task: Task) -> Any:  # fmt: skip
        """The first state from the evaluated candidates (f NaN-cleaned, v)."""
        raise NotImplementedError

    def ask(self, key: jax.Array, state: Any, params: Any, task: Task) -> tuple[Array, Any]:
        """This iteration's candidates X (N, D) and what ``tell`` needs beside them; only
        the box of ``task`` is used."""
        raise NotImplementedError

    def tell(self, key: jax.Array, state: Any, X: Array, pending: Any, f: Array, v: Array,
             params: Any, task: Task) -> Any:  # fmt: skip
        """The next state from the evaluated candidates (f NaN-cleaned, v)."""
        raise NotImplementedError

    @classmethod
    def asks(cls) -> bool:
        """Whether the entry implements ask/tell (else only init/step: run fused)."""
        halves = cls.ask is not Optimizer.ask and cls.init_ask is not Optimizer.init_ask
        # a subclass that overrides init or step itself (the older extension point) means
        # its own algorithm: the inherited halves would silently run the parent's
        return halves and cls.init is Optimizer.init and cls.step is Optimizer.step

    def best(self, state: Any) -> Best:
        raise NotImplementedError

    def front(self, state: Any) -> Front:
        raise NotImplementedError

    @classmethod
    def setting_names(cls) -> tuple[str, ...]:
        """The numeric (vmappable) settings a user may give."""
        return tuple(k for k in cls.Params._fields if k not in cls.fixed)

    @classmethod
    def make_params(cls, dtype: Any, preset: dict[str, float], **settings: float) -> Any:
        """``Params`` of arrays: class defaults ← preset ← settings (names checked by
        ``registry.validate``). Integer-valued fields keep an int32 dtype."""
        vals = cls.Params()._asdict() | preset | settings
        ints = getattr(cls, "int_fields", ())
        return cls.Params(
            **{
                k: jnp.asarray(vals[k], jnp.int32 if k in ints else dtype)
                for k in cls.Params._fields
            }
        )

    def describe(self, params: Any) -> dict[str, Any]:
        """What the archive records about the settings used (JSON-friendly)."""
        import numpy as np

        out: dict[str, Any] = {
            "bounds": self.bounds,
            "n_particles": self.n,
            "n_iters": self.n_iters,
        }
        out |= {k: getattr(self, k) for k in self.options}
        out |= {k: np.asarray(getattr(params, k)).tolist() for k in params._fields}
        return out
