"""Study D as a swarm Problem: the master lengths that minimise the tip-velocity mismatch
between the PLAS master and slave over the master's workspace (SPEC §6).

Over joint samples θ ~ U(box) (common to the whole swarm) and joint-rate directions
u ~ U(sphere) in (θ2', θ3', θ4'), both arms at the same configuration θ (the reading of
eq. 27-29), the master's joint rates u map to the slave's K(θ)u (eq. 28):

- ``vel_rel`` = Σ|Δv| / Σ|v_m|: the tip-velocity mismatch Δv = J_s K u − J_m u per unit
  of master tip speed (a ratio estimator, delta-method SE); dimensionless;
- ``vel_reduction`` = 1 − vel_rel/vel_rel(built master), paired on the same samples
  (delta-method SE of the paired ratio);
- ``vel_abs``: mean |Δv| in mm/s at a joint-rate vector of norm ``joint_rate_deg_s``;
  ``vel_max``: its largest value over the samples;
- ``pos_mean`` / ``pos_max``: the tip-displacement mismatch when the master moves from
  home (θ = 0) to θ along the straight joint path and the slave follows θ'_s = K(θ_m)θ'_m
  (midpoint rule, ``n_path`` points): |Δp_s − Δp_m| in mm;
- ``k2_min`` … ``k4``: the factors' range over a grid of the box; ``reach``;
  ``counterweight`` and ``inertia`` of the counterbalance (§2.1.2) for this d6.

The maxima are sample maxima and carry no standard error: a sample maximum is a lower
bound of the true one, not a mean, and has no normal error; with N iid samples, with
95 % confidence the mismatch exceeds it on less than a fraction 3/N of the workspace
(docs/plas.md). Constraints (g ≤ 0): reach within ±tolerance of the built master;
min/max of every factor over the grid within ``factor_range``.

f = Σ w · index / index(built master) over (velocity: vel_rel, position: pos_mean,
inertia: inertia); the built master is scored in every call on the same samples (one more
row), so f = 1 means "as good as the built master". The velocity term is
1 − vel_reduction and carries its paired SE; the others add w·se/ref (ref held fixed), so
f_se bounds f's standard error.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.numerics import montecarlo as mc
from designopt.problems.base import Problem
from designopt.studies.plas import mechanism as m
from designopt.studies.plas.settings import PlasSettings

ROWS = (0, 1, 2)
INDICES = ("f", "vel_rel", "vel_reduction", "vel_abs", "vel_max", "pos_mean", "pos_max",
           "k2_min", "k2_max", "k3_min", "k3_max", "k4", "reach", "counterweight", "inertia")  # fmt: skip
SUMMARY = ("vel_rel", "vel_reduction", "vel_abs", "pos_mean")


def _norm(v: jnp.ndarray) -> jnp.ndarray:
    """|v| over the last axis with a finite gradient at 0."""
    s = jnp.sum(v * v, -1)
    ok = s > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, s, 1.0)), 0.0)


def directions(u: jnp.ndarray) -> jnp.ndarray:
    """Two uniforms (…, 2) → a uniform direction on the unit sphere (…, 3)."""
    z = 2.0 * u[..., 0] - 1.0
    phi = 2.0 * jnp.pi * u[..., 1]
    r = jnp.sqrt(jnp.maximum(1.0 - z * z, 0.0))
    return jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), z], -1)


def sample(params: Mapping[str, Any], start, n: int, sampler: str, dtype):
    """Joint samples θ (n, 3) in rad and rate directions u (n, 3): rows start … of the
    study's sample stream."""
    w = mc.unit_samples(params["sample_key"], start, n, 5, sampler, dtype)
    lo, hi = params["q_lower"].astype(dtype), params["q_upper"].astype(dtype)
    return lo + (hi - lo) * w[:, :3], directions(w[:, 3:])


def factors(master: jnp.ndarray, slave: jnp.ndarray, theta: jnp.ndarray) -> jnp.ndarray:
    """(M, 3) designs × (C, 3) angles → K (M, C, 3) = (k2, k3, k4) of eq. (28)."""
    k = m.mapping_factors(master[:, None, :], slave[None, :], theta[None])
    return jnp.stack(k, -1)


def pointwise(master: jnp.ndarray, slave: jnp.ndarray, theta: jnp.ndarray, u: jnp.ndarray,
              n_path: int) -> dict[str, jnp.ndarray]:  # fmt: skip
    """Per-sample quantities for designs ``master`` (M, 3) = (a2', a3', d6), the slave
    row (3,), angles θ (C, 3) and rate directions u (C, 3):
    dv = |J_s K u − J_m u| (mm/rad), vm = |J_m u|, dp = |Δp_s − Δp_m| (mm), all (M, C)."""
    M, C = master.shape[0], theta.shape[0]
    q = m.q4(theta)
    Js = m.SLAVE.jacobian(slave[None], q, rows=ROWS, cols=m.POSITION_COLS)  # (1, C, 3, 3)
    Jm = m.MASTER.jacobian(master, q, rows=ROWS, cols=m.POSITION_COLS)  # (M, C, 3, 3)
    K = factors(master, slave, theta)
    vs = jnp.einsum("mcij,mcj->mci", Js * K[:, :, None, :], jnp.broadcast_to(u, (M, C, 3)))
    vm = jnp.einsum("mcij,cj->mci", Jm, u)
    # home → θ along the straight joint path; the slave integrates θ'_s = K(θ_m) θ'_m
    ts = (jnp.arange(n_path, dtype=theta.dtype) + 0.5) / n_path
    Kbar = sum(factors(master, slave, t * theta) for t in ts) / n_path
    theta_s = Kbar * theta[None]  # (M, C, 3)
    _, ps = m.SLAVE.fk(slave[None], m.q4(theta_s.reshape(M * C, 3)))
    _, ps0 = m.SLAVE.fk(slave[None], jnp.zeros((1, 4), theta.dtype))
    _, pm = m.MASTER.fk(master, q)
    _, pm0 = m.MASTER.fk(master, jnp.zeros((1, 4), theta.dtype))
    dp = (ps.reshape(M, C, 3) - ps0) - (pm - pm0)
    return {"dv": _norm(vs - vm), "vm": _norm(vm), "dp": _norm(dp)}


def _moments(z: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Σ z (M, k) and Σ z zᵀ (M, k, k) over the sample axis of z (M, C, k)."""
    return jnp.sum(z, 1), jnp.einsum("mci,mcj->mij", z, z)


def _delta(s1, s2, n, grad_fn):
    """Value and delta-method SE of a smooth function of the means of z from its sums."""
    mean = s1 / n
    cov = (s2 / n - mean[..., :, None] * mean[..., None, :]) * (n / (n - 1.0))
    val, g = grad_fn(mean)
    var = jnp.einsum("...i,...ij,...j->...", g, cov, g) / n
    return val, jnp.sqrt(jnp.maximum(var, 0.0))


def _ratio(mean):
    a, w = mean[..., 0], mean[..., 1]
    return a / w, jnp.stack([1 / w, -a / w**2, 0 * a, 0 * a], -1)


def _reduction(mean):
    a, w, b, wb = mean[..., 0], mean[..., 1], mean[..., 2], mean[..., 3]
    q = 1.0 - (a * wb) / (w * b)
    g = jnp.stack([-wb / (w * b), a * wb / (w**2 * b), a * wb / (w * b**2), -a / (w * b)], -1)
    return q, g


def counterbalance(
    d6: jnp.ndarray, cb: Mapping[str, jnp.ndarray]
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(counterweight m in g, inertia I in g·cm²) for master d6 (mm): L grows by
    ``L_per_d6`` per mm of d6 beyond the built 60 mm (§2.1.2, eq. 1)."""
    L = cb["L"] + cb["L_per_d6"] * (d6 - m.BUILT["d6"])
    mass = m.counterbalance_mass(cb["M"], L, cb["r"], cb["l"], cb["theta"])
    inertia = m.counterbalance_inertia(cb["M"], L / 10.0, mass, cb["l"] / 10.0)
    return mass, inertia


def full_design(params: Mapping[str, Any], X: jnp.ndarray) -> jnp.ndarray:
    """(M, D) design variables → (M, 3) master rows (a2', a3', d6)."""
    return params["fixed_row"].astype(X.dtype) + X @ params["select"].astype(X.dtype)


def build_fn(s: PlasSettings, dtype: Any):
    """The pure swarm function fn(params, X, key) -> (f, indices with *_se)."""
    mm = s.mismatch
    pl = mm.plan()
    R = pl.replicates
    MC = ("vel_rel", "vel_reduction", "vel_abs", "pos_mean")  # Monte-Carlo estimates

    def raw(params, master):
        """Indices of designs ``master`` (M, 3); the built master is appended as the last
        row so that the paired reduction shares its samples."""
        master = jnp.concatenate([master, params["built"][None].astype(dtype)], 0)
        slave = params["slave"].astype(dtype)
        M = master.shape[0]

        def body(acc, k):
            w = mc.chunk_points(params["sample_key"], k, pl, 5, dtype)
            lo, hi = params["q_lower"].astype(dtype), params["q_upper"].astype(dtype)
            theta, u = lo + (hi - lo) * w[:, :3], directions(w[:, 3:])
            pw = pointwise(master, slave, theta, u, mm.n_path)
            a, w = pw["dv"], pw["vm"]
            z = jnp.stack(
                [a, w, jnp.broadcast_to(a[-1], a.shape), jnp.broadcast_to(w[-1], w.shape)], -1
            )
            s1, s2 = _moments(z)
            ps = mc.to_replicate((mc.power_sums(1.0, a), mc.power_sums(1.0, pw["dp"])), k, pl)
            new = (mc.place(s1, k, pl), mc.place(s2, k, pl), *ps,
                   jnp.max(a, 1), jnp.max(pw["dp"], 1))  # fmt: skip
            return (acc[0] + new[0], acc[1] + new[1], mc.add(acc[2], new[2]),
                    mc.add(acc[3], new[3]), jnp.maximum(acc[4], new[4]),
                    jnp.maximum(acc[5], new[5])), None  # fmt: skip

        ps0 = mc.zero_sums((M,), pl, dtype)
        rep = (R,) if R > 1 else ()
        init = (jnp.zeros((M, *rep, 4), dtype), jnp.zeros((M, *rep, 4, 4), dtype), ps0, ps0,
                jnp.zeros((M,), dtype), jnp.zeros((M,), dtype))  # fmt: skip
        (s1, s2, ps_v, ps_p, vmax, pmax), _ = jax.lax.scan(body, init, jnp.arange(pl.n_chunks))
        n = jnp.asarray(float(pl.n_rep if R > 1 else pl.n_used), dtype)
        rate = params["rate"].astype(dtype)
        out = {}
        out["vel_rel"], out["vel_rel_se"] = _delta(s1, s2, n, _ratio)
        out["vel_reduction"], out["vel_reduction_se"] = _delta(s1, s2, n, _reduction)
        ev = mc.mean(ps_v)
        out["vel_abs"], out["vel_abs_se"] = rate * ev.value, rate * ev.se
        out["vel_max"] = rate * vmax
        ep = mc.mean(ps_p)
        out["pos_mean"], out["pos_mean_se"] = ep.value, ep.se
        out["pos_max"] = pmax
        K = factors(master, slave, params["grid"].astype(dtype))
        for i, name in ((0, "k2"), (1, "k3")):
            out[name + "_min"], out[name + "_max"] = K[..., i].min(1), K[..., i].max(1)
        out["k4"] = K[:, 0, 2]
        out["reach"] = m.reach(master)
        out["counterweight"], out["inertia"] = counterbalance(
            master[:, 2], params["counterbalance"]
        )
        for k in (
            "k2_min",
            "k2_max",
            "k3_min",
            "k3_max",
            "k4",
            "reach",
            "counterweight",
            "inertia",
        ):
            out[k + "_se"] = jnp.zeros_like(out[k])
        reps = {k: out[k] for k in MC}  # (M, R) with replicates, else (M,)
        for k in MC:  # mean of the replicates and SD/√R (or the delta-method SE)
            out[k], out[k + "_se"] = mc.combine(out[k], out[k + "_se"], pl)
        split = ({k: v[:-1] for k, v in d.items()} for d in (out, reps))
        return *split, {k: v[-1] for k, v in out.items()}, {k: v[-1] for k, v in reps.items()}

    def fn(params, X, key):
        X = X.astype(dtype)
        out, rep, ref, ref_rep = raw(params, full_design(params, X))
        w = params["weights"].astype(dtype)
        if R > 1:  # f per replicate (the built master's ratios too): SE from their spread
            f_r = w[0] * (1.0 - rep["vel_reduction"])
            f_r = f_r + w[1] * rep["pos_mean"] / ref_rep["pos_mean"]
            f_r = f_r + w[2] * (out["inertia"] / ref["inertia"])[:, None]
            e = mc.combine(f_r, None, pl)
            return e.value, out | {"f_se": e.se}
        # velocity term: vel_rel / vel_rel(built) = 1 − vel_reduction, with its paired SE
        f = w[0] * (1.0 - out["vel_reduction"])
        f_se = w[0] * out["vel_reduction_se"]
        for i, k in ((1, "pos_mean"), (2, "inertia")):
            f = f + w[i] * out[k] / ref[k]
            f_se = f_se + w[i] * out[k + "_se"] / ref[k]
        return f, out | {"f_se": f_se}

    return fn, raw


def constraint_fn(params, X):
    """G (M, 4): reach above/below ±tol of the built master's, factors above/below the
    range (relative); feasible when every g ≤ 0."""
    master = full_design(params, X)
    r = m.reach(master)
    r0, tol = params["reach0"], params["reach_tol"]
    K = factors(master, params["slave"].astype(X.dtype), params["grid"].astype(X.dtype))
    lo, hi = params["factor_range"][0], params["factor_range"][1]
    return jnp.stack([
        (r - (1 + tol) * r0) / r0,
        ((1 - tol) * r0 - r) / r0,
        (K.max((1, 2)) - hi) / hi,
        (lo - K.min((1, 2))) / lo,
    ], -1)  # fmt: skip


def grid(lower: np.ndarray, upper: np.ndarray, n: int) -> np.ndarray:
    """An n³ grid over the joint box (rad), for the factors' range."""
    axes = [np.linspace(a, b, n) for a, b in zip(lower, upper, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def problem(s: PlasSettings, keys: Mapping[str, jax.Array], dtype: Any) -> Problem:
    """The plas Problem: design box from ``variables``, the other master lengths from
    ``fixed`` (built values otherwise), constraints as above."""
    dtype = jnp.dtype(dtype)
    names, lower, upper = s.box()
    base = s.design()
    select = np.zeros((len(names), 3))
    fixed_row = np.array([base[k] for k in m.MASTER_KEYS])
    for i, n in enumerate(names):
        j = m.MASTER_KEYS.index(n)
        select[i, j] = 1.0
        fixed_row[j] = 0.0
    box = np.deg2rad(np.array(s.joint_ranges_deg.rows(), np.float64))
    cb = s.counterbalance
    built = np.array([m.BUILT[k] for k in m.MASTER_KEYS])
    ob = s.objective
    params = {
        "fixed_row": jnp.asarray(fixed_row, dtype),
        "select": jnp.asarray(select, dtype),
        "built": jnp.asarray(built, dtype),
        "slave": jnp.asarray([s.slave.a2, s.slave.a3, s.slave.d5], dtype),
        "q_lower": jnp.asarray(box[:, 0], dtype),
        "q_upper": jnp.asarray(box[:, 1], dtype),
        "grid": jnp.asarray(grid(box[:, 0], box[:, 1], s.constraints.n_grid), dtype),
        "rate": jnp.asarray(np.deg2rad(s.mismatch.joint_rate_deg_s), dtype),
        "sample_key": keys["samples"],
        "counterbalance": {
            "M": jnp.asarray(cb.M_g, dtype),
            "L": jnp.asarray(cb.L_mm, dtype),
            "r": jnp.asarray(cb.r_mm, dtype),
            "l": jnp.asarray(cb.l_mm, dtype),
            "theta": jnp.asarray(np.deg2rad(cb.theta_deg), dtype),
            "L_per_d6": jnp.asarray(cb.L_per_d6, dtype),
        },  # fmt: skip
        "reach0": jnp.asarray(built.sum(), dtype),
        "reach_tol": jnp.asarray(s.constraints.reach_tolerance, dtype),
        "factor_range": jnp.asarray(s.constraints.factor_range, dtype),
        "weights": jnp.asarray([ob.velocity, ob.position, ob.inertia], dtype),
    }
    fn, _ = build_fn(s, dtype)
    info = {
        "study": "plas",
        "n_samples_used": s.mismatch.n_used(),
        "fixed": {k: v for k, v in base.items() if k not in names},
        "built": dict(m.BUILT),
        "joint_ranges_deg": s.joint_ranges_deg.model_dump(),
        "dtype": dtype.name,
    }
    return Problem(names, lower, upper, fn, params, info, constraints=constraint_fn,
                   n_samples_used=info["n_samples_used"])  # fmt: skip
