"""``study.task.ik.best`` and ``climb``: a bad choice is refused in one line naming the key
(exit 2 from the CLI), ``clearance`` needs a collision section, and the solver's options
carry ``climb`` (docs/task.md, "The kept solution")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _run(tmp_path: Path, ik: dict, drop_collision: bool = False) -> subprocess.CompletedProcess:
    cfg = yaml.safe_load((ROOT / "tests/data/ur5_port.yaml").read_text())
    cfg["study"]["task"]["ik"] = ik
    cfg["study"]["task"]["region"]["points"] = str(ROOT / "tests/data/ur5_port_targets.csv")
    cfg["study"]["chain"]["urdf"] = str(ROOT / "configs/robots/ur5/ur5_instrument.urdf")
    if drop_collision:
        cfg["study"].pop("collision")
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return subprocess.run([sys.executable, "-m", "designopt", "run", str(p), "--dry-run"],
                          capture_output=True, text=True, cwd=tmp_path)  # fmt: skip


def test_unknown_best_is_refused_naming_the_key(tmp_path):
    r = _run(tmp_path, {"best": "fastest"})
    assert r.returncode == 2, r.stderr
    err = r.stderr.strip()
    assert "study.task.ik.best" in err and "Traceback" not in err
    assert len(err.splitlines()) == 1


def test_clearance_needs_collision(tmp_path):
    r = _run(tmp_path, {"best": "clearance"}, drop_collision=True)
    assert r.returncode == 2, r.stderr
    assert "task.ik.best" in r.stderr and "collision" in r.stderr
    assert "Traceback" not in r.stderr


def test_climb_reaches_the_solver_options():
    from designopt.app import config as C
    from designopt.studies.serial import taskindex

    cfg = C.validate(yaml.safe_load((ROOT / "tests/data/ur5_port.yaml").read_text()),
                     str(ROOT / "tests/data/ur5_port.yaml"), checks=False)  # fmt: skip
    o = taskindex.options(cfg.study)
    assert (o.n_best, o.climb) == (8, 12)
