"""The robot drawn from arrays (docs/figures.md, "The robot"): any number of arms, each a
chain at one joint configuration, as matplotlib 3-D or as a projection onto a plane, with
the task region and the tool-axis cone. The interactive report's plotly traces
(``designopt.figures.html.robot``) are built from the same geometry.

An :class:`Arm` is what ``SerialModel.joint_frames`` gives for one design and one
configuration (joint origins, the last the tip; joint axes; the tip rotation), with a
link radius, a colour, a label, an optional base pose in the world (several arms at
different bases) and a ``colliding`` flag. The drawing:

- links: capsules of the arm's radius (tubes between consecutive joint origins and balls
  at the joints; the base origin first), with the chain's centre line and its joints on
  top (``Line3D``/``Line2D`` whose data are the joint origins);
- joint axes: short arrows from each joint origin along its axis (in a projection, an
  axis nearly normal to the plane is a ring at the joint);
- the base frame and the tool frame: x red, y green, z blue;
- meshes (URDF visuals) in the arm's colour, translucent;
- the region (box, ball, cylinder, cone) as a wireframe with translucent faces, the
  tool-axis cone as rays from an anchor point, targets as dots coloured by a value.

A ``colliding`` arm is drawn red with a hatched outline, and ``Scene.collisions`` (point
pairs) are marked with red crosses joined by a line, for a study with several arms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from designopt.figures import style

THICKNESS = 0.02
"""Default link radius: this share of the longest arm's length (its centre line)."""
COLLIDING = "#d62728"
FRAME_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")
"""x, y, z of the base and tool frames."""
SIDES = 12
"""Facets around a link's tube."""


@dataclass
class Arm:
    """One chain at one configuration: ``origins`` (n + 1, 3) (joint origins, the last the
    tip), ``axes`` (n, 3) unit joint axes, ``tip`` (3, 3) the tool frame's rotation, all
    in the arm's base frame; ``base`` (4, 4) that frame in the world (None: the world);
    ``meshes`` [(vertices (k, 3), faces (m, 3))] in the base frame; ``radius`` the link
    radius (None: :func:`thickness` of the drawing); ``types`` "R"/"P" per joint."""

    origins: np.ndarray
    axes: np.ndarray
    tip: np.ndarray
    radius: float | None = None
    color: str = "#1f77b4"
    label: str = ""
    colliding: bool = False
    base: np.ndarray | None = None
    meshes: Sequence[tuple[np.ndarray, np.ndarray]] = ()
    types: str = ""

    def world(self) -> Arm:
        """The same arm with its base pose applied (``base`` None after)."""
        if self.base is None:
            return self
        R, t = np.asarray(self.base)[:3, :3], np.asarray(self.base)[:3, 3]
        return replace(self, origins=np.asarray(self.origins) @ R.T + t,
                       axes=np.asarray(self.axes) @ R.T, tip=R @ np.asarray(self.tip),
                       meshes=[(V @ R.T + t, F) for V, F in self.meshes], base=None)  # fmt: skip

    @property
    def base_point(self) -> np.ndarray:
        return np.zeros(3) if self.base is None else np.asarray(self.base)[:3, 3]

    @property
    def base_rotation(self) -> np.ndarray:
        return np.eye(3) if self.base is None else np.asarray(self.base)[:3, :3]

    def points(self) -> np.ndarray:
        """(n + 2, 3): the base origin, then the joint origins and the tip (world)."""
        w = self.world()
        return np.vstack([self.base_point, np.asarray(w.origins, np.float64)])

    def length(self) -> float:
        """The length of the centre line (base origin → joints → tip)."""
        return float(np.linalg.norm(np.diff(self.points(), axis=0), axis=1).sum())


@dataclass
class Cone:
    """A cone of tool z axes: rays of ``length`` from ``apex`` within ``half_angle``
    degrees of ``direction``."""

    apex: np.ndarray
    direction: np.ndarray
    half_angle: float
    length: float


@dataclass
class Targets:
    """Task targets (N, 3) coloured by ``value`` where ``ok``, grey crosses elsewhere."""

    xyz: np.ndarray
    value: np.ndarray
    ok: np.ndarray
    label: str = "1/k"
    size: float = 3.0
    alpha: float = 0.5


@dataclass
class Scene:
    """What one panel shows: arms, the region (a ``designopt.kinematics.task`` region),
    the tool-axis cone, targets, ``marks`` [(point (3,), colour)] (e.g. the targets the
    arms reach), ``collisions`` [(point a, point b)], ``ports`` and ``scopes`` (each
    endoscope's outer end, its incision point or its shaft's far end, and its tip; its
    incision point is among the ``ports``)."""

    arms: list[Arm]
    title: str = ""
    region: Any = None
    cone: Cone | None = None
    targets: Targets | None = None
    marks: list[tuple[np.ndarray, str]] = field(default_factory=list)
    collisions: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    obstacles: list[Any] = field(default_factory=list)  # collision obstacle models
    ports: list[np.ndarray] = field(default_factory=list)
    scopes: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # (outer end, tip)


def thickness(arms: Sequence[Arm]) -> float:
    """The default link radius of a drawing: :data:`THICKNESS` × the longest arm."""
    size = max((a.length() for a in arms), default=0.0)
    return THICKNESS * size if size > 0 else 1e-3


def radii(arms: Sequence[Arm]) -> list[float]:
    """Each arm's link radius (its own, else :func:`thickness`)."""
    t = thickness(arms)
    return [a.radius if a.radius is not None and a.radius > 0 else t for a in arms]


# ------------------------------------------------------------------ geometry


def _basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors normal to d and to each other."""
    a = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def tube(p0: np.ndarray, p1: np.ndarray, r: float, sides: int = SIDES):
    """The side of a cylinder of radius r from p0 to p1: (vertices (2·sides, 3), faces).
    A zero-length one (p0 = p1) is a flat ring, kept so that a drawing's topology does
    not depend on the pose."""
    d = p1 - p0
    n = np.linalg.norm(d)
    u, v = _basis(d / n if n > 0 else np.array([0.0, 0.0, 1.0]))
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = r * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * v)
    V = np.vstack([p0 + ring, p1 + ring])
    i = np.arange(sides)
    j = (i + 1) % sides
    F = np.vstack([np.c_[i, j, i + sides], np.c_[j, j + sides, i + sides]])
    return V, F


def ball(c: np.ndarray, r: float, n: int = 8):
    """A UV sphere of radius r about c: (vertices, faces)."""
    th = np.linspace(0, np.pi, n // 2 + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, n, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    V = c + r * np.vstack([[0, 0, 1.0], ring, [0, 0, -1.0]])
    k, m = len(th), n
    F = [[0, 1 + (b + 1) % m, 1 + b] for b in range(m)]
    for a in range(k - 1):
        for b in range(m):
            p, q = 1 + a * m + b, 1 + a * m + (b + 1) % m
            F += [[p, q, q + m], [p, q + m, p + m]]
    last = 1 + k * m
    F += [[last, 1 + (k - 1) * m + b, 1 + (k - 1) * m + (b + 1) % m] for b in range(m)]
    return V, np.asarray(F)


def merge(parts: Sequence[tuple[np.ndarray, np.ndarray]]):
    """Meshes (V, F) joined into one."""
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3), int)
    off = np.cumsum([0] + [len(V) for V, _ in parts[:-1]])
    return np.vstack([V for V, _ in parts]), np.vstack(
        [F + o for (_, F), o in zip(parts, off, strict=True)]
    )


def capsules(arm: Arm, r: float, keep_all: bool = False):
    """The arm's links as capsules of radius r (world frame): tubes between consecutive
    points of :meth:`Arm.points` and a ball at each point; zero-length links are skipped
    unless ``keep_all`` (the report keeps them: one topology for every pose)."""
    P = arm.points()
    tol = 1e-9 * max(arm.length(), 1e-300)
    links = [k for k in range(len(P) - 1) if keep_all or np.linalg.norm(P[k + 1] - P[k]) > tol]
    parts = [tube(P[k], P[k + 1], r) for k in links]
    keep = range(len(P)) if keep_all else \
        [0] + [i for i in range(1, len(P)) if np.linalg.norm(P[i] - P[i - 1]) > tol]  # fmt: skip
    parts += [ball(P[i], r) for i in keep]
    return merge(parts)


def axis_arrows(arm: Arm, length: float) -> np.ndarray:
    """(n, 2, 3): each joint axis as a segment of ``length`` from its origin (world)."""
    w = arm.world()
    o = np.asarray(w.origins, np.float64)[:-1]
    return np.stack([o, o + length * np.asarray(w.axes, np.float64)], 1)


def triads(arm: Arm, length: float) -> np.ndarray:
    """(2, 3, 2, 3): the base frame's and the tool frame's x, y, z as segments (world)."""
    w = arm.world()
    out = []
    for R, p in (
        (arm.base_rotation, arm.base_point),
        (np.asarray(w.tip), np.asarray(w.origins)[-1]),
    ):
        out.append(np.stack([np.stack([p, p + length * R[:, k]]) for k in range(3)]))
    return np.stack(out)


def _circle(c: np.ndarray, u: np.ndarray, v: np.ndarray, r: float, n: int = 48) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n + 1)
    return c + r * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * v)


def _frame(axis: Sequence[float]) -> np.ndarray:
    z = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    u, v = _basis(z)
    return np.stack([u, v, z], -1)


OBSTACLE = "#7f7f7f"
ANATOMY = "#c51b7d"  # obstacles inside the patient (``inside: true``): apart from the skin
ANATOMY_EDGE = "#4d0026"  # their outline
WALL = "#f4a582"  # the body wall the ports lie on
PORT = "#000000"
SCOPE = "#238b45"  # an endoscope: its incision point and its shaft to the tip


def is_wall(ob: Any) -> bool:
    """Whether ``ob`` is a body wall (``designopt.kinematics.wall``), drawn as the skin."""
    from designopt.kinematics.wall import EllipsoidWall, HalfSpaceWall, MeshWall

    return isinstance(ob, EllipsoidWall | HalfSpaceWall | MeshWall)


def obstacle_colour(ob: Any) -> str:
    """The body wall skin-coloured, the anatomy (``inside``) red, the rest grey."""
    return WALL if is_wall(ob) else ANATOMY if getattr(ob, "inside", False) else OBSTACLE


def obstacle_name(k: int, ob: Any) -> str:
    """``obstacle 2: ball``, ``anatomy 3: mesh organ.stl``, ``body wall: ellipsoid``."""
    if is_wall(ob):
        return f"body wall: {ob.shape}"
    what = ob.shape + (f" {Path(ob.file).name}" if ob.shape == "mesh" else "")
    return f"{'anatomy' if getattr(ob, 'inside', False) else 'obstacle'} {k}: {what}"


def anatomy_lines(ob: Any) -> list[np.ndarray]:
    """Lines that outline a thin piece of anatomy at any scale: a capsule ``inside`` the
    patient (a vessel) as its axis a → b; nothing for other shapes (their faces show)."""
    if getattr(ob, "inside", False) and ob.shape == "capsule":
        return [np.stack([np.asarray(ob.a, np.float64), np.asarray(ob.b, np.float64)])]
    return []


def obstacle_mesh(ob: Any, center: np.ndarray, ext: float):
    """An obstacle (``designopt.kinematics.collision`` model) as a triangle mesh
    (vertices, faces): a ball, a capsule (tube and end balls), a box; a half-space as a
    square of side 1.2·``ext`` in its plane, centred on ``center``'s projection."""
    kind = ob.shape
    if kind == "ball":
        return ball(np.asarray(ob.center, np.float64), float(ob.radius), 16)
    if kind == "ellipsoid":  # a body wall
        V, F = ball(np.zeros(3), 1.0, 24)
        return np.asarray(ob.center, np.float64) + V * np.asarray(ob.radii, np.float64), F
    if kind == "mesh":
        from designopt.kinematics.sdf import load_mesh

        V, F = load_mesh(Path(ob.file))
        R, t = ob.pose()
        return (float(ob.scale) * np.asarray(V, np.float64)) @ R.T + t, np.asarray(F)
    if kind == "capsule":
        a, b, r = np.asarray(ob.a, np.float64), np.asarray(ob.b, np.float64), float(ob.radius)
        return merge([tube(a, b, r), ball(a, r, 16), ball(b, r, 16)])
    if kind == "box":
        c, h = np.asarray(ob.center, np.float64), np.asarray(ob.size, np.float64) / 2
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        V = c + corners * h
        F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])  # fmt: skip
        return V, F
    if kind == "halfspace":
        n = np.asarray(ob.normal, np.float64)
        n = n / np.linalg.norm(n)
        p = np.asarray(ob.point, np.float64)
        c = center - ((center - p) @ n) * n
        u, v = _basis(n)
        h = 0.6 * ext
        V = np.array([c - h * u - h * v, c + h * u - h * v, c + h * u + h * v, c - h * u + h * v])
        return V, np.array([[0, 1, 2], [0, 2, 3]])
    raise ValueError(f"unknown obstacle shape {kind!r}")


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def hull_2d(P: np.ndarray) -> np.ndarray:
    """The convex hull (k, 2) of points (n, 2), counter-clockwise (Andrew's monotone
    chain): an obstacle's outline in a view."""
    P = np.unique(np.round(np.asarray(P, np.float64), 12), axis=0)
    if len(P) < 3:
        return P

    def half(pts):
        out: list = []
        for p in pts:
            while len(out) >= 2 and _cross(out[-1] - out[-2], p - out[-2]) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(P), half(P[::-1])
    return np.asarray(lower[:-1] + upper[:-1])


def region_wire(region: Any) -> list[np.ndarray]:
    """The region's edges as polylines (k, 3): a box's 12 edges, a ball's three great
    circles, a cylinder's end circles and 8 generators, a cone's (frustum's) end circles
    (a point at depth 0) and 8 generators; none for a points file."""
    from designopt.kinematics import task

    if isinstance(region, task.Box):
        c, s = np.asarray(region.center), np.asarray(region.size) / 2
        corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
        out = []
        for a in range(8):
            for b in range(a + 1, 8):
                if np.sum(corners[a] != corners[b]) == 1:
                    out.append(c + s * corners[[a, b]])
        return out
    if isinstance(region, task.Ball):
        c, r = np.asarray(region.center), region.radius
        e = np.eye(3)
        return [_circle(c, e[i], e[j], r) for i, j in ((0, 1), (0, 2), (1, 2))]
    if isinstance(region, task.Cylinder):
        Fm = _frame(region.axis)
        c, r, h = np.asarray(region.center), region.radius, region.height
        ends = [c + s * h / 2 * Fm[:, 2] for s in ((-1, 1) if h > 0 else (0,))]
        out = [_circle(e, Fm[:, 0], Fm[:, 1], r) for e in ends]
        if h > 0:
            for t in np.linspace(0, 2 * np.pi, 8, endpoint=False):
                d = r * (math.cos(t) * Fm[:, 0] + math.sin(t) * Fm[:, 1])
                out.append(np.stack([ends[0] + d, ends[1] + d]))
        return out
    if isinstance(region, task.Cone):
        Fm = _frame(region.axis)
        a, tn = np.asarray(region.apex), math.tan(math.radians(region.half_angle))
        d0, d1 = region.depth
        out = [_circle(a + d * Fm[:, 2], Fm[:, 0], Fm[:, 1], d * tn) for d in (d0, d1) if d > 0]
        for t in np.linspace(0, 2 * np.pi, 8, endpoint=False):
            rim = math.cos(t) * Fm[:, 0] + math.sin(t) * Fm[:, 1]
            out.append(np.stack([a + d * (Fm[:, 2] + tn * rim) for d in (d0, d1)]))
        return out
    return []


def region_faces(region: Any, n: int = 32):
    """The region's surface as triangles (V, F), for translucent faces; empty for a
    points file."""
    from designopt.kinematics import task

    if isinstance(region, task.Box):
        c, s = np.asarray(region.center), np.asarray(region.size) / 2
        V = c + s * np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
        quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        F = [[a, b, c_] for a, b, c_, _ in quads] + [[a, c_, d] for a, _, c_, d in quads]
        return V, np.asarray(F)
    if isinstance(region, task.Ball):
        return ball(np.asarray(region.center), region.radius, n)
    if isinstance(region, task.Cylinder | task.Cone):
        Fm = _frame(region.axis)
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        rim = np.cos(t)[:, None] * Fm[:, 0] + np.sin(t)[:, None] * Fm[:, 1]
        if isinstance(region, task.Cylinder):
            c, r, h = np.asarray(region.center), region.radius, region.height
            rings = [c - h / 2 * Fm[:, 2] + r * rim, c + h / 2 * Fm[:, 2] + r * rim]
        else:
            a, tn = np.asarray(region.apex), math.tan(math.radians(region.half_angle))
            rings = [a + d * (Fm[:, 2] + tn * rim) for d in region.depth]
        V = np.vstack([*rings, [r_.mean(0) for r_ in rings]])
        i = np.arange(n)
        j = (i + 1) % n
        F = np.vstack([np.c_[i, j, i + n], np.c_[j, j + n, i + n],
                       np.c_[np.full(n, 2 * n), j, i], np.c_[np.full(n, 2 * n + 1), i + n, j + n]])  # fmt: skip
        return V, F
    return np.zeros((0, 3)), np.zeros((0, 3), int)


def cone_rays(cone: Cone, n: int = 12) -> list[np.ndarray]:
    """The tool-axis cone as polylines: the axis, n rays on the rim and the rim circle."""
    Fm = _frame(cone.direction)
    a, L, h = np.asarray(cone.apex, np.float64), cone.length, math.radians(cone.half_angle)
    out = [np.stack([a, a + L * Fm[:, 2]])]
    if h > 0:
        ring = [a + L * (math.cos(h) * Fm[:, 2] + math.sin(h) * (math.cos(t) * Fm[:, 0]
                + math.sin(t) * Fm[:, 1])) for t in np.linspace(0, 2 * np.pi, 49)]  # fmt: skip
        out.append(np.asarray(ring))
        out += [np.stack([a, ring[k]]) for k in range(0, 48, 48 // n)]
    return out


def scene_points(scene: Scene) -> np.ndarray:
    """Every point a scene draws but its obstacles (arms, meshes, region, cone, targets,
    marks, ports, colliding pairs): what the view holds (:func:`view_box`). Obstacles
    are clipped to that view, so a far-away one does not shrink it."""
    pts = [a.points() for a in scene.arms]
    pts += [a.world().meshes[k][0] for a in scene.arms for k in range(len(a.meshes))]
    pts += region_wire(scene.region)
    if scene.cone is not None:
        pts += cone_rays(scene.cone)
    if scene.targets is not None:
        pts.append(np.asarray(scene.targets.xyz, np.float64))
    pts += [np.atleast_2d(p) for p, _ in scene.marks]
    pts += [np.atleast_2d(np.asarray(p, np.float64)) for p in scene.ports]
    pts += [np.stack(ab) for ab in scene.collisions]
    pts += [np.stack(ab) for ab in scene.scopes]
    return np.vstack(pts) if pts else np.zeros((1, 3))


def _extent(scene: Scene) -> float:
    return float(np.ptp(scene_points(scene), 0).max()) or 1.0


MARGIN = 0.1
"""The view's margin around what it holds: this share of its extent on every side."""


def view_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the view of ``points`` (k, 3): their bounding box with a margin of
    :data:`MARGIN` × their extent, each side at least 0.6 × the extent (no flat box)."""
    P = np.asarray(points, np.float64).reshape(-1, 3)
    P = P[np.all(np.isfinite(P), 1)]
    if not len(P):
        return np.zeros(3), np.ones(3)
    lo, hi = P.min(0), P.max(0)
    ext = float((hi - lo).max()) or 1.0
    mid, half = (lo + hi) / 2, np.maximum((hi - lo) / 2 + MARGIN * ext, 0.3 * ext)
    return mid - half, mid + half


def _corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                     for i in (0, 1) for j in (0, 1) for k in (0, 1)])  # fmt: skip


def _plane_in_box(p: np.ndarray, n: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """The polygon (vertices (k, 3), fan faces) where the plane through p normal to n
    cuts the box [lo, hi]; None when it misses the box."""
    C = _corners(lo, hi)
    d = (C - p) @ n
    pts = []
    for a in range(8):
        for b in range(a + 1, 8):
            if np.sum(C[a] != C[b]) == 1 and d[a] * d[b] <= 0 and d[a] != d[b]:
                pts.append(C[a] + d[a] / (d[a] - d[b]) * (C[b] - C[a]))
    if len(pts) < 3:
        return None
    P = np.unique(np.round(np.asarray(pts), 12), axis=0)
    if len(P) < 3:
        return None
    c = P.mean(0)
    u, v = _basis(n)
    P = P[np.argsort(np.arctan2((P - c) @ v, (P - c) @ u))]
    F = np.array([[0, i, i + 1] for i in range(1, len(P) - 1)])
    return P, F


def _vec(v: Any) -> str:
    return "(" + ", ".join(f"{float(a):.4g}" for a in np.asarray(v).ravel()) + ")"


def describe_obstacle(ob: Any, unit: str = "") -> str:
    """``ball at (x, y, z), r = 0.1 m``: an obstacle in words, for a note."""
    u = f" {unit}" if unit else ""
    if ob.shape == "ball":
        return f"ball at {_vec(ob.center)}{u}, r = {float(ob.radius):.4g}{u}"
    if ob.shape == "capsule":
        return f"capsule {_vec(ob.a)}–{_vec(ob.b)}{u}, r = {float(ob.radius):.4g}{u}"
    if ob.shape == "box":
        return f"box at {_vec(ob.center)}{u}, size {_vec(ob.size)}{u}"
    if ob.shape == "mesh":
        return f"mesh {Path(ob.file).name} at {_vec(ob.xyz)}{u}"
    if ob.shape == "ellipsoid":
        return f"ellipsoid at {_vec(ob.center)}{u}, semi-axes {_vec(ob.radii)}{u}"
    return f"half-space through {_vec(ob.point)}{u}, normal {_vec(ob.normal)}"


def clip_obstacle(ob: Any, lo: np.ndarray, hi: np.ndarray):
    """An obstacle within the view box [lo, hi] as (vertices, faces, how): a box cut to
    the view exactly, a half-space as the polygon where its plane cuts the view, a ball
    or capsule with its vertices moved into the view; ``how`` is "" (whole), "cut" or
    "outside" (nothing to draw: vertices and faces None)."""
    if ob.shape == "halfspace":
        n = np.asarray(ob.normal, np.float64)
        n = n / np.linalg.norm(n)
        pf = _plane_in_box(np.asarray(ob.point, np.float64), n, lo, hi)
        inside = float(np.max((_corners(lo, hi) - np.asarray(ob.point, np.float64)) @ n)) < 0
        return (*pf, "") if pf is not None else (None, None, "inside" if inside else "outside")
    V, F = obstacle_mesh(ob, (lo + hi) / 2, 1.0)
    a, b = V.min(0), V.max(0)
    if np.any(a > hi) or np.any(b < lo):
        return None, None, "outside"
    if ob.shape == "box":  # the box cut to the view: a box (corners in obstacle_mesh's order)
        V = _corners(np.maximum(a, lo), np.minimum(b, hi))
    cut = bool(np.any(a < lo) or np.any(b > hi))
    return np.clip(V, lo, hi), F, "cut" if cut else ""


def clipped_obstacles(obstacles: Sequence[Any], lo: np.ndarray, hi: np.ndarray, unit: str = ""
                      ) -> tuple[list[tuple[int, Any, np.ndarray, np.ndarray]], list[str]]:  # fmt: skip
    """The obstacles within the view [lo, hi]: [(number, obstacle, vertices, faces)] to
    draw, and a note for each one clipped (``obstacle 2 (ball at …) outside the view``,
    ``… cut at the view's edge``; a half-space whose plane misses the view: outside it,
    or the whole view inside it)."""
    keep, notes = [], []
    for k, ob in enumerate(obstacles):
        V, F, how = clip_obstacle(ob, lo, hi)
        if V is not None:
            keep.append((k, ob, V, F))
        what = f"obstacle {k} ({describe_obstacle(ob, unit)})"
        if how == "outside":
            notes.append(f"{what} outside the view")
        elif how == "cut":
            notes.append(f"{what} cut at the view's edge")
        elif how == "inside":
            notes.append(f"{what}: the whole view lies inside it")
    return keep, notes


def clip_note(notes: Sequence[str]) -> str:
    """The notes of :func:`clipped_obstacles` as one line ("" when none)."""
    return ("view clipped to the robots, task and ports: " + "; ".join(dict.fromkeys(notes))
            if notes else "")  # fmt: skip


def clipped_note(scenes: Sequence[Scene], unit: str = "", limits: np.ndarray | None = None) -> str:
    """What a drawing of ``scenes`` on the view of ``limits`` (default: the scenes'
    own points, as :func:`figure` draws them) leaves out of its obstacles, one line."""
    pts = np.vstack([scene_points(sc) for sc in scenes]) if limits is None else limits
    lo, hi = view_box(pts)
    return clip_note([n for sc in scenes for n in clipped_obstacles(sc.obstacles, lo, hi, unit)[1]])


# ---------------------------------------------------------------- matplotlib


def legend_handles(scene: Scene) -> list:
    """Legend entries of a scene: each labelled arm, the joint axes, the frames, the
    tool-axis cone, colliding pairs."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    hs = [Patch(facecolor=COLLIDING if a.colliding else a.color, alpha=0.6,
                hatch="///" if a.colliding else None, label=a.label + (" (colliding)" if a.colliding else ""))
          for a in scene.arms if a.label]  # fmt: skip
    if scene.arms:
        hs.append(Line2D([], [], color="0.2", lw=1.2, label="joint axes"))
        hs.append(Line2D([], [], color=FRAME_COLOURS[0], lw=1.5,
                         label="base, tool frame (x red, y green, z blue)"))  # fmt: skip
    if scene.cone is not None:
        hs.append(Line2D([], [], color="#8c564b", lw=1, ls="--",
                         label=f"tool z axes within {scene.cone.half_angle:g}°"))  # fmt: skip
    if scene.collisions:
        hs.append(Line2D([], [], color=COLLIDING, marker="x", lw=1, label="colliding pair"))
    kinds = {obstacle_colour(ob) for ob in scene.obstacles}
    for colour, label in ((OBSTACLE, "obstacles"), (ANATOMY, "anatomy (inside the patient)"),
                          (WALL, "body wall")):  # fmt: skip
        if colour in kinds:
            hs.append(Patch(facecolor=colour, alpha=0.7 if colour == ANATOMY else 0.35,
                            edgecolor=ANATOMY_EDGE if colour == ANATOMY else "none",
                            label=label))  # fmt: skip
    if scene.ports:
        hs.append(Line2D([], [], color=PORT, marker="o", mfc="white", ls="none", label="port"))
    if scene.scopes:
        hs.append(Line2D([], [], color=SCOPE, lw=2, label="endoscope (its port among the ports)"))
    return hs


def draw_3d(ax: Any, scene: Scene, unit: str, legend: bool = True,
            limits: np.ndarray | None = None, clip: bool = False, zoom: float = 1.0) -> Any:  # fmt: skip
    """Draw ``scene`` on a 3-D axes: region, targets, obstacles and ports, arms
    (capsules, meshes, centre lines, axes, frames), marks, collisions; equal scales, axes
    labelled in ``unit``. ``limits``: points (k, 3) the axes must hold (default: the
    scene's own, :func:`scene_points`); the view is their :func:`view_box`, and the
    obstacles are clipped to it (:func:`clipped_note` says which). ``clip``: the arms,
    targets and marks are clipped to the view too (a view zoomed on the patient, where
    the robots reach beyond it); ``zoom``: the 3-D box's scale within the axes
    (matplotlib's ``set_box_aspect`` zoom). Returns the targets' colour mappable (None
    without reached targets)."""
    kw = {"axlim_clip": True} if clip else {}
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    pts = scene_points(scene) if limits is None else np.asarray(limits, np.float64)
    lo, hi = view_box(pts)
    ax.computed_zorder = False
    Vr, Fr = region_faces(scene.region)
    if len(Fr):
        ax.add_collection3d(Poly3DCollection(Vr[Fr], facecolor="#9ecae1", alpha=0.12,
                                             edgecolor="none", zorder=1))  # fmt: skip
    for line in region_wire(scene.region):
        ax.plot(*line.T, color="#3182bd", lw=0.8, alpha=0.8, zorder=1.5)
    if scene.cone is not None:
        for k, line in enumerate(cone_rays(scene.cone)):
            ax.plot(*line.T, color="#8c564b", lw=1.2 if k == 0 else 0.7, ls="--", zorder=1.5)
    for _, ob, Vo, Fo in clipped_obstacles(scene.obstacles, lo, hi)[0]:
        if getattr(ob, "inside", False):  # the anatomy: opaque, outlined, on top of the wall
            ax.add_collection3d(Poly3DCollection(Vo[Fo], facecolors=ANATOMY, alpha=0.7,
                                                 edgecolors=ANATOMY_EDGE, linewidths=0.15,
                                                 shade=True, zorder=1.8))  # fmt: skip
            for line in anatomy_lines(ob):  # a thin vessel stays visible at any scale
                ax.plot(*np.clip(line, lo, hi).T, color=ANATOMY_EDGE, lw=2.2, zorder=1.9,
                        solid_capstyle="round")  # fmt: skip
            continue
        if clip and ob.shape != "halfspace":  # its faces within the view, none flattened on it
            Vo, Fo = _inside_faces(ob, lo, hi)
        ax.add_collection3d(Poly3DCollection(Vo[Fo], facecolor=obstacle_colour(ob),
                                             alpha=0.10 if is_wall(ob) else 0.18,
                                             edgecolor="none", zorder=1))  # fmt: skip
    for pt in scene.ports:
        ax.scatter(*np.asarray(pt, np.float64)[:, None], marker="o", s=60, c="white",
                   edgecolors=PORT, lw=1.5, depthshade=False, zorder=6)  # fmt: skip
    for a, b in scene.scopes:
        ax.plot(*np.stack([a, b]).T, color=SCOPE, lw=2.2, zorder=5.5)
    t, mappable = scene.targets, None
    if t is not None:
        ok = np.asarray(t.ok, bool)
        xyz = np.asarray(t.xyz)
        if ok.any():
            mappable = ax.scatter(*xyz[ok].T, c=np.asarray(t.value)[ok], cmap="viridis", s=t.size, alpha=t.alpha,
                       lw=0, depthshade=False, rasterized=True, zorder=2, **kw)  # fmt: skip
        if (~ok).any():
            ax.scatter(*xyz[~ok].T, marker="x", c="0.5", s=6, lw=0.6, depthshade=False,
                       rasterized=True, zorder=2, **kw)  # fmt: skip
    rs = radii(scene.arms)
    polys, colours = [], []
    for arm, r in zip(scene.arms, rs, strict=True):
        col = COLLIDING if arm.colliding else arm.color
        if clip:  # each link's part within the view, a thick line (an instrument's shaft)
            P = arm.points()
            for a, b in zip(P[:-1], P[1:], strict=True):
                seg = clip_segment(a, b, lo, hi)
                if seg is not None:
                    ax.plot(*np.stack(seg).T, color=col, lw=4.5, alpha=0.8, zorder=3.5,
                            solid_capstyle="round")  # fmt: skip
                    ax.plot(*np.stack(seg).T, color="0.15", lw=1.0, zorder=4)
        else:
            V, F = capsules(arm, r)
            polys.append(V[F])
            colours += [col] * len(F)
        for Vm, Fm in arm.world().meshes:
            polys.append(Vm[Fm])
            colours += ["#b0b0b0"] * len(Fm)
    if polys:
        pc = Poly3DCollection(np.concatenate(polys), facecolors=colours, alpha=0.55, shade=True,
                              edgecolor="none", zorder=3, rasterized=True, **kw)  # fmt: skip
        ax.add_collection3d(pc, **kw)
    for k_arm, (arm, r) in enumerate(zip(scene.arms, rs, strict=True)):
        P = arm.points()  # the centre line's data are the joints (gid: tests read them back)
        ax.plot(*P.T, color="0.15", lw=1.0, marker="o", ms=2.5, zorder=4, gid=f"arm{k_arm}-joints",
                **kw)  # fmt: skip
        L = max(4 * r, 0.08 * arm.length())
        L = min(L, 0.1 * float(np.max(hi - lo))) if clip else L
        for seg in axis_arrows(arm, L):
            ax.quiver(*seg[0], *(seg[1] - seg[0]), color="0.2", lw=1.0, arrow_length_ratio=0.3,
                      zorder=5, **kw)  # fmt: skip
        for tri in triads(arm, 0.75 * L):
            for k, seg in enumerate(tri):
                ax.plot(*seg.T, color=FRAME_COLOURS[k], lw=1.6, zorder=5, **kw)
        if arm.colliding:
            ax.plot(*P.T, color=COLLIDING, lw=2.5, ls=":", zorder=4, **kw)
    for p, col in scene.marks:
        ax.scatter(*np.asarray(p)[:, None], marker="*", s=90, c=col, edgecolors="k", lw=0.5,
                   depthshade=False, zorder=6, **kw)  # fmt: skip
    for a, b in scene.collisions:
        s = np.stack([a, b])
        ax.plot(*s.T, color=COLLIDING, lw=1.5, marker="x", ms=8, zorder=6, **kw)
    ax.set_xlim(lo[0], hi[0])  # the view: robots, task and ports; obstacles clipped to it
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple((hi - lo) / (hi - lo).max()), zoom=zoom)
    ax.set_xlabel(style.label("x", unit))
    ax.set_ylabel(style.label("y", unit))
    ax.set_zlabel(style.label("z", unit))
    from matplotlib.ticker import MaxNLocator

    for a_ in (ax.xaxis, ax.yaxis, ax.zaxis):
        a_.set_major_locator(MaxNLocator(4))
    if scene.title:  # above the box where it is zoomed beyond the axes
        ax.set_title(scene.title, fontsize=9, y=1.0 + 0.5 * max(zoom - 1.0, 0.0))
    if legend and legend_handles(scene):
        ax.legend(handles=legend_handles(scene), loc="upper left", fontsize=7, framealpha=0.85)
    return mappable


def draw_2d(ax: Any, arms: Sequence[Arm], E: np.ndarray, rs: Sequence[float] | None = None,
            alpha: float = 0.45) -> None:  # fmt: skip
    """The arms projected onto the plane spanned by the orthonormal columns of E (3, 2):
    each link a capsule outline of its radius (a stadium: the projection of a capsule),
    the centre line with its joints, the joint axes as arrows (a ring where an axis is
    within 11.5° of the plane's normal), the base and tool frames. Patches and lines
    only (no collections)."""
    from matplotlib.patches import Circle, FancyArrowPatch, Polygon

    rs = radii(arms) if rs is None else rs
    for k_arm, (arm, r) in enumerate(zip(arms, rs, strict=True)):
        col = COLLIDING if arm.colliding else arm.color
        P = arm.points() @ E
        tol = 1e-9 * max(arm.length(), 1e-300)
        for a, b in zip(P[:-1], P[1:], strict=True):
            d = b - a
            n = np.linalg.norm(d)
            if n > tol:
                nv = np.array([-d[1], d[0]]) / n * r
                ax.add_patch(Polygon([a + nv, b + nv, b - nv, a - nv], closed=True, fc=col,
                                     alpha=alpha, lw=0, hatch="///" if arm.colliding else None))  # fmt: skip
        for p in P:
            ax.add_patch(Circle(p, r, fc=col, alpha=alpha, lw=0))
        ax.plot(P[:, 0], P[:, 1], color="0.15", lw=1.0, marker="o", ms=2.5, zorder=4,
                gid=f"arm{k_arm}-joints")  # fmt: skip
        L = max(4 * r, 0.08 * arm.length())
        for seg in axis_arrows(arm, L):
            s2 = seg @ E
            if np.linalg.norm(s2[1] - s2[0]) > 0.2 * L:
                ax.add_patch(FancyArrowPatch(s2[0], s2[1], arrowstyle="-|>", mutation_scale=7,
                                             color="0.2", lw=0.9, zorder=5))  # fmt: skip
            else:  # about normal to the plane
                ax.add_patch(Circle(s2[0], 0.6 * r, fill=False, ec="0.2", lw=0.9, zorder=5))
        for tri in triads(arm, 0.75 * L):
            for k, seg in enumerate(tri):
                s2 = seg @ E
                if np.linalg.norm(s2[1] - s2[0]) > 0.05 * L:
                    ax.plot(s2[:, 0], s2[:, 1], color=FRAME_COLOURS[k], lw=1.5, zorder=5)


def draw_region_2d(ax: Any, region: Any, E: np.ndarray) -> None:
    """The region's wireframe projected onto the plane of E (lines only)."""
    for line in region_wire(region):
        p = line @ E
        ax.plot(p[:, 0], p[:, 1], color="#3182bd", lw=0.8, alpha=0.8, zorder=1.5)


def draw_obstacles_2d(ax: Any, scene: Scene, E: np.ndarray) -> None:
    """The scene's obstacles (their outlines: the projections' convex hulls, clipped to
    the scene's :func:`view_box`) and ports in the plane of E."""
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Polygon

    centre, ext = scene_points(scene).mean(0), _extent(scene)
    lo, hi = view_box(scene_points(scene))
    for _, ob, V, _ in clipped_obstacles(scene.obstacles, lo, hi)[0]:
        if ob.shape == "halfspace":  # its side of the line where the plane cuts the view
            n = np.asarray(ob.normal, np.float64) / np.linalg.norm(ob.normal)
            n2 = n @ E
            if np.linalg.norm(n2) < 0.3:
                continue  # seen face-on: it would fill the view and say nothing
            n2 = n2 / np.linalg.norm(n2)
            t2 = np.array([-n2[1], n2[0]])
            c2 = np.asarray(ob.point, np.float64) @ E  # on the plane's trace in the view
            c2 = c2 + ((centre @ E - c2) @ t2) * t2
            h = 20 * ext  # far beyond the view; kept out of the autoscale
            poly = [c2 - h * t2, c2 + h * t2, c2 + h * t2 - h * n2, c2 - h * t2 - h * n2]
            ax.add_collection(PolyCollection([poly], facecolors=OBSTACLE, alpha=0.3,
                                             edgecolors="0.35", linewidths=0.8, zorder=1.2),
                              autolim=False)  # fmt: skip
            continue
        H = hull_2d(V @ E)  # clipped to the view: a far-away obstacle does not widen it
        inside = getattr(ob, "inside", False)
        if len(H) >= 3:  # the anatomy opaque and outlined over the wall
            ax.add_patch(Polygon(H, closed=True, fc=obstacle_colour(ob),
                                 alpha=0.65 if inside else 0.3,
                                 ec=ANATOMY_EDGE if inside else "0.35", lw=1.2 if inside else 0.8,
                                 zorder=1.3 if inside else 1.2))  # fmt: skip
        for line in anatomy_lines(ob):
            p2 = np.clip(line, lo, hi) @ E
            ax.plot(p2[:, 0], p2[:, 1], color=ANATOMY_EDGE, lw=2.0, zorder=1.35,
                    solid_capstyle="round")  # fmt: skip
    for pt in scene.ports:
        uv = np.asarray(pt, np.float64) @ E
        ax.plot(uv[0], uv[1], marker="o", ms=8, mfc="white", mec=PORT, mew=1.5, ls="none",
                zorder=6)  # fmt: skip
    for a, b in scene.scopes:
        ax.plot(*(np.stack([a, b]) @ E).T, color=SCOPE, lw=2.2, zorder=5.5)


def clip_segment(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray] | None:  # fmt: skip
    """The part of the segment a–b within the box [lo, hi] (Liang–Barsky); None when
    it misses the box."""
    d = b - a
    t0, t1 = 0.0, 1.0
    for k in range(3):
        for p, q in ((-d[k], a[k] - lo[k]), (d[k], hi[k] - a[k])):
            if p == 0:
                if q < 0:
                    return None
                continue
            r = q / p
            if p < 0:
                t0 = max(t0, r)
            else:
                t1 = min(t1, r)
            if t0 > t1:
                return None
    return a + t0 * d, a + t1 * d


def _inside_faces(ob: Any, lo: np.ndarray, hi: np.ndarray):
    """An obstacle's faces that lie within the box [lo, hi] (an ellipsoid finely
    meshed), as (vertices, faces): a surface cut at the view's edge, not flattened on it."""
    if ob.shape == "ellipsoid":
        V, F = ball(np.zeros(3), 1.0, 72)
        V = np.asarray(ob.center, np.float64) + V * np.asarray(ob.radii, np.float64)
    else:
        V, F = obstacle_mesh(ob, (lo + hi) / 2, 1.0)
    inside = np.all((V >= lo) & (V <= hi), 1)
    return V, F[np.all(inside[F], 1)]


def figure(scenes: Sequence[Scene], unit: str, title: str = "", size: float = 5.0, *,
           limits: np.ndarray | None = None, zoom: float = 1.0,
           table: tuple[Sequence[str], Sequence[Sequence[str]]] | None = None,
           notes: Sequence[str] = (), min_width: float = 0.0):  # fmt: skip
    """One 3-D panel per scene, side by side on common axis limits (so that arms compare
    by size; obstacles clipped to the view, :func:`clipped_note` added to the title), the
    legend below them, ``title`` wrapped to the width; laid out by hand in
    inches (constrained layout does not see a 3-D axes' labels). Returns the figure (save
    it with ``designopt.figures.save``).

    ``limits``: points (k, 3) the common view holds (default: the scenes' own); given,
    the arms, targets, marks and obstacles are clipped to it (a view zoomed on the
    patient: the caller's notes say what it holds).
    ``zoom``: the 3-D boxes' scale in their panels. ``table`` (column heads, rows) and
    ``notes`` (lines): numbers under the legend, a matplotlib table then text rows; with
    either, the clipping note joins the notes rather than the title. ``min_width``: the
    figure's least width (inches; the panels centred)."""
    import textwrap

    from designopt.figures.canvas import plt

    n = len(scenes)
    W = max(size * n + 0.5, min_width)
    note = clipped_note(scenes, unit, limits) if limits is None else ""
    below = table is not None or bool(notes)
    if below:
        notes = [*notes, note] if note else list(notes)
    else:
        title = "\n".join(x for x in (title, note) if x)
    lines = [ln for par in title.split("\n")
             for ln in textwrap.wrap(par, int(W * (10.5 if below else 12.5)),
                                     break_on_hyphens=False)]  # fmt: skip
    note_lines = [ln for par in notes for ln in textwrap.wrap(par, int(W * 14.5))]
    handles = list({h.get_label(): h for sc in scenes for h in legend_handles(sc)}.values())
    ncol = max(1, min(len(handles), int(W // 2.6)))
    rows = -(-len(handles) // ncol)
    rows_t = max((sc.title.count("\n") + 1 for sc in scenes if sc.title), default=1)
    top = 0.15 + 0.19 * len(lines) + 0.15 * rows_t  # the title, then the panels' own titles
    top += 0.5 * max(zoom - 1.0, 0.0) * size  # a zoomed box's title sits higher
    table_h = 0.24 * (len(table[1]) + 1) if table is not None else 0.0
    under = table_h + (0.1 if table is not None else 0.0) + 0.17 * len(note_lines)
    under += 0.1 if under else 0.0
    bottom = 0.55 + (0.22 * rows + 0.15 if handles else 0.0) + under  # x, y labels hang below
    H = size + top + bottom
    fig = plt.figure(figsize=(W, H))
    pts = np.vstack([scene_points(sc) for sc in scenes]) if limits is None else limits
    x0 = 0.5 * (W - size * n - 0.5)
    for k, sc in enumerate(scenes):
        ax = fig.add_axes(((x0 + 0.1 + k * size) / W, bottom / H, (size - 0.45) / W, size / H),
                          projection="3d")  # fmt: skip
        draw_3d(ax, sc, unit, legend=False, limits=pts, clip=limits is not None, zoom=zoom)
    if handles:
        fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, (0.1 + under) / H),
                   ncol=ncol, fontsize=8, framealpha=0.9)  # fmt: skip
    y = under - 0.05
    if table is not None:
        head, cells = table
        tab_ax = fig.add_axes((0.3 / W, (y - table_h) / H, (W - 0.6) / W, table_h / H))
        tab_ax.set_axis_off()
        tab = tab_ax.table(cellText=[list(r) for r in cells], colLabels=list(head),
                           cellLoc="center", bbox=(0, 0, 1, 1))  # fmt: skip
        tab.auto_set_font_size(False)
        tab.set_fontsize(8)
        chars = [max(len(str(x)) for x in col) + 2 for col in zip(head, *cells, strict=True)]
        for (r, c), cell in tab.get_celld().items():
            cell.set_width(chars[c] / sum(chars))
            cell.set_edgecolor("0.6")
            if r == 0:
                cell.set_facecolor("#eeeeee")
                cell.get_text().set_weight("bold")
        y -= table_h + 0.1
    for ln in note_lines:
        fig.text(0.3 / W, y / H, ln, fontsize=8, va="top")
        y -= 0.17
    if lines:
        fig.suptitle("\n".join(lines), fontsize=9.5 if not below else 11, y=1 - 0.1 / H,
                     va="top", weight="normal" if not below else "bold")  # fmt: skip
    return fig
