"""PSO family and test functions: values, convergence, determinism, PTPSO identities."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt import optim
from designopt.problems import benchmark
from designopt.problems import benchmarks as bf


def test_functions_at_optimum_and_hand_computed_points():
    for name, (f, _, xo) in bf.FUNCTIONS.items():
        x = jnp.full((1, 7), xo)
        assert abs(float(f(x)[0])) < 1e-9, name
    one = jnp.ones((1, 2))
    assert float(bf.sphere(one)[0]) == pytest.approx(2.0)
    assert float(bf.rastrigin(one)[0]) == pytest.approx(2.0)  # 20 + 2·(1 − 10)
    assert float(bf.griewank(one)[0]) == pytest.approx(
        1 + 2 / 4000 - np.cos(1) * np.cos(1 / np.sqrt(2))
    )
    e = np.e
    assert float(bf.ackley(one)[0]) == pytest.approx(-20 * np.exp(-0.2) - e + 20 + e)
    assert float(bf.rosenbrock(jnp.zeros((1, 2)))[0]) == pytest.approx(1.0)


def test_shifted_optimum_moves_with_the_shift():
    for name in bf.FUNCTIONS:
        P = benchmark(name, dim=5, shift=3)
        xo = P.info["optimum"]
        assert np.all(xo >= P.lower) and np.all(xo <= P.upper)
        f0, _ = P.evaluate(jnp.asarray(xo)[None])
        assert abs(float(f0[0])) < 1e-9
        assert np.abs(P.info["shift"]).max() > 0
        fc, _ = P.evaluate(jnp.asarray(np.full(5, bf.FUNCTIONS[name][2]))[None])
        assert float(fc[0]) > 1e-3  # the unshifted optimum is no longer optimal


def test_constriction_factor():
    assert optim.constriction(4.1) == pytest.approx(0.72984, abs=5e-6)


def test_penalty_coefficient_eq48():
    a, rc = jnp.asarray(10.0), jnp.asarray(0.9)
    assert float(optim.penalty_coefficient(jnp.asarray(0.0), a, rc)) == pytest.approx(
        0.0, abs=1e-15
    )
    assert float(optim.penalty_coefficient(rc, a, rc)) == pytest.approx(1.0)


@pytest.mark.parametrize("name", ["p1", "p2", "p4", "p5", "p6", "p7"])
def test_variants_solve_sphere_10(name):
    r = optim.run(name, benchmark("sphere", 10), jax.random.key(0), 50, 1000, 10)
    assert r.best_f.mean() < 1e-6


def test_ptpso_on_sphere_reaches_its_penalty_floor():
    """Eq. (47) counts the best particle itself, so ρ ≥ 1/M and p_c > 0: a permanent small
    one-sided kick sets a floor (docs/optimizers.md). Disabled penalty = p2 reaches 1e-40."""
    r = optim.run("ptpso", benchmark("sphere", 10), jax.random.key(0), 50, 1000, 10)
    assert r.best_f.mean() < 1e-4
    assert np.all(np.diff(r.history, axis=1) <= 0)


def test_ptpso_without_penalty_is_p2_exactly():
    P = benchmark("rastrigin", 10)
    a = optim.run("p3", P, jax.random.key(3), 20, 200, 4, penalty=0.0)
    b = optim.run("p2", P, jax.random.key(3), 20, 200, 4)
    np.testing.assert_array_equal(a.history, b.history)


def test_single_run_equals_same_run_inside_batch():
    from designopt.optim import registry, runner

    P = benchmark("ackley", 10)
    key = jax.random.key(11)
    batch = optim.run("p5", P, key, 30, 100, 5)
    keys = jax.random.split(key, 5)
    # run 3 alone, with the same key the batch gave it
    opt = registry.build("p5", 30, 100)
    par = optim.make_params("p5")
    lo, hi = jnp.asarray(P.lower), jnp.asarray(P.upper)
    st = dict(opt=opt, fn=P.fn, cons=None)
    alone = runner._init(keys[3:4], par, P.params, lo, hi, **st)
    _, recs = runner._advance(alone, par, P.params, lo, hi, length=100, **st)
    _, f, _ = runner._unpack(np.asarray(recs), 2)  # x, f, v of every iteration
    np.testing.assert_array_equal(np.asarray(f)[0], batch.history[3, 1:])
    chunked = optim.run("p5", P, key, 30, 100, 5, chunk_iters=7)
    np.testing.assert_array_equal(chunked.history, batch.history)


def test_convergence_iteration_definition():
    h = np.array([[5.0, 4.0, 4.0, 3.0, 3.0 - 5e-7, 3.0 - 6e-7]])
    assert optim.convergence_iteration(h)[0] == 3
    assert optim.convergence_iteration(np.array([[1.0, 1.0, 1.0]]))[0] == 0


def test_p2_matches_numpy_reference_by_mann_whitney():
    """p2 on Rastrigin D=10 over 50 runs vs a straightforward numpy implementation."""
    from scipy.stats import mannwhitneyu

    D, M, T, R = 10, 30, 300, 50
    chi = optim.constriction(4.1)
    rng = np.random.default_rng(0)
    lo, hi = -5.12, 5.12
    vmax = 0.2 * (hi - lo)

    def f(x):
        return 10 * D + np.sum(x * x - 10 * np.cos(2 * np.pi * x), -1)

    ref = []
    for _ in range(R):
        x = rng.uniform(lo, hi, (M, D))
        v = rng.uniform(-vmax, vmax, (M, D))
        fx = f(x)
        pb, pf = x.copy(), fx.copy()
        g = pb[np.argmin(pf)].copy()
        for _ in range(T):
            v = chi * (
                v + 2.05 * rng.random((M, D)) * (pb - x) + 2.05 * rng.random((M, D)) * (g - x)
            )
            v = np.clip(v, -vmax, vmax)
            x = x + v
            out = (x < lo) | (x > hi)
            x = np.clip(x, lo, hi)
            v[out] = 0.0
            fx = f(x)
            b = fx < pf
            pb[b], pf[b] = x[b], fx[b]
            g = pb[np.argmin(pf)].copy()
        ref.append(pf.min())
    r = optim.run("p2", benchmark("rastrigin", D), jax.random.key(0), M, T, R)
    assert mannwhitneyu(r.best_f, np.array(ref)).pvalue > 0.01
    u = optim.run("p2", benchmark("rastrigin", D), jax.random.key(0), M, T, R, draws="uniform")
    assert mannwhitneyu(u.best_f, np.array(ref)).pvalue > 0.01


def test_bad_names_and_settings():
    with pytest.raises(ValueError, match="unknown optimizer 'p9'; known: .*cmaes"):
        optim.validate("p9", {})
    with pytest.raises(
        ValueError, match="unknown setting 'inertia' for optimizer 'p1'; allowed: w"
    ):
        optim.validate("p1", {"inertia": 3})
    with pytest.raises(ValueError, match="unknown setting 'gamma' for optimizer 'cmaes'"):
        optim.validate("cmaes", {"gamma": 1e-3})
    with pytest.raises(ValueError, match="unknown setting 'rule'"):
        optim.validate("p1", {"rule": 2})  # set by the variant, not by the user
    with pytest.raises(ValueError, match="draws.*one of mix32"):
        optim.validate("p3", {"draws": "mersenne"})
    with pytest.raises(ValueError, match="must be a number"):
        optim.validate("p3", {"gamma": "small"})
    with pytest.raises(ValueError, match="population size .* 1 .* needs ≥ 2"):
        optim.validate("ptpso", {}, n_particles=1)
    with pytest.raises(ValueError, match="needs ≥ 4"):
        optim.validate("cmaes", {}, n_particles=3)
    with pytest.raises(ValueError, match="population size"):
        optim.run("p1", benchmark("sphere", 2), jax.random.key(0), 1, 5, 2)
    with pytest.raises(ValueError, match="unknown benchmark"):
        benchmark("styblinski")
    for msg in ("p9", "inertia"):
        with pytest.raises(ValueError) as e:
            optim.validate(msg if msg == "p9" else "p1", {} if msg == "p9" else {msg: 1})
        assert "\n" not in str(e.value)
    optim.validate("cmaes", {"sigma0": 0.2, "active": 0}, n_particles=8)
    optim.validate("p3", {"gamma": 1e-5, "draws": "uniform"}, n_particles=2)


def test_registry_names_and_settings():
    assert {"p1", "p7", "ptpso", "cmaes"} <= set(optim.names())
    assert set(optim.OPTIMIZERS) == set(optim.names())
    assert "gamma" in optim.setting_names("ptpso") and "rule" not in optim.setting_names("p1")
    assert "draws" not in optim.setting_names("p3")  # a string option, not vmappable
    assert optim.option_names("p3")["draws"][0] == "mix32"
    assert optim.setting_names("cmaes") == ("sigma0", "c1_scale", "cmu_scale", "cs_scale",
                                             "cc_scale", "active")  # fmt: skip


def test_run_batch_members_equal_single_runs():
    P = benchmark("rastrigin", 6)
    key = jax.random.key(4)
    members = [{"gamma": 1e-7}, {"gamma": 1e-2, "rho_c": 0.5}, {"penalty": 0.0}]
    batch = optim.run_batch("p3", P, key, members, 12, 60, 3)
    assert batch.history.shape == (3, 3, 61)
    for i, m in enumerate(members):
        one = optim.run("p3", P, key, 12, 60, 3, **m)
        np.testing.assert_allclose(batch.history[i], one.history, rtol=1e-12)


def test_checkpoint_resume_gives_the_uninterrupted_result():
    P = benchmark("griewank", 8)
    key = jax.random.key(9)
    full = optim.run("p6", P, key, 15, 40, 3, chunk_iters=7)
    saved = []
    optim.run("p6", P, key, 15, 40, 3, chunk_iters=7, checkpoint=saved.append)
    assert [c.done for c in saved] == [7, 14, 21, 28, 35]
    resumed = optim.run("p6", P, key, 15, 40, 3, chunk_iters=7, resume=saved[2])
    np.testing.assert_array_equal(resumed.history, full.history)
    np.testing.assert_array_equal(resumed.history_x, full.history_x)


def test_refine_reaches_known_minimisers_and_respects_the_box():
    from designopt.optim.polish import refine
    from designopt.problems.base import Problem

    P = benchmark("sphere", 4, shift=2)  # interior optimum at the seeded shift
    x0 = np.array([[50.0, -40.0, 10.0, 30.0]])
    r = refine(P, x0, steps=400, learning_rate=0.01)
    np.testing.assert_allclose(r.x[0], P.info["optimum"], atol=1e-2)
    assert r.gain[0] == pytest.approx(r.f0[0] - r.f[0]) and r.f[0] < 1e-3

    # optimum (5, −5) outside the box [0, 3] × [−1, 1]: the projection lands on the corner
    def fn(p, X, key):
        y = jnp.sum((X - jnp.array([5.0, -5.0])) ** 2, axis=1)
        return y, {"f": y}

    Q = Problem(("u", "v"), np.array([0.0, -1.0]), np.array([3.0, 1.0]), fn)
    r = refine(Q, np.array([[1.0, 0.5], [2.5, -0.2]]), steps=300, learning_rate=0.02)
    np.testing.assert_allclose(r.x, [[3.0, -1.0], [3.0, -1.0]], atol=1e-9)
    np.testing.assert_allclose(r.f, [20.0, 20.0], atol=1e-9)


def test_row_sum_max_equals_numpy_and_ptpso_distances():
    """pso.row_sum_max (the reduction PTPSO's distances use, eq. 46) against numpy."""
    from designopt.optim.pso import row_sum_max

    rng = np.random.default_rng(0)
    e = rng.normal(size=(7, 13)).astype(np.float32) ** 2
    total, top = row_sum_max(jnp.asarray(e))
    np.testing.assert_allclose(np.asarray(total), e.sum(1), rtol=2e-6)
    np.testing.assert_array_equal(np.asarray(top), e.max(1))
    x = rng.uniform(-5, 5, size=(50, 30))
    g = x[3]
    d2, _ = jax.jit(row_sum_max)(jnp.asarray((x - g) ** 2))
    d = np.sqrt(np.asarray(d2))
    np.testing.assert_allclose(d, np.linalg.norm(x - g, axis=1), rtol=1e-12, atol=0)
    assert d[3] == 0.0
