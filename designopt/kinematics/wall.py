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

A mesh wall's closest point is exact too (:func:`mesh_closest`), for every point,
however far from the skin: the nearest of the mesh's triangles is found by comparing the
squared distance to every triangle (a loop over blocks of :data:`TRI_BLOCK` triangles,
values only), then the closest point of that one triangle is computed again, with its
derivative: p − ((p − V₀)·N) N where p projects inside the face (dq/dp = I − N Nᵀ), else
the nearest point of its nearest edge (dq/dp = E Eᵀ/|E|² inside the edge, 0 at a
corner). Its error is rounding only: |q − q_exact| ≤ :data:`MESH_BOUND` × the mesh's
size in float64 (tests/test_wall_projection.py checks 200 designs of the planning box
against trimesh's exact closest point). Where two triangles are equally near (a point on
the wall's medial axis) the projection jumps from one to the other, as the exact
projection does. The cost is one pass over the triangles per port, (ports × triangles)
distance tests: a segmentation's skin of some 10⁵ triangles is best decimated first.
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

    shape: Literal["ellipsoid"] = Field(
        description="`ellipsoid`: the patient is inside an ellipsoid (an insufflated abdomen).",
    )
    center: Point = Field(description="The ellipsoid's centre [x, y, z] (length unit).")
    radii: tuple[Length, Length, Length] = Field(
        description="Semi-axes along the world's x, y, z (length unit), each > 0.",
    )


class MeshWall(MeshObstacle):
    """The patient is inside a closed mesh (e.g. the skin from a CT segmentation): the
    keys of a mesh obstacle (``file``, ``xyz``, ``rpy``, ``scale``, ``resolution``,
    ``padding``; ``designopt.kinematics.collision.MeshObstacle``). A port is projected
    onto the mesh's exact closest point (:func:`mesh_closest`: within :data:`MESH_BOUND`
    of the mesh's size, from any point); the grid (``resolution``, ``padding``) is not
    used by the projection."""

    def triangles(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(triangles (T, 3, 3) in the mesh's frame after its scale, R (3, 3), t (3,)),
        float64: x_world = R x_mesh + t."""
        v, f = sdf.load_mesh(self.file)
        R, t = self.pose()
        return np.asarray(v, np.float64)[f] * float(self.scale), R, t

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
TRI_BLOCK = 256
"""Triangles compared at once per step of a mesh wall's nearest-triangle search (fewer
when many points are projected together: the block holds at most :data:`PAIRS` pairs)."""
PAIRS = 1 << 20
"""Point–triangle pairs held at once by the nearest-triangle search (about 80 MB)."""
MESH_BOUND = 1e-12
"""A mesh wall's projection is its exact closest point to within this share of the
mesh's size (its bounding box's diagonal) in float64: rounding only."""


def wall_params(
    wall: HalfSpaceWall | EllipsoidWall | MeshWall, dtype: Any = jnp.float64
) -> dict[str, jax.Array]:
    """The wall's numbers as arrays: ``c`` (3,) (the plane's point, the ellipsoid's
    centre) and ``v`` (3,) (the plane's unit normal, the ellipsoid's semi-axes); for a
    mesh, ``tri`` (T, 3, 3) its triangles in its own frame (after the scale), ``R``
    (3, 3) and ``t`` (3,) its pose (x_world = R x_mesh + t). The triangle count shapes
    the compiled program; the pose and the vertices do not."""
    if isinstance(wall, MeshWall):
        tri, R, t = wall.triangles()
        return {"tri": jnp.asarray(tri, dtype), "R": jnp.asarray(R, dtype),
                "t": jnp.asarray(t, dtype)}  # fmt: skip
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
        return mesh_closest(params, p)
    c, v = params["c"].astype(p.dtype), params["v"].astype(p.dtype)
    if kind == "halfspace":
        return p - jnp.sum((p - c) * v, -1, keepdims=True) * v
    if kind == "ellipsoid":
        return c + _ellipsoid_closest(p - c, v)
    raise ValueError(f"unknown body wall {kind!r}; known: {list(WALL_SHAPES)}")


def mesh_closest(params: dict[str, jax.Array], p: jax.Array) -> jax.Array:
    """The exact closest point (..., 3) of a mesh wall (``wall_params``' ``tri``, ``R``,
    ``t``) to each world point p (..., 3) (module docstring): differentiable in p and the
    pose, exact to rounding."""
    tri = params["tri"].astype(p.dtype)
    R, t = params["R"].astype(p.dtype), params["t"].astype(p.dtype)
    x = (p.reshape(-1, 3) - t) @ R  # Rᵀ (p − t): the mesh's frame
    k = _nearest_triangle(tri, jax.lax.stop_gradient(x))
    q = _triangle_closest(x, tri[k])
    return (q @ R.T + t).reshape(p.shape)


def _nearest_triangle(tri: jax.Array, x: jax.Array) -> jax.Array:
    """The index (P,) of the triangle of ``tri`` (T, 3, 3) nearest each point x (P, 3)
    (values only): every triangle compared, in blocks (:data:`TRI_BLOCK`, :data:`PAIRS`);
    the first of equally near ones."""
    T, P = tri.shape[0], x.shape[0]
    B = int(max(1, min(T, TRI_BLOCK, PAIRS // max(P, 1))))
    n = -(-T // B)
    pad = jnp.concatenate([tri, jnp.broadcast_to(tri[-1:], (n * B - T, 3, 3))])
    blocks = pad.reshape(n, B, 3, 3)

    def body(i, carry):
        best, kbest = carry
        d2 = _triangle_d2(x, blocks[i])  # (P, B)
        j = jnp.argmin(d2, axis=1)
        v = jnp.take_along_axis(d2, j[:, None], 1)[:, 0]
        better = v < best
        return jnp.where(better, v, best), jnp.where(better, (i * B + j).astype(jnp.int32), kbest)

    init = (jnp.full((P,), jnp.inf, x.dtype), jnp.zeros((P,), jnp.int32))
    _, k = jax.lax.fori_loop(0, n, body, init)
    return jnp.minimum(k, T - 1)


def _parts(x: jax.Array, V: jax.Array):
    """Per point–triangle pair (x (..., 3), V (..., 3, 3) broadcast): w = x − Vᵢ, the edges
    Eᵢ = Vᵢ₊₁ − Vᵢ, |Eᵢ|², the unit normal N (0 for a degenerate triangle), whether x
    projects inside the face, and each edge's nearest-point parameter sᵢ ∈ [0, 1]."""
    E = jnp.roll(V, -1, axis=-2) - V
    EE = jnp.sum(E * E, -1)
    n = jnp.cross(E[..., 0, :], -E[..., 2, :])
    nn = jnp.sum(n * n, -1)
    tiny = jnp.finfo(x.dtype).tiny
    ok = nn > jnp.sqrt(tiny)
    N = n / jnp.sqrt(jnp.where(ok, nn, 1.0))[..., None]
    N = jnp.where(ok[..., None], N, 0.0)
    w = x[..., None, :] - V
    M = jnp.cross(N[..., None, :], E)  # in-plane inward edge normals
    inside = ok & jnp.all(jnp.sum(w * M, -1) >= 0.0, -1)
    s = jnp.clip(jnp.sum(w * E, -1) / jnp.where(EE > tiny, EE, 1.0), 0.0, 1.0)
    return w, E, N, inside, s


def _triangle_d2(x: jax.Array, V: jax.Array) -> jax.Array:
    """Squared distances (P, B) of points x (P, 3) to triangles V (B, 3, 3)."""
    w, E, N, inside, s = _parts(x[:, None, :], V[None])
    r = w - s[..., None] * E
    edge = jnp.min(jnp.sum(r * r, -1), -1)
    sn = jnp.sum(w[..., 0, :] * N, -1)
    return jnp.where(inside, sn * sn, edge)


def _triangle_closest(x: jax.Array, V: jax.Array) -> jax.Array:
    """The closest point (P, 3) of triangle V (P, 3, 3) to x (P, 3), differentiable: the
    projection onto the face where x projects inside it, else the nearest point of the
    nearest edge (which edge: chosen on values)."""
    w, E, N, inside, s = _parts(x, V)
    face = x - jnp.sum(w[..., 0, :] * N, -1)[..., None] * N
    on = V + s[..., None] * E  # each edge's nearest point (P, 3, 3)
    r = jax.lax.stop_gradient(x[..., None, :] - on)
    i = jnp.argmin(jnp.sum(r * r, -1), -1)
    edge = jnp.take_along_axis(on, i[..., None, None], -2)[..., 0, :]
    return jnp.where(inside[..., None], face, edge)


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
