"""The da Vinci study's indices and objective as a swarm Problem (docs/davinci.md).

Over the surgical workspace around H (``settings.Workspace``; samples shared by the
whole swarm):

- ``gci``: mean of 1/k_F (Frobenius, normalised to [0, 1]) of the 6×6 Jacobian made
  dimensionless by the characteristic length L (linear rows / L, the q3 column × L), over
  joint samples whose shaft fills the cone; a direction the design cannot reach within
  the q1, q2 ranges counts 0;
- ``coverage``: the fraction of those samples within the q1, q2 ranges;
- ``ik_success``: the production IK solver's success rate on task poses in the cone
  (errors ≤ 1e-9 mm / rad, joints within limits); with ``indices.solver: closed_form``
  the closed form's (then equal to ``reach``: a quick setting for tests and scans);
- ``reach``: the fraction of task poses reachable within limits at all (from the closed
  form of the RCM geometry; ``reach − ik_success`` is what the solver misses).

f = −(w_gci · gci + w_ik · ik_success). Each index has its standard error (delta method
for the mean, binomial for rates). The IK part carries no gradient (``stop_gradient``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics.conditioning import inv_cond
from designopt.numerics import montecarlo as mc
from designopt.problems.base import Problem
from designopt.studies.davinci import ik
from designopt.studies.davinci import mechanism as mech
from designopt.studies.davinci.settings import KEYS, DavinciSettings

INDICES = ("gci", "coverage", "ik_success", "reach")
_SCALE = {"alpha_deg": math.pi / 180, "beta_deg": math.pi / 180, "l_QH": 1.0, "l_IJ": 1.0}


def cone_axis(q12_deg: tuple[float, float]) -> np.ndarray:
    """World direction of the Table 1 arm's shaft at (q1, q2) (deg)."""
    q = np.array([math.radians(q12_deg[0]), math.radians(q12_deg[1]), 0, 0, 0, 0])
    R, _ = _fk3(jnp.asarray(mech.table1()), jnp.asarray(q))
    return np.asarray(R)[:, 1]


@jax.jit
def _fk3(links, q):
    """The Table 1 arm's frame 3 in one jitted call (op by op, the FK compiled some twenty
    one-op programs at set-up)."""
    return mech.frame_model(3).fk(links, q)


def _basis(c: np.ndarray) -> np.ndarray:
    c = c / np.linalg.norm(c)
    t = np.array([1.0, 0.0, 0.0]) if abs(c[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(c, t)
    e1 /= np.linalg.norm(e1)
    return np.stack([c, e1, np.cross(c, e1)])


def cone_dirs(basis: jnp.ndarray, cos_max: jnp.ndarray, u0, u1) -> jnp.ndarray:
    """Directions uniform over the spherical cap of the cone (rows of ``basis``: axis,
    two normals)."""
    ct = 1.0 - u0 * (1.0 - cos_max)
    st = jnp.sqrt(jnp.maximum(1.0 - ct * ct, 0.0))
    ph = 2 * math.pi * u1
    return (ct[:, None] * basis[0] + (st * jnp.cos(ph))[:, None] * basis[1]
            + (st * jnp.sin(ph))[:, None] * basis[2])  # fmt: skip


def shaft_joints(x: jnp.ndarray, s: jnp.ndarray) -> jnp.ndarray:
    """(q1, q2) putting the shaft along s (C, 3) for one design x (4,) (kernel units):
    s = Rx(α − π)·(−sin q1 cos ψ, cos q1 cos ψ, sin ψ), ψ = q2 + π/2 − β."""
    c, sn = jnp.cos(x[0] - math.pi), jnp.sin(x[0] - math.pi)
    u = jnp.stack([s[:, 0], c * s[:, 1] + sn * s[:, 2], -sn * s[:, 1] + c * s[:, 2]], -1)
    q2 = jnp.arcsin(jnp.clip(u[:, 2], -1.0, 1.0)) - (math.pi / 2 - x[1])
    return jnp.stack([jnp.arctan2(-u[:, 0], u[:, 1]), q2], -1)


def full_designs(params: Mapping[str, Any], X: jnp.ndarray) -> jnp.ndarray:
    """(M, 4) kernel-unit designs (α, β rad; l_QH, l_IJ mm) from the variables X (M, V)."""
    M = X.shape[0]
    full = jnp.broadcast_to(params["fixed"], (M, 4))
    return full.at[:, params["var_cols"]].set(X * params["var_scale"])


def _rot_about(axis: jnp.ndarray, v: jnp.ndarray, ang: jnp.ndarray) -> jnp.ndarray:
    """Rodrigues: v rotated by ang about the unit axis (row-wise)."""
    c, s = jnp.cos(ang)[:, None], jnp.sin(ang)[:, None]
    k = axis
    return v * c + jnp.cross(k, v) * s + k * jnp.sum(k * v, -1, keepdims=True) * (1 - c)


def task_poses(params, x: jnp.ndarray, n: int, dtype) -> jnp.ndarray:
    """IK task poses (n, 4, 4) for design x (its own H): jaw point J at depth along a cone
    direction s, the jaw's pointing direction y6 (J − I at q6 = 0, along the shaft at
    q5 = 0) within ``tool_cone`` of s, the jaw axis z6 at a uniform angle about it."""
    u = mc.unit_samples(params["ik_key"], 0, n, 6, "uniform", dtype)
    s = cone_dirs(params["basis"], params["cos_cone"], u[:, 0], u[:, 1])
    depth = params["depth"][0] + (params["depth"][1] - params["depth"][0]) * u[:, 2]
    p = mech.rcm_point(x)[None] + depth[:, None] * s
    # the jaw's pointing direction y6 tilted from s by at most tool_cone, the jaw axis z6
    # at a uniform angle about it
    t = jnp.where(
        jnp.abs(s[:, :1]) < 0.9, jnp.asarray([1.0, 0, 0], dtype), jnp.asarray([0, 1.0, 0], dtype)
    )
    n1 = jnp.cross(s, t)
    n1 = n1 / jnp.linalg.norm(n1, axis=-1, keepdims=True)
    n1 = _rot_about(s, n1, 2 * math.pi * u[:, 3])
    ct = 1.0 - u[:, 4] * (1.0 - params["cos_tool"])
    b = _rot_about(n1, s, jnp.arccos(jnp.clip(ct, -1.0, 1.0)))
    z = jnp.cross(b, n1)
    z = z / jnp.linalg.norm(z, axis=-1, keepdims=True)
    z = _rot_about(b, z, 2 * math.pi * (u[:, 5] - 0.5))
    R = jnp.stack([jnp.cross(b, z), b, z], -1)
    top = jnp.concatenate([R, p[:, :, None]], -1)
    bottom = jnp.broadcast_to(jnp.asarray([0.0, 0.0, 0.0, 1.0], dtype), (n, 1, 4))
    return jnp.concatenate([top, bottom], -2)


def _rate(ok: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    n = ok.shape[-1]
    p = jnp.mean(ok.astype(jnp.float64 if ok.dtype == bool else ok.dtype), -1)
    return p, jnp.sqrt(jnp.maximum(p * (1 - p), 0.0) / (n - 1))


def solver_options(s: DavinciSettings) -> ik.Options:
    k = s.ik
    return ik.Options(first_iter=k.first_iter, continue_iter=k.continue_iter,
                      max_iter=k.max_iter, warm_iter=k.warm_iter, retries=k.retries,
                      success_pos=k.success_pos_mm, success_rot=k.success_rot_rad)  # fmt: skip


def solver_grid(s: DavinciSettings) -> ik.Grid:
    k = s.ik
    return ik.Grid(k.grid_deg, k.grid_q3_mm, k.grid_wrist_deg, k.grid_q6_deg)


def workspace_samples(s: DavinciSettings, params, x: jnp.ndarray, dtype: Any):
    """Joint samples (n, 6) over the surgical cone for design x and whether their
    (q1, q2) lie within the joint ranges."""
    ind = s.indices
    pl = sample_plan(s)
    if pl.replicates == 1:
        u = mc.unit_samples(params["sample_key"], 0, ind.n_samples, 6, ind.sampler, dtype)
    else:  # R shifted Halton sets, replicate after replicate
        pts = jax.vmap(lambda k: mc.chunk_points(params["sample_key"], k, pl, 6, dtype))
        u = pts(jnp.arange(pl.n_chunks)).reshape(pl.n_used, 6)
    sdir = cone_dirs(params["basis"], params["cos_cone"], u[:, 0], u[:, 1])
    q12 = shaft_joints(x, sdir)
    q3 = params["depth"][0] + (params["depth"][1] - params["depth"][0]) * u[:, 2]
    wl, wh = params["wrist"][:, 0], params["wrist"][:, 1]
    q = jnp.concatenate([q12, q3[:, None], wl + (wh - wl) * u[:, 3:]], -1)
    inside = jnp.all((q12 >= params["q_lower"][:2]) & (q12 <= params["q_upper"][:2]), -1)
    return q, inside


def sample_plan(s: DavinciSettings) -> mc.Plan:
    """The GCI samples: one stream, or ``replicates`` RQMC sets of ⌈n/R⌉ (one chunk each)."""
    ind = s.indices
    return mc.plan(ind.n_samples, ind.n_samples, ind.sampler, ind.replicates)


def inv_k(s: DavinciSettings, x: jnp.ndarray, q: jnp.ndarray) -> jnp.ndarray:
    """1/k_F (normalised) of the dimensionless 6×6 Jacobian at q (C, 6)."""
    L = s.indices.length_mm
    col = jnp.asarray([1.0, 1.0, L, 1.0, 1.0, 1.0], q.dtype)
    J = mech.ARM.jacobian(x, q, char_length=L) * col
    return inv_cond(J, "fro", normalized=True)


def dexterity(s: DavinciSettings, params, x: jnp.ndarray, dtype: Any):
    """(gci, se, coverage, se) of one design x (4,) (kernel units)."""
    q, inside = workspace_samples(s, params, x, dtype)
    g = jnp.where(inside, inv_k(s, x, q), 0.0)
    pl = sample_plan(s)
    if pl.replicates > 1:
        g = g.reshape(pl.replicates, pl.n_rep)
    est = mc.finish(mc.mean(mc.power_sums(jnp.ones_like(g), g)), pl)
    cov, cov_se = _rate(inside.astype(dtype))
    return est.value, est.se, cov, cov_se


def build_fn(s: DavinciSettings, dtype: Any):
    """The pure swarm function fn(params, X, key) -> (f, indices with *_se)."""
    w = s.objective
    n_ik = s.indices.n_ik
    o = solver_options(s)._replace(chunk=n_ik)
    grid = solver_grid(s)

    def solvability(params, x):
        x = jax.lax.stop_gradient(x)
        T = task_poses(params, x, n_ik, dtype)
        _, reach = ik.closed_form(x, T)
        if s.indices.solver == "closed_form":
            ok = reach
        else:
            ok = ik.solve(x, ik.build_database(x, grid, dtype), T, o=o).success
        return _rate(ok.astype(dtype)) + _rate(reach.astype(dtype))

    def fn(params, X, key):
        full = full_designs(params, X.astype(dtype))
        gci, gci_se, cov, cov_se = jax.vmap(lambda x: dexterity(s, params, x, dtype))(full)
        iks, iks_se, rch, rch_se = jax.vmap(lambda x: solvability(params, x))(full)
        f = -(w.gci * gci + w.ik_success * iks)
        # the GCI and the IK rate use independent samples: their errors add in quadrature
        f_se = jnp.sqrt((w.gci * gci_se) ** 2 + (w.ik_success * iks_se) ** 2)
        out = {"gci": gci, "gci_se": gci_se, "coverage": cov, "coverage_se": cov_se,
               "ik_success": iks, "ik_success_se": iks_se, "reach": rch, "reach_se": rch_se,
               "f_se": f_se}  # fmt: skip
        return f, out

    return fn


def make_params(s: DavinciSettings, keys: Mapping[str, jax.Array], dtype: Any) -> dict:
    names = tuple(s.variables)
    fixed = {**s.design(), **{k: 0.5 * sum(s.variables[k]) for k in names}}
    ws = s.workspace
    return {
        "fixed": jnp.asarray([fixed[k] * _SCALE[k] for k in KEYS], dtype),
        "var_cols": jnp.asarray([KEYS.index(k) for k in names], jnp.int32),
        "var_scale": jnp.asarray([_SCALE[k] for k in names], dtype),
        "basis": jnp.asarray(_basis(cone_axis(ws.axis_q_deg)), dtype),
        "cos_cone": jnp.asarray(math.cos(math.radians(ws.cone_deg)), dtype),
        "cos_tool": jnp.asarray(math.cos(math.radians(ws.tool_cone_deg)), dtype),
        "depth": jnp.asarray(ws.depth_mm, dtype),
        "wrist": jnp.asarray(np.radians(np.asarray(ws.wrist_deg, np.float64)), dtype),
        "q_lower": jnp.asarray(mech.LOWER, dtype),
        "q_upper": jnp.asarray(mech.UPPER, dtype),
        "sample_key": keys["samples"],
        "ik_key": jax.random.fold_in(keys["samples"], 1),
    }


def problem(s: DavinciSettings, keys: Mapping[str, jax.Array], dtype: Any) -> Problem:
    """The da Vinci study's Problem: design box from ``variables`` (deg, mm)."""
    dtype = jnp.dtype(dtype)
    names, lower, upper = s.box()
    info = {
        "study": "davinci",
        "n_samples_used": sample_plan(s).n_used,
        "sampler": s.indices.sampler,
        "replicates": sample_plan(s).replicates,
        "n_ik": s.indices.n_ik,
        "fixed": s.design(),
        "length_mm": s.indices.length_mm,
        "weights": s.objective.model_dump(),
        "dtype": dtype.name,
    }
    return Problem(names, lower, upper, build_fn(s, dtype), make_params(s, keys, dtype), info,
                   n_samples_used=info["n_samples_used"])  # fmt: skip
