"""A URDF's own ``<collision>`` shapes as capsules, placed by a batched JAX forward kinematics
(``study.collision.links: urdf``).

- :func:`capsules` reads the ``<collision>`` elements of every link on an imported path
  (the base link and each path joint's child) and gives, in the link's frame, one capsule
  that contains each shape (the shape's ``<origin>`` applied):

  * ``sphere``: the ball itself (a = b = centre, the sphere's radius);
  * ``cylinder`` (radius r, length l along its origin's z): the segment from −l/2 to +l/2
    on the axis, radius r. A point of the cylinder has its axial coordinate in
    [−l/2, l/2], so its nearest point on the segment is its foot on the axis, and its
    distance is its radial distance ≤ r;
  * ``box`` (size): the segment joining the centres of the two faces across the longest
    side L (from −L/2 to +L/2 on that axis), radius half the diagonal of the two shorter
    sides, √(s₁² + s₂²)/2. A point of the box projects inside the segment, so its
    distance is its distance to the axis, at most the cross-section's half diagonal. This
    radius is the least any capsule on that axis can have (the four long edges lie at
    exactly that distance), and with it the segment cannot be shorter (the corners sit at
    its ends);
  * ``capsule`` (radius, length along z: an extension some URDF tools read): itself;
  * ``mesh`` (after its ``scale``): on the vertices' principal axis (PCA) through their
    centroid, the least radius d = the largest distance of a vertex from that axis, and
    the shortest segment on the axis within d of every vertex (each end pulled in as far
    as every vertex allows); the radius is then recomputed as the largest distance of a
    vertex from the final segment, so every vertex lies within it by construction (to the
    rounding of one distance). A capsule is convex, so it holds the vertices' convex hull
    and with it every triangle of the mesh.

  A mesh file is found as the project's URDF drawings find it (:func:`resolve_mesh`). A
  mesh that cannot be found or read, or a shape whose numbers cannot be read, is a
  ``ValueError`` that names the link and the file (the study makes it a config error).
- :func:`link_frames` gives the links' 4×4 transforms in the base frame for designs X
  (M, D) and joints q (C, n_active): the URDF rule T ← T · Trans(xyz) · Rz(yaw) Ry(pitch)
  Rx(roll) · Motion(axis, q_joint) along the path, design-dependent origins through the
  same bindings (and the same ``length`` semantics) as :func:`urdf.lower`, mimic joints
  q = multiplier · q_master + offset, prismatic joints a translation along the unit axis,
  continuous ones as revolute. Pure jnp: it traces under ``jit``/``vmap``/``grad``.
- :func:`world_capsules` places every capsule by its link's frame.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from designopt.kinematics.urdf import MOVABLE, Bindings, Imported, UJoint, _origin_lins, rpy_matrix


@dataclass(frozen=True, eq=False)
class LinkCapsule:
    """A capsule in ``link``'s frame: the points within ``radius`` of the segment a–b."""

    link: str
    a: np.ndarray  # (3,)
    b: np.ndarray  # (3,)
    radius: float
    kind: str = ""  # the shape it bounds: sphere, cylinder, box, capsule or mesh
    filename: str = ""  # a mesh's filename as written


# ------------------------------------------------------------------------ meshes


def resolve_mesh(filename: str, urdf_path: str | os.PathLike | None) -> Path | None:
    """The file a mesh ``filename`` names, or None when none exists: ``package://PKG/rest``
    in each folder of ``$ROS_PACKAGE_PATH`` (``D/PKG/rest``, or ``D/rest`` when ``D`` is
    itself named PKG), then in the URDF's folder and each folder above it (likewise),
    then ``rest`` beside the URDF; ``file://`` and absolute paths as they are; a relative
    path from the URDF's folder (from the working directory without a URDF path)."""
    here = Path(urdf_path).resolve().parent if urdf_path else None
    cands: list[Path] = []
    if filename.startswith("package://"):
        pkg, _, rest = filename[len("package://") :].partition("/")
        for d in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
            cands += [Path(d) / pkg / rest] + ([Path(d) / rest] if Path(d).name == pkg else [])
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


def _mesh_vertices(link: str, filename: str, urdf_path) -> np.ndarray:
    """The vertices (k, 3) of a mesh file (as the file gives them); ValueError naming the
    link and the file when it cannot be found or read."""
    import trimesh

    path = resolve_mesh(filename, urdf_path)
    where = f"collision.links: the URDF's link {link!r}, <collision> mesh '{filename}'"
    if path is None:
        near = f" (looked beside {urdf_path} and in the folders above it" if urdf_path else " ("
        raise ValueError(f"{where}: no such file{near}; for package:// names, set "
                         "ROS_PACKAGE_PATH to the folder that holds the package)")  # fmt: skip
    try:
        m = trimesh.load(str(path), force="mesh")
        v = np.asarray(m.vertices, np.float64).reshape(-1, 3)
    except Exception as e:  # trimesh raises many kinds for an unreadable file
        raise ValueError(f"{where}: cannot read {path}: {e}") from None
    if len(v) == 0 or not np.all(np.isfinite(v)):
        raise ValueError(f"{where}: {path} has no (finite) vertices")
    return v


def bounding_capsule(points: ArrayLike) -> tuple[np.ndarray, np.ndarray, float]:
    """(a, b, r): a capsule holding every point of ``points`` (k, 3) (and so their convex
    hull). The axis is the points' principal axis through their centroid; the radius the
    least on that axis (the largest distance from it); each end of the segment pulled in
    as far as every point allows at that radius; the radius then recomputed from the
    final segment, so containment holds by construction."""
    P = np.asarray(points, np.float64).reshape(-1, 3)
    c = P.mean(0)
    D = P - c
    if len(P) > 1 and np.any(D):
        e = np.linalg.eigh(D.T @ D)[1][:, -1]  # the largest eigenvalue's eigenvector
    else:
        e = np.array([0.0, 0.0, 1.0])
    t = D @ e
    d = np.linalg.norm(D - t[:, None] * e, axis=1)  # distances from the axis
    r0 = float(d.max())
    s = np.sqrt(np.maximum(r0 * r0 - d * d, 0.0))
    # within r0 of [t0, t1] ⇔ t0 ≤ t_i + s_i and t1 ≥ t_i − s_i for every point i
    t0, t1 = float(np.min(t + s)), float(np.max(t - s))
    if t1 < t0:  # every point is within r0 of one point of the axis: a ball
        t0 = t1 = 0.5 * (t0 + t1)
    a, b = c + t0 * e, c + t1 * e
    return a, b, float(_seg_dist(P, a, b).max())


def _seg_dist(P: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances of the points P (k, 3) from the segment a–b."""
    d = b - a
    dd = float(d @ d)
    s = np.zeros(len(P)) if dd == 0.0 else np.clip((P - a) @ d / dd, 0.0, 1.0)
    return np.linalg.norm(P - (a + s[:, None] * d), axis=1)


# ------------------------------------------------------------------------ shapes


def _floats(raw: str | None, n: int, default: float | None, what: str) -> tuple[float, ...]:
    if raw is None:
        if default is None:
            raise ValueError(f"{what}: missing")
        return (default,) * n
    try:
        v = [float(x) for x in raw.replace(",", " ").split()]
    except ValueError:
        v = []
    if len(v) == 1 and n == 3 and what.endswith("scale"):  # scale="2": uniform
        v = v * 3
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise ValueError(
            f"{what}={raw!r}: not {'a finite number' if n == 1 else f'{n} finite numbers'}"
        )
    return tuple(v)


def _positive(el, attr: str, what: str, allow_zero: bool = False) -> float:
    (v,) = _floats(el.get(attr), 1, None, f"{what} {attr}")
    if v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{what} {attr}={v:g}: must be {'≥' if allow_zero else '>'} 0")
    return v


def _shape(link: str, col, urdf_path) -> LinkCapsule:
    """The capsule of one <collision> element in the link's frame."""
    from lxml import etree

    what = f'<link name="{link}"> <collision>'
    o = col.find("origin")
    xyz = _floats(None if o is None else o.get("xyz"), 3, 0.0, f"{what} <origin> xyz")
    rpy = _floats(None if o is None else o.get("rpy"), 3, 0.0, f"{what} <origin> rpy")
    R, p = rpy_matrix(*rpy), np.asarray(xyz)
    g = col.find("geometry")
    geo = None if g is None else next((c for c in g if isinstance(c.tag, str)), None)
    if geo is None:
        raise ValueError(f"{what}: no <geometry> shape")
    tag = etree.QName(geo).localname
    what = f"{what} <{tag}>"
    if tag == "sphere":
        r = _positive(geo, "radius", what, allow_zero=True)
        return LinkCapsule(link, p.copy(), p.copy(), r, "sphere")
    if tag in ("cylinder", "capsule"):
        r = _positive(geo, "radius", what, allow_zero=True)
        h = 0.5 * _positive(geo, "length", what, allow_zero=True)
        return LinkCapsule(link, p - h * R[:, 2], p + h * R[:, 2], r, tag)
    if tag == "box":
        size = _floats(geo.get("size"), 3, None, f"{what} size")
        if min(size) < 0:
            raise ValueError(f"{what} size={geo.get('size')!r}: must be ≥ 0")
        k = int(np.argmax(size))
        others = [size[i] for i in range(3) if i != k]
        r = 0.5 * math.hypot(*others)
        h = 0.5 * size[k]
        return LinkCapsule(link, p - h * R[:, k], p + h * R[:, k], r, "box")
    if tag == "mesh":
        fn = geo.get("filename")
        if not fn:
            raise ValueError(f"{what}: no filename")
        scale = np.asarray(_floats(geo.get("scale"), 3, 1.0, f"{what} scale"))
        V = _mesh_vertices(link, fn, urdf_path) * scale
        a, b, r = bounding_capsule(V @ R.T + p)
        return LinkCapsule(link, a, b, r, "mesh", fn)
    raise ValueError(f"{what}: unknown shape (known: box, cylinder, sphere, mesh, capsule)")


def path_links(imp: Imported) -> tuple[str, ...]:
    """The links on the imported path, base first: the base and each joint's child."""
    return (imp.base, *(j.child for j in imp.path))


def capsules(text: str, urdf_path: str | os.PathLike | None, imp: Imported) -> list[LinkCapsule]:
    """One capsule per ``<collision>`` element of every link on the path (module
    docstring), links in path order, each link's in file order; links without one are
    left out. ``urdf_path`` is where mesh paths are resolved from."""
    from lxml import etree

    root = etree.fromstring(text.encode("utf-8"))
    by_name: dict[str, list] = {}
    for el in root.findall("link"):
        by_name.setdefault(str(el.get("name")), []).append(el)
    out: list[LinkCapsule] = []
    for link in path_links(imp):
        for el in by_name.get(link, []):
            for col in el.findall("collision"):
                out.append(_shape(link, col, urdf_path))
    return out


# ------------------------------------------------------------------------ frames


def _lin(lin, x: Array) -> Array:
    """const + Σ scale·x[k] of a binding's linear form (one design x)."""
    c, xc = lin
    v = jnp.asarray(c, x.dtype)
    for k, s in xc:
        v = v + s * x[k]
    return v


def _rpy(r: Array, p: Array, y: Array) -> Array:
    """Rz(y) Ry(p) Rx(r) (3, 3)."""
    cr, sr, cp, sp, cy, sy = jnp.cos(r), jnp.sin(r), jnp.cos(p), jnp.sin(p), jnp.cos(y), jnp.sin(y)
    return jnp.stack([
        jnp.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr]),
        jnp.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr]),
        jnp.stack([-sp, cp * sr, cp * cr]),
    ])  # fmt: skip


def _axis_rot(axis: Sequence[float], q: Array) -> Array:
    """Rotation by q about the unit ``axis``: cos q · (I − a aᵀ) + sin q · [a]× + a aᵀ."""
    a = np.asarray(axis, np.float64)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    A = np.outer(a, a)
    dt = q.dtype
    return jnp.cos(q) * jnp.asarray(np.eye(3) - A, dt) + jnp.sin(q) * jnp.asarray(K, dt) + \
        jnp.asarray(A, dt)  # fmt: skip


def _joint_q(imp: Imported, j: UJoint, q: Array) -> Array:
    """The joint's value: its column of q, or its master's (a mimic joint)."""
    if j.mimic is None:
        return q[imp.active.index(j.name)]
    m, mult, off = j.mimic
    return mult * q[imp.active.index(m)] + off


def _frames_one(imp: Imported, bindings: Bindings, x: Array, q: Array, upto: int) -> list:
    """(R, p) of the path's links 0..upto (link 0 the base) for one design and one q."""
    dt = x.dtype
    where = imp.robot.where
    R, p = jnp.eye(3, dtype=dt), jnp.zeros(3, dt)
    out = [(R, p)]
    for j in imp.path[:upto]:
        xyz, rpy = _origin_lins(j, bindings, where)
        t = jnp.stack([_lin(v, x) for v in xyz])
        if any(xc for _, xc in rpy):
            Ro = _rpy(*(_lin(v, x) for v in rpy))
        else:
            Ro = jnp.asarray(rpy_matrix(*(c for c, _ in rpy)), dt)
        p = p + R @ t
        R = R @ Ro
        if j.type in MOVABLE:
            qj = _joint_q(imp, j, q)
            if j.type == "prismatic":
                p = p + R @ (qj * jnp.asarray(j.axis, dt))
            else:
                R = R @ _axis_rot(j.axis, qj)
        out.append((R, p))
    return out


def _homog(R: Array, p: Array) -> Array:
    top = jnp.concatenate([R, p[:, None]], 1)
    return jnp.concatenate([top, jnp.asarray([[0.0, 0.0, 0.0, 1.0]], R.dtype)], 0)


_COMPILED: dict = {}
_COMPILED_MAX = 64


def _compiled(imp: Imported, bindings: Bindings, idx: tuple[int, ...]):
    """The jitted (M, D), (C, n) → (M, C, len(idx), 4, 4) of one path, bindings and link
    selection, kept (a few dozen at most) so that eager calls compile once: op by op, the
    path's small operations would each compile on their first use."""
    bkey = tuple(sorted((k, (float(c), tuple((int(i), float(s)) for i, s in xc)))
                        for k, (c, xc) in bindings.items()))  # fmt: skip
    key = (id(imp), bkey, idx)
    hit = _COMPILED.get(key)
    if hit is not None and hit[0] is imp:
        return hit[1]
    b = dict(bkey)
    upto = max(idx, default=0)

    def one(x: Array, q: Array) -> Array:
        fr = _frames_one(imp, b, x, q, upto)
        if not idx:
            return jnp.zeros((0, 4, 4), x.dtype)
        return jnp.stack([_homog(*fr[i]) for i in idx])

    def run(X: Array, Q: Array) -> Array:
        return jax.vmap(lambda x: jax.vmap(lambda q: one(x, q))(Q))(X)

    fn = jax.jit(run)
    while len(_COMPILED) >= _COMPILED_MAX:
        _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[key] = (imp, fn)
    return fn


def _prep(imp: Imported, bindings: Bindings, X: ArrayLike, q: ArrayLike):
    X, q = jnp.asarray(X), jnp.asarray(q)
    dt = jnp.result_type(X, q)
    if not jnp.issubdtype(dt, jnp.floating):
        dt = jnp.result_type(float)
    X, q = X.astype(dt), q.astype(dt)
    single = (X.ndim == 1, q.ndim == 1)
    X = X[None] if X.ndim == 1 else X
    q = q[None] if q.ndim == 1 else q
    need = 1 + max((k for _, xc in bindings.values() for k, _ in xc), default=-1)
    if X.ndim != 2 or X.shape[1] < need:
        raise ValueError(f"X must have shape (M, D) with D ≥ {need} (the bindings' design "
                         f"columns), got {X.shape}")  # fmt: skip
    n = len(imp.active)
    if q.ndim != 2 or q.shape[1] != n:
        raise ValueError(f"q must have shape (C, {n}) (active joints), got {q.shape}")
    return X, q, single


def link_frames(
    imp: Imported, bindings: Bindings, X: ArrayLike, q: ArrayLike, links: Sequence[str]
) -> Array:
    """The base-frame 4×4 transforms of the named path ``links``: (M, C, len(links), 4, 4)
    for designs X (M, D) (design columns in kernel units, as :func:`urdf.lower` takes
    them) and active joints q (C, n_active); a 1-D X or q drops its axis."""
    order = path_links(imp)
    idx = []
    for lk in links:
        if lk not in order:
            raise ValueError(f"link '{lk}' is not on the path from '{imp.base}' to "
                             f"'{imp.tip}' (links: {', '.join(order)})")  # fmt: skip
        idx.append(order.index(lk))
    X, q, (sx, sq) = _prep(imp, bindings, X, q)
    T = _compiled(imp, bindings, tuple(idx))(X, q)
    if sq:
        T = T[:, 0]
    if sx:
        T = T[0]
    return T


def world_capsules(
    imp: Imported, bindings: Bindings, caps: Sequence[LinkCapsule], X: ArrayLike, q: ArrayLike
) -> tuple[Array, Array]:
    """The capsules placed in the base frame: (segments (..., K, 2, 3), radii (K,)) with
    the leading axes of :func:`link_frames` (M, C; a 1-D X or q drops its axis)."""
    links = list(dict.fromkeys(c.link for c in caps))
    T = link_frames(imp, bindings, X, q, links)
    dt = T.dtype
    which = np.array([links.index(c.link) for c in caps], np.int64)
    ends = jnp.asarray(np.array([[c.a, c.b] for c in caps], np.float64).reshape(-1, 2, 3), dt)
    Tk = T[..., which, :, :]  # (..., K, 4, 4)
    seg = jnp.einsum("...kij,kej->...kei", Tk[..., :3, :3], ends) + Tk[..., None, :3, 3]
    radii = jnp.asarray(np.array([c.radius for c in caps], np.float64), dt)
    return seg, radii
