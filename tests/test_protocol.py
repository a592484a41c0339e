"""Contract tests every registry entry must pass (the optimizer protocol, docs/optimizers.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt import optim
from designopt.optim import registry
from designopt.problems import benchmark
from designopt.problems import constrained as cp
from designopt.problems.base import Problem

ENTRIES = sorted({e.name for e in optim.OPTIMIZERS.values()})


def _corner_problem():
    """f = Σ x on [0, 1] × [−2, 3] × [5, 6]: the optimum is the lower corner, so every
    optimizer pushes against the box."""

    def fn(p, X, key):
        y = jnp.sum(X, axis=1)
        return y, {"f": y}

    return Problem(("a", "b", "c"), np.array([0.0, -2.0, 5.0]), np.array([1.0, 3.0, 6.0]), fn)


def test_registry_covers_the_pso_family_and_cmaes():
    assert ENTRIES == ["cmaes", "p1", "p2", "p3", "p4", "p5", "p6", "p7"]


BOX_CASES = [(n, "clip") for n in ENTRIES] + [(n, b) for n in ("p3", "p6", "cmaes")
                                               for b in ("reflect", "reinit")]  # fmt: skip


@pytest.mark.parametrize("name,bounds", BOX_CASES)
def test_designs_stay_in_the_box(name, bounds):
    P = _corner_problem()
    r = optim.run(name, P, jax.random.key(1), 8, 25, 3, bounds=bounds)
    assert np.all(r.history_x >= P.lower) and np.all(r.history_x <= P.upper)
    assert np.all(np.diff(r.history, axis=-1) <= 0)  # best so far never worsens
    assert r.settings["bounds"] == bounds and r.settings["optimizer"] == name


@pytest.mark.parametrize("name", ENTRIES)
def test_resume_is_bit_exact_and_seeds_reproduce(name):
    P = benchmark("griewank", 4)
    key = jax.random.key(9)
    full = optim.run(name, P, key, 8, 12, 3, chunk_iters=4)
    saved = []
    again = optim.run(name, P, key, 8, 12, 3, chunk_iters=4, checkpoint=saved.append)
    assert [c.done for c in saved] == [4, 8]
    for c in saved:
        assert all(isinstance(v, np.ndarray) for v in c.state.values())
    resumed = optim.run(name, P, key, 8, 12, 3, chunk_iters=4, resume=saved[0])
    for a, b, c in ((full, again, resumed),):
        for field in ("history", "history_x", "history_v"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
            np.testing.assert_array_equal(getattr(a, field), getattr(c, field))
    other = optim.run(name, P, jax.random.key(10), 8, 12, 3, chunk_iters=4)
    assert not np.array_equal(other.history, full.history)


@pytest.mark.parametrize("name", ENTRIES)
def test_batch_of_settings_equals_single_runs(name):
    P = benchmark("rastrigin", 3)
    key = jax.random.key(4)
    s = optim.setting_names(name)[0]
    e = registry.resolve(name)
    base = float(e.preset.get(s, e.cls.Params()._asdict()[s]))
    members = [{}, {s: 0.8 * base}]
    batch = optim.run_batch(name, P, key, members, 8, 20, 3)
    assert batch.history.shape == (2, 3, 21)
    for i, m in enumerate(members):
        one = optim.run(name, P, key, 8, 20, 3, **m)
        np.testing.assert_allclose(batch.history[i], one.history, rtol=1e-9, atol=1e-12)
    assert batch.settings[s] == pytest.approx([base, 0.8 * base])


@pytest.mark.parametrize("name", ENTRIES)
def test_constraints_are_honoured(name):
    # min Σx² s.t. Σx ≥ 1 in D = 3: optimum f* = 1/3 on the constraint
    P = cp.sphere_linear(3)
    r = optim.run(name, P, jax.random.key(2), 30, 200, 4)
    hv, hf = r.history_v, r.history
    assert np.all(np.diff(hv, axis=-1) <= 0)  # violation of the best never grows
    feas = hv == 0
    assert np.all(feas[:, 1:] >= feas[:, :-1])  # once feasible, the best stays feasible
    both = feas[:, 1:] & feas[:, :-1]
    assert np.all(np.diff(hf, axis=-1)[both] <= 0)  # …and only improves
    assert np.all(r.best_v == 0)
    assert np.all(np.asarray(P.violation(r.best_x)) == 0)
    assert np.all(r.best_f >= 1 / 3 - 1e-12) and np.median(r.best_f) < 1 / 3 + 2e-3


@pytest.mark.parametrize("name", ["p3", "cmaes"])
def test_cec2006_g08_known_optimum(name):
    """g08: f* = −0.0958250414 in a small feasible region of a multimodal objective."""
    G = cp.g08()
    r = optim.run(name, G, jax.random.key(3), 30, 200, 4)
    assert np.all(r.best_v == 0)
    np.testing.assert_allclose(np.median(r.best_f), G.info["f_opt"], rtol=1e-4)


def test_cmaes_on_g06_reaches_the_known_optimum():
    """g06: both constraints active, a feasible region of 0.0066 % of the box."""
    G = cp.g06()
    r = optim.run("cmaes", G, jax.random.key(0), 30, 300, 6)
    assert np.all(r.best_v == 0)
    np.testing.assert_allclose(np.median(r.best_f), G.info["f_opt"], rtol=1e-6)


def test_violation_helpers():
    P = cp.g06()
    X = jnp.asarray([P.info["optimum"], [50.0, 50.0]])
    v = np.asarray(P.violation(X))
    assert v[0] == 0 and v[1] > 0
    assert np.all(np.asarray(benchmark("sphere", 2).violation(jnp.ones((3, 2)))) == 0)


def test_argbest_is_the_two_pass_rule_in_one_reduction():
    """``argbest`` (one reduction over (v, f, index)) gives the index of the rule it
    replaced, ties, ±0, ±inf and NaN included: the least violation (a NaN one first), then
    the least f (a NaN one first), then the first index."""
    from designopt.optim.protocol import argbest

    def two_pass(f, v):
        vmin = jnp.min(v)
        i = jnp.argmin(jnp.where(v == vmin, f, jnp.inf))
        return jnp.where(v[i] == vmin, i, jnp.argmin(v))

    rng = np.random.default_rng(0)
    vs = np.array([0.0, -0.0, 1.0, 2.0, np.inf, np.nan, 0.5])
    fs = np.array([0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan, 3.0])
    new, old = jax.jit(jax.vmap(argbest)), jax.jit(jax.vmap(two_pass))
    for n in (1, 2, 5, 50):
        v = rng.choice(vs, (3000, n))
        for f in (rng.choice(fs, (3000, n)), rng.normal(size=(3000, n))):
            for dt in (jnp.float32, jnp.float64):
                a, b = jnp.asarray(f, dt), jnp.asarray(v, dt)
                np.testing.assert_array_equal(new(a, b), old(a, b))
