"""The 2-DOF spherical RCM mechanism (docs/sphere.md): forward kinematics, the Jacobian of
the tool direction, the closed-form inverse kinematics (both branches), the reachable band.

The remote centre is the origin. Joint axis 1 is the base z axis; joint 1 turns the first
link about it by θ1, joint 2 turns the second link about axis 2 by θ2; link angle α12 lies
between axes 1 and 2, α23 between axis 2 and the tool. As a standard-DH chain with a = d = 0:

    z2 = Rz(θ1) Rx(α12) e_z,        u = Rz(θ1) Rx(α12) Rz(θ2) Rx(α23) e_z   (the tool)

    u = Rz(θ1) (s2 s23,  −c12 c2 s23 − s12 c23,  −s12 c2 s23 + c12 c23)

so the angle φ between axis 1 and the tool satisfies cos φ = c12 c23 − s12 s23 cos θ2.
The tool direction moves as u̇ = θ̇1 (z1 × u) + θ̇2 (z2 × u): the 3×2 Jacobian
J = [z1 × u, z2 × u], both columns ⟂ u (the tool's angular velocity ⟂ the tool, turned by
90° in the tangent plane: the same singular values). Its Gram matrix depends on φ only:

    JᵀJ = [[sin²φ, c12 − c23 cos φ], [c12 − c23 cos φ, s23²]],   det = (s12 s23 sin θ2)²

(z1·z2 = c12, z2·u = c23, |z1 × u| = sin φ, and |det[z1, z2, u]| = s12 s23 |sin θ2|).

Every function is pure and broadcasts over leading axes; angles in radians, designs
(α12, α23) are arrays.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from designopt.kinematics.conditioning import inv_cond as _inv_cond

Array = jnp.ndarray


def _safe_sqrt(x: Array) -> Array:
    """√x with 0 (and a zero gradient) for x ≤ 0."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def _rz(t: Array, v: tuple[Array, Array, Array]) -> Array:
    c, s = jnp.cos(t), jnp.sin(t)
    return jnp.stack([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]], -1)


def link_direction(theta2: Array, a12: Array, a23: Array) -> tuple[Array, Array, Array]:
    """v = Rx(α12) Rz(θ2) Rx(α23) e_z: the tool before joint 1's turn (three components)."""
    c2, s2 = jnp.cos(theta2), jnp.sin(theta2)
    c12, s12, c23, s23 = jnp.cos(a12), jnp.sin(a12), jnp.cos(a23), jnp.sin(a23)
    return s2 * s23, -c12 * c2 * s23 - s12 * c23, -s12 * c2 * s23 + c12 * c23


def axes(theta1: Array, theta2: Array, a12: Array, a23: Array) -> tuple[Array, Array, Array]:
    """(z1, z2, u) (..., 3): joint axis 1 (the base z), joint axis 2 and the tool."""
    shape = jnp.broadcast_shapes(*(jnp.shape(x) for x in (theta1, theta2, a12, a23)))
    dt = jnp.result_type(theta1, theta2, a12, a23, float)
    zero, one = jnp.zeros(shape, dt), jnp.ones(shape, dt)
    z1 = jnp.stack([zero, zero, one], -1)
    s12, c12 = jnp.sin(a12), jnp.cos(a12)
    z2 = _rz(theta1, (zero, -s12 * one, c12 * one))
    u = _rz(theta1, link_direction(theta2, a12, a23))
    return z1, z2, u


def direction(theta1: Array, theta2: Array, a12: Array, a23: Array) -> Array:
    """The tool direction u (..., 3): the forward kinematics."""
    return axes(theta1, theta2, a12, a23)[2]


def jacobian(theta1: Array, theta2: Array, a12: Array, a23: Array) -> Array:
    """∂u/∂(θ1, θ2) (..., 3, 2) = [z1 × u, z2 × u] (the rate of the tool direction)."""
    z1, z2, u = axes(theta1, theta2, a12, a23)
    return jnp.stack([jnp.cross(z1, u), jnp.cross(z2, u)], -1)


def jacobian_ad(theta1: Array, theta2: Array, a12: Array, a23: Array) -> Array:
    """∂u/∂(θ1, θ2) (3, 2) of one configuration by forward-mode autodiff of
    :func:`direction` (the cross-check of :func:`jacobian`)."""
    f = lambda q: direction(q[0], q[1], a12, a23)  # noqa: E731
    return jax.jacfwd(f)(jnp.stack([jnp.asarray(theta1), jnp.asarray(theta2)]))


def inv_cond(J: Array) -> Array:
    """1/k = σmin/σmax of (..., 3, 2) Jacobians (the shared closed form on the entries:
    exactly 0 when singular, never NaN, with a finite gradient)."""
    return _inv_cond(J, "2")


def inv_cond_phi(cos_phi: Array, a12: Array, a23: Array) -> Array:
    """1/k in closed form from the Gram matrix above, a function of φ only (the
    reference for the IK → Jacobian path; 0 when singular)."""
    c12, c23, s23 = jnp.cos(a12), jnp.cos(a23), jnp.sin(a23)
    g11 = 1.0 - cos_phi * cos_phi
    g22 = s23 * s23 * jnp.ones_like(cos_phi)
    g12 = c12 - c23 * cos_phi
    half = 0.5 * (g11 + g22)
    det = g11 * g22 - g12 * g12
    lmax = half + _safe_sqrt(half * half - det)
    ratio = jnp.where(lmax > 0, det / jnp.where(lmax > 0, lmax * lmax, 1.0), 0.0)
    return _safe_sqrt(ratio)


def reach_band(a12: Array, a23: Array) -> tuple[Array, Array]:
    """(φmin, φmax): the tool reaches exactly the directions at angle φ ∈ [φmin, φmax]
    from axis 1, φmin = |α12 − α23|, φmax = min(α12 + α23, 2π − α12 − α23)."""
    tot = a12 + a23
    return jnp.abs(a12 - a23), jnp.minimum(tot, 2.0 * jnp.pi - tot)


def ik(u: Array, a12: Array, a23: Array) -> tuple[Array, Array, Array]:
    """The closed-form inverse kinematics of the tool direction u (..., 3) (unit):
    cos θ2 = (c12 c23 − u_z)/(s12 s23), both branches θ2 = ±acos; θ1 turns the branch's
    v (:func:`link_direction`) onto u about axis 1: θ1 = atan2(v × u, v · u) in the xy
    plane. Returns (θ1 (..., 2), θ2 (..., 2), reachable (...)): the last axis the branches
    (+, −). NaN-free: an unreachable u gets the nearest boundary's angles (flagged), and u
    on axis 1 (θ1 undefined) gets θ1 = 0."""
    a12, a23 = jnp.asarray(a12), jnp.asarray(a23)
    c12, s12, c23, s23 = jnp.cos(a12), jnp.sin(a12), jnp.cos(a23), jnp.sin(a23)
    c2 = (c12 * c23 - u[..., 2]) / (s12 * s23)
    ok = jnp.abs(c2) <= 1.0
    c2c = jnp.clip(c2, -1.0, 1.0)
    s2 = _safe_sqrt(1.0 - c2c * c2c)
    th2 = jnp.stack([jnp.arctan2(s2, c2c), jnp.arctan2(-s2, c2c)], -1)
    vx, vy, _ = link_direction(th2, a12[..., None], a23[..., None])
    ux, uy = u[..., 0][..., None], u[..., 1][..., None]
    y, x = vx * uy - vy * ux, vx * ux + vy * uy
    some = (x * x + y * y) > 0
    th1 = jnp.where(some, jnp.arctan2(jnp.where(some, y, 0.0), jnp.where(some, x, 1.0)), 0.0)
    return th1, th2, ok
