"""The quadratic penalty: a constrained Problem as an unconstrained one.

f_pen(x) = f(x) + μ · Σ_j max(g_j(x), 0)²  (constraints g ≤ 0),

the classic exterior penalty (e.g. Nocedal & Wright, *Numerical Optimization*, §17.1).
The weight μ is an array in ``params``, so one compiled kernel serves every weight. The
default way to handle constraints is Deb's feasibility rules inside the optimizers
(docs/optimizers.md); this is the alternative a config picks with
``optimizer.constraints: {method: penalty, weight: μ}``. A penalty trades feasibility for
f: the optimum of f_pen lies slightly outside the feasible set, by O(1/μ).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import jax.numpy as jnp

from designopt.problems.base import Array, Problem, constraint_values


def penalty_sum(g: Array) -> Array:
    """Σ_j max(g_j, 0)² over the last axis of G (M, n_c) → (M,); NaN counts as +inf."""
    g = jnp.asarray(g)
    if g.ndim == 1:
        g = g[:, None]
    p = jnp.sum(jnp.square(jnp.maximum(g, 0.0)), axis=-1)
    return jnp.where(jnp.isnan(p), jnp.inf, p)


def quadratic(problem: Problem, weight: float) -> Problem:
    """``problem`` with its constraints folded into f by a quadratic penalty of weight μ;
    aux gains ``penalty`` (the added term). A problem without constraints is returned
    unchanged."""
    if problem.constraints is None:
        return problem
    if not weight > 0:
        raise ValueError(f"penalty weight must be > 0, got {weight}")
    fn, cons = problem.fn, problem.constraints

    def penalised(params: Any, X: Array, key: Any) -> tuple[Array, dict[str, Array]]:
        f, aux = fn(params["inner"], X, key)
        pen = params["weight"] * penalty_sum(constraint_values(cons, params["inner"], X, aux))
        return f + pen.astype(f.dtype), aux | {"penalty": pen}

    params = {"inner": problem.params, "weight": jnp.asarray(weight)}
    info = problem.info | {"constraint_handling": "quadratic penalty", "penalty_weight": weight}
    return replace(problem, fn=penalised, params=params, info=info, constraints=None)
