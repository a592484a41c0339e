"""The final stage (``final.race``; designopt.app.verdict, issue #66 item 1): candidate
layouts raced on the validation stream.

- two exactly equal optima (a planar 2R arm whose GCI depends on l2/l1 only: a design
  and its double) give "a tied set" naming the variables in which they differ, at three
  validation seeds; a known gap gives "one recommendation";
- the validation stream depends on ``final.seed`` alone, and its stages differ;
- a run with the race prints the verdict table and archives the ``verdict`` group, which
  reads back to the same table; its final design is the race's best and ``eval --fresh``
  gives its quoted values;
- a bad ``final.margin`` name, a NaN margin, a cap under 30 or of fewer than 2 stages:
  one line naming the key, exit 2;
- the shipped planning case at a tiny size runs end to end with the verdict printed.
"""

from __future__ import annotations

import copy
import json
import math

import jax
import numpy as np
import pytest
import yaml

from designopt.app import verdict
from designopt.app.config import validate
from designopt.app.job import Job
from designopt.cli.commands import main
from designopt.figures.html.run import _verdict
from designopt.io import archive
from designopt.results.verdict import lines as verdict_lines

PLANAR = {
    "study": {
        "name": "serial",
        "chain": {"convention": "standard", "joints": [
            {"type": "R", "a": "l1", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]},
            {"type": "R", "a": "l2", "alpha": 0, "d": 0, "theta": 0, "limits": [-180, 180]}]},
        "variables": {"l1": [0.2, 2.0], "l2": [0.2, 2.0]},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "joint", "n_samples": 64},
        "objective": {"gci": -1.0},
    },
    "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 2, "n_runs": 1},
    "final": {"race": True, "stage": 32, "max_samples": 128},
}  # fmt: skip


def _raw(**final) -> dict:
    raw = copy.deepcopy(PLANAR)
    raw["final"] |= final
    return raw


def _job(**final) -> Job:
    return Job.build(validate(_raw(**final), "c.yaml"), "c.yaml")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_exactly_equal_optima_give_a_tied_set(seed):
    # the GCI of a planar 2R arm depends on l2/l1 only: (0.5, 0.35) and (1, 0.7) are
    # equal on every sample (the Jacobian doubles, exactly in binary)
    job = _job(seed=seed)
    g = verdict.race_candidates(job, np.array([[0.5, 0.35], [1.0, 0.7]]))
    at = g["attrs"]
    assert at["summary"] == "a tied set of 2 layouts", at
    assert sorted(np.asarray(g["verdict"]).astype(str)) == ["best", "equivalent"]
    assert g["settled"].tolist() == [1, 1]  # shown equivalent, not merely unseparated
    np.testing.assert_array_equal(g["diff"], 0.0)
    assert at["tie_note"] == "the tied layouts differ in l1, l2"
    assert at["reason"] == "decided" and g["n_samples"].tolist() == [64, 64]  # 2 stages


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_known_gap_gives_one_recommendation(seed):
    job = _job(seed=seed)
    X = np.array([[1.0, 0.3], [1.0, 0.7]])  # l2/l1 = 0.7 is near the GCI's best, 0.3 not
    g = verdict.race_candidates(job, X)
    at = g["attrs"]
    assert at["summary"] == "one recommendation" and at["best"] == 1, at
    assert np.asarray(g["verdict"]).astype(str).tolist() == ["worse", "best"]
    # the gap: f = −gci, so the worse layout's difference from the best is > the margin
    assert g["diff"][0, 0] > at["margin"][0] and g["diff"][1, 0] == 0.0
    assert at["objectives"] == ["f"] and at["senses"] == ["min"]


def test_the_validation_stream_depends_on_final_seed_alone():
    a = _job(seed=5)
    b = Job.build(validate(_raw(seed=5) | {"seed": 9}, "c.yaml"), "c.yaml")
    data = lambda k: np.asarray(jax.random.key_data(k))  # noqa: E731
    np.testing.assert_array_equal(data(verdict.validation_key(a.cfg)),
                                  data(verdict.validation_key(b.cfg)))  # fmt: skip
    assert not np.array_equal(data(verdict.validation_key(a.cfg)),
                              data(verdict.validation_key(_job(seed=6).cfg)))  # fmt: skip
    # its stages are independent replications: a design's values differ from stage to stage
    x = np.array([[1.0, 0.7]])
    from designopt.app import quoted

    s0 = quoted.blocked(verdict.stage_problem(a, 0), x)["gci"]
    s1 = quoted.blocked(verdict.stage_problem(a, 1), x)["gci"]
    assert s0[0] != s1[0]
    # and the run's final stream (folded from --seed) is another
    fin = quoted.blocked(quoted.problem(a, a.search_problem), x)["gci"]
    assert fin[0] not in (s0[0], s1[0])


def _write(tmp_path, raw: dict) -> str:
    raw = dict(raw) | {"output": str(tmp_path / "r.h5")}
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(raw, sort_keys=False))
    return str(p)


def test_a_raced_run_prints_archives_and_quotes_the_verdict(tmp_path, capsys):
    p = _write(tmp_path, _raw())
    capsys.readouterr()
    assert main(["run", p, "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "the final stage: " in out and "\n  verdict: " in out
    rec = archive.load(tmp_path / "r.h5")
    g = rec.groups["verdict"]
    C = len(g["x"])
    assert g["mean"].shape == (C, 1) and np.asarray(g["verdict"]).shape == (C,)
    assert "best" in np.asarray(g["verdict"]).astype(str).tolist()
    table = verdict_lines(g, rec.names, rec.hint("units", {}))
    assert all(f"  {ln}" in out for ln in table)  # the archive reads back to the printed table
    sec = _verdict(archive.read(tmp_path / "r.h5"), {})  # the HTML report's section
    assert sec.title == "The final stage" and sec.items[0].count("<tr>") == C + 1
    assert f"Verdict: {g['attrs']['summary']}" in sec.items[0]
    # the run's final design is the race's best; eval --fresh gives its quoted values
    np.testing.assert_array_equal(rec.groups["final"]["x"], verdict.best_x(g))
    design = [f"--design={n}={float(v)!r}" for n, v in zip(rec.names, verdict.best_x(g), strict=True)]
    assert main(["eval", p, *design, "--fresh", "--json"]) == 0
    vals = json.loads(capsys.readouterr().out)
    vals = vals["designs"][0]["values"] if "designs" in vals else vals
    assert vals["gci"] == float(rec.groups["final"]["gci"])


@pytest.mark.parametrize("final,key", [
    ({"margin": {"reach_nowhere": 0.01}}, "final.margin.reach_nowhere"),
    ({"margin": math.nan}, "final.margin"),
    ({"max_samples": 20}, "final.max_samples"),
    ({"stage": 64, "max_samples": 100}, "final.max_samples"),  # one stage: no paired SE
])  # fmt: skip
def test_bad_race_keys_exit_2_naming_the_key(tmp_path, capsys, final, key):
    p = _write(tmp_path, _raw(**final))
    capsys.readouterr()
    assert main(["run", p, "--no-figures"]) == 2
    out, err = capsys.readouterr()
    assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
    assert f"key '{key}'" in err and "Traceback" not in out + err
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.slow
def test_the_planning_case_at_a_tiny_size_prints_its_verdict(tmp_path, capsys):
    capsys.readouterr()
    assert main(["run", "configs/port_placement.yaml", "--no-figures", "--out",
                 str(tmp_path / "pp.h5"), "--set", "optimizer.n_particles=8", "--set",
                 "optimizer.n_iters=2", "--set", "study.indices.n_samples=32", "--set",
                 "final.stage=32", "--set", "final.max_samples=64"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "the final stage: " in out and "instrument_ok" in out
    last = [ln for ln in out.splitlines() if ln.startswith("verdict: ")]
    assert len(last) == 1 and ("one recommendation" in last[0] or "a tied set" in last[0]
                               or "a front of" in last[0])  # fmt: skip
    rec = archive.load(tmp_path / "pp.h5")
    g = rec.groups["verdict"]
    assert g["attrs"]["constraints"] == ["instrument_ok"]
    assert g["attrs"]["objectives"] == ["arms_ok", "gci"]
    # the front is formed from the race's survivors, none of them judged worse
    surv = np.asarray(g["x"])[np.asarray(g["verdict"]).astype(str) != "worse"]
    for x in rec.X:
        assert np.any(np.all(np.isclose(surv, x), axis=1))
    # the front's designs are drawn on the samples front/ is on: its targets group's
    from designopt.api import load
    from designopt.studies.serial import blocks

    s, keys = load(tmp_path / "pp.h5").front_stream()
    assert s.indices.n_samples == rec.groups["front"]["attrs"]["n_samples"]
    sol = blocks.solutions(s, rec.X[:1], keys)
    tg = rec.groups["targets"]
    np.testing.assert_array_equal(sol["target_p"], tg["target_p"])
    np.testing.assert_array_equal(sol["q"][:, 0], np.asarray(tg["q"])[0])


def test_a_halton_sampler_draws_other_points_at_each_stage():
    # one randomly shifted Halton sequence: the stage's key shifts it, so stages differ
    raw = _raw()
    raw["study"]["indices"]["sampler"] = "halton"
    job = Job.build(validate(raw, "c.yaml"), "c.yaml")
    from designopt.app import quoted

    x = np.array([[1.0, 0.7]])
    s0, s1 = (quoted.blocked(verdict.stage_problem(job, s), x)["gci"][0] for s in (0, 1))
    assert s0 != s1


def test_a_race_best_other_than_the_searchs_becomes_the_quoted_final_design(tmp_path, capsys,
                                                                           monkeypatch):  # fmt: skip
    """The wiring when the race picks another candidate than the search's final design
    (forced here: the last candidate made the best): ``final/x`` is it, ``best_run/final``
    holds its values on the search's samples, and ``eval --fresh`` gives its quoted ones."""
    real = verdict.race_candidates

    def last_is_best(job, X, **kw):
        g = real(job, X, **kw)
        g["attrs"]["best"] = len(X) - 1
        return g

    monkeypatch.setattr(verdict, "race_candidates", last_is_best)
    raw = _raw()
    raw["optimizer"] |= {"n_particles": 6, "n_iters": 6}
    p = _write(tmp_path, raw)
    assert main(["run", p, "--quiet", "--no-figures"]) == 0
    rec = archive.load(tmp_path / "r.h5")
    g = rec.groups["verdict"]
    assert len(g["x"]) >= 2  # the search's final design and another
    xb = np.asarray(g["x"])[-1]
    np.testing.assert_array_equal(rec.groups["final"]["x"], xb)
    assert rec.groups["final"]["attrs"]["stage"] == "race"
    job = _job()
    search = verdict.quoted.blocked(job.search_problem, xb[None])
    assert float(rec.groups["best_run"]["final"]["gci"]) == float(search["gci"][0])
    capsys.readouterr()
    design = [f"--design={n}={float(v)!r}" for n, v in zip(rec.names, xb, strict=True)]
    assert main(["eval", p, *design, "--fresh", "--json"]) == 0
    vals = json.loads(capsys.readouterr().out)
    vals = vals["designs"][0]["values"] if "designs" in vals else vals
    assert vals["gci"] == float(rec.groups["final"]["gci"])


def test_the_planning_cases_arms_show_a_mirror_symmetry_and_a_tie_names_it():
    # arms [-b, by] / [b, by] with ports [-px, py0] / [px, py1]: x → −x with the arms
    # trading places maps a layout to the one with py0 and py1 swapped
    path = "configs/port_placement.yaml"
    cfg = validate(yaml.safe_load(open(path)), path)
    names = ["b", "by", "px", "py0", "py1"]
    pairs, what = verdict.mirror_pairs(cfg, names)
    assert pairs == [("py0", "py1"), ("py1", "py0")] and what.startswith("x → −x")
    lo, hi = np.array([0.45, -0.2, 0.02, -0.14, -0.14]), np.array([0.8, 0.2, 0.14, 0.14, 0.14])
    X = np.array([[0.6, -0.06, 0.08, -0.09, 0.11], [0.6, -0.06, 0.08, 0.11, -0.09],
                  [0.6, -0.06, 0.08, 0.11, 0.11]])  # fmt: skip
    note = verdict.racing.tie_note(X, names, lo, hi, pairs=pairs, labels=["#0", "#1", "#2"])
    assert note == "the tied layouts differ in py0, py1; mirror images: #0 and #1"
    assert verdict.mirror_pairs(validate(_raw(), "c.yaml"), ["l1", "l2"]) is None  # no arms
    raw = yaml.safe_load(open(path))
    raw["study"]["arms"][1]["port"] = ["px", "py1", 0.25]  # not mirrored: another height
    assert verdict.mirror_pairs(validate(raw, path), names) is None


def test_stages_drawn_ahead_decide_as_stages_drawn_when_asked(monkeypatch):
    """Where a stage is one call and a core would idle, the race draws the next stage
    beside the one it asks for (``per_call``), and reads it for the designs still
    active: the verdict group equals the one of stages drawn one at a time, array for
    array, though a stage was drawn for a design the race had dropped by then."""
    from designopt.core import concurrency

    monkeypatch.setattr(concurrency, "threads", lambda: 2)
    job = _job(max_samples=32 * 8)  # 8 stages
    X = np.array([[0.0, 1.0], [0.001, 2.0], [0.04, 3.0]])  # f: column 0 + noise
    calls: list[tuple[int, int]] = []

    def stage_fn(s: int, Xa: np.ndarray) -> dict[str, np.ndarray]:
        calls.append((s, len(Xa)))
        noise = [np.random.default_rng([s, int(x[1])]).normal(0.0, 0.01) for x in Xa]
        return {"f": Xa[:, 0] + np.asarray(noise)}

    one = verdict.race_candidates(job, X, stage_fn=stage_fn)
    asked, calls[:] = list(calls), []
    two = verdict.race_candidates(job, X, stage_fn=stage_fn, per_call=16)
    assert set(one) == set(two)
    for k in one:
        if k != "attrs":
            np.testing.assert_array_equal(np.asarray(one[k]), np.asarray(two[k]), err_msg=k)
    drop = {k: v for k, v in one["attrs"].items() if k != "wall_s"}
    assert drop == {k: v for k, v in two["attrs"].items() if k != "wall_s"}
    n = np.asarray(one["n_samples"]) // 32  # each candidate's stages
    assert n.min() < n.max() <= 8  # a candidate dropped before the others stopped
    drawn = dict(calls)  # stage → designs it was drawn for, ahead
    assert any(drawn.get(s, 0) > np.sum(n > s) for s in range(8)), (calls, n)
    assert len(calls) > len(asked) or set(calls) != set(asked)
