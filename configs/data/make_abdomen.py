"""Writes ``abdomen.stl`` beside this script: the insufflated abdomen of the planning case
(configs/port_placement.yaml, docs/planning.md) as a closed mesh, the ellipsoid of its
``task.body_wall`` (centre (0, 0, 0.06) m, semi-axes 0.20 × 0.25 × 0.12 m) sampled as
the unit icosphere of 3 subdivisions (642 vertices, 1280 faces) scaled by the semi-axes.
The mesh is the obstacle that keeps the arms' links out of the patient; the analytic
ellipsoid places the ports. The mesh's vertices lie on the ellipsoid and its faces
inside it (a chord is inside a convex surface), by at most 1.04 mm.

Deterministic (the STL writer of make_organ.py). Run: ``python configs/data/make_abdomen.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

CENTER = (0.0, 0.0, 0.06)
SEMI_AXES = (0.20, 0.25, 0.12)


def abdomen() -> tuple[np.ndarray, np.ndarray]:
    """(vertices (642, 3) float64, faces (1280, 3)) of the abdomen."""
    ico = trimesh.creation.icosphere(subdivisions=3)
    v = np.asarray(ico.vertices, np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return np.asarray(CENTER) + v * np.asarray(SEMI_AXES), np.asarray(ico.faces, np.int64)


def main() -> Path:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from make_organ import stl_bytes

    v, f = abdomen()
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    out = Path(__file__).resolve().parent / "abdomen.stl"
    data = stl_bytes(v, f)
    out.write_bytes(b"designopt abdomen.stl (configs/data/make_abdomen.py)".ljust(80, b" ")
                    + data[80:])  # fmt: skip
    return out


if __name__ == "__main__":
    print(main())
