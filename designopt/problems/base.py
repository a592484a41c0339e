"""The problem abstraction every optimizer and study uses.

A problem is a design box plus a *pure* function ``fn(params, X, key) -> (f, aux)`` that
scores a whole swarm X (M, D) in one call: f (M,) and named sub-objectives aux[name] (M,).
``params`` is a pytree of arrays (fixed lengths, normalisation bounds, sample keys …),
passed as an argument rather than baked into the trace, so one compiled kernel serves a
swarm, a sweep, and ``jax.grad``.

Constraints (optional): ``constraints(params, X) -> G (M, n_c)``; a design is feasible
when every g ≤ 0. Optimizers see the total violation v = Σ max(g, 0) (``total_violation``)
beside f and rank candidates by Deb's feasibility rules (docs/optimizers.md). No
constraint function means zero constraints: v = 0 everywhere. Bounds on the indices fn
computes (e.g. a task's reach ≥ 0.99) read fn's aux instead of computing them again: a
constraint function marked by :func:`reads_indices` is called as ``g(params, X, aux)``;
:func:`scored` is the one place that evaluates f, aux and v together.

Sample sharding (optional, docs/scaling.md): ``shard_samples(mesh) -> Problem`` gives the
same problem whose fn (and constraints) spread their Monte-Carlo sample chunks over the
mesh's ``samples`` axis (``designopt.numerics.montecarlo.scan_chunks``); None: not supported.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

Array = jnp.ndarray
ProblemFn = Callable[[Any, Array, jax.Array], tuple[Array, dict[str, Array]]]
ConstraintFn = Callable[[Any, Array], Array]


def total_violation(g: Array) -> Array:
    """Σ_j max(g_j, 0) over the last axis of constraint values G (M, n_c) → (M,); NaN
    counts as +inf (an unevaluable design is never feasible)."""
    g = jnp.asarray(g)
    v = jnp.sum(jnp.maximum(g, 0.0), axis=-1)
    return jnp.where(jnp.isnan(v), jnp.inf, v)


class Staged(NamedTuple):
    """A problem's scoring in two stages (``Problem.staged``, optional), for a study whose
    costly part has a shape of its own (the task's IK: designs × targets): ``values``
    runs on the host and computes that part of exactly ``designs`` designs X (designs, D)
    through programs of one fixed shape each, whatever called it (the search, a front's
    re-scoring, ``eval``, ``scan``, the normalisation probe, figures), and gives a
    pytree of arrays; ``reduce(params, X, key, values)`` is pure and gives what ``fn``
    gives: ``fn(params, X, key) == reduce(params, X, key, values(params, X))``. The
    scoring (``designopt.problems.evaluate.staged_scores``) calls them block by block
    of ``designs`` rows, the last one padded. ``least(params)``: params with which
    ``values`` runs every program it runs at the least cost (the task's: its first chunk
    of targets), for a call made to compile them; None: ``params`` themselves.
    ``calls``: the independent program calls one block's ``values`` makes (the task's:
    its chunks of targets), which run side by side on the CPU's cores."""

    values: Callable[[Any, Array], Any]
    reduce: Callable[..., tuple[Array, dict[str, Array]]]
    designs: int
    least: Callable[[Any], Any] | None = None
    calls: int = 1


@dataclass(frozen=True, eq=False)
class Problem:
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    fn: ProblemFn
    params: Any = None
    info: dict[str, Any] = field(default_factory=dict)
    constraints: Callable | None = (
        None  # G = g(params, X) (M, n_c), g ≤ 0; reads_indices: g(params, X, aux)
    )
    shard_samples: Callable[[Any], Problem] | None = None  # mesh → the sample-sharded problem
    n_objectives: int = 1
    """m: f is (M,) when 1, (M, m) for a multi-objective problem (all minimised)."""
    n_samples_used: int = 0
    """Monte-Carlo samples behind each index value (0: a closed-form problem)."""
    norm_bounds: np.ndarray | None = None
    """(k, 2) min/max of the normalised indices (the Halton probe), archived with the
    run; the same numbers travel in ``params`` for the trace."""
    na_range: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    """Indices that may be n/a (NaN, with NaN SE: a ratio over too few items) and the
    range of each: a search ranks an n/a value at the end of its range that is worst
    for its sense (:func:`na_worst`); the archive keeps the NaN."""
    staged: Staged | None = None
    """The scoring in two stages (:class:`Staged`): one compiled program per structure
    for every phase; None: ``fn`` in one program per shape (``evaluate_batch``)."""

    def __post_init__(self) -> None:
        lo, hi = np.asarray(self.lower, np.float64), np.asarray(self.upper, np.float64)
        if lo.shape != (len(self.names),) or hi.shape != lo.shape:
            raise ValueError(
                f"lower/upper must have shape ({len(self.names)},), got {lo.shape}, {hi.shape}"
            )
        bad = [n for n, a, b in zip(self.names, lo, hi, strict=True) if not a < b]
        if bad:
            raise ValueError(f"lower must be < upper for {bad}")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @property
    def dim(self) -> int:
        return len(self.names)

    def evaluate(self, X: Array, key: jax.Array | None = None) -> tuple[Array, dict[str, Array]]:
        """Fitness (M,) and sub-objectives of a swarm X (M, D)."""
        X = jnp.asarray(X)
        if X.ndim != 2 or X.shape[1] != self.dim:
            raise ValueError(f"X must have shape (M, {self.dim}), got {tuple(X.shape)}")
        key = jax.random.key(0) if key is None else key
        return self.fn(self.params, X, key)

    def violation(self, X: Array) -> Array:
        """Total constraint violation Σ max(g, 0) of a swarm X (M, D); zeros without
        constraints."""
        X = jnp.asarray(X)
        if X.ndim != 2 or X.shape[1] != self.dim:
            raise ValueError(f"X must have shape (M, {self.dim}), got {tuple(X.shape)}")
        if getattr(self.constraints, "reads_indices", False):
            return scored(self.fn, self.constraints, self.params, X, jax.random.key(0))[2]
        return violation_of(self.constraints, self.params, X)


def na_worst(v: Array, lo: float, hi: float, minimised: bool) -> Array:
    """``v`` with NaN replaced by the worst value of [lo, hi] for a search that minimises
    (hi) or maximises (lo) it."""
    return jnp.where(jnp.isnan(v), jnp.asarray(hi if minimised else lo, v.dtype), v)


def reads_indices(fn: Callable[[Any, Array, dict[str, Array]], Array]) -> Callable:
    """Mark a constraint function g(params, X, aux) -> G (M, n_c) that bounds indices of
    the problem's own aux (one evaluation serves f and the constraints)."""
    fn.reads_indices = True  # type: ignore[attr-defined]
    return fn


def constraint_values(constraints: Callable, params: Any, X: Array,
                      aux: dict[str, Array] | None) -> Array:  # fmt: skip
    """G (M, n_c) of ``constraints``; ``aux`` is needed by a :func:`reads_indices` one."""
    if getattr(constraints, "reads_indices", False):
        if aux is None:
            raise ValueError("these constraints bound indices: evaluate fn first (scored)")
        g = jnp.asarray(constraints(params, X, aux))
    else:
        g = jnp.asarray(constraints(params, X))
    return g[:, None] if g.ndim == 1 else g


def scored(fn: ProblemFn, constraints: Callable | None, params: Any, X: Array,
           key: jax.Array) -> tuple[Array, dict[str, Array], Array]:  # fmt: skip
    """(f, aux, v): one evaluation of fn and the total violation of the constraints."""
    f, aux = fn(params, X, key)
    return f, aux, violation_of(constraints, params, X, aux)


def violation_of(constraints: Callable | None, params: Any, X: Array,
                 aux: dict[str, Array] | None = None) -> Array:  # fmt: skip
    """Pure form of ``Problem.violation`` (for jitted code: ``constraints`` is static)."""
    if constraints is None:
        return jnp.zeros(X.shape[:1], X.dtype)
    return total_violation(constraint_values(constraints, params, X, aux)).astype(X.dtype)


@partial(jax.jit, static_argnames=("fn", "constraints"))
def evaluate_batch(params: Any, X: Array, keys: jax.Array, fn: ProblemFn,
                   constraints: Callable | None = None
                   ) -> tuple[Array, dict[str, Array], Array]:  # fmt: skip
    """:func:`scored` over R groups of candidates X (R, N, D), group r with keys[r] (R,):
    f (R, N[, m]), aux {name: (R, N)}, v (R, N). The one compiled objective of a run: the
    runner's every evaluation (``optim.run(..., separate=True)``) and the scoring after
    it (``designopt.problems.evaluate.score`` with the run's ``eval_shape``) call it with one shape."""
    return jax.vmap(lambda x, k: scored(fn, constraints, params, x, k))(X, keys)
