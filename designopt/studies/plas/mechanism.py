"""The PLAS slave and its all-joints master (seed 004) as chains on the generic frame
kernel (``designopt.kinematics.kernel``), the mapping factors of eq. (28) as a function of
the design, and the counterbalance of §2.1.2.

Chains (all lengths in mm, angles in rad; the closed forms they are checked against are
in ``paper.py``):

- ``SLAVE_FULL``: Table 1, standard DH, joints (d1, θ2, θ3, θ4, d5, θ6); variables
  (a2, a3, d6s). The table reaches the reduced model's tip with θ4_reduced = π/2 − θ4.
- ``MASTER_FULL``: Table 3 as *reconstructed* (the printed table does not give the
  seed's own closed form eq. (5); docs/plas.md): standard DH, joints
  (d1', θ2, θ3, θ4, θ5, d6'); variables (a2p, d6). Its FK is eq. (5) exactly.
- ``SLAVE``: Table 4, modified DH, joints (θ2, θ3, θ4, θ5); variables (a2, a3, d5).
- ``MASTER``: Table 5, modified DH, joints (θ2, θ3, θ4, θ5); variables (a2p, a3p, d6).
  ``a3p`` (an offset between the master's joints 3 and 4) is 0 on the built master
  (Table 5 has none): it is our optional extra design length.

The mapping of eq. (27)-(28) equates, joint by joint, the master's and the slave's
coefficients of v_y (joints 2, 3) and v_z (joint 4) at one common configuration θ.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from designopt.kinematics.kernel import SerialModel, dh_model

HP = math.pi / 2

MASTER_KEYS: tuple[str, ...] = ("a2p", "a3p", "d6")
"""The master's lengths (mm) a design may vary: a2', the optional offset a3', d6."""
SLAVE_KEYS: tuple[str, ...] = ("a2", "a3", "d5")
BUILT: dict[str, float] = {"a2p": 138.0, "a3p": 0.0, "d6": 60.0}
"""The built master (seed 004 §3.4)."""
SLAVE_LENGTHS: dict[str, float] = {"a2": 50.0, "a3": 15.0, "d5": 30.0}
"""The slave's lengths used by the mapping (seed 004 §3.4)."""

SLAVE_FULL: SerialModel = dh_model(
    "standard", "PRRRPR",
    alpha=[HP, 0.0, 3 * HP, HP, 0.0, 0.0],
    a=[0.0, "a2", "a3", 0.0, 0.0, 0.0],
    d=[0.0, 0.0, 0.0, 0.0, 0.0, "d6s"],
    theta=[0.0] * 6,
    variables=("a2", "a3", "d6s"),
)  # fmt: skip
"""Table 1 (standard DH): d1 and d5 are the prismatic joints (d5 is the tool extension the
mapping treats as a fixed length), d6s the slave's fixed tool offset (not given: 0)."""

MASTER_FULL: SerialModel = dh_model(
    "standard", "PRRRRP",
    alpha=[0.0, HP, -HP, HP, 0.0, 0.0],
    a=[0.0, "a2p", 0.0, 0.0, 0.0, 0.0],
    d=[0.0, 0.0, 0.0, 0.0, 0.0, "d6"],
    theta=[0.0, 0.0, 0.0, HP, HP, 0.0],
    variables=("a2p", "d6"),
)  # fmt: skip
"""Table 3 as reconstructed so that its FK is the seed's eq. (5) (R and p) for every
joint value: rows (α, a, d, θ) = (0, 0, d1', 0), (π/2, a2', 0, θ2), (−π/2, 0, 0, θ3),
(π/2, 0, 0, θ4 + π/2), (0, 0, 0, θ5 + π/2), (0, 0, d6 + d6', 0). The printed a1 and a5
do not appear in eq. (5) and are left out (0)."""

SLAVE: SerialModel = dh_model(
    "modified", "RRRR",
    alpha=[0.0, 0.0, HP, HP],
    a=[0.0, "a2", "a3", 0.0],
    d=[0.0, 0.0, 0.0, "d5"],
    theta=[0.0, 0.0, HP, 0.0],
    variables=SLAVE_KEYS,
)  # fmt: skip
MASTER: SerialModel = dh_model(
    "modified", "RRRR",
    alpha=[0.0, 0.0, HP, HP],
    a=[0.0, "a2p", "a3p", 0.0],
    d=[0.0, 0.0, 0.0, "d6"],
    theta=[0.0, 0.0, HP, 0.0],
    variables=MASTER_KEYS,
)  # fmt: skip

# the reduced models' joints: (θ2, θ3, θ4, θ5); the position block uses the first three
POSITION_COLS = (0, 1, 2)


def slave_row(slave: Mapping[str, float] | None = None) -> np.ndarray:
    s = {**SLAVE_LENGTHS, **(slave or {})}
    return np.array([[s[k] for k in SLAVE_KEYS]], np.float64)


def master_rows(design: Mapping[str, float] | Mapping[str, np.ndarray]) -> np.ndarray:
    d = {**BUILT, **design}
    cols = [np.atleast_1d(np.asarray(d[k], np.float64)) for k in MASTER_KEYS]
    n = max(c.shape[0] for c in cols)
    return np.stack([np.broadcast_to(c, (n,)) for c in cols], -1)


def q4(theta: jnp.ndarray) -> jnp.ndarray:
    """(…, 3) angles (θ2, θ3, θ4) → (…, 4) joint vector of the reduced models (θ5 = 0)."""
    return jnp.concatenate([theta, jnp.zeros_like(theta[..., :1])], -1)


def mapping_factors(master: jnp.ndarray, slave: jnp.ndarray, theta: jnp.ndarray):
    """Eq. (28) as a function of the design: factors (k2, k3, k4) with
    θ'_slave,i = k_i θ'_master,i at the common configuration ``theta`` (…, 3).

    ``master`` (…, 3) holds (a2', a3', d6), ``slave`` (…, 3) holds (a2, a3, d5); all
    broadcast against theta[..., 0]. With a3' = 0 these are the seed's
    k2 = (C23·d6C4 + a2'C2)/(C23(a3 + d5C4) + a2C2), k3 = d6C4/(a3 + d5C4), k4 = d6/d5.
    """
    t2, t3, t4 = theta[..., 0], theta[..., 1], theta[..., 2]
    a2p, a3p, d6 = master[..., 0], master[..., 1], master[..., 2]
    a2, a3, d5 = slave[..., 0], slave[..., 1], slave[..., 2]
    c2, c23, c4 = jnp.cos(t2), jnp.cos(t2 + t3), jnp.cos(t4)
    A = a3p + d6 * c4  # the master's tip arm beyond joint 3, in the joint-2/3 plane
    B = a3 + d5 * c4  # the slave's
    k2 = (c23 * A + a2p * c2) / (c23 * B + a2 * c2)
    k3 = A / B
    k4 = jnp.broadcast_to(d6 / d5, k2.shape)
    return k2, k3, k4


def reach(master: jnp.ndarray) -> jnp.ndarray:
    """The master's total reach from joint 2 to the handle, a2' + a3' + d6 (…, 3) → (…)."""
    return master[..., 0] + master[..., 1] + master[..., 2]


def counterbalance_mass(M, L, r, l, theta):
    """Eq. (1) of §2.1.2: the counterweight m that holds joint 4 at tilt θ:
    m = M(L cos θ − r sin θ)/(r sin θ + l cos θ) (any consistent units)."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return M * (L * c - r * s) / (r * s + l * c)


def counterbalance_inertia(M, L, m, l):
    """I = M L² + m l² about joint 4 (§2.1.2)."""
    return M * L**2 + m * l**2
