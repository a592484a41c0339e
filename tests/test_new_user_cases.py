"""Cases a new user met (issue: views and reports that never crash and never mislead):
an n/a index on the HTML page with its counts and the run's warnings, ``show --csv``
refused before anything is printed, ``--set KEY=null``, YAML's ``1e3`` read as a
number, a ``set`` key given twice, a far region named as the region."""

from __future__ import annotations

from pathlib import Path

import yaml

from designopt.cli.commands import main

DISK = {"shape": "cylinder", "center": [1.1, 0.0, 0.0], "axis": [0, 0, 1], "radius": 0.5,
        "height": 0.0}  # fmt: skip


def _short_arm(tmp_path) -> Path:
    """A 2R arm whose box barely reaches the disk's near edge: a handful of converged
    targets of 64, so collision_free is n/a."""
    cfg = {"study": {
        "name": "serial",
        "chain": {"convention": "standard", "joints": [
            {"type": "R", "a": "l1", "limits": [-180, 180]},
            {"type": "R", "a": "l2", "limits": [-180, 180]}]},
        "variables": {"l1": [0.3, 0.32], "l2": [0.3, 0.32]},
        "task": {"region": DISK, "ik": {"n_best": 1}},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": 64},
        "objective": {"gci": -1.0},
        "collision": {"radius": 0.02, "obstacles": [
            {"shape": "ball", "center": [0.0, 2.0, 0.0], "radius": 0.1}]}},
        "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 1, "n_runs": 1},
        "precision": "float64", "seed": 0, "output": str(tmp_path / "short.h5")}  # fmt: skip
    p = tmp_path / "short.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def test_html_report_says_na_with_counts_and_the_warnings(tmp_path, capsys):
    cfg = _short_arm(tmp_path)
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "collision_free = n/a (" in out and "warning: " in out
    assert main(["report", str(tmp_path / "short.h5"), "--html"]) == 0
    page = (tmp_path / "short.html").read_text()
    assert "n/a (" in page and "Warnings" in page
    assert ">nan<" not in page.lower()


def test_show_csv_is_refused_before_the_summary(tmp_path, capsys):
    cfg = _short_arm(tmp_path)
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 0
    capsys.readouterr()
    assert main(["show", str(tmp_path / "short.h5"), "--csv", str(tmp_path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and "give a .csv file name" in err


def test_set_null_unsets_a_key_and_exponents_without_a_dot_are_numbers(tmp_path, capsys):
    capsys.readouterr()
    argv = ["run", "configs/urdf_puma560_port.yaml", "--dry-run", "--out", str(tmp_path / "o.h5"),
            "--set", "study.task.port=null", "--set", "study.task.insertion=null"]  # fmt: skip
    assert main(argv) == 0  # no port: the config as if the file gave none
    two = yaml.safe_load(open("configs/two_arms_front.yaml"))
    two["study"]["arms"][0]["base"]["xyz"] = ["-b", 0, "1e-3"]  # YAML 1.1 reads 1e-3 as text
    two["output"] = str(tmp_path / "t.h5")
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(two))
    assert main(["run", str(tmp_path / "t.yaml"), "--dry-run"]) == 0


def test_a_set_field_given_twice_is_refused(tmp_path, capsys):
    cfg = yaml.safe_load(open("configs/urdf_puma560_port.yaml"))
    cfg["study"]["chain"]["urdf"] = str(Path("configs/robots/puma560.urdf").resolve())
    cfg["study"]["chain"]["set"] = {"joint3.origin.x": 0.5, "joint3": {"origin": {"x": "a2"}},
                                    "joint5.origin.z": "d4", "tool_joint.origin.z": "l_tool"}  # fmt: skip
    cfg["output"] = str(tmp_path / "o.h5")
    (tmp_path / "d.yaml").write_text(yaml.safe_dump(cfg))
    capsys.readouterr()
    assert main(["run", str(tmp_path / "d.yaml"), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "study.chain.set.joint3.origin.x': given twice" in err and len(err.strip().splitlines()) == 1


def test_a_far_region_with_ports_is_named_as_the_region(tmp_path, capsys):
    capsys.readouterr()
    argv = ["run", "configs/urdf_puma560_port.yaml", "--dry-run", "--out", str(tmp_path / "o.h5"),
            "--set", "study.task.region.center=[50, 0.1, -0.36]"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "task.region" in err and "insertion" not in err.split(":")[2]


def test_an_na_objective_term_is_said_beside_f():
    from designopt.app.config import validate
    from designopt.studies.serial import reach

    cfg = yaml.safe_load(open("configs/two_arms_front.yaml"))
    cfg["study"]["objective"] = {"arms_free": -1.0}
    cfg["optimizer"] = {"name": "ptpso", "n_particles": 4, "n_iters": 1}
    s = validate(cfg, "test").study
    final = {"f": 0.0, "arms_free": float("nan"), "arms_free_se": float("nan"),
             "arms_free_n": 3.0, "arms_free_of": 64.0, "reach_all": 0.05, "reach_all_se": 0.02}  # fmt: skip
    w = reach.warnings(s, final)
    assert any(x.startswith("f: its term(s) arms_free n/a") for x in w), w
    assert any("arms_free: n/a (3 of 64" in x for x in w), w
