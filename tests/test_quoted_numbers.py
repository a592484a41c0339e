"""Every quoted number has one path, and every run kind says the same warnings (issue #65,
items 3-5; ``designopt.app.quoted``).

- a weighted run (two runs, its search on ``optimizer.fidelity``'s IK settings), a
  constrained run and a front of a planar 3R through 128 fixed targets
  (tests/data/planar3r_task.yaml): ``eval --fresh`` of every quoted design gives the
  archive's values bit for bit (value and SE), on the stream the run used and with its
  sample count; the weighted run's quoted values are the study's own IK settings' (the
  same config without the fidelity gives them), not the search's;
- ``eval`` prints the IK coverage figure, in text and JSON, and a front archives and
  prints it (its worst design's);
- a front whose designs reach nothing (every target inside a ball of the scene) prints
  the warnings the same config prints as a weighted run.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import yaml

from designopt.app import records
from designopt.cli.commands import main
from designopt.io import archive

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"


def _raw(**over) -> dict:
    raw = yaml.safe_load((DATA / "planar3r_task.yaml").read_text())
    raw["study"]["task"]["region"]["points"] = str(DATA / "planar3r_targets.csv")
    raw["final"] = {"n_samples": 64}
    for k, v in over.items():
        node = raw
        *head, last = k.split(".")
        for h in head:
            node = node.setdefault(h, {})
        node[last] = v
    return raw


def _write(tmp_path: Path, raw: dict, name: str) -> str:
    raw = copy.deepcopy(raw) | {"output": str(tmp_path / f"{name}.h5")}
    p = tmp_path / f"{name}.yaml"
    p.write_text(yaml.safe_dump(raw))
    return str(p)


def _eval(capsys, cfg: str, x: dict[str, float], *more: str) -> dict:
    design = [f"--design={k}={v!r}" for k, v in x.items()]
    capsys.readouterr()
    assert main(["eval", cfg, *design, "--fresh", "--json", *more]) == 0
    return json.loads(capsys.readouterr().out)


def _same(ev: dict, vals: dict, keys) -> None:
    for k in keys:
        a = float(np.asarray(vals[k]))
        assert ev[k] == a or (ev[k] is None and np.isnan(a)), (k, ev[k], a)


INDICES = ("gci", "gci_se", "reach", "reach_se", "manipulability", "manipulability_se",
           "joint_margin", "joint_margin_se")  # fmt: skip


def test_a_weighted_run_quotes_the_studys_ik_and_eval_fresh_gives_it(tmp_path, capsys):
    """Two runs (the final design and each run's best scored in one batch), the search on
    ``n_best: 2`` where the study asks 8: ``eval --fresh`` gives ``final/`` bit for bit,
    and so does ``eval --fresh`` of the same config without the fidelity (the quoted
    values are the study's settings', whatever the search scored with)."""
    opt = {"name": "ptpso", "n_particles": 4, "n_iters": 2, "n_runs": 2,
           "fidelity": {"study.task.ik.n_best": 2}}  # fmt: skip
    p = _write(tmp_path, _raw(optimizer=opt), "w")
    q = _write(tmp_path, _raw(optimizer={k: v for k, v in opt.items() if k != "fidelity"}), "q")
    assert main(["run", p, "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    rec = records.load(tmp_path / "w.h5")
    assert rec.fidelity == {"study.task.ik.n_best": 2} and rec.n_samples_used == 128
    fin = rec.final
    ev = _eval(capsys, p, rec.x)
    _same(ev, fin, ("f", "f_se", *INDICES))
    design = [f"--design={k}={v!r}" for k, v in rec.x.items()]
    assert main(["eval", p, *design, "--fresh"]) == 0  # the text names the stream
    assert "(the final stream, final.n_samples: 128 samples per design)" in capsys.readouterr().out
    _same(_eval(capsys, q, rec.x), fin, ("f", "f_se", *INDICES))  # the study's own IK
    # the quoted design's coverage figure: eval --fresh says the run's
    tg = rec["targets"]["attrs"]
    assert ev["ik_better"] == float(tg["ik_better"]) and ev["ik_coverage"]
    assert ev["ik_coverage"][0].startswith("IK coverage:") and "IK coverage:" in out
    # each run's best design, scored in the run's batch, gives eval --fresh's too
    runs = rec.runs
    x0 = dict(zip(rec.names, np.asarray(runs["x"])[0].tolist(), strict=True))
    _same(_eval(capsys, p, x0), {k: np.asarray(runs[k])[0] for k in INDICES}, INDICES)


def test_a_constrained_run_and_eval_print_the_coverage_figure(tmp_path, capsys):
    """A constrained run's final design: ``eval --fresh`` gives it bit for bit; ``eval``
    (text and JSON, the study's own samples) prints the IK coverage figure."""
    cons = [{"index": "reach", "ge": 0.9}, {"terms": {"l1": 1, "l2": 1}, "le": 2.2}]
    p = _write(tmp_path, _raw(**{"study.constraints": cons,
                                 "optimizer.n_iters": 2}), "c")  # fmt: skip
    assert main(["run", p, "--quiet", "--no-figures"]) == 0
    capsys.readouterr()
    rec = records.load(tmp_path / "c.h5")
    ev = _eval(capsys, p, rec.x)
    _same(ev, rec.final, ("f", "f_se", "violation", *INDICES))
    assert ev["feasible"] == bool(float(rec.final["violation"]) <= 0)
    design = [f"--design={k}={v!r}" for k, v in rec.x.items()]
    assert main(["eval", p, *design, "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert 0 <= js["ik_better"] <= 1 and js["ik_better_n"] > 0
    (line,) = js["ik_coverage"]
    assert line.startswith("IK coverage: a second, independent set of seeds") and "%" in line
    assert main(["eval", p, *design]) == 0
    txt = capsys.readouterr().out
    assert line in txt.splitlines()  # the text prints the same line
    for w in js["warnings"]:
        assert f"warning: {w}" in txt


def test_a_fronts_designs_give_eval_fresh_and_carry_the_coverage_figure(tmp_path, capsys):
    """A front of gci against the total length, two runs: every front design (and each
    run's recommended design) gives ``eval --fresh``'s values bit for bit, on the front's
    stream and its sample count; the front archives every design's coverage share and
    prints its worst design's line, in the summary and on the HTML page."""
    from designopt.figures.html.page import page

    raw = _raw(**{"study.objective": {"pareto": {"gci": "max",
                                                 "length": {"min": {"l1": 1, "l2": 1, "l3": 1}}}},
                  "optimizer": {"name": "nsga2", "n_particles": 8, "n_iters": 2, "n_runs": 2},
                  "front": {"n_samples": 64, "max_points": 3}})  # fmt: skip
    raw.pop("final")
    p = _write(tmp_path, raw, "f")
    assert main(["run", p, "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    rec = records.load(tmp_path / "f.h5")
    vals, n = rec.values, len(rec.X)
    assert 1 <= n <= 3
    for i, x in enumerate(rec.designs):
        ev = _eval(capsys, p, x)
        _same(ev, {k: v[i] for k, v in vals.items()}, INDICES)
        assert rec.n_samples == 128
    design = [f"--design={k}={v!r}" for k, v in rec.designs[0].items()]
    assert main(["eval", p, *design, "--fresh"]) == 0  # the text names the stream
    assert "(the front stream, front.n_samples: 128 samples per design)" in capsys.readouterr().out
    runs = rec.runs
    x0 = dict(zip(rec.names, np.asarray(runs["x"])[1].tolist(), strict=True))
    _same(_eval(capsys, p, x0), {k: np.asarray(runs[k])[1] for k in INDICES}, INDICES)
    at = rec["front"]["attrs"]
    share = np.asarray(at["ik_better"], np.float64)
    assert share.shape == (n,) and np.all((share >= 0) & (share <= 1))
    (line,) = rec.coverage_lines
    assert "IK coverage: a second, independent set of seeds" in line
    assert line in out
    html = page(archive.read(tmp_path / "f.h5"))
    assert "<h3>IK coverage</h3>" in html and "IK coverage: a second" in html


def test_a_front_that_reaches_nothing_says_so_as_a_weighted_run_does(tmp_path, capsys):
    """Every target inside a ball of the scene: no design reaches any. The weighted run
    says ``reach = 0`` and the missed reach constraint; the front of the same config
    says the same lines of its designs (each distinct line once, naming them), in its
    summary, its archive and on its HTML page."""
    from designopt.figures.html.page import page

    scene = {"radius": 0.02, "obstacles": [{"shape": "ball", "center": [1.0, 0.3, 0.0],
                                            "radius": 0.7}]}  # fmt: skip
    cons = [{"index": "reach", "ge": 0.9}]
    base = _raw(**{"study.collision": scene, "study.constraints": cons,
                   "optimizer.n_iters": 1})  # fmt: skip
    p = _write(tmp_path, base, "w")
    assert main(["run", p, "--quiet", "--no-figures"]) == 0
    out_w = capsys.readouterr().out
    w_lines = [ln.strip() for ln in out_w.splitlines() if ln.strip().startswith("warning: ")]
    assert any(ln.startswith("warning: reach = 0 ") for ln in w_lines), out_w
    raw = copy.deepcopy(base)
    raw["study"]["objective"] = {"pareto": {"gci": "max", "reach": "max"}}
    raw["optimizer"] = {"name": "nsga2", "n_particles": 8, "n_iters": 1, "n_runs": 1}
    raw["front"] = {"n_samples": 64, "max_points": 3}
    raw.pop("final")
    q = _write(tmp_path, raw, "f")
    assert main(["run", q, "--quiet", "--no-figures"]) == 0
    out_f = capsys.readouterr().out
    f_lines = [ln.strip() for ln in out_f.splitlines() if ln.strip().startswith("warning: ")]
    rec = records.load(tmp_path / "f.h5")
    assert np.all(np.asarray(rec.values["reach"]) == 0)
    n = len(rec.X)
    every = ", ".join(f"#{i}" for i in range(n))
    label = f"front design{'s' if n > 1 else ''} {every}: "
    for ln in w_lines:  # the weighted run's lines that speak of the values, not of f
        body = ln.removeprefix("warning: ")
        if body.startswith(("reach", "collision_free")):
            assert f"warning: {label}{body}" in f_lines, (body, f_lines)
    assert rec.warnings and all(w.startswith("front design") for w in rec.warnings)
    html = page(archive.read(tmp_path / "f.h5"))
    assert "<h3>Warnings</h3>" in html and "reach = 0 " in html
    assert "Traceback" not in out_w + out_f


def test_a_fronts_warnings_are_said_once_naming_their_designs():
    """``quoted.grouped``: each distinct line once, with the designs it concerns in the
    order first said; the page shows the coverage lines and the warnings as text."""
    from designopt.app import quoted
    from designopt.figures.html.run import notes_html

    per = [["reach = 0 ± 0: a", "x"], [], ["reach = 0 ± 0: a"], ["y <b>"]]
    assert quoted.grouped(per, "front design") == [
        "front designs #0, #2: reach = 0 ± 0: a", "front design #0: x",
        "front design #3: y <b>"]  # fmt: skip
    assert quoted.grouped([[], []]) == []
    html = notes_html(["IK coverage: 1.0 %"], json.dumps(["y <b>"]))
    assert "<h3>IK coverage</h3>" in html and "<li>y &lt;b&gt;</li>" in html
    assert notes_html([], []) == "" and notes_html(None, None) == ""
