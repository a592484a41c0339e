"""Numbers that cannot be trusted never get through (designopt.core.validation), and results say
when they are infeasible: one test per row of the table in docs/configs.md ("Numbers
that are refused"), plus a sweep of NaN, ±inf and huge values over every real number of
every shipped config, and the API and CLI flags."""

from __future__ import annotations

import copy
import csv
import math
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

import designopt
from designopt.app import config, pipeline
from designopt.cli.commands import main
from designopt.core import validation
from designopt.core.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]

PLANAR = {
    "study": {
        "name": "serial",
        "chain": {
            "convention": "standard",
            "joints": [
                {"type": "R", "a": "l1", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]},
                {"type": "R", "a": "l2", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]},
            ],
        },  # fmt: skip
        "variables": {"l1": [0.2, 2.0], "l2": [0.2, 2.0]},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "joint", "n_samples": 512},
        "objective": {"gci": -1.0},
    },
    "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 2, "n_runs": 1},
    "scan": {"vary": {"l2": {"from": 0.2, "to": 2.0, "num": 5}}, "design": {"l1": 1.0}},
    "precision": "float64",
    "seed": 0,
}
MASTER9 = {
    "study": {"name": "master9", "indices": {"n_samples": 1024}, "n_norm": 8},
    "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 2, "n_runs": 1},
    "precision": "float64",
    "seed": 0,
}


def cfg_file(tmp_path: Path, raw: dict, edit=None) -> Path:
    raw = copy.deepcopy(raw)
    if edit is not None:
        edit(raw)
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(raw, sort_keys=False))
    return p


def one_line_exit_2(capsys, argv: list[str], *needles: str) -> str:
    capsys.readouterr()
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in out + err
    for n in needles:
        assert n in err, (n, err)
    return err


def written(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if p.name != "c.yaml")


# ------------------------------------------------------------- the table's rows


@pytest.mark.parametrize("edit,key", [
    (lambda r: r["study"]["variables"].update(l2=[0.2, math.inf]), "study.variables.l2.1"),
    (lambda r: r["study"]["chain"]["joints"][0].update(limits=[-math.inf, 180]),
     "study.chain.joints.0.limits.0"),
    (lambda r: r["study"].update(fixed={"h": math.nan}) or r["study"]["chain"]["joints"][1]
     .update(d="h"), "study.fixed.h"),
    (lambda r: r["study"]["chain"]["joints"][0].update(alpha=math.nan),
     "study.chain.joints.0.alpha"),
    (lambda r: r["scan"].update(vary={"l2": [0.5, math.nan, 1.0]}), "scan.vary.l2.1"),
    (lambda r: r["study"]["variables"].update(l2=[0.2, "1e999"]), "study.variables.l2.1"),
    (lambda r: r["study"]["variables"].update(l2=[0.2, 1e308]), "study.variables.l2.1"),
    (lambda r: r["study"]["objective"].update(gci=math.nan), "study.objective.gci"),
])  # fmt: skip
@pytest.mark.parametrize("command", ["run", "scan", "eval"])
def test_serial_non_finite_numbers_are_refused_before_work(tmp_path, capsys, edit, key, command):
    p = cfg_file(tmp_path, PLANAR, edit)
    extra = [] if command == "eval" else ["--out", str(tmp_path / "out" / "a.h5"), "--quiet"]
    one_line_exit_2(capsys, [command, str(p), *extra], f"key '{key}'", str(p))
    assert written(tmp_path) == []


@pytest.mark.parametrize("edit,key", [
    (lambda r: r["study"].update(variables={"a1": [250, math.inf], "a3": [250, 350]}),
     "study.variables.a1.1"),
    (lambda r: r["study"].update(weights=[math.nan, 2, 1]), "study.weights.0"),
])  # fmt: skip
def test_master9_non_finite_numbers_are_refused(tmp_path, capsys, edit, key):
    p = cfg_file(tmp_path, MASTER9, edit)
    one_line_exit_2(capsys, ["run", str(p), "--out", str(tmp_path / "o" / "a.h5")], f"'{key}'")
    assert written(tmp_path) == []


@pytest.mark.parametrize("design,needle", [
    (["l1=1e308"], "--design l1: 1e+308 is too large"),
    (["l1=nan"], "--design l1: nan is not a finite number"),
    (["l1=-inf"], "--design l1: -inf is not a finite number"),
    (["l1=1e999"], "--design l1: inf"),
    (["l1=1,l1=2"], "--design l1: given twice"),  # within one design (one flag)
    (["l1=abc"], "--design l1: 'abc' is not a number"),
])  # fmt: skip
def test_design_flags(tmp_path, capsys, design, needle):
    p = cfg_file(tmp_path, PLANAR)
    argv = ["eval", str(p)] + [x for d in design for x in ("--design", d)]
    one_line_exit_2(capsys, argv, needle)


@pytest.mark.parametrize("seed", ["99999999999999999999999", "-1", "4294967296"])
def test_seed_flag_out_of_range(tmp_path, capsys, seed):
    p = cfg_file(tmp_path, PLANAR)
    one_line_exit_2(capsys, ["eval", str(p), "--seed", seed], f"--seed {seed}", "4294967295")


def test_largest_seed_is_accepted(tmp_path, capsys):
    p = cfg_file(tmp_path, PLANAR, lambda r: r.update(seed=validation.SEED_MAX))
    assert main(["eval", str(p), "--json"]) == 0


def test_seed_in_the_config_out_of_range(tmp_path, capsys):
    p = cfg_file(tmp_path, PLANAR, lambda r: r.update(seed=2**70))
    one_line_exit_2(capsys, ["eval", str(p)], "key 'seed': must be ≤ 4294967295")


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1e300, [0.5, math.nan]])
def test_the_python_api_refuses_non_finite_designs(value):
    with pytest.raises(ConfigError, match="design variable 'l1'"):
        designopt.evaluate(PLANAR, {"l1": value})


def test_the_python_api_refuses_a_non_finite_config_built_in_python():
    cfg = config.validate(copy.deepcopy(PLANAR), "cfg")
    cfg.study.fixed["h"] = math.inf  # past validation: the API checks again
    with pytest.raises(ConfigError, match="study.fixed.h"):
        designopt.evaluate(cfg, {"l1": 1.0})


def test_scan_range_num_zero_names_the_key_not_pydantic(tmp_path, capsys):
    p = cfg_file(tmp_path, PLANAR, lambda r: r["scan"]["vary"]["l2"].update(num=0))
    err = one_line_exit_2(capsys, ["scan", str(p)], "key 'scan.vary.l2.num': must be ≥ 1")
    assert "list[float]" not in err and "Input should" not in err


@pytest.mark.parametrize("edit,needle", [
    (lambda r: r["scan"].update(mode="zip"), "key 'scan.mode': must be one of 'grid' or 'list'"),
    (lambda r: r["optimizer"].update(n_particles="many"),
     "key 'optimizer.n_particles': must be an integer"),
    (lambda r: r["study"]["variables"].update(l2=[0.2]),
     "key 'study.variables.l2': needs at least 2 values"),
    (lambda r: r["study"].update(bogus=1), "key 'study.bogus': unknown key"),
])  # fmt: skip
def test_messages_in_the_words_of_a_config(tmp_path, capsys, edit, needle):
    p = cfg_file(tmp_path, PLANAR, edit)
    err = one_line_exit_2(capsys, ["run", str(p), "--dry-run"], needle)
    for internal in ("list[float]", "function-after", "tuple[", "Input should", "pydantic"):
        assert internal not in err, err


def test_scan_names_the_best_feasible_design_apart_from_a_better_infeasible_one(tmp_path, capsys):
    """The planar 2R's GCI peaks near l2/l1 ≈ 0.7 (f = -GCI: about -0.30 at l2 = 0.5,
    -0.37 at 0.7). With l1 = 1 and l1 + l2 ≤ 1.5 only l2 ≤ 0.5 is feasible: the summary's
    best is the feasible l2 = 0.5, and the better, infeasible l2 = 0.7 is named apart
    with its violation (0.2)."""

    def edit(r):
        r["study"]["constraints"] = [{"terms": {"l1": 1, "l2": 1}, "le": 1.5}]
        r["scan"]["vary"] = {"l2": [0.3, 0.5, 0.7, 0.9]}

    p = cfg_file(tmp_path, PLANAR, edit)
    out_h5 = tmp_path / "o" / "s.h5"
    assert main(["scan", str(p), "--out", str(out_h5), "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    with h5py.File(out_h5) as h:
        f, v, x = h["scan/f"][()], h["scan/violation"][()], h["scan/x"][()]
    feas = v <= 0
    assert feas.tolist() == [True, True, False, False]
    i = int(np.flatnonzero(feas)[np.argmin(f[feas])])
    assert "constraints: 2 of 4 designs feasible" in out
    assert f"lowest f among the feasible: l1 = 1, l2 = {x[i, 1]:.4g}" in out
    j = int(np.argmin(np.where(feas, np.inf, f)))
    assert f[j] < f[i]  # the optimum of the 2R's GCI lies at l2/l1 ≈ 0.71: infeasible here
    assert f"lower f only where infeasible: l1 = 1, l2 = {x[j, 1]:.4g}" in out
    assert main(["show", str(out_h5)]) == 0
    assert "lowest f among the feasible" in capsys.readouterr().out


def test_eval_reports_feasibility(tmp_path, capsys):
    def edit(r):
        r["study"]["constraints"] = [{"terms": {"l1": 1, "l2": 1}, "le": 1.5}]

    p = cfg_file(tmp_path, PLANAR, edit)
    assert main(["eval", str(p), "--design", "l1=1", "--design", "l2=0.9"]) == 0
    assert "constraints: violated by 0.4" in capsys.readouterr().out
    assert main(["eval", str(p), "--design", "l1=1", "--design", "l2=0.4", "--json"]) == 0
    assert '"feasible": true' in capsys.readouterr().out


def test_a_non_finite_result_writes_nothing(tmp_path, capsys, monkeypatch):
    """The safety net behind the input checks: a run whose final design scores NaN
    (here injected) exits 2 naming the index, and leaves no archive or checkpoint."""
    real = pipeline.run_groups

    def poisoned(cfg, problem, res, dtype):
        tree = real(cfg, problem, res, dtype)
        tree["final"]["gci"] = np.float64(np.nan)
        return tree

    monkeypatch.setattr(pipeline, "run_groups", poisoned)
    p = cfg_file(tmp_path, PLANAR)
    one_line_exit_2(capsys, ["run", str(p), "--out", str(tmp_path / "o" / "a.h5"), "--quiet"],
                    "gci is not finite", "nothing written")  # fmt: skip
    assert written(tmp_path / "o") == []


def test_check_finite_names_the_design():
    X = np.array([[1.0, 0.5], [1.0, 2.0]])
    with pytest.raises(ConfigError, match="at l1 = 1, l2 = 2"):
        pipeline.check_finite({"f": np.array([0.1, np.inf])}, "c.yaml", "scan", ["l1", "l2"], X)


# ------------------------------------------------------------------- IK archives


@pytest.fixture(scope="module")
def ik_archive(tmp_path_factory):
    """The da Vinci IK of the shipped example poses with one unreachable pose added."""
    folder = tmp_path_factory.mktemp("ik")
    rows = list(csv.reader((ROOT / "docs" / "davinci_poses.csv").open()))
    head, body = rows[0], rows[1:4]
    far = dict(zip(head, body[0], strict=True))
    far["x"] = far.get("x", "0")
    if "T03" in far:
        far["T03"] = "5000"
    else:
        far["x"] = "5000"
    poses = folder / "poses.csv"
    with poses.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerows([head, *body, [far[h] for h in head]])
    out = folder / "p_ik.h5"
    assert main(["ik", str(ROOT / "configs" / "davinci_ik.yaml"), "--poses", str(poses),
                 "--out", str(out), "--csv", "--quiet"]) == 0  # fmt: skip
    return out


def test_show_of_an_ik_archive(ik_archive, capsys):
    capsys.readouterr()
    assert main(["show", str(ik_archive)]) == 0
    out = capsys.readouterr().out
    assert "4 poses: 3 solved (75.00 %), 1 failed" in out
    assert "worst errors of the solved: position" in out
    assert "failed rows: 4 (position error" in out


def test_ik_csv_holds_the_archived_joints(ik_archive):
    with h5py.File(ik_archive) as h:
        q, ok = h["ik/q"][()], h["ik/success"][()]
    rows = list(csv.DictReader(ik_archive.with_name("p_ik_joints.csv").open()))
    assert [r["row"] for r in rows] == ["1", "2", "3", "4"]
    # angles in degrees, the insertion q3 in mm; each unit in its column's header
    head = [f"q{i} [{'mm' if i == 3 else 'deg'}]" for i in range(1, 7)]
    got = np.array([[float(r[h]) for h in head] for r in rows])
    want = np.where(np.arange(6) == 2, q, np.rad2deg(q))
    np.testing.assert_array_equal(got, want)  # repr keeps every digit
    assert [r["success"] == "1" for r in rows] == ok.tolist()


@pytest.mark.parametrize("flag,value,needle", [
    ("--max-minutes", "nan", "--max-minutes"),
    ("--max-minutes", "inf", "--max-minutes"),
    ("--max-minutes", "-1", "--max-minutes"),
])  # fmt: skip
def test_other_numeric_flags(tmp_path, capsys, flag, value, needle):
    p = cfg_file(tmp_path, PLANAR)
    one_line_exit_2(capsys, ["run", str(p), flag, value, "--out", str(tmp_path / "o" / "a.h5")],
                    needle)  # fmt: skip
    assert written(tmp_path) == []


def test_an_unused_fixed_value_is_an_error(tmp_path, capsys):
    p = cfg_file(tmp_path, PLANAR, lambda r: r["study"].update(fixed={"l3": 0.3}))
    one_line_exit_2(capsys, ["eval", str(p)], "fixed value(s) ['l3'] appear in no DH entry")


def test_bench_seed_out_of_range(tmp_path, capsys):
    """The benchmark suite's seeds take the same check as a study's (flag and config)."""
    cfg = ROOT / "configs" / "pso_benchmark.yaml"
    out = tmp_path / "b.h5"
    one_line_exit_2(capsys, ["bench", str(cfg), "--seed", str(2**70), "--out", str(out)],
                    f"--seed {2**70}", "4294967295")  # fmt: skip
    p = tmp_path / "c.yaml"
    p.write_text(cfg.read_text() + "\nseed: -1\n" if "seed:" not in cfg.read_text()
                 else cfg.read_text().replace("seed: 0", "seed: -1"))  # fmt: skip
    one_line_exit_2(capsys, ["bench", str(p), "--out", str(out)], "key 'seed': must be ≥ 0")
    assert not out.exists()


def test_task_points_refuse_non_finite_rows(tmp_path):
    from designopt.kinematics.task import read_points

    p = tmp_path / "pts.csv"
    p.write_text("x,y,z\n0,0,0\n1,nan,0\n")
    with pytest.raises(ValueError, match="row 2: nan is not a finite number"):
        read_points(p)
    p.write_text("x,y,z\n0,0,1e300\n")
    with pytest.raises(ValueError, match="row 1: 1e\\+300 is too large"):
        read_points(p)
