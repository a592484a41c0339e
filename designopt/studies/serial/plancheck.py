"""Plans that refuse the impossible (docs/planning.md, "What is refused"): checks of a
serial study's operating-room set-up, on the validated settings, in NumPy (they run
once, before any solve), and the lines said after a run and on ``eval``.

Refused before any solve (:func:`check`, a ``ValueError`` naming the key):

- a port point (an arm's or the camera's) farther from ``task.body_wall`` than the
  wall's own size in some design of the box (:func:`wall_size`; the port's entries at the corners of their box): a
  unit slip, said with the unit it looks like (``300`` in a chain in m: millimetres,
  write ``0.3``);
- an ``inside: true`` obstacle that lies entirely outside the body wall;
- a task region every sampled target of which lies inside the anatomy (the ``inside``
  obstacles);
- an arm's base inside the body wall (an ellipsoid or a mesh) or inside an ``inside``
  obstacle in some design of the box (the middle, the corners of the box of the
  variables its ``xyz`` names, and that box's points nearest each solid), or its base
  column (from the base to where the first joint acts: the base link, which
  ``links: auto``'s capsules leave out) passing through one.

Said after a run and on ``eval`` (:func:`warnings`): incision points closer than
``task.port_gap`` (:func:`port_gap`), and the share of the task region's targets that
lie inside each ``inside`` obstacle.

Signed distances are positive outside a solid: the wall's (:func:`wall_distance`; the
patient is the solid) and the obstacles' (:func:`obstacle_distance`), exact for every
shape (a mesh's by ``kinematics.sdf.exact_sdf``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.kinematics import task as tk
from designopt.kinematics.task import region_center_radius
from designopt.studies.serial import bodies
from designopt.studies.serial.placement import entry_range, ports_of
from designopt.studies.serial.settings import SerialSettings, entry_value, length_unit

HALFSPACE_FACTOR = 4.0
"""A half-space wall has no size of its own: a port point is measured from the task
region's centre instead, against this many times (the region's bounding radius + the
distance of its centre from the wall's plane)."""
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6}
"""Length units a unit slip is recognised between (their size in metres)."""
UNIT_NAMES = {"m": "metres", "cm": "centimetres", "mm": "millimetres", "um": "micrometres",
              "µm": "micrometres"}  # fmt: skip
PORT_GAP_M = 0.05
"""The default ``task.port_gap``: 5 cm, the common laparoscopic rule of thumb of trocars
at least about 5 cm apart (robotic systems' port-placement guides ask for 6-10 cm)."""
SAMPLES = 8192
"""Targets of the task region sampled (a fixed seed) for the anatomy checks; a points
file's targets are all taken."""
SEED = 0
BOX_LATTICE = 9
"""Points per edge of the lattice that stands for a box obstacle (the wall check)."""
CAPSULE_POINTS = 33
"""Points along a capsule obstacle's segment (the wall check)."""
ELLIPSOID_BISECTIONS = 100
"""Bisection steps of an ellipsoid wall's closest point (the bracket shrinks 2⁻¹⁰⁰)."""
SLIP = 5.0
"""A port entry is taken for a unit slip when its magnitude exceeds this many times the
wall's reach along its axis (an ellipsoid's |centre| + semi-axis, a mesh's largest
|coordinate|): a slip is a factor of 10 or more."""


# ------------------------------------------------------------------ signed distances


def _mesh_world(o: Any) -> tuple[np.ndarray, np.ndarray]:
    """A mesh obstacle's (or mesh wall's) vertices in the world (V, 3) and faces (F, 3)."""
    from designopt.kinematics import sdf

    v, f = sdf.load_mesh(o.file)
    R, t = o.pose()
    return np.asarray(v, np.float64) * float(o.scale) @ R.T + t, np.asarray(f, np.int64)


def _ellipsoid_distance(y: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The distance (n,) of points y (n, 3) (the ellipsoid's frame) from the surface of
    the ellipsoid of semi-axes a: the Lagrange condition x_i = a_i² y_i / (a_i² + t) of
    the closest point, t by bisection on the bracket of ``kinematics.wall``."""
    a = np.broadcast_to(np.asarray(a, np.float64), y.shape)
    a2 = a * a
    i = np.argmin(a, -1)[:, None]
    amin = np.take_along_axis(a, i, -1)[:, 0]
    ymin = np.abs(np.take_along_axis(y, i, -1)[:, 0])
    lo = -(amin**2) + amin * ymin
    hi = -(amin**2) + np.linalg.norm(a * y, axis=-1)
    tiny = np.finfo(np.float64).tiny

    def g(t: np.ndarray) -> np.ndarray:
        den = np.maximum(a2 + t[:, None], tiny)
        return np.sum((a * y / den) ** 2, -1) - 1.0

    for _ in range(ELLIPSOID_BISECTIONS):
        mid = 0.5 * (lo + hi)
        up = g(mid) > 0
        lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
    t = 0.5 * (lo + hi)
    x = a2 * y / np.maximum(a2 + t[:, None], tiny)
    return np.linalg.norm(y - x, axis=-1)


def wall_distance(wall: Any, P: Any) -> np.ndarray:
    """The signed distance (n,) of points P (n, 3) from the body wall's surface: positive
    outside the patient, negative inside."""
    P = np.asarray(P, np.float64).reshape(-1, 3)
    if wall.shape == "halfspace":
        return (P - np.asarray(wall.point)) @ np.asarray(wall.unit_normal())
    if wall.shape == "ellipsoid":
        y = P - np.asarray(wall.center, np.float64)
        a = np.asarray(wall.radii, np.float64)
        d = _ellipsoid_distance(y, a)
        return np.where(np.sum((y / a) ** 2, -1) < 1.0, -d, d)
    from designopt.kinematics import sdf

    v, f = _mesh_world(wall)
    return sdf.exact_sdf(v, f, P)


def wall_size(wall: Any, region: Any = None) -> tuple[float, str]:
    """(the wall's size, what it is): the diagonal of an ellipsoid's or a mesh's bounding
    box; for a half-space :data:`HALFSPACE_FACTOR` × (the task region's bounding
    radius + its centre's distance from the plane)."""
    if wall.shape == "ellipsoid":
        return float(2 * np.linalg.norm(wall.radii)), "its bounding box's diagonal"
    if wall.shape == "mesh":
        v, _ = _mesh_world(wall)
        return float(np.linalg.norm(v.max(0) - v.min(0))), "its bounding box's diagonal"
    c, r = region_center_radius(region)
    h = abs(float(wall_distance(wall, c[None])[0]))
    return HALFSPACE_FACTOR * (r + h), (f"{HALFSPACE_FACTOR:g} × (the task region's radius + "
                                        "its distance from the plane)")  # fmt: skip


def _segment_distance(P: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = b - a
    dd = float(d @ d)
    t = np.zeros(len(P)) if dd == 0 else np.clip((P - a) @ d / dd, 0.0, 1.0)
    return np.linalg.norm(P - a - t[:, None] * d, axis=-1)


def obstacle_distance(o: Any, P: Any) -> np.ndarray:
    """The signed distance (n,) of points P (n, 3) from obstacle ``o``: negative inside."""
    P = np.asarray(P, np.float64).reshape(-1, 3)
    if o.shape == "ball":
        return np.linalg.norm(P - np.asarray(o.center), axis=-1) - o.radius
    if o.shape == "capsule":
        return _segment_distance(P, np.asarray(o.a, np.float64), np.asarray(o.b, np.float64)) \
            - o.radius  # fmt: skip
    if o.shape == "box":
        q = np.abs(P - np.asarray(o.center)) - np.asarray(o.size) / 2
        return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(-1), 0.0)
    if o.shape == "halfspace":
        return (P - np.asarray(o.point)) @ np.asarray(o.unit_normal())
    from designopt.kinematics import sdf

    v, f = _mesh_world(o)
    return sdf.exact_sdf(v, f, P)


def _inside_obstacles(s: SerialSettings) -> list[tuple[int, Any]]:
    c = s.collision
    return [(i, o) for i, o in enumerate(c.obstacles if c is not None else []) if o.inside]


# ------------------------------------------------------------------ the task's samples


def region_samples(region: Any, n: int = SAMPLES, seed: int = SEED) -> np.ndarray:
    """n points (n, 3) uniform in the task region (a points file: its targets), from a
    NumPy generator of ``seed``: the targets the anatomy checks count."""
    if isinstance(region, tk.Points):
        return np.asarray(region.xyz(), np.float64)
    rng = np.random.default_rng(seed)
    u = rng.uniform(size=(n, 3))
    if isinstance(region, tk.Box):
        return np.asarray(region.center) + (u - 0.5) * np.asarray(region.size)
    if isinstance(region, tk.Ball):
        g = rng.normal(size=(n, 3))
        d = g / np.linalg.norm(g, axis=-1, keepdims=True)
        return np.asarray(region.center) + region.radius * np.cbrt(u[:, :1]) * d
    frame = tk._frame(region.axis)
    if isinstance(region, tk.Cylinder):
        r = region.radius * np.sqrt(u[:, 0])
        t = 2 * np.pi * u[:, 1]
        local = np.stack([r * np.cos(t), r * np.sin(t), (u[:, 2] - 0.5) * region.height], -1)
        return np.asarray(region.center) + local @ np.asarray(frame).T
    d0, d1 = region.depth  # a cone: axial depth of density ∝ s²
    sd = np.cbrt(d0**3 + u[:, 0] * (d1**3 - d0**3))
    r = sd * math.tan(math.radians(region.half_angle)) * np.sqrt(u[:, 1])
    t = 2 * np.pi * u[:, 2]
    local = np.stack([r * np.cos(t), r * np.sin(t), sd], -1)
    return np.asarray(region.apex) + local @ np.asarray(frame).T


_SHARES: dict[str, dict[int, np.ndarray]] = {}


def _inside_masks(s: SerialSettings) -> dict[int, np.ndarray]:
    """{obstacle index: whether each sampled target (:func:`region_samples`) lies inside
    it} for every ``inside`` obstacle (kept per task region and obstacles: a front's
    designs share them)."""
    obs = _inside_obstacles(s)
    if s.task is None or not obs:
        return {}
    key = s.task.region.model_dump_json() + "|" + "|".join(o.model_dump_json() for _, o in obs)
    if key not in _SHARES:
        P = region_samples(s.task.region)
        _SHARES.clear()  # one set-up at a time
        _SHARES[key] = {i: obstacle_distance(o, P) < 0 for i, o in obs}
    return _SHARES[key]


def inside_shares(s: SerialSettings) -> dict[int, float]:
    """{obstacle index: the share of the task region's sampled targets
    (:func:`region_samples`) inside it} for every ``inside`` obstacle."""
    return {i: float(np.mean(m)) for i, m in _inside_masks(s).items()}


# ------------------------------------------------------------------ the design box


def _corners(s: SerialSettings, entries: Sequence[float | str]) -> np.ndarray:
    """The corners (K, 3) of the box the entries span over the design box."""
    r = [entry_range(s, v) for v in entries]
    return np.unique(np.array(list(itertools.product(*r)), np.float64), axis=0)


def _designs(s: SerialSettings, entries: Sequence[float | str]) -> list[dict[str, float]]:
    """The middle of the design box and the corners of the box of the variables the
    entries name (the other variables at their middle; at most 6 named: 64 corners, more
    named: the middle and 64 random designs of a fixed seed)."""
    mid = {k: (float(lo) + float(hi)) / 2 for k, (lo, hi) in s.variables.items()}
    names = sorted({v.removeprefix("-") for v in entries if isinstance(v, str)
                    and v.removeprefix("-") in s.variables})  # fmt: skip
    if not names:
        return [mid]
    lo = np.array([float(s.variables[k][0]) for k in names])
    hi = np.array([float(s.variables[k][1]) for k in names])
    if len(names) <= 6:
        u = np.array(list(itertools.product([0.0, 1.0], repeat=len(names))))
    else:
        u = np.random.default_rng(SEED).uniform(size=(64, len(names)))
    return [mid] + [mid | dict(zip(names, (lo + w * (hi - lo)).tolist(), strict=True)) for w in u]


# ------------------------------------------------------------------ the refusals


def check(s: SerialSettings) -> None:
    """ValueError ``"<key>: <why>"`` for a set-up no design can make sense of (module
    docstring): a port farther from the body wall than the wall's size (a unit slip), an
    ``inside`` obstacle outside the wall, a task region entirely inside the anatomy, an
    arm's base inside the patient."""
    if s.task is None:
        return
    _check_port_units(s)
    _check_anatomy_in_wall(s)
    _check_region_in_anatomy(s)
    _check_bases(s)


def _port_key(s: SerialSettings, k: int) -> str:
    arm = None if s.arms is None else s.arms[k]
    return "task.port" if arm is None or arm.port is None else f"arms.{k}.port"


def _fmt(p: Any) -> str:
    return "[" + ", ".join(f"{float(v):.4g}" for v in np.asarray(p, np.float64).reshape(-1)) + "]"


def _far(s: SerialSettings, corners: np.ndarray) -> np.ndarray:
    """How far (K,) each port point lies: from the wall's surface (an ellipsoid, a mesh),
    from the task region's centre (a half-space)."""
    wall = s.task.body_wall  # type: ignore[union-attr]
    if wall.shape == "halfspace":
        c, _ = region_center_radius(s.task.region)  # type: ignore[union-attr]
        return np.linalg.norm(corners - c, axis=-1)
    return np.abs(wall_distance(wall, corners))


def _slip(s: SerialSettings, entries: Sequence[float | str], size: float,
          bound: np.ndarray) -> tuple[list[int], float, str] | None:  # fmt: skip
    """(the entries to rescale, the factor, the unit they look like) when the port's
    entries of magnitude above :data:`SLIP` × ``bound`` (the wall's reach along each
    axis), rescaled from a smaller unit to the chain's, bring every corner within
    ``size`` of the wall."""
    u = length_unit(s)
    big = [i for i, v in enumerate(entries)
           if max(map(abs, entry_range(s, v))) > SLIP * bound[i]]  # fmt: skip
    if not big:
        return None
    here = UNITS.get(u)
    cands = [(w, f / here) for w, f in UNITS.items() if here is not None and f < here] \
        if here is not None else [("mm", 1e-3), ("cm", 1e-2)]  # fmt: skip
    for w, f in sorted(cands, key=lambda c: -c[1]):  # the nearest unit first: cm before mm
        if w == "µm":
            continue
        r = [entry_range(s, v) for v in entries]
        r = [(a * f, b * f) if i in big else (a, b) for i, (a, b) in enumerate(r)]
        corners = np.array(list(itertools.product(*r)), np.float64)
        if np.all(_far(s, corners) <= size):
            return big, f, w
    return None


def _num(v: float) -> str:
    return f"{v:.6g}"


def _check_port_units(s: SerialSettings) -> None:
    """A port point farther from the body wall than the wall's size in a corner of the
    box its entries span: refused, with the unit it looks like when one fits."""
    wall = s.task.body_wall  # type: ignore[union-attr]
    if wall is None:
        return
    size, what = wall_size(wall, s.task.region)  # type: ignore[union-attr]
    u = length_unit(s)
    if wall.shape == "ellipsoid":
        bound = np.abs(wall.center) + np.asarray(wall.radii)
    elif wall.shape == "mesh":
        bound = np.max(np.abs(_mesh_world(wall)[0]), 0)
    else:
        c, _ = region_center_radius(s.task.region)  # type: ignore[union-attr]
        bound = np.abs(c) + size
    cam = s.task.camera  # type: ignore[union-attr]
    rows = [(_port_key(s, k), p) for k, p in enumerate(s.ports()) if k != s.camera_arm()]
    rows += [] if cam is None else [("task.camera.port", cam.port)]
    for key, entries in rows:
        if entries is None:
            continue
        corners = _corners(s, entries)
        d = _far(s, corners)
        j = int(np.argmax(d))
        if d[j] <= size:
            continue
        frm = "the task region's centre" if wall.shape == "halfspace" else "task.body_wall"
        some = " in some designs of the box" if len(corners) > 1 else ""
        where = (f"the port {_fmt(corners[j])} lies {d[j]:.4g} {u} from {frm}{some}, "
                 f"farther than the wall's size ({size:.4g} {u}, {what})")  # fmt: skip
        slip = _slip(s, entries, size, bound)
        if slip is None:
            raise ValueError(f"{key}: {where}: check the port's coordinates and their unit "
                             f"(the chain's length unit is {u})")  # fmt: skip
        big, f, w = slip
        fixes = []
        for i in big:
            v = entries[i]
            if isinstance(v, str) and v.removeprefix("-") in s.variables:
                n = v.removeprefix("-")
                lo, hi = (float(x) for x in s.variables[n])
                fixes.append((f"variables.{n}", f"the box of {n} [{_num(lo)}, {_num(hi)}]",
                              f"[{_num(lo * f)}, {_num(hi * f)}]"))  # fmt: skip
            elif isinstance(v, str):
                n = v.removeprefix("-")
                x = float(s.fixed[n])
                fixes.append((f"fixed.{n}", f"the fixed value {n} = {_num(x)}", _num(x * f)))
            else:
                fixes.append((f"{key}.{i}", _num(float(v)), _num(float(v) * f)))
        names = UNIT_NAMES[w]
        unit = f"the chain's unit is {u}" if u in UNITS else \
            f"the chain's length unit is undeclared ({u}); if it is m"  # fmt: skip
        said = "; ".join(f"{a} looks like {names}: {unit}, write {b}" for _, a, b in fixes)
        raise ValueError(f"{fixes[0][0]}: {said} ({key}: {where}; a unit slip)")


def _check_anatomy_in_wall(s: SerialSettings) -> None:
    """An ``inside`` obstacle entirely outside the body wall: refused. A ball by its
    centre, a capsule by points along its segment, a box by a lattice (each point's
    distance less the radius and half the spacing: a bound), a mesh by its vertices and
    face centroids; an ``inside`` half-space is not checked (it is unbounded)."""
    wall = s.task.body_wall  # type: ignore[union-attr]
    if wall is None:
        return
    u = length_unit(s)
    for i, o in _inside_obstacles(s):
        if o.shape == "halfspace":
            continue
        if o.shape == "ball":
            P, pad = np.asarray([o.center], np.float64), o.radius
        elif o.shape == "capsule":
            a, b = np.asarray(o.a, np.float64), np.asarray(o.b, np.float64)
            t = np.linspace(0.0, 1.0, CAPSULE_POINTS)[:, None]
            P = a + t * (b - a)
            pad = o.radius + float(np.linalg.norm(b - a)) / (CAPSULE_POINTS - 1) / 2
        elif o.shape == "box":
            g = np.linspace(0.0, 1.0, BOX_LATTICE) - 0.5
            P = np.asarray(o.center) + np.stack(np.meshgrid(g, g, g, indexing="ij"),
                                                -1).reshape(-1, 3) * np.asarray(o.size)  # fmt: skip
            pad = float(np.linalg.norm(o.size)) / (BOX_LATTICE - 1) / 2
        else:
            v, f = _mesh_world(o)
            P, pad = np.concatenate([v, v[f].mean(1)]), 0.0
        gap = float(np.min(wall_distance(wall, P))) - pad
        if gap > 0:
            raise ValueError(
                f"collision.obstacles.{i}: marked inside: true (anatomy inside the patient) "
                f"but it lies entirely outside task.body_wall (at least {gap:.4g} {u} "
                "outside it): move it inside the wall, or drop inside: true for an obstacle "
                "outside the patient"
            )


def _check_region_in_anatomy(s: SerialSettings) -> None:
    """Every sampled target inside the anatomy: refused naming ``task.region``."""
    masks = _inside_masks(s)
    if not masks:
        return
    union = np.any(np.stack(list(masks.values())), 0)
    if not np.all(union):
        return
    whole = [i for i, m in masks.items() if np.all(m)]
    which = [i for i, m in masks.items() if np.any(m)]
    names = ", ".join(f"collision.obstacles.{i}" for i in (whole[:1] or which))
    n = len(union)
    raise ValueError(
        f"task.region: every one of its {n} sampled targets lies inside the anatomy "
        f"({names}, inside: true): the instrument can never reach them without entering "
        "it; move the region or the obstacle"
    )


def _probes(shape: Any, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Points of the box [lo, hi] nearest a solid (M, 3): its centre (an ellipsoid, a
    ball, a box: exact, the nearness is separable per axis) or points along its segment
    (a capsule) clamped into the box; for a mesh a 5³ lattice of the box and its
    vertices' mean clamped."""
    if shape.shape in ("ellipsoid", "ball", "box"):
        c = np.asarray(shape.center, np.float64)[None]
    elif shape.shape == "capsule":
        a, b = np.asarray(shape.a, np.float64), np.asarray(shape.b, np.float64)
        c = a + np.linspace(0.0, 1.0, CAPSULE_POINTS)[:, None] * (b - a)
    else:
        g = np.linspace(0.0, 1.0, 5)
        w = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
        c = np.concatenate([_mesh_world(shape)[0].mean(0)[None], lo + w * (hi - lo)])
    return np.clip(c, lo, hi)


def _check_bases(s: SerialSettings) -> None:
    """An arm's base origin inside the body wall (an ellipsoid or mesh wall: a half-space
    wall is unbounded, so a base beside the patient lies below its plane too) or inside
    an ``inside`` obstacle (not a half-space) in some design: refused naming
    ``arms.<k>.base``. The designs tried: :func:`_designs`, and, where each entry names
    its own variable (the bases then fill a box), the box's points nearest each solid
    (:func:`_probes`). Without arms the base is the world's origin (the key: the
    solid's)."""
    wall = s.task.body_wall  # type: ignore[union-attr]
    solids: list[tuple[str, str, Any, Any]] = []
    if wall is not None and wall.shape != "halfspace":
        solids.append(("task.body_wall", "task.body_wall (the patient)", wall,
                       lambda P: wall_distance(wall, P)))  # fmt: skip
    for i, o in _inside_obstacles(s):
        if o.shape != "halfspace":
            solids.append((f"collision.obstacles.{i}", f"collision.obstacles.{i} (inside: true)",
                           o, lambda P, o=o: obstacle_distance(o, P)))  # fmt: skip
    if not solids:
        return
    u = length_unit(s)
    rows = [(f"arms.{k}.base", a.base.xyz, a.base.rpy) for k, a in enumerate(s.arms)] \
        if s.arms else [(None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))]  # fmt: skip
    from designopt.studies.serial import setup

    tops = [_column_top(setup.arm_view(s, k)) for k in range(len(rows))] if setup.mixed(s) \
        else [_column_top(s)] * len(rows)  # each arm its own robot's column
    for (arm_key, xyz, rpy), top in zip(rows, tops, strict=True):
        var = [v.removeprefix("-") if isinstance(v, str) and v.removeprefix("-") in s.variables
               else None for v in xyz]  # fmt: skip
        named = sorted({n for n in var if n is not None})
        box = named and len(named) == sum(n is not None for n in var)
        designs = _designs(s, xyz)
        for solid_key, what, shape, sd in solids:
            key = arm_key or solid_key  # one arm: its base is the world's origin
            tried = list(designs)
            if box:
                lo, hi = (np.array(r) for r in zip(*(entry_range(s, v) for v in xyz),
                                                    strict=True))  # fmt: skip
                for p in _probes(shape, lo, hi):
                    tried.append(designs[0] | {n: (-p[i] if str(xyz[i]).startswith("-") else p[i])
                                               for i, n in enumerate(var) if n is not None})  # fmt: skip
            P = np.asarray([[entry_value(s, v, d) for v in xyz] for d in tried], np.float64)
            inside = sd(P) < 0
            if not np.any(inside) and top is not None:
                R = np.radians([[entry_value(s, v, d) for v in rpy] for d in tried])
                R = bodies.rpy_matrix(R[:, 0], R[:, 1], R[:, 2], np)  # (K, 3, 3)
                f = np.linspace(0.0, 1.0, CAPSULE_POINTS)
                col = P[:, None] + f[None, :, None] * (R @ top)[:, None]  # (K, T, 3)
                flat = col.reshape(-1, 3)
                near = _in_bounds(shape, flat)  # the rest is outside: no distance needed
                through = np.zeros(len(flat), bool)
                if near.any():
                    through[near] = sd(flat[near]) < 0
                through = through.reshape(col.shape[:2])
                if np.any(through):
                    j = int(np.argmax(through.any(1)))
                    c = col[j, int(np.argmax(through[j]))]
                    at = ", ".join(f"{n} = {tried[j][n]:.4g}" for n in named)
                    every = "in every design of the box" if np.all(through.any(1)) else \
                        f"in some designs of the box (e.g. {at})"  # fmt: skip
                    fix = f"narrow the box of {', '.join(named)}" if named and not \
                        np.all(through.any(1)) else "move the base"  # fmt: skip
                    raise ValueError(
                        f"{arm_key or solid_key}: the arm's base column (from the base at "
                        f"{_fmt(P[j])} {u} to its first joint, {np.linalg.norm(top):.4g} {u} "
                        f"long) passes through {what} at {_fmt(c)} {u} {every}; a robot "
                        f"stands outside the patient: {fix}"
                    )
            if not np.any(inside):
                continue
            j = int(np.argmax(inside))
            at = ", ".join(f"{n} = {tried[j][n]:.4g}" for n in named)
            every = "in every design of the box" if np.all(inside) else \
                f"in some designs of the box (e.g. {at})"  # fmt: skip
            whose = "the arm's base" if s.arms else \
                "the arm's base (the world's origin: one arm's base frame is the world)"  # fmt: skip
            fix = f"narrow the box of {', '.join(named)}" if named and not np.all(inside) \
                else "move it"  # fmt: skip
            raise ValueError(
                f"{key}: {whose} stands inside {what} {every}: at {_fmt(P[j])} {u}; a "
                f"robot's base stands outside the patient: {fix}"
            )


def _in_bounds(shape: Any, P: np.ndarray) -> np.ndarray:
    """(K,) bool: the points P (K, 3) within a box that holds the solid ``shape`` (a
    mesh's vertices' box, an ellipsoid's, a ball's, a capsule's; a box's bounding ball);
    every point of a half-space or another shape."""
    kind = shape.shape
    if kind == "mesh":
        V = _mesh_world(shape)[0]
        lo, hi = V.min(0), V.max(0)
    elif kind in ("ellipsoid", "ball", "box"):
        c = np.asarray(shape.center, np.float64)
        r = (np.asarray(shape.radii, np.float64) if kind == "ellipsoid" else
             float(shape.radius) if kind == "ball" else
             0.5 * float(np.linalg.norm(shape.size)))  # fmt: skip
        lo, hi = c - r, c + r
    elif kind == "capsule":
        ab = np.stack([np.asarray(shape.a, np.float64), np.asarray(shape.b, np.float64)])
        lo, hi = ab.min(0) - float(shape.radius), ab.max(0) + float(shape.radius)
    else:
        return np.ones(len(P), bool)
    eps = 1e-9 * (1.0 + float(np.max(np.abs(hi - lo))))
    return np.all((P >= lo - eps) & (P <= hi + eps), -1)


def _column_top(s: SerialSettings) -> np.ndarray | None:
    """Where the chain's first joint acts in the base frame (``bodies.base_column``),
    None when it acts at the base (no column)."""
    from designopt.studies.serial.mechanism import build

    top = bodies.base_column(s, build(s))
    return None if float(np.linalg.norm(top)) <= 1e-12 else top


# ------------------------------------------------------------------ after a run


def port_gap(s: SerialSettings) -> float | None:
    """The least distance between two incision points (the chain's length unit):
    ``task.port_gap``, else :data:`PORT_GAP_M` in the chain's unit when it is one of
    :data:`UNITS` (None: an undeclared unit, no check); None also for 0."""
    if s.task is None:
        return None
    g = getattr(s.task, "port_gap", None)
    if g is None:
        here = UNITS.get(length_unit(s))
        g = None if here is None else PORT_GAP_M / here
    return None if g is None or g <= 0 else float(g)


def incisions(s: SerialSettings, final: Mapping[str, Any]) -> np.ndarray | None:
    """The incision points (A, 3) of the design ``final`` holds: its ``ports`` (the
    final record's placement: the ports projected onto the body wall), else computed
    from its design ``x`` (the ports' entries at x, projected as the run projects them);
    None without ports or a design."""
    ports = s.ports() if s.task is not None else [None]
    if any(p is None for p in ports):
        return None
    if "ports" in final:
        p = np.asarray(final["ports"], np.float64)
        if p.size == 3 * len(ports):
            return p.reshape(-1, 3)
    x = final.get("x")
    if x is None:
        return None
    xv = np.asarray(x, np.float64).reshape(-1)
    if len(xv) != len(s.variables):
        return None
    design = dict(zip(s.variables, xv.tolist(), strict=True))
    return np.stack([ports_of(s, k, [design])[0] for k in range(len(ports))])


def camera_incision(s: SerialSettings, final: Mapping[str, Any]) -> np.ndarray | None:
    """The camera's incision point (3,) of the design ``final`` holds: its ``camera``
    (the final record's placement), else computed from its design ``x``; None without a
    camera or a design."""
    if s.task is None or s.task.camera is None:
        return None
    if "camera" in final:
        return np.asarray(final["camera"], np.float64).reshape(-1)[:3]
    x = final.get("x")
    if x is None or np.asarray(x).size != len(s.variables):
        return None
    from designopt.studies.serial.placement import camera_at

    return camera_at(s, np.asarray(x, np.float64).reshape(1, -1))[0, :3]


def warnings(s: SerialSettings, final: Mapping[str, Any]) -> list[str]:
    """Lines for a run's final design (and each design ``eval`` scores): incision points
    closer than :func:`port_gap`, and the share of the task region's targets inside each
    ``inside`` obstacle (when above 0)."""
    if s.task is None:
        return []
    out = []
    u = length_unit(s)
    g = port_gap(s)
    p = incisions(s, final) if g is not None else None
    keep = list(s.instrument_arms()) if p is not None and s.arms is not None else None
    if keep is not None:
        p = p[np.asarray(keep)]  # type: ignore[index]  # the camera arm's port is the camera's
    if p is not None and s.shared_port():
        p, keep = p[:1], (keep or [0])[:1]  # one task.port, which the arms share
    names = [] if p is None else [f"arm {k}" if s.arms is not None else "the port"
                                  for k in (keep or range(len(p)))]  # fmt: skip
    cam = None if g is None else camera_incision(s, final)
    if cam is not None:  # the endoscope's incision point
        p = cam[None] if p is None else np.concatenate([p, cam[None]])
        names.append("the camera")
    if p is not None and len(p) > 1:
        for i, j in itertools.combinations(range(len(p)), 2):
            d = float(np.linalg.norm(p[i] - p[j]))
            if d < g:  # type: ignore[operator]
                arms = names[i].startswith("arm ") and names[j].startswith("arm ")
                who = f"arms {names[i][4:]} and {names[j][4:]}" if arms else \
                    f"{names[i]} and {names[j]}"  # fmt: skip
                out.append(f"task.port_gap: the incision points of {who} are {d:.3g} {u} "
                           f"apart, closer than {g:.3g} {u}: the trocars and the instruments "
                           "crowd each other (keep ports at least about 5 cm apart)")  # fmt: skip
    for i, share in inside_shares(s).items():
        if share > 0:
            n = len(_inside_masks(s)[i])
            out.append(f"{100 * share:.3g} % of the task region's targets ({n} sampled) lie "
                       f"inside collision.obstacles.{i}: they can never be reached")  # fmt: skip
    return out
