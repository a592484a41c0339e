"""Registry of the PSO variants p1..p7 (SPEC §3.3) with their defaults and sources.

Seed 000's Table 3 (the variants' settings) is lost; every value below is our choice,
taken from the cited reference where it gives one, and is overridable by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp

from designopt.optim.pso import Params, constriction, rule_index

CHI_41 = constriction(4.1)  # 0.729843...

BASE: dict[str, float] = dict(
    w=0.7,
    w_start=0.9,
    w_end=0.4,
    u=1.0015,
    alpha=0.4,
    beta=0.2,
    c1=1.5,
    c2=1.5,
    chi=1.0,
    vmax_frac=0.2,
    penalty=0.0,
    gamma=1e-7,
    a=10.0,
    rho_c=0.9,
    symmetric_r3=0.0,
)


@dataclass(frozen=True)
class Variant:
    name: str
    rule: str
    defaults: dict[str, float] = field(default_factory=dict)
    source: str = ""


VARIANTS: dict[str, Variant] = {
    "p1": Variant("p1", "constant", dict(w=0.7, c1=1.5, c2=1.5), "basic PSO, seed 000 eq. (44)-(45)"),
    "p2": Variant(
        "p2", "constant", dict(w=1.0, c1=2.05, c2=2.05, chi=CHI_41),
        "constriction factor, Eberhart & Shi 2000 [32] (Clerc-Kennedy χ, φ = 4.1)",
    ),
    "p3": Variant(
        "p3", "constant", dict(w=1.0, c1=2.05, c2=2.05, chi=CHI_41, penalty=1.0),
        "PTPSO = p2 + penalty term, seed 000 eq. (46)-(50)",
    ),
    "p4": Variant(
        "p4", "nonlinear", dict(w_start=0.9, u=1.0015, c1=2.0, c2=2.0),
        "nonlinear time-varying inertia w_t = w0·u^-t, Jiao et al. 2008 [33]",
    ),
    "p5": Variant(
        "p5", "linear", dict(w_start=0.9, w_end=0.4, c1=2.0, c2=2.0),
        "linearly decreasing inertia 0.9 → 0.4, Shi & Eberhart 1999 [34], [35]",
    ),
    "p6": Variant(
        "p6", "adaptive", dict(w_start=0.6, alpha=0.4, beta=0.2, c1=2.0, c2=2.0),
        "dynamic adaptation (evolution speed, aggregation degree), Yang et al. 2007 [36]",
    ),
    "p7": Variant(
        "p7", "random", dict(c1=1.494, c2=1.494),
        "random inertia w = 0.5 + U(0,1)/2, Eberhart & Shi 2001 [37]",
    ),
}  # fmt: skip

ALIASES = {
    "basic": "p1",
    "pso": "p1",
    "constriction": "p2",
    "ptpso": "p3",
    "nonlinear_inertia": "p4",
    "linear_inertia": "p5",
    "ldiw": "p5",
    "adaptive": "p6",
    "dynamic_adaptation": "p6",
    "random_inertia": "p7",
}


def resolve(name: str) -> Variant:
    key = ALIASES.get(name.lower(), name.lower())
    if key not in VARIANTS:
        raise ValueError(
            f"unknown optimizer {name!r}; known: {sorted(VARIANTS)} and aliases {sorted(ALIASES)}"
        )
    return VARIANTS[key]


def make_params(name: str, dtype=jnp.float64, **overrides: Any) -> Params:
    """Params pytree for a variant: BASE ← the variant's defaults ← overrides."""
    v = resolve(name)
    unknown = [k for k in overrides if k not in BASE]
    if unknown:
        raise ValueError(f"unknown optimizer setting(s) {unknown}; known: {sorted(BASE)}")
    vals = {**BASE, **v.defaults, **overrides}
    out = {k: jnp.asarray(vals[k], dtype) for k in Params._fields if k != "rule"}
    return Params(**out, rule=jnp.asarray(rule_index(v.rule), jnp.int32))


def stack_params(params: list[Params]) -> Params:
    """Stack Params along a new leading axis (a batch of settings to vmap over)."""
    return Params(*(jnp.stack(leaves) for leaves in zip(*params, strict=True)))
