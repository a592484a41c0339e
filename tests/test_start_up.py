"""A warm command's start-up (issue #54, part 3): what a config names and what was checked
before is read back from the cache folder, so a warm ``eval`` or ``show`` neither imports
trimesh, yourdfpy nor matplotlib nor parses and checks its files again; every such
entry gives exactly what a fresh parse gives, and a file that fails its checks is never
kept (its error comes back each time)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from designopt.kinematics import sdf, urdf

ROOT = Path(__file__).resolve().parents[1]
URDF = ROOT / "configs/robots/ur5/ur5_instrument.urdf"
ORGAN = ROOT / "configs/data/organ.stl"

CHILD = r"""
import hashlib, json, sys
import jax
jax.config.update("jax_compilation_cache_dir", sys.argv[1])
import designopt.app.pipeline  # what eval and show import
from designopt.kinematics import sdf, urdf
r = urdf.parse(open(sys.argv[2]).read(), "arm.urdf")
v, f = sdf.load_mesh(sys.argv[3])
print(json.dumps({"modules": [m for m in ("trimesh", "yourdfpy", "matplotlib") if m in sys.modules],
                  "robot": urdf._to_json(r),
                  "mesh": hashlib.sha256(v.tobytes() + f.tobytes()).hexdigest()}))
"""


def _child(cache: Path) -> dict:
    r = subprocess.run([sys.executable, "-c", CHILD, str(cache), str(URDF), str(ORGAN)],
                       capture_output=True, text=True, timeout=300,
                       env=os.environ | {"JAX_PLATFORMS": "cpu"})  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_a_warm_process_reads_the_urdf_and_the_mesh_back_without_their_libraries(tmp_path):
    cache = tmp_path / "cache"
    cold = _child(cache)
    assert set(cold["modules"]) >= {"trimesh", "yourdfpy"}  # parsed and checked
    assert len(list(cache.glob("designopt-urdf-*.json"))) == 1
    assert len(list(cache.glob("designopt-mesh-*.npz"))) == 1
    warm = _child(cache)
    assert warm["modules"] == []  # no trimesh, yourdfpy or matplotlib at all
    assert warm["robot"] == cold["robot"] and warm["mesh"] == cold["mesh"]
    # what was kept is what a fresh parse and check give, bit for bit
    fresh = urdf._parse(URDF.read_text(), "arm.urdf")
    assert urdf._from_json(warm["robot"]) == fresh
    v, f = sdf._checked(str(ORGAN.resolve()))
    import hashlib

    assert hashlib.sha256(v.tobytes() + f.tobytes()).hexdigest() == warm["mesh"]


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    folder.mkdir()
    monkeypatch.setattr(sdf, "cache_folder", lambda: folder)
    sdf._load.cache_clear()
    yield folder
    sdf._load.cache_clear()


def test_a_damaged_entry_is_parsed_again_and_replaced(cache):
    text = URDF.read_text()
    want = urdf._parse(text, "arm.urdf")
    assert urdf.parse(text, "arm.urdf") == want
    (entry,) = cache.glob("designopt-urdf-*.json")
    entry.write_text("{not json")
    assert urdf.parse(text, "arm.urdf") == want
    assert urdf._from_json(entry.read_text()) == want
    v, f = sdf.load_mesh(ORGAN)
    (mesh,) = cache.glob("designopt-mesh-*.npz")
    mesh.write_bytes(b"truncated")
    sdf._load.cache_clear()
    v2, f2 = sdf.load_mesh(ORGAN)
    assert np.array_equal(v, v2) and np.array_equal(f, f2)
    assert not v2.flags.writeable and not f2.flags.writeable


def test_another_text_or_place_is_another_entry_and_a_refused_file_is_not_kept(cache, tmp_path):
    text = URDF.read_text()
    a = urdf.parse(text, "a.urdf")
    b = urdf.parse(text, "b.urdf")  # the place is in the messages and in Robot.where
    assert (a.where, b.where) == ("a.urdf", "b.urdf")
    moved = text.replace('name="elbow_joint"', 'name="elbow"', 1)
    assert "elbow" in urdf.parse(moved, "a.urdf").joints
    assert len(list(cache.glob("designopt-urdf-*.json"))) == 3
    bad = text.replace("<robot", "<robt", 1).replace("</robot>", "</robt>")
    for _ in range(2):
        with pytest.raises(urdf.ConfigError, match="not a URDF"):
            urdf.parse(bad, "bad.urdf")
    assert len(list(cache.glob("designopt-urdf-*.json"))) == 3
    # a mesh with a hole: refused each time, nothing kept
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=1)
    m.update_faces(np.arange(len(m.faces)) != 0)
    holed = tmp_path / "holed.stl"
    m.export(holed)
    for _ in range(2):
        sdf._load.cache_clear()
        with pytest.raises(ValueError, match="not watertight"):
            sdf.load_mesh(holed)
    assert len(list(cache.glob("designopt-mesh-*.npz"))) == 0


def test_normalisation_bounds_are_kept_and_read_back(tmp_path, monkeypatch):
    """A normalised objective's probe (``n_norm`` designs scored before a run or an eval)
    is kept in the cache folder: a second build with the same settings and streams reads
    the same bounds back without scoring a design; another seed or another setting is
    another entry; a damaged entry is scored again."""
    import jax.numpy as jnp

    import designopt
    from designopt.core import exported
    from designopt.core.keys import streams
    from designopt.problems import normalise
    from designopt.studies import STUDIES

    monkeypatch.setattr(exported, "folder", lambda: tmp_path)
    over = {"study.indices.n_samples": 512, "study.objective.n_norm": 4}
    cfg = designopt.load_config(ROOT / "configs/puma560.yaml", over)
    st = STUDIES["serial"]

    def bounds(c, seed=0):
        return np.asarray(st.problem(c.study, streams(seed), jnp.float64).norm_bounds)

    b0 = bounds(cfg)
    files = sorted(tmp_path.glob("designopt-bounds-*.npy"))
    assert len(files) == 1 and np.all(b0[:, 1] > b0[:, 0])
    real = normalise.mc.box_samples

    def refuse(*a, **k):
        raise AssertionError("the probe scored designs again")

    monkeypatch.setattr(normalise.mc, "box_samples", refuse)
    assert np.array_equal(bounds(cfg), b0)  # read back, bit for bit
    monkeypatch.setattr(normalise.mc, "box_samples", real)
    b1 = bounds(cfg, seed=1)
    other = designopt.load_config(ROOT / "configs/puma560.yaml",
                                  over | {"study.indices.n_samples": 256})  # fmt: skip
    b2 = bounds(other)
    assert len(list(tmp_path.glob("designopt-bounds-*.npy"))) == 3
    assert not np.array_equal(b1, b0) and not np.array_equal(b2, b0)
    files[0].write_bytes(b"damaged")
    assert np.array_equal(bounds(cfg), b0)  # scored again, and kept again
    assert np.array_equal(np.load(files[0]), b0)
