"""Pareto fronts of a study's indices (study.objective.pareto, docs/pareto.md): the planar
2R arm's front against its known geometry and a brute-force grid, re-scoring honesty,
the record's round trip, the hypervolume history of the best front found so far, every
index shown beside the objectives, and the bad inputs (exit 2, one line naming the
key)."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

import designopt
from designopt import results
from designopt.app import fronts as fr
from designopt.app.job import Job
from designopt.cli.commands import main
from designopt.numerics import pareto
from designopt.problems.evaluate import score
from designopt.results import front as front_record

ROOT = Path(__file__).resolve().parents[1]
PLANAR = ROOT / "configs" / "planar2r.yaml"
FRONT = {"optimizer.name": "nsga2", "optimizer.n_particles": 40, "optimizer.n_iters": 40,
         "optimizer.n_runs": 2, "study.indices.n_samples": 2048,
         "study.objective": {"pareto": {"gci": "max", "volume": "max"}}}  # fmt: skip


@pytest.fixture(scope="module")
def front(tmp_path_factory):
    cfg = designopt.load_config(PLANAR, FRONT)
    out = tmp_path_factory.mktemp("front") / "f.h5"
    return cfg, designopt.run(cfg, out=out), out


def test_the_planar_2r_front_has_the_known_shape(front):
    """Volume ∫|det J| dq = 8π·l1·l2 grows with both lengths; the GCI depends on l2/l1 only
    and peaks at l2/l1 = 1/√2 (the isotropic ratio). So the front is l1 at its upper bound
    (2) with l2 from √2 (best GCI) to 2 (largest volume)."""
    _, rec, _ = front
    assert isinstance(rec, results.FrontRecord) and rec.objectives == {
        "gci": "max",
        "volume": "max",
    }
    X = rec.X
    assert len(X) >= 10
    np.testing.assert_allclose(X[:, 0], 2.0, atol=0.05)  # l1 at its bound
    ratio = X[:, 1] / X[:, 0]
    assert ratio.min() == pytest.approx(1 / np.sqrt(2), abs=0.04)  # the best-GCI end
    assert ratio.max() == pytest.approx(1.0, abs=0.02)  # the largest-volume end
    vol = rec.values["volume"]
    z = (vol - 8 * np.pi * X[:, 0] * X[:, 1]) / rec.values["volume_se"]
    assert np.all(np.abs(z) < 5)
    # sorted by the first objective (gci, max): descending
    assert np.all(np.diff(rec.F[:, 0]) <= 0)


def test_the_front_matches_a_brute_force_grid(front):
    """Every point of a 41 × 41 grid scored with the same fresh samples is dominated by
    the front or within 2 SE of it; the front's hypervolume is at least 99 % of the
    grid's non-dominated set's."""
    cfg, rec, _ = front
    g = np.linspace(0.2, 2.0, 41)
    L1, L2 = np.meshgrid(g, g, indexing="ij")
    problem, _ = fr.rescoring_problem(Job.build(cfg, "t"))
    vals = score(problem, np.stack([L1.ravel(), L2.ravel()], -1))
    G = np.stack([-vals["gci"], -vals["volume"]], -1)  # minimised
    nd = pareto.non_dominated(G)
    ref = -rec.reference
    hv_grid = pareto.hypervolume(G[nd], ref)
    assert rec.hypervolume >= 0.99 * hv_grid


def test_rescoring_changes_values_only_as_much_as_their_ses_explain(front):
    """Over four fronts (seeds), the front designs scored on the optimizer's samples and
    on the fresh ones differ by independent Monte-Carlo errors: |z| > 3 is rare and z²
    averages about 1 (the selection favours lucky samples, so a little above 1 is
    expected)."""
    cfg, rec, _ = front
    z = []
    for seed in range(4):
        c = cfg if seed == 0 else designopt.load_config(PLANAR, FRONT | {"seed": seed})
        r = rec if seed == 0 else designopt.run(c)
        old = designopt.evaluate(c, {"l1": r.X[:, 0], "l2": r.X[:, 1]})
        for j, k in enumerate(r.objectives):
            z.append((old[k] - r.F[:, j]) / np.hypot(old[k + "_se"], r.F_se[:, j]))
    z = np.concatenate(z)
    assert len(z) >= 400
    assert np.mean(np.abs(z) > 3) <= 0.03
    assert 0.3 < np.mean(z**2) < 2.5


def test_ambiguous_pairs_are_those_within_two_ses(front):
    _, rec, _ = front
    F, se = rec.F, rec.F_se
    want = {(i, j) for i in range(len(F)) for j in range(i + 1, len(F))
            if np.any(np.abs(F[i] - F[j]) <= 2 * np.hypot(se[i], se[j]))}  # fmt: skip
    assert {tuple(p) for p in rec.ambiguous.tolist()} == want


def test_the_front_record_round_trips_and_shows(front, capsys):
    _, rec, out = front
    back = designopt.load(out)
    assert back == rec, back.differs(rec)
    assert results.from_tree(rec.to_tree()) == rec
    assert back.history.shape == (2, 41)
    assert np.all(back.history[:, -1] > back.history[:, 0])  # the search improved the front
    assert main(["show", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Pareto front of gci (max), volume (max)" in text and "hypervolume" in text
    # every other index of the study beside the objectives, by name and value ± SE
    assert back.indices == ["gcsei", "manipulability"]
    head = next(ln for ln in text.splitlines() if "gcsei" in ln and "manipulability" in ln
                and "#" in ln)  # fmt: skip
    # each name with its unit (the planar 2R's lengths in L, volume an area)
    assert head.split()[:11] == ["#", "l1", "[L]", "l2", "[L]", "gci", "volume", "[L^2]", "gcsei",
                                 "manipulability", "[L^2]"]  # fmt: skip
    v, se = back.values["manipulability"], back.values["manipulability_se"]
    assert f"{v[0]:11.5g} ± {se[0]:7.1e}" in text and f"{v[-1]:11.5g} ± {se[-1]:7.1e}" in text
    assert "search: hypervolume of the best front found so far" in text


def test_the_history_is_the_best_front_found_so_far(front):
    """optimizer/hypervolume: the hypervolume of the archive of every design evaluated
    (never decreasing, never below the population's, its last value the archived
    archive's when nothing was cut from it); the population's is kept beside it."""
    _, rec, _ = front
    o = rec.groups["optimizer"]
    H, pop = rec.history, rec.population_history
    assert H.shape == pop.shape == (2, 41)
    assert np.all(np.diff(H, axis=1) >= 0) and np.all(H >= pop)
    np.testing.assert_array_equal(o["final_hypervolume"], H[:, -1])
    sg = np.array([1.0 if s == "min" else -1.0 for s in rec.objectives.values()])
    ref = rec.reference * sg  # minimised
    assert o["archive_f"].shape == (2, 4 * 40, 2)
    for i in range(2):
        A = o["archive_f"][i]
        A = A[~np.isnan(A).any(1)] * sg
        assert len(A) and not pareto.dominance_matrix_np(A).any()
        hv = pareto.hypervolume(A, ref)
        assert H[i, -1] >= hv * (1 - 1e-12)
        if o["archive_pruned"][i] == 0:  # exact: the final population adds nothing to it
            assert H[i, -1] == pytest.approx(hv, rel=1e-12)
            F = o["population_f"][i] * sg
            assert pareto.hypervolume(np.concatenate([A, F]), ref) == pytest.approx(hv, rel=1e-12)


def test_the_summary_shows_every_index_and_continues_wide_tables(front):
    """A task front of gci and length must show the reach beside them (low gci at the
    short end meant: does not reach). With more indices than fit a line, the columns go
    on in a block below, each row still numbered."""
    _, rec, _ = front
    n = len(rec.F)
    rng = np.random.default_rng(0)
    extra = {"reach": np.linspace(1.0, 0.0, n), "reach_se": np.full(n, 0.01)}
    for k in ("joint_margin", "gci_q05", "eta", "zeta", "omega"):
        extra[k], extra[k + "_se"] = rng.uniform(0, 1, n), rng.uniform(0, 0.01, n)
    extra["violation"] = np.zeros(n)  # an index without an SE
    g = {k: dict(v) if isinstance(v, dict) else v for k, v in rec.groups.items()}
    g["front"] = g["front"] | extra
    alt = dataclasses.replace(rec, groups=g)
    assert alt.indices[-1] == "violation" and set(alt.indices) == {
        "gcsei", "manipulability", "reach", "joint_margin", "gci_q05", "eta", "zeta", "omega",
        "violation"}  # fmt: skip
    lines = alt.summary()
    text = "\n".join(lines)
    assert "… the same designs, continued:" in text
    assert max(len(ln) for ln in lines if ln.startswith("  ")) <= front_record.WIDTH + 2
    heads = [ln.split() for ln in lines if ln.strip().startswith("#")]
    assert len(heads) >= 2 and all(h[0] == "#" for h in heads)
    names = [k for h in heads for k in re.sub(r" \[[^\]]*\]", "", " ".join(h[1:])).split()]
    assert names == alt.names + list(alt.objectives) + alt.indices  # each with its unit
    for i in (0, n - 1):  # the first and last designs are always shown
        rows = [ln for ln in lines if ln.split()[:1] == [str(i)]]
        assert len(rows) == len(heads)
        assert f"{extra['reach'][i]:11.5g} ± {0.01:7.1e}" in " ".join(rows)
        assert any(ln.rstrip().endswith(f"{0.0:11.5g}") for ln in rows)  # violation, no SE


def _cfg_file(tmp_path, **over):
    raw = yaml.safe_load(PLANAR.read_text())
    raw["optimizer"] = {"name": "nsga2", "n_particles": 8, "n_iters": 2, "n_runs": 2}
    raw["study"]["objective"] = {"pareto": {"gci": "max", "volume": "max"}}
    for k, v in over.items():
        node = raw
        *head, last = k.split(".")
        for h in head:
            node = node.setdefault(h, {})
        node[last] = v
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(raw))
    return p


@pytest.mark.parametrize("over,needle", [
    ({"study.objective": {"pareto": {"gci": "max"}}},
     "key 'study.objective.pareto': a front needs at least 2 indices"),
    ({"study.objective": {"pareto": {"gci": "max", "lenght": "min"}}},
     "key 'study.objective.pareto.lenght': unknown index"),
    ({"study.objective": {"pareto": {"gci": "up", "volume": "max"}}},
     "key 'study.objective.pareto.gci': sense must be 'min' or 'max'"),
    ({"optimizer.name": "ptpso"}, "key 'optimizer.name': 'ptpso' is single-objective"),
    ({"study.objective": {"gci": -1.0}}, "key 'optimizer.name': 'nsga2' optimises a Pareto front"),
    ({"front.reference": [0.1, 2.0, 3.0]}, "key 'front.reference': 3 values for 2 objectives"),
])  # fmt: skip
def test_bad_fronts_exit_2_with_one_line(tmp_path, capsys, over, needle):
    p = _cfg_file(tmp_path, **over)
    assert main(["run", str(p), "--out", str(tmp_path / "o" / "a.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "o" / "a.h5").exists()


def test_gci_against_total_length_follows_the_known_ratios():
    """GCI (max) against the total length l1 + l2 (min), a linear objective. The GCI
    depends on l2/l1 only and peaks at 1/√2; below the length 0.2·(1 + √2) that ratio
    cannot be had with l2 ≥ 0.2, so the front is l2 at its lower bound with l1 from 0.2
    (ratio 1) to 0.2·√2 (ratio 1/√2); every longer arm is dominated. But for the peak:
    the GCI is flat there (it falls with the square of the ratio's distance from 1/√2),
    so a longer arm whose ratio is closer to the (sampled) peak than any short arm's
    ties for the top GCI and is not dominated in a finite population; one or two such
    points appear in about half the seeds, with either survival rule."""
    over = FRONT | {"study.objective": {"pareto": {"gci": "max",
                                                  "length": {"min": {"l1": 1, "l2": 1}}}}}  # fmt: skip
    rec = designopt.run(designopt.load_config(PLANAR, over))
    X = rec.X
    ratio = X[:, 1] / X[:, 0]
    g = rec.F[:, list(rec.objectives).index("gci")]
    off = np.abs(X[:, 1] - 0.2) > 0.01
    assert off.sum() <= 2 and np.all(g[off] >= g.max() - 1e-4), (X[off], g.max() - g[off])
    np.testing.assert_allclose(ratio[off], 1 / np.sqrt(2), atol=2e-3)  # only at the peak
    on = ~off
    np.testing.assert_allclose(X[on, 1], 0.2, atol=0.01)  # l2 at its bound
    assert ratio.min() == pytest.approx(1 / np.sqrt(2), abs=0.03)
    assert ratio.max() == pytest.approx(1.0, abs=0.03)
    assert X[on, 0].max() <= 0.2 * np.sqrt(2) + 0.02
    j = list(rec.objectives).index("length")
    np.testing.assert_allclose(rec.F[:, j], X.sum(1), rtol=1e-12)  # exact, no samples
    assert np.all(rec.F_se[:, j] == 0)
    assert rec.objectives == {"gci": "max", "length": "min"}


def test_a_linear_objective_names_design_variables(tmp_path, capsys):
    p = _cfg_file(tmp_path, **{"study.objective": {"pareto": {
        "gci": "max", "length": {"min": {"l1": 1, "l3": 1}}}}})  # fmt: skip
    assert main(["run", str(p), "--out", str(tmp_path / "a.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "key 'study.objective.pareto.length.min.l3': not a design variable" in err


def test_a_sweep_of_fronts_is_refused_in_one_line(tmp_path, capsys):
    p = _cfg_file(tmp_path, **{"sweep": {"vary": {"optimizer.eta_c": [5.0, 15.0]}}})
    assert main(["sweep", str(p), "--out", str(tmp_path / "o" / "s.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "key 'sweep': a sweep of Pareto fronts" in err
    p = _cfg_file(tmp_path, **{"sweep": {"vary": {"optimizer.eta_c": [5.0]}},
                               "study.objective": {"gci": -1.0}})  # fmt: skip
    assert main(["sweep", str(p), "--out", str(tmp_path / "o" / "s.h5"), "--quiet"]) == 2
    assert "'nsga2' optimises a Pareto front" in capsys.readouterr().err
    assert not (tmp_path / "o" / "s.h5").exists()


def test_a_replay_study_has_no_front(tmp_path, capsys):
    raw = yaml.safe_load((ROOT / "configs" / "rcm_teleop.yaml").read_text())
    raw["study"]["trajectory"] = str(ROOT / "configs" / raw["study"]["trajectory"])
    raw["study"]["objective"] = {"pareto": {"a": "min", "b": "max"}}
    p = tmp_path / "t.yaml"
    p.write_text(yaml.safe_dump(raw))
    assert main(["run", str(p), "--out", str(tmp_path / "t.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "key 'study.objective.pareto'" in err and "no front" in err
