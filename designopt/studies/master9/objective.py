"""Study A as a problem: the 9-DOF master's composite objective (seed 000 eq. 43, SPEC §3.2).

f = w_k·norm(f_k) + w_l·norm(f_l) + w_p·norm(f_p), norm(x) = (x - x_min)/(x_max - x_min),
weights (4, 2, 1) as in eq. (43). With the ``rqmc`` sampler (default) f is computed per
replicate and ``f_se`` is the SD of those values over √R (honest, docs/indices.md); with
one i.i.d. stream, ``f_se`` = Σ |w_i| se_i/(x_max − x_min), an upper bound. The seed does
not say where x_min/x_max come from: we score a space-filling (Halton) sample of
``n_norm`` designs over the design box once, before optimising, and keep the bounds fixed
(``designopt.problems.normalise``; they are ``problem.norm_bounds`` and archived).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from designopt.core.keys import streams
from designopt.numerics import montecarlo as mc
from designopt.problems import normalise
from designopt.problems.base import Problem
from designopt.studies.master9 import mechanism as m
from designopt.studies.master9.indices import reduce_replicates, replicate_indices, swarm_indices
from designopt.studies.master9.settings import Indices, Master9Settings

SUBOBJECTIVES = ("f_k", "f_l", "f_p")
DEFAULT_VARIABLES = {"a1": (250.0, 350.0), "a3": (250.0, 350.0), "d3": (50.0, 150.0)}


def _full_design(params: Mapping[str, Any], X, names) -> dict:
    M = X.shape[0]
    d = {k: jnp.broadcast_to(jnp.asarray(v, X.dtype), (M,)) for k, v in params["fixed"].items()}
    for i, n in enumerate(names):
        d[n] = X[:, i]
    return d


def build_fn(names: tuple[str, ...], settings: Indices, dtype, mesh: Any = None):
    """The pure swarm objective fn(params, X, key) for these design variables; the
    Monte-Carlo samples come from ``params["sample_key"]`` (common random numbers), their
    chunks spread over the ``samples`` axis of ``mesh`` when given."""

    def fn(params, X, key):
        X = X.astype(dtype)
        d = _full_design(params, X, names)
        p = settings.plan
        rep = replicate_indices(d, params["sample_key"], settings, dtype, mesh)
        ind = reduce_replicates(rep, p)
        b = params["bounds"]  # (3, 2): rows f_k, f_l, f_p; cols min, max
        w = [params["weights"][i] for i in range(len(SUBOBJECTIVES))]
        if p.replicates > 1:  # f per replicate: its SE from the replicate spread
            f_r = normalise.weighted_sum([rep[n] for n in SUBOBJECTIVES], b, w)
            f_est = mc.combine(f_r, None, p)
            return f_est.value, ind | {"f_se": f_est.se}
        # the sub-objectives share samples: Σ |w_i| se_i / span_i bounds f's standard error
        ses = [ind[n + "_se"] for n in SUBOBJECTIVES]
        f, f_se = normalise.weighted_sum([ind[n] for n in SUBOBJECTIVES], b, w, ses)
        return f, ind | {"f_se": f_se}

    return fn


def problem(
    settings: Master9Settings | Mapping[str, Any] | None = None,
    keys: Mapping[str, jax.Array] | None = None,
    dtype: Any = None,
) -> Problem:
    """The study-A problem (eq. 43) for the ``study:`` settings of a config.

    ``settings`` is a :class:`Master9Settings` or a plain mapping of the same keys
    (``variables``, ``fixed``, ``indices``, ``n_norm``; for scripts also ``dtype`` and
    ``seed``). ``keys`` holds the named streams of ``designopt.studies.streams`` (the
    Monte-Carlo samples from ``samples``, the Halton shift of the normalisation designs
    from ``normalisation``); default ``streams(seed)``. ``dtype`` defaults to float64 when
    x64 is enabled, else float32.
    """
    if not isinstance(settings, Master9Settings):
        cfg = dict(settings or {})
        dtype = cfg.pop("dtype", dtype)
        seed = int(cfg.pop("seed", 0))
        keys = streams(seed) if keys is None else keys
        settings = Master9Settings.model_validate({"name": "master9", **cfg})
    keys = streams(0) if keys is None else keys
    if dtype is None:
        dtype = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
    dtype = jnp.dtype(dtype)
    names, lower, upper = settings.box()
    fixed = {**m.default_design(), **{k: float(v) for k, v in settings.fixed.items()}}
    m.check_design(fixed)
    ind = settings.indices
    fn = build_fn(names, ind, dtype)
    fixed_free = {k: v for k, v in fixed.items() if k not in names}
    params = {
        "fixed": {k: jnp.asarray(v, dtype) for k, v in fixed_free.items()},
        "sample_key": keys["samples"],
        "bounds": normalise.unit_bounds(len(SUBOBJECTIVES), dtype),
        "weights": jnp.asarray(ind.weights3, dtype),
    }
    # normalisation bounds from a Halton sample of the design box (fixed during the run)
    from designopt.core import exported

    bounds = normalise.probe_bounds(
        fn, params, SUBOBJECTIVES, lower, upper, settings.n_norm, keys, dtype,
        identity=exported.fingerprint(settings.model_dump(mode="json")),
    )
    params["bounds"] = jnp.asarray(bounds, dtype)
    info = {
        "study": "master9",
        "settings": ind.record(),
        "n_samples_used": ind.n_used,
        "fixed": fixed_free,
        "norm_bounds": {n: bounds[i].tolist() for i, n in enumerate(SUBOBJECTIVES)},
        "n_norm": settings.n_norm,
        "dtype": dtype.name,
    }
    typed = {"n_samples_used": ind.n_used, "norm_bounds": bounds}

    def shard_samples(mesh: Any) -> Problem:
        sharded = build_fn(names, ind, dtype, mesh)
        return Problem(names, lower, upper, sharded, params, info, **typed)

    return Problem(names, lower, upper, fn, params, info, shard_samples=shard_samples, **typed)


def indices(
    design: Mapping[str, float] | None = None,
    n_samples: int = 200_000,
    key: jax.Array | None = None,
    **settings,
) -> dict[str, float]:
    """Global indices of one design (seed 000 eq. 35-42) with standard errors, in float64.

    Returns gci, gcsei, f_k, gpi, f_p, volume (∫|det J_v| dq, mm³), L, f_l and the
    ``*_se`` standard errors; ``settings`` are fields of
    :class:`~designopt.studies.master9.settings.Indices` (chunk, default 32768; measure,
    sampler, backlash_deg, norm, …). Needs ``jax_enable_x64`` (float64 arrays).
    """
    design = {**m.default_design(), **(design or {})}
    m.check_design(design)
    s = Indices.model_validate({"chunk": 32_768, **settings, "n_samples": n_samples})
    key = jax.random.key(0) if key is None else key
    batch = {k: jnp.asarray([v], jnp.float64) for k, v in design.items()}
    out = jax.jit(lambda d, k: swarm_indices(d, k, s))(batch, key)
    res = {k: float(v[0]) for k, v in out.items()}
    res["n_samples"] = s.n_used
    return res
