"""The isotropy of the 2-DOF spherical RCM mechanism over a cone of tool directions, as a
swarm Problem (docs/sphere.md).

Tool directions u are drawn uniformly on the cone's spherical cap (cos t uniform in
[cos β, 1], the azimuth uniform; the same directions for the whole swarm: common random
numbers), and for every design (α12, α23) each direction is solved by the closed-form IK
(both branches), its 3×2 Jacobian built from the solution and its 1/k = σmin/σmax
computed; the better-conditioned branch is kept (the two are mirror images and agree:
tests/test_sphere.py). An unreachable direction counts 1/k = 0; a singular one gives 0,
never NaN. Indices, each with its standard error (``designopt.numerics.montecarlo``):

- ``gci``: the mean of 1/k over the cone (unreached = 0);
- ``reach``: the share of the cone's directions the design reaches;
- ``gci_reached``: the mean of 1/k over the reached directions only (a ratio: n/a under
  :data:`N_MIN` reached directions);
- ``arc_length``: α12 + α23 (rad), the links' arcs on the unit sphere: the compactness
  term of a hybrid objective (no sampling, SE 0).

f = Σ w·index over ``objective`` (gci, reach, arc_length); its Monte-Carlo part is the
mean of one per-direction quantity, so its SE is exact (the replicates' spread under rqmc).
Constraints (g ≤ 0): ``reach_min`` − reach, and the exact reach of a wider cone
(``reach_all_deg``) from the reachable band of :func:`mechanism.reach_band`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.numerics import montecarlo as mc
from designopt.problems.base import Problem, reads_indices
from designopt.studies.sphere import mechanism as m
from designopt.studies.sphere.settings import DESIGN_KEYS, OBJECTIVE_KEYS, SphereSettings

INDICES = ("gci", "reach", "gci_reached", "arc_length")
SAMPLED = ("f", "gci", "reach", "gci_reached")
Array = jnp.ndarray


def cone_frame(gamma: Array) -> tuple[Array, Array, Array]:
    """(c, e1, e2): the cone's axis at angle γ from axis 1 (in the xz plane), e1 ⟂ c in
    that plane pointing toward axis 1, and e2 = y completing the frame."""
    s, c = jnp.sin(gamma), jnp.cos(gamma)
    zero, one = jnp.zeros_like(s), jnp.ones_like(s)
    return (jnp.stack([s, zero, c]), jnp.stack([-c, zero, s]), jnp.stack([zero, one, zero]))


def cone_directions(w: Array, cos_half: Array, gamma: Array) -> Array:
    """Unit samples w (C, 2) → directions (C, 3) uniform on the spherical cap of half-angle
    β (cos β = ``cos_half``) about the cone's axis (:func:`cone_frame`)."""
    ct = 1.0 - w[:, 0] * (1.0 - cos_half)
    st = jnp.sqrt(jnp.maximum(1.0 - ct * ct, 0.0))
    psi = 2.0 * jnp.pi * w[:, 1]
    c, e1, e2 = cone_frame(gamma)
    return (ct[:, None] * c + (st * jnp.cos(psi))[:, None] * e1
            + (st * jnp.sin(psi))[:, None] * e2)  # fmt: skip


def pointwise(u: Array, a12: Array, a23: Array) -> tuple[Array, Array, Array]:
    """For directions u (C, 3) and designs a12, a23 (M,) (rad): 1/k of each branch
    (M, C, 2), 1/k kept (M, C: the better branch, 0 where unreachable) and reachable
    (M, C)."""
    th1, th2, ok = m.ik(u[None], a12[:, None], a23[:, None])
    J = m.jacobian(th1, th2, a12[:, None, None], a23[:, None, None])
    per = m.inv_cond(J)
    return per, jnp.where(ok, jnp.max(per, -1), 0.0), ok


def design_columns(s: SphereSettings, params: Mapping[str, Any], X: Array) -> tuple[Array, Array]:
    """(α12, α23) (M,) in rad from the swarm X (M, V) in degrees and the fixed values."""
    base = params["design"].astype(X.dtype)
    cols = []
    for i, k in enumerate(DESIGN_KEYS):
        cols.append(X[:, list(s.variables).index(k)] * (jnp.pi / 180.0) if k in s.variables
                    else jnp.broadcast_to(base[i], X.shape[:1]))  # fmt: skip
    return cols[0], cols[1]


def sample_plan(s: SphereSettings) -> mc.Plan:
    """``replicates`` × ⌈n/R⌉ directions in chunks of at most ``index.chunk``."""
    ix = s.index
    return mc.plan(ix.n_samples, ix.chunk, ix.sampler, ix.replicates)


def chunk_sums(p: Mapping[str, Any], a12: Array, a23: Array, w: Array) -> dict[str, mc.PowerSums]:
    """Power sums over one chunk of unit samples w (C, 2): f's sampled part
    (w_gci·1/k + w_reach·reached), 1/k, reached, and 1/k over the reached directions."""
    u = cone_directions(w, p["cos_half"], p["gamma"])
    _, g, ok = pointwise(u, a12, a23)
    okf = ok.astype(w.dtype)
    wt = p["weights"]
    h = wt[0] * g + wt[1] * okf
    return {
        "f": mc.mean_sums(1.0, h),
        "gci": mc.mean_sums(1.0, g),
        "reach": mc.mean_sums(1.0, okf),
        "gci_reached": mc.mean_sums(okf, g),
    }


def estimates(s: SphereSettings, params: Mapping[str, Any], X: Array,
              mesh: Any = None) -> dict[str, Any]:  # fmt: skip
    """Every sampled estimate (value, se) for the swarm X, streamed over chunks of
    directions (spread over the ``samples`` axis of ``mesh`` when given)."""
    dt = X.dtype
    a12, a23 = design_columns(s, params, X)
    pl = sample_plan(s)
    p = {k: v.astype(dt) for k, v in params.items() if k != "sample_key"}

    def sums(k):
        w = mc.chunk_points(params["sample_key"], k, pl, 2, dt)
        return mc.to_replicate(chunk_sums(p, a12, a23, w), k, pl)

    init = {n: mc.zero_sums((X.shape[0],), pl, dt) for n in SAMPLED}
    acc = mc.scan_chunks(sums, init, pl.n_chunks, mesh)
    return {n: mc.finish(mc.mean(ps), pl) for n, ps in acc.items()} | {"a12": a12, "a23": a23}


N_MIN = 30
"""``gci_reached`` is a ratio over the reached directions: n/a (NaN, with
``gci_reached_n`` of ``gci_reached_of``) when fewer than this many are reached, as every
ratio index of designopt (docs/task.md, the n/a rule)."""


def build_fn(s: SphereSettings, mesh: Any = None):
    """fn(params, X, key) -> (f, every index with its SE)."""
    n_used = sample_plan(s).n_used

    def fn(params, X, key):
        e = estimates(s, params, X, mesh)
        out: dict[str, Array] = {}
        for k in ("gci", "reach", "gci_reached"):
            out[k], out[k + "_se"] = e[k].value, e[k].se
        n = jnp.round(e["reach"].value * n_used)  # the reached directions
        few = n < N_MIN
        out["gci_reached"] = jnp.where(few, jnp.nan, out["gci_reached"])
        out["gci_reached_se"] = jnp.where(few, jnp.nan, out["gci_reached_se"])
        out["gci_reached_n"], out["gci_reached_of"] = n, jnp.full_like(n, n_used)
        out["arc_length"] = e["a12"] + e["a23"]
        out["arc_length_se"] = jnp.zeros_like(out["arc_length"])
        w_arc = params["weights"][2].astype(X.dtype)
        f = e["f"].value + w_arc * out["arc_length"]
        return f, out | {"f_se": e["f"].se}

    return fn


def band_margins(params: Mapping[str, Any], a12: Array, a23: Array) -> Array:
    """(M, 2) g ≤ 0 of the exact full reach of the wider cone [γ − βe, γ + βe] (rad, / π):
    its far edge within φmax, its near edge beyond φmin."""
    lo, hi = m.reach_band(a12, a23)
    ext = params["ext"].astype(a12.dtype)
    return jnp.stack([(ext[1] - hi) / jnp.pi, (lo - ext[0]) / jnp.pi], -1)


def build_constraints(s: SphereSettings):
    """constraints(params, X, aux) -> G (M, n_c), feasible when ≤ 0; None without any."""
    c = s.constraints
    if c.reach_min is None and c.reach_all_deg is None:
        return None

    @reads_indices
    def constraints(params, X, aux):
        """Reach is read from the indices fn computed (not estimated a second time)."""
        cols = []
        if c.reach_min is not None:
            cols.append((c.reach_min - aux["reach"].astype(X.dtype))[:, None])
        if c.reach_all_deg is not None:
            cols.append(band_margins(params, *design_columns(s, params, X)))
        return jnp.concatenate(cols, -1)

    return constraints


def make_params(s: SphereSettings, keys: Mapping[str, jax.Array], dtype: Any) -> dict[str, Any]:
    """Every number the kernel reads (an input of the compiled program, not a constant)."""
    des = s.design()
    g = s.cone.axis_angle_deg
    e = s.constraints.reach_all_deg or 0.0
    return {
        "design": jnp.asarray(np.deg2rad([des[k] for k in DESIGN_KEYS]), dtype),
        "gamma": jnp.asarray(np.deg2rad(g), dtype),
        "cos_half": jnp.asarray(np.cos(np.deg2rad(s.cone.half_angle_deg)), dtype),
        "ext": jnp.asarray(np.deg2rad([g - e, g + e]), dtype),
        "weights": jnp.asarray([s.weights()[k] for k in OBJECTIVE_KEYS], dtype),
        "sample_key": keys["samples"],
    }


def problem(s: SphereSettings, keys: Mapping[str, jax.Array], dtype: Any) -> Problem:
    """f = Σ w·index (default: −gci, the isotropy over the cone maximised) over the link
    angles, with the optional reach constraints."""
    dtype = jnp.dtype(dtype)
    params = make_params(s, keys, dtype)
    names, lower, upper = s.box()
    pl = sample_plan(s)
    info = {
        "study": "sphere_rcm",
        "n_samples_used": pl.n_used,
        "sampler": pl.sampler,
        "replicates": pl.replicates,
        "fixed": {k: v for k, v in s.design().items() if k not in s.variables},
        "cone_half_angle_deg": s.cone.half_angle_deg,
        "cone_axis_angle_deg": s.cone.axis_angle_deg,
        "weights": s.weights(),
        "dtype": dtype.name,
    }

    na = {"gci_reached": (0.0, 1.0)}  # n/a under N_MIN reached directions

    def shard_samples(mesh: Any) -> Problem:
        return Problem(names, lower, upper, build_fn(s, mesh), params, info,
                       build_constraints(s), n_samples_used=pl.n_used, na_range=na)  # fmt: skip

    return Problem(names, lower, upper, build_fn(s), params, info, build_constraints(s),
                   shard_samples, n_samples_used=pl.n_used, na_range=na)  # fmt: skip
