"""Mesh obstacles: a closed triangle mesh's signed distance function (SDF) sampled once on
a grid on the host, then interpolated trilinearly in JAX (``study.collision.obstacles``,
``shape: mesh``; docs/task.md, "Mesh obstacles").

Host side (NumPy, float64)
--------------------------
* :func:`load_mesh` reads a file with trimesh and refuses one that cannot be read or is
  not watertight (every edge shared by exactly two faces); a watertight mesh with
  inverted or inconsistent winding is re-oriented (the inside of a closed surface is
  well defined), and refused if that fails.
* :func:`exact_sdf` is the exact signed distance, negative inside (trimesh's
  ``proximity.signed_distance`` has the opposite sign): the distance to the nearest
  triangle — the distance to its plane when the point projects inside it, else to the
  nearest of its edges — over every triangle that can be nearest (a triangle whose
  bounding sphere is farther than an upper bound of the distance is skipped, which
  changes nothing), in dense matrix products per block of points; the sign is that of
  (p − q)·N, q the nearest point and N the angle-weighted pseudo-normal of the feature q
  lies on (face, edge or vertex), exact for a closed, consistently oriented mesh
  (Bærentzen and Aanæs, "Signed distance computation using the angle weighted
  pseudonormal", IEEE TVCG 11(3), 2005). No ray casting.
* :func:`build_grid` samples it on ``resolution``³ points spanning the mesh's bounding box
  grown by ``padding`` on every side (default :data:`PAD_CELLS` cells), in the mesh's own
  frame after its scale. Cells may differ per axis (h_x, h_y, h_z); the padding is the
  same length on every side.
* :func:`mesh_grid` builds a file's grid at most once per process (kept in memory by
  :func:`grid_key`: the file's SHA-256, scale, resolution, padding and
  :data:`GRID_VERSION`) and keeps it on disk in the compilation cache's folder when one
  is configured (:func:`cache_folder`; the CLI's ``compile_cache``): written whole (a
  temporary file renamed), and loaded only when it holds the same key, the right shape
  and finite numbers; anything else is rebuilt and replaced.

JAX side (pure jnp, float32 or float64 from the caller, jit/vmap/grad)
----------------------------------------------------------------------
* :func:`grid_sdf`: trilinear interpolation. Error bound: the SDF is 1-Lipschitz, the
  interpolant is a convex combination Σ wᵢ f(vᵢ) of the cell's 8 corner values, so
  |I(p) − f(p)| ≤ Σ wᵢ |vᵢ − p| ≤ (Σ wᵢ |vᵢ − p|²)^½ = (Σₖ tₖ(1 − tₖ) hₖ²)^½ ≤ ½ |h|,
  half the cell's diagonal (√3/2 · h for cubic cells of side h). The bound is attained:
  for f = |p − c| (a point obstacle at a cell's centre c) every corner is √3 h/2 away.
  Outside the grid's box the value is the one at the nearest point q of the box plus the
  distance |p − q|: by the Lipschitz bound an upper bound of the SDF (up to the
  interpolation error at q). It is exact when p lies along the SDF's gradient from q and
  at most |p − q| + f(q) − (|p − q|² + f(q)²)^½ ≤ min(|p − q|, f(q)) too large, because
  the mesh lies inside the box (so every mesh point m has (p − q)·(m − q) ≤ 0 and
  |p − m|² ≥ |p − q|² + |q − m|²). Every point outside the box is at least the padding
  away from the mesh, so with padding ≥ (capsule radius + margin) a collision verdict
  never depends on a value outside the box.
* :func:`mesh_sdf`: the same at world points, through the mesh's pose (R, t) given as
  arrays (x_mesh = Rᵀ (x_world − t)): moving a mesh compiles nothing.
* :func:`capsule_mesh`: the capsule's signed distance, the least SDF over its centre line
  less its radius. The centre line is clipped to the grid's box and that part sampled at
  :func:`samples` evenly spaced points (a count fixed by the resolution: spacing ≤ the
  largest cell side), plus :data:`LINE_SAMPLES` evenly spaced points over the whole
  segment (its ends included; they carry a segment that misses the box). Where the exact
  minimum lies in the box: exact − ½|h| ≤ result ≤ exact + ½|h| + δ/2, δ the spacing of
  the samples in the box (≤ max h); never below exact − ½|h| anywhere. The gradient is
  that of the interpolated SDF at the best sample, carried to the ends by its parameter
  (the samples' parameters held fixed: the envelope theorem's gradient; it is the exact
  derivative of the result wherever the clipped part does not change, e.g. both ends in
  the box). The search over the samples runs on values only, in a loop over blocks of
  :data:`BLOCK` samples (memory of one block).

Several meshes stack into one pytree (:func:`stack`): ``grid`` (nm, G, G, G) with G the
largest resolution (a coarser grid fills its corner of the array; ``cells`` (nm,) says
how many cells per axis each uses), ``origin`` and ``cell`` (nm, 3), ``R`` (nm, 3, 3) and
``t`` (nm, 3). Only G and nm shape a compiled program.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import threading
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

DEFAULT_RESOLUTION = 64
"""Grid points per axis of a mesh obstacle's SDF unless its ``resolution`` says."""
MIN_RESOLUTION, MAX_RESOLUTION = 32, 128
"""The resolutions a mesh obstacle may ask for (128³ float64 values are 16 MiB)."""
PAD_CELLS = 4
"""The default padding of the grid's box around the mesh's bounding box, in cells."""
LINE_SAMPLES = 9
"""Evenly spaced samples over a whole centre line (ends included) in :func:`capsule_mesh`."""
BLOCK = 8
"""Samples evaluated together per step of :func:`capsule_mesh`'s loop."""

_BLOCK_SIZE = 128
"""Points per block of :func:`exact_sdf`'s culling (consecutive in Z-order)."""
_TIES = 4
"""Candidates per point measured directly after the expanded-square screening."""


# --------------------------------------------------------------------------- host: mesh


def load_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (k, 3) float64, faces (m, 3) int64) of a closed mesh file, outward
    oriented; ValueError naming the file when it cannot be read, has no faces, is not
    watertight or cannot be oriented. Read once per file version (path, mtime, size)."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as e:
        raise ValueError(f"cannot read {p}: {e.strerror or e}") from None
    return _load(str(p.resolve()), st.st_mtime_ns, st.st_size)


MESH_VERSION = 1
"""Part of a checked mesh's cache key (:func:`load_mesh`), with trimesh's version: raise it
when the checks or the repair change."""


def package_version(package: str) -> str:
    """An installed package's version (from its metadata: the package is not imported)."""
    from importlib import metadata

    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "-"


@lru_cache(maxsize=32)
def _load(path: str, mtime_ns: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """A checked mesh, from the cache folder when this file's bytes passed the checks
    before (``designopt-mesh-*.npz``: a warm command then neither imports trimesh, about
    0.4 s, nor reads and repairs the file again); else checked and kept there."""
    folder = cache_folder()
    file = key = None
    with contextlib.suppress(OSError):  # (a folder, unreadable: _checked says which)
        key = f"{MESH_VERSION}:{package_version('trimesh')}:{_content_hash(path, mtime_ns, size)}"
    if folder is not None and key is not None:
        file = folder / f"designopt-mesh-{hashlib.sha256(key.encode()).hexdigest()[:40]}.npz"
        try:
            with np.load(file, allow_pickle=False) as z:
                if str(z["key"]) == key:
                    v, f = np.array(z["v"], np.float64), np.array(z["f"], np.int64)
                    if v.ndim == 2 and v.shape[1] == 3 and f.ndim == 2 and f.shape[1] == 3:
                        v.flags.writeable = False
                        f.flags.writeable = False
                        return v, f
        except Exception:  # noqa: BLE001  (none yet, truncated, foreign: check the file)
            pass
    # trimesh's checks divide by a flat mesh's zero volume (NumPy's RuntimeWarnings) and
    # warn on odd files: silenced here only, so a refusal is the one line of its error
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        v, f = _checked(path)
    if file is not None and key is not None:
        _write_npz(file, key=np.array(key), v=v, f=f)
    return v, f


def _checked(path: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    if Path(path).is_dir():
        raise ValueError(f"{path} is a folder, not a mesh file")
    try:
        m = trimesh.load(path, force="mesh")
    except Exception as e:  # trimesh raises many kinds for an unreadable file
        raise ValueError(f"cannot read {path} as a mesh: {e}") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ValueError(f"cannot read {path} as a mesh: no triangles in it")
    v = np.asarray(m.vertices, np.float64)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{path}: the mesh has non-finite vertices")
    if not m.is_watertight:
        raise ValueError(f"{path}: the mesh is not watertight (some edge does not join "
                         "exactly two faces), so it has no inside; close it (e.g. fill its "
                         "holes in MeshLab or Blender) and export it again")  # fmt: skip
    size = float(np.linalg.norm(np.ptp(v, axis=0)))
    if not abs(float(m.volume)) > 1e-9 * size**3:
        raise ValueError(f"{path}: the mesh is closed but encloses no volume (a flat or "
                         "collapsed surface), so it has no inside")  # fmt: skip
    if not m.is_volume:
        trimesh.repair.fix_normals(m)  # consistent winding, outward normals
        if not m.is_volume:
            raise ValueError(f"{path}: the mesh is closed but its faces cannot be oriented "
                             "consistently (a non-manifold or self-touching surface)")  # fmt: skip
    v, f = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    v.flags.writeable = False
    f.flags.writeable = False
    return v, f


# --------------------------------------------------------------------------- host: SDF


@dataclass(frozen=True)
class _Tris:
    """Per-triangle data of a mesh for :func:`exact_sdf` (float64)."""

    V: np.ndarray  # (T, 3, 3) corners V0, V1, V2
    E: np.ndarray  # (T, 3, 3) edges V1 − V0, V2 − V1, V0 − V2
    EE: np.ndarray  # (T, 3) squared edge lengths
    N: np.ndarray  # (T, 3) unit normals (0 for a degenerate triangle)
    M: np.ndarray  # (T, 3, 3) in-plane inward edge normals N × Eᵢ
    ok: np.ndarray  # (T,) non-degenerate
    centre: np.ndarray  # (T, 3) centroids
    radius: np.ndarray  # (T,) bounding-sphere radii about the centroid
    edge_n: np.ndarray  # (T, 3, 3) the pseudo-normal of each edge (sum of its faces' normals)
    vert_n: np.ndarray  # (T, 3, 3) the angle-weighted pseudo-normal of each corner


def _tris(v: np.ndarray, f: np.ndarray) -> _Tris:
    V = v[f]
    E = np.roll(V, -1, axis=1) - V
    EE = np.einsum("tij,tij->ti", E, E)
    n = np.cross(E[:, 0], -E[:, 2])
    nn = np.linalg.norm(n, axis=1)
    ok = nn > 1e-300
    N = np.where(ok[:, None], n / np.where(ok, nn, 1.0)[:, None], 0.0)
    M = np.cross(N[:, None, :], E)
    centre = V.mean(1)
    radius = np.linalg.norm(V - centre[:, None], axis=2).max(1)
    # edge pseudo-normals: the (unit) normals of the two faces sharing each edge, summed
    a, b = f, np.roll(f, -1, axis=1)
    key = np.sort(np.stack([a, b], -1).reshape(-1, 2), axis=1)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    en = np.zeros((inv.max() + 1, 3))
    np.add.at(en, inv, np.repeat(N, 3, axis=0))
    edge_n = en[inv].reshape(-1, 3, 3)
    # vertex pseudo-normals: the face normals weighted by the face's angle at the vertex
    u = E / np.sqrt(np.maximum(EE, 1e-300))[..., None]
    cosang = -np.einsum("tij,tij->ti", u, np.roll(u, 1, axis=1))  # angle at corner i
    ang = np.arccos(np.clip(cosang, -1.0, 1.0))
    vn = np.zeros((len(v), 3))
    np.add.at(vn, f.ravel(), (ang[..., None] * N[:, None, :]).reshape(-1, 3))
    return _Tris(V, E, EE, N, M, ok, centre, radius, edge_n, vn[f])


def _nearest(P: np.ndarray, t: _Tris, J: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The nearest triangle (P,) of each point of P among ``J``: all pairs screened at
    once in matrix products (squares expanded, coordinates shifted by ``c`` to keep them
    small), then the :data:`_TIES` best of each point measured directly (the expanded
    squares round by ~1e-16 of the block's size squared, which can reorder near ties)."""
    p = P - c
    pp = np.einsum("ij,ij->i", p, p)[:, None]
    # each point's own bound: its distance to the nearest centroid (centroids lie on the
    # mesh); keep the triangles whose bounding sphere comes within it for some point
    C = t.centre[J] - c
    dc = np.sqrt(np.maximum(pp - 2.0 * (p @ C.T) + np.einsum("ij,ij->i", C, C), 0.0))
    slack = 1e-7 * (np.sqrt(pp.max()) + t.radius[J].max())  # over the squares' rounding
    near = dc - t.radius[J] <= dc.min(1, keepdims=True) + slack
    J = J[np.any(near, axis=0)]
    V, E, EE, N, M = t.V[J] - c, t.E[J], t.EE[J], t.N[J], t.M[J]
    best = None
    for i in range(3):  # the three edges (point–segment distances)
        q = p @ E[:, i].T - np.einsum("ij,ij->i", V[:, i], E[:, i])  # (p − Vᵢ)·Eᵢ
        s = np.clip(q / np.maximum(EE[:, i], 1e-300), 0.0, 1.0)
        d2v = pp - 2.0 * (p @ V[:, i].T) + np.einsum("ij,ij->i", V[:, i], V[:, i])
        d2 = d2v - 2.0 * s * q + s * s * EE[:, i]
        best = d2 if best is None else np.minimum(best, d2)
    inside = np.broadcast_to(t.ok[J], best.shape).copy()
    for i in range(3):  # the projection inside the triangle: in-plane edge tests
        inside &= p @ M[:, i].T - np.einsum("ij,ij->i", V[:, i], M[:, i]) >= 0.0
    sn = p @ N.T - np.einsum("ij,ij->i", V[:, 0], N)
    d2 = np.maximum(np.where(inside, sn * sn, best), 0.0)
    if len(J) <= _TIES:
        K = np.broadcast_to(J, d2.shape)
    else:  # the few best by the expanded squares, measured directly: rounding-exact ties
        K = J[np.argpartition(d2, _TIES - 1, axis=1)[:, :_TIES]]
    n, k = K.shape
    dist = np.abs(_signed(np.repeat(P, k, axis=0), t, K.ravel())).reshape(n, k)
    return K[np.arange(n), np.argmin(dist, axis=1)]


def _signed(P: np.ndarray, t: _Tris, k: np.ndarray) -> np.ndarray:
    """The signed distance of points P to their nearest triangles ``k``: the distance in
    the direct form (p − q, no expanded squares), the sign by the pseudo-normal of the
    feature (face, edge, vertex) that holds the nearest point q (+ outside)."""
    V, E, EE, N, M = t.V[k], t.E[k], t.EE[k], t.N[k], t.M[k]
    w = P[:, None, :] - V  # (P, 3, 3): p − Vᵢ
    inside = t.ok[k] & np.all(np.einsum("pij,pij->pi", w, M) >= 0.0, axis=1)
    s = np.clip(np.einsum("pij,pij->pi", w, E) / np.maximum(EE, 1e-300), 0.0, 1.0)
    r = w - s[..., None] * E  # p − (nearest point of edge i)
    i = np.argmin(np.einsum("pij,pij->pi", r, r), axis=1)
    at = np.arange(len(P))
    si, ri = s[at, i], r[at, i]
    normal = np.where((si <= 0.0)[:, None], t.vert_n[k, i],
                      np.where((si >= 1.0)[:, None], t.vert_n[k, (i + 1) % 3],
                               t.edge_n[k, i]))  # fmt: skip
    sn = np.einsum("pj,pj->p", w[:, 0], N)
    side = np.where(inside, sn, np.einsum("pj,pj->p", ri, normal))
    dist = np.where(inside, np.abs(sn), np.sqrt(np.einsum("pj,pj->p", ri, ri)))
    return np.where(side < 0.0, -dist, dist)


def _morton(P: np.ndarray) -> np.ndarray:
    """The points' Z-order (Morton) codes on a lattice over their box of about one point
    per cell (2ᵇ cells per axis, 2³ᵇ ≥ n, b ≤ 10; a grid of 2ᵇ points per axis maps onto
    it one to one): runs of consecutive codes are compact clusters of points."""
    n = 1 << int(np.clip(np.ceil(np.log2(max(len(P), 2)) / 3), 1, 10))
    span = np.maximum(np.ptp(P, 0), 1e-300)
    q = np.minimum((P - P.min(0)) / span * n, n - 1).astype(np.uint64)
    for shift, mask in ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249)):
        q = (q | (q << np.uint64(shift))) & np.uint64(mask)  # spread 10 bits 3 apart
    return (q[:, 0] << np.uint64(2)) | (q[:, 1] << np.uint64(1)) | q[:, 2]


def exact_sdf(vertices: ArrayLike, faces: ArrayLike, points: ArrayLike) -> np.ndarray:
    """The exact signed distance (n,) of points (n, 3) to the closed, outward-oriented
    triangle mesh (vertices, faces): negative inside (module docstring), float64.

    Points are taken in blocks of :data:`_BLOCK_SIZE` consecutive points in Z-order
    (compact clusters, whatever the points' density); a block checks
    only the triangles that can hold a nearest point of one of its points: those whose
    bounding sphere (about the centroid) comes within U + ρ of the block's centre c, ρ
    the block's radius and U = (the distance from c to its nearest vertex) + ρ, an upper
    bound of every block point's distance; of these, each point keeps those that come
    within its distance to the nearest centroid (:func:`_nearest`). The result is the
    same as checking every triangle."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    P = np.asarray(points, np.float64).reshape(-1, 3)
    if len(P) == 0:
        return np.zeros(0)
    t = _tris(v, f)
    order = np.argsort(_morton(P), kind="stable")  # nearby points stay together
    cuts = np.arange(_BLOCK_SIZE, len(P), _BLOCK_SIZE)
    tri = np.empty(len(P), np.int64)
    for idx in np.split(order, cuts):
        Q = P[idx]
        c = (Q.min(0) + Q.max(0)) / 2
        rho = float(np.linalg.norm(Q - c, axis=1).max())
        U = float(np.sqrt(np.min(np.sum((v - c) ** 2, axis=1)))) + rho
        J = np.flatnonzero(np.linalg.norm(t.centre - c, axis=1) - t.radius <= U + rho)
        tri[idx] = _nearest(Q, t, J, c)
    return _signed(P, t, tri)


@dataclass(frozen=True)
class MeshGrid:
    """A mesh's SDF on a grid, in the mesh's frame: ``values`` (n, n, n) float64 at the
    points ``origin + (i, j, k) * cell``; ``build_s`` the seconds it took."""

    values: np.ndarray
    origin: np.ndarray
    cell: np.ndarray
    build_s: float = 0.0

    @property
    def resolution(self) -> int:
        return int(self.values.shape[0])

    def bound(self) -> float:
        """Trilinear interpolation's error bound in the box: half the cell's diagonal."""
        return float(np.linalg.norm(self.cell)) / 2


def grid_box(vertices: ArrayLike, resolution: int = DEFAULT_RESOLUTION,
             padding: float | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(origin (3,), cell (3,)) of the grid of ``resolution`` points per axis over the
    vertices' bounding box grown by ``padding`` on every side (None: :data:`PAD_CELLS`
    cells of the longest axis)."""
    v = np.asarray(vertices, np.float64)
    lo, hi = v.min(0), v.max(0)
    ext = hi - lo
    n = int(resolution) - 1
    if padding is None:
        padding = PAD_CELLS * float(ext.max()) / (n - 2 * PAD_CELLS)
    cell = (ext + 2 * padding) / n
    return lo - padding, cell


def build_grid(vertices: ArrayLike, faces: ArrayLike, resolution: int = DEFAULT_RESOLUTION,
               padding: float | None = None) -> MeshGrid:  # fmt: skip
    """The mesh's exact SDF (:func:`exact_sdf`) at every point of the grid of
    :func:`grid_box`, once, on the host."""
    import time

    t0 = time.perf_counter()
    origin, cell = grid_box(vertices, resolution, padding)
    ax = [origin[k] + cell[k] * np.arange(resolution) for k in range(3)]
    P = np.stack(np.meshgrid(*ax, indexing="ij"), -1).reshape(-1, 3)
    vals = exact_sdf(vertices, faces, P).reshape((resolution,) * 3)
    return MeshGrid(vals, origin, cell, time.perf_counter() - t0)


GRID_VERSION = "exact-sdf-1"
"""The grid algorithm's version, part of every cached grid's key: change it whenever
:func:`build_grid` or :func:`exact_sdf` would give other values, and every cached file
is rebuilt."""
KEEP_GRIDS = 16
"""Grids kept in memory (the most recently used)."""

_GRIDS: dict[str, MeshGrid] = {}
_LOCK = threading.Lock()  # guards _GRIDS and _KEY_LOCKS
_KEY_LOCKS: dict[str, threading.Lock] = {}  # one per grid key: one build at a time
BUILDS: dict[str, int] = {}
"""How many times each grid (by its key, :func:`grid_key`) was built in this process:
read by the tests (a grid is built at most once per process)."""


def cache_folder() -> Path | None:
    """Where mesh grids are kept between runs: the compilation cache's folder
    (``jax_compilation_cache_dir``, set by the CLI's ``compile_cache``, ``cli.setup.use_cache``);
    None (memory only) when none is configured."""
    d = jax.config.jax_compilation_cache_dir
    return None if not d else Path(d)


@lru_cache(maxsize=64)
def _content_hash(path: str, mtime_ns: int, size: int) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def grid_key(path: str | os.PathLike, scale: float = 1.0, resolution: int = DEFAULT_RESOLUTION,
             padding: float | None = None) -> str:  # fmt: skip
    """The text that identifies a mesh file's grid: :data:`GRID_VERSION`, the SHA-256 of
    the file's bytes, the scale, the resolution and the padding (exact float reprs). The
    pose is not part of it: the grid lies in the mesh's own frame (after the scale), and
    a pose moves it at lookup (:func:`mesh_sdf`), so a moved mesh reuses its grid."""
    import json

    p = Path(path).resolve()
    st = p.stat()
    return json.dumps({"version": GRID_VERSION,
                       "sha256": _content_hash(str(p), st.st_mtime_ns, st.st_size),
                       "scale": repr(float(scale)), "resolution": int(resolution),
                       "padding": None if padding is None else repr(float(padding))},
                      sort_keys=True)  # fmt: skip


def grid_file(folder: Path, key: str) -> Path:
    """The cached grid's file for ``key`` in ``folder``."""
    import hashlib

    return folder / f"designopt-grid-{hashlib.sha256(key.encode()).hexdigest()[:40]}.npz"


def _read_grid(path: Path, key: str, resolution: int) -> MeshGrid | None:
    """The grid in ``path`` when it is whole and made for ``key``; None otherwise (no
    file, a damaged or foreign one, another key, wrong shapes or non-finite numbers)."""
    import time

    t0 = time.perf_counter()
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                return None
            vals = np.array(z["values"], np.float64)
            origin = np.array(z["origin"], np.float64)
            cell = np.array(z["cell"], np.float64)
    except Exception:  # noqa: BLE001  (missing, truncated, not an npz: rebuild)
        return None
    n = int(resolution)
    if vals.shape != (n, n, n) or origin.shape != (3,) or cell.shape != (3,):
        return None
    if not (np.all(np.isfinite(vals)) and np.all(np.isfinite(origin))
            and np.all(np.isfinite(cell)) and np.all(cell > 0)):  # fmt: skip
        return None
    return MeshGrid(vals, origin, cell, time.perf_counter() - t0)


def _write_grid(path: Path, key: str, g: MeshGrid) -> None:
    """``g`` into ``path`` whole (a temporary file renamed over it), or nothing when the
    folder cannot be written (the cache only saves time)."""
    _write_npz(path, key=np.array(key), values=g.values, origin=g.origin, cell=g.cell)


def _write_npz(path: Path, **arrays: np.ndarray) -> None:
    """``arrays`` into ``path`` whole, or nothing when the folder cannot be written
    (``core.exported.write_cached``)."""
    import io

    from designopt.core import exported

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    exported.write_cached(path, buf.getvalue())


def mesh_grid(path: str | os.PathLike, scale: float = 1.0, resolution: int = DEFAULT_RESOLUTION,
              padding: float | None = None) -> MeshGrid:  # fmt: skip
    """:func:`build_grid` of the mesh file (:func:`load_mesh`) scaled by ``scale``: built
    at most once per process for one :func:`grid_key` (kept in memory, the
    :data:`KEEP_GRIDS` last used), and kept on disk in :func:`cache_folder` when one is
    configured: a later process loads it (a file that is damaged or made for another key
    is rebuilt and replaced, never trusted)."""
    v, f = load_mesh(path)  # the errors, named
    key = grid_key(path, scale, resolution, padding)
    with _LOCK:
        lock = _KEY_LOCKS.setdefault(key, threading.Lock())
    with lock:  # one build per key: a second caller (a prefetch's thread) waits for it
        with _LOCK:
            g = _GRIDS.pop(key, None)
        if g is None:
            folder = cache_folder()
            file = None if folder is None else grid_file(folder, key)
            g = None if file is None else _read_grid(file, key, resolution)
            if g is None:
                pad = None if padding is None else float(padding)
                g = build_grid(v * float(scale), f, int(resolution), pad)
                BUILDS[key] = BUILDS.get(key, 0) + 1
                if file is not None:
                    _write_grid(file, key, g)
            g.values.flags.writeable = False
        with _LOCK:
            _GRIDS[key] = g  # the most recently used last
            while len(_GRIDS) > KEEP_GRIDS:
                _GRIDS.pop(next(iter(_GRIDS)))
    return g


def stack(grids: list[MeshGrid], R: ArrayLike, t: ArrayLike, dtype=jnp.float64) -> dict[str, Array]:
    """The pytree of several meshes (module docstring): ``grid`` (nm, G, G, G), G the
    largest resolution (a smaller grid in its corner, the rest its edge values, never
    read), ``origin``, ``cell`` (nm, 3), ``cells`` (nm,) each grid's cells per axis,
    ``R`` (nm, 3, 3) and ``t`` (nm, 3) the poses (x_world = R x_mesh + t). No grids: every
    array empty, with G = :data:`DEFAULT_RESOLUTION`."""
    G = max((g.resolution for g in grids), default=DEFAULT_RESOLUTION)
    vals = np.zeros((len(grids), G, G, G))
    for i, g in enumerate(grids):
        vals[i] = np.pad(g.values, [(0, G - g.resolution)] * 3, mode="edge")
    if vals.size >= 2**31:
        raise ValueError(f"{len(grids)} mesh grids of {G}³ points are too many to index")

    def arr(x, shape):
        return jnp.asarray(np.asarray(x, np.float64).reshape(shape), dtype)

    nm = len(grids)
    return {
        "grid": jnp.asarray(vals, dtype),
        "origin": arr([g.origin for g in grids], (nm, 3)),
        "cell": arr([g.cell for g in grids], (nm, 3)),
        "cells": arr([g.resolution - 1 for g in grids], (nm,)),
        "R": arr(R, (nm, 3, 3)),
        "t": arr(t, (nm, 3)),
    }


# --------------------------------------------------------------------------- JAX


def _floats(*xs: ArrayLike) -> list[Array]:
    arrs = [jnp.asarray(x) for x in xs]
    dt = jnp.result_type(*arrs, float)
    return [a.astype(dt) for a in arrs]


def _safe_norm(x: Array) -> Array:
    """|x| over the last axis, with a zero (not NaN) derivative at 0."""
    s = jnp.sum(x * x, axis=-1)
    pos = s > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, s, 1.0)), 0.0)


_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], np.int32)


def _interp(flat: Array, G: int, off: Array, origin: Array, cell: Array, cells: Array,
            p: Array) -> Array:  # fmt: skip
    """The grid value at points p (..., 3) of the mesh frame: trilinear in the box, the
    value at the nearest point of the box plus the distance to it outside. ``flat`` the
    flattened grids, ``off`` (...) each point's grid's offset in it (m·G³), ``origin``,
    ``cell`` (..., 3) and ``cells`` (...) its grid's, broadcast against p."""
    top = cells[..., None]
    uc = jnp.clip((p - origin) / cell, 0.0, top)
    i = jax.lax.stop_gradient(jnp.clip(jnp.floor(uc), 0.0, top - 1.0))
    f = uc - i  # (..., 3) in [0, 1]
    ii = i.astype(jnp.int32)
    base = off + (ii[..., 0] * G + ii[..., 1]) * G + ii[..., 2]
    corner = jnp.asarray((_CORNERS[:, 0] * G + _CORNERS[:, 1]) * G + _CORNERS[:, 2])
    v = jnp.take(flat, base[..., None] + corner, mode="clip")  # (..., 8)
    bits = jnp.asarray(_CORNERS, bool)
    w = jnp.prod(jnp.where(bits, f[..., None, :], 1.0 - f[..., None, :]), axis=-1)
    q = origin + uc * cell  # the nearest point of the box
    return jnp.sum(w * v, axis=-1) + _safe_norm(p - q)


def _grids(grid: Array) -> tuple[Array, int, Array]:
    """(flattened grids, G, offsets (*B,)) of grids (*B, G, G, G)."""
    G = grid.shape[-1]
    if grid.shape[-3:] != (G, G, G):
        raise ValueError(f"grid: needs (..., G, G, G), got {grid.shape}")
    B = grid.shape[:-3]
    off = jnp.arange(math.prod(B), dtype=jnp.int32).reshape(B) * (G**3)
    return grid.reshape(-1), G, off


def grid_sdf(p: ArrayLike, grid: ArrayLike, origin: ArrayLike, cell: ArrayLike,
             cells: ArrayLike | None = None) -> Array:  # fmt: skip
    """The interpolated SDF (...,) at points p (..., 3) in the mesh's frame (module
    docstring): ``grid`` (*B, G, G, G) (B = () for one mesh, (nm,) for a stack),
    ``origin``, ``cell`` (*B, 3), ``cells`` (*B,) the cells per axis each grid uses
    (None: G − 1); p's trailing batch axes index B (p (..., nm, 3) for a stack)."""
    p, grid, origin, cell = _floats(p, grid, origin, cell)
    flat, G, off = _grids(grid)
    cells = (
        jnp.full(grid.shape[:-3], G - 1, p.dtype) if cells is None else jnp.asarray(cells, p.dtype)
    )
    return _interp(flat, G, off, origin, cell, cells, p)


def to_mesh_frame(x: ArrayLike, R: ArrayLike, t: ArrayLike) -> Array:
    """Rᵀ (x − t): world points x (..., 3) in the frame of a mesh posed by R (..., 3, 3),
    t (..., 3) (x_world = R x_mesh + t)."""
    x, R, t = _floats(x, R, t)
    return jnp.sum(R * (x - t)[..., :, None], axis=-2)


def mesh_sdf(p: ArrayLike, grid: ArrayLike, origin: ArrayLike, cell: ArrayLike,
             cells: ArrayLike, R: ArrayLike, t: ArrayLike) -> Array:  # fmt: skip
    """:func:`grid_sdf` at world points p (..., 3) of meshes posed by R, t (*B, 3, 3),
    (*B, 3)."""
    return grid_sdf(to_mesh_frame(p, R, t), grid, origin, cell, cells)


def samples(resolution: int) -> int:
    """Samples of a centre line's part in a grid's box in :func:`capsule_mesh`: with
    ⌈√3 (n − 1)⌉ intervals over a part no longer than the box's diagonal, (n − 1)|h|, the
    spacing is at most |h|/√3 ≤ max h for every grid of n ≤ ``resolution`` points."""
    return math.ceil(math.sqrt(3.0) * (int(resolution) - 1)) + 1


def _clip(p0: Array, d: Array, lo: Array, hi: Array) -> tuple[Array, Array]:
    """(s0, s1): the part of the segment p0 + s d, s ∈ [0, 1], inside the box [lo, hi]
    (slab method); s0 = s1 = 0 when it misses the box. Values only."""
    dt = p0.dtype
    big = jnp.asarray(1e30, dt)  # beyond any parameter: a slab that holds every s
    tiny = float(np.sqrt(np.finfo(dt).tiny))
    moving = jnp.abs(d) > tiny
    dd = jnp.where(moving, d, 1.0)
    ta, tb = (lo - p0) / dd, (hi - p0) / dd
    within = (p0 >= lo) & (p0 <= hi)
    enter = jnp.where(moving, jnp.minimum(ta, tb), jnp.where(within, -big, big))
    leave = jnp.where(moving, jnp.maximum(ta, tb), jnp.where(within, big, -big))
    s0 = jnp.maximum(jnp.max(enter, -1), 0.0)
    s1 = jnp.minimum(jnp.min(leave, -1), 1.0)
    hit = s0 <= s1
    return jnp.where(hit, s0, 0.0), jnp.where(hit, s1, 0.0)


def _params(k: Array, s0: Array, s1: Array, n_in: int) -> Array:
    """Sample k's parameter on the segment: k < n_in evenly on [s0, s1], then
    :data:`LINE_SAMPLES` evenly on [0, 1] (later indices repeat the last)."""
    dt = s0.dtype
    kin = jnp.minimum(k, n_in - 1).astype(dt) / (n_in - 1)
    kl = jnp.clip(k - n_in, 0, LINE_SAMPLES - 1).astype(dt) / (LINE_SAMPLES - 1)
    return jnp.where(k < n_in, s0 + kin * (s1 - s0), kl)


def best_sample(a0: ArrayLike, a1: ArrayLike, grid: ArrayLike, origin: ArrayLike,
                cell: ArrayLike, cells: ArrayLike, R: ArrayLike, t: ArrayLike) -> Array:  # fmt: skip
    """The parameter s (...,) in [0, 1] of the centre-line sample a0 + s (a1 − a0) of
    least interpolated SDF (:func:`capsule_mesh`'s samples; arguments as there), without
    a derivative. The search runs in a loop over blocks of :data:`BLOCK` samples."""
    a0, a1, grid, origin, cell, cells, R, t = (
        jax.lax.stop_gradient(x) for x in _floats(a0, a1, grid, origin, cell, cells, R, t)
    )
    flat, G, off = _grids(grid)
    p0 = to_mesh_frame(a0, R, t)
    d = to_mesh_frame(a1, R, t) - p0
    shape = jnp.broadcast_shapes(p0.shape[:-1], d.shape[:-1], origin.shape[:-1], cells.shape)
    p0, d, o, c = (jnp.broadcast_to(x, (*shape, 3)) for x in (p0, d, origin, cell))
    cs = jnp.broadcast_to(cells, shape)
    s0, s1 = _clip(p0, d, o, o + cs[..., None] * c)
    n_in = samples(G)
    n_blocks = -(-(n_in + LINE_SAMPLES) // BLOCK)
    o, c, cs = o[..., None, :], c[..., None, :], cs[..., None]
    of = jnp.broadcast_to(off, shape)[..., None]

    def block(b, carry):
        best, kbest = carry
        k = b * BLOCK + jnp.arange(BLOCK, dtype=jnp.int32)
        s = _params(k, s0[..., None], s1[..., None], n_in)  # (..., BLOCK)
        v = _interp(flat, G, of, o, c, cs, p0[..., None, :] + s[..., None] * d[..., None, :])
        j = jnp.argmin(v, axis=-1)
        vb = jnp.take_along_axis(v, j[..., None], -1)[..., 0]
        better = vb < best
        kb = jnp.take_along_axis(jnp.broadcast_to(k, v.shape), j[..., None], -1)[..., 0]
        return jnp.where(better, vb, best), jnp.where(better, kb, kbest)

    init = (jnp.full(shape, jnp.inf, p0.dtype), jnp.zeros(shape, jnp.int32))
    _, kbest = jax.lax.fori_loop(0, n_blocks, block, init)
    return _params(kbest, s0, s1, n_in)


def capsule_mesh(a0: ArrayLike, a1: ArrayLike, r: ArrayLike, grid: ArrayLike,
                 origin: ArrayLike, cell: ArrayLike, cells: ArrayLike, R: ArrayLike,
                 t: ArrayLike) -> Array:  # fmt: skip
    """Signed distance (...,) between the capsules (a0–a1, r) (world points (..., 3),
    radii (...)) and the meshes of the stack (``grid`` (*B, G, G, G), ``origin``,
    ``cell`` (*B, 3), ``cells`` (*B,), poses ``R`` (*B, 3, 3), ``t`` (*B, 3)), broadcast
    (the capsules' trailing batch axes index B): the least interpolated SDF over
    :func:`samples` (G) points of the centre line's part in the grid's box and
    :data:`LINE_SAMPLES` points of the whole line (:func:`best_sample`), less r. Error
    bound and gradient: the module docstring."""
    a0, a1, r, grid, origin, cell, cells, R, t = _floats(a0, a1, r, grid, origin, cell,
                                                         cells, R, t)  # fmt: skip
    s = best_sample(a0, a1, grid, origin, cell, cells, R, t)
    x = a0 + s[..., None] * (a1 - a0)  # differentiable in the ends and the pose
    return mesh_sdf(x, grid, origin, cell, cells, R, t) - r
