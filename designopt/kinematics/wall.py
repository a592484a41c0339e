"""The body wall a port lies on (``task.body_wall``, docs/planning.md): a half-space (the
patient below a plane) or an axis-aligned ellipsoid (an insufflated abdomen).

A port is *projected* onto the wall along the wall's normal: the port a design gives
(numbers or design variables) is replaced by the wall's closest point to it, so the
search may move a port's coordinates freely and every port it scores lies on the wall.
(The alternative, two surface coordinates per port, would make a port's entries mean
different things on different walls; a projection keeps them the world coordinates a
surgeon marks on the skin.) The wall's numbers are arrays (:func:`wall_params`): moving
the wall compiles nothing; only its kind shapes a program.

The ellipsoid's closest point solves the Lagrange condition
x_i = a_i² y_i / (a_i² + t), Σ (x_i / a_i)² = 1 (y = p − centre, a the semi-axes) for t by
bisection on the bracket t ∈ [−a_min² + a_min |y_min|, −a_min² + |a ∘ y|] (where the
left side, g(t) = Σ (a_i y_i / (a_i² + t))² − 1, decreases from ≥ 0 to ≤ 0), then one
Newton step that carries the implicit derivative dt/dp, so ``jax.grad`` of a port's
position is that of the exact projection.
"""

from __future__ import annotations

from functools import partial
from typing import Annotated, Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
from pydantic import Discriminator, Field, Tag, field_validator

from designopt.core.settings import Section
from designopt.kinematics import sdf
from designopt.kinematics.collision import HalfSpace, Length, MeshObstacle, Point

BISECTIONS = 80
"""Bisection steps of the ellipsoid projection (the bracket shrinks 2⁻⁸⁰: below a float64
ulp of t for any wall the size of a patient)."""


def _not_inside(cls: Any, v: bool) -> bool:
    if v:
        raise ValueError("a body wall places the ports and is not an obstacle; remove "
                         "inside (give the anatomy under collision.obstacles)")  # fmt: skip
    return v


class HalfSpaceWall(HalfSpace):
    """The patient is the side of the plane through ``point`` opposite ``normal``
    (``normal`` points out of the patient, e.g. up from a supine patient's belly): the
    keys of a half-space obstacle (``designopt.kinematics.collision.HalfSpace``)."""

    _flat = field_validator("inside")(classmethod(_not_inside))


class EllipsoidWall(Section):
    """The patient is inside the ellipsoid with centre ``center`` and semi-axes ``radii``
    along the world's x, y, z (an insufflated abdomen). Coordinates and radii are checked
    as an obstacle's are (finite, at most ``collision.MAX_LENGTH``; radii > 0)."""

    shape: Literal["ellipsoid"]
    center: Point
    radii: tuple[Length, Length, Length]


class MeshWall(MeshObstacle):
    """The patient is inside a closed mesh (e.g. the skin from a CT segmentation): the
    keys of a mesh obstacle (``file``, ``xyz``, ``rpy``, ``scale``, ``resolution``,
    ``padding``; ``designopt.kinematics.collision.MeshObstacle``). A port is projected
    onto the zero level of its interpolated signed distance (:data:`MESH_STEPS` steps
    p ← p − d(p) ∇d/|∇d|): on the wall to within the grid's error bound."""

    _flat = field_validator("inside")(classmethod(_not_inside))


def _wall_kind(v: Any) -> str:
    return str(v.get("shape") if isinstance(v, dict) else getattr(v, "shape", ""))


BodyWall = Annotated[
    Annotated[HalfSpaceWall, Tag("halfspace")]
    | Annotated[EllipsoidWall, Tag("ellipsoid")]
    | Annotated[MeshWall, Tag("mesh")],
    Discriminator(_wall_kind),
    Field(description="the body wall the ports lie on: {shape: halfspace | ellipsoid | mesh, ...}"),
]
WALL_SHAPES = ("halfspace", "ellipsoid", "mesh")
MESH_STEPS = 8
"""Projection steps onto a mesh wall's zero level (each exact for a plane; the grid's
SDF is 1-Lipschitz and piecewise trilinear, so a few steps land within its error)."""


def wall_params(
    wall: HalfSpaceWall | EllipsoidWall | MeshWall, dtype: Any = jnp.float64
) -> dict[str, jax.Array]:
    """The wall's numbers as arrays: ``c`` (3,) (the plane's point, the ellipsoid's
    centre) and ``v`` (3,) (the plane's unit normal, the ellipsoid's semi-axes); for a
    mesh, its grid and pose (``sdf.stack`` of one mesh)."""
    if isinstance(wall, MeshWall):
        R, t = wall.pose()
        return sdf.stack([wall.grid()], R[None], t[None], dtype)
    if isinstance(wall, HalfSpaceWall):
        c, v = np.asarray(wall.point, np.float64), np.asarray(wall.unit_normal(), np.float64)
    else:
        c, v = np.asarray(wall.center, np.float64), np.asarray(wall.radii, np.float64)
    return {"c": jnp.asarray(c, dtype), "v": jnp.asarray(v, dtype)}


@partial(jax.jit, static_argnames=("kind",))
def project(kind: str, params: dict[str, jax.Array], p: jax.Array) -> jax.Array:
    """The wall's closest point (..., 3) to each point ``p`` (..., 3) (``kind``: a
    :data:`WALL_SHAPES` name, static)."""
    if kind == "mesh":
        return _mesh_closest(params, p)
    c, v = params["c"].astype(p.dtype), params["v"].astype(p.dtype)
    if kind == "halfspace":
        return p - jnp.sum((p - c) * v, -1, keepdims=True) * v
    if kind == "ellipsoid":
        return c + _ellipsoid_closest(p - c, v)
    raise ValueError(f"unknown body wall {kind!r}; known: {list(WALL_SHAPES)}")


def _mesh_closest(params: dict[str, jax.Array], p: jax.Array) -> jax.Array:
    """Points p (..., 3) moved onto the zero level of a mesh wall's interpolated SDF."""
    g = {k: v[0] for k, v in params.items()}  # the one mesh of the stack

    def d(x):  # the SDF at one point
        return sdf.mesh_sdf(x, g["grid"], g["origin"], g["cell"], g["cells"], g["R"], g["t"])

    grad = jax.vmap(jax.value_and_grad(d))
    flat = p.reshape(-1, 3)

    def step(_, x):
        v, n = grad(x)
        norm = jnp.linalg.norm(n, axis=-1, keepdims=True)
        return x - v[:, None] * n / jnp.where(norm > 0, norm, 1.0)

    return jax.lax.fori_loop(0, MESH_STEPS, step, flat).reshape(p.shape)


def distance(kind: str, params: dict[str, jax.Array], p: jax.Array) -> jax.Array:
    """The distance (...,) of each point ``p`` (..., 3) from the wall's surface."""
    return jnp.linalg.norm(p - project(kind, params, p), axis=-1)


def _ellipsoid_closest(y: jax.Array, a: jax.Array) -> jax.Array:
    """The closest point (..., 3) of the ellipsoid Σ (x_i/a_i)² = 1 to ``y`` (..., 3)
    (the ellipsoid's own frame)."""
    a = jnp.broadcast_to(a, y.shape)
    a2 = a * a
    i = jnp.argmin(a, -1)[..., None]
    amin = jnp.take_along_axis(a, i, -1)[..., 0]
    ymin = jnp.abs(jnp.take_along_axis(y, i, -1)[..., 0])
    lo = -(amin**2) + amin * ymin
    hi = -(amin**2) + jnp.linalg.norm(a * y, axis=-1)
    tiny = jnp.finfo(y.dtype).tiny

    def g(t):  # Σ (a_i y_i / (a_i² + t))² − 1, decreasing on the bracket
        den = a2 + t[..., None]
        return jnp.sum((a * y / jnp.where(den > tiny, den, tiny)) ** 2, -1) - 1.0

    def step(_, b):
        lo, hi = b
        mid = 0.5 * (lo + hi)
        up = g(mid) > 0
        return jnp.where(up, mid, lo), jnp.where(up, hi, mid)

    lo, hi = jax.lax.fori_loop(0, BISECTIONS, step, (jax.lax.stop_gradient(lo),
                                                     jax.lax.stop_gradient(hi)))  # fmt: skip
    t = jax.lax.stop_gradient(0.5 * (lo + hi))
    # one Newton step: zero where t solves g, and its derivative is the implicit dt/dp
    den = a2 + t[..., None]
    den = jnp.where(den > tiny, den, tiny)
    dg = -2.0 * jnp.sum((a * y) ** 2 / den**3, -1)
    t = t - g(t) / jnp.where(dg < 0, dg, -1.0)
    den = a2 + t[..., None]
    return a2 * y / jnp.where(den > tiny, den, tiny)
