"""The PSO family of seed 000 (eq. 44-50) as one pure, vmappable update.

State and Params are pytrees of arrays (evosax-style split): Params can be batched to
vmap over a grid of settings. The seven variants p1..p7 (SPEC §3.3, seed 000 Table 3,
reconstructed from its references [32]-[37]) differ only in their inertia rule, the
constriction factor and PTPSO's penalty term; ``VARIANTS`` says which and every default.

Update (eq. 44-45, per-dimension r1, r2 ~ U(0,1)):
    v ← χ·(w·v + c1 r1 (p − x) + c2 r2 (g − x)) [+ PTPSO penalty];  v ← clip(v, ±v_max);  x ← x + v
PTPSO penalty (eq. 46-49): d_i = ‖x_i − g‖, ρ = #{d_i < γ d_max}/M, d_max = box diagonal,
p_c = (a^{ρ−ρc} − a^{−ρc})/(1 − a^{−ρc}), term = p_c (1 − γ) v_max/√D · r3, r3 ~ U(0,1)
(seed; one-sided) or U(−1,1) (``symmetric_r3``). It is added after the constriction.
NaN fitness counts as +inf.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

Array = jnp.ndarray
INERTIA_RULES = ("constant", "nonlinear", "linear", "adaptive", "random")
BOUNDS = ("clip", "reflect", "reinit")
DRAWS = ("uniform", "splitmix")  # how r1, r2, r3 are drawn (see _splitmix_pair)


class Params(NamedTuple):
    w: Array  # constant inertia (p1, p2, p3)
    w_start: Array  # linear rule start (p5), nonlinear w0 (p4), adaptive w_ini (p6)
    w_end: Array  # linear rule end (p5)
    u: Array  # nonlinear decay base (p4): w_t = w0 · u^(−t)
    alpha: Array  # adaptive (p6): weight of evolution speed
    beta: Array  # adaptive (p6): weight of aggregation degree
    c1: Array
    c2: Array
    chi: Array  # constriction factor (1 = none)
    vmax_frac: Array  # v_max = vmax_frac · (upper − lower)
    penalty: Array  # 1 = PTPSO penalty on, 0 = off
    gamma: Array
    a: Array
    rho_c: Array
    symmetric_r3: Array  # 1 = r3 ~ U(−1, 1)
    rule: Array  # int32 index into INERTIA_RULES (an array, so one kernel serves all variants)


class State(NamedTuple):
    x: Array  # (M, D)
    v: Array
    pbest_x: Array
    pbest_f: Array  # (M,)
    prev_pbest_f: Array  # (M,) for the adaptive rule
    gbest_x: Array  # (D,)
    gbest_f: Array  # ()
    f: Array  # (M,) current fitness
    t: Array  # iteration counter
    key: jax.Array


def splitmix64(seed: Array, n: int) -> Array:
    """The first n outputs (uint64) of SplitMix64 started at state ``seed``."""
    u64 = jnp.uint64
    z = seed.astype(u64) + (jnp.arange(n, dtype=u64) + u64(1)) * u64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> u64(30))) * u64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> u64(27))) * u64(0x94D049BB133111EB)
    return z ^ (z >> u64(31))


def _splitmix_pair(key: jax.Array, shape: tuple[int, ...], dt) -> tuple[Array, Array]:
    """Two U[0, 1) arrays on the 2^-24 grid from SplitMix64 (``draws="splitmix"``).

    One 64-bit seed per call comes from the JAX key (threefry); the (M, D) array is the
    SplitMix64 sequence (Steele, Lea & Flood 2014; passes BigCrush) counted from that
    seed: z = seed + (i + 1)·0x9E3779B97F4A7C15, then its mix64 finaliser. Bits 40-63 give
    r1 and bits 8-31 give r2. Threefry dominates a PSO step on CPU (about 85 % of p2's time on
    Rastrigin-30); this is about 8× cheaper per number. The default stays ``"uniform"``
    (``jax.random.uniform``); tests compare both by Mann-Whitney. Needs jax x64 (uint64),
    which ``import designopt`` enables.
    """
    if not jax.config.jax_enable_x64:
        raise RuntimeError('draws="splitmix" needs jax_enable_x64 (uint64 arithmetic)')
    u64 = jnp.uint64
    n = 1
    for s in shape:
        n *= s
    z = splitmix64(jax.random.bits(key, (), u64), n)
    scale = jnp.asarray(2.0**-24, dt)
    r1 = (z >> u64(40)).astype(dt) * scale
    r2 = ((z >> u64(8)) & u64(0xFFFFFF)).astype(dt) * scale
    return r1.reshape(shape), r2.reshape(shape)


def constriction(phi: float) -> float:
    """Clerc-Kennedy χ = 2/|2 − φ − sqrt(φ² − 4φ)| for φ = c1 + c2 > 4 (0.72984 at φ = 4.1)."""
    return 2.0 / abs(2.0 - phi - (phi * phi - 4.0 * phi) ** 0.5)


def _clean(f: Array) -> Array:
    return jnp.where(jnp.isnan(f), jnp.inf, f)


def init(
    key: jax.Array, evaluate: Callable, lower: Array, upper: Array, n_particles: int, p: Params
) -> State:
    """Uniform positions in the box, velocities uniform in ±v_max, first evaluation."""
    kx, kv, ke, key = jax.random.split(key, 4)
    D = lower.shape[0]
    x = lower + (upper - lower) * jax.random.uniform(kx, (n_particles, D), lower.dtype)
    vmax = p.vmax_frac * (upper - lower)
    v = vmax * jax.random.uniform(kv, (n_particles, D), lower.dtype, -1.0, 1.0)
    f = _clean(evaluate(x, ke))
    i = jnp.argmin(f)
    return State(x, v, x, f, f, x[i], f[i], f, jnp.asarray(0, jnp.int32), key)


def inertia(s: State, p: Params, n_iters: int, key: jax.Array) -> Array:
    """Per-particle inertia (M, 1) at iteration s.t for the rule p.rule (lax.switch)."""
    M = s.x.shape[0]
    dt = s.x.dtype
    t = s.t.astype(dt)

    def constant():
        return jnp.broadcast_to(p.w, (M,)).astype(dt)

    def nonlinear():  # Jiao, Lian & Gu 2008 [33]
        return jnp.broadcast_to(p.w_start * p.u ** (-t), (M,)).astype(dt)

    def linear():  # Shi & Eberhart 1999 [34]
        w = p.w_start - (p.w_start - p.w_end) * t / max(n_iters, 1)
        return jnp.broadcast_to(w, (M,)).astype(dt)

    def adaptive():  # Yang, Yuan, Yuan & Mao 2007 [36]
        a_, b_ = jnp.abs(s.prev_pbest_f), jnp.abs(s.pbest_f)
        hi = jnp.maximum(a_, b_)
        h = jnp.where(hi > 0, jnp.minimum(a_, b_) / jnp.where(hi > 0, hi, 1.0), 1.0)
        fbest = jnp.abs(s.gbest_f)
        fmean = jnp.abs(jnp.mean(jnp.where(jnp.isfinite(s.f), s.f, s.gbest_f)))
        top = jnp.maximum(fbest, fmean)
        agg = jnp.where(top > 0, jnp.minimum(fbest, fmean) / jnp.where(top > 0, top, 1.0), 1.0)
        return (p.w_start - p.alpha * (1.0 - h) + p.beta * agg).astype(dt)

    def random():  # Eberhart & Shi 2001 [37]
        return 0.5 + 0.5 * jax.random.uniform(key, (M,), dt)

    branches = {"constant": constant, "nonlinear": nonlinear, "linear": linear,
                "adaptive": adaptive, "random": random}  # fmt: skip
    w = jax.lax.switch(p.rule, [branches[r] for r in INERTIA_RULES])
    return w[:, None]


def rule_index(rule: str) -> int:
    if rule not in INERTIA_RULES:
        raise ValueError(f"unknown inertia rule {rule!r}; one of {INERTIA_RULES}")
    return INERTIA_RULES.index(rule)


def penalty_coefficient(rho: Array, a: Array, rho_c: Array) -> Array:
    """p_c of seed 000 eq. (48): 0 at ρ = 0, 1 at ρ = ρc, growing fast beyond."""
    return (a ** (rho - rho_c) - a ** (-rho_c)) / (1.0 - a ** (-rho_c))


def step(
    s: State,
    p: Params,
    evaluate: Callable,
    lower: Array,
    upper: Array,
    bounds: str,
    n_iters: int,
    draws: str = "uniform",
) -> State:
    """One iteration of eq. (44)-(50) for the whole swarm."""
    key, k1, k2, k3, kw, kb, ke = jax.random.split(s.key, 7)
    M, D = s.x.shape
    dt = s.x.dtype
    if draws == "uniform":
        r1 = jax.random.uniform(k1, (M, D), dt)
        r2 = jax.random.uniform(k2, (M, D), dt)
    elif draws == "splitmix":
        r1, r2 = _splitmix_pair(k1, (M, D), dt)
    else:
        raise ValueError(f"unknown draws {draws!r}; one of {DRAWS}")
    w = inertia(s, p, n_iters, kw)
    v = p.chi * (w * s.v + p.c1 * r1 * (s.pbest_x - s.x) + p.c2 * r2 * (s.gbest_x - s.x))
    vmax = p.vmax_frac * (upper - lower)

    # PTPSO penalty, eq. (46)-(49); computed only when the penalty is on (a real branch
    # unless the settings are vmapped)
    def kick():
        d = jnp.sqrt(jnp.sum((s.x - s.gbest_x) ** 2, axis=1))
        dmax = jnp.sqrt(jnp.sum((upper - lower) ** 2))
        rho = jnp.mean((d < p.gamma * dmax).astype(dt))
        pc = penalty_coefficient(rho, p.a, p.rho_c)
        u3 = (
            jax.random.uniform(k3, (M, D), dt)
            if draws == "uniform"
            else _splitmix_pair(k3, (M, D), dt)[0]
        )
        r3 = jnp.where(p.symmetric_r3 > 0, 2.0 * u3 - 1.0, u3)
        return (p.penalty * pc * (1.0 - p.gamma) * vmax / jnp.sqrt(D) * r3).astype(dt)

    v = v + jax.lax.cond(p.penalty != 0, kick, lambda: jnp.zeros((M, D), dt))
    v = jnp.clip(v, -vmax, vmax)
    x = s.x + v
    if bounds == "clip":
        out = (x < lower) | (x > upper)
        x = jnp.clip(x, lower, upper)
        v = jnp.where(out, 0.0, v)
    elif bounds == "reflect":
        span = upper - lower
        y = jnp.mod(x - lower, 2 * span)
        refl = y > span
        x = lower + jnp.where(refl, 2 * span - y, y)
        v = jnp.where((s.x + v < lower) | (s.x + v > upper), -v, v)
    elif bounds == "reinit":
        out = (x < lower) | (x > upper)
        fresh = lower + (upper - lower) * jax.random.uniform(kb, (M, D), dt)
        x = jnp.where(out, fresh, x)
    else:
        raise ValueError(f"unknown bounds handling {bounds!r}; one of {BOUNDS}")
    f = _clean(evaluate(x, ke))
    better = f < s.pbest_f
    pbest_x = jnp.where(better[:, None], x, s.pbest_x)
    pbest_f = jnp.where(better, f, s.pbest_f)
    i = jnp.argmin(pbest_f)
    improved = pbest_f[i] < s.gbest_f
    gbest_x = jnp.where(improved, pbest_x[i], s.gbest_x)
    gbest_f = jnp.where(improved, pbest_f[i], s.gbest_f)
    return State(x, v, pbest_x, pbest_f, s.pbest_f, gbest_x, gbest_f, f, s.t + 1, key)
