"""Global performance indices of the 9-DOF master (seed 000 eq. 35-43, SPEC §3.2).

The position Jacobian J_v (eq. 34) and the backlash displacement are *linear* in the
lengths (a1, a3, a4, d3). The kernel therefore computes each sample's trigonometry once
(``features``) and applies a whole swarm of designs as a few multiply-adds per sample,
in structure-of-arrays form (one (M, C) array per matrix entry) that XLA fuses. The
3×3 Frobenius condition number uses J_v's zero pattern (J31 = J32 = 0) in the adjugate.
Samples are shared by every design of a swarm (common random numbers).
"""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics.conditioning import inv_cond
from designopt.numerics import montecarlo as mc
from designopt.studies.master9.settings import Indices

Array = jnp.ndarray
LINEAR_KEYS = ("a1", "a3", "a4", "d3")


def features(q: Array) -> dict[str, Array]:
    """Per-sample trigonometry (C,) arrays: everything J_v and det need."""
    q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2]
    s1, c1, s12, c12 = jnp.sin(q1), jnp.cos(q1), jnp.sin(q1 + q2), jnp.cos(q1 + q2)
    s3, c3 = jnp.sin(q3), jnp.cos(q3)
    return dict(s1=s1, c1=c1, s12=s12, c12=c12, s3=s3, c3=c3, c3c12=c3 * c12, c3s12=c3 * s12)


_features = features  # the name earlier versions used


def _pos_features(q: Array) -> Array:
    """(C, 7) position basis: P = a1 (c1, s1, 0) + d3 (c12, s12, 0) + a3 (c3 s12, -c3 c12, -s3)
    + a4 (s12, -c12, 0) + const (seed 000 eq. 4)."""
    q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2]
    s12, c12, c3 = jnp.sin(q1 + q2), jnp.cos(q1 + q2), jnp.cos(q3)
    return jnp.stack([jnp.cos(q1), jnp.sin(q1), c12, s12, c3 * s12, c3 * c12, jnp.sin(q3)], -1)


def jv_entries(x: dict[str, Array], f: dict[str, Array]) -> tuple[Array, ...]:
    """The 7 nonzero entries of J_v (eq. 34, fixed) for designs (M, 1) × samples (C,)."""
    a1, a3, a4, d3 = (x[k] for k in LINEAR_KEYS)
    j01 = a3 * f["c3c12"] + a4 * f["c12"] - d3 * f["s12"]
    j11 = a3 * f["c3s12"] + a4 * f["s12"] + d3 * f["c12"]
    j00 = j01 - a1 * f["s1"]
    j10 = j11 + a1 * f["c1"]
    j02 = -a3 * (f["s12"] * f["s3"])
    j12 = a3 * (f["c12"] * f["s3"])
    j22 = -a3 * f["c3"]
    return j00, j01, j02, j10, j11, j12, j22


def inv_cond_fro_jv(J: tuple[Array, ...]) -> tuple[Array, Array]:
    """(det J_v, raw 1/k_F) from the entries, adjugate with J20 = J21 = 0; 0 if singular."""
    j00, j01, j02, j10, j11, j12, j22 = J
    m = j00 * j11 - j01 * j10
    det = j22 * m
    c20 = j01 * j12 - j02 * j11
    c21 = j02 * j10 - j00 * j12
    nJ2 = j00 * j00 + j01 * j01 + j02 * j02 + j10 * j10 + j11 * j11 + j12 * j12 + j22 * j22
    nC2 = (
        j22 * j22 * (j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11) + c20 * c20 + c21 * c21 + m * m
    )
    den2 = nJ2 * nC2
    ok = den2 > 0
    r = jnp.where(ok, jnp.abs(det) * jax.lax.rsqrt(jnp.where(ok, den2, 1.0)), 0.0)
    return det, r


def _corner_deltas(q: Array, delta: Array) -> Array:
    """(8, C, 7) change of the position basis at the 2³ corners of the backlash box."""
    base = _pos_features(q)
    signs = jnp.asarray(list(itertools.product((-1.0, 1.0), repeat=3)), q.dtype)  # (8, 3)
    qc = q[None] + signs[:, None, :] * delta  # (8, C, 3)
    return jax.vmap(_pos_features)(qc) - base[None]


def emax(x: dict[str, Array], dP: Array) -> Array:
    """Largest tip displacement over the backlash corners (seed 000 eq. 39), (M, C)."""
    a1, a3, a4, d3 = (x[k][..., None] for k in LINEAR_KEYS)  # (M, 1, 1)
    dc1, ds1, dc12, ds12, dc3s12, dc3c12, ds3 = (dP[..., i] for i in range(7))  # (8, C)
    ex = a1 * dc1 + d3 * dc12 + a3 * dc3s12 + a4 * ds12
    ey = a1 * ds1 + d3 * ds12 - a3 * dc3c12 - a4 * dc12
    ez = -a3 * ds3
    return jnp.sqrt(jnp.max(ex * ex + ey * ey + ez * ez, axis=-2))  # max over corners


def _chunk_sums(x, q, delta, s: Indices):
    f = features(q)
    xm = {k: v[:, None] for k, v in x.items()}
    J = jv_entries(xm, f)
    det, r = inv_cond_fro_jv(J)
    if s.norm == "2":
        z = jnp.zeros_like(det)
        j00, j01, j02, j10, j11, j12, j22 = J
        Jm = jnp.stack(
            [
                jnp.stack([j00, j01, j02], -1),
                jnp.stack([j10, j11, j12], -1),
                jnp.stack([z, z, j22], -1),
            ],
            -2,
        )
        r = inv_cond(Jm, "2")
    elif s.normalized:
        r = 3.0 * r
    adet = jnp.abs(det)
    w = adet if s.measure == "cartesian" else jnp.ones_like(adet)
    e = emax({k: v[:, None] for k, v in x.items()}, _corner_deltas(q, delta))
    return mc.power_sums(w, r), mc.power_sums(w, e), mc.power_sums(adet, jnp.ones_like(adet))


def index_sums(x: dict[str, Array], key: jax.Array, s: Indices, dtype=None, mesh=None):
    """Accumulated power sums for (1/k, e_max, |det J_v|) over all samples, per design
    (the chunks spread over the ``samples`` axis of ``mesh`` when given)."""
    dtype = mc.out_dtype(dtype)
    lo, hi = s.box
    lo, hi = jnp.asarray(lo, dtype), jnp.asarray(hi, dtype)
    p = s.plan
    delta = jnp.deg2rad(jnp.asarray(s.backlash, dtype))
    x = {k: jnp.asarray(x[k], dtype) for k in LINEAR_KEYS}
    M = x["a1"].shape[0]

    def sums(k):
        u = mc.chunk_points(key, k, p, 3, dtype)
        q = lo + (hi - lo) * u
        return mc.to_replicate(_chunk_sums(x, q, delta, s), k, p)

    init = tuple(mc.zero_sums((M,), p, dtype) for _ in range(3))
    return mc.scan_chunks(sums, init, p.n_chunks, mesh)


def replicate_indices(
    design: dict[str, Array], key: jax.Array, s: Indices, dtype=None, mesh=None
) -> dict[str, Array]:
    """The indices of :func:`swarm_indices` per replicate: (M, R) arrays (with R = 1, (M,)
    arrays and the delta-method ``*_se``); reduce with ``mc.combine(v, se, s.plan)``."""
    dtype = mc.out_dtype(dtype)
    ps_k, ps_p, ps_v = index_sums(design, key, s, dtype, mesh)
    lo, hi = s.box
    qvol = float(np.prod(hi - lo))
    gci, gcsei, fk = mc.mean(ps_k), mc.std(ps_k), mc.std_minus_mean(ps_k)
    gpi = mc.mean(ps_p)
    vol = mc.box_integral(ps_v, qvol)
    L = (
        jnp.asarray(design["a1"], dtype)
        + jnp.asarray(design["a3"], dtype)
        + jnp.asarray(design["d3"], dtype)
    )
    if s.plan.replicates > 1:
        L = L[:, None]
    has_vol = vol.value > 0
    v_safe = jnp.where(has_vol, vol.value, 1.0)
    fl = jnp.where(has_vol, L / jnp.cbrt(v_safe), jnp.inf)  # no workspace: f_l = +inf
    fl_se = jnp.where(has_vol, fl * vol.se / (3.0 * v_safe), jnp.inf)
    return {
        "gci": gci.value, "gci_se": gci.se,
        "gcsei": gcsei.value, "gcsei_se": gcsei.se,
        "f_k": fk.value, "f_k_se": fk.se,
        "gpi": gpi.value, "gpi_se": gpi.se,
        "f_p": gpi.value, "f_p_se": gpi.se,
        "volume": vol.value, "volume_se": vol.se,
        "L": L, "f_l": fl, "f_l_se": fl_se,
    }  # fmt: skip


REPORTED = ("gci", "gcsei", "f_k", "gpi", "f_p", "volume", "f_l")


def reduce_replicates(rep: dict[str, Array], p: mc.Plan) -> dict[str, Array]:
    """(M,) values and SEs from :func:`replicate_indices` (mean and SD/√R of the replicates)."""
    out = {"L": rep["L"][:, 0] if p.replicates > 1 else rep["L"]}
    for n in REPORTED:
        e = mc.combine(rep[n], rep[n + "_se"], p)
        out[n], out[n + "_se"] = e.value, e.se
    return out


def swarm_indices(
    design: dict[str, Array], key: jax.Array, s: Indices, dtype=None, mesh=None
) -> dict[str, Array]:
    """All indices of eq. (35)-(42) for a swarm: design values of shape (M,). Returns (M,) arrays."""
    rep = replicate_indices(design, key, s, dtype, mesh)
    return reduce_replicates(rep, s.plan)
