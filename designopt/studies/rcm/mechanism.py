"""The planar 2-DOF RCM mechanism and the 3-DOF arm built on it (the planar RCM
mechanism paper, Sensors 2023; docs/rcm.md).

Planar mechanism (seed 003 §2.2-2.4, Fig. 3). Active prismatic joints d1, d2; with
u = d1 − a, v = d2, r = √(u² + v²) and θ = atan2(v, u) (eq. 1):
- A1 = (u, v), A2 = (d1 + b − a, d2) = R + (u, v), R = (b, 0) (eq. 2-3);
- the tool tip D = A2 − c·ω, ω = (cos θ, sin θ) (eq. 7), i.e. D = R + (1 − c/r)(u, v):
  the rod A2B2 always passes through R (the remote centre of motion);
- insertion depth d = c − r (eq. 25; D lies beyond R when d > 0);
- Jacobian ∂D/∂(d1, d2) (eq. 9) with E = c/r² (**not** the printed c/r; docs/rcm.md):
  J = I − (c/r) n nᵀ, n = (−sin θ, cos θ): eigenvalues 1 and 1 − c/r = −d/(c − d),
  det J = 1 − c/r (eq. 10): singular only at r = c, when D = R;
- 1/k = min(|c − r|, r)/max(|c − r|, r): isotropic at d = c/2, 0 at D = R, never NaN;
- IK (eq. 17-18) on the branch d > 0.

3-DOF arm (seed 003 §3, Table 3, standard DH): a base revolute θ1 about the vertical
axis through R, then θ2 and the insertion d of the planar mechanism, θ2 = atan2(a − d1, d2)
(eq. 26): tip P = (−d cθ1 cθ2, −d sθ1 cθ2, d sθ2 + L) (eq. 21/24); IK eq. (30)-(32).
All functions are pure and broadcast over leading axes; designs (a, b, c, L) are arrays.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics.kernel import dh_model

Array = jnp.ndarray

BUILT = {"a": 120.0, "b": 260.0, "c": 250.0}
"""The built design, mm (seed 003 Table 1)."""
JOINTS = {"theta1_deg": (-38.0, 38.0), "d1": (22.0, 215.0), "d2": (35.0, 200.0)}
"""The built arm's joint ranges (seed 003 Table 2)."""


def _uv(d1: Array, d2: Array, a: Array) -> tuple[Array, Array, Array]:
    u = d1 - a
    v = d2
    r = jnp.sqrt(u * u + v * v)
    return u, v, r


def fk(d1: Array, d2: Array, a: Array, b: Array, c: Array) -> Array:
    """Tool tip D (..., 2) of the planar mechanism, eq. (1)-(3), (7)."""
    u, v, r = _uv(d1, d2, a)
    safe = jnp.where(r > 0, r, 1.0)
    s = 1.0 - c / safe
    return jnp.stack([b + s * u, s * v], -1)


def rod_point(d1: Array, d2: Array, a: Array, b: Array, t: Array) -> Array:
    """A point of the output rod A2B2 at signed distance t from A2 along −ω (eq. 2):
    A2 − t·ω; the rod passes through R = (b, 0) at t = r."""
    u, v, r = _uv(d1, d2, a)
    safe = jnp.where(r > 0, r, 1.0)
    return jnp.stack([d1 + b - a - t * u / safe, d2 - t * v / safe], -1)


def depth(d1: Array, d2: Array, a: Array, c: Array) -> Array:
    """Insertion depth d = c − r (eq. 25): the tip's distance beyond R."""
    return c - _uv(d1, d2, a)[2]


def jacobian(d1: Array, d2: Array, a: Array, c: Array) -> Array:
    """∂D/∂(d1, d2) (..., 2, 2), eq. (9) with E = c/r² (corrected; docs/rcm.md)."""
    u, v, r = _uv(d1, d2, a)
    safe = jnp.where(r > 0, r, 1.0)
    E = c / (safe * safe)
    sin, cos = v / safe, u / safe
    return jnp.stack(
        [
            jnp.stack([1 - E * v * sin, E * u * sin], -1),
            jnp.stack([E * v * cos, 1 - E * u * cos], -1),
        ],
        -2,
    )


def inv_cond_r(r: Array, c: Array) -> Array:
    """1/k of J from r = |A1C| (eigenvalues 1 and 1 − c/r): min(|c−r|, r)/max(|c−r|, r);
    0 at the singularity r = c, never NaN (also 0 at r = 0, where θ is undefined)."""
    e = jnp.abs(c - r)
    hi = jnp.maximum(e, r)
    return jnp.where(hi > 0, jnp.minimum(e, r) / jnp.where(hi > 0, hi, 1.0), 0.0)


def inv_cond(d1: Array, d2: Array, a: Array, c: Array) -> Array:
    """1/k of the planar Jacobian at (d1, d2), in closed form."""
    return inv_cond_r(_uv(d1, d2, a)[2], c)


def det_j(r: Array, c: Array) -> Array:
    """det J = 1 − c/r (eq. 10); −inf-free: 0 is returned for r = 0."""
    return jnp.where(r > 0, 1.0 - c / jnp.where(r > 0, r, 1.0), 0.0)


def ik(x: Array, y: Array, a: Array, b: Array, c: Array) -> tuple[Array, Array]:
    """(d1, d2) placing the tip at D = (x, y), eq. (17)-(18), branch d > 0 (the tip
    beyond R). At D = R (ρ = 0) the rod direction is undefined: NaN-free, d1 = a, d2 = 0."""
    px = x - b
    rho = jnp.sqrt(px * px + y * y)
    safe = jnp.where(rho > 0, rho, 1.0)
    s = jnp.where(rho > 0, 1.0 - c / safe, 0.0)
    return a + s * px, s * y


# ----------------------------------------------------------------------------- 3-DOF arm


def arm_joints(d1: Array, d2: Array, a: Array, c: Array) -> tuple[Array, Array]:
    """(θ2, d) of the DH model from the prismatic joints, eq. (25)-(26)."""
    u, v, r = _uv(d1, d2, a)
    return jnp.arctan2(-u, v), c - r


def arm_fk(theta1: Array, d1: Array, d2: Array, a: Array, c: Array, L: Array) -> Array:
    """Tool tip P (..., 3) of the 3-DOF arm, eq. (24)/(27), θ1 in radians."""
    th2, d = arm_joints(d1, d2, a, c)
    c1, s1, c2, s2 = jnp.cos(theta1), jnp.sin(theta1), jnp.cos(th2), jnp.sin(th2)
    return jnp.stack([-d * c1 * c2, -d * s1 * c2, d * s2 + L], -1)


def arm_ik(p: Array, a: Array, c: Array, L: Array) -> tuple[Array, Array, Array]:
    """(θ1, d1, d2) placing the tip at P (..., 3), eq. (30)-(32); θ1 = atan2(−y, −x), the
    branch cos θ2 > 0 that eq. (30) picks for |θ1| < 90° (seed 003 §3.3). NaN-free at
    the RCM point (d = 0), where the direction is undefined."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    h = jnp.sqrt(x * x + y * y)
    d = jnp.sqrt(h * h + (z - L) ** 2)
    safe = jnp.where(d > 0, d, 1.0)
    t1 = jnp.arctan2(-y, -x)
    return t1, a - (c - d) * (z - L) / safe, (c - d) * h / safe


def arm_det(d1: Array, d2: Array, a: Array, c: Array) -> Array:
    """|det ∂P/∂(θ1, d1, d2)| = d²·|cos θ2|/r = d²·v/r² (spherical coordinates (d, θ2, θ1)
    around R, and ∂(r, θ2)/∂(u, v) = 1/r): the Cartesian volume element of the arm."""
    u, v, r = _uv(d1, d2, a)
    safe = jnp.where(r > 0, r, 1.0)
    d = c - r
    return jnp.where(r > 0, d * d * jnp.abs(v) / (safe * safe), 0.0)


def arm_dh():
    """The arm as a generic-kernel DH model (Table 3, standard DH, eq. 20); design column
    L, joint variables (θ1, θ2, d): rows (θ1, L, 0, −90°), (θ2 − 90°, 0, 0, 90°), (0, d, 0, 0)."""
    h = np.pi / 2
    return dh_model("standard", ["R", "R", "P"], alpha=[-h, h, 0.0], a=[0.0, 0.0, 0.0],
                    d=["L", 0.0, 0.0], theta=[0.0, -h, 0.0], variables=["L"])  # fmt: skip


def planar_jacobian_ad(d1: Array, d2: Array, a: Array, b: Array, c: Array) -> Array:
    """∂D/∂(d1, d2) by forward-mode autodiff of :func:`fk` (for the cross-check)."""
    f = lambda q: fk(q[0], q[1], a, b, c)  # noqa: E731
    return jax.jacfwd(f)(jnp.stack([d1, d2]))
