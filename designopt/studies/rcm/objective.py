"""η over stated workspaces, the reach of the task cone, and the design Problem of the
planar RCM mechanism (the planar RCM mechanism paper, Sensors 2023; docs/rcm.md).

Workspaces (the paper never defines W in eq. 12, so every result names its own):
- ``box``: the joint box (d1, d2) ∈ Q, sampled uniformly in joint space;
- ``cone``: the task cone at R (apex angle, insertion depth), sampled uniformly in
  Cartesian space (its planar sector, or the 3-D cone of the arm) and mapped by IK;
- ``reach``: the part of that cone whose IK lies in the joint box.
Measures: ``cartesian`` (uniform in the tip's space) or ``joint`` (uniform in the joints);
one becomes the other by the weight |det J|^{±1}: |det J| = |1 − c/r| in the plane
(eq. 10), d²·v/r² for the arm (mechanism.arm_det). 1/k depends on the sample through
r = |A1C| only, and r = c − d on the cone.

Every estimate is a ratio estimator Σ w g / Σ w with its delta-method standard error, or
with ``sampler: rqmc`` the mean of R replicate ratios and their SD/√R (designopt.numerics.montecarlo); the samples are shared by the whole swarm and what depends on the
sample only (depths, directions) is computed once per sample.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.numerics import montecarlo as mc
from designopt.problems.base import Problem, reads_indices
from designopt.studies.rcm import mechanism as m
from designopt.studies.rcm.settings import DESIGN_KEYS, RcmSettings

INDICES = ("eta", "eta_box", "eta_cone", "eta_reach", "reach", "eq19_margin")
CHUNK = 4096  # samples per chunk: (M, 4096) arrays stay in cache (benchmarks/rcm.py: 3× faster than 16384)


def cone_samples(u: jnp.ndarray, p: Mapping[str, Any], dim: int) -> dict[str, jnp.ndarray]:
    """Tip positions uniform in the task cone from unit samples u (C, 3): depth d
    (density ∝ d^(dim−1)) and the offsets of the tip from R: on the cone's axis (dim 1),
    in the plane (dim 2: (C, 2), R = origin) or for the arm (dim 3: (C, 3), R = origin,
    home direction −x)."""
    lo, hi, half = p["depth"][0], p["depth"][1], p["half_apex"]
    if dim == 1:  # the cone's axis: depth uniform along the rod
        d = lo + u[:, 0] * (hi - lo)
        return {"d": d, "off": d[:, None] * jnp.stack([jnp.zeros_like(d), -jnp.ones_like(d)], -1)}
    if dim == 2:
        d = jnp.sqrt(lo * lo + u[:, 0] * (hi * hi - lo * lo))
        phi = (2.0 * u[:, 1] - 1.0) * half
        return {"d": d, "off": d[:, None] * jnp.stack([jnp.sin(phi), -jnp.cos(phi)], -1)}
    d = jnp.cbrt(lo**3 + u[:, 0] * (hi**3 - lo**3))
    ca = 1.0 - u[:, 1] * (1.0 - jnp.cos(half))  # uniform on the spherical cap
    sa = jnp.sqrt(jnp.maximum(1.0 - ca * ca, 0.0))
    psi = 2.0 * jnp.pi * u[:, 2]
    direc = jnp.stack([-ca, sa * jnp.cos(psi), sa * jnp.sin(psi)], -1)
    return {"d": d, "off": d[:, None] * direc}


def _in(x: jnp.ndarray, rng: jnp.ndarray) -> jnp.ndarray:
    return (x >= rng[0]) & (x <= rng[1])


def chunk_sums(p: Mapping[str, Any], a: jnp.ndarray, c: jnp.ndarray, u: jnp.ndarray,
               s: RcmSettings) -> dict[str, mc.PowerSums]:  # fmt: skip
    """Power sums over one chunk of unit samples u (C, 3) for designs a, c (M,), in the
    configured measure: 1/k on the box, on the cone, on its reachable part, and the reach
    indicator."""
    dt = u.dtype
    a_, c_ = a[:, None], c[:, None]
    # the joint box: (d1, d2) uniform
    d1 = p["d1"][0] + (p["d1"][1] - p["d1"][0]) * u[:, 0]
    d2 = p["d2"][0] + (p["d2"][1] - p["d2"][0]) * u[:, 1]
    r_box = jnp.sqrt((d1[None] - a_) ** 2 + d2[None] ** 2)
    g_box = m.inv_cond_r(r_box, c_)
    det_box = jnp.abs(m.det_j(r_box, c_))
    # the task cone: sample geometry once, IK per design
    cs = cone_samples(u, p, s.cone.dim)
    d = cs["d"][None]
    r = c_ - d
    g_cone = m.inv_cond_r(jnp.abs(r), c_)
    if s.cone.dim <= 2:
        off = cs["off"]
        k1, k2 = m.ik(off[None, :, 0], off[None, :, 1], a_, 0.0, c_)
        ok = _in(k1, p["d1"]) & _in(k2, p["d2"]) & (r > 0)
        rs = jnp.where(r > 0, r, 1.0)
        # 1/|det J| = r/|c − r| in the plane; along the axis d2 = c − d: |∂d2/∂d| = 1
        w_joint = jnp.where(r > 0, rs / d, 0.0) if s.cone.dim == 2 else jnp.ones_like(r)
    else:
        P = cs["off"][None]
        t1, k1, k2 = m.arm_ik(P, a_, c_, 0.0)
        ok = _in(t1, p["theta1"]) & _in(k1, p["d1"]) & _in(k2, p["d2"]) & (r > 0)
        det = m.arm_det(k1, k2, a_, c_)
        w_joint = jnp.where(det > 0, 1.0 / jnp.where(det > 0, det, 1.0), 0.0)
    okf = ok.astype(dt)
    if s.eta.measure == "cartesian":  # uniform in the tip's space
        w_box, w_cone = det_box, jnp.ones_like(g_cone)
    else:  # uniform in the joints
        w_box, w_cone = jnp.ones_like(g_box), w_joint
    return {
        "box": mc.mean_sums(w_box, g_box),
        "cone": mc.mean_sums(w_cone, g_cone),
        "reach_eta": mc.mean_sums(okf * w_cone, g_cone),
        "reach": mc.mean_sums(1.0, okf),
    }


def design_columns(s: RcmSettings, params: Mapping[str, Any], X: jnp.ndarray):
    """(a, c) (M,) from the swarm X (M, V) and the fixed values."""
    base = params["design"].astype(X.dtype)  # (2,) a, c
    cols = []
    for i, k in enumerate(DESIGN_KEYS):
        cols.append(X[:, list(s.variables).index(k)] if k in s.variables
                    else jnp.broadcast_to(base[i], X.shape[:1]))  # fmt: skip
    return cols[0], cols[1]


def estimates(s: RcmSettings, params: Mapping[str, Any], X: jnp.ndarray,
              mesh: Any = None) -> dict[str, Any]:  # fmt: skip
    """Every estimate (value, se) for the swarm X, streamed over chunks of samples (spread
    over the ``samples`` axis of ``mesh`` when given)."""
    dt = X.dtype
    a, c = design_columns(s, params, X)
    pl = sample_plan(s)
    p = {k: v.astype(dt) for k, v in params.items() if k not in ("sample_key", "design")}

    def sums(k):
        u = mc.chunk_points(params["sample_key"], k, pl, 3, dt)
        return mc.to_replicate(chunk_sums(p, a, c, u, s), k, pl)

    keys = ("box", "cone", "reach_eta", "reach")
    init = {n: mc.zero_sums((X.shape[0],), pl, dt) for n in keys}
    acc = mc.scan_chunks(sums, init, pl.n_chunks, mesh)
    return {n: mc.finish(mc.mean(ps), pl) for n, ps in acc.items()} | {"a": a, "c": c}


def sample_plan(s: RcmSettings) -> mc.Plan:
    """Chunks of the η integrals: ``replicates`` × ⌈n/R⌉ samples (one stream for uniform)."""
    return mc.plan(s.eta.n_samples, CHUNK, s.eta.sampler, s.eta.replicates)


def eq19_margin(s: RcmSettings, p: Mapping[str, Any], a: jnp.ndarray, c: jnp.ndarray):
    """a − sin(apex/2)·(c − depth_min): eq. (19) holds when ≥ 0."""
    return a - jnp.sin(p["half_apex"]) * (c - p["depth"][0])


def build_fn(s: RcmSettings, mesh: Any = None):
    """fn(params, X, key) -> (f = −η, every index with its SE)."""
    ws = s.eta.workspace

    def fn(params, X, key):
        e = estimates(s, params, X, mesh)
        p = {k: v.astype(X.dtype) for k, v in params.items() if k != "sample_key"}
        out = {}
        for name, src in (("eta_box", "box"), ("eta_cone", "cone"), ("eta_reach", "reach_eta"),
                          ("reach", "reach")):  # fmt: skip
            out[name], out[name + "_se"] = e[src].value, e[src].se
        out["eta"], out["eta_se"] = out[f"eta_{ws}"], out[f"eta_{ws}_se"]
        out["eq19_margin"] = eq19_margin(s, p, e["a"], e["c"])
        return -out["eta"], out | {"f_se": out["eta_se"]}

    return fn


def build_constraints(s: RcmSettings):
    """constraints(params, X, aux) -> G (M, n_c), feasible when ≤ 0: eq. (19) as
    (sin(apex/2)(c − d_min) − a)/c, and reach_min − reach; None when both are off."""
    cons = s.constraints
    if not cons.eq19 and cons.reach_min is None:
        return None

    @reads_indices
    def constraints(params, X, aux):
        """Reach is read from the indices fn computed (not estimated a second time)."""
        p = {k: v.astype(X.dtype) for k, v in params.items() if k != "sample_key"}
        a, c = design_columns(s, params, X)
        cols = []
        if cons.eq19:
            cols.append(-eq19_margin(s, p, a, c) / c)
        if cons.reach_min is not None:
            cols.append(cons.reach_min - aux["reach"].astype(X.dtype))
        return jnp.stack(cols, -1)

    return constraints


def make_params(s: RcmSettings, keys: Mapping[str, jax.Array], dtype: Any) -> dict[str, Any]:
    des = s.design()
    j = s.joints
    return {
        "design": jnp.asarray([des["a"], des["c"]], dtype),
        "b": jnp.asarray(des["b"], dtype),
        "d1": jnp.asarray(j.d1, dtype),
        "d2": jnp.asarray(j.d2, dtype),
        "theta1": jnp.asarray(np.deg2rad(j.theta1_deg), dtype),
        "depth": jnp.asarray(s.cone.depth, dtype),
        "half_apex": jnp.asarray(np.deg2rad(s.cone.apex_deg / 2), dtype),
        "sample_key": keys["samples"],
    }


def check_reach(s: RcmSettings, params: Mapping[str, Any], dtype: Any, n_grid: int = 48) -> None:
    """Pre-flight: refuse a joint box that reaches too little of the cone for every design
    on an n_grid^V grid of the design box (4096 samples each)."""
    if s.constraints.reach_min is None:
        return
    names = list(s.variables)
    axes = [np.linspace(*s.variables[k], n_grid) for k in names]
    X = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], -1)
    small = s.model_copy(update={"eta": s.eta.model_copy(update={"n_samples": 4096})})
    reach = np.asarray(jax.jit(lambda p, X: estimates(small, p, X)["reach"].value)(
        params, jnp.asarray(X, dtype)))  # fmt: skip
    best = float(reach.max())
    if best < s.constraints.reach_min - 0.02:
        i = int(reach.argmax())
        at = ", ".join(f"{k} = {X[i, j]:.1f}" for j, k in enumerate(names))
        raise ValueError(
            f"joints: the joint box reaches at most {100 * best:.1f} % of the task cone for "
            f"any design in the box (best at {at}); constraints.reach_min is "
            f"{100 * s.constraints.reach_min:.1f} %: widen study.joints or the design box, "
            "or lower constraints.reach_min"
        )


def problem(s: RcmSettings, keys: Mapping[str, jax.Array], dtype: Any) -> Problem:
    """max η over the chosen workspace (f = −η) subject to eq. (19) and the reach of the
    task cone; every η of the three workspaces reported with its SE."""
    dtype = jnp.dtype(dtype)
    params = make_params(s, keys, dtype)
    check_reach(s, params, dtype)
    names, lower, upper = s.box()
    pl = sample_plan(s)
    info = {
        "study": "rcm",
        "n_samples_used": pl.n_used,
        "sampler": pl.sampler,
        "replicates": pl.replicates,
        "fixed": {k: v for k, v in s.design().items() if k not in s.variables},
        "workspace": s.eta.workspace,
        "measure": s.eta.measure,
        "cone_dim": s.cone.dim,
        "dtype": dtype.name,
    }

    def shard_samples(mesh: Any) -> Problem:
        return Problem(names, lower, upper, build_fn(s, mesh), params, info,
                       build_constraints(s), n_samples_used=pl.n_used)  # fmt: skip

    return Problem(names, lower, upper, build_fn(s), params, info, build_constraints(s),
                   shard_samples, n_samples_used=pl.n_used)  # fmt: skip
