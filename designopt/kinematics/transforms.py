"""Homogeneous transforms. Every function broadcasts over leading dimensions.

All angles in rad, lengths in mm. Inputs may be Python floats or arrays of any shape;
the result has shape ``broadcast(inputs) + (4, 4)``.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax.typing import ArrayLike

Array = jnp.ndarray


def _assemble(rows: list[list[ArrayLike]]) -> Array:
    """Stack a 4x4 nested list of broadcastable scalars/arrays into (..., 4, 4)."""
    flat = [jnp.asarray(x) for r in rows for x in r]
    shape = jnp.broadcast_shapes(*[x.shape for x in flat])
    dtype = jnp.result_type(*flat)
    flat = [jnp.broadcast_to(x.astype(dtype), shape) for x in flat]
    return jnp.stack(flat, axis=-1).reshape(shape + (4, 4))


def rotx(t: ArrayLike) -> Array:
    """Rotation about x by angle t (rad)."""
    c, s = jnp.cos(t), jnp.sin(t)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    return _assemble([[o, z, z, z], [z, c, -s, z], [z, s, c, z], [z, z, z, o]])


def roty(t: ArrayLike) -> Array:
    """Rotation about y by angle t (rad)."""
    c, s = jnp.cos(t), jnp.sin(t)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    return _assemble([[c, z, s, z], [z, o, z, z], [-s, z, c, z], [z, z, z, o]])


def rotz(t: ArrayLike) -> Array:
    """Rotation about z by angle t (rad)."""
    c, s = jnp.cos(t), jnp.sin(t)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    return _assemble([[c, -s, z, z], [s, c, z, z], [z, z, o, z], [z, z, z, o]])


def trans(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> Array:
    """Pure translation by (x, y, z)."""
    x, y, z = jnp.asarray(x), jnp.asarray(y), jnp.asarray(z)
    zero = jnp.zeros_like(x + y + z)
    one = jnp.ones_like(zero)
    return _assemble(
        [[one, zero, zero, x], [zero, one, zero, y], [zero, zero, one, z], [zero, zero, zero, one]]
    )


def transx(t: ArrayLike) -> Array:
    return trans(t, 0.0, 0.0)


def transy(t: ArrayLike) -> Array:
    return trans(0.0, t, 0.0)


def transz(t: ArrayLike) -> Array:
    return trans(0.0, 0.0, t)


def dh_standard(theta: ArrayLike, d: ArrayLike, a: ArrayLike, alpha: ArrayLike) -> Array:
    """Standard (distal) DH link transform T = Rz(θ) Tz(d) Tx(a) Rx(α), closed form."""
    ct, st = jnp.cos(theta), jnp.sin(theta)
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    z = jnp.zeros_like(ct * ca)
    o = jnp.ones_like(z)
    return _assemble(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [z, sa + z, ca + z, d + z],
            [z, z, z, o],
        ]
    )


def dh_modified(alpha: ArrayLike, a: ArrayLike, theta: ArrayLike, d: ArrayLike) -> Array:
    """Modified (Craig) DH link transform T = Rx(α_{i-1}) Tx(a_{i-1}) Rz(θ_i) Tz(d_i).

    Closed form as printed in seed 000 eq. (1).
    """
    ct, st = jnp.cos(theta), jnp.sin(theta)
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    z = jnp.zeros_like(ct * ca)
    o = jnp.ones_like(z)
    return _assemble(
        [
            [ct, -st + z, z, a + z],
            [st * ca, ct * ca, -sa + z, -sa * d],
            [st * sa, ct * sa, ca + z, ca * d],
            [z, z, z, o],
        ]
    )
