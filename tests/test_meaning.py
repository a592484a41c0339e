"""Results that say when they mean nothing, in real units (docs/task.md, docs/urdf.md):
a task region no design can reach is refused before anything runs (the reach bound of
every design against brute-force forward kinematics, the region's nearest distance
against samples), a final design far from what was asked says so in the summary, the
archive, ``show`` and its figure; lengths are printed in the chain's declared unit (m
for a URDF), angles in degrees; a float64 config runs from Python with JAX's global
precision untouched; ``--overwrite`` leaves nothing of the old archive beside the new."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from figcheck import assert_clean

import designopt
from designopt.cli.commands import main
from designopt.kinematics import task as tk
from designopt.kinematics.kernel import dh_model

ROOT = Path(__file__).resolve().parents[1]


def planar_task(tmp_path: Path, center=(1.2, 0, 0), reach=None, n=64, iters=2, **study) -> Path:
    """A tiny planar 2R task config (the disk of configs/planar2r_task.yaml, moved)."""
    s = {"name": "serial",
         "chain": {"convention": "standard",
                   "joints": [{"type": "R", "a": "l1", "limits": [-180, 180]},
                              {"type": "R", "a": "l2", "limits": [-180, 180]}]},
         "variables": {"l1": [0.2, 2.0], "l2": [0.2, 2.0]},
         "task": {"region": {"shape": "cylinder", "center": list(center), "axis": [0, 0, 1],
                             "radius": 0.5, "height": 0},
                  "ik": {"n_db": 64, "n_nearest": 0, "n_random": 2}},
         "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": n},
         "objective": {"gci": -1.0}} | study  # fmt: skip
    if reach is not None:
        s["constraints"] = [{"index": "reach", "ge": reach}]
    raw = {"study": s, "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": iters},
           "precision": "float64", "seed": 0, "output": str(tmp_path / "out" / "a.h5")}  # fmt: skip
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(raw))
    return p


def one_line_exit_2(capsys, argv, *needles):
    assert main(argv) == 2, argv
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, (n, err)
    return err


# ------------------------------------------------------------ before: reach and size


def test_a_task_no_design_can_reach_is_refused_before_anything_runs(tmp_path, capsys):
    """The disk 50 L away (a mm/m slip): exit 2 naming study.task.region, its nearest
    distance (49.5) and the largest reach (l1 + l2 ≤ 4), for run, --dry-run, scan and eval;
    nothing written."""
    cfg = planar_task(tmp_path, center=(50, 0, 0))
    for argv in (["run", str(cfg), "--quiet"], ["run", str(cfg), "--dry-run"],
                 ["eval", str(cfg), "--design", "l1=1"]):  # fmt: skip
        one_line_exit_2(capsys, argv, "key 'study.task.region'", "49.5 L", "at most 4 L")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]


def test_a_task_just_within_reach_is_accepted(tmp_path, capsys):
    """The disk's nearest point 3.95 from the base, the longest arm 4: not refused."""
    cfg = planar_task(tmp_path, center=(4.45, 0, 0))
    assert main(["run", str(cfg), "--dry-run"]) == 0, capsys.readouterr().err


def test_a_box_of_zero_size_is_refused(tmp_path, capsys):
    raw = yaml.safe_load(planar_task(tmp_path).read_text())
    raw["study"]["task"]["region"] = {"shape": "box", "center": [1.2, 0, 0], "size": [0, 0, 0]}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    one_line_exit_2(capsys, ["run", str(tmp_path / "c.yaml"), "--dry-run"],
                    "key 'study.task.region.size'", "one point")  # fmt: skip


def test_reach_bound_holds_and_is_tight_for_a_stretched_chain():
    """Brute force: the tip distance of random designs in the box at random joints never
    exceeds the bound; a planar chain stretched out (q = 0, longest links) meets it."""
    rng = np.random.default_rng(0)
    m = dh_model("standard", "RRP", alpha=[np.pi / 2, 0.3, 0.0], a=["a1", "a2", 0.1],
                 d=[0.2, "d2", 0.05], theta=[0.0, 0.4, 0.0])  # fmt: skip
    xl, xu = np.array([0.1, 0.2, -0.3]), np.array([0.5, 0.9, 0.4])
    ql, qu = np.array([-3.0, -2.0, 0.0]), np.array([3.0, 2.0, 0.25])
    bound = m.reach_bound(xl, xu, ql, qu)
    X = xl + (xu - xl) * rng.uniform(size=(200, 3))
    q = ql + (qu - ql) * rng.uniform(size=(500, 3))
    R, p = m.fk(X, q)
    assert np.linalg.norm(np.asarray(p), axis=-1).max() <= bound + 1e-12
    # |a1| ≤ .5, |d1| = .2, |a2| ≤ .9, |d2| ≤ .4, |a3| = .1, |d3 + q3| ≤ .3
    assert bound == pytest.approx(0.5 + 0.2 + 0.9 + 0.4 + 0.1 + 0.3, rel=1e-12)
    flat = dh_model("standard", "RR", alpha=[0.0, 0.0], a=["l1", "l2"], d=[0.0, 0.0],
                    theta=[0.0, 0.0])  # fmt: skip
    b = flat.reach_bound([0.2, 0.2], [2.0, 1.5], [-3.0, -3.0], [3.0, 3.0])
    _, p = flat.fk(np.array([2.0, 1.5]), np.zeros(2))
    assert b == pytest.approx(float(np.linalg.norm(p)), rel=1e-12) == pytest.approx(3.5)


@pytest.mark.parametrize("region", [
    {"shape": "box", "center": [2.0, -1.0, 0.5], "size": [1.0, 0.5, 0.2]},
    {"shape": "ball", "center": [0.3, 2.0, -1.0], "radius": 0.7},
    {"shape": "cylinder", "center": [1.5, 0.5, 2.0], "axis": [0.2, 0.1, 1.0], "radius": 0.4,
     "height": 0.8},
    {"shape": "cylinder", "center": [1.2, 0.0, 0.0], "axis": [0, 0, 1], "radius": 0.5,
     "height": 0.0},
    {"shape": "cone", "apex": [0.5, 0.5, 2.0], "axis": [0, 0, -1], "half_angle": 20,
     "depth": [0.5, 1.2]},
], ids=["box", "ball", "cylinder", "disk", "cone"])  # fmt: skip
def test_nearest_distance_against_samples(region):
    """The region's nearest point to the base: every sample is at least that far; for the
    exact shapes the nearest of 200,000 samples comes within 2 % of it."""
    import jax

    r = tk.Task.model_validate({"region": region}).region
    pts = np.asarray(tk.sample_region(tk.kind(r), tk.region_params(r), jax.random.key(0), 200_000))
    d = np.linalg.norm(pts, axis=-1)
    near = tk.nearest_distance(r)
    assert d.min() >= near - 1e-9
    if region["shape"] != "cone":  # a cone's is a lower bound (its bounding ball)
        assert d.min() <= near * 1.02 + 1e-3


# ------------------------------------------------------------ after: far from what was asked


@pytest.fixture(scope="module")
def far_run(tmp_path_factory):
    """A run over a disk beyond the reach of most of the box (3.4 to 4.4 from the base),
    with no reach constraint: the best design reaches little of it."""
    d = tmp_path_factory.mktemp("far")
    cfg = planar_task(d, center=(3.9, 0, 0), iters=2)
    return cfg, d / "out" / "a.h5"


def test_a_barely_reaching_design_is_said_so_everywhere(far_run, capsys):
    cfg, out = far_run
    assert main(["run", str(cfg), "--quiet"]) == 0
    printed = capsys.readouterr().out
    rec = designopt.load(out)
    reach = rec.indices["reach"][0]
    assert reach < 0.95
    (w,) = rec.warnings  # archived
    assert w.startswith("reach = ") and "% of the task region's targets" in w
    assert f"warning: {w}" in printed  # printed with the summary
    assert main(["show", str(out)]) == 0
    assert f"warning: {w}" in capsys.readouterr().out  # and by show
    from designopt.app import reporting
    from designopt.figures import canvas

    canvas.RECORD = []
    try:
        reporting.draw_figures(out, rec)
        (fig,) = [f for name, f in canvas.RECORD if name == "task"]
        title = fig._suptitle
        assert "WARNING: reach = " in title.get_text() and title.get_color() == "crimson"
        assert_clean(canvas.RECORD)  # units, clipping, overlaps (docs/figures.md)
    finally:
        import matplotlib.pyplot as plt

        for _, f in canvas.RECORD:
            plt.close(f)
        canvas.RECORD = None


def test_a_missed_index_constraint_is_a_warning_and_a_met_one_is_not(tmp_path):
    from designopt.studies.serial import reach
    from designopt.studies.serial.settings import SerialSettings

    raw = yaml.safe_load(planar_task(tmp_path, reach=0.99).read_text())["study"]
    s = SerialSettings.model_validate(raw)
    missed = reach.warnings(s, {"reach": 0.69, "reach_se": 0.01})
    assert len(missed) == 1 and "asked ≥ 0.99" in missed[0] and "reach = 0.69" in missed[0]
    assert reach.warnings(s, {"reach": 0.985, "reach_se": 0.01}) == []  # within 2 SE
    assert reach.warnings(s, {"reach": 1.0, "reach_se": 0.0}) == []


# ------------------------------------------------------------------------------ units


def urdf_arm(tmp_path: Path, **study) -> Path:
    raw = yaml.safe_load((ROOT / "configs" / "urdf_arm.yaml").read_text())
    raw["study"]["chain"]["urdf"] = str(ROOT / "configs" / raw["study"]["chain"]["urdf"])
    raw["study"]["indices"]["n_samples"] = 256
    raw["study"] |= study
    raw["optimizer"] = {"name": "ptpso", "n_particles": 4, "n_iters": 2}
    raw["output"] = str(tmp_path / "u.h5")
    p = tmp_path / "u.yaml"
    p.write_text(yaml.safe_dump(raw))
    return p


def test_a_urdf_chain_prints_metres_and_refuses_another_unit(tmp_path, capsys):
    cfg = urdf_arm(tmp_path)
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "l_wrist = " in out and " m\n" in out.split("l_wrist = ")[1][:20]
    assert " L\n" not in out and " L " not in out
    units = designopt.studies.get("serial").units(designopt.load(tmp_path / "u.h5").config.study)
    assert units["l_wrist"] == "m" and units["__length__"] == "m"
    one_line_exit_2(capsys, ["run", str(urdf_arm(tmp_path, units={"length": "mm"})),
                             "--dry-run"], "key 'study.units.length'", "metres")  # fmt: skip


@pytest.mark.parametrize("declared,unit", [(None, "L"), ("mm", "mm"), ("m", "m")])
def test_a_dh_chain_keeps_the_unit_it_declares(declared, unit):
    from designopt.studies.serial.settings import SerialSettings, units

    raw = yaml.safe_load((ROOT / "configs" / "planar2r.yaml").read_text())["study"]
    if declared:
        raw["units"] = {"length": declared}
    u = units(SerialSettings.model_validate(raw))
    assert u["l1"] == u["l2"] == u["__length__"] == unit
    assert u["volume"] == f"{unit}^2"  # the planar position Jacobian: an area


def test_the_error_names_the_deepest_key(tmp_path, capsys):
    cfg = urdf_arm(tmp_path)
    raw = yaml.safe_load(cfg.read_text())
    raw["study"]["chain"]["limits"] = {"tool_roll": [180, -180]}
    cfg.write_text(yaml.safe_dump(raw))
    one_line_exit_2(capsys, ["run", str(cfg), "--dry-run"],
                    "key 'study.chain.limits.tool_roll'", "not below")  # fmt: skip


# ------------------------------------------------------------ Python API, outputs


def test_the_api_runs_float64_without_touching_the_global_flag(tmp_path):
    """In a fresh process (x64 off, as JAX starts): evaluate a float64 config; JAX's flag
    is still off afterwards and the caller's own arrays stay float32."""
    code = f"""
import json, jax, jax.numpy as jnp, designopt
cfg = designopt.load_config({str(ROOT / "configs" / "planar2r.yaml")!r},
                            {{"precision": "float64", "study.indices.n_samples": 256}})
res = designopt.evaluate(cfg, {{"l1": 1.0, "l2": 0.5}})
print(json.dumps({{"gci": float(res["gci"][0]), "dtype": str(res["gci"].dtype),
                  "x64": bool(jax.config.jax_enable_x64), "mine": str(jnp.ones(1).dtype)}}))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)  # fmt: skip
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["dtype"] == "float64" and 0 < got["gci"] <= 1
    assert got["x64"] is False and got["mine"] == "float32"


def test_overwrite_leaves_nothing_of_the_old_archive(tmp_path, capsys):
    """A run with figures and an HTML page, then --overwrite --no-figures: the old
    figures and page are gone (they showed the old archive)."""
    raw = yaml.safe_load((ROOT / "configs" / "planar2r.yaml").read_text())
    raw["study"]["indices"]["n_samples"] = 256
    raw["optimizer"] = {"name": "ptpso", "n_particles": 4, "n_iters": 2}
    raw["output"] = str(tmp_path / "p.h5")
    raw.pop("scan", None)
    cfg = tmp_path / "p.yaml"
    cfg.write_text(yaml.safe_dump(raw))
    assert main(["run", str(cfg), "--quiet"]) == 0
    assert main(["report", str(tmp_path / "p.h5"), "--html"]) == 0
    assert (tmp_path / "p_figures").is_dir() and (tmp_path / "p.html").is_file()
    assert main(["run", str(cfg), "--quiet", "--no-figures", "--overwrite"]) == 0
    assert not (tmp_path / "p_figures").exists() and not (tmp_path / "p.html").exists()
    assert (tmp_path / "p.h5").is_file()
    capsys.readouterr()


@pytest.fixture(scope="module")
def dh_run(tmp_path_factory):
    """A tiny DH (planar 2R) run archive."""
    d = tmp_path_factory.mktemp("dh")
    raw = yaml.safe_load((ROOT / "configs" / "planar2r.yaml").read_text())
    raw["study"]["indices"]["n_samples"] = 256
    raw["optimizer"] = {"name": "ptpso", "n_particles": 4, "n_iters": 2}
    raw["output"] = str(d / "p.h5")
    raw.pop("scan", None)
    (d / "p.yaml").write_text(yaml.safe_dump(raw))
    assert main(["run", str(d / "p.yaml"), "--quiet", "--no-figures"]) == 0
    return d / "p.h5"


@pytest.fixture(scope="module")
def urdf_run(tmp_path_factory):
    """A tiny URDF-chain run archive."""
    d = tmp_path_factory.mktemp("urdf")
    assert main(["run", str(urdf_arm(d)), "--quiet", "--no-figures"]) == 0
    return d / "u.h5"


@pytest.mark.parametrize("case", ["dh-chain", "urdf-is-a-folder", "not-an-archive",
                                  "archive-is-a-folder"])  # fmt: skip
def test_export_refuses_in_one_line_and_writes_nothing(tmp_path, capsys, dh_run, urdf_run,
                                                       case):  # fmt: skip
    capsys.readouterr()
    (tmp_path / "adir").mkdir()
    (tmp_path / "text.h5").write_text("not hdf5")
    archive, out, needles = {
        "dh-chain": (dh_run, tmp_path / "o.urdf", ["DH table, not a URDF"]),
        "urdf-is-a-folder": (urdf_run, tmp_path / "adir", ["adir", "is a folder"]),
        "not-an-archive": (tmp_path / "text.h5", tmp_path / "o.urdf", ["text.h5"]),
        "archive-is-a-folder": (tmp_path / "adir", tmp_path / "o.urdf", ["adir"]),
    }[case]
    one_line_exit_2(capsys, ["export", str(archive), "--urdf", str(out)], *needles)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "text.h5"]
    assert list((tmp_path / "adir").iterdir()) == []
