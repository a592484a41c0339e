"""The quadratic-penalty option (optimizer.constraints.method = penalty)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt import optim
from designopt.problems import penalty
from designopt.problems.constrained import g06, sphere_linear


def test_penalised_value_matches_numpy():
    p = g06()
    q = penalty.quadratic(p, 250.0)
    X = np.random.default_rng(0).uniform(p.lower, p.upper, (64, 2))
    f, aux = q.evaluate(jnp.asarray(X))
    x1, x2 = X[:, 0], X[:, 1]
    g = np.stack([-((x1 - 5) ** 2) - (x2 - 5) ** 2 + 100, (x1 - 6) ** 2 + (x2 - 5) ** 2 - 82.81], 1)
    ref = (x1 - 10) ** 3 + (x2 - 20) ** 3 + 250.0 * np.sum(np.maximum(g, 0) ** 2, 1)
    np.testing.assert_allclose(np.asarray(f), ref, rtol=1e-5)
    assert q.constraints is None and np.all(np.asarray(aux["penalty"]) >= 0)


def test_weight_is_an_array_not_a_trace_constant():
    p = sphere_linear(3)
    q1, q2 = penalty.quadratic(p, 10.0), penalty.quadratic(p, 1e4)
    X = jnp.full((2, 3), 0.1)  # Σx = 0.3: g = 0.7
    jf = jax.jit(q1.fn)
    f1 = jf(q1.params, X, jax.random.key(0))[0]
    f2 = jf(q2.params, X, jax.random.key(0))[0]
    np.testing.assert_allclose(np.asarray(f2 - f1), (1e4 - 10.0) * 0.49, rtol=1e-5)
    assert jf._cache_size() == 1


@pytest.mark.parametrize("weight", [1e2, 1e4])
def test_penalty_optimum_approaches_the_constrained_one(weight):
    """min Σx² s.t. Σx ≥ 1 (D = 5): with x_i = t the penalised objective is
    D·t² + μ(1 − D·t)², minimal at t = μ/(1 + μD), so Σx = μD/(1 + μD) < 1."""
    D = 5
    q = penalty.quadratic(sphere_linear(D), weight)
    res = optim.run("cmaes", q, jax.random.key(1), n_particles=16, n_iters=300, n_runs=2,
                    dtype=jnp.float64 if jax.config.jax_enable_x64 else jnp.float32)  # fmt: skip
    x = res.best_x[int(np.argmin(res.best_f))]
    np.testing.assert_allclose(x.sum(), weight * D / (1.0 + weight * D), rtol=2e-3)
