"""Collision geometry: batched, differentiable signed distances between the capsules of an
arm's links, the world's obstacles (balls, capsules, axis-aligned boxes, half-spaces,
closed meshes) and the links of another arm, and the ``study.collision`` config section
that describes them.

Conventions
-----------
* Every distance is *signed* and measured between the surfaces: positive when the shapes
  are apart (the gap), zero when they touch, negative when they overlap. A capsule is the
  set of points within ``r`` of its centre segment ``a0``–``a1`` (a ball is a capsule of
  zero length); its distance to another shape is the distance of its centre segment less
  ``r``. An overlap's magnitude is therefore the radii less the centre-line distance
  (capsule–capsule, capsule–ball), or ``r`` plus how deep the centre line reaches into a
  box or beyond a half-space's plane.
* Lengths are in the chain's length unit; obstacles are given in the chain's base frame.
* Every function is pure jnp: it broadcasts over arbitrary leading batch dimensions (e.g.
  designs × targets), computes in the inputs' floating dtype (float32 or float64), traces
  under ``jit``/``vmap`` and has NaN-free values and gradients, also for parallel and
  zero-length segments (divisions are guarded with the double-``where`` pattern). Where a
  distance is not differentiable (touching centre lines, ties between closest points)
  the gradient is a finite one-sided or averaged one; where two centre lines meet, its
  norm part is zero.
* Capsule–box: the box's exact signed distance function (SDF) is convex and 1-Lipschitz,
  so its restriction to the segment, s ↦ SDF(a0 + s (a1 − a0)) on [0, 1], is convex with
  Lipschitz constant |a1 − a0|. Its minimum is found by golden-section search in a
  ``lax.fori_loop`` (a loop, not unrolled): after n iterations a minimiser lies in a
  bracket of width φ⁻ⁿ (φ the golden ratio), and the result is the least of the SDF at the
  bracket's middle and at the two ends (so a minimum at an end is exact). It exceeds the
  exact minimum by at most |a1 − a0|·φ⁻ⁿ/2: n = 45 in float64 (≤ 2.0e-10·|a1 − a0|) and
  n = 35 in float32 (≤ 2.4e-8·|a1 − a0|, below float32's resolution). The search runs on
  values only; the gradient is the SDF's partial gradient at the minimiser found (the
  envelope theorem), so no derivative goes through the loop.
* Capsule–mesh: the mesh's SDF is sampled once on a grid on the host and interpolated
  trilinearly; the capsule's distance is the least over samples of its centre line
  (:mod:`designopt.kinematics.sdf`, which states and tests the error bound).

:func:`clearance` combines these into one number per sample: the least signed distance
of an arm's link capsules to every obstacle and between its non-adjacent links, less the
config's ``margin`` (so a negative clearance is a collision by the config's rule).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike
from pydantic import (
    AfterValidator,
    ConfigDict,
    Discriminator,
    Field,
    StrictBool,
    Tag,
    TypeAdapter,
    ValidationInfo,
    field_validator,
    model_validator,
)

from designopt.core.settings import Section
from designopt.kinematics import sdf

MAX_LENGTH = 1e6
"""The largest magnitude of a coordinate, radius, size or margin of the collision section
(in the chain's unit: a million metres, or millimetres, is no operating room)."""

GOLDEN_ITERATIONS = {"float64": 45, "float32": 35}
"""Golden-section iterations of :func:`capsule_box` per dtype (error ≤ |a1 − a0|·φ⁻ⁿ/2)."""

_INVPHI = (math.sqrt(5.0) - 1.0) / 2.0  # 1/φ ≈ 0.618: the bracket shrinks by this per step

ObstacleParams = dict[str, dict[str, Array]]


# --------------------------------------------------------------------------- config


def _finite(v: float) -> float:
    if math.isnan(v):
        raise ValueError("nan is not a finite number")
    if math.isinf(v):
        raise ValueError(f"{v} is not a finite number")
    if abs(v) > MAX_LENGTH:
        raise ValueError(f"{v:g} is too large (|x| must be ≤ {MAX_LENGTH:g} in the chain's unit)")
    return v


def _positive(v: float) -> float:
    _finite(v)
    if not v > 0:
        raise ValueError(f"must be > 0, got {v:g}")
    return v


Coord = Annotated[float, AfterValidator(_finite)]
"""A finite real of magnitude ≤ :data:`MAX_LENGTH`."""
Length = Annotated[float, AfterValidator(_positive)]
"""A finite real in (0, :data:`MAX_LENGTH`]."""
Point = tuple[Coord, Coord, Coord]


class _Obstacle(Section):
    """What every obstacle has: ``inside`` marks anatomy inside the patient, checked
    against the instrument past its port instead of the arm outside (docs/planning.md)."""

    inside: StrictBool = Field(
        False,
        description="true: anatomy inside the patient, checked against the instrument past its "
        "port (radius `tool_radius`) instead of the arm outside; a body wall refuses "
        "it.",
    )


class BallObstacle(_Obstacle):
    """A solid ball."""

    shape: Literal["ball"] = Field(description="`ball`: a solid ball.")
    center: Point = Field(
        description="The ball's centre [x, y, z] in the base frame (length unit).",
    )
    radius: Length = Field(description="The ball's radius (length unit).")


class CapsuleObstacle(_Obstacle):
    """A solid capsule: the points within ``radius`` of the segment ``a``–``b`` (e.g. a
    bar, another instrument, an assistant's arm); ``a == b`` makes it a ball."""

    shape: Literal["capsule"] = Field(
        description="`capsule`: the points within `radius` of the segment a–b.",
    )
    a: Point = Field(description="One end [x, y, z] of the capsule's segment (length unit).")
    b: Point = Field(
        description="The other end [x, y, z] of the segment (length unit); equal to `a`: a ball.",
    )
    radius: Length = Field(description="The capsule's radius (length unit).")


class BoxObstacle(_Obstacle):
    """A solid axis-aligned box of edge lengths ``size`` (each > 0) about ``center``."""

    shape: Literal["box"] = Field(description="`box`: a solid axis-aligned box.")
    center: Point = Field(description="The box's centre [x, y, z] (length unit).")
    size: tuple[Length, Length, Length] = Field(
        description="Edge lengths [sx, sy, sz] (length unit), each > 0.",
    )


class HalfSpace(_Obstacle):
    """The solid side of a plane: the points x with (x − point)·normal < 0, i.e. the
    normal points out of the solid (e.g. up from a table, or out of the patient at the
    skin). ``normal`` need not be a unit vector but must not be zero."""

    shape: Literal["halfspace"] = Field(description="`halfspace`: the solid side of a plane.")
    point: Point = Field(description="A point [x, y, z] on the plane (length unit).")
    normal: Point = Field(
        description="The plane's normal, pointing out of the solid (non-zero; need not be a unit "
        "vector).",
    )

    @field_validator("normal")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if not math.hypot(*v) > 0:
            raise ValueError(f"normal must be a non-zero vector, got {list(v)}")
        return v

    def unit_normal(self) -> tuple[float, float, float]:
        """The normal scaled to length 1 (in float64, before any cast)."""
        n = math.hypot(*self.normal)
        return (self.normal[0] / n, self.normal[1] / n, self.normal[2] / n)


class MeshObstacle(_Obstacle):
    """A solid bounded by a closed triangle mesh (e.g. an organ from a CT segmentation):
    ``file`` (STL, OBJ, PLY, … whatever trimesh reads; a relative path is read from the
    config file's folder) scaled by ``scale`` about the file's origin, then turned by
    ``rpy`` (degrees, R = Rz(yaw)·Ry(pitch)·Rx(roll)) and moved by ``xyz``:
    x = R·(scale·x_file) + xyz. Its signed distance is sampled on a grid of
    ``resolution``³ points (32 to 128) over its bounding box grown by ``padding`` on every
    side (default 4 cells), computed once (:mod:`designopt.kinematics.sdf`). A mesh that
    cannot be read or is not watertight is refused."""

    shape: Literal["mesh"] = Field(description="`mesh`: a solid bounded by a closed triangle mesh.")
    file: str = Field(
        description="The mesh file (STL, OBJ, PLY, ... whatever trimesh reads), read from the "
        "config file's folder when relative; it must be watertight.",
    )
    xyz: Point = Field(
        (0.0, 0.0, 0.0),
        description="Translation [x, y, z] of the mesh after its scale and turn (length unit).",
    )
    rpy: Point = Field(
        (0.0, 0.0, 0.0),
        description="Roll, pitch, yaw (deg) turning the mesh: R = Rz(yaw)·Ry(pitch)·Rx(roll).",
    )
    scale: Length = Field(
        1.0,
        description="Scale applied to the file's coordinates about its origin, e.g. 0.001 for a "
        "mesh in mm under a chain in m.",
    )
    resolution: int = Field(
        sdf.DEFAULT_RESOLUTION,
        description="Grid points per axis (32 to 128) of the signed-distance grid sampled once "
        "over the mesh's bounding box.",
    )
    padding: Length | None = Field(
        None,
        description="How far the distance grid extends past the mesh's bounding box on every side "
        "(length unit; default 4 cells).",
    )

    @field_validator("file")
    @classmethod
    def _read(cls, v: str, info: ValidationInfo) -> str:
        ctx = info.context if isinstance(info.context, dict) else {}
        p = Path(v).expanduser()
        if not p.is_absolute():
            folder = ctx.get("config_dir")
            p = (Path(folder) if folder is not None else Path.cwd()) / p
        if not p.exists():
            raise ValueError(f"{p}: no such mesh file (a relative path is read from the "
                             "config file's folder)")  # fmt: skip
        sdf.load_mesh(p)  # ValueError naming the file: unreadable, not watertight
        return str(p.resolve())

    @field_validator("resolution", mode="before")
    @classmethod
    def _resolution(cls, v: Any) -> Any:
        lo, hi = sdf.MIN_RESOLUTION, sdf.MAX_RESOLUTION
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise ValueError(f"must be an integer from {lo} to {hi} (grid points per axis), "
                             f"got {v!r}")  # fmt: skip
        return v

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(R (3, 3), t (3,)): x_world = R x_mesh + t (x_mesh after the scale), float64."""
        from designopt.kinematics.urdf import rpy_matrix

        r, p, y = (math.radians(a) for a in self.rpy)
        return rpy_matrix(r, p, y), np.asarray(self.xyz, np.float64)

    def grid(self) -> sdf.MeshGrid:
        """The mesh's SDF grid in its own frame (built once per file version and settings)."""
        return sdf.mesh_grid(self.file, self.scale, self.resolution, self.padding)


OBSTACLE_SHAPES = ("ball", "capsule", "box", "halfspace", "mesh")


def _obstacle_kind(v: Any) -> str:
    if isinstance(v, dict):
        return str(v.get("shape", ""))
    return str(getattr(v, "shape", ""))


Obstacle = Annotated[
    Union[  # noqa: UP007
        Annotated[BallObstacle, Tag("ball")], Annotated[CapsuleObstacle, Tag("capsule")],
        Annotated[BoxObstacle, Tag("box")], Annotated[HalfSpace, Tag("halfspace")],
        Annotated[MeshObstacle, Tag("mesh")],
    ],
    Discriminator(_obstacle_kind, custom_error_type="obstacle",
                  custom_error_message="unknown obstacle shape: give shape ball, capsule, "
                                       "box or halfspace, or mesh (with a file)"),
]  # fmt: skip
_OBSTACLE: TypeAdapter[Any] = TypeAdapter(Obstacle)


class Collision(Section):
    """The ``study.collision`` section: the arm's links as capsules and what they must
    not touch.

    - ``links``: ``auto`` makes link i the capsule from joint i's origin to joint i + 1's
      (the tool tip for the last link); ``urdf`` takes the links from the URDF chain.
    - ``radius``: one capsule radius for every link, or a list with one per link (its
      length is checked against the chain by the study: :meth:`link_radii`).
    - ``self``: also check the arm's non-adjacent link pairs against each other.
    - ``obstacles``: world geometry in the base frame (ball, capsule, box, halfspace,
      mesh).
    - ``margin``: a clearance below this (≥ 0) counts as a collision.
    - ``tool_radius``: the instrument's radius past the port, against the obstacles
      marked ``inside`` (default: the last capsule's radius).
    """

    model_config = ConfigDict(populate_by_name=True)  # `self` in YAML, `self_` in Python

    links: Literal["auto", "urdf"] = Field(
        "auto",
        description="`auto`: link i is the capsule from joint i's origin to joint i + 1's (the "
        "tool tip for the last); `urdf`: the links from the URDF chain.",
    )
    radius: float | list[float] | None = Field(
        None,
        description="Capsule radius of every link (length unit), or a list with one per link.",
    )
    self_: StrictBool = Field(
        True,
        alias="self",
        description="Also check the arm's non-adjacent link pairs against each other.",
    )
    obstacles: list[Obstacle] = Field(
        [],
        description="World geometry in the base frame the links must not touch: each `{shape: ball "
        "| capsule | box | halfspace | mesh, ...}`.",
    )
    margin: Annotated[float, AfterValidator(_finite)] = Field(
        0.0,
        description="A clearance below this (length unit, ≥ 0) counts as a collision.",
    )
    tool_radius: Length | None = Field(
        None,
        description="The instrument's radius past the port (length unit), checked against the "
        "obstacles marked `inside` (default: the last capsule's radius).",
    )

    @field_validator("radius", mode="before")
    @classmethod
    def _radii(cls, v: Any) -> Any:
        # checked here, before the union, for one error naming the bad radius (the union
        # would report a failure per member)
        if v is None:
            return v
        many = isinstance(v, list | tuple)
        if many and not v:
            raise ValueError("needs at least one radius (or one number for every link)")
        for i, x in enumerate(v if many else [v]):
            at = f"radius[{i}]: " if many else ""
            try:
                if isinstance(x, bool) or not isinstance(x, int | float | str):
                    raise TypeError
                r = float(x)
            except (TypeError, ValueError, OverflowError):
                raise ValueError(f"{at}{x!r} is not a number") from None
            try:
                _positive(r)
            except ValueError as e:
                raise ValueError(f"{at}{e}") from None
        return v

    @model_validator(mode="after")
    def _radius_rule(self) -> Collision:
        # (links: auto without a radius: the study refuses it unless each arm gives its own)
        if self.links == "urdf" and self.radius is not None:
            raise ValueError("radius: under links: urdf the URDF's <collision> shapes give "
                             "the radii; remove radius (margin adds a safety distance)")  # fmt: skip
        return self

    @field_validator("margin")
    @classmethod
    def _margin(cls, v: float) -> float:
        if v < 0:
            raise ValueError(f"must be ≥ 0, got {v:g}")
        return v

    def link_radii(self, n_links: int) -> tuple[float, ...]:
        """One radius per link of a chain of ``n_links`` links; ValueError when a list of
        radii has another length."""
        if isinstance(self.radius, list):
            if len(self.radius) != n_links:
                raise ValueError(f"collision.radius: the list has {len(self.radius)} radii "
                                 f"but the chain has {n_links} links")  # fmt: skip
            return tuple(self.radius)
        assert self.radius is not None, "links: urdf takes the URDF's radii"
        return (float(self.radius),) * n_links

    def params(self, dtype=jnp.float64) -> ObstacleParams:
        """The obstacles as arrays: :func:`obstacle_params`."""
        return obstacle_params(self.obstacles, dtype)


def prefetch_grids(obstacles: Sequence[Any]) -> None:
    """Start building the SDF grids of the mesh obstacles among ``obstacles`` in a
    thread of their own, so that they are ready (or on their way) when
    :func:`obstacle_params` asks for them: a set-up's checks meanwhile trace and compile
    programs, which leave the GIL free. ``sdf.mesh_grid`` builds a grid once: a caller
    that asks for one under construction waits for it. Errors are left to that caller.
    Nothing starts on one core (``concurrency.threads``)."""
    import contextlib
    import threading

    from designopt.core import concurrency

    meshes = [o for o in obstacles if _obstacle_kind(o) == "mesh" and hasattr(o, "grid")]
    if not meshes or concurrency.threads() <= 1:
        return

    def build() -> None:
        for o in meshes:
            with contextlib.suppress(Exception):
                o.grid()

    th = threading.Thread(target=build, name="designopt-grids", daemon=True)
    _PREFETCHING.append(th)
    th.start()


def prefetch_done() -> None:
    """Wait until the grids :func:`prefetch_grids` started are built (e.g. a test,
    before it swaps ``sdf``'s grid cache)."""
    while _PREFETCHING:
        _PREFETCHING.pop().join()


_PREFETCHING: list[Any] = []  # the threads prefetch_grids started, not yet waited for


def obstacle_params(obstacles: Sequence[Any], dtype=jnp.float64) -> ObstacleParams:
    """Obstacle models (or their dicts, validated here) as a pytree of arrays grouped by shape, so that one compiled
    program serves any obstacle values (the counts are its shapes):

    - ``ball``: ``c`` (nb, 3) centres, ``r`` (nb,) radii;
    - ``capsule``: ``a``, ``b`` (nc, 3) segment ends, ``r`` (nc,) radii;
    - ``box``: ``c`` (nx, 3) centres, ``half`` (nx, 3) half sizes;
    - ``halfspace``: ``p`` (nh, 3) plane points, ``n`` (nh, 3) unit outward normals;
    - ``mesh``: ``grid`` (nm, G, G, G) the SDF grids (G the largest resolution),
      ``origin``, ``cell`` (nm, 3), ``cells`` (nm,), ``R`` (nm, 3, 3), ``t`` (nm, 3)
      (:func:`sdf.stack`; the grids are built on the host, once per file and settings).

    Every group is present; a shape without obstacles has zero-length arrays (the mesh
    group's grid (0, 64, 64, 64))."""
    groups: dict[str, list[Any]] = {k: [] for k in OBSTACLE_SHAPES}
    for o in obstacles:
        if isinstance(o, dict):
            o = _OBSTACLE.validate_python(o)
        kind = _obstacle_kind(o)
        if kind not in groups:
            raise TypeError(f"unknown obstacle {o!r}")
        groups[kind].append(o)

    def arr(rows: list, width: int | None) -> Array:
        shape = (len(rows), width) if width else (len(rows),)
        return jnp.asarray(np.asarray(rows, np.float64).reshape(shape), dtype)

    b, c, x, h, m = (groups[k] for k in OBSTACLE_SHAPES)
    poses = [o.pose() for o in m]
    meshes = sdf.stack([o.grid() for o in m], [R for R, _ in poses], [t for _, t in poses], dtype)
    return {
        "ball": {"c": arr([o.center for o in b], 3), "r": arr([o.radius for o in b], None)},
        "capsule": {
            "a": arr([o.a for o in c], 3),
            "b": arr([o.b for o in c], 3),
            "r": arr([o.radius for o in c], None),
        },
        "box": {
            "c": arr([o.center for o in x], 3),
            "half": arr([[s / 2 for s in o.size] for o in x], 3),
        },
        "halfspace": {"p": arr([o.point for o in h], 3), "n": arr([o.unit_normal() for o in h], 3)},
        "mesh": meshes,
    }


# --------------------------------------------------------------------------- distances


def _floats(*xs: ArrayLike) -> list[Array]:
    arrs = [jnp.asarray(x) for x in xs]  # Python scalars stay weakly typed
    dt = jnp.result_type(*arrs, float)
    return [a.astype(dt) for a in arrs]


def _dot(u: Array, v: Array) -> Array:
    return jnp.sum(u * v, axis=-1)


def _tiny(dtype) -> float:
    """A positive floor for squared lengths: below it a segment counts as a point. Its
    square root bounds every quotient by a finite number, in values and gradients."""
    return float(np.sqrt(np.finfo(dtype).tiny))


def _safe_sqrt(x: Array) -> Array:
    """√x for x ≥ 0, with a zero (not infinite) derivative at 0."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def _point_segment_sq(p: Array, a: Array, d: Array) -> Array:
    """Squared distance from points p to the segments a + t d, t ∈ [0, 1]."""
    dd = _dot(d, d)
    ok = dd > _tiny(dd.dtype)
    t = jnp.where(ok, _dot(p - a, d) / jnp.where(ok, dd, 1.0), 0.0)
    t = jnp.clip(t, 0.0, 1.0)
    w = p - a - t[..., None] * d
    return _dot(w, w)


def segment_segment(a0: ArrayLike, a1: ArrayLike, b0: ArrayLike, b1: ArrayLike) -> Array:
    """The least distance (≥ 0) between the segments a0–a1 and b0–b1, (..., 3) each
    (broadcast), as (...,).

    The minimum of |P(s) − Q(t)| over [0, 1]² lies either inside (where the common
    normal of the two lines meets both segments) or on an edge of the square, where it is
    the distance of an end to the other segment. The result is the least of the four
    end–segment distances and the distance at the lines' closest points clipped to the
    segments (always a pair of points on the segments, so never below the true minimum,
    and the minimum itself when it is inside). Parallel or zero-length segments skip the
    inside candidate (their minimum is at an end)."""
    a0, a1, b0, b1 = _floats(a0, a1, b0, b1)
    d1, d2 = a1 - a0, b1 - b0
    dt = d1.dtype
    # the four end–segment distances in one stacked call: ends of a vs b, ends of b vs a
    ends = _point_segment_sq(jnp.stack(jnp.broadcast_arrays(a0, a1, b0, b1), -2),
                             jnp.stack(jnp.broadcast_arrays(b0, b0, a0, a0), -2),
                             jnp.stack(jnp.broadcast_arrays(d2, d2, d1, d1), -2))  # fmt: skip
    n = jnp.cross(d1, d2)
    nn = _dot(n, n)  # |d1|²|d2|² sin²θ, without the cancellation of aa·bb − ab²
    eps = float(np.finfo(dt).eps)
    ok = nn > jnp.maximum(eps * eps * _dot(d1, d1) * _dot(d2, d2), _tiny(dt))
    den = jnp.where(ok, nn, 1.0)
    r = b0 - a0
    s = jnp.clip(jnp.where(ok, _dot(jnp.cross(r, d2), n) / den, 0.0), 0.0, 1.0)
    t = jnp.clip(jnp.where(ok, _dot(jnp.cross(r, d1), n) / den, 0.0), 0.0, 1.0)
    w = a0 + s[..., None] * d1 - b0 - t[..., None] * d2
    inside = _dot(w, w)
    return _safe_sqrt(jnp.minimum(jnp.min(ends, -1), inside))


def capsule_capsule(
    a0: ArrayLike, a1: ArrayLike, ra: ArrayLike, b0: ArrayLike, b1: ArrayLike, rb: ArrayLike
) -> Array:
    """Signed distance between the capsules (a0–a1, ra) and (b0–b1, rb): the centre
    segments' distance less both radii. Points (..., 3), radii (...), broadcast."""
    a0, a1, ra, b0, b1, rb = _floats(a0, a1, ra, b0, b1, rb)
    return segment_segment(a0, a1, b0, b1) - ra - rb


def capsule_ball(a0: ArrayLike, a1: ArrayLike, r: ArrayLike, c: ArrayLike, rc: ArrayLike) -> Array:
    """Signed distance between the capsule (a0–a1, r) and the ball (c, rc)."""
    a0, a1, r, c, rc = _floats(a0, a1, r, c, rc)
    return _safe_sqrt(_point_segment_sq(c, a0, a1 - a0)) - r - rc


def capsule_halfspace(
    a0: ArrayLike, a1: ArrayLike, r: ArrayLike, point: ArrayLike, normal: ArrayLike
) -> Array:
    """Signed distance between the capsule (a0–a1, r) and the solid half-space
    {x : (x − point)·normal < 0}; ``normal`` must be a unit vector. Exact: the plane's
    signed distance is linear along the segment, so its least value is at an end."""
    a0, a1, r, point, normal = _floats(a0, a1, r, point, normal)
    return jnp.minimum(_dot(a0 - point, normal), _dot(a1 - point, normal)) - r


def box_sdf(p: ArrayLike, center: ArrayLike, half: ArrayLike) -> Array:
    """The exact signed distance (...,) from points p (..., 3) to the solid axis-aligned
    box of half sizes ``half`` about ``center``: the Euclidean distance outside, minus the
    distance to the nearest face inside."""
    p, center, half = _floats(p, center, half)
    return _box_sdf(p - center, half)


def _box_sdf(p: Array, half: Array) -> Array:
    q = jnp.abs(p) - half
    out = jnp.maximum(q, 0.0)
    return _safe_sqrt(_dot(out, out)) + jnp.minimum(jnp.max(q, axis=-1), 0.0)


def capsule_box(
    a0: ArrayLike, a1: ArrayLike, r: ArrayLike, center: ArrayLike, half: ArrayLike
) -> Array:
    """Signed distance between the capsule (a0–a1, r) and the solid axis-aligned box of
    half sizes ``half`` (each ≥ 0) about ``center``: min over s ∈ [0, 1] of the box's
    exact SDF at a0 + s (a1 − a0), less r.

    Method: golden-section search of that convex 1-D function in a ``lax.fori_loop`` of
    :data:`GOLDEN_ITERATIONS` steps (45 in float64, 35 in float32); the result is the least
    of the SDF at the final bracket's middle and at s = 0 and 1. Error bound: the SDF is
    1-Lipschitz, so the result exceeds the exact distance by at most
    |a1 − a0|·φ⁻ⁿ/2 ≈ 2.0e-10·|a1 − a0| (float64), 2.4e-8·|a1 − a0| (float32), plus
    rounding; never less than it (up to rounding). The gradient is the SDF's partial
    gradient at the point found (no derivative through the search)."""
    a0, a1, r, center, half = _floats(a0, a1, r, center, half)
    dt = a0.dtype
    p0, d = a0 - center, a1 - a0
    shape = jnp.broadcast_shapes(p0.shape, d.shape, half.shape)[:-1]
    sp0, sd, shalf = (jax.lax.stop_gradient(v) for v in (p0, d, half))

    def f(s: Array) -> Array:  # the SDF at s (..., k) along the segment, values only
        return _box_sdf(sp0[..., None, :] + s[..., None] * sd[..., None, :], shalf[..., None, :])

    lo, hi = jnp.zeros(shape, dt), jnp.ones(shape, dt)
    x1, x2 = hi - _INVPHI * (hi - lo), lo + _INVPHI * (hi - lo)
    f12 = f(jnp.stack([x1, x2], -1))

    def step(_, c):
        lo, hi, x1, x2, f1, f2 = c
        left = f1 < f2  # a minimiser lies in [lo, x2]; otherwise in [x1, hi]
        lo, hi = jnp.where(left, lo, x1), jnp.where(left, x2, hi)
        x = jnp.where(left, hi - _INVPHI * (hi - lo), lo + _INVPHI * (hi - lo))
        fx = f(x[..., None])[..., 0]
        return (lo, hi, jnp.where(left, x, x2), jnp.where(left, x1, x),
                jnp.where(left, fx, f2), jnp.where(left, f1, fx))  # fmt: skip

    n = GOLDEN_ITERATIONS.get(jnp.dtype(dt).name, GOLDEN_ITERATIONS["float64"])
    lo, hi, *_ = jax.lax.fori_loop(0, n, step, (lo, hi, x1, x2, f12[..., 0], f12[..., 1]))
    cand = jnp.stack([(lo + hi) / 2, jnp.zeros(shape, dt), jnp.ones(shape, dt)], -1)
    best = jnp.argmin(f(cand), axis=-1)
    s = jnp.take_along_axis(cand, best[..., None], -1)[..., 0]
    return _box_sdf(p0 + s[..., None] * d, half) - r


# --------------------------------------------------------------------------- an arm


def link_segments(origins: ArrayLike) -> Array:
    """Link segments (..., n, 2, 3) from joint origins (..., n + 1, 3) (the first output
    of ``SerialModel.joint_frames``): link i runs from origin i to origin i + 1, the last
    one to the tip — the ``links: auto`` capsules."""
    (o,) = _floats(origins)
    return jnp.stack([o[..., :-1, :], o[..., 1:, :]], -2)


def nonadjacent_pairs(n_links: int) -> tuple[tuple[int, int], ...]:
    """Every link pair (i, j) with j ≥ i + 2 of a chain of ``n_links`` links: the pairs a
    self-collision check compares (adjacent links share a joint and always touch)."""
    return tuple((i, j) for i in range(n_links) for j in range(i + 2, n_links))


def _radii(radii: ArrayLike, n: int, dt) -> Array:
    r = jnp.asarray(radii, dt)
    return jnp.broadcast_to(r, (n,)) if r.ndim == 0 else r


def clearance_terms(
    segments: ArrayLike,
    radii: ArrayLike,
    obstacles: ObstacleParams | None = None,
    self_pairs: Sequence[tuple[int, int]] = (),
) -> tuple[Array, Array]:
    """(obstacle_min, self_min), each (...,): the least signed distance of the link
    capsules to any obstacle, and between the link pairs ``self_pairs`` (a static tuple
    of (i, j) index pairs, e.g. :func:`nonadjacent_pairs`).

    ``segments`` (..., L, 2, 3): the arm's link segments in the base frame (e.g.
    :func:`link_segments`); ``radii`` (L,) or (..., L) or a scalar; ``obstacles``: the
    pytree of :func:`obstacle_params` (None: none). Every link is checked against every
    obstacle with one broadcast array operation per shape.

    A term with nothing to check (no obstacles, no pairs) is +inf: a constant, so its
    gradient is zero, and ``jnp.minimum`` with a finite term passes that term's value and
    gradient unchanged (no NaN). Callers that average or store a term should mask inf."""
    (seg,) = _floats(segments)
    dt = seg.dtype
    L = seg.shape[-3]
    r = _radii(radii, L, dt)
    batch = jnp.broadcast_shapes(seg.shape[:-3], r.shape[:-1])
    a0, a1 = seg[..., 0, :], seg[..., 1, :]  # (..., L, 3)
    A0, A1, R = a0[..., :, None, :], a1[..., :, None, :], r[..., :, None]  # vs obstacles

    obs = []
    o = obstacles or {}
    if "ball" in o and o["ball"]["r"].shape[0]:
        obs.append(capsule_ball(A0, A1, R, o["ball"]["c"], o["ball"]["r"]))
    if "capsule" in o and o["capsule"]["r"].shape[0]:
        g = o["capsule"]
        obs.append(capsule_capsule(A0, A1, R, g["a"], g["b"], g["r"]))
    if "box" in o and o["box"]["c"].shape[0]:
        obs.append(capsule_box(A0, A1, R, o["box"]["c"], o["box"]["half"]))
    if "halfspace" in o and o["halfspace"]["p"].shape[0]:
        obs.append(capsule_halfspace(A0, A1, R, o["halfspace"]["p"], o["halfspace"]["n"]))
    if "mesh" in o and o["mesh"]["grid"].shape[0]:
        g = o["mesh"]
        obs.append(sdf.capsule_mesh(A0, A1, R, g["grid"], g["origin"], g["cell"], g["cells"],
                                    g["R"], g["t"]))  # fmt: skip
    inf = jnp.full(batch, jnp.inf, dt)
    obstacle_min = inf
    for d in obs:  # one term per shape (at most five), each (..., L, n_shape)
        obstacle_min = jnp.minimum(obstacle_min, jnp.min(d, axis=(-2, -1)))

    self_min = inf
    pairs = tuple(self_pairs)
    if pairs:
        ij = np.asarray(pairs, np.int64).reshape(-1, 2)
        if ij.min() < 0 or ij.max() >= L or np.any(ij[:, 0] == ij[:, 1]):
            raise ValueError(f"self_pairs {pairs}: needs pairs of distinct links in 0..{L - 1}")
        i, j = ij[:, 0], ij[:, 1]
        rr = jnp.broadcast_to(r, (*batch, L))
        d = capsule_capsule(a0[..., i, :], a1[..., i, :], rr[..., i],
                            a0[..., j, :], a1[..., j, :], rr[..., j])  # fmt: skip
        self_min = jnp.minimum(self_min, jnp.min(d, axis=-1))
    return obstacle_min, self_min


def clearance(
    segments: ArrayLike,
    radii: ArrayLike,
    obstacles: ObstacleParams | None = None,
    self_pairs: Sequence[tuple[int, int]] = (),
    margin: ArrayLike | None = None,
) -> Array:
    """The arm's clearance (...,): the least of :func:`clearance_terms`, less ``margin``
    (None: 0), so that a negative value is a collision by the config's rule. +inf when
    there is nothing to check (see :func:`clearance_terms`)."""
    obstacle_min, self_min = clearance_terms(segments, radii, obstacles, self_pairs)
    c = jnp.minimum(obstacle_min, self_min)
    return c if margin is None else c - jnp.asarray(margin, c.dtype)


def arms_clearance(seg_a: ArrayLike, ra: ArrayLike, seg_b: ArrayLike, rb: ArrayLike) -> Array:
    """The least capsule–capsule signed distance (...,) between every link of arm a
    (segments (..., La, 2, 3), radii (La,), (..., La) or a scalar) and every link of arm b
    (likewise), both in the same frame."""
    sa, sb = _floats(seg_a, seg_b)
    dt = sa.dtype
    ra, rb = _radii(ra, sa.shape[-3], dt), _radii(rb, sb.shape[-3], dt)
    d = capsule_capsule(sa[..., :, None, 0, :], sa[..., :, None, 1, :], ra[..., :, None],
                        sb[..., None, :, 0, :], sb[..., None, :, 1, :], rb[..., None, :])  # fmt: skip
    return jnp.min(d, axis=(-2, -1))
