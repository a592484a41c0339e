"""CMA-ES entry: known behaviour on Sphere and an ellipsoid, and a statistical comparison
with evosax's CMA_ES on the same functions (skipped when evosax is not installed)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt import optim
from designopt.numerics import statistics
from designopt.problems import benchmark
from designopt.problems.base import Problem

D, LAM = 8, 16


def _ellipsoid(p, X, key):
    w = 10.0 ** (6.0 * jnp.arange(X.shape[1]) / (X.shape[1] - 1))
    y = jnp.sum(w * (X - 1.0) ** 2, axis=1)
    return y, {"f": y}


ELLIPSOID = Problem(tuple(f"x{i}" for i in range(D)), np.full(D, -5.0), np.full(D, 5.0), _ellipsoid)
SPHERE = benchmark("sphere", D, shift=4)


def _iterations_to(history: np.ndarray, target: float) -> np.ndarray:
    hit = history <= target
    return np.where(hit.any(-1), hit.argmax(-1), history.shape[-1])


@pytest.mark.parametrize("P,budget", [(SPHERE, 250), (ELLIPSOID, 600)])
def test_cmaes_converges_to_1e8(P, budget):
    """Sphere (shifted optimum) and a 10⁶-conditioned ellipsoid in D = 8, λ = 16: every run
    reaches 1e-8 within the budget (Hansen's CMA-ES needs ~ 2e3 and ~ 6e3 evaluations)."""
    r = optim.run("cmaes", P, jax.random.key(0), LAM, budget, 10)
    assert np.all(r.best_f < 1e-8)
    np.testing.assert_allclose(r.best_x, np.broadcast_to(P.info.get("optimum", 1.0), r.best_x.shape),
                               atol=1e-3)  # fmt: skip


def _evosax_iterations(P, budget, n_runs, sigma0, target):
    from evosax.algorithms import CMA_ES

    fn = jax.jit(lambda X: P.fn(P.params, X, None)[0])
    lo, hi = jnp.asarray(P.lower), jnp.asarray(P.upper)
    es = CMA_ES(population_size=LAM, solution=jnp.zeros(D))
    params = es.default_params.replace(std_init=jnp.asarray(sigma0 * float(hi[0] - lo[0])))

    def one(key):
        k0, k1 = jax.random.split(key)
        mean = lo + (hi - lo) * jax.random.uniform(k0, (D,))
        state = es.init(k1, mean, params)

        def body(st, k):
            x, st = es.ask(k, st, params)
            x = jnp.clip(x, lo, hi)
            st, _ = es.tell(k, x, fn(x), st, params)
            return st, st.best_fitness

        _, h = jax.lax.scan(body, state, jax.random.split(key, budget))
        return h

    h = np.asarray(jax.jit(jax.vmap(one))(jax.random.split(jax.random.key(7), n_runs)))
    return _iterations_to(h, target), h[:, -1]


@pytest.mark.parametrize("P,budget", [(SPHERE, 250), (ELLIPSOID, 600)])
def test_cmaes_matches_evosax(P, budget):
    """Iterations to reach 1e-8 over 20 runs: same distribution as evosax's CMA_ES (same λ,
    σ0, initial-mean distribution; Mann-Whitney p > 0.01, medians within 25 %)."""
    pytest.importorskip("evosax")
    n = 20
    ev_it, _ = _evosax_iterations(P, budget, n, 0.3, 1e-8)
    r = optim.run("cmaes", P, jax.random.key(3), LAM, budget, n)
    ours = _iterations_to(r.history, 1e-8)
    _, p = statistics.mann_whitney_u(ours, ev_it)
    assert p > 0.01, (np.median(ours), np.median(ev_it))
    assert abs(np.median(ours) / np.median(ev_it) - 1) < 0.25
