"""CMA-ES (Hansen 2016, "The CMA Evolution Strategy: A Tutorial", arXiv:1604.00772) as an
optimizer entry: a compact JAX version with the tutorial's default constants, active
(negative) weights, cumulative step-size adaptation and the h_σ stall indicator — the same
algorithm as evosax's ``CMA_ES`` (tests compare the two where evosax is installed).

It works in the unit box u = (x − lower)/(upper − lower), so σ0 is a fraction of the box
width. Samples outside the box are repaired by the bounds rule (clip, reflect, reinit) and
the repaired samples enter the update, so the mean stays in the box. Candidates are ranked
by Deb's feasibility rules (protocol.order). One departure from the tutorial, for speed
(the eigendecomposition of C was 90 % of a step at D = 30): samples are drawn as y = A z
with A the Cholesky factor of C, and the step-size path uses A⁻¹ y_w where the tutorial
uses C^(−1/2) y_w. Both are N(0, I) under random selection and give the same norms
‖C^(−1/2) y‖ = ‖A⁻¹ y‖ (the active weights' rescaling is unchanged); only the path's
orientation differs, which CSA, reading its length, does not see. The population size is the runner's
``n_particles`` (λ), μ = ⌊λ/2⌋. The learning rates are the tutorial's, times the ``*_scale``
settings (1 = default), so a sweep can tune them in one vmapped batch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from designopt.optim.protocol import Best, Optimizer, Task, apply_bounds, better, order

Array = jnp.ndarray


class Params(NamedTuple):
    sigma0: float = 0.3  # initial step size, fraction of the box width
    c1_scale: float = 1.0  # × the rank-one learning rate c1 = 2/((D + 1.3)² + μ_eff)
    cmu_scale: float = 1.0  # × the rank-μ learning rate
    cs_scale: float = 1.0  # × the step-size cumulation rate c_σ
    cc_scale: float = 1.0  # × the covariance-path cumulation rate c_c
    active: float = 1.0  # 1 = negative weights for the worse half (active CMA), 0 = off


class State(NamedTuple):
    mean: Array  # (D,) in unit-box coordinates
    sigma: Array  # ()
    p_sigma: Array  # (D,)
    p_c: Array  # (D,)
    C: Array  # (D, D)
    best_x: Array  # (D,) design coordinates
    best_f: Array
    best_v: Array
    t: Array


def constants(p: Params, lam: int, D: int, dt) -> dict[str, Array]:
    """The tutorial's weights and learning rates for λ, D (Hansen 2016, Table 1)."""
    mu = lam // 2
    i = jnp.arange(1, lam + 1, dtype=dt)
    wp = jnp.log((lam + 1) / 2.0) - jnp.log(i)
    pos = jnp.arange(lam) < mu
    mu_eff = jnp.sum(jnp.where(pos, wp, 0.0)) ** 2 / jnp.sum(jnp.where(pos, wp**2, 0.0))
    neg = ~pos
    mu_eff_m = jnp.sum(jnp.where(neg, wp, 0.0)) ** 2 / jnp.maximum(
        jnp.sum(jnp.where(neg, wp**2, 0.0)), 1e-30
    )
    c_c = p.cc_scale * (4 + mu_eff / D) / (D + 4 + 2 * mu_eff / D)
    c_1 = p.c1_scale * 2.0 / ((D + 1.3) ** 2 + mu_eff)
    c_mu = p.cmu_scale * jnp.minimum(
        1 - c_1 - 1e-8, 2.0 * (mu_eff - 2 + 1 / mu_eff) / ((D + 2) ** 2 + mu_eff)
    )
    alpha = jnp.minimum(
        jnp.minimum(1 + c_1 / c_mu, 1 + 2 * mu_eff_m / (mu_eff + 2)),
        (1 - c_1 - c_mu) / (D * c_mu),
    )
    w_pos = jnp.where(pos, wp, 0.0) / jnp.sum(jnp.where(pos, wp, 0.0))
    w_neg = jnp.where(neg, wp, 0.0) / jnp.maximum(jnp.sum(jnp.where(neg, -wp, 0.0)), 1e-30)
    weights = w_pos + p.active * alpha * w_neg
    c_s = p.cs_scale * (mu_eff + 2) / (D + mu_eff + 5)
    d_s = 1 + 2 * jnp.maximum(0.0, jnp.sqrt((mu_eff - 1) / (D + 1)) - 1) + c_s
    chi_n = jnp.sqrt(D) * (1 - 1 / (4 * D) + 1 / (21 * D**2))
    return dict(weights=weights.astype(dt), w_pos=w_pos.astype(dt), mu_eff=mu_eff, c_c=c_c,
                c_1=c_1, c_mu=c_mu, c_s=c_s, d_s=d_s, chi_n=chi_n)  # fmt: skip


def cholesky_factor(C: Array) -> Array:
    """Lower-triangular A with A Aᵀ = C; if C has lost positive definiteness (rounding),
    the factor of its diagonal part instead."""
    D = C.shape[0]
    scale = jnp.maximum(jnp.max(jnp.abs(jnp.diag(C))), jnp.finfo(C.dtype).tiny)
    A = jnp.linalg.cholesky(C + (10 * jnp.finfo(C.dtype).eps) * scale * jnp.eye(D, dtype=C.dtype))
    diag = jnp.diag(jnp.sqrt(jnp.maximum(jnp.diag(C), jnp.finfo(C.dtype).tiny)))
    return jnp.where(jnp.all(jnp.isfinite(A)), A, diag)


@dataclass(frozen=True)
class CMAES(Optimizer):
    """CMA-ES with λ = ``n`` (the runner's n_particles); no string options."""

    Params: ClassVar[type] = Params
    min_population: ClassVar[int] = 4  # μ = λ/2 ≥ 2 keeps the rank-μ update defined

    def init_ask(self, key: jax.Array, p: Params, task: Task) -> tuple[Array, Array]:
        """The initial mean, uniform in the box (unit coordinates), asked as one design."""
        lo, hi = task.lower, task.upper
        m = jax.random.uniform(jax.random.fold_in(key, 0), lo.shape, lo.dtype)
        return (lo + (hi - lo) * m)[None], m

    def init_tell(self, key: jax.Array, x: Array, m: Array, f: Array, v: Array, p: Params,
                  task: Task) -> State:  # fmt: skip
        dt = m.dtype
        z = jnp.zeros(m.shape[0], dt)
        sigma = jnp.asarray(p.sigma0, dt)
        return State(m, sigma, z, z, jnp.eye(m.shape[0], dtype=dt), x[0], f[0], v[0],
                     jnp.asarray(0, jnp.int32))  # fmt: skip

    def ask(self, key: jax.Array, s: State, p: Params, task: Task) -> tuple[Array, tuple]:
        """λ samples of N(mean, σ² C), repaired into the unit box, in design units; the
        pending part is (unit samples, Cholesky factor, symmetrised C)."""
        lo, hi = task.lower, task.upper
        dt = lo.dtype
        lam, D = self.n, lo.shape[0]
        C = (s.C + s.C.T) / 2
        A = cholesky_factor(C)
        z = jax.random.normal(jax.random.fold_in(key, 0), (lam, D), dt)
        y = z @ A.T  # ~ N(0, C)
        zero, one = jnp.zeros(D, dt), jnp.ones(D, dt)
        u = apply_bounds(s.mean + s.sigma * y, zero, one, self.bounds,
                         lambda: jax.random.uniform(jax.random.fold_in(key, 2), (lam, D), dt))  # fmt: skip
        return lo + (hi - lo) * u, (u, A, C)

    def tell(self, key: jax.Array, s: State, x: Array, pending: tuple, f: Array, v: Array,
             p: Params, task: Task) -> State:  # fmt: skip
        """Mean, step size, paths and covariance from the ranked samples."""
        u, A, C = pending
        dt = x.dtype
        lam, D = x.shape
        k = constants(p, lam, D, dt)
        idx = order(f, v)
        ys = (u[idx] - s.mean) / s.sigma  # repaired steps, best first
        y_w = k["w_pos"] @ ys
        mean = s.mean + s.sigma * y_w
        # A⁻¹ y_w for C^(−1/2) y_w: the same N(0, I) law and norms (see the module doc)
        white_w = jax.scipy.linalg.solve_triangular(A, y_w, lower=True)
        p_sigma = (1 - k["c_s"]) * s.p_sigma + jnp.sqrt(
            k["c_s"] * (2 - k["c_s"]) * k["mu_eff"]
        ) * white_w
        norm_ps = jnp.linalg.norm(p_sigma)
        sigma = s.sigma * jnp.exp((k["c_s"] / k["d_s"]) * (norm_ps / k["chi_n"] - 1))
        sigma = jnp.clip(sigma, 1e-30, 1e3).astype(dt)
        t = s.t + 1
        h_s = (
            norm_ps / jnp.sqrt(1 - (1 - k["c_s"]) ** (2 * t.astype(dt)))
            < (1.4 + 2 / (D + 1)) * k["chi_n"]
        ).astype(dt)
        p_c = (1 - k["c_c"]) * s.p_c + h_s * jnp.sqrt(k["c_c"] * (2 - k["c_c"]) * k["mu_eff"]) * y_w
        dh = (1 - h_s) * k["c_c"] * (2 - k["c_c"])
        w = k["weights"]
        nz = jnp.sum(
            jax.scipy.linalg.solve_triangular(A, ys.T, lower=True) ** 2, axis=0
        )  # ‖C^(−1/2) y‖²
        w_o = w * jnp.where(w >= 0, 1.0, D / jnp.maximum(nz, 1e-8))
        rank_mu = (ys * w_o[:, None]).T @ ys
        C = ((1 + k["c_1"] * dh - k["c_1"] - k["c_mu"] * jnp.sum(w)) * C
             + k["c_1"] * jnp.outer(p_c, p_c) + k["c_mu"] * rank_mu)  # fmt: skip
        C = C.astype(dt)
        i = idx[0]
        g = better(f[i], v[i], s.best_f, s.best_v)
        return State(
            mean.astype(dt), sigma, p_sigma.astype(dt), p_c.astype(dt), C,
            jnp.where(g, x[i], s.best_x), jnp.where(g, f[i], s.best_f),
            jnp.where(g, v[i], s.best_v), t,
        )  # fmt: skip

    def best(self, s: State) -> Best:
        return Best(s.best_x, s.best_f, s.best_v)
