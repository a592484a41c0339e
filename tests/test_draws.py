"""The optimizers' uniform draws: mix32 (32-bit, counter-based, the default), threefry
("uniform") and SplitMix64 ("splitmix", x64 only)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt import optim
from designopt.numerics import statistics
from designopt.optim import draws
from designopt.problems import benchmark


def test_mix32_runs_without_x64_and_is_uniform():
    with jax.enable_x64(False):
        u = np.asarray(draws.uniform("mix32", jax.random.key(3), 0, (400_000,), jnp.float32))
        v = np.asarray(draws.uniform("mix32", jax.random.key(3), 1, (400_000,), jnp.float32))
        assert u.dtype == np.float32
    for r in (u, v):
        assert r.min() >= 0 and r.max() < 1
        assert abs(r.mean() - 0.5) < 0.002 and abs(r.var() - 1 / 12) < 0.001
        hist, _ = np.histogram(r, bins=64, range=(0, 1))
        chi2 = ((hist - len(r) / 64) ** 2 / (len(r) / 64)).sum()
        assert chi2 < 120  # 63 degrees of freedom: p ≈ 1e-5
    assert abs(np.corrcoef(u, v)[0, 1]) < 0.01  # two streams of one key
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.01  # neighbours in one stream
    # neighbouring steps (keys from successive splits) are unrelated too
    k1, k2 = jax.random.split(jax.random.key(5))
    a = np.asarray(draws.uniform("mix32", k1, 0, (100_000,), jnp.float32))
    b = np.asarray(draws.uniform("mix32", k2, 0, (100_000,), jnp.float32))
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.015


def test_mix32_bits_are_balanced_and_float64_matches_the_grid():
    c = jnp.arange(200_000, dtype=jnp.uint32)
    z = np.asarray(draws.mix32_bits(jnp.uint32(12345), jnp.uint32(678), c))
    bits = (z[:, None] >> np.arange(32, dtype=np.uint32)) & 1
    assert np.all(np.abs(bits.mean(0) - 0.5) < 0.006)
    u64 = np.asarray(draws.uniform("mix32", jax.random.key(1), 0, (1000,), jnp.float64))
    assert u64.dtype == np.float64 and np.all(u64 * 2**24 == np.round(u64 * 2**24))
    g = draws.mixgamma(jnp.asarray([0, 1, 0xFFFFFFFF], jnp.uint32))
    assert np.all(np.asarray(g) % 2 == 1)


def test_splitmix_reference_values_and_x64_requirement():
    # the reference implementation's first outputs from state 0 (Vigna, splitmix64.c)
    z = draws.splitmix64(jnp.asarray(0, jnp.uint64), 3)
    assert [int(v) for v in z] == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F]
    u = np.asarray(draws.uniform("splitmix", jax.random.key(3), 0, (200_000,), jnp.float64))
    assert 0 <= u.min() and u.max() < 1 and abs(u.mean() - 0.5) < 0.003
    with jax.enable_x64(False):
        with pytest.raises(ValueError, match="needs 64-bit integers"):
            optim.validate("p3", {"draws": "splitmix"})


def test_ptpso_runs_in_float32_without_x64():
    with jax.enable_x64(False):
        r = optim.run("ptpso", benchmark("rastrigin", 5), jax.random.key(0), 10, 30, 3,
                      dtype=jnp.float32)  # fmt: skip
        assert r.history.dtype == np.float32 and np.all(np.isfinite(r.best_f))


@pytest.mark.slow
@pytest.mark.parametrize("fname", ["rastrigin", "griewank"])
def test_mix32_and_threefry_give_the_same_ptpso_results(fname):
    """100 runs of PTPSO (defaults, 50 particles, 1000 iterations, D = 30, float32): the
    final values with mix32 and with threefry draws do not differ (Mann-Whitney)."""
    P = benchmark(fname, 30)
    kw = dict(n_particles=50, n_iters=1000, n_runs=100, dtype=jnp.float32)
    with jax.enable_x64(False):
        a = optim.run("ptpso", P, jax.random.key(0), **kw)
        b = optim.run("ptpso", P, jax.random.key(0), draws="uniform", **kw)
    _, p = statistics.mann_whitney_u(a.best_f, b.best_f)
    assert a.settings["draws"] == "mix32" and b.settings["draws"] == "uniform"
    assert p > 0.01, (fname, np.median(a.best_f), np.median(b.best_f), p)
