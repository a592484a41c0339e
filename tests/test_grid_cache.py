"""Mesh distance grids kept on disk and built at most once per process (issue 53, part 2),
and a flat closed mesh refused in one line (part 8)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from designopt.kinematics import collision, sdf

ROOT = Path(__file__).resolve().parents[1]
ORGAN = ROOT / "configs/data/organ.stl"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh grid cache: the folder ``tmp_path/cache``, nothing in memory, no builds."""
    folder = tmp_path / "cache"
    collision.prefetch_done()  # no grid of an earlier test's checks still on its way
    monkeypatch.setattr(sdf, "cache_folder", lambda: folder)
    monkeypatch.setattr(sdf, "_GRIDS", {})
    monkeypatch.setattr(sdf, "BUILDS", {})
    return folder


def _forget(monkeypatch):
    """A new process's memory: no grid kept, the build counts as they were."""
    monkeypatch.setattr(sdf, "_GRIDS", {})


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob("designopt-grid-*.npz"))


def _unmark(folder: Path) -> None:
    marks = list(folder.glob("designopt-checked-*"))
    assert marks, "the first run's checks left their marker"
    for m in marks:
        m.unlink()


def test_a_cached_grid_loads_bit_for_bit_and_is_built_once(cache, monkeypatch):
    g = sdf.mesh_grid(ORGAN, 1.0, 32)
    key = sdf.grid_key(ORGAN, 1.0, 32)
    assert sdf.BUILDS == {key: 1}
    assert _files(cache) == [sdf.grid_file(cache, key)]
    assert sdf.mesh_grid(ORGAN, 1.0, 32) is g and sdf.BUILDS[key] == 1  # in memory
    _forget(monkeypatch)
    h = sdf.mesh_grid(ORGAN, 1.0, 32)  # from the file
    assert h is not g and sdf.BUILDS[key] == 1
    for a, b in ((g.values, h.values), (g.origin, h.origin), (g.cell, h.cell)):
        assert a.dtype == b.dtype == np.float64 and a.tobytes() == b.tobytes()
    # the values are the exact SDF at the grid's points (not only what was written)
    v, f = sdf.load_mesh(ORGAN)
    i = np.array([[0, 0, 0], [5, 17, 9], [31, 31, 31], [16, 16, 16]])
    np.testing.assert_array_equal(h.values[tuple(i.T)], sdf.exact_sdf(v, f, h.origin + i * h.cell))
    # no folder: memory only, nothing written
    monkeypatch.setattr(sdf, "cache_folder", lambda: None)
    _forget(monkeypatch)
    sdf.mesh_grid(ORGAN, 1.0, 33)
    assert len(_files(cache)) == 1 and sdf.BUILDS[sdf.grid_key(ORGAN, 1.0, 33)] == 1


def test_the_key_follows_content_scale_resolution_padding_not_the_path_or_pose(cache, tmp_path):
    copy = tmp_path / "copy.stl"
    copy.write_bytes(ORGAN.read_bytes())
    base = sdf.grid_key(ORGAN, 1.0, 32, None)
    assert sdf.grid_key(copy, 1.0, 32, None) == base  # the same bytes elsewhere
    other = {sdf.grid_key(ORGAN, 2.0, 32, None), sdf.grid_key(ORGAN, 1.0, 40, None),
             sdf.grid_key(ORGAN, 1.0, 32, 0.02), sdf.grid_key(ORGAN, 1.0, 32, 0.021)}  # fmt: skip
    assert len(other) == 4 and base not in other
    m = trimesh.load(str(ORGAN), force="mesh")
    m.vertices[:, 0] *= 1.1  # the same file name, other content
    m.export(str(copy))
    assert sdf.grid_key(copy, 1.0, 32, None) != base
    # the pose is not in the key: the grid lies in the mesh's frame, moved at lookup
    from designopt.kinematics.collision import Collision

    def obstacle(xyz, rpy):
        raw = {"radius": 0.01, "obstacles": [{"shape": "mesh", "file": str(ORGAN),
                                              "xyz": xyz, "rpy": rpy, "resolution": 32}]}  # fmt: skip
        return Collision.model_validate(raw, context={"config_dir": str(tmp_path)}).obstacles[0]

    a, b = obstacle([0, 0, 0], [0, 0, 0]), obstacle([0.3, -0.1, 0.2], [10, 20, 30])
    assert a.grid() is b.grid() and sdf.BUILDS == {base: 1}
    R, t = b.pose()
    g = b.grid()
    u = np.random.default_rng(4).uniform(size=(50, 3))  # points of the grid's box, moved
    p = (g.origin + u * 31 * g.cell) @ R.T + t
    got = np.asarray(sdf.mesh_sdf(p, g.values, g.origin, g.cell, 31, R, t))
    v, f = sdf.load_mesh(ORGAN)
    exact = sdf.exact_sdf(v @ R.T + t, f, p)
    assert np.abs(got - exact).max() <= g.bound()


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other key", "wrong shape", "nan"])
def test_a_damaged_or_foreign_file_is_rebuilt(cache, monkeypatch, damage):
    key = sdf.grid_key(ORGAN, 1.0, 32)
    g = sdf.mesh_grid(ORGAN, 1.0, 32)
    path = sdf.grid_file(cache, key)
    good = path.read_bytes()
    if damage == "garbage":
        path.write_bytes(b"not a grid")
    elif damage == "truncated":
        path.write_bytes(good[: len(good) // 2])
    else:
        vals = {"other key": g.values, "wrong shape": g.values[:-1],
                "nan": np.where(g.values > 0, np.nan, g.values)}[damage]  # fmt: skip
        np.savez(path.with_suffix(".tmp.npz"), key=np.array(key if damage != "other key" else
                                                            key.replace("32", "33")),
                 values=vals, origin=g.origin, cell=g.cell)  # fmt: skip
        os.replace(path.with_suffix(".tmp.npz"), path)
    _forget(monkeypatch)
    h = sdf.mesh_grid(ORGAN, 1.0, 32)
    assert sdf.BUILDS[key] == 2  # not trusted: built again
    assert h.values.tobytes() == g.values.tobytes()
    assert path.read_bytes() == good  # and the file made whole again
    assert not list(cache.glob(".grid-*"))  # no temporary file left behind


def _planar(mesh_file: str) -> dict:
    """A small 2R chain beside a mesh obstacle (a dry run validates it, grids and all)."""
    return {"study": {
        "name": "serial",
        "chain": {"convention": "standard", "joints": [
            {"type": "R", "a": "l1", "limits": [-180, 180]},
            {"type": "R", "a": "l2", "limits": [-180, 180]}]},
        "variables": {"l1": [0.3, 1.5], "l2": [0.3, 1.5]},
        "task": {"region": {"shape": "box", "center": [1.0, 0.0, 0.0], "size": [0.2, 0.2, 0.0]},
                 "ik": {"n_best": 1}},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": 16},
        "objective": {"gci": -1.0},
        "collision": {"radius": 0.05, "obstacles": [
            {"shape": "mesh", "file": mesh_file, "xyz": [0.7, 0.5, 0.0], "resolution": 32}]}},
        "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 1},
        "precision": "float64", "seed": 3}  # fmt: skip


def _cli(args: list[str], env_cache: Path, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, DESIGNOPT_CACHE_DIR=str(env_cache))
    return subprocess.run([sys.executable, "-m", "designopt", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)  # fmt: skip


def test_the_cli_keeps_grids_in_its_cache_folder_and_reuses_them(tmp_path):
    """Two dry runs in two processes: the first writes the grid into the compilation
    cache's folder, the second loads it (the file is not written again); a damaged file
    is replaced by a whole one."""
    (tmp_path / "organ.stl").write_bytes(ORGAN.read_bytes())
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(_planar("organ.stl")))
    folder = tmp_path / "cache"
    r = _cli(["run", "c.yaml", "--dry-run", "--out", "o.h5"], folder, tmp_path)
    assert r.returncode == 0, r.stderr
    files = _files(folder)
    assert len(files) == 1
    stamp, data = files[0].stat().st_mtime_ns, files[0].read_bytes()
    # the study's checks (which build or load the grid) run once per settings: their
    # marker in the same folder (app.config.check_study) goes, so each run loads it
    _unmark(folder)
    r = _cli(["run", "c.yaml", "--dry-run", "--out", "o.h5"], folder, tmp_path)
    assert r.returncode == 0, r.stderr
    assert _files(folder) == files and files[0].stat().st_mtime_ns == stamp  # loaded
    files[0].write_bytes(data[:100])
    _unmark(folder)
    r = _cli(["run", "c.yaml", "--dry-run", "--out", "o.h5"], folder, tmp_path)
    assert r.returncode == 0, r.stderr
    assert files[0].read_bytes() == data  # rebuilt, the same bytes


def _flat(path: Path) -> None:
    """A closed (watertight) mesh of zero volume: a tetrahedron whose corners are coplanar."""
    v = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    m = trimesh.Trimesh(v, f, process=False)
    with np.errstate(all="ignore"):  # trimesh divides by the zero volume
        assert m.is_watertight and abs(m.volume) < 1e-15
    m.export(str(path))


def test_a_flat_closed_mesh_is_refused_in_one_line(tmp_path):
    _flat(tmp_path / "flat.stl")
    with pytest.raises(ValueError, match="encloses no volume"):
        sdf.load_mesh(tmp_path / "flat.stl")
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(_planar("flat.stl")))
    r = _cli(["run", "c.yaml", "--dry-run", "--out", "o.h5"], tmp_path / "cache", tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "obstacles.0.file" in lines[0] and "flat.stl" in lines[0], lines[0]
    assert "encloses no volume" in lines[0] and "Warning" not in r.stderr


def test_a_prefetched_grid_is_built_once_and_waited_for(cache, monkeypatch, tmp_path):
    """``collision.prefetch_grids`` builds a mesh obstacle's grid in a thread of its own;
    the obstacle's own ``grid()``, asked at once, waits for that build instead of
    building it again: one build, the same grid object, the values of a direct build."""
    from designopt.core import concurrency
    from designopt.kinematics.collision import Collision

    monkeypatch.setattr(concurrency, "threads", lambda: 2)  # as on a 2-core machine
    raw = {"radius": 0.01, "obstacles": [{"shape": "ball", "center": [0, 0, 0], "radius": 0.1},
                                         {"shape": "mesh", "file": str(ORGAN), "resolution": 32}]}  # fmt: skip
    obs = Collision.model_validate(raw, context={"config_dir": str(tmp_path)}).obstacles
    key = sdf.grid_key(ORGAN, 1.0, 32, None)
    collision.prefetch_grids(obs)
    g = obs[1].grid()  # meanwhile: waits for the thread's build (or finds it done)
    collision.prefetch_done()
    assert sdf.BUILDS == {key: 1} and obs[1].grid() is g
    v, f = sdf.load_mesh(ORGAN)
    np.testing.assert_array_equal(g.values, sdf.build_grid(v, f, 32, None).values)
