"""Task-based design (serial ``measure: task``, docs/task.md) against independent
references: the planar 2R over a disk (reach = the disk's area inside the annulus
|l1 − l2| ≤ r ≤ l1 + l2; GCI, manipulability and the 5 % quantile of 1/k as quadratures
in r, since both depend on q2 alone), a spatial 3R over a ball (reach = the ball's volume
inside the spherical shell), tool-axis targets, index constraints under Deb's rules and
the penalty, common random numbers, and bad input (exit 2, one line, nothing written)."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import jax
import numpy as np
import pytest
import yaml
from scipy import integrate

from designopt import api
from designopt.cli import main

jax.config.update("jax_enable_x64", True)

C, RHO = 1.2, 0.5  # disk centre (distance from the base) and radius

TWO_R = {
    "study": {
        "name": "serial",
        "chain": {"convention": "standard", "joints": [
            {"type": "R", "a": "l1", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]},
            {"type": "R", "a": "l2", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]},
        ]},
        "variables": {"l1": [0.2, 2.0], "l2": [0.2, 2.0]},
        "task": {"region": {"shape": "cylinder", "center": [C, 0, 0], "axis": [0, 0, 1],
                            "radius": RHO, "height": 0},
                 "ik": {"n_db": 256, "n_nearest": 1, "n_random": 2, "rounds": 2}},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task",
                    "n_samples": 2048},
        "objective": {"gci": -1.0},
    },
    "optimizer": {"name": "ptpso", "n_particles": 8, "n_iters": 4, "n_runs": 1},
    "precision": "float64",
    "seed": 3,
    "output": "results/t/t.h5",
}  # fmt: skip


# ------------------------------------------------------------------- 2R references


def _arc(r: float, c: float = C, rho: float = RHO) -> float:
    """Length of the circle of radius r about the base inside the disk: the density of
    the disk's area in r (∫ arc dr = π ρ²)."""
    if r <= abs(c - rho) or r >= c + rho:
        return 2 * math.pi * r if r <= rho - c else 0.0
    return 2 * r * math.acos((r * r + c * c - rho * rho) / (2 * r * c))


def _inv_k_2r(l1: float, l2: float, r: float) -> float:
    """σmin/σmax of the planar 2R Jacobian at the tip distance r (through q2 only):
    eigenvalues of JᵀJ = [[l1² + l2² + 2 l1 l2 c2, l2² + l1 l2 c2], [·, l2²]]."""
    c2 = np.clip((r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2), -1, 1)
    a, b, d = l1**2 + l2**2 + 2 * l1 * l2 * c2, l2**2 + l1 * l2 * c2, l2**2
    tr, det = a + d, a * d - b * b
    disc = math.sqrt(max(tr * tr / 4 - det, 0.0))
    lmax, lmin = tr / 2 + disc, max(tr / 2 - disc, 0.0)
    return math.sqrt(lmin / lmax)


def _ref_2r(l1: float, l2: float) -> dict[str, float]:
    """reach, gci, manipulability (l1 l2 |sin q2|) and the 5 % quantile of 1/k (0 where
    unreached) over the disk, by quadrature in r."""
    area = math.pi * RHO**2
    lo, hi = max(abs(l1 - l2), C - RHO), min(l1 + l2, C + RHO)
    if hi <= lo:
        return {"reach": 0.0, "gci": 0.0, "manipulability": 0.0, "gci_q05": 0.0}
    pts = [lo, hi]

    def q(f):
        return integrate.quad(f, lo, hi, points=pts, limit=400, epsabs=1e-13)[0] / area

    def s2(r):
        c2 = np.clip((r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2), -1, 1)
        return math.sqrt(1 - c2 * c2)

    reach = q(_arc)
    out = {"reach": reach, "gci": q(lambda r: _arc(r) * _inv_k_2r(l1, l2, r)),
           "manipulability": q(lambda r: _arc(r) * l1 * l2 * s2(r))}  # fmt: skip
    # the distribution of 1/k over the disk: unreached share at 0, the rest from r
    r = np.linspace(lo, hi, 40001)
    w = np.array([_arc(x) for x in r]) * (r[1] - r[0]) / area
    v = np.array([_inv_k_2r(l1, l2, x) for x in r])
    order = np.argsort(v)
    cdf = (1 - reach) + np.cumsum(w[order]) * reach / w.sum()
    out["gci_q05"] = 0.0 if 1 - reach >= 0.05 else float(np.interp(0.05, cdf, v[order]))
    return out


@pytest.fixture(scope="module")
def two_r():
    """Four designs in one swarm call: two reach the whole disk, two do not."""
    designs = {"l1": np.array([1.0, 1.5, 1.0, 0.5]), "l2": np.array([1.0, 1.0, 0.6, 0.4])}
    return designs, api.evaluate(copy.deepcopy(TWO_R), designs)


def test_2r_disk_reach_gci_manipulability_quantile(two_r):
    designs, res = two_r
    for j, (l1, l2) in enumerate(zip(designs["l1"], designs["l2"], strict=True)):
        ref = _ref_2r(l1, l2)
        for k in ("reach", "gci", "manipulability", "gci_q05"):
            got, se = res[k][j], res[k + "_se"][j]
            tol = 4 * se + 1e-12 + (2e-3 if k == "gci_q05" else 0.0)  # interpolation
            assert abs(got - ref[k]) <= tol, (l1, l2, k, got, se, ref[k])
    assert res["reach"][0] == 1.0 and res["reach"][1] == 1.0
    assert 0.9 < res["reach"][2] < 0.98 and res["reach"][3] < 0.2
    assert np.all(res["reach_se"] > 0)  # positive even where every target is reached
    # the whole disk reached by both full designs: f = −gci exactly
    np.testing.assert_allclose(res["f"], -res["gci"], rtol=0, atol=0)


def test_2r_joint_margin_against_the_solutions(two_r):
    """joint_margin = mean over targets of the smallest normalised distance to a limit
    (±180°: 1 − |q|/π), 0 where unreached: recomputed from an independent 2R IK."""
    designs, res = two_r
    from designopt.config import validate
    from designopt.prepare import build_problem
    from designopt.studies import streams

    cfg = validate(copy.deepcopy(TWO_R), "config")
    p = np.asarray(build_problem(cfg, streams(cfg.seed)).params["target_p"])
    r = np.linalg.norm(p[:, :2], axis=-1)
    for j in (0, 1):  # designs reaching everything: the best-conditioned branch is ±q2
        l1, l2 = designs["l1"][j], designs["l2"][j]
        c2 = np.clip((r**2 - l1**2 - l2**2) / (2 * l1 * l2), -1, 1)
        q2 = np.arccos(c2)  # elbow down; elbow up is −q2 with the same 1/k
        best = []
        for s in (1.0, -1.0):
            q1 = np.arctan2(p[:, 1], p[:, 0]) - np.arctan2(l2 * np.sin(s * q2), l1 + l2 * c2)
            q1 = (q1 + np.pi) % (2 * np.pi) - np.pi
            best.append(np.minimum(1 - np.abs(q1) / np.pi, 1 - np.abs(q2) / np.pi))
        lo_m, hi_m = np.minimum(*best).mean(), np.maximum(*best).mean()
        # the IK keeps either branch (equal 1/k): the mean margin lies between the two
        assert lo_m - 1e-9 <= res["joint_margin"][j] <= hi_m + 1e-9, (j, lo_m, hi_m)


# ------------------------------------------------------------------- 3R over a ball


def test_3r_ball_reach_is_the_volume_share():
    """Spatial 3R (base yaw, then a planar 2R in the vertical plane, l2 = 0.5, l3 = 0.3):
    the reachable set is the shell 0.2 ≤ |p| ≤ 0.8; a ball of radius 0.3 at distance 0.7
    pokes out of it. reach = vol(ball ∩ shell)/vol(ball) by quadrature of the sphere
    area inside the ball."""
    c, rho, r_in, r_out = 0.7, 0.3, 0.2, 0.8

    def cap(r):  # area of the sphere of radius r inside the ball
        if r <= c - rho or r >= c + rho:
            return 0.0
        cos_t = (r * r + c * c - rho * rho) / (2 * r * c)
        return 2 * math.pi * r * r * (1 - cos_t)

    ref = integrate.quad(cap, max(r_in, c - rho), min(r_out, c + rho), limit=200)[0]
    ref /= 4 / 3 * math.pi * rho**3
    cfg = {
        **copy.deepcopy(TWO_R),
        "study": {
            "name": "serial",
            "chain": {"convention": "standard", "joints": [
                {"type": "R", "a": 0, "alpha": 90, "d": 0, "theta": 0, "limits": [-180, 180]},
                {"type": "R", "a": "l2", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]},
                {"type": "R", "a": "l3", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]},
            ]},
            "variables": {"l2": [0.1, 1.0], "l3": [0.1, 1.0]},
            "task": {"region": {"shape": "ball", "center": [0, c, 0], "radius": rho},
                     "ik": {"n_db": 512, "n_nearest": 2, "n_random": 2, "rounds": 3}},
            "indices": {"jacobian": "position", "measure": "task", "n_samples": 4096},
            "objective": {"reach": -1.0},
        },
    }  # fmt: skip
    res = api.evaluate(cfg, {"l2": 0.5, "l3": 0.3})
    assert 0.5 < ref < 0.95
    assert abs(res["reach"][0] - ref) <= 4 * res["reach_se"][0], (res["reach"][0], ref)


# ------------------------------------------------------------------- tool axis


def test_tool_axis_targets_meet_the_cone():
    """Tool axes drawn in a 30° cone about −z lie in it and fill it (cos θ uniform on
    [cos 30°, 1]: mean cos θ = (1 + cos 30°)/2); the PUMA 560's solved targets meet
    position and axis to the IK's tolerance."""
    from designopt.prepare import build_problem
    from designopt.studies import streams
    from designopt.studies.serial import taskindex
    from designopt.studies.serial.mechanism import build
    from designopt.studies.serial.objective import design_full

    cfg = api.load_config("configs/puma560_task.yaml",
                          {"study.indices.n_samples": 48, "study.task.ik.n_db": 512})  # fmt: skip
    pb = build_problem(cfg, streams(cfg.seed))
    z = np.asarray(pb.params["target_R"])[:, :, 2]
    cos_t = z @ np.array([0.0, 0.0, -1.0])
    assert np.all(cos_t >= math.cos(math.radians(30)) - 1e-12)
    assert abs(cos_t.mean() - (1 + math.cos(math.radians(30))) / 2) < 0.02
    s = cfg.study
    X = np.array([[0.4318, 0.4318]])
    per = taskindex.per_target(build(s), s, pb.params, design_full(pb.params, X, np.float64),
                               np.float64)  # fmt: skip
    ok = np.asarray(per["success"][0]) > 0
    assert ok.mean() > 0.9
    mech = build(s)
    R, p = mech.model.fk(design_full(pb.params, X, np.float64)[0], per["q"][0])
    pt = np.asarray(pb.params["target_p"])
    assert np.max(np.linalg.norm(np.asarray(p) - pt, axis=-1)[ok]) < 1e-8
    ang = np.arccos(np.clip(np.sum(np.asarray(R)[:, :, 2] * z, -1), -1, 1))
    assert np.max(ang[ok]) < 1e-7


# ------------------------------------------------------------------- constraints


def test_index_constraint_value_is_ge_minus_index():
    cfg = copy.deepcopy(TWO_R)
    cfg["study"]["constraints"] = [{"index": "reach", "ge": 0.99}]
    res = api.evaluate(cfg, {"l1": [1.0, 1.0], "l2": [0.6, 1.0]})
    np.testing.assert_allclose(res["violation"], np.maximum(0.99 - res["reach"], 0), atol=1e-15)
    assert res["violation"][0] > 0.01 and res["violation"][1] == 0


@pytest.mark.parametrize("method", ["deb", "penalty"])
def test_reach_constraint_is_met_by_the_run(method):
    cfg = copy.deepcopy(TWO_R)
    cfg["study"]["indices"]["n_samples"] = 256
    cfg["study"]["constraints"] = [{"index": "reach", "ge": 0.99}]
    cfg["optimizer"] |= {"n_particles": 6, "n_iters": 3}
    if method == "penalty":
        cfg["optimizer"]["constraints"] = {"method": "penalty", "weight": 1000.0}
    rec = api.run(cfg)
    x = rec.x
    res = api.evaluate(cfg, {k: x[k] for k in ("l1", "l2")})
    assert res["reach"][0] >= 0.99 - 2 * res["reach_se"][0], (x, res["reach"])


def test_index_constraint_on_the_joint_measure():
    """{index: gci, le: 0.3} on the joint measure: g = gci − 0.3."""
    cfg = yaml.safe_load(Path("configs/planar2r.yaml").read_text())
    cfg["study"]["indices"]["n_samples"] = 2048
    cfg["study"]["constraints"] = [{"index": "gci", "le": 0.3}]
    cfg["optimizer"] = {"name": "ptpso", "n_particles": 10, "n_iters": 8, "n_runs": 1}
    res = api.evaluate(cfg, {"l1": [1.0, 1.0], "l2": [1.0, 0.25]})
    np.testing.assert_allclose(res["violation"], np.maximum(res["gci"] - 0.3, 0), atol=1e-15)
    assert res["violation"][0] > 0 and res["violation"][1] == 0


def test_common_random_numbers(two_r):
    """A design scores the same alone as in a swarm (the same targets and IK seeds)."""
    _, both = two_r
    one = api.evaluate(copy.deepcopy(TWO_R), {"l1": 1.0, "l2": 0.6})
    for k in ("reach", "gci", "gci_q05", "joint_margin", "manipulability"):
        assert abs(both[k][2] - one[k][0]) <= 1e-12, k


# ------------------------------------------------------------------- CLI


def _write(tmp_path: Path, cfg: dict) -> Path:
    cfg = copy.deepcopy(cfg)
    cfg["output"] = str(tmp_path / "out" / "r.h5")
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def _region(**r):
    def f(c):
        c["study"]["task"]["region"] = r

    return f


def _set(path: str, value):
    def f(c):
        d = c
        *head, last = path.split(".")
        for k in head:
            d = d[k]
        if value is None:
            d.pop(last)
        else:
            d[last] = value

    return f


BAD = [
    (_region(shape="torus", center=[1, 0, 0], radius=1), "study.task.region"),
    (_region(shape="ball", center=[1, 0, 0], radius=0), "study.task.region.radius"),
    (_region(shape="cylinder", center=[1, 0, 0], radius=-1), "radius"),
    (_region(shape="cone", apex=[0, 0, 0], axis=[0, 0, 1], half_angle=0, depth=[0, 1]),
     "half_angle"),
    (_region(shape="cone", apex=[0, 0, 0], axis=[0, 0, 1], half_angle=95, depth=[0, 1]),
     "half_angle"),
    (_set("study.task", None), "measure"),
    (_set("study.indices.measure", "joint"), "task"),
    (_set("study.indices.sampler", "rqmc"), "sampler"),
    (_set("precision", "float32"), "precision"),
    (_set("study.constraints", [{"index": "volume", "ge": 1}]), "constraints.0.index"),
]  # fmt: skip


@pytest.mark.parametrize("edit,needle", BAD)
def test_bad_input_exit_2_one_line(tmp_path, capsys, edit, needle):
    cfg = copy.deepcopy(TWO_R)
    edit(cfg)
    p = _write(tmp_path, cfg)
    assert main(["eval", str(p)]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1, err
    assert main(["run", str(p), "--quiet"]) == 2
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text,needle", [
    ("x,y\n1,2\n", "no column(s) ['z']"),
    ("x,y,z\n1,a,2\n", "row 1"),
    ("x,y,z\n1,2,3\n1,nan,2\n", "row 2"),
])  # fmt: skip
def test_bad_points_file(tmp_path, capsys, text, needle):
    (tmp_path / "pts.csv").write_text(text)
    cfg = copy.deepcopy(TWO_R)
    cfg["study"]["task"]["region"] = {"points": "pts.csv"}
    p = _write(tmp_path, cfg)
    assert main(["eval", str(p)]) == 2
    err = capsys.readouterr().err
    assert needle in err and "pts.csv" in err and err.count("\n") == 1, err


def test_points_file_eval_scan_run(tmp_path, capsys):
    """A points file (header x,y,z, relative to the config) through eval, scan and run."""
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(0.8, 1.4, 64), rng.uniform(-0.3, 0.3, 64), np.zeros(64)]
    (tmp_path / "pts.csv").write_text("x,y,z\n" + "\n".join(",".join(map(str, r)) for r in pts))
    cfg = copy.deepcopy(TWO_R)
    cfg["study"]["task"]["region"] = {"points": "pts.csv"}
    cfg["optimizer"] |= {"n_particles": 4, "n_iters": 1}
    cfg["scan"] = {"vary": {"l2": {"from": 0.3, "to": 1.2, "num": 4}}, "design": {"l1": 1.0}}
    p = _write(tmp_path, cfg)
    assert main(["eval", str(p), "--design", "l1=0.5", "--design", "l2=0.3"]) == 0
    out = capsys.readouterr().out
    assert "reach" in out and "gci_q05" in out
    for cmd in ("scan", "run"):
        o = tmp_path / f"{cmd}.h5"
        assert main([cmd, str(p), "--out", str(o), "--quiet", "--no-figures"]) == 0
        rec = api.load(o)
        assert rec.config.study.indices.measure == "task"
    r = api.load(tmp_path / "run.h5")
    assert set(r.final) >= {"reach", "reach_se", "gci_q05", "gci_q05_se", "joint_margin"}
