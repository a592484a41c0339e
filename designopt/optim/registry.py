"""The optimizer registry: name → (optimizer class, preset, source), and input checks.

Add an optimizer by writing its file (see protocol.py and docs/optimizers.md) and one
line in ``OPTIMIZERS``.
"""

from __future__ import annotations

import numbers
from typing import Any, NamedTuple

import jax.numpy as jnp

from designopt.optim import draws as rng
from designopt.optim.cmaes import CMAES
from designopt.optim.nsga2 import NSGA2
from designopt.optim.protocol import BOUNDS, Optimizer
from designopt.optim.pso import ALIASES, PSO, VARIANTS


class Entry(NamedTuple):
    name: str  # canonical name
    cls: type[Optimizer]
    preset: dict[str, float]  # over the class's Params defaults
    source: str


_NSGA2_SOURCE = (
    "NSGA-II, Deb, Pratap, Agarwal & Meyarivan 2002, with pymoo 0.6's default SBX and "
    "polynomial mutation"
)

OPTIMIZERS: dict[str, Entry] = {
    **{k: Entry(k, PSO, pre, src) for k, (pre, src) in VARIANTS.items()},
    **{a: Entry(k, PSO, VARIANTS[k][0], VARIANTS[k][1]) for a, k in ALIASES.items()},
    "cmaes": Entry("cmaes", CMAES, {}, "CMA-ES, Hansen 2016 tutorial (arXiv:1604.00772)"),
    "cma_es": Entry("cmaes", CMAES, {}, "CMA-ES, Hansen 2016 tutorial (arXiv:1604.00772)"),
}

# Entries whose objective is a vector (f (M, m), a Pareto front): the same Entry, resolved
# and validated by the same functions. A table of their own because the contract tests of
# ``OPTIMIZERS`` (tests/test_protocol.py) are about a best-so-far design; NSGA-II's own
# versions of them are in tests/test_nsga2.py.
MULTI_OBJECTIVE: dict[str, Entry] = {
    "nsga2": Entry("nsga2", NSGA2, {}, _NSGA2_SOURCE),
    "nsga_ii": Entry("nsga2", NSGA2, {}, _NSGA2_SOURCE),
}


def register(name: str, cls: type[Optimizer], preset: dict[str, float] | None = None,
             source: str = "") -> Entry:  # fmt: skip
    """Add a user's optimizer (an ``Optimizer`` subclass: ``Params``, ``init``, ``step``,
    ``best``; or ``front`` with ``multi_objective = True``) under ``name``; configs then
    name it in ``optimizer.name``. A name may be registered once."""
    key = str(name).lower()
    if key in OPTIMIZERS or key in MULTI_OBJECTIVE:
        raise ValueError(f"an optimizer named {key!r} is already registered")
    if not (isinstance(cls, type) and issubclass(cls, Optimizer)):
        raise ValueError(f"{cls!r} is not a designopt.optim.Optimizer subclass")
    e = Entry(key, cls, dict(preset or {}), source or cls.__name__)
    (MULTI_OBJECTIVE if cls.multi_objective else OPTIMIZERS)[key] = e
    return e


def names() -> list[str]:
    """Every accepted single-objective optimizer name (canonical names and aliases);
    ``multi_objective_names()`` lists the others."""
    return sorted(OPTIMIZERS)


def resolve(name: str) -> Entry:
    key = str(name).lower()
    e = OPTIMIZERS.get(key) or MULTI_OBJECTIVE.get(key)
    if e is None:
        known = ", ".join(names() + multi_objective_names())
        raise ValueError(f"unknown optimizer {name!r}; known: {known}")
    return e


def setting_names(name: str) -> tuple[str, ...]:
    """The numeric (vmappable) settings of optimizer ``name``."""
    return resolve(name).cls.setting_names()


def multi_objective_names() -> list[str]:
    """The accepted names of the multi-objective optimizers (canonical names and aliases)."""
    return sorted(MULTI_OBJECTIVE)


def is_multi_objective(name: str) -> bool:
    """Whether optimizer ``name`` optimises a vector objective (a front)."""
    return resolve(name).cls.multi_objective


def option_names(name: str) -> dict[str, tuple[str, ...]]:
    """The static string options of ``name`` and their allowed values (first = default)."""
    return dict(resolve(name).cls.options)


def validate(
    name: str,
    settings: dict[str, Any],
    n_particles: int | None = None,
    n_objectives: int | None = None,
) -> None:
    """ValueError (one line, naming the bad thing) for an unknown optimizer, a setting it
    does not have, a value of the wrong kind, a population below what it needs, or (with
    ``n_objectives``) a single-objective optimizer asked for a front or a multi-objective
    one given a single objective."""
    e = resolve(name)
    if n_objectives is not None:
        multi = [k for k, x in MULTI_OBJECTIVE.items() if k == x.name]
        if n_objectives > 1 and not e.cls.multi_objective:
            raise ValueError(
                f"optimizer {name!r} is single-objective; the problem has {n_objectives} "
                f"objectives (a Pareto front): use {' or '.join(sorted(multi))}"
            )
        if n_objectives < 2 and e.cls.multi_objective:
            raise ValueError(
                f"optimizer {name!r} is multi-objective; the problem has a single objective: "
                "use a single-objective optimizer (e.g. ptpso or cmaes)"
            )
    nums, opts = e.cls.setting_names(), e.cls.options
    for k, val in settings.items():
        if k in opts:
            if not isinstance(val, str) or val not in opts[k]:
                raise ValueError(
                    f"setting {k!r} of optimizer {name!r} must be one of {', '.join(opts[k])}, "
                    f"got {val!r}"
                )
            if k == "draws":
                rng.check(val)
        elif k in nums:
            if isinstance(val, bool) or not isinstance(val, numbers.Real):
                raise ValueError(
                    f"setting {k!r} of optimizer {name!r} must be a number, got {val!r}"
                )
        else:
            allowed = ", ".join([*nums, *opts])
            raise ValueError(f"unknown setting {k!r} for optimizer {name!r}; allowed: {allowed}")
    if n_particles is not None and n_particles < max(2, e.cls.min_population):
        need = max(2, e.cls.min_population)
        raise ValueError(
            f"population size (n_particles) {n_particles} is too small for {name!r}: needs ≥ {need}"
        )


def split_settings(name: str, settings: dict[str, Any]) -> tuple[dict[str, float], dict[str, str]]:
    """(numeric settings, static options) after ``validate``."""
    opts = resolve(name).cls.options
    return ({k: v for k, v in settings.items() if k not in opts},
            {k: v for k, v in settings.items() if k in opts})  # fmt: skip


def make_params(name: str, dtype: Any = jnp.float64, **settings: float) -> Any:
    """The ``Params`` pytree of ``name`` (class defaults ← preset ← numeric ``settings``)."""
    validate(name, settings)
    e = resolve(name)
    nums, _ = split_settings(name, settings)
    return e.cls.make_params(dtype, e.preset, **nums)


def build(
    name: str, n_particles: int, n_iters: int, bounds: str = "clip", **options: str
) -> Optimizer:
    """The (static, hashable) optimizer object for ``name`` with its string options."""
    e = resolve(name)
    if bounds not in BOUNDS:
        raise ValueError(f"bounds must be one of {BOUNDS}, got {bounds!r}")
    return e.cls(n=n_particles, n_iters=n_iters, bounds=bounds, **options)
