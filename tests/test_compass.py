"""The compass polish (``refine: {method: compass}``): the search itself against known
minimisers, and the runs it serves (a front's recommended designs, a weighted run's best
ones) against the values recomputed independently on the search's own samples."""

from pathlib import Path

import h5py
import numpy as np
import pytest

from designopt.cli.commands import main
from designopt.optim.compass import compass


def _free(f):
    return lambda X: (np.zeros(len(X)), f(X))


def test_reaches_a_quadratics_minimiser_from_every_start_within_its_step():
    c = np.array([0.3, -0.2, 0.55])
    A = np.diag([1.0, 10.0, 0.1])  # badly scaled: the step is per variable's box width
    f = _free(lambda X: np.einsum("ni,ij,nj->n", X - c, A, X - c))
    lo, hi = np.array([-1.0, -1, 0]), np.array([1.0, 1, 2])
    x0 = np.array([[0.9, 0.9, 1.9], [-1, -1, 0], [0.3, -0.2, 0.55]])
    r = compass(f, x0, lo, hi, step=0.1, tol=1e-6, max_iters=2000)
    # at its end no poll at the last step (< tol) improves: within tol of the box widths
    assert np.all(np.abs(r.x - c) <= 1e-6 * (hi - lo) + 1e-15)
    assert np.all(r.f <= r.f0) and np.all(np.diff(r.history, axis=1) <= 0)
    assert r.f[2] == r.f0[2] == 0.0  # a start at the minimiser stays
    again = compass(f, x0, lo, hi, step=0.1, tol=1e-6, max_iters=2000)
    assert np.array_equal(again.x, r.x)  # deterministic


def test_counts_its_work_and_stops_at_its_iteration_cap():
    f = _free(lambda X: np.sum(X**2, 1))
    r = compass(f, np.array([[0.5, 0.5]]), -np.ones(2), np.ones(2), step=0.25, tol=1e-9,
                max_iters=3)  # fmt: skip
    assert r.iterations == 3 and r.history.shape == (1, 4)
    assert r.evaluations == 1 + 3 * 4  # the start, then 2D polls per iteration
    # 0.5 → 0 along each variable: two moves of 0.25 × width 2 = 0.5, then one halving
    assert np.allclose(r.x, [[0.0, 0.0]]) and r.step[0] == 0.125


def test_a_minimiser_outside_the_box_ends_on_its_face():
    f = _free(lambda X: np.sum((X - np.array([3.0, 0.25])) ** 2, 1))
    r = compass(f, np.array([[0.0, 0.0]]), -np.ones(2), np.ones(2), tol=1e-7, max_iters=500)
    assert r.x[0, 0] == 1.0 and abs(r.x[0, 1] - 0.25) <= 2e-7


def test_feasible_first_then_the_value_debs_rules():
    # min x² + y² subject to x + y ≥ 1: the optimum (0.5, 0.5) on the constraint's edge
    def ev(X):
        return np.maximum(1.0 - X.sum(1), 0.0), np.sum(X**2, 1)

    x0 = np.array([[-0.8, -0.9], [2.0, 2.0]])  # infeasible, and feasible but far
    r = compass(ev, x0, -2 * np.ones(2), 2 * np.ones(2), step=0.1, tol=1e-8, max_iters=5000)
    assert r.v0[0] > 0 and np.all(r.v == 0)
    # a compass search stalls on a constraint's edge at a point of it (no poll along the
    # axes is feasible and lower): on the edge, never below the constrained minimum 0.5
    assert np.allclose(r.x.sum(1), 1.0, atol=1e-7)
    assert np.all(r.f >= 0.5 - 1e-12) and r.f[1] < r.f0[1]
    # the feasible start only ever moved to feasible designs of lower value
    assert np.all(np.diff(r.history[1]) <= 0)


def test_nan_values_rank_last():
    def ev(X):
        f = np.sum(X**2, 1)
        return np.zeros(len(X)), np.where(X[:, 0] < 0, np.nan, f)

    r = compass(ev, np.array([[0.5, 0.5]]), -np.ones(2), np.ones(2), tol=1e-6)
    assert r.x[0, 0] >= 0 and np.isfinite(r.f[0])


ROOT = Path(__file__).resolve().parents[1]
FRONT = ROOT / "configs" / "planar2r_front.yaml"  # the planar 2R arm's gci-volume front
WEIGHTED = ROOT / "configs" / "planar2r.yaml"  # its gci alone, PTPSO
SMALL = {"study.indices.n_samples": 512, "optimizer.n_particles": 8, "optimizer.n_iters": 3}
POLISH = {"refine.method": "compass", "refine.step": 0.1, "refine.tol": 0.01}


def sets(d):
    return [a for k, v in d.items() for a in ("--set", f"{k}={v}")]


def test_a_fronts_runs_are_polished_by_their_scaled_distance_on_the_search_samples(tmp_path,
                                                                                   capsys):  # fmt: skip
    import designopt

    over = SMALL | {"front.n_samples": 1024, "optimizer.n_runs": 2}
    # the form docs/planning.md shows: the runs and the polish set on the command line
    assert main(["run", str(FRONT), *sets(over | POLISH), "--out", str(tmp_path / "f.h5"),
                 "--quiet", "--no-figures"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "polish: each run's recommended design, by a compass search on the search's " \
           "samples" in out and "polished by a compass search" in out  # fmt: skip
    with h5py.File(tmp_path / "f.h5") as h:
        g = h["refine"]
        x0, x, d0, d = (g[k][()] for k in ("x0", "x", "d0", "d"))
        ideal, nadir = g["ideal"][()], g["nadir"][()]
        runs_x = h["runs/x"][()]
        front_x = h["front/x"][()]
        assert g.attrs["iterations"] == g["history"].shape[1] - 1
    assert np.all(d <= d0) and np.any(d < d0) and np.array_equal(runs_x, x)
    # the archived distances, recomputed from the indices on the search's samples (the
    # study's own stream: eval of the same config), by the archived ideal and nadir
    cfg = designopt.load_config(FRONT, over)
    vals = designopt.evaluate(cfg, [dict(l1=a, l2=b) for a, b in np.concatenate([x0, x])])
    F = np.stack([vals["gci"], vals["volume"]], -1)
    span = np.where(nadir != ideal, nadir - ideal, 1.0)
    dist = np.sqrt(np.sum(((F - ideal) / span) ** 2, -1))
    assert np.allclose(dist, np.concatenate([d0, d]), rtol=1e-9, atol=1e-12)
    # the report's section: the same distances
    from designopt.figures.html.page import sections
    from designopt.io import archive

    sec = {s.id: s for s in sections(archive.read(tmp_path / "f.h5"))}["refine"]
    html = "".join(i for i in sec.items if isinstance(i, str))
    assert sec.title == "Compass polish" and all(f"{v:.6g}" in html for v in (*d0, *d))
    # each polished design joined the front's candidates: it is on the front, or a front
    # design dominates it on the search's samples
    fv = designopt.evaluate(cfg, [dict(l1=a, l2=b) for a, b in front_x])
    Ff = np.stack([fv["gci"], fv["volume"]], -1)
    for xi, fi in zip(x, F[len(x0):], strict=True):
        on = np.any(np.all(front_x == xi, 1))
        dominated = np.any(np.all(Ff >= fi, 1) & np.any(Ff > fi, 1))
        assert on or dominated


def test_a_gradient_polish_of_a_front_is_refused(tmp_path, capsys):
    assert main(["run", str(FRONT), "--set", "refine.method=adam", "--out",
                 str(tmp_path / "f.h5"), "--quiet"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "refine.method" in err and "compass" in err and err.count("\n") == 1
    assert not (tmp_path / "f.h5").exists()


def test_a_weighted_runs_best_designs_are_polished_and_stand_for_their_runs(tmp_path, capsys):
    import designopt

    over = SMALL | {"optimizer.n_runs": 2}
    assert main(["run", str(WEIGHTED), *sets(over | POLISH | {"refine.n_best": 2}), "--out",
                 str(tmp_path / "w.h5"), "--quiet", "--no-figures"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "polish (compass, " in out and "polished by a compass search" in out
    with h5py.File(tmp_path / "w.h5") as h:
        g = h["refine"]
        order, x0, f0, x, f = (g[k][()] for k in ("run_index", "x0", "f0", "x", "f"))
        best_x, best_f = h["optimizer/best_x"][()], h["optimizer/best_f"][()]
        runs_x = h["runs/x"][()]
        final_x = h["final/x"][()]
        assert g.attrs["method"] == "compass"
    assert np.array_equal(x0, best_x[order]) and np.allclose(f0, best_f[order], atol=1e-12)
    assert np.all(f <= f0) and np.array_equal(runs_x[order], x)
    # the final design: the better stage (a compass step is never worse)
    want = x[np.argmin(f)] if f.min() < best_f.min() else best_x[np.argmin(best_f)]
    assert np.array_equal(final_x, want)
    # f of the polished designs on the search's samples: −gci from eval of the config
    vals = designopt.evaluate(designopt.load_config(WEIGHTED, over),
                              [dict(l1=a, l2=b) for a, b in x])  # fmt: skip
    assert np.allclose(vals["f"], f, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("bad,needle", [
    ({"refine.method": "compass", "refine.step": 0.9}, "refine.step"),
    ({"refine.method": "compass", "refine.tol": 0}, "refine.tol"),
    ({"refine.method": "newton"}, "refine.method"),
])  # fmt: skip
def test_bad_compass_settings_name_their_key(tmp_path, capsys, bad, needle):
    assert main(["run", str(WEIGHTED), *sets(bad), "--out", str(tmp_path / "w.h5"),
                 "--quiet"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not (tmp_path / "w.h5").exists()
