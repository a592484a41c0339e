"""9-DOF haptic master manipulator of seed 000 (SPEC §3.1).

Joint vector everywhere in this module: q = (q1, q2, q3, q6, q7, q8, q9) in rad; the
passive joints q4 = -q3 (parallelogram) and q5 = -q1 - q2 (position compensation) are
applied inside. Lengths in mm. ``design`` is a dict with the keys ``DESIGN_KEYS``; its
values may be floats or arrays broadcastable against q's leading dimensions (a swarm).

Typos of the seed fixed here (docs/kinematics.md lists them with their checks):
eq. (3) R23; eq. (34) J21 and J22; eq. (53) d4 → a4; eq. (10) denominator; eq. (21)
degenerate (the redundancy is resolved by an explicit rule, see ``ik``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from designopt.kinematics.kernel import SerialModel, dh_model

Array = jnp.ndarray

DESIGN_KEYS: tuple[str, ...] = ("a1", "a3", "d3", "a4", "a5", "d2", "d5", "d6")
"""Design parameters (mm). a1, a3, d3 are the paper's design variables; the rest are fixed
structural lengths whose values the seed's Table 5 no longer shows (docs/kinematics.md)."""

PAPER_INITIAL = {"a1": 285.997, "a3": 280.933, "d3": 130.030}
"""Design at the paper's first PTPSO iteration (seed 000 §IV.C)."""
PAPER_FINAL = {"a1": 324.238, "a3": 317.076, "d3": 50.000}
"""Design at the paper's last PTPSO iteration (seed 000 §IV.C)."""

FIXED_DEFAULTS = {"a4": 10.0, "a5": 60.0, "d2": 30.0, "d5": 50.0, "d6": 80.0}
"""Our defaults for the lengths of the unreadable Table 5. a4 = 10 mm makes the convex-hull
workspace volumes of the two published designs reproduce the paper's ratio V_final/V_initial
(docs/indices.md); a5, d2, d5, d6 only translate the workspace."""

JOINT_NAMES: tuple[str, ...] = ("q1", "q2", "q3", "q6", "q7", "q8", "q9")
JOINT_LIMITS_DEG = np.array(
    [[-50, 40], [-60, 60], [-70, 70], [-120, 120], [-130, 160], [-45, 45], [-180, 180]],
    dtype=np.float64,
)
JOINT_LIMITS = np.deg2rad(JOINT_LIMITS_DEG)
"""(7, 2) joint ranges in rad (seed 000 Table 1); q9 is unlimited, stored as [-π, π]."""

POSITION_LIMITS = JOINT_LIMITS[:3]

_HP = math.pi / 2
COUPLING = np.zeros((9, 7))
for _i, _j in [(0, 0), (1, 1), (2, 2), (5, 3), (6, 4), (7, 5), (8, 6)]:
    COUPLING[_i, _j] = 1.0
COUPLING[3, 2] = -1.0  # q4 = -q3 (parallelogram)
COUPLING[4, 0] = COUPLING[4, 1] = -1.0  # q5 = -q1 - q2 (position compensation)
"""(9, 7): chain joints q1..q9 = COUPLING @ active joints (q1, q2, q3, q6, q7, q8, q9)."""

MODEL: SerialModel = dh_model(
    "modified",
    ("R",) * 9,
    alpha=[0.0, 0.0, -_HP, 0.0, _HP, 0.0, -_HP, _HP, _HP],
    a=[0.0, "a1", 0.0, "a3", "a4", "a5", 0.0, 0.0, 0.0],
    d=[0.0, ("d2", -1.0), "d3", 0.0, "d5", "d6", 0.0, 0.0, 0.0],
    theta=[0.0, -_HP, 0.0, 0.0, 0.0, -_HP, 0.0, _HP, -_HP],
    variables=DESIGN_KEYS,
    coupling=COUPLING,
)
"""The 9-joint modified-DH chain of SPEC §3.1 (reconstructed Table 1) on the frame kernel:
every length of ``DESIGN_KEYS`` is a design variable (a column of X, in that order), the
7 active joints drive the 9 chain joints through ``COUPLING``."""


def default_design() -> dict[str, float]:
    """The paper's optimised design (PAPER_FINAL) with the fixed lengths' defaults, in mm."""
    return {**PAPER_FINAL, **FIXED_DEFAULTS}


def check_design(design: Mapping[str, ArrayLike]) -> None:
    """Raise ValueError naming any missing or unknown key (called at the Python edge)."""
    if not isinstance(design, Mapping):
        raise ValueError(
            f"design must be a dict with keys {DESIGN_KEYS}, got {type(design).__name__}"
        )
    missing = [k for k in DESIGN_KEYS if k not in design]
    if missing:
        raise ValueError(f"design is missing key(s) {missing}; needs {list(DESIGN_KEYS)}")
    unknown = [k for k in design if k not in DESIGN_KEYS]
    if unknown:
        raise ValueError(f"design has unknown key(s) {unknown}; allowed {list(DESIGN_KEYS)}")


def _check_q(q: ArrayLike, n: int = 7, name: str = "q") -> Array:
    q = jnp.asarray(q)
    if q.ndim < 1 or q.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got {tuple(q.shape)}")
    return q


def _d(design: Mapping[str, ArrayLike], dtype) -> dict[str, Array]:
    return {k: jnp.asarray(design[k], dtype=dtype) for k in DESIGN_KEYS}


def _float(q: Array) -> Array:
    return q if jnp.issubdtype(q.dtype, jnp.floating) else q.astype(jnp.float64)


def _pairs(q: Array, design: Mapping[str, ArrayLike]) -> tuple[Array, Array, tuple]:
    """Designs X (N, 8) and configurations (N, 7), one pair per element of the broadcast
    leading shape of q and the design values."""
    dd = _d(design, q.dtype)
    lead = jnp.broadcast_shapes(q.shape[:-1], *[v.shape for v in dd.values()])
    X = jnp.stack([jnp.broadcast_to(dd[k], lead) for k in DESIGN_KEYS], -1)
    return X.reshape(-1, len(DESIGN_KEYS)), jnp.broadcast_to(q, lead + (7,)).reshape(-1, 7), lead


def _fk(q: Array, design: Mapping[str, ArrayLike]) -> Array:
    X, qf, lead = _pairs(q, design)
    R, p = jax.vmap(MODEL.fk)(X, qf)  # (N, 3, 3), (N, 3)
    top = jnp.concatenate([R, p[:, :, None]], -1)
    bottom = jnp.broadcast_to(jnp.asarray([0.0, 0.0, 0.0, 1.0], R.dtype), (R.shape[0], 1, 4))
    return jnp.concatenate([top, bottom], -2).reshape(lead + (4, 4))


def fk(q: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """Base-to-holding-point transform (..., 4, 4) of the chain (seed 000 eq. 1-2), by the
    frame kernel; design values broadcast against q's leading dimensions."""
    check_design(design)
    q = _float(_check_q(q))
    return _fk(q, design)


def position(q3: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """Holding-point position from q1..q3 (..., 3), closed form of seed 000 eq. (4)."""
    q3 = _float(jnp.asarray(q3))
    p = _d(design, q3.dtype)
    q1, q2, qq3 = q3[..., 0], q3[..., 1], q3[..., 2]
    s12, c12 = jnp.sin(q1 + q2), jnp.cos(q1 + q2)
    w = p["a3"] * jnp.cos(qq3) + p["a4"]
    px = p["a1"] * jnp.cos(q1) + p["d3"] * c12 + w * s12
    py = p["a1"] * jnp.sin(q1) + p["d3"] * s12 - w * c12 - p["a5"]
    pz = p["d6"] - p["d2"] + p["d5"] - p["a3"] * jnp.sin(qq3)
    return jnp.stack(jnp.broadcast_arrays(px, py, pz), axis=-1)


def rotation(q4: ArrayLike) -> Array:
    """Holding-point orientation from q6..q9 (..., 3, 3), seed 000 eq. (3) with R23 fixed.

    The printed R23 = -c6 s8 - c7 c9 is a typo; the chain gives -c6 s8 - c7 c8 s6 (which
    is also the third column of eq. (33)'s J_w, the approach vector a).
    """
    q4 = _float(jnp.asarray(q4))
    c6, s6 = jnp.cos(q4[..., 0]), jnp.sin(q4[..., 0])
    c7, s7 = jnp.cos(q4[..., 1]), jnp.sin(q4[..., 1])
    c8, s8 = jnp.cos(q4[..., 2]), jnp.sin(q4[..., 2])
    c9, s9 = jnp.cos(q4[..., 3]), jnp.sin(q4[..., 3])
    rows = [
        [c6 * c9 * s7 + c8 * s6 * s9 + c6 * c7 * s8 * s9, c8 * c9 * s6 - c6 * s7 * s9 + c6 * c7 * c9 * s8, s6 * s8 - c6 * c7 * c8],
        [c9 * s6 * s7 - c6 * c8 * s9 + c7 * s6 * s8 * s9, c7 * c9 * s6 * s8 - c6 * c8 * c9 - s6 * s7 * s9, -c6 * s8 - c7 * c8 * s6],
        [s7 * s8 * s9 - c7 * c9, c7 * s9 + c9 * s7 * s8, -c8 * s7],
    ]  # fmt: skip
    return jnp.stack([jnp.stack(r, -1) for r in rows], -2)


def fk_closed(q: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """Transform (..., 4, 4) from the paper's closed forms eq. (3)-(4) (typos fixed)."""
    check_design(design)
    q = _float(_check_q(q))
    R = rotation(q[..., 3:])
    P = position(q[..., :3], design)
    lead = jnp.broadcast_shapes(R.shape[:-2], P.shape[:-1])
    R = jnp.broadcast_to(R, lead + (3, 3))
    P = jnp.broadcast_to(P, lead + (3,))
    top = jnp.concatenate([R, P[..., None]], axis=-1)
    bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], dtype=top.dtype), lead + (1, 4))
    return jnp.concatenate([top, bottom], axis=-2)


def jacobian(q: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """Geometric Jacobian (..., 6, 7) in the base frame, rows v then ω, columns the active
    joints, from the frame kernel (the passive joints enter through ``COUPLING``;
    equivalent to seed 000 eq. 31)."""
    check_design(design)
    q = _float(_check_q(q))
    X, qf, lead = _pairs(q, design)
    return jax.vmap(MODEL.jacobian)(X, qf).reshape(lead + (6, 7))


def jacobian_v_closed(q3: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """Position block J_v (..., 3, 3) in closed form, seed 000 eq. (34) with two typos fixed:
    J21 ends in + a1 c1 (printed: a repeated d3 c12), J22 has + d3 c12 (missing in print).

    J_v is linear in (a1, a3, a4, d3) and independent of a5, d2, d5, d6.
    """
    q3 = _float(jnp.asarray(q3))
    p = _d(design, q3.dtype)
    q1, q2, qq3 = q3[..., 0], q3[..., 1], q3[..., 2]
    s12, c12 = jnp.sin(q1 + q2), jnp.cos(q1 + q2)
    w = p["a3"] * jnp.cos(qq3) + p["a4"]
    j12 = w * c12 - p["d3"] * s12
    j22 = w * s12 + p["d3"] * c12
    j11 = j12 - p["a1"] * jnp.sin(q1)
    j21 = j22 + p["a1"] * jnp.cos(q1)
    j13 = -p["a3"] * s12 * jnp.sin(qq3)
    j23 = p["a3"] * c12 * jnp.sin(qq3)
    j33 = -p["a3"] * jnp.cos(qq3)
    z = jnp.zeros_like(j33 + j11)
    rows = [[j11, j12, j13], [j21, j22, j23], [z, z, j33]]
    rows = [jnp.broadcast_arrays(*r) for r in rows]
    lead = jnp.broadcast_shapes(*[x.shape for r in rows for x in r])
    return jnp.stack([jnp.stack([jnp.broadcast_to(x, lead) for x in r], -1) for r in rows], -2)


def jacobian_w_closed(q4: ArrayLike) -> Array:
    """Angular block J_w (..., 3, 4) for (q6, q7, q8, q9), seed 000 eq. (33)."""
    q4 = _float(jnp.asarray(q4))
    c6, s6 = jnp.cos(q4[..., 0]), jnp.sin(q4[..., 0])
    c7, s7 = jnp.cos(q4[..., 1]), jnp.sin(q4[..., 1])
    c8, s8 = jnp.cos(q4[..., 2]), jnp.sin(q4[..., 2])
    z, o = jnp.zeros_like(c6), jnp.ones_like(c6)
    rows = [
        [z, s6, -c6 * s7, s6 * s8 - c6 * c7 * c8],
        [z, -c6, -s6 * s7, -c6 * s8 - c7 * c8 * s6],
        [o, z, c7, -c8 * s7],
    ]
    return jnp.stack([jnp.stack(r, -1) for r in rows], -2)


def jacobian_closed(q: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """Block-diagonal J = [J_v 0; 0 J_w] (..., 6, 7), seed 000 eq. (32)-(34)."""
    check_design(design)
    q = _float(_check_q(q))
    Jv = jacobian_v_closed(q[..., :3], design)
    Jw = jacobian_w_closed(q[..., 3:])
    lead = jnp.broadcast_shapes(Jv.shape[:-2], Jw.shape[:-2])
    Jv = jnp.broadcast_to(Jv, lead + (3, 3))
    Jw = jnp.broadcast_to(Jw, lead + (3, 4))
    top = jnp.concatenate([Jv, jnp.zeros(lead + (3, 4), Jv.dtype)], -1)
    bot = jnp.concatenate([jnp.zeros(lead + (3, 3), Jv.dtype), Jw], -1)
    return jnp.concatenate([top, bot], -2)


def det_jv(q3: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """det J_v = a1 a3 cos q3 ((a3 cos q3 + a4) cos q2 - d3 sin q2) (derived from eq. 34)."""
    q3 = _float(jnp.asarray(q3))
    p = _d(design, q3.dtype)
    c3 = jnp.cos(q3[..., 2])
    return (
        p["a1"]
        * p["a3"]
        * c3
        * ((p["a3"] * c3 + p["a4"]) * jnp.cos(q3[..., 1]) - p["d3"] * jnp.sin(q3[..., 1]))
    )


def cond_fro_eq53(q3: ArrayLike, design: Mapping[str, ArrayLike]) -> Array:
    """Raw Frobenius condition number of J_v as printed in seed 000 eq. (53), with the
    printed ``d_4`` read as ``a_4`` (the only reading that matches ‖J‖_F‖J⁻¹‖_F)."""
    q3 = _float(jnp.asarray(q3))
    p = _d(design, q3.dtype)
    a1, a3, a4, d3 = p["a1"], p["a3"], p["a4"], p["d3"]
    cq2, sq2, cq3 = jnp.cos(q3[..., 1]), jnp.sin(q3[..., 1]), jnp.cos(q3[..., 2])
    num = (
        2 * a3**4 * cq3**2 + a1**2 * a3**2 + 2 * a3**2 * a4**2 + a1**2 * d3**2
        - a1**2 * a3**2 * cq2**2 + a1**2 * a4**2 * cq2**2 - a1**2 * d3**2 * cq2**2
        + 2 * a3**2 * d3**2 * cq3**2 + 4 * a3**3 * a4 * cq3 - a1**2 * a4 * d3 * jnp.sin(2 * q3[..., 1])
        + 2 * a1 * a3**3 * cq3 * sq2 + 2 * a1**2 * a3**2 * cq2**2 * cq3**2 + 2 * a1 * a3**2 * a4 * sq2
        + 2 * a1**2 * a3 * a4 * cq2**2 * cq3 + 2 * a1 * a3**2 * d3 * cq2 * cq3**2
        - 2 * a1**2 * a3 * d3 * cq2 * cq3 * sq2
    )  # fmt: skip
    den = a1**2 * a3**2 * cq3**2 * (
        a4**2 * cq2**2 - d3**2 * cq2**2 + d3**2 + a3**2 * cq2**2 * cq3**2
        + 2 * a3 * a4 * cq2**2 * cq3 - 2 * a4 * d3 * cq2 * sq2 - 2 * a3 * d3 * cq2 * cq3 * sq2
    )  # fmt: skip
    fro2 = (
        2 * a3**2 * cq3**2 + a1**2 + a3**2 + 2 * a4**2 + 2 * d3**2 + 2 * a1 * a4 * sq2
        + 4 * a3 * a4 * cq3 + 2 * a1 * d3 * cq2 + 2 * a1 * a3 * cq3 * sq2
    )  # fmt: skip
    return jnp.sqrt(num / den) * jnp.sqrt(fro2)


# ----------------------------------------------------------------------------- IK


def _wrap(x: Array) -> Array:
    return jnp.arctan2(jnp.sin(x), jnp.cos(x))


def _in_limits(q: Array, lim: np.ndarray, tol: float = 1e-9) -> Array:
    lo = jnp.asarray(lim[:, 0], q.dtype)
    hi = jnp.asarray(lim[:, 1], q.dtype)
    return jnp.all((q >= lo - tol) & (q <= hi + tol), axis=-1)


def _wrapped_dist2(q: Array, q_ref: Array) -> Array:
    """Squared angle-wrapped distance Σ wrap(q - q_ref)² over the last axis."""
    return jnp.sum(_wrap(q - q_ref) ** 2, axis=-1)


def _closest(q: Array, ok: Array, q_ref: Array) -> tuple[Array, Array]:
    """Of the branches q (..., B, n) with mask ok (..., B), the one closest to q_ref (..., n)
    in the angle-wrapped distance among those with ok; branch 0 where none is ok."""
    score = jnp.where(ok, _wrapped_dist2(q, q_ref[..., None, :]), jnp.inf)
    q = jnp.broadcast_to(q, score.shape + q.shape[-1:])
    ok = jnp.broadcast_to(ok, score.shape)
    best = jnp.argmin(score, axis=-1)
    qb = jnp.take_along_axis(q, best[..., None, None], axis=-2)[..., 0, :]
    okb = jnp.take_along_axis(ok, best[..., None], axis=-1)[..., 0]
    return qb, okb


def _check_ref(q_ref: ArrayLike, n: int, dtype) -> Array:
    q_ref = jnp.asarray(q_ref)
    if q_ref.ndim < 1 or q_ref.shape[-1] != n:
        raise ValueError(f"q_ref must have shape (..., {n}), got {tuple(q_ref.shape)}")
    return q_ref.astype(dtype)


def ik_position_branches(
    p: ArrayLike, design: Mapping[str, ArrayLike], within_limits: bool = True
) -> tuple[Array, Array]:
    """All four solutions q1..q3 of the holding-point position (seed 000 eq. 9-15, corrected).

    The planar part is a two-link arm: (p_x, p_y + a5) = a1 e(q1) + Rot(q1+q2)(d3, -w),
    w = a3 cos q3 + a4. Eq. (10)-(12) are this arm's law of cosines divided by p_x (the
    printed eq. 10 misses the brackets around its numerator); we solve it without the
    division so p_x = 0 is no singularity. Branches, in this order:
    0/1: q3 = asin(s3), elbow q1 = atan2(u) ± acos(·); 2/3: q3 = π - asin(s3), same elbows.
    Branches 2/3 have |q3| ≥ 90° and so are never within the limits (|q3| ≤ 70°); they are
    returned for completeness. Returns (q (..., 4, 3), ok (..., 4)); ok says the position is
    reachable on that branch and, with ``within_limits`` (default), that q is within limits.
    """
    p = _float(jnp.asarray(p))
    dd = _d(design, p.dtype)
    a1, a3, a4, d3 = dd["a1"], dd["a3"], dd["a4"], dd["d3"]
    s3 = (dd["d6"] - dd["d2"] + dd["d5"] - p[..., 2]) / a3  # eq. (9)
    reach3 = jnp.abs(s3) <= 1.0
    q3a = jnp.arcsin(jnp.clip(s3, -1.0, 1.0))
    ux, uy = p[..., 0], p[..., 1] + dd["a5"]
    r2 = ux**2 + uy**2
    base = jnp.arctan2(uy, ux)
    qs, oks = [], []
    for q3 in (q3a, _wrap(jnp.pi - q3a)):
        w = a3 * jnp.cos(q3) + a4
        K = (r2 + a1**2 - d3**2 - w**2) / (2 * a1)  # = u · e(q1)
        ratio = K / jnp.sqrt(jnp.where(r2 > 0, r2, 1.0))
        reach = reach3 & (jnp.abs(ratio) <= 1.0) & (r2 > 0)
        dq = jnp.arccos(jnp.clip(ratio, -1.0, 1.0))
        for sgn in (1.0, -1.0):
            q1 = _wrap(base + sgn * dq)
            rx, ry = ux - a1 * jnp.cos(q1), uy - a1 * jnp.sin(q1)
            q12 = jnp.arctan2(ry, rx) - jnp.arctan2(-w, d3)  # eq. (14)-(15) with atan2
            q2 = _wrap(q12 - q1)
            qs.append(jnp.stack(jnp.broadcast_arrays(q1, q2, q3), -1))
            oks.append(reach)
    lead = jnp.broadcast_shapes(*[x.shape[:-1] for x in qs], *[o.shape for o in oks])
    q = jnp.stack([jnp.broadcast_to(x, lead + (3,)) for x in qs], -2)
    ok = jnp.stack([jnp.broadcast_to(o, lead) for o in oks], -1)
    if within_limits:
        ok = ok & _in_limits(q, POSITION_LIMITS)
    return q, ok


def ik_position(
    p: ArrayLike, design: Mapping[str, ArrayLike], q_ref: ArrayLike | None = None
) -> tuple[Array, Array]:
    """q1..q3 from the holding-point position; the branches are ``ik_position_branches``.

    - ``q_ref=None``: of the two elbow branches we keep one within the joint limits,
      preferring the one with det J_v > 0 (the sheet the workspace is built on).
    - ``q_ref`` (..., 3), broadcastable against p's leading dimensions: the branch within
      limits closest to q_ref in the angle-wrapped distance.
    Returns (q (..., 3), ok (...)) with ok False where no branch is within limits.
    """
    q, ok = ik_position_branches(p, design)
    if q_ref is not None:
        return _closest(q, ok, _check_ref(q_ref, 3, q.dtype))
    qa, qb, oka, okb = q[..., 0, :], q[..., 1, :], ok[..., 0], ok[..., 1]
    deta = det_jv(qa, design)
    prefer_a = oka & (~okb | (deta > 0))
    return jnp.where(prefer_a[..., None], qa, qb), oka | okb


def _rz_t(R: Array, t: Array) -> Array:
    """Rz(t)ᵀ R."""
    c, s = jnp.cos(t), jnp.sin(t)
    r0 = c[..., None] * R[..., 0, :] + s[..., None] * R[..., 1, :]
    r1 = -s[..., None] * R[..., 0, :] + c[..., None] * R[..., 1, :]
    return jnp.stack([r0, r1, R[..., 2, :]], -2)


def ik_orientation_branches(
    R: ArrayLike, q6: ArrayLike, within_limits: bool = True
) -> tuple[Array, Array]:
    """Both solutions q6..q9 of the holding-point rotation for a given q6.

    With the chain of SPEC §3.1, R = Rz(q6-π)·Ry(q7)·Rz(q8+π/2)·Ry(π/2-q9)·Rx(π/2), so for a
    given q6, (q7, q8 + π/2, π/2 - q9) are the Y-Z-Y Euler angles of
    N = Rz(q6-π)ᵀ R Rx(π/2)ᵀ. Branch 0 has q8 ∈ [-90°, 90°]; branch 1 is the other Euler
    solution (q7 + π, -q8 - π, q9 - π), whose |q8| ≥ 90° is never within the limits
    (|q8| ≤ 45°); it is returned for completeness. ``q6`` broadcasts against R's leading
    dimensions. Returns (q (..., 2, 4), ok (..., 2)); with ``within_limits`` (default) ok
    says q is within the joint limits, otherwise ok is all True.
    """
    R = _float(jnp.asarray(R))
    q6 = jnp.asarray(q6, R.dtype)
    lead = jnp.broadcast_shapes(R.shape[:-2], q6.shape)
    R = jnp.broadcast_to(R, lead + (3, 3))
    q6 = jnp.broadcast_to(q6, lead)
    M = _rz_t(R, q6 - jnp.pi)
    # N = M Rx(π/2)ᵀ: columns (m0, m1, m2) → (m0, -m2, m1)
    N = jnp.stack([M[..., :, 0], -M[..., :, 2], M[..., :, 1]], -1)
    sb = jnp.sqrt(N[..., 1, 0] ** 2 + N[..., 1, 2] ** 2)
    beta = jnp.arctan2(sb, N[..., 1, 1])
    q7 = jnp.arctan2(N[..., 2, 1], -N[..., 0, 1])
    gamma = jnp.arctan2(N[..., 1, 2], N[..., 1, 0])
    q8 = beta - jnp.pi / 2
    q9 = _wrap(jnp.pi / 2 - gamma)
    qa = jnp.stack([q6, q7, q8, q9], -1)
    qb = jnp.stack([q6, _wrap(q7 + jnp.pi), _wrap(-q8 - jnp.pi), _wrap(q9 - jnp.pi)], -1)
    q = jnp.stack([qa, qb], -2)
    ok = _in_limits(q, JOINT_LIMITS[3:]) if within_limits else jnp.ones(lead + (2,), bool)
    return q, ok


def ik_orientation(
    R: ArrayLike, q6: ArrayLike | None = None, q_ref: ArrayLike | None = None
) -> tuple[Array, Array]:
    """q6..q9 from the holding-point rotation (replaces seed 000 eq. 16-25).

    Four joints for three DOF (``ik_orientation_branches``). Eq. (21) cannot fix q6 (its
    numerator n_x o_z - n_z o_x + a_y is zero for every rotation because n × o = a), so:
    - ``q6`` given: q7, q8, q9 follow uniquely within limits (q8 ∈ (-90°, 90°));
    - ``q6=None, q_ref=None``: among the solutions within limits, the one with the smallest
      |q8|, i.e. farthest from q8 = ±90° where the q7 and q9 axes coincide (the seed's "A6
      coincident with A8" singularity). q6 = atan2(a_y, a_x) or that + π gives q8 = 0
      exactly (s8 = a_x s6 - a_y c6, eq. 18) and is tried first; where both put q7 out of
      limits, a grid of q6 over its range is searched (``Q6_GRID`` points);
    - ``q_ref`` (..., 4) given: the solution within limits closest to q_ref (angle-wrapped
      distance). With ``q6`` given, of its Euler branches. Otherwise q6 is free: the best of
      the candidates q6 = q_ref's q6 (so a reference that solves R is returned unchanged),
      the two q8 = 0 values above and the ``Q6_GRID`` grid, refined by ``Q6_REFINE_STEPS``
      Gauss-Newton steps along the wrist's self-motion (a local minimum of the distance,
      never farther than the best candidate).
    Returns (q (..., 4), ok (...)).
    """
    R = _float(jnp.asarray(R))
    if q_ref is not None:
        q_ref = _check_ref(q_ref, 4, R.dtype)
        if q6 is not None:
            return _closest(*ik_orientation_branches(R, q6), q_ref)
        cands = _q6_candidates(R)
        lead = jnp.broadcast_shapes(q_ref.shape[:-1], cands.shape[:-1])
        q6c = jnp.concatenate(
            [
                jnp.broadcast_to(q_ref[..., 0:1], lead + (1,)),
                jnp.broadcast_to(cands, lead + cands.shape[-1:]),
            ],
            axis=-1,
        )
        q, ok = _closest(*_orientation_candidates(R, q6c), q_ref)
        return _refine_q6(R, q, ok, q_ref), ok
    if q6 is None:
        return _ik_orientation_auto(R)
    q, ok = ik_orientation_branches(R, q6)
    return q[..., 0, :], ok[..., 0]


Q6_GRID = 73


def _q6_candidates(R: Array) -> Array:
    """(..., 2 + Q6_GRID) q6 values the redundancy rule tries (q8 = 0 ones first)."""
    base = jnp.arctan2(R[..., 1, 2], R[..., 0, 2])
    grid = jnp.linspace(JOINT_LIMITS[3, 0], JOINT_LIMITS[3, 1], Q6_GRID, dtype=R.dtype)
    grid = jnp.broadcast_to(grid, base.shape + (Q6_GRID,))
    return jnp.concatenate([base[..., None], _wrap(base + jnp.pi)[..., None], grid], -1)


def _orientation_candidates(R: Array, q6c: Array) -> tuple[Array, Array]:
    """Wrist branch 0 for each q6 candidate (..., C) → (q (..., C, 4), ok (..., C)); the
    other Euler branch is never within limits."""
    qs, oks = jax.vmap(lambda c: ik_orientation_branches(R, c), in_axes=-1, out_axes=(-3, -2))(
        q6c
    )  # (..., C, 2, 4), (..., C, 2)
    return qs[..., 0, :], oks[..., 0]


Q6_REFINE_STEPS = 24


def _refine_q6(R: Array, q: Array, ok: Array, q_ref: Array) -> Array:
    """Damped Gauss-Newton on the redundant q6 from the best candidate q (..., 4): minimise
    Σ wrap(q(q6) - q_ref)² along the wrist's self-motion. A step is taken only where it stays
    within limits and lowers the distance (so the result is never farther than q); a refused
    step is halved, a taken one doubled (at most a full step), so a minimum on a joint limit
    is approached to about 2^-(Q6_REFINE_STEPS/2) of the first step."""

    def wrist(q6):
        qs, oks = ik_orientation_branches(R, q6)
        return qs[..., 0, :], oks[..., 0]  # the other Euler branch is never within limits

    def step(_, carry):
        q, dist, scale = carry
        qq, dq = jax.jvp(lambda t: wrist(t)[0], (q[..., 0],), (jnp.ones_like(q[..., 0]),))
        r = _wrap(qq - q_ref)
        den = jnp.sum(dq * dq, -1)
        q6 = q[..., 0] - scale * jnp.sum(dq * r, -1) / jnp.where(den > 0, den, 1.0)
        qn, okn = wrist(q6)
        distn = _wrapped_dist2(qn, q_ref)
        better = okn & (distn < dist)
        scale = jnp.where(better, jnp.minimum(2 * scale, 1.0), scale / 2)
        return jnp.where(better[..., None], qn, q), jnp.where(better, distn, dist), scale

    q = jnp.broadcast_to(q, jnp.broadcast_shapes(q.shape, q_ref.shape, R.shape[:-2] + (4,)))
    dist = jnp.where(ok, _wrapped_dist2(q, q_ref), -jnp.inf)  # nothing to refine where not ok
    scale = jnp.ones_like(dist)
    q, _, _ = jax.lax.fori_loop(0, Q6_REFINE_STEPS, step, (q, dist, scale))
    return q


def _ik_orientation_auto(R: Array) -> tuple[Array, Array]:
    qs, oks = _orientation_candidates(R, _q6_candidates(R))
    score = jnp.where(oks, jnp.abs(qs[..., 2]), jnp.inf)
    best = jnp.argmin(score, axis=-1)
    q = jnp.take_along_axis(qs, best[..., None, None], axis=-2)[..., 0, :]
    ok = jnp.take_along_axis(oks, best[..., None], axis=-1)[..., 0]
    return q, ok


def _check_T(T: ArrayLike) -> Array:
    T = _float(jnp.asarray(T))
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"T must have shape (..., 4, 4), got {tuple(T.shape)}")
    return T


def ik_branches(
    T: ArrayLike,
    design: Mapping[str, ArrayLike],
    q6: ArrayLike | None = None,
    within_limits: bool = True,
) -> tuple[Array, Array]:
    """Every closed-form IK branch of the poses T (..., 4, 4) for one value of q6.

    q6 (the redundant wrist joint) is ``q6`` where given (broadcastable against T's leading
    dimensions), else the one ``ik_orientation``'s redundancy rule picks. The 8 branches are
    the products of the 4 position branches (``ik_position_branches``: elbow ±, and the two
    q3 = π - asin ones, never within limits) and the 2 wrist branches
    (``ik_orientation_branches``; the second never within limits): branch b = 2 i + j with
    position branch i and wrist branch j. Within the joint limits only branches 0 and 2
    (the two elbows, standard wrist) can hold.
    Returns (q (..., 8, 7), ok (..., 8)); ok as in the two functions named above.
    """
    check_design(design)
    T = _check_T(T)
    if q6 is None:
        q6 = _ik_orientation_auto(T[..., :3, :3])[0][..., 0]
    qp, okp = ik_position_branches(T[..., :3, 3], design, within_limits)
    qo, oko = ik_orientation_branches(T[..., :3, :3], q6, within_limits)
    lead = jnp.broadcast_shapes(qp.shape[:-2], qo.shape[:-2])
    qp = jnp.broadcast_to(qp[..., :, None, :], lead + (4, 2, 3))
    qo = jnp.broadcast_to(qo[..., None, :, :], lead + (4, 2, 4))
    q = jnp.concatenate([qp, qo], -1).reshape(lead + (8, 7))
    ok = (okp[..., :, None] & oko[..., None, :]).reshape(lead + (8,))
    return q, ok


def ik(
    T: ArrayLike,
    design: Mapping[str, ArrayLike],
    q6: ArrayLike | None = None,
    full_output: bool = False,
    q_ref: ArrayLike | None = None,
) -> Array | tuple[Array, Array]:
    """Closed-form IK (..., 4, 4) → q (..., 7) within the joint limits.

    Position and orientation decouple (seed 000 §III.B): ``ik_position`` and
    ``ik_orientation`` say how each is solved, which typos of the seed they avoid and which
    branch each keeps. Without ``q_ref`` the elbow with det J_v > 0 and the wrist with the
    smallest |q8| are preferred. With ``q_ref`` (..., 7), broadcastable against T's leading
    dimensions, the solution within limits closest to q_ref in the angle-wrapped distance
    Σ wrap(q - q_ref)² is returned (the distance is a sum over the decoupled position and
    wrist joints, so each part is chosen on its own); a q_ref that solves T within limits
    comes back unchanged. ``ik_branches`` gives all branches.
    Poses with no solution within limits give NaN rows; ``full_output=True`` also returns
    the boolean mask of solved poses.
    """
    check_design(design)
    T = _check_T(T)
    if q_ref is not None:
        q_ref = _check_ref(q_ref, 7, T.dtype)
    qp, okp = ik_position(T[..., :3, 3], design, None if q_ref is None else q_ref[..., :3])
    qo, oko = ik_orientation(T[..., :3, :3], q6, None if q_ref is None else q_ref[..., 3:])
    lead = jnp.broadcast_shapes(qp.shape[:-1], qo.shape[:-1])
    q = jnp.concatenate([jnp.broadcast_to(qp, lead + (3,)), jnp.broadcast_to(qo, lead + (4,))], -1)
    ok = okp & oko
    q = jnp.where(ok[..., None], q, jnp.nan)
    return (q, ok) if full_output else q


def sample_joints(key: jax.Array, n: int, dtype=jnp.float64) -> Array:
    """n configurations (n, 7) uniform in the joint limits (for tests and demos)."""
    lo = jnp.asarray(JOINT_LIMITS[:, 0], dtype)
    hi = jnp.asarray(JOINT_LIMITS[:, 1], dtype)
    return jax.random.uniform(key, (n, 7), dtype, lo, hi)
