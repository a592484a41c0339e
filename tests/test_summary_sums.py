"""One true summary (issue 53): the wall line's parts add up to its total, the line is
the one place that splits the wall time and counts XLA programs (the run's own lines
no longer give a second split or a second count), every index is printed with its unit,
and `eval`'s warnings speak of the design given, not of a best design found."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from designopt.cli.commands import main

ROOT = Path(__file__).resolve().parents[1]
TINY = """
study:
  name: serial
  chain:
    convention: standard
    joints:
      - {type: R, a: l1, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
      - {type: R, a: l2, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
  variables: {l1: [0.2, 2.0], l2: [0.2, 2.0]}
  units: {length: m}
  indices: {jacobian: [vx, vy], norm: "2", measure: joint, n_samples: 500}
  objective: {gci: -1.0}
optimizer: {name: ptpso, n_particles: 6, n_iters: 3, n_runs: 1}
precision: float64
seed: 0
output: OUT
"""
PART = re.compile(r"(start-up|setup|optimizer|scoring|figures|rest) ([\d.]+) s")


def test_the_wall_line_adds_up_and_is_the_one_count(tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(TINY.replace("OUT", str(tmp_path / "a.h5")))
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    wall = [ln for ln in lines if ln.startswith("wall ")]
    assert len(wall) == 1 and wall[0] == lines[-1], out  # one split of the wall time
    total = float(wall[0].split()[1])
    parts = dict((k, float(v)) for k, v in PART.findall(wall[0]))
    assert list(parts) == ["start-up", "setup", "optimizer", "scoring", "figures", "rest"]
    # each part and the total rounded to 0.1 s: the sum within 7 roundings of 0.05 s
    assert abs(sum(parts.values()) - total) <= 7 * 0.05 + 1e-9, wall[0]
    assert parts["figures"] == 0.0 and parts["optimizer"] > 0
    compile_s = float(re.search(r"compile ([\d.]+) s summed over threads", wall[0]).group(1))
    assert 0 < compile_s <= total + 0.05  # this run compiles on one thread (no staged IK)
    # one count of programs, with its meaning stated, and no other count anywhere
    assert len(re.findall(r"\d+ XLA programs", out)) == 1
    assert "compilations" not in out and "loading it from the compilation cache" in wall[0]
    # the search's samples, and the final design's fresh re-scoring (4 ×: final.n_samples)
    assert "samples per design: 500 in the search, 2000 fresh for the final values" in lines
    # every index with its unit: manipulability of a planar 2R in m^2, gci dimensionless
    man = [ln for ln in lines if ln.strip().startswith("manipulability")]
    assert len(man) == 1 and man[0].rstrip().split("±")[1].split()[1] == "m^2", man
    gci = [ln for ln in lines if ln.strip().startswith("gci ")]
    assert gci and " m" not in gci[0].split("±")[1], gci
    # show: the same indices with their units
    assert main(["show", str(tmp_path / "a.h5")]) == 0
    shown = capsys.readouterr().out
    m = re.search(r"manipulability = [\d.]+ ± [\d.e+-]+ (\S+)", shown)
    assert m and m.group(1).rstrip(";") == "m^2", shown


def test_the_archived_stage_times_fit_inside_the_printed_wall(tmp_path, capsys):
    """The archive's stage times are parts of the run (setup + optimizer + scoring ≤
    wall), so no printed line can add them to more than the total."""
    import h5py

    cfg = tmp_path / "c.yaml"
    cfg.write_text(TINY.replace("OUT", str(tmp_path / "a.h5")))
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 0
    capsys.readouterr()
    with h5py.File(tmp_path / "a.h5") as h:
        a = {k: float(h.attrs[k]) for k in ("wall_time_s", "setup_time_s", "optimizer_time_s",
                                              "post_time_s", "compile_time_s")}  # fmt: skip
    assert a["setup_time_s"] + a["optimizer_time_s"] + a["post_time_s"] <= a["wall_time_s"] + 1e-9
    assert a["compile_time_s"] <= a["wall_time_s"] + 1e-9
    assert np.isfinite(list(a.values())).all()


def test_eval_warnings_speak_of_the_design_given(tmp_path, capsys):
    """A user's design missing a constraint: "missed by this design"."""
    cfg = ROOT / "configs/planar2r_task.yaml"
    rc = main(["eval", str(cfg), "--set", "study.indices.n_samples=64", "--design", "l1=0.3",
               "l2=0.3", "--no-cache"])  # fmt: skip
    out = capsys.readouterr().out
    assert rc == 0
    warns = [ln for ln in out.splitlines() if ln.startswith("warning:")]
    assert any("missed by this design" in w for w in warns), out
    assert "best design" not in out


def test_a_replay_run_has_one_wall_line_that_adds_up(tmp_path, capsys):
    """A study whose run is a replay (rcm_teleop): its one stage, and no second split."""
    cfg = ROOT / "configs/rcm_teleop.yaml"
    assert main(["run", str(cfg), "--out", str(tmp_path / "t.h5"), "--quiet",
                 "--no-figures"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    wall = [ln for ln in out.splitlines() if "wall" in ln and " s" in ln]
    assert len(wall) == 1 and wall[0].startswith("wall "), out
    total = float(wall[0].split()[1])
    parts = dict((k, float(v)) for k, v in re.findall(
        r"(start-up|run|figures|rest) ([\d.]+) s", wall[0]))  # fmt: skip
    assert list(parts) == ["start-up", "run", "figures", "rest"], wall[0]
    assert abs(sum(parts.values()) - total) <= 5 * 0.05 + 1e-9, wall[0]
    assert len(re.findall(r"\d+ XLA programs", out)) == 1
