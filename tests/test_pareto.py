"""designopt.numerics.pareto: hypervolume against moocore, sorting and crowding against brute force
and pymoo (where installed), IGD+ by hand, and the multi-objective test problems' fronts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.numerics import pareto as pa
from designopt.problems import multi

moocore = pytest.importorskip("moocore")

_hv2 = jax.jit(lambda F, r, ok: pa.hypervolume_jax(F, r, ok))


def _random_fronts(rng, m, n):
    """Random point sets of three kinds: uniform (mostly dominated), on a sphere (all
    non-dominated) and with ties and points outside the reference box."""
    U = rng.random((n, m))
    S = np.abs(rng.normal(size=(n, m)))
    S /= np.linalg.norm(S, axis=1, keepdims=True)
    T = rng.integers(0, 6, (n, m)) / 5.0 * 1.2  # a grid: ties, some ≥ 1.1
    return U, S, T


@pytest.mark.parametrize("m", [2, 3])
def test_hypervolume_agrees_with_moocore(m):
    rng = np.random.default_rng(m)
    ref = np.full(m, 1.1)
    for n in (1, 7, 64):
        for F in _random_fronts(rng, m, n):
            want = moocore.hypervolume(F, ref=ref)
            assert pa.hypervolume(F, ref) == pytest.approx(want, rel=1e-12, abs=1e-15)
    # the JAX version (inside the optimizer's loop), one shape: 64 points
    for _ in range(4):
        for F in _random_fronts(rng, m, 64):
            ok = rng.random(64) < 0.8
            want = moocore.hypervolume(F[ok], ref=ref) if ok.any() else 0.0
            got = float(_hv2(jnp.asarray(F), jnp.asarray(ref), jnp.asarray(ok)))
            assert got == pytest.approx(want, rel=1e-12, abs=1e-15)


def test_hypervolume_four_objectives_and_known_values():
    rng = np.random.default_rng(4)
    F = rng.random((40, 4))
    assert pa.hypervolume(F, np.full(4, 1.1)) == pytest.approx(
        moocore.hypervolume(F, ref=np.full(4, 1.1)), rel=1e-12
    )
    # one point: a box; two points in 2-D: two boxes minus their overlap
    assert pa.hypervolume([[0.5, 0.25, 0.0]], [1, 1, 1]) == pytest.approx(0.375)
    assert pa.hypervolume([[0.0, 0.5], [0.5, 0.0]], [1, 1]) == pytest.approx(0.75)
    assert pa.hypervolume([[1.0, 0.0], [2.0, -1.0]], [1, 1]) == 0.0  # on/outside the box
    # ZDT1's front against (1.1, 1.1): 1.1² − ∫₀¹ (1 − √f) df = 0.87667
    assert pa.hypervolume(multi.true_front("zdt1", 20001), [1.1, 1.1]) == pytest.approx(
        1.21 - 1 / 3, abs=1e-4
    )
    with pytest.raises(ValueError, match="reference point has 2 values"):
        pa.hypervolume(F, [1.0, 1.0])
    assert np.isnan(float(pa.hypervolume_jax(jnp.asarray(F), jnp.ones(4))))


def test_front_ranks_agree_with_brute_force_and_pymoo():
    rng = np.random.default_rng(0)
    ranks = jax.jit(lambda F, v: pa.front_ranks(F, v))
    cd = jax.jit(pa.crowding_distance)
    for trial in range(6):
        m = 2 + trial % 2
        F = rng.integers(0, 8, (50, m)).astype(float)  # many ties and duplicates
        v = np.where(rng.random(50) < 0.3, rng.integers(1, 4, 50), 0).astype(float)
        want = pa.front_ranks_np(F, v)
        got = np.asarray(ranks(jnp.asarray(F), jnp.asarray(v)))
        np.testing.assert_array_equal(got, want)
        # unconstrained: a brute-force definition of rank 0
        r0 = np.asarray(ranks(jnp.asarray(F), jnp.zeros(50)))
        dominated = [
            any(np.all(F[j] <= F[i]) and np.any(F[j] < F[i]) for j in range(50)) for i in range(50)
        ]
        np.testing.assert_array_equal(r0 == 0, ~np.asarray(dominated))
        np.testing.assert_array_equal(pa.non_dominated(F), ~np.asarray(dominated))
        np.testing.assert_array_equal(pa.non_dominated(F, v), want == 0)
        c = np.asarray(cd(jnp.asarray(F), jnp.asarray(got)))
        np.testing.assert_allclose(c, pa.crowding_distance_np(F, want), rtol=1e-12)
    # early stop: at least n_stop ranked, the rest marked n
    F = rng.random((50, 2))
    part = np.asarray(pa.front_ranks(jnp.asarray(F), None, n_stop=10))
    full = pa.front_ranks_np(F)
    assert (part < 50).sum() >= 10
    np.testing.assert_array_equal(part[part < 50], full[part < 50])
    assert np.all(full[part == 50] > part[part < 50].max())
    nds = pytest.importorskip("pymoo.util.nds.non_dominated_sorting")
    F = rng.random((120, 3))
    fronts = nds.NonDominatedSorting().do(F)
    want = np.empty(120, int)
    for k, fr in enumerate(fronts):
        want[fr] = k
    np.testing.assert_array_equal(pa.front_ranks_np(F), want)


def test_crowding_distance_against_pymoo():
    metrics = pytest.importorskip("pymoo.operators.survival.rank_and_crowding.metrics")
    rng = np.random.default_rng(1)
    F = rng.random((30, 3))
    np.testing.assert_allclose(
        pa.crowding_distance_np(F, np.zeros(30, int)), metrics.calc_crowding_distance(F)
    )


def _prune_np(F, rank, n, tie):
    """Brute-force pruning: remove the least-crowded point of the last front (crowding
    recomputed from scratch on its survivors by numpy, ties by ``tie``) until n remain."""
    counts = np.bincount(rank, minlength=len(F) + 1)
    last = int(np.argmax(np.cumsum(counts) >= n))
    keep = rank < last
    alive = list(np.flatnonzero(rank == last))
    while keep.sum() + len(alive) > n:
        d = pa.crowding_distance_np(F[alive], np.zeros(len(alive), int))
        low = np.flatnonzero(d == d.min())
        alive.pop(int(low[np.argmin(tie[np.asarray(alive)[low]])]))
    keep[alive] = True
    return keep


@pytest.mark.parametrize("m", [2, 3])
def test_pruning_the_last_front_matches_brute_force(m):
    """``prune_last_front`` (linked lists, O(m) per removal) keeps the same points as
    recomputing every crowding distance after each removal, on random sets with several
    fronts, fronts of one point, duplicated values and a front with a constant objective."""
    rng = np.random.default_rng(m)
    fn = jax.jit(lambda F, r, t: pa.prune_last_front(F, r, 40, t))
    for case in range(12):
        F = rng.uniform(size=(100, m))
        if case % 3 == 1:
            F = np.round(F * 6) / 6  # ties in every objective
        if case % 3 == 2:
            F[:, 0] = 0.5  # a constant objective
        F[:, -1] += case / 12 * F[:, 0]
        rank = pa.front_ranks_np(F)
        tie = rng.uniform(size=100)
        kept, crowd = fn(jnp.asarray(F), jnp.asarray(rank, jnp.int32), jnp.asarray(tie))
        want = _prune_np(F, rank, 40, tie)
        np.testing.assert_array_equal(np.asarray(kept), want)
        last = rank == rank[want].max()
        got = np.asarray(crowd)[want & last]
        ref = pa.crowding_distance_np(F[want & last], np.zeros((want & last).sum(), int))
        np.testing.assert_allclose(got, ref, rtol=1e-12)


def test_pruning_with_a_failed_design_in_the_front():
    """A non-finite objective (a failed design) stands in as √(largest float): pruning
    gives the crowding distances the one-shot JAX crowding and numpy give with that value
    (dividing by a range near the largest float used to flush every gap of that objective
    to 0), and removes the same point as recomputing from scratch."""
    F = np.array([[0.0, 1.0], [0.3, 0.6], [0.6, 0.3], [np.inf, 0.0]])
    big = np.sqrt(np.finfo(np.float64).max)
    rank = jnp.zeros(4, jnp.int32)
    tie = jnp.asarray([0.1, 0.2, 0.3, 0.4])
    _, crowd = pa.prune_last_front(jnp.asarray(F), rank, 4, tie)
    ref = pa.crowding_distance_np(np.where(np.isfinite(F), F, big), np.zeros(4, int))
    np.testing.assert_allclose(np.asarray(crowd), ref, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(pa.crowding_distance(jnp.asarray(F), rank)), ref)
    assert ref[2] > 0.75  # the gap to the failed design counts
    kept, _ = jax.jit(lambda F, t: pa.prune_last_front(F, rank, 3, t))(jnp.asarray(F), tie)
    want = _prune_np(np.where(np.isfinite(F), F, big), np.zeros(4, int), 3, np.asarray(tie))
    np.testing.assert_array_equal(np.asarray(kept), want)
    assert not want[1]


def test_igd_plus_by_hand_and_against_pymoo():
    Z = np.array([[0.0, 1.0], [1.0, 0.0]])
    # a point at (0.5, 0.5): distance to each z is ‖max(a − z, 0)‖ = 0.5
    assert pa.igd_plus([[0.5, 0.5]], Z) == pytest.approx(0.5)
    assert pa.igd_plus(Z, Z) == 0.0
    assert pa.igd_plus([[-1.0, -1.0]], Z) == 0.0  # dominating the whole front
    with pytest.raises(ValueError, match="objectives"):
        pa.igd_plus(np.zeros((2, 3)), Z)
    ind = pytest.importorskip("pymoo.indicators.igd_plus")
    rng = np.random.default_rng(2)
    Zs = multi.true_front("zdt1", 200)
    A = rng.random((40, 2))
    assert pa.igd_plus(A, Zs) == pytest.approx(ind.IGDPlus(Zs)(A), rel=1e-12)


def test_problems_evaluate_on_their_fronts():
    """Designs on the Pareto set give the sampled front's values (g = 1 for ZDT, the unit
    sphere for DTLZ2), and IGD+ of the true front to itself is 0."""
    x1 = np.linspace(0, 1, 11)
    X = np.zeros((11, 30))
    X[:, 0] = x1
    for name, h in (("zdt1", 1 - np.sqrt(x1)), ("zdt2", 1 - x1**2)):
        F, _ = multi.multi_benchmark(name).evaluate(jnp.asarray(X))
        np.testing.assert_allclose(np.asarray(F), np.stack([x1, h], 1), atol=1e-12)
    P = multi.multi_benchmark("dtlz2", n_objectives=4)
    assert P.dim == 13 and P.n_objectives == 4
    X = np.random.default_rng(0).random((20, 13))
    X[:, 3:] = 0.5
    F = np.asarray(P.evaluate(jnp.asarray(X))[0])
    np.testing.assert_allclose(np.sum(F**2, axis=1), 1.0, rtol=1e-12)
    Z = multi.true_front("dtlz2", 100)
    assert Z.shape[1] == 3 and np.allclose(np.sum(Z**2, 1), 1.0)
    assert pa.non_dominated(Z).all()
    z3 = multi.true_front("zdt3", 500)
    assert pa.non_dominated(z3).all() and z3[:, 1].min() < -0.77


@pytest.mark.parametrize("name", ["srn", "bnh"])
def test_constrained_fronts_match_a_brute_force_scan(name):
    """The sampled true front dominates (IGD+ ≈ 0) the non-dominated set of 100 000 random
    feasible designs, and covers it (IGD+ the other way small against the front's range)."""
    P = multi.multi_benchmark(name)
    rng = np.random.default_rng(0)
    X = jnp.asarray(P.lower + (P.upper - P.lower) * rng.random((100_000, 2)))
    F = np.asarray(P.evaluate(X)[0])
    ok = np.asarray(P.violation(X)) == 0
    B = F[ok][pa.non_dominated(F[ok])]
    Z = multi.true_front(name, 5000)
    span = np.ptp(Z, axis=0).max()
    assert pa.igd_plus(Z, B) < 1e-4 * span  # nothing found beyond the true front
    assert pa.igd_plus(B, Z) < 3e-3 * span  # and the scan comes close to all of it
    ref = B.max(axis=0)
    assert pa.hypervolume(Z, ref) >= pa.hypervolume(B, ref)


def test_bad_problem_input():
    with pytest.raises(ValueError, match="unknown multi-objective benchmark"):
        multi.multi_benchmark("zdt9")
    with pytest.raises(ValueError, match="zdt1 has 2 objectives"):
        multi.multi_benchmark("zdt1", n_objectives=3)
    with pytest.raises(ValueError, match="srn has dim 2"):
        multi.multi_benchmark("srn", dim=5)
    with pytest.raises(ValueError, match="dim must be ≥ 3"):
        multi.multi_benchmark("dtlz2", dim=2)
