"""The da Vinci patient-side arm (seed 002 eq. 1-3) on the generic frame kernel.

Chain of elementary transforms (angles in rad, lengths in mm)::

    Rx(α − π) Rz(q1) Tz(l_QH) · Rx(π/2 − β) Ry(π/2) Rz(q2) · Ty(q3)
      · Rx(−π/2) Rz(q4) · Rx(π/2) Rz(q5) · Ty(l_IJ) Ry(π/2) Rz(q6)

q3 is the prismatic insertion (the paper's l_IH). The design columns are
``DESIGN_KEYS`` = (alpha, beta, l_QH, l_IJ) (rad, rad, mm, mm), always array inputs.

Geometry used throughout (and tested): the origin of frame 2 is the remote centre of
motion H = Rx(α − π)·(0, 0, l_QH), independent of q1, q2, q3; the instrument shaft is the
y axis of frame 2 (q3 slides along it, so it passes through H); q4 rolls about the shaft,
q5 pitches about an axis through the shaft tip I, and the jaw axis q6 sits l_IJ from I.
The tool axis z6 is x5, so it does not depend on q6.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from designopt.kinematics.kernel import ET, SerialModel, et_model

HP = math.pi / 2
DESIGN_KEYS: tuple[str, ...] = ("alpha", "beta", "l_QH", "l_IJ")
"""Design columns: α, β (rad), l_QH, l_IJ (mm)."""

TABLE1 = {"alpha": math.radians(20.0), "beta": math.radians(30.45), "l_QH": 784.29, "l_IJ": 10.0}
"""Table 1 in our reading (α = 20°, β = β1 = 30.45°, l_QH = 784.29 mm, l_IJ = 10 mm)."""

LOWER = np.array([-HP, -math.radians(135.0), 0.0, -math.pi, -HP, -HP])
UPPER = np.array([HP, 0.0, 315.0, math.pi, HP, HP])
"""Joint ranges of §3.2 (rad; q3 in mm)."""

JOINT_NAMES = ("q1", "q2", "q3", "q4", "q5", "q6")
JOINT_UNITS = ("rad", "rad", "mm", "rad", "rad", "rad")

ELEMENTS: tuple[ET, ...] = (
    ET("Rx", None, "alpha", -math.pi, 1.0),  # seed 002 eq. (1): {−(π − α)}_x
    ET("Rz", 0),  # {q1}_z
    ET("Tz", None, "l_QH"),  # {l_QH}_z
    ET("Rx", None, "beta", HP, -1.0),  # {−(β − π/2)}_x
    ET("Ry", None, None, HP),  # {π/2}_y
    ET("Rz", 1),  # {q2}_z
    ET("Ty", 2),  # {q3}_y (prismatic)
    ET("Rx", None, None, -HP),  # {−π/2}_x
    ET("Rz", 3),  # {q4}_z
    ET("Rx", None, None, HP),  # {π/2}_x
    ET("Rz", 4),  # {q5}_z
    ET("Ty", None, "l_IJ"),  # {l_IJ}_y
    ET("Ry", None, None, HP),  # {π/2}_y
    ET("Rz", 5),  # {q6}_z
)
"""Seed 002 eq. (3), one element per factor."""

ARM: SerialModel = et_model(ELEMENTS, variables=DESIGN_KEYS)
"""The full 6-joint arm (tip frame 6 at J)."""

_FRAME_END = {1: 3, 2: 6, 3: 7, 4: 9, 5: 11, 6: 14}


def frame_model(k: int) -> SerialModel:
    """Frame k of eq. (1) (k = 1..6) as a kernel model over all six joints (joints after
    frame k have no effect)."""
    if k == 6:
        return ARM
    els = ELEMENTS[: _FRAME_END[k]]
    nc = sum(e.joint is not None for e in els)
    return et_model(els, variables=DESIGN_KEYS, coupling=np.eye(nc, 6))


def table1() -> np.ndarray:
    """The design vector of Table 1 (alpha, beta, l_QH, l_IJ)."""
    return np.array([TABLE1[k] for k in DESIGN_KEYS])


def rcm_point(X) -> jnp.ndarray:
    """H = Rx(α − π)·(0, 0, l_QH) (mm), the origin of frame 2, for designs X (..., 4)."""
    X = jnp.asarray(X)
    a, L = X[..., 0], X[..., 2]
    return jnp.stack([jnp.zeros_like(L), -jnp.sin(a - math.pi) * L, jnp.cos(a - math.pi) * L], -1)


def pose(X, q) -> jnp.ndarray:
    """Homogeneous tip pose (..., 4, 4) for one design X (4,) and joints q (C, 6) or (6,)."""
    R, p = ARM.fk(X, q)
    top = jnp.concatenate([R, p[..., None]], -1)
    bottom = jnp.broadcast_to(jnp.asarray([0.0, 0.0, 0.0, 1.0], R.dtype), (*R.shape[:-2], 1, 4))
    return jnp.concatenate([top, bottom], -2)
