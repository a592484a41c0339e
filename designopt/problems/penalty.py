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

    def add(params: Any, X: Array, f: Array, aux: dict[str, Array]):
        pen = params["weight"] * penalty_sum(constraint_values(cons, params["inner"], X, aux))
        return f + pen.astype(f.dtype), aux | {"penalty": pen}

    def penalised(params: Any, X: Array, key: Any) -> tuple[Array, dict[str, Array]]:
        return add(params, X, *fn(params["inner"], X, key))

    st = problem.staged  # its two stages on the inner params, the penalty in the second
    if st is not None:
        values0, reduce0 = st.values, st.reduce

        def values(params: Any, X: Array) -> Any:
            return values0(params["inner"], X)

        def reduce(params: Any, X: Array, key: Any, vals: Any):
            return add(params, X, *reduce0(params["inner"], X, key, vals))

        st = st._replace(values=values, reduce=reduce)
    params = {"inner": problem.params, "weight": jnp.asarray(weight)}
    info = problem.info | {"constraint_handling": "quadratic penalty", "penalty_weight": weight}
    return replace(problem, fn=penalised, params=params, info=info, constraints=None, staged=st)
