"""Compiled programs are reused: in-process (a second run compiles nothing) and across
processes through the persistent cache, whose folder is honoured and which changes no
number."""

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import yaml

from designopt.app import pipeline
from designopt.app.config import validate

JOINT = {"type": "R", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]}
TINY = {  # a planar 2R arm: every stage (setup, PSO, polish, scoring), quick to compile
    "study": {"name": "serial",
              "chain": {"convention": "standard",
                        "joints": [JOINT | {"a": "l1"}, JOINT | {"a": "l2"}]},
              "variables": {"l1": [0.2, 2.0], "l2": [0.2, 2.0]},
              "indices": {"jacobian": ["vx", "vy"], "norm": "fro", "normalized": False,
                          "measure": "joint", "n_samples": 1024},
              "objective": {"gci": -1.0}},
    "optimizer": {"name": "ptpso", "n_particles": 6, "n_iters": 4, "n_runs": 2},
    "refine": {"steps": 3, "learning_rate": 0.01},
    "precision": "float64",
    "seed": 2,
}  # fmt: skip
KEYS = ("optimizer/history", "optimizer/history_x", "final/x", "final/f", "refine/x")


def test_second_run_in_the_same_process_compiles_nothing(tmp_path):
    first = pipeline.run(validate(TINY, "tiny"), "tiny", "tiny", tmp_path / "a.h5")
    assert first.attrs["compilations"] > 0  # the counter sees compilations at all
    again = pipeline.run(validate(TINY, "tiny"), "tiny", "tiny", tmp_path / "b.h5")
    assert again.attrs["compilations"] == 0, again.attrs["compilations_by_stage"]
    np.testing.assert_array_equal(first.tree["final"]["x"], again.tree["final"]["x"])


def _run(tmp_path: Path, out: str, cache: Path, *flags: str) -> dict[str, np.ndarray]:
    cfg = tmp_path / "c.yaml"
    # a checkpoint every chunk in every run: with the default cadence (10 s) a run slowed by
    # a loaded machine wrote one, and compiled its program, where the other had not
    cfg.write_text(yaml.safe_dump(TINY | {"output": str(tmp_path / "unused.h5"),
                                          "checkpoint_every_s": 0}))
    env = os.environ | {"DESIGNOPT_CACHE_DIR": str(cache)}
    cmd = [sys.executable, "-m", "designopt.cli", "run", str(cfg), "--quiet", "--no-figures",
           "--out", str(tmp_path / out), *flags]  # fmt: skip
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    with h5py.File(tmp_path / out) as h:
        return {k: h[k][()] for k in KEYS}


def _files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file()] if folder.exists() else []


def test_cache_folder_is_honoured_no_cache_writes_nothing_and_numbers_are_identical(tmp_path):
    cache = tmp_path / "cache"
    cold = _run(tmp_path, "cold.h5", cache)
    n_cold = len(_files(cache))
    assert n_cold > 0, "DESIGNOPT_CACHE_DIR was not used"
    warm = _run(tmp_path, "warm.h5", cache)  # programs loaded from the cache
    assert len(_files(cache)) == n_cold  # the same programs: nothing new written
    other = tmp_path / "other"
    off = _run(tmp_path, "off.h5", other, "--no-cache")
    assert _files(other) == [], "--no-cache wrote into the cache folder"
    for k in KEYS:
        np.testing.assert_array_equal(warm[k], cold[k], err_msg=k)
        np.testing.assert_array_equal(off[k], cold[k], err_msg=k)
