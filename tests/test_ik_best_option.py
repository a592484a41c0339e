"""``study.task.ik.best`` and ``climb``: a bad choice is refused in one line naming the key
(exit 2 from the CLI), ``clearance`` needs a collision section, and the solver's options
carry ``climb`` (docs/task.md, "The kept solution")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from designopt.cli import main

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


def test_coverage_figure_sees_a_weak_search_and_not_a_thorough_one():
    """The coverage figure (``blocks.coverage``, archived as the targets group's attrs
    ``ik_better``): with the first converged seed kept (``n_best: 1``) on a redundant
    planar 3R, a second, independent set of seeds finds a better solution at most
    targets; with the best-solution settings at almost none (≤ 2 %)."""
    import jax
    import jax.numpy as jnp

    from designopt.app import config as C
    from designopt.core import keys as K
    from designopt.studies.serial import STUDY

    jax.config.update("jax_enable_x64", True)
    path = ROOT / "tests/data/planar3r_task.yaml"
    cfg = C.validate(yaml.safe_load(path.read_text()), str(path), checks=False)
    s = cfg.study
    x = [float(np.mean(v)) for v in s.variables.values()]
    keys = K.streams(0)
    weak = s.model_copy(update={"task": s.task.model_copy(update={
        "ik": s.task.ik.model_copy(update={"n_best": 1, "climb": 0})})})  # fmt: skip
    a = STUDY.targets(weak, x, keys, jnp.float64)["attrs"]
    b = STUDY.targets(s, x, keys, jnp.float64)["attrs"]
    assert a["ik_better_n"] >= 64 and b["ik_better_n"] == a["ik_better_n"]
    assert a["ik_better"] > 0.2, a["ik_better"]
    assert b["ik_better"] <= 0.02, b["ik_better"]
    # printed (the run summary's line) and, above 2 %, warned about with what to raise
    share = f"{100 * a['ik_better']:.1f} % of {int(a['ik_better_n'])} targets"
    assert len(a["lines"]) == 1 and share in a["lines"][0], a["lines"]
    assert len(a["warnings"]) == 1 and share in a["warnings"][0], a["warnings"]
    assert "raise study.task.ik.n_best (now 1)" in a["warnings"][0]
    assert f"{100 * b['ik_better']:.1f} % of" in b["lines"][0] and "warnings" not in b


def test_coverage_warning_reaches_the_run_summary_and_the_archive(tmp_path, capsys):
    """A run whose IK keeps the first converged seed on the redundant 3R: the coverage
    line and its ``warning:`` are printed by ``designopt run`` and by ``designopt show``
    of its archive, and kept in the archive's final warnings."""
    import designopt

    out = tmp_path / "weak.h5"
    argv = ["run", str(ROOT / "tests/data/planar3r_task.yaml"), "--out", str(out),
            "--no-figures", "--set", "study.task.ik.n_best=1", "--set", "study.task.ik.climb=0",
            "--set", "optimizer.n_iters=1", "--set", "optimizer.n_particles=2"]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "  IK coverage: a second, independent set of seeds finds a better solution" in text
    warn = [ln for ln in text.splitlines() if ln.startswith("  warning: IK coverage")]
    assert len(warn) == 1 and "raise study.task.ik.n_best (now 1)" in warn[0], text
    assert main(["show", str(out)]) == 0  # show prints the line and the warning too
    shown = capsys.readouterr().out
    assert "IK coverage: a second, independent set of seeds" in shown
    assert f"warning: {warn[0].strip().removeprefix('warning: ')}" in shown
    rec = designopt.load(out)
    assert any(w.startswith("IK coverage") for w in rec.warnings)
    share = rec.groups["targets"]["attrs"]["ik_better"]
    assert share > 0.02 and f"{100 * share:.1f} %" in warn[0]


def test_coverage_lines_count_targets_per_arm_and_give_clearance_its_unit():
    """Two arms compare targets × arms (``ik_better_n`` = 128 is 64 targets × 2 arms), and
    the clearance's threshold carries the chain's length unit; at 2 % exactly no warning."""
    from types import SimpleNamespace as NS

    from designopt.studies.serial import blocks

    ik = NS(best="clearance", n_best=1, n_nearest=4, climb=0)
    s = NS(arms=[0, 1], task=NS(ik=ik), chain=None, units=NS(length="mm"))
    (line,), (warn,) = blocks.coverage_lines(s, {"ik_better": 0.05, "ik_better_n": 128.0})
    assert line.endswith("(clearance higher by > 0.001 mm) at 5.0 % of 64 targets × 2 arms")
    assert "at 5.0 % of 64 targets × 2 arms (more than 2 %)" in warn
    lines, warns = blocks.coverage_lines(s, {"ik_better": 0.02, "ik_better_n": 128.0})
    assert warns == [] and "2.0 % of 64 targets × 2 arms" in lines[0]
