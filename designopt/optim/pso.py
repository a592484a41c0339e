"""The PSO family of seed 000 (eq. 44-50) as one optimizer entry: p1..p7 in one kernel.

The seven variants (SPEC §3.3, seed 000 Table 3, reconstructed from its references
[32]-[37]) differ only in their inertia rule, the constriction factor and PTPSO's penalty
term; the rule is an int32 field of ``Params`` (``lax.switch``), so one compiled kernel
serves every variant and any vmapped batch of settings. ``VARIANTS`` holds each variant's
preset over the class defaults.

Update (eq. 44-45, per-dimension r1, r2 ~ U(0,1)):
    v ← χ·(w·v + c1 r1 (p − x) + c2 r2 (g − x)) [+ PTPSO penalty];  v ← clip(v, ±v_max);  x ← x + v
PTPSO penalty (eq. 46-49): d_i = ‖x_i − g‖, ρ = #{d_i < γ d_max}/M, d_max = box diagonal,
p_c = (a^{ρ−ρc} − a^{−ρc})/(1 − a^{−ρc}), term = p_c (1 − γ) v_max/√D · r3, r3 ~ U(0,1)
(seed; one-sided) or U(−1,1) (``symmetric_r3``). It is added after the constriction.
Personal and global bests follow Deb's feasibility rules (protocol.better); NaN f = +inf.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from designopt.optim import draws as rng
from designopt.optim.protocol import Best, Optimizer, Task, apply_bounds, argbest, better

Array = jnp.ndarray
INERTIA_RULES = ("constant", "nonlinear", "linear", "adaptive", "random")


class Params(NamedTuple):
    w: float = 0.7  # constant inertia (p1, p2, p3)
    w_start: float = 0.9  # linear rule start (p5), nonlinear w0 (p4), adaptive w_ini (p6)
    w_end: float = 0.4  # linear rule end (p5)
    u: float = 1.0015  # nonlinear decay base (p4): w_t = w0 · u^(−t)
    alpha: float = 0.4  # adaptive (p6): weight of evolution speed
    beta: float = 0.2  # adaptive (p6): weight of aggregation degree
    c1: float = 1.5
    c2: float = 1.5
    chi: float = 1.0  # constriction factor (1 = none)
    vmax_frac: float = 0.2  # v_max = vmax_frac · (upper − lower)
    penalty: float = 0.0  # 1 = PTPSO penalty on, 0 = off
    gamma: float = 1e-7
    a: float = 10.0
    rho_c: float = 0.9
    symmetric_r3: float = 0.0  # 1 = r3 ~ U(−1, 1)
    rule: int = 0  # index into INERTIA_RULES (set by the variant, not a user setting)


class State(NamedTuple):
    x: Array  # (M, D)
    v: Array
    f: Array  # (M,) current fitness
    pbest_x: Array
    pbest_f: Array  # (M,)
    pbest_v: Array  # (M,) constraint violation of the personal best
    prev_pbest_f: Array  # (M,) for the adaptive rule
    gbest_x: Array  # (D,)
    gbest_f: Array  # ()
    gbest_v: Array  # ()
    t: Array  # iteration counter


def constriction(phi: float) -> float:
    """Clerc-Kennedy χ = 2/|2 − φ − sqrt(φ² − 4φ)| for φ = c1 + c2 > 4 (0.72984 at φ = 4.1)."""
    return 2.0 / abs(2.0 - phi - (phi * phi - 4.0 * phi) ** 0.5)


CHI_41 = constriction(4.1)  # 0.729843...


def rule_index(rule: str) -> int:
    if rule not in INERTIA_RULES:
        raise ValueError(f"unknown inertia rule {rule!r}; one of {INERTIA_RULES}")
    return INERTIA_RULES.index(rule)


def penalty_coefficient(rho: Array, a: Array, rho_c: Array) -> Array:
    """p_c of seed 000 eq. (48): 0 at ρ = 0, 1 at ρ = ρc, growing fast beyond."""
    return (a ** (rho - rho_c) - a ** (-rho_c)) / (1.0 - a ** (-rho_c))


def row_sum_max(e: Array) -> tuple[Array, Array]:
    """Σ and max over the last axis of a 2-D array, as one two-output reduction.

    With both outputs in use, XLA keeps it as its own loop reduction fused with the
    producer of ``e``; a plain sum goes to the CPU backend's YNNPACK reduction, which first
    materialised the broadcast global best as a full (M, D) array (PTPSO's distances)."""
    zero = jnp.zeros((), e.dtype)
    return jax.lax.reduce(
        (e, e), (zero, zero), lambda a, b: (a[0] + b[0], jnp.maximum(a[1], b[1])), (1,)
    )


# name: (preset over Params defaults, source)
VARIANTS: dict[str, tuple[dict[str, float], str]] = {
    "p1": (dict(w=0.7, c1=1.5, c2=1.5, rule=0), "basic PSO, seed 000 eq. (44)-(45)"),
    "p2": (dict(w=1.0, c1=2.05, c2=2.05, chi=CHI_41, rule=0),
           "constriction factor, Eberhart & Shi 2000 [32] (Clerc-Kennedy χ, φ = 4.1)"),
    "p3": (dict(w=1.0, c1=2.05, c2=2.05, chi=CHI_41, penalty=1.0, rule=0),
           "PTPSO = p2 + penalty term, seed 000 eq. (46)-(50)"),
    "p4": (dict(w_start=0.9, u=1.0015, c1=2.0, c2=2.0, rule=1),
           "nonlinear time-varying inertia w_t = w0·u^-t, Jiao et al. 2008 [33]"),
    "p5": (dict(w_start=0.9, w_end=0.4, c1=2.0, c2=2.0, rule=2),
           "linearly decreasing inertia 0.9 → 0.4, Shi & Eberhart 1999 [34], [35]"),
    "p6": (dict(w_start=0.6, alpha=0.4, beta=0.2, c1=2.0, c2=2.0, rule=3),
           "dynamic adaptation (evolution speed, aggregation degree), Yang et al. 2007 [36]"),
    "p7": (dict(c1=1.494, c2=1.494, rule=4),
           "random inertia w = 0.5 + U(0,1)/2, Eberhart & Shi 2001 [37]"),
}  # fmt: skip

ALIASES = {
    "basic": "p1",
    "pso": "p1",
    "constriction": "p2",
    "ptpso": "p3",
    "nonlinear_inertia": "p4",
    "linear_inertia": "p5",
    "ldiw": "p5",
    "adaptive": "p6",
    "dynamic_adaptation": "p6",
    "random_inertia": "p7",
}

FORCE_PLATFORM: str | None = None
"""Tests only: ``"cpu"`` or ``"other"`` picks that formulation of ``on_cpu`` whatever the
backend (the other one is what a GPU runs; CI has none)."""


def on_cpu(cpu, other):
    """``cpu()`` in a program lowered for the CPU, ``other()`` for any other platform.

    Two formulations of the same arithmetic: the CPU's keeps PSO's per-step decisions
    (inertia rule, penalty on or off) as ``lax.switch``/``lax.cond``, whose outputs XLA
    materialises once and whose untaken branches cost nothing; the other computes every
    branch and selects elementwise, so the step has no conditional. On a GPU each
    conditional inside the scan makes XLA copy the branch index to the host and wait for
    it, every iteration (and splits the loop body's CUDA graph), which costs far more than
    the few small branches it saves. ``lax.platform_dependent`` decides at lowering: the
    compiled program holds one formulation only. Where the CPU is JAX's default backend
    (designopt runs its programs on the default backend's devices) only ``cpu`` is
    traced: both would double the step's tracing time, which every warm run pays."""
    if FORCE_PLATFORM is not None:
        return cpu() if FORCE_PLATFORM == "cpu" else other()
    if jax.default_backend() == "cpu":
        return cpu()
    return jax.lax.platform_dependent(cpu=cpu, default=other)


# random-number streams of one step (protocol: the step key is fresh every iteration)
_R1, _R2, _R3, _RW, _RB, _RX, _RV = range(7)


@dataclass(frozen=True)
class PSO(Optimizer):
    """p1..p7 (the variant is the preset; see VARIANTS). Options: ``draws``."""

    draws: str = rng.DEFAULT
    eval_slot: ClassVar[int] = 99

    Params: ClassVar[type] = Params
    options: ClassVar[dict[str, tuple[str, ...]]] = {"draws": rng.DRAWS}
    fixed: ClassVar[tuple[str, ...]] = ("rule",)
    int_fields: ClassVar[tuple[str, ...]] = ("rule",)
    min_population: ClassVar[int] = 2

    def _u(self, key, slot, shape, dt):
        return rng.uniform(self.draws, key, slot, shape, dt)

    def init_ask(self, key: jax.Array, p: Params, task: Task) -> tuple[Array, Array]:
        """Uniform positions in the box (asked) and velocities uniform in ±v_max."""
        lo, hi = task.lower, task.upper
        dt = lo.dtype
        shape = (self.n, lo.shape[0])
        x = lo + (hi - lo) * self._u(key, _RX, shape, dt)
        vmax = p.vmax_frac * (hi - lo)
        v = (vmax * (2.0 * self._u(key, _RV, shape, dt) - 1.0)).astype(dt)
        return x, v

    def init_tell(self, key: jax.Array, x: Array, v: Array, f: Array, viol: Array, p: Params,
                  task: Task) -> State:  # fmt: skip
        i = argbest(f, viol)
        return State(x, v, f, x, f, viol, f, x[i], f[i], viol[i], jnp.asarray(0, jnp.int32))

    def inertia(self, s: State, p: Params, key: jax.Array) -> Array:
        """Per-particle inertia (M, 1) at iteration s.t for the rule p.rule (lax.switch)."""
        M = s.x.shape[0]
        dt = s.x.dtype
        t = s.t.astype(dt)
        n_iters = self.n_iters

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
            w = p.w_start - p.alpha * (1.0 - h) + p.beta * agg
            return jnp.where(jnp.isfinite(w), w, p.w_start).astype(dt)

        def random():  # Eberhart & Shi 2001 [37]
            return 0.5 + 0.5 * self._u(key, _RW, (M,), dt)

        branches = {"constant": constant, "nonlinear": nonlinear, "linear": linear,
                    "adaptive": adaptive, "random": random}  # fmt: skip
        fns = [branches[r] for r in INERTIA_RULES]

        def every_rule():  # all five (M,) vectors, one picked elementwise: no conditional
            i = jnp.clip(p.rule, 0, len(fns) - 1)  # as lax.switch clamps its index
            return jax.lax.select_n(i, *(f() for f in fns))

        w = on_cpu(lambda: jax.lax.switch(p.rule, fns), every_rule)
        return w[:, None]

    def ask(self, key: jax.Array, s: State, p: Params, task: Task) -> tuple[Array, Array]:
        """The moves of eq. (44)-(49) for the whole swarm: new positions (asked) and
        velocities."""
        lower, upper = task.lower, task.upper
        M, D = s.x.shape
        dt = s.x.dtype
        w = self.inertia(s, p, key)
        vmax = p.vmax_frac * (upper - lower)

        # PTPSO penalty, eq. (46)-(49)
        def kick():
            d2, e_max = row_sum_max((s.x - s.gbest_x) ** 2)
            r = p.gamma * jnp.sqrt(jnp.sum((upper - lower) ** 2))  # γ·d_max
            # e_max ≤ d² so √e_max < r whenever d < r: the second test changes nothing, it
            # keeps the max output alive (see row_sum_max)
            near = (jnp.sqrt(d2) < r) & (jnp.sqrt(e_max) < r)
            rho = jnp.mean(near.astype(dt))
            pc = penalty_coefficient(rho, p.a, p.rho_c)
            u3 = self._u(key, _R3, (M, D), dt)
            r3 = jnp.where(p.symmetric_r3 > 0, 2.0 * u3 - 1.0, u3)
            return (p.penalty * pc * (1.0 - p.gamma) * vmax / jnp.sqrt(D) * r3).astype(dt)

        def velocity(penalised: bool):
            def new_v():  # eq. (44) [+ the penalty], clamped to ±v_max
                r1, r2 = rng.uniform_pair(self.draws, key, _R1, (M, D), dt)  # _R1, _R2
                v = p.chi * (
                    w * s.v + p.c1 * r1 * (s.pbest_x - s.x) + p.c2 * r2 * (s.gbest_x - s.x)
                )
                v = v + (kick() if penalised else jnp.zeros((M, D), dt))
                return jnp.clip(v, -vmax, vmax)

            return new_v

        def either():  # both as one select: no conditional
            return jnp.where(p.penalty != 0, velocity(True)(), velocity(False)())

        # On the CPU v is the output of a conditional, so XLA materialises it once: fused
        # into its consumers (position, bounds, fitness, personal best) the draws and the
        # update were recomputed in each of them (five times per step; an
        # optimization_barrier no longer prevents that). The penalty branch runs only when
        # the penalty is on (a real branch unless the settings are vmapped). On a GPU a
        # conditional costs more than the recomputation: its branch index is copied to the
        # host and waited for, every iteration (see ``on_cpu``).
        v = on_cpu(lambda: jax.lax.cond(p.penalty != 0, velocity(True), velocity(False)), either)
        x = s.x + v
        out = (x < lower) | (x > upper)
        x = apply_bounds(
            x,
            lower,
            upper,
            self.bounds,
            lambda: lower + (upper - lower) * self._u(key, _RB, (M, D), dt),
        )
        # the velocity of a coordinate that left the box: stopped at a clipped face,
        # reversed at a reflecting one, kept by a re-initialised particle
        if self.bounds == "clip":
            v = jnp.where(out, 0.0, v)
        elif self.bounds == "reflect":
            v = jnp.where(out, -v, v)
        return x, v

    def tell(self, key: jax.Array, s: State, x: Array, v: Array, f: Array, viol: Array,
             p: Params, task: Task) -> State:  # fmt: skip
        """Personal and global bests of eq. (50) by Deb's rules."""
        imp = better(f, viol, s.pbest_f, s.pbest_v)
        pbest_x = jnp.where(imp[:, None], x, s.pbest_x)
        pbest_f = jnp.where(imp, f, s.pbest_f)
        pbest_v = jnp.where(imp, viol, s.pbest_v)
        i = argbest(pbest_f, pbest_v)
        g = better(pbest_f[i], pbest_v[i], s.gbest_f, s.gbest_v)
        return State(
            x, v, f, pbest_x, pbest_f, pbest_v, s.pbest_f,
            jnp.where(g, pbest_x[i], s.gbest_x), jnp.where(g, pbest_f[i], s.gbest_f),
            jnp.where(g, pbest_v[i], s.gbest_v), s.t + 1,
        )  # fmt: skip

    def best(self, s: State) -> Best:
        return Best(s.gbest_x, s.gbest_f, s.gbest_v)

    def describe(self, params: Params) -> dict:
        import numpy as np

        out = super().describe(params)
        rule = np.asarray(params.rule).ravel()
        out["rule"] = INERTIA_RULES[int(rule[0])] if rule.size else None
        return out
