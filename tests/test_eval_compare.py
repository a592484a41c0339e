"""`designopt eval CONFIG --design … --design …` (issue 53): designs compared, one column
each and their paired differences. The difference's SE is checked against NumPy from
the per-replicate values recomputed here design by design (a non-task study, planar2r,
and a task study, whose per-target values also give the difference exactly and its
per-target paired SE), the grouping of the flags, and bad input (one line, exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import jax
import numpy as np
import pytest

from designopt.app import pipeline
from designopt.app.config import load
from designopt.app.job import Job, build_problem
from designopt.cli.commands import design_groups, main
from designopt.problems.evaluate import score
from designopt.studies import get

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parents[1]
PLANAR = str(ROOT / "configs/planar2r.yaml")
TASK = str(ROOT / "configs/planar2r_task.yaml")


def _replicated(cfg, designs: list[dict[str, float]], replicas: int) -> list[dict]:
    """Each design scored on its own (not in one call) on the run's samples and on the
    replicate sample sets the paired SE is documented to use."""
    job = Job.build(cfg, "test", n_designs=1)
    root = jax.random.fold_in(job.keys["samples"], pipeline.PAIRED_STREAM)
    sets = [dict(job.keys)] + [dict(job.keys) | {"samples": jax.random.fold_in(root, r)}
                               for r in range(replicas)]  # fmt: skip
    names = job.problem.names
    out = []
    for keys in sets:
        pb = job.problem if keys is sets[0] else build_problem(cfg, keys, "test", job.dtype)
        rows = {}
        for d in designs:
            x = np.array([[d[n] for n in names]])
            for k, v in score(pb, x, batch=1).items():
                rows.setdefault(k, []).append(float(np.asarray(v)[0]))
        out.append({k: np.array(v) for k, v in rows.items()})
    return out


@pytest.fixture(scope="module")
def planar():
    cfg, _ = load(PLANAR, overrides={"study.indices.n_samples": 2000})
    designs = [{"l1": 1.0, "l2": 0.8}, {"l1": 1.1, "l2": 0.8}, {"l1": 0.6, "l2": 1.5}]
    return cfg, designs, pipeline.compare(cfg, designs, "test", replicas=5)


def test_paired_se_is_the_spread_of_the_differences_over_the_sample_sets(planar):
    cfg, designs, out = planar
    reps = _replicated(cfg, designs, 5)
    for j, diff in enumerate(out["differences"]):
        assert diff["of"] == (j + 1, 0)
        for k in ("gci", "gcsei", "manipulability", "f"):
            d = np.array([r[k][j + 1] - r[k][0] for r in reps])  # NumPy, design by design
            np.testing.assert_allclose(diff["values"][k], d[0], rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(diff["values"][k + "_se"], np.std(d, ddof=1),
                                       rtol=1e-9)  # fmt: skip
    # the designs' own values: those of scoring each alone on the run's samples
    for i, row in enumerate(out["designs"]):
        np.testing.assert_allclose(row["values"]["gci"], reps[0]["gci"][i], rtol=1e-12)
    # close designs on common samples: the paired SE far below either SE alone
    v0, v1 = out["designs"][0]["values"], out["designs"][1]["values"]
    unpaired = np.hypot(v0["gci_se"], v1["gci_se"])
    assert out["differences"][0]["values"]["gci_se"] < unpaired / 3


def test_task_difference_is_the_mean_of_the_per_target_differences():
    """The task study: gci and reach are means over the targets, so the difference is
    the mean of the per-target differences (the targets hook, NumPy) and its paired SE
    is close to the per-target SE sd(d_i)/√N (the replicate spread estimates it; 8
    replicates: within a factor 2.5)."""
    cfg, _ = load(TASK, overrides={"study.indices.n_samples": 256})
    designs = [{"l1": 1.0, "l2": 0.9}, {"l1": 1.1, "l2": 0.9}]
    out = pipeline.compare(cfg, designs, "test")
    job = Job.build(cfg, "test", n_designs=1)
    st = get("serial")
    tg = [st.targets(cfg.study, np.array([d["l1"], d["l2"]]), job.keys, job.dtype)
          for d in designs]  # fmt: skip
    per = {"reach": [t["success"][0].astype(float) for t in tg],
           "gci": [np.where(t["success"][0] > 0, t["inv_k"][0], 0.0) for t in tg]}
    diff = out["differences"][0]["values"]
    for k, (a, b) in per.items():
        d = b - a
        np.testing.assert_allclose(diff[k], d.mean(), rtol=1e-9, atol=1e-12)
        se = np.std(d, ddof=1) / np.sqrt(len(d))
        if se > 0:
            assert se / 2.5 <= diff[k + "_se"] <= 2.5 * se, (k, diff[k + "_se"], se)
        for i, t in ((0, a), (1, b)):  # each design's own value: the mean of its targets
            np.testing.assert_allclose(out["designs"][i]["values"][k], t.mean(), rtol=1e-9)


def test_design_flags_group_into_designs():
    assert design_groups([["b=0.6"], ["px=0.03"]]) == [{"b": 0.6, "px": 0.03}]
    assert design_groups([["b=0.6"], ["b=0.7"]]) == [{"b": 0.6}, {"b": 0.7}]
    assert design_groups([["b=0.6,by=0"], ["b=0.7,by=0.1"]]) == [{"b": 0.6, "by": 0.0},
                                                                {"b": 0.7, "by": 0.1}]  # fmt: skip
    assert design_groups([["b=0.6", "by=0"], ["px=0.03"]]) == [{"b": 0.6, "by": 0.0},
                                                             {"px": 0.03}]  # fmt: skip
    assert design_groups([]) == [{}]


def test_the_command_prints_a_column_per_design_and_the_paired_difference(capsys):
    rc = main(["eval", PLANAR, "--set", "study.indices.n_samples=500", "--design", "l1=1.0",
               "--design", "l1=1.1,l2=0.8", "--no-cache"])  # fmt: skip
    out = capsys.readouterr().out
    assert rc == 0, out
    lines = out.splitlines()
    assert lines[0].startswith("design 1: l1 = 1 L") and "l2: the middle of the box" in lines[0]
    assert lines[1].startswith("design 2: l1 = 1.1 L, l2 = 0.8 L")
    head = [h.strip() for h in lines[2].split("  ") if h.strip()]
    assert head == ["design 1", "design 2", "design 2 − design 1"], lines[2]
    assert any(ln.strip().startswith("gci ") and "±" in ln for ln in lines)
    assert "paired SE" in out
    rc = main(["eval", PLANAR, "--set", "study.indices.n_samples=500", "--design", "l1=1.0",
               "--design", "l1=1.1,l2=0.8", "--json", "--no-cache"])  # fmt: skip
    js = json.loads(capsys.readouterr().out)
    assert rc == 0 and len(js["designs"]) == 2 and js["designs"][0]["middle_of_box"] == ["l2"]
    d = js["differences"][0]
    assert d["of"] == [2, 1]
    np.testing.assert_allclose(d["gci"], js["designs"][1]["gci"] - js["designs"][0]["gci"],
                               rtol=1e-12)  # fmt: skip
    assert 0 < d["gci_se"] < js["designs"][0]["gci_se"]


@pytest.mark.parametrize("design, needle", [
    ("l1=5", "l1=5: outside the design box [0.2, 2] of variable 'l1'"),
    ("zz=1", "'zz'"),
])  # fmt: skip
def test_bad_design_is_one_line_exit_2(capsys, design, needle):
    rc = main(["eval", PLANAR, "--design", "l1=1", "--design", design, "--no-cache"])
    out, err = capsys.readouterr()
    assert rc == 2 and err.count("\n") == 1 and needle in err, err
    assert "Traceback" not in out + err
