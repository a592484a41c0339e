"""Writes ``organ.stl`` beside this script: a small, smooth, closed organ-like mesh (a
kidney-shaped bean about 12 × 7.5 × 6 cm, in metres) for mesh obstacles (docs/task.md,
"Mesh obstacles") and the tests (tests/test_sdf.py).

Deterministic: no randomness, a fixed STL header, float32 vertices written by NumPy (the
same bytes on every run; another platform's libm may move a vertex by an ulp). Made from the unit icosphere of 3 subdivisions (642 vertices,
1280 faces) by a radial map v -> ρ(v) v, ρ > 0 (one inward dent for the hilum, three gentle
lobes), then scaled by the semi-axes and bent about z. A radial map of a sphere keeps the
surface closed and star-shaped about the origin; the script checks that every face still
faces away from the origin (no fold-over), that the mesh is watertight with consistent
winding and positive volume, and that it is not convex (the dent is a concavity, so the
signed-distance tests see one).

Run: ``python configs/data/make_organ.py`` (needs numpy and trimesh).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

SEMI_AXES = (0.06, 0.035, 0.03)
"""Semi-axes of the bean before the dent and the bend (m)."""
BEND = 8.0
"""The bend y += BEND · x² (1/m)."""


def organ() -> tuple[np.ndarray, np.ndarray]:
    """(vertices (642, 3) float64, faces (1280, 3)) of the organ."""
    ico = trimesh.creation.icosphere(subdivisions=3)
    v = np.asarray(ico.vertices, np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = np.asarray(ico.faces, np.int64)
    hilum = np.array([0.0, 1.0, 0.0])  # the dent on the +y side, inside the bend
    dent = 0.35 * np.exp(-np.sum((v - hilum) ** 2, axis=1) / 0.4)
    lobes = 0.06 * np.cos(3.0 * np.arctan2(v[:, 2], v[:, 0])) * (1 - v[:, 1] ** 2)
    rho = 1.0 - dent + lobes
    p = v * rho[:, None] * np.asarray(SEMI_AXES)
    tri = p[f]  # before the bend: star-shaped about the origin, no face folded over
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, tri.mean(1)) > 0), "a face folded over"
    # bend about z: y grows with x², a bean's curve; (x, y, z) -> (x, y + k x², z) is a
    # bijection of space, so it keeps the surface free of self-intersections
    p[:, 1] += BEND * p[:, 0] ** 2
    return p, f


def check(v: np.ndarray, f: np.ndarray) -> None:
    """AssertionError unless the mesh is a closed, outward, non-convex volume."""
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert m.convex_hull.volume > 1.02 * m.volume, "the dent should make it non-convex"


def stl_bytes(v: np.ndarray, f: np.ndarray) -> bytes:
    """A binary STL: fixed 80-byte header, face count, then per face the unit normal and
    the three vertices (float32) and a zero attribute."""
    tri = v[f].astype(np.float32)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).astype(np.float64)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    rec = np.zeros(len(f), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = n.astype(np.float32), tri
    head = b"designopt organ.stl (configs/data/make_organ.py)".ljust(80, b" ")
    return head + np.uint32(len(f)).tobytes() + rec.tobytes()


def main() -> Path:
    v, f = organ()
    check(v, f)
    out = Path(__file__).resolve().parent / "organ.stl"
    out.write_bytes(stl_bytes(v, f))
    return out


if __name__ == "__main__":
    print(main())
