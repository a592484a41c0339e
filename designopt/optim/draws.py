"""Uniform random numbers for the optimizers' per-dimension draws (PSO's r1, r2, r3).

Three generators, picked by the static option ``draws``:

- ``"mix32"`` (default): counter-based and 32-bit only, so it runs in a float32 process
  without x64. It is SplitMix (Steele, Lea & Flood 2014) cut to 32 bits, with a stream per
  step: the step's JAX key gives two 32-bit words (k0, k1) — its raw key data, no extra
  threefry call — and number i of stream ``slot`` is
      z = h(k0 + c·γ),   c = slot·n + i,   γ = mixgamma(k1) (odd, ≥ 12 bit transitions),
  with h the "lowbias32" finaliser (C. Wellons, hash-prospector; lower bias than murmur3's
  fmix32), and u = (z >> 8)·2⁻²⁴ on the 24-bit grid (float32: the top 23 bits as the mantissa
  of a number in [1, 2), minus 1 — no integer-to-float conversion). As in SplitMix's
  ``split``, a different γ per step keeps the streams of different steps from being
  shifted copies of each other. About 9 integer operations per number against threefry's
  ~50 (20 rounds per two words).
- ``"uniform"``: ``jax.random.uniform`` (threefry2x32), the reference.
- ``"splitmix"``: SplitMix64 (uint64 arithmetic): needs ``jax_enable_x64``.

tests/test_draws.py checks mix32's moments, correlations and bit balance, and that 100 runs
of PTPSO on Rastrigin and Griewank D30 give the same final-value distribution as threefry
(Mann-Whitney).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

Array = jnp.ndarray
DRAWS = ("mix32", "uniform", "splitmix")
DEFAULT = "mix32"
_GOLDEN32 = 0x9E3779B9


def lowbias32(x: Array) -> Array:
    """Wellons' lowbias32 finaliser (a bijection of uint32)."""
    u = jnp.uint32
    x = x ^ (x >> u(16))
    x = x * u(0x7FEB352D)
    x = x ^ (x >> u(15))
    x = x * u(0x846CA68B)
    return x ^ (x >> u(16))


def mixgamma(k1: Array) -> Array:
    """An odd Weyl increment from a key word, with enough bit transitions (SplitMix's
    ``mixGamma`` rule, scaled to 32 bits: < 12 transitions → xor 0xAAAAAAAA)."""
    u = jnp.uint32
    g = lowbias32(k1 ^ u(_GOLDEN32)) | u(1)
    weak = jax.lax.population_count(g ^ (g >> u(1))) < u(12)
    return jnp.where(weak, g ^ u(0xAAAAAAAA), g)


def mix32_bits(k0: Array, k1: Array, counter: Array) -> Array:
    """The mix32 word for each uint32 ``counter`` under the key words (k0, k1)."""
    return lowbias32(k0 + counter * mixgamma(k1))


def _key_words(key: jax.Array) -> tuple[Array, Array]:
    kd = jax.random.key_data(key).reshape(-1).astype(jnp.uint32)
    return kd[0], kd[-1]


def splitmix64(seed: Array, n: int) -> Array:
    """The first n outputs (uint64) of SplitMix64 started at state ``seed``."""
    u64 = jnp.uint64
    z = seed.astype(u64) + (jnp.arange(n, dtype=u64) + u64(1)) * u64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> u64(30))) * u64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> u64(27))) * u64(0x94D049BB133111EB)
    return z ^ (z >> u64(31))


def check(kind: str) -> None:
    """ValueError for an unknown generator, or splitmix without x64."""
    if kind not in DRAWS:
        raise ValueError(f"unknown draws {kind!r}; one of {DRAWS}")
    if kind == "splitmix" and not jax.config.jax_enable_x64:
        raise ValueError(
            'draws "splitmix" needs 64-bit integers (jax_enable_x64); use "mix32" (32-bit)'
        )


def _unit16(h: Array, dtype) -> Array:
    """U[0, 1) on the 16-bit grid from the low 16 bits of h (uint32)."""
    h = h & jnp.uint32(0xFFFF)
    if jnp.dtype(dtype) == jnp.float32:
        one = jax.lax.bitcast_convert_type(
            (h << jnp.uint32(7)) | jnp.uint32(0x3F800000), jnp.float32
        )
        return one - 1.0
    return h.astype(jnp.int32).astype(dtype) * jnp.asarray(2.0**-16, dtype)


def uniform_pair(
    kind: str, key: jax.Array, slot: int, shape: tuple[int, ...], dtype
) -> tuple[Array, Array]:
    """Two U[0, 1) arrays of ``shape`` (PSO's r1 and r2). With mix32 both come from one
    32-bit word per element — its high and low halves, on the 16-bit grid (a resolution of
    1.5e-5 in a coefficient that scales the pull toward the bests) — half the hashing;
    the other generators give two independent streams ``slot`` and ``slot + 1``."""
    if kind != "mix32":
        return uniform(kind, key, slot, shape, dtype), uniform(kind, key, slot + 1, shape, dtype)
    n = 1
    for s in shape:
        n *= s
    k0, k1 = _key_words(key)
    z = mix32_bits(k0, k1, jnp.arange(n, dtype=jnp.uint32) + jnp.uint32(slot * n))
    return _unit16(z >> jnp.uint32(16), dtype).reshape(shape), _unit16(z, dtype).reshape(shape)


def uniform(kind: str, key: jax.Array, slot: int, shape: tuple[int, ...], dtype) -> Array:
    """U[0, 1) array of ``shape`` from stream ``slot`` of the step key ``key``.

    Different slots of one key are independent streams (mix32: disjoint counter ranges;
    threefry/splitmix: ``fold_in(key, slot)``).
    """
    n = 1
    for s in shape:
        n *= s
    if kind == "mix32":
        k0, k1 = _key_words(key)
        c = jnp.arange(n, dtype=jnp.uint32) + jnp.uint32(slot * n)
        z = mix32_bits(k0, k1, c)
        if jnp.dtype(dtype) == jnp.float32:  # 1.m × 2⁰ from the top 23 bits, minus 1
            one = jax.lax.bitcast_convert_type(
                (z >> jnp.uint32(9)) | jnp.uint32(0x3F800000), jnp.float32
            )
            return (one - 1.0).reshape(shape)
        u = (z >> jnp.uint32(8)).astype(jnp.int32).astype(dtype) * jnp.asarray(2.0**-24, dtype)
        return u.reshape(shape)
    k = jax.random.fold_in(key, slot)
    if kind == "uniform":
        return jax.random.uniform(k, shape, dtype)
    if kind == "splitmix":
        check(kind)
        u64 = jnp.uint64
        z = splitmix64(jax.random.bits(k, (), u64), n)
        return ((z >> u64(40)).astype(dtype) * jnp.asarray(2.0**-24, dtype)).reshape(shape)
    raise ValueError(f"unknown draws {kind!r}; one of {DRAWS}")
