"""Indices that cannot be gamed and numbers that never mislead (docs/task.md, "Several
arms"): a ratio estimator over fewer than ``N_MIN`` items is n/a (NaN in the archive,
``n/a (k of N)`` in print, null in JSON), a search ranks it worst, ``arms_ok`` is the
unconditional share, and a task of one target is refused before anything runs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from designopt.app.config import validate
from designopt.app.fronts import objective_problem
from designopt.cli.commands import main
from designopt.problems.base import Problem
from designopt.results.base import value_text
from designopt.studies.serial import taskindex

jax.config.update("jax_enable_x64", True)


def test_ratio_is_na_under_n_min_and_the_delta_method_estimate_above():
    rng = np.random.default_rng(0)
    N = 400
    x = (rng.random((3, N)) < np.array([[0.02], [0.5], [0.9]])).astype(np.float64)
    y = x * (rng.random((3, N)) < 0.7)
    r, se = map(np.asarray, taskindex.ratio(jnp.asarray(y), jnp.asarray(x)))
    sx = x.sum(-1)
    assert sx[0] < taskindex.N_MIN <= sx[1]
    assert np.isnan(r[0]) and np.isnan(se[0])
    for m in (1, 2):  # Σy/Σx and the delta-method SE, as numpy computes them
        want = y[m].sum() / sx[m]
        res = y[m] - want * x[m]
        want_se = np.sqrt(np.sum(res**2) / (N * (N - 1))) / (sx[m] / N)
        pt = (y[m].sum() + 2) / (sx[m] + 4)  # never below the Agresti–Coull SE
        want_se = max(want_se, np.sqrt(pt * (1 - pt) / (sx[m] + 4)))
        assert r[m] == pytest.approx(want, rel=1e-12)
        assert se[m] == pytest.approx(want_se, rel=1e-12)


def _per(A: int, M: int, N: int, p_reach: float, rng) -> dict[str, jnp.ndarray]:
    """Synthetic per-target values of A arms: 2-joint capsules far apart (every tuple
    free) except where ``close`` puts arm 1 on arm 0."""
    ok = (rng.random((A, M, N)) < p_reach).astype(np.float64)
    seg = np.zeros((A, M, N, 1, 2, 3))
    seg[..., 0, 1, 2] = 1.0  # vertical unit segments
    seg[1, ..., 0] += 10.0  # arm 1 far away in x
    return {"success": jnp.asarray(ok), "converged": jnp.asarray(ok),
            "inv_k": jnp.asarray(ok), "manipulability": jnp.asarray(ok),
            "joint_margin": jnp.asarray(ok), "clearance": jnp.asarray(ok),
            "segments": jnp.asarray(seg)}  # fmt: skip


def test_arms_ok_is_the_unconditional_share_and_arms_free_is_na_on_few_tuples():
    """Design 0 reaches a handful of tuples (arms_free n/a, arms_ok near 0), design 1
    most (both defined): arms_ok = arms_free × the share of tuples every arm reaches."""
    rng = np.random.default_rng(1)
    A, N = 2, 512
    per = _per(A, 2, N, 0.9, rng)
    succ = np.asarray(per["success"]).copy()
    succ[:, 0] = 0.0
    succ[:, 0, :5] = 1.0  # design 0: 5 targets per arm
    per |= {"success": jnp.asarray(succ), "converged": jnp.asarray(succ)}
    key = jax.random.key(7)
    est = taskindex.estimates(per, key, (0.1,), 0.0)
    cnt = taskindex.counts(per, key)
    n_tuples, of = map(np.asarray, cnt["arms_free"])
    assert of == N and n_tuples[0] < taskindex.N_MIN < n_tuples[1]
    free, free_se = map(np.asarray, est["arms_free"])
    ok, ok_se = map(np.asarray, est["arms_ok"])
    assert np.isnan(free[0]) and np.isnan(free_se[0])
    assert free[1] == 1.0 and free_se[1] > 0  # far apart: every tuple reached is free
    assert ok[1] == pytest.approx(n_tuples[1] / N, rel=1e-12)  # unconditional
    assert ok[0] == pytest.approx(n_tuples[0] / N) and 0 < ok_se[0] < 0.05
    assert np.all(np.isfinite(ok_se))
    cf_n, cf_of = map(np.asarray, cnt["collision_free"])
    assert cf_of == A * N and cf_n[0] == 10


def test_a_front_ranks_an_na_index_worst():
    """objective_problem puts an n/a value at the worst end of its range for its sense
    (maximised: 0), never NaN into the optimizer's F."""

    def fn(params, X, key):
        v = jnp.where(X[:, 0] > 0.5, jnp.nan, X[:, 0])
        return X[:, 0], {"a": v, "a_se": 0 * v, "b": X[:, 1], "b_se": 0 * v}

    prob = Problem(("x", "y"), np.zeros(2), np.ones(2), fn, na_range={"a": (0.0, 1.0)})
    for sense, want in (("max", 0.0), ("min", 1.0)):
        F, aux = objective_problem(prob, {"a": sense, "b": "min"}).evaluate(
            jnp.asarray([[0.9, 0.1], [0.2, 0.3]]))  # fmt: skip
        F = np.asarray(F)
        assert np.all(np.isfinite(F))
        sign = -1.0 if sense == "max" else 1.0
        assert F[0, 0] == sign * want and F[1, 0] == pytest.approx(sign * 0.2)
        assert np.isnan(np.asarray(aux["a"])[0])  # the archive keeps the NaN


def test_value_text_prints_na_with_its_counts_and_no_minus_zero():
    assert value_text(float("nan"), float("nan"), n=12, of=256) == "n/a (12 of 256)"
    assert value_text(float("nan")) == "n/a"
    assert value_text(-0.0, 0.0, ".6g", ".2g") == "0 ± 0"
    assert "nan" not in value_text(0.5, float("nan"))


# ------------------------------------------------------------------ from the command line


def _two_arm_cfg(tmp_path, n: int = 64, **task) -> str:
    with open("configs/two_arms_front.yaml") as f:
        cfg = yaml.safe_load(f)
    s = cfg["study"]
    s["indices"]["n_samples"] = n
    s["task"] |= task
    cfg["output"] = str(tmp_path / "out.h5")
    cfg["front"] = {"n_samples": n}
    p = tmp_path / "two.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return str(p)


def test_eval_json_is_valid_and_says_na_where_every_tuple_is_out_of_reach(tmp_path, capsys):
    """Arms far from the site (b at its upper bound with short links) reach almost no
    tuple: arms_free and collision_free are null in JSON, n/a with a warning in print."""
    cfg = _two_arm_cfg(tmp_path)
    argv = ["eval", cfg, "--design", "b=0.9", "l2=0.25", "l3=0.25"]
    capsys.readouterr()
    assert main([*argv, "--json"]) == 0
    out = capsys.readouterr().out
    assert "NaN" not in out
    res = json.loads(out)
    assert res["arms_free"] is None and res["arms_free_se"] is None
    assert res["arms_free_n"] < taskindex.N_MIN and res["arms_free_of"] == 64
    assert all(v is None or math.isfinite(v) for v in res.values() if not isinstance(v, list))
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "nan" not in text.lower().replace("n/a", "")
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("arms_free ="))
    assert "n/a (" in line and "of 64)" in line
    assert not (tmp_path / "out.h5").exists()  # eval writes nothing


def _two_pumas(tmp_path, arm1_insertion=None) -> object:
    """configs/urdf_puma560_port.yaml as two PUMAs facing each other across the site,
    each through its own port, task.insertion for both (arm 1's own if given)."""
    with open("configs/urdf_puma560_port.yaml") as f:
        base = yaml.safe_load(f)
    s = base["study"]
    s["chain"]["urdf"] = str(Path("configs/robots/puma560.urdf").resolve())
    port = s["task"].pop("port")
    s["indices"]["n_samples"] = 64
    s["arms"] = [{"base": {"xyz": [0, 0, 0]}, "port": port},
                 {"base": {"xyz": [1.0, 0.2, 0], "rpy": [0, 0, 180]},
                  "port": [0.55, 0.1, -0.2]}]  # fmt: skip
    if arm1_insertion is not None:
        s["arms"][1]["insertion"] = arm1_insertion
    s["objective"] = {"reach_all": -1.0}
    s["constraints"] = []
    base["output"] = str(tmp_path / "out.h5")
    return validate(base, "test")


def test_per_arm_insertion_and_task_insertion_apply_to_every_arm_port(tmp_path):
    """task.insertion with per-arm ports applies to each arm's own port (it was refused:
    "give task.port"); arms[k].insertion narrows arm k alone."""
    from designopt.app import pipeline

    wide = _two_pumas(tmp_path)
    assert wide.study.insertions() == [(0.05, 0.30), (0.05, 0.30)]
    design = {"a2": 0.43, "d4": 0.43, "l_tool": 0.4}
    w = pipeline.evaluate(wide, design)
    narrow = _two_pumas(tmp_path, [0.05, 0.16])
    assert narrow.study.insertions() == [(0.05, 0.30), (0.05, 0.16)]
    n = pipeline.evaluate(narrow, design)
    assert w["reach_0"][0] > 0.5 and w["reach_1"][0] > 0.5
    assert n["reach_0"][0] == w["reach_0"][0]  # arm 0 keeps task.insertion
    assert 0 < n["reach_1"][0] < w["reach_1"][0]  # arm 1: only the shallow targets


@pytest.mark.parametrize("edit, says", [
    ({"insertion": [0.1, 0.2]}, "task.insertion': is the tool's depth past a port"),
    ({"arms1_insertion": [0.1, 0.2]}, "arms.1.insertion': is the tool's depth past a port"),
    ({"n_samples": 1}, "indices.n_samples': must be > 1"),
    ({"points": "x,y,z\n0,0,0.25\n"}, "a task needs at least 2"),
])  # fmt: skip
def test_insertion_without_ports_and_one_target_tasks_are_refused(tmp_path, capsys, edit, says):
    base = yaml.safe_load(open("configs/two_arms_front.yaml"))
    s = base["study"]
    if "insertion" in edit:
        s["task"]["insertion"] = edit["insertion"]
    if "arms1_insertion" in edit:
        s["arms"][1]["insertion"] = edit["arms1_insertion"]
    if "n_samples" in edit:
        s["indices"]["n_samples"] = edit["n_samples"]
    if "points" in edit:
        (tmp_path / "one.csv").write_text(edit["points"])
        s["task"]["region"] = {"points": "one.csv"}
    base["output"] = str(tmp_path / "out.h5")
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(base))
    capsys.readouterr()
    assert main(["eval", str(p)]) == 2
    out, err = capsys.readouterr()
    assert says in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out.h5").exists()
