"""The decision statistics of the final stage (designopt.numerics.racing): verdicts on
synthetic races with a known answer at ten seeds each, share-constraint status and the
Wilson interval against scipy, clearing against a brute-force loop, the race's paired
differences against a direct NumPy computation on the very samples it drew, the mirror
test, and the config keys' bad input. NumPy only; no JAX compile."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError
from scipy import stats

from designopt.app import config
from designopt.app.config import Final
from designopt.core.errors import ConfigError
from designopt.numerics import racing
from designopt.numerics.statistics import holm

SEEDS = range(10)


def noisy(mu, seed, sd=0.05, common=0.1, shares=None, log=None):
    """A sample_fn: candidate c's value on sample t is mu[c] + common noise of t (the same
    target for every candidate) + the candidate's own noise; ``shares``: one share
    constraint whose success count per stage is exactly round(share·n). ``log`` collects
    every (active, stage, values) drawn."""
    mu = np.atleast_2d(np.asarray(mu, float).T).T  # (C, m)

    def fn(active, st):
        rng = np.random.default_rng([seed, st.index])
        n = st.size
        v = mu[:, None, :] + rng.normal(0, common, (1, n, 1)) + rng.normal(0, sd, (*mu.shape[:1], n, mu.shape[1]))
        v = v[active]
        if log is not None:
            log.append((active.copy(), st, v.copy()))
        if shares is None:
            return v
        return racing.Draw(v, np.round(np.asarray(shares, float)[active] * n)[:, None])

    return fn


# ------------------------------------------------------------- verdicts


@pytest.mark.parametrize("seed", SEEDS)
def test_two_equal_optima_give_a_tied_set(seed):
    """Two candidates with the same distribution and a clearly worse third: the race
    shows the two equivalent within the margin and stops the third early."""
    r = racing.race(noisy([0.5, 0.5, 0.3], seed), 3, margin=0.01, max_samples=4096, stage=64,
                    maximize=True)  # fmt: skip
    assert r.summary == "a tied set of 2 layouts"
    assert set(r.tied) == {0, 1} and r.best in (0, 1)
    assert r.reason == "decided" and r.settled[[0, 1]].all()
    assert list(r.verdict[[0, 1]]) in (["best", "equivalent"], ["equivalent", "best"])
    assert r.verdict[2] == "worse" and r.why[2] == "margin"
    assert r.n_samples[2] == 64 < r.n_samples[0] == r.n_samples[1] < 4096


@pytest.mark.parametrize("seed", SEEDS)
def test_a_gap_larger_than_the_margin_gives_one_recommendation(seed):
    """A gap of 0.03 against a margin of 0.01: the better one, alone, well before the cap;
    minimised objectives are the same race with the signs flipped."""
    for mu, maximize, best in (([0.5, 0.47, 0.3], True, 0), ([0.5, 0.47, 0.3], False, 2),
                               ([0.47, 0.5], True, 1)):  # fmt: skip
        r = racing.race(noisy(mu, seed), len(mu), margin=0.01, max_samples=4096, stage=64,
                        maximize=maximize)  # fmt: skip
        assert r.summary == "one recommendation", (mu, maximize, r.summary)
        assert r.best == best and r.tied == (best,) and r.reason == "one left"
        assert [v == "best" for v in r.verdict] == [i == best for i in range(len(mu))]
        assert r.n_samples.max() < 4096


def test_symmetric_scene_gives_a_tied_mirror_pair():
    """A scene symmetric under y → −y: designs (x, y) and (x, −y) score the same on every
    target, so their paired differences are exactly 0 and the race ties them at once;
    the tied layouts differ in y only, and they are mirror images (not of a third)."""
    X = np.array([[0.3, 0.4], [0.3, -0.4], [0.3, 0.401], [0.6, 0.1]])
    keep, groups = racing.clear(X, [0, -1], [1, 1], radius=0.02)
    assert list(keep) == [0, 1, 3] and list(groups) == [0, 1, 0, 2]
    Xc = X[keep]

    def fn(active, st):
        t = np.random.default_rng([7, st.index]).uniform(-1, 1, (st.size, 2))  # targets
        x = Xc[active]
        d2 = (x[:, None, 0] - np.abs(t[None, :, 0])) ** 2 + (np.abs(x[:, None, 1]) - np.abs(t[None, :, 1])) ** 2
        return np.exp(-d2)[..., None]

    r = racing.race(fn, 3, margin=0.01, max_samples=512, stage=64, maximize=True)
    assert r.summary == "a tied set of 2 layouts" and set(r.tied) == {0, 1}
    assert r.diff_se[r.tied[1], 0] == 0.0 and r.diff[r.tied[1], 0] == 0.0
    assert r.n_samples[0] == 64 and r.reason in ("decided", "one left")
    names = ["x", "y"]
    assert racing.differing_variables(Xc[[0, 1]], names, [0, -1], [1, 1]) == ["y"]
    flip = [("y", "y", -1)]
    assert racing.mirror(Xc[0], Xc[1], names, flip, lo=[0, -1], hi=[1, 1])
    assert not racing.mirror(Xc[0], Xc[2], names, flip, lo=[0, -1], hi=[1, 1])
    note = racing.tie_note(Xc[list(r.tied)], names, [0, -1], [1, 1], flip, labels=["A", "B"])
    assert note == "the tied layouts differ in y; mirror images: A and B"
    assert racing.tie_note(Xc[[0, 2]], names, [0, -1], [1, 1], flip) == "the tied layouts differ in x, y"


def test_a_clearly_worse_candidate_stops_at_the_first_stage():
    r = racing.race(noisy([0.5, 0.5, 0.1, 0.2], 3), 4, margin=0.01, max_samples=2048, stage=64,
                    maximize=True)  # fmt: skip
    assert list(r.n_samples[2:]) == [64, 64] and list(r.verdict[2:]) == ["worse", "worse"]
    assert r.n_samples[:2].min() > 64


def test_one_candidate_is_one_recommendation():
    r = racing.race(noisy([0.5], 0), 1, margin=0.01, max_samples=100, stage=50)
    assert r.summary == "one recommendation" and r.n_samples.tolist() == [50]
    assert r.verdict.tolist() == ["best"]


def test_not_separable_within_the_cap_is_an_unsettled_tie():
    """A gap of exactly the margin cannot be called worse nor equivalent: the race goes
    to the cap and says the data cannot choose (a tied set, not settled)."""
    r = racing.race(noisy([0.5, 0.49], 1), 2, margin=0.01, max_samples=256, stage=64,
                    maximize=True)  # fmt: skip
    assert r.reason == "cap" and not r.decided and r.n_samples.tolist() == [256, 256]
    assert r.summary == "a tied set of 2 layouts"
    other = 1 - r.best
    assert r.verdict[other] == "equivalent" and not r.settled[other] and not r.settled[r.best]


@pytest.mark.parametrize("seed", range(3))
def test_several_objectives_dominance_with_confidence(seed):
    """Two objectives (both minimised): A = (0, 0.5) and B = (0.5, 0) are a trade-off,
    C = (0.05, 0.55) is dominated by A by 0.05 on both, D has A's distribution: the race
    keeps the front {A, D, B}, A and D tied, C dominated."""
    mu = np.array([[0, 0.5], [0.5, 0], [0.05, 0.55], [0, 0.5]])
    r = racing.race(noisy(mu, seed), 4, margin=[0.01, 0.01], max_samples=4096, stage=64)
    assert r.summary == "a front of 3 layouts" and r.reason == "decided"
    assert r.verdict[2] == "worse" and r.why[2] == "dominated"
    assert set(r.tied) == {0, 1, 3} and r.verdict[1] == "best"
    assert sorted(r.verdict[[0, 3]]) == ["best", "equivalent"]
    assert r.settled[[0, 1, 3]].all() and not r.settled[2]
    assert r.n_samples[1] < r.n_samples[0] == r.n_samples[3] < 4096  # B decided early


def test_several_objectives_not_separable_within_the_cap_is_one_unsettled_group():
    """Two objectives, two layouts with the same distribution and a cap too small to show
    them equivalent: one group (a tied set), not a front of two."""
    mu = np.array([[0.2, 0.5], [0.2, 0.5]])
    r = racing.race(noisy(mu, 3, sd=0.2), 2, margin=0.01, max_samples=128, stage=64)
    assert r.reason == "cap" and r.summary == "a tied set of 2 layouts"
    assert sorted(r.verdict) == ["best", "equivalent"] and not r.settled.any()


def test_a_trade_off_is_not_eliminated():
    """B is better than A by 0.1 on objective 0 and worse by 0.03 on objective 1 (more
    than the margin): B does not dominate A, both stay."""
    mu = np.array([[0.1, 0.5], [0.0, 0.53]])
    r = racing.race(noisy(mu, 0), 2, margin=0.01, max_samples=4096, stage=64)
    assert list(r.verdict) == ["best", "best"] and r.summary == "a front of 2 layouts"


# ------------------------------------------------------------- constraint status


def test_constraint_status():
    z = 1.96
    assert racing.constraint_status(500, 1000, 0.5, z) == "at its bound"
    assert racing.constraint_status(800, 1000, 0.5, z) == "met"
    assert racing.constraint_status(200, 1000, 0.5, z) == "missed"
    assert racing.constraint_status(200, 1000, 0.5, z, "<=") == "met"
    assert racing.constraint_status(800, 1000, 0.5, z, "<=") == "missed"
    assert racing.constraint_status(500, 1000, 0.5, z, "<=") == "at its bound"
    out = racing.constraint_status(np.array([500, 800, 200]), 1000, 0.5, z)
    assert out.tolist() == ["at its bound", "met", "missed"]
    with pytest.raises(ValueError, match="sense"):
        racing.constraint_status(5, 10, 0.5, z, "==")


def test_the_race_samples_a_constraint_at_its_bound_to_the_cap():
    """Three layouts equal on the objective, their shares exactly at the bound 0.5, well
    above (0.8) and well below (0.2): the missed one is worse at once, the met one stops
    when its ties are shown, the one at its bound is sampled to the cap."""
    r = racing.race(noisy([0.5, 0.5, 0.5], 2, shares=[0.5, 0.8, 0.2]), 3, margin=0.01,
                    max_samples=2048, stage=64, maximize=True, bound=0.5)  # fmt: skip
    assert r.status[:, 0].tolist() == ["at its bound", "met", "missed"]
    assert r.verdict[2] == "worse" and r.why[2] == "constraint" and r.n_samples[2] == 64
    assert r.n_samples[0] == 2048 > r.n_samples[1] and r.reason == "cap"
    assert np.allclose(r.share[:, 0], [32 / 64, 51 / 64, 13 / 64], rtol=1e-15)  # round(share·64)
    assert np.all(r.share_lo <= r.share) and np.all(r.share <= r.share_hi)


def test_a_better_layout_at_its_bound_does_not_eliminate_a_met_one():
    """The leader (better by 0.05) sits at its bound; the met layout is not eliminated by
    it, since the leader may yet miss its constraint."""
    r = racing.race(noisy([0.55, 0.5], 4, shares=[0.5, 0.9]), 2, margin=0.01, max_samples=512,
                    stage=64, maximize=True, bound=0.5)  # fmt: skip
    assert r.best == 0 and r.status[:, 0].tolist() == ["at its bound", "met"]
    assert r.verdict[1] != "worse" and r.summary == "a tied set of 2 layouts"


@pytest.mark.parametrize("cl", [0.9, 0.95, 0.99, 0.999])
def test_wilson_against_scipy(cl):
    z = stats.norm.ppf(1 - (1 - cl) / 2)
    for n in (1, 7, 30, 128, 1000):
        k = np.arange(n + 1)
        lo, hi = racing.wilson(k, n, z)
        for kk in (0, 1, n // 3, n // 2, n - 1, n):
            ci = stats.binomtest(int(kk), n).proportion_ci(confidence_level=cl, method="wilson")
            assert abs(lo[kk] - ci.low) < 1e-12 and abs(hi[kk] - ci.high) < 1e-12, (n, kk)
    assert racing.wilson(0, 0, 1.96) == (0.0, 1.0)


def test_normal_quantile_and_tail_against_scipy():
    for p in (1e-9, 0.001, 0.025, 0.3, 0.5, 0.9, 0.975, 1 - 0.05 / 32, 1 - 1e-9):
        assert abs(racing.norm_ppf(p) - stats.norm.ppf(p)) < 1e-10
    x = np.array([-np.inf, -5, -1.2, 0, 0.7, 3, 8, np.inf])
    assert np.allclose(racing.norm_sf(x), stats.norm.sf(x), rtol=1e-12, atol=0)


# ------------------------------------------------------------- clearing


def brute_clear(X, lo, hi, radius):
    U = (np.asarray(X) - lo) / (np.asarray(hi) - lo)
    groups = [-1] * len(U)
    keep = []
    for i in range(len(U)):
        if groups[i] >= 0:
            continue
        for j in range(len(U)):
            if groups[j] < 0 and math.dist(U[i], U[j]) <= radius:
                groups[j] = len(keep)
        keep.append(i)
    return keep, groups


@pytest.mark.parametrize("seed", range(5))
def test_clear_against_a_brute_force_loop(seed):
    rng = np.random.default_rng(seed)
    lo, hi = np.array([0.0, -2.0, 10.0]), np.array([1.0, 2.0, 30.0])
    X = lo + (hi - lo) * rng.random((60, 3))
    X[30:40] = X[:10] + (hi - lo) * rng.normal(0, 0.01, (10, 3))  # near copies
    for radius in (0.0, 0.05, 0.2, 0.5):
        keep, groups = racing.clear(X, lo, hi, radius)
        k2, g2 = brute_clear(X, lo, hi, radius)
        assert keep.tolist() == k2 and groups.tolist() == g2
        U = (X - lo) / (hi - lo)
        assert np.all(np.linalg.norm(U - U[keep[groups]], axis=1) <= radius)
        if len(keep) > 1:
            D = np.linalg.norm(U[keep][:, None] - U[keep][None], axis=-1)
            assert D[~np.eye(len(keep), dtype=bool)].min() > radius


def test_clear_merges_within_the_radius_only():
    lo, hi = np.zeros(2), np.array([1.0, 10.0])
    X = np.array([[0.5, 5.0], [0.51, 5.0], [0.5, 5.0 + 0.3], [0.53, 5.0]])  # 0.01, 0.03, 0.03
    keep, groups = racing.clear(X, lo, hi, 0.02)
    assert keep.tolist() == [0, 2, 3] and groups.tolist() == [0, 0, 1, 2]
    keep, groups = racing.clear(X, lo, hi, 0.0)
    assert keep.tolist() == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="radius"):
        racing.clear(X, lo, hi, -0.1)


# ------------------------------------------------------------- paired statistics, Holm


def test_paired_against_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(1, 0.3, (200, 3)), rng.normal(0.9, 0.3, (200, 3))
    m, se = racing.paired(a, b)
    d = a - b
    assert np.allclose(m, d.mean(0), rtol=1e-14) and np.allclose(se, d.std(0, ddof=1) / math.sqrt(200), rtol=1e-12)
    reps_a, reps_b = a[:, 0].reshape(20, 10).mean(1), b[:, 0].reshape(20, 10).mean(1)  # R = 10
    m, se = racing.paired(reps_a, reps_b)
    assert np.isclose(se, np.std(reps_a - reps_b, ddof=1) / math.sqrt(20), rtol=1e-12)
    with pytest.raises(ValueError):
        racing.paired(a[:1], b[:1])


def test_race_statistics_against_the_samples_it_drew():
    """The race's running sums against NumPy on the samples it drew: each candidate's
    mean and SE, and its paired difference from the best on their common prefix."""
    log: list = []
    mu = np.array([[0.5, 0.2], [0.5, 0.21], [0.45, 0.2], [0.3, 0.1]])
    r = racing.race(noisy(mu, 5, log=log), 4, margin=[0.01, 0.02], max_samples=1000,
                    stage=96, maximize=[True, False])  # fmt: skip
    per = {c: [] for c in range(4)}
    for active, _, v in log:
        for row, c in enumerate(active):
            per[int(c)].append(v[row])
    vals = {c: np.concatenate(per[c]) for c in per}
    for c in range(4):
        x = vals[c]
        assert len(x) == r.n_samples[c]
        assert np.allclose(r.mean[c], x.mean(0), rtol=1e-12, atol=1e-14)
        assert np.allclose(r.se[c], x.std(0, ddof=1) / math.sqrt(len(x)), rtol=1e-9)
        n = min(len(x), len(vals[r.best]))
        if c == r.best:
            assert np.all(r.diff[c] == 0) and np.all(r.diff_se[c] == 0)
            continue
        m, se = racing.paired(x[:n], vals[r.best][:n])
        assert np.allclose(r.diff[c], m, rtol=1e-9, atol=1e-13)
        assert np.allclose(r.diff_se[c], se, rtol=1e-7)


def test_holm_reject_against_the_existing_function_and_the_step_down():
    rng = np.random.default_rng(1)
    for _ in range(50):
        p = rng.random(12) ** 3
        got = racing.holm_reject(p, 0.05)
        assert np.array_equal(got, holm(p) < 0.05)
        order = np.argsort(p)  # the textbook step-down
        want = np.zeros(12, bool)
        for i, j in enumerate(order):
            if p[j] >= 0.05 / (12 - i):
                break
            want[j] = True
        assert np.array_equal(got, want)


# ------------------------------------------------------------- mirror images


def test_mirror_of_two_ports_that_trade_places():
    names = ["p1_x", "p1_y", "p2_x", "p2_y", "h"]
    pairs = [("p1_x", "p2_x"), ("p2_x", "p1_x"), ("p1_y", "p2_y", -1), ("p2_y", "p1_y", -1)]
    a = np.array([0.10, 0.05, 0.20, -0.03, 0.4])
    b = np.array([0.20, 0.03, 0.10, -0.05, 0.4])  # the image of a
    assert racing.mirror(a, b, names, pairs, tol=1e-12)
    assert racing.mirror(b, a, names, pairs, tol=1e-12)
    c = b.copy()
    c[4] = 0.5  # a shared variable differs: not a mirror image
    assert not racing.mirror(a, c, names, pairs, tol=1e-3)
    assert not racing.mirror(a, a, names, pairs, tol=1e-3)  # a is not symmetric itself
    with pytest.raises(ValueError, match="two pairs"):
        racing.mirror(a, b, names, [("p1_x", "p2_x"), ("p1_y", "p2_x")])
    with pytest.raises(ValueError, match="unknown"):
        racing.mirror(a, b, names, [("q", "p2_x")])


def test_differing_variables():
    X = np.array([[0.1, 1.0, 5.0], [0.1, 1.5, 5.01]])
    assert racing.differing_variables(X, ["a", "b", "c"], [0, 0, 0], [1, 2, 10]) == ["b"]
    assert racing.differing_variables(X[:1], ["a", "b", "c"], [0, 0, 0], [1, 2, 10]) == []


# ------------------------------------------------------------- bad input


@pytest.mark.parametrize("raw,key", [
    ({"margin": math.nan}, "margin"),
    ({"margin": -0.01}, "margin"),
    ({"margin": 0}, "margin"),
    ({"margin": "small"}, "margin"),
    ({"margin": {"gci": math.nan}}, "margin.gci"),
    ({"margin": {"gci": -1}}, "margin.gci"),
    ({"max_samples": -100}, "max_samples"),
    ({"max_samples": 29}, "max_samples"),
    ({"max_samples": math.nan}, "max_samples"),
    ({"radius": -0.1}, "radius"),
    ({"radius": math.inf}, "radius"),
    ({"radius": "wide"}, "radius"),
    ({"seed": -1}, "seed"),
    ({"seed": math.nan}, "seed"),
    ({"seed": "abc"}, "seed"),
    ({"stage": 10}, "stage"),
    ({"stage": 512, "max_samples": 256}, "stage"),
    ({"alpha": 0.0}, "alpha"),
])  # fmt: skip
def test_bad_final_keys_name_the_key(raw, key):
    with pytest.raises(ConfigError, match=rf"^c\.yaml: key '{key}': "):
        config.validate(raw, "c.yaml", model=Final)
    if not any(isinstance(v, float) and not math.isfinite(v) for v in raw.values()):
        with pytest.raises(ValidationError):
            Final.model_validate(raw)


def test_final_defaults_and_margins():
    f = Final()
    assert (f.seed, f.max_samples, f.stage, f.radius, f.alpha) == (20260, 1024, 128, 0.02, 0.05)
    assert f.margin_of("gci") == 0.01 and f.margin_of("arms_ok", share=True) == 0.02
    f = config.validate({"margin": {"gci": 0.005}, "max_samples": 30, "stage": 30}, "c.yaml",
                        model=Final)  # fmt: skip
    assert f.margin_of("gci") == 0.005 and f.margin_of("arms_ok", share=True) == 0.02
    assert config.validate({"margin": 0.03}, "c.yaml", model=Final).margin_of("arms_ok", True) == 0.03


def test_race_refuses_bad_arguments():
    fn = noisy([0.5, 0.4], 0)
    for kw, needle in (({"margin": 0.0}, "margin"), ({"margin": math.nan}, "margin"),
                       ({"margin": 0.01, "alpha": 1.5}, "alpha"),
                       ({"margin": 0.01, "max_samples": 1}, "2 samples")):  # fmt: skip
        with pytest.raises(ValueError, match=needle):
            racing.race(fn, 2, **{"max_samples": 256, **kw})
    with pytest.raises(ValueError, match="shape"):
        racing.race(lambda a, st: np.zeros((len(a), st.size + 1)), 2, margin=0.01, max_samples=64)
    with pytest.raises(ValueError, match="non-finite"):
        racing.race(lambda a, st: np.full((len(a), st.size), np.nan), 2, margin=0.01, max_samples=64)
    with pytest.raises(ValueError, match="bounds"):
        racing.race(lambda a, st: racing.Draw(np.zeros((len(a), st.size)), np.zeros((len(a), 1))),
                    2, margin=0.01, max_samples=64)  # fmt: skip


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
}  # fmt: skip


@pytest.mark.parametrize("final,key", [
    ({"margin": math.nan}, "final.margin"),
    ({"margin": {"gci": -1}}, "final.margin.gci"),
    ({"max_samples": 20}, "final.max_samples"),
    ({"radius": -0.5}, "final.radius"),
    ({"seed": "abc"}, "final.seed"),
])  # fmt: skip
def test_bad_final_keys_in_a_run_config_exit_2_naming_the_key(tmp_path, capsys, final, key):
    """The same refusals from a config file on the command line: one line, exit 2, before
    any work."""
    import yaml

    from designopt.cli.commands import main

    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(PLANAR | {"final": final}, sort_keys=False))
    capsys.readouterr()
    assert main(["eval", str(p)]) == 2
    out, err = capsys.readouterr()
    assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
    assert f"key '{key}'" in err and "Traceback" not in out + err


@pytest.mark.parametrize("df", [1, 2, 3, 7.5, 30, 200])
def test_student_t_tail_and_quantile_against_scipy(df):
    for x in (-3.0, -0.5, 0.0, 1e-6, 0.3, 1.2, 4.0, 20.0):
        assert abs(racing.t_sf(x, df) - stats.t.sf(x, df)) < 1e-9
    for p in (1e-6, 0.01, 0.025, 0.3, 0.5, 0.9, 0.999):
        q = stats.t.ppf(p, df)
        assert abs(racing.t_ppf(p, df) - q) < 1e-8 * max(1.0, abs(q))
    assert racing.t_ppf(0.975, math.inf) == racing.norm_ppf(0.975)


def test_a_race_of_replication_means_uses_students_t():
    """Units that are replication means (student=True, a first stage of 2 units): on the
    same draws, a difference the normal approximation calls ((d − δ)/SE = 3 at the first
    look) is not called with 1 degree of freedom; with more units it is."""
    def fn(active, st):  # candidate 1 worse by 0.1 ± 0.03 per unit, a common unit effect
        u = np.arange(st.start, st.stop)
        common = 0.2 * np.sin(u)[None, :]
        d = 0.1 + 0.03 * np.where(u % 2 == 0, 1.0, -1.0)[None, :]
        return (np.array([[0.0], [1.0]])[active] * d + common)[..., None]

    normal = racing.race(fn, 2, margin=0.01, max_samples=2, stage=1, first=2)
    student = racing.race(fn, 2, margin=0.01, max_samples=2, stage=1, first=2, student=True)
    assert normal.verdict.tolist() == ["best", "worse"]  # z = 3: p = 0.0013
    assert student.verdict.tolist() == ["best", "equivalent"] and student.reason == "cap"
    longer = racing.race(fn, 2, margin=0.01, max_samples=12, stage=1, first=2, student=True)
    assert longer.verdict.tolist() == ["best", "worse"] and longer.n_samples[1] < 12
