"""Study A as a problem: the 9-DOF master's composite objective (seed 000 eq. 43, SPEC §3.2).

f = w_k·norm(f_k) + w_l·norm(f_l) + w_p·norm(f_p), norm(x) = (x - x_min)/(x_max - x_min),
weights (4, 2, 1) as in eq. (43). The seed does not say where x_min/x_max come from: we
score a space-filling (Halton) sample of ``n_norm`` designs over the design box once,
before optimising, and keep the bounds fixed (they are returned in ``problem.info`` and
archived).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt import montecarlo as mc
from designopt.problems.base import Problem
from designopt.studies.master9 import mechanism as m
from designopt.studies.master9.indices import IndexSettings, swarm_indices

SUBOBJECTIVES = ("f_k", "f_l", "f_p")
DEFAULT_VARIABLES = {"a1": (250.0, 350.0), "a3": (250.0, 350.0), "d3": (50.0, 150.0)}


def _full_design(params: Mapping[str, Any], X, names) -> dict:
    M = X.shape[0]
    d = {k: jnp.broadcast_to(jnp.asarray(v, X.dtype), (M,)) for k, v in params["fixed"].items()}
    for i, n in enumerate(names):
        d[n] = X[:, i]
    return d


def build_fn(names: tuple[str, ...], settings: IndexSettings, dtype, resample: bool = False):
    """The pure swarm objective fn(params, X, key) for these design variables."""

    def fn(params, X, key):
        X = X.astype(dtype)
        d = _full_design(params, X, names)
        k = key if resample else params["sample_key"]
        ind = swarm_indices(d, k, settings, dtype)
        b = params["bounds"]  # (3, 2): rows f_k, f_l, f_p; cols min, max
        w = params["weights"]
        f = sum(
            w[i] * (ind[n] - b[i, 0]) / (b[i, 1] - b[i, 0]) for i, n in enumerate(SUBOBJECTIVES)
        )
        return f, ind

    return fn


def problem(config: Mapping[str, Any] | None = None) -> Problem:
    """Build the study-A problem from a plain dict (the ``study`` section of a config).

    Keys (all optional): ``variables`` {name: [lo, hi]} in mm (default a1, a3 ∈ [250, 350],
    d3 ∈ [50, 150]); ``fixed`` {name: value} overriding ``default_design()``; ``indices``
    (fields of IndexSettings); ``n_norm`` (designs for the normalisation bounds, 64);
    ``dtype`` ('float32'/'float64'); ``seed`` (sample key); ``resample`` (fresh samples
    from the optimizer's key at each call instead of one fixed set; default False).
    """
    config = dict(config or {})
    variables = {
        k: tuple(map(float, v)) for k, v in config.get("variables", DEFAULT_VARIABLES).items()
    }
    unknown = [k for k in variables if k not in m.DESIGN_KEYS]
    if unknown:
        raise ValueError(f"unknown design variable(s) {unknown}; allowed {list(m.DESIGN_KEYS)}")
    fixed = {**m.default_design(), **{k: float(v) for k, v in config.get("fixed", {}).items()}}
    m.check_design(fixed)
    ind_cfg = dict(config.get("indices", {}))
    for k in ("backlash_deg", "weights"):
        if k in ind_cfg and not isinstance(ind_cfg[k], (list, tuple)):
            ind_cfg[k] = (float(ind_cfg[k]),) * 3
        if k in ind_cfg:
            ind_cfg[k] = tuple(float(v) for v in ind_cfg[k])
    settings = IndexSettings(**ind_cfg)
    dtype = jnp.dtype(config.get("dtype", "float64"))
    names = tuple(variables)
    lower = np.array([variables[n][0] for n in names])
    upper = np.array([variables[n][1] for n in names])
    sample_key = jax.random.key(int(config.get("seed", 0)))
    fn = build_fn(names, settings, dtype, bool(config.get("resample", False)))
    fixed_free = {k: v for k, v in fixed.items() if k not in names}

    # normalisation bounds from a Halton sample of the design box (fixed during the run)
    n_norm = int(config.get("n_norm", 64))
    u = mc.unit_samples(jax.random.key(12345), 0, n_norm, len(names), "halton")
    Xn = jnp.asarray(lower) + jnp.asarray(upper - lower) * u
    probe = {
        "fixed": fixed_free,
        "sample_key": sample_key,
        "bounds": jnp.array([[0.0, 1.0]] * 3),
        "weights": jnp.asarray(settings.weights),
    }
    _, ind = jax.jit(fn)(probe, Xn, sample_key)
    bounds = np.array([[float(ind[n].min()), float(ind[n].max())] for n in SUBOBJECTIVES])
    params = {**probe, "bounds": jnp.asarray(bounds)}
    info = {
        "study": "master9",
        "settings": asdict(settings),
        "n_samples_used": settings.n_used,
        "fixed": fixed_free,
        "norm_bounds": {n: bounds[i].tolist() for i, n in enumerate(SUBOBJECTIVES)},
        "n_norm": n_norm,
        "dtype": dtype.name,
    }
    return Problem(names, lower, upper, fn, params, info)


def indices(
    design: Mapping[str, float] | None = None,
    n_samples: int = 200_000,
    key: jax.Array | None = None,
    **settings,
) -> dict[str, float]:
    """Global indices of one design (seed 000 eq. 35-42) with standard errors, in float64.

    Returns gci, gcsei, f_k, gpi, f_p, volume (∫|det J_v| dq, mm³), L, f_l and the
    ``*_se`` standard errors; ``settings`` are fields of
    :class:`~designopt.studies.master9.indices.IndexSettings` (measure, sampler,
    backlash_deg, norm, …). Needs ``jax_enable_x64`` (float64 arrays).
    """
    design = {**m.default_design(), **(design or {})}
    m.check_design(design)
    s = IndexSettings(n_samples=n_samples, **settings)
    key = jax.random.key(0) if key is None else key
    batch = {k: jnp.asarray([v], jnp.float64) for k, v in design.items()}
    out = jax.jit(lambda d, k: swarm_indices(d, k, s))(batch, key)
    res = {k: float(v[0]) for k, v in out.items()}
    res["n_samples"] = s.n_used
    return res
