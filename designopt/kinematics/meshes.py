"""A URDF's visual geometry placed by forward kinematics, for drawings (docs/urdf.md,
"Drawing the robot").

- :func:`visuals` reads every ``<link><visual>`` of the URDF text: meshes (STL, DAE, OBJ,
  … whatever trimesh reads) and the primitives ``box``, ``cylinder`` and ``sphere``, each
  with its ``<origin>`` and the mesh's ``scale``;
- :func:`resolve` finds a mesh file: ``package://PKG/rest`` in ``$ROS_PACKAGE_PATH``, then
  in the URDF's folder and each folder above it (``A/PKG/rest``, or ``A/rest`` when ``A``
  is itself named PKG), then ``rest`` beside the URDF; ``file://`` and absolute paths as
  they are, relative ones from the URDF's folder;
- :func:`link_poses` places the links in the chain's base frame with NumPy: the URDF rule
  T = Trans(xyz) · Rz(yaw) Ry(pitch) Rx(roll) · Motion(axis, q) along the path, with the
  ``set`` numbers of a design written in (as ``urdf.export_text`` writes them), links
  hanging off the path by fixed joints included (above the base too);
- :func:`placed` gives each link's triangles (vertices in the base frame, faces),
  decimated by vertex clustering (:func:`decimate`) to a budget of triangles in all,
  shared in proportion to each mesh's size (none below :data:`KEEP`).

A mesh is drawn as the file gives it: a length that is a design variable moves the links
after it, but no mesh is stretched (``Placed.moved`` names the links whose own geometry
spans a changed origin, so a drawing can say so).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from designopt.kinematics.urdf import ANGLE_FIELDS, MOVABLE, Imported, UJoint, rpy_matrix

MAX_TRIANGLES = 20_000
"""Triangles of one robot's meshes in a drawing, all links together (decimated above)."""
KEEP = 64
"""A mesh of this many triangles or fewer is never decimated (a box keeps its 12): the
budget is shared among the meshes in proportion to their size, none below this."""


@dataclass(frozen=True)
class Visual:
    """One ``<visual>`` of a link: ``kind`` mesh, box, cylinder or sphere; ``origin``
    (4, 4) in the link frame; ``size`` the primitive's (box: x y z; cylinder: radius,
    length; sphere: radius); ``filename`` as written and ``scale`` (3,) for a mesh."""

    link: str
    kind: str
    origin: np.ndarray
    filename: str = ""
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    size: tuple[float, ...] = ()


def _floats(text: str | None, n: int, default: float) -> tuple[float, ...]:
    if text is None:
        return (default,) * n
    v = [float(x) for x in text.replace(",", " ").split()]
    if len(v) == 1 and n == 3:  # scale="2": uniform
        v = v * 3
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise ValueError(f"expected {n} finite numbers, got {text!r}")
    return tuple(v)


def _origin(el) -> np.ndarray:
    T = np.eye(4)
    if el is not None:
        xyz = _floats(el.get("xyz"), 3, 0.0)
        r, p, y = _floats(el.get("rpy"), 3, 0.0)
        T[:3, :3] = rpy_matrix(r, p, y)
        T[:3, 3] = xyz
    return T


def visuals(text: str) -> list[Visual]:
    """Every ``<visual>`` geometry of the URDF ``text``, link by link in file order (a
    visual whose numbers cannot be read is left out)."""
    from lxml import etree

    root = etree.fromstring(text.encode("utf-8"))
    out = []
    for link in root.findall("link"):
        for vis in link.findall("visual"):
            g = vis.find("geometry")
            if g is None or len(g) == 0:
                continue
            geo = g[0]
            tag = etree.QName(geo).localname if isinstance(geo.tag, str) else ""
            try:
                T = _origin(vis.find("origin"))
                if tag == "mesh" and geo.get("filename"):
                    v = Visual(link.get("name"), "mesh", T, geo.get("filename"),
                               _floats(geo.get("scale"), 3, 1.0))  # fmt: skip
                elif tag == "box":
                    v = Visual(link.get("name"), "box", T, size=_floats(geo.get("size"), 3, 0.0))
                elif tag == "cylinder":
                    v = Visual(link.get("name"), "cylinder", T,
                               size=(float(geo.get("radius")), float(geo.get("length"))))  # fmt: skip
                elif tag == "sphere":
                    v = Visual(link.get("name"), "sphere", T, size=(float(geo.get("radius")),))
                else:
                    continue
            except (TypeError, ValueError):
                continue
            out.append(v)
    return out


def resolve(filename: str, urdf_path: str | Path | None) -> Path | None:
    """The file a mesh ``filename`` names (module docstring), or None if none exists."""
    here = Path(urdf_path).resolve().parent if urdf_path else None
    cands: list[Path] = []
    if filename.startswith("package://"):
        pkg, _, rest = filename[len("package://") :].partition("/")
        for d in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
            cands += [Path(d) / pkg / rest, Path(d) / rest] if Path(d).name == pkg else \
                [Path(d) / pkg / rest]  # fmt: skip
        if here is not None:
            for a in (here, *here.parents):
                cands.append(a / rest if a.name == pkg else a / pkg / rest)
            cands.append(here / rest)
    elif filename.startswith("file://"):
        cands.append(Path(filename[len("file://") :]))
    else:
        p = Path(filename)
        cands.append(p if p.is_absolute() or here is None else here / p)
    return next((c for c in cands if c.is_file()), None)


@lru_cache(maxsize=64)
def _load_file(path: str, mtime: float) -> tuple[np.ndarray, np.ndarray] | None:
    import warnings

    import trimesh

    try:  # a drawing takes the file as it is: trimesh's and NumPy's warnings silenced here
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            m = trimesh.load(path, force="mesh")
    except Exception:  # trimesh raises many kinds for an unreadable file
        return None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        return None
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def geometry(v: Visual, urdf_path: str | Path | None) -> tuple[np.ndarray, np.ndarray] | None:
    """(vertices (k, 3) in the link frame, faces (m, 3)) of a visual: its origin and (a
    mesh) its scale applied; None when a mesh file is missing or unreadable."""
    import trimesh

    if v.kind == "mesh":
        p = resolve(v.filename, urdf_path)
        got = None if p is None else _load_file(str(p), p.stat().st_mtime)
        if got is None:
            return None
        V, F = got
        V = V * np.asarray(v.scale)
    else:
        prim = {"box": lambda s: trimesh.primitives.Box(extents=s),
                "cylinder": lambda s: trimesh.primitives.Cylinder(radius=s[0], height=s[1]),
                "sphere": lambda s: trimesh.primitives.Sphere(radius=s[0])}[v.kind](v.size)  # fmt: skip
        V, F = np.asarray(prim.vertices, np.float64), np.asarray(prim.faces, np.int64)
    return V @ v.origin[:3, :3].T + v.origin[:3, 3], F


def _rodrigues(axis: Sequence[float], a: float) -> np.ndarray:
    k = np.asarray(axis, np.float64)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * (K @ K)


def joint_transform(j: UJoint, values: Mapping[tuple[str, str], float], q: float) -> np.ndarray:
    """parent_T_child of joint ``j`` at joint value q (rad / length), with the ``set``
    numbers ``values`` {(joint, field): number (rad, file lengths)} written in."""
    xyz = np.asarray(j.xyz, np.float64)
    if (j.name, "length") in values:
        xyz = values[(j.name, "length")] * xyz / np.linalg.norm(xyz)
    for i, f in enumerate(("x", "y", "z")):
        if (j.name, f) in values:
            xyz[i] = values[(j.name, f)]
    rpy = [values.get((j.name, f), j.rpy[i]) for i, f in enumerate(ANGLE_FIELDS)]
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*rpy)
    T[:3, 3] = xyz
    M = np.eye(4)
    if j.type in ("revolute", "continuous"):
        M[:3, :3] = _rodrigues(j.axis, q)
    elif j.type == "prismatic":
        M[:3, 3] = np.asarray(j.axis) * q
    return T @ M


def link_poses(imp: Imported, values: Mapping[tuple[str, str], float],
               q: Sequence[float]) -> dict[str, np.ndarray]:  # fmt: skip
    """{link: base_T_link (4, 4)} at active joint values q: the links on the path and
    every link joined to one of them by fixed joints (above the base too); a movable
    joint off the path is not followed (its value is unknown)."""
    rob = imp.robot
    qa = dict(zip(imp.active, (float(x) for x in q), strict=True))
    on_path = {j.name for j in imp.path}

    def value(j: UJoint) -> float:
        if j.type not in MOVABLE:
            return 0.0
        if j.mimic is not None:
            m, mult, off = j.mimic
            return mult * qa.get(m, 0.0) + off
        return qa.get(j.name, 0.0)

    children: dict[str, list[UJoint]] = {}
    for j in rob.joints.values():
        children.setdefault(j.parent, []).append(j)
    parent = rob.parent_joint()
    poses = {imp.base: np.eye(4)}
    todo = [imp.base]
    while todo:
        link = todo.pop()
        T = poses[link]
        for j in children.get(link, []):
            if j.child not in poses and (j.name in on_path or j.type == "fixed"):
                poses[j.child] = T @ joint_transform(j, values, value(j))
                todo.append(j.child)
        pj = parent.get(link)
        if pj is not None and pj.type == "fixed" and pj.parent not in poses:
            poses[pj.parent] = T @ np.linalg.inv(joint_transform(pj, values, 0.0))
            todo.append(pj.parent)
    return poses


def decimate(V: np.ndarray, F: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ``target`` triangles by vertex clustering: vertices merged per cell of a
    cubic grid (the finest grid that meets the budget, by bisection), each cell's vertex
    their mean, faces that collapse dropped. Unchanged when already within budget; never
    empty (a target too small for any surface gives the coarsest grid that keeps one)."""
    if len(F) <= target:
        return V, F
    lo_c, ext = V.min(0), float(np.ptp(V, 0).max()) or 1.0

    def cluster(n: int) -> tuple[np.ndarray, np.ndarray]:
        key = np.floor((V - lo_c) / (ext / n)).astype(np.int64)
        _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        inv = inv.ravel()
        W = np.zeros((len(cnt), 3))
        np.add.at(W, inv, V)
        G = inv[F]
        G = G[(G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])]
        first = np.unique(np.sort(G, 1), axis=0, return_index=True)[1]  # no duplicates
        return W / cnt[:, None], G[np.sort(first)]

    n = 1
    while len(cluster(n)[1]) == 0 and n < 1 << 16:  # the coarsest grid with a surface
        n *= 2
    a, best = n, cluster(n)
    if len(best[1]) <= target:
        b = 2 * a
        while len(cluster(b)[1]) <= target and b < 1 << 16:
            a, b = b, 2 * b
        best = cluster(a)
        while b - a > 1:
            m = (a + b) // 2
            got = cluster(m)
            if len(got[1]) <= target:
                a, best = m, got
            else:
                b = m
    Vn, Fn = best
    used = np.unique(Fn)
    remap = np.full(len(Vn), -1)
    remap[used] = np.arange(len(used))
    return Vn[used], remap[Fn]


@dataclass
class Placed:
    """A robot's visual geometry in its base frame: ``meshes`` [(link, vertices (k, 3),
    faces (m, 3))], the ``missing`` mesh files (as written), ``triangles`` drawn and
    before decimation (``full``), and ``moved``: links whose own geometry spans an origin
    whose numbers differ from the file's (drawn unscaled)."""

    meshes: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    triangles: int = 0
    full: int = 0
    moved: list[str] = field(default_factory=list)


@lru_cache(maxsize=16)
def _geometry(text: str, urdf_path: str | None, max_triangles: int | None):
    """Every visual's (link, vertices, faces) in its link frame, decimated to
    ``max_triangles`` in all; the missing files; the triangles before decimation."""
    parts, missing = [], []
    for v in visuals(text):
        g = geometry(v, urdf_path)
        if g is None:
            missing.append(v.filename)
        else:
            parts.append((v.link, *g))
    full = sum(len(F) for _, _, F in parts)
    if max_triangles is not None and full > max_triangles:  # shared in proportion
        parts = [(lk, *decimate(V, F, max(max_triangles * len(F) // full, KEEP)))
                 for lk, V, F in parts]  # fmt: skip
    return tuple(parts), tuple(missing), full


def placed(imp: Imported, text: str, urdf_path: str | Path | None,
           values: Mapping[tuple[str, str], float], q: Sequence[float],
           max_triangles: int | None = MAX_TRIANGLES) -> Placed:  # fmt: skip
    """Every visual of the links :func:`link_poses` places, in the base frame, at active
    joints q with the ``set`` numbers ``values`` (rad, file lengths); decimated to
    ``max_triangles`` in all (None: as read). Files are read (and decimated) once."""
    poses = link_poses(imp, values, q)
    parts, missing, full = _geometry(text, None if urdf_path is None else str(urdf_path),
                                     max_triangles)  # fmt: skip
    out = Placed(full=full, missing=list(missing))
    for link, V, F in parts:
        if link in poses:
            T = poses[link]
            out.meshes.append((link, V @ T[:3, :3].T + T[:3, 3], F))
    out.triangles = sum(len(F) for _, _, F in out.meshes)
    changed = {jn for (jn, f), x in values.items() if _differs(imp, jn, f, x)}
    out.moved = sorted({imp.robot.joints[jn].parent for jn in changed}
                       & {lk for lk, *_ in out.meshes})  # fmt: skip
    return out


def _differs(imp: Imported, joint: str, fld: str, x: float) -> bool:
    """Whether the ``set`` number ``x`` of (joint, field) differs from the file's own."""
    return abs(original(imp, joint, fld) - x) > 1e-12 * max(1.0, abs(x))


def original(imp: Imported, joint: str, fld: str) -> float:
    """The file's own number of a ``set`` field (rad for angles, file lengths)."""
    j = imp.robot.joints[joint]
    if fld == "length":
        return float(np.linalg.norm(j.xyz))
    if fld in ("x", "y", "z"):
        return float(j.xyz["xyz".index(fld)])
    return float(j.rpy[ANGLE_FIELDS.index(fld)])
