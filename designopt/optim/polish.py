"""Gradient polish after PSO (optax), projected onto the design box (SPEC §7, issue 5).

Designs are mapped to the unit box u = (x − lower)/(upper − lower) so that one learning
rate suits every variable. The update is one optax chain, ``chain(adam | sgd,
project_box(0, 1))``: the last transform turns the step into the one that lands on the
Euclidean projection of u + step onto the box (``optax.projections.projection_box``), so
``optax.apply_updates`` keeps every iterate feasible. All polished designs run as one
vmap; steps as one lax.scan.
"""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from designopt.problems.base import Problem


class RefineResult(NamedTuple):
    x0: np.ndarray  # (n, D) starting designs
    f0: np.ndarray  # (n,)
    x: np.ndarray  # (n, D) polished designs (best point seen along the path)
    f: np.ndarray  # (n,)
    history: np.ndarray  # (n, steps + 1) objective along the path
    gain: np.ndarray  # (n,) f0 − f ≥ 0


def project_box(lower: Any, upper: Any) -> optax.GradientTransformation:
    """A stateless optax transform ending a chain: replaces the incoming update d by
    P(u + d) − u, P the projection onto [lower, upper] (``optax.projections.projection_box``),
    so that ``apply_updates(u, ·)`` gives the projected iterate."""

    def init(params):
        return optax.EmptyState()

    def update(updates, state, params=None):
        if params is None:
            raise ValueError("project_box needs the current params")
        moved = optax.apply_updates(params, updates)
        proj = optax.projections.projection_box(moved, lower, upper)
        return jax.tree.map(lambda p, u: p - u, proj, params), state

    return optax.GradientTransformation(init, update)


def make_optimizer(method: str, learning_rate: float) -> optax.GradientTransformation:
    """The polish's optax chain in unit-box coordinates: the method, then the projection."""
    if method == "adam":
        base = optax.adam(learning_rate)
    elif method == "sgd":
        base = optax.sgd(learning_rate)
    else:
        raise ValueError(f"unknown refine method {method!r}; one of adam, sgd")
    return optax.chain(base, project_box(0.0, 1.0))


@partial(jax.jit, static_argnames=("fn", "method", "steps"))
def _polish(fn, params, key, lo, span, u0, learning_rate, method: str, steps: int):
    """The vmapped polish of unit-box designs u0 (n, D) as one compiled program; the
    learning rate and every number are arguments, so a second polish compiles nothing."""
    dtype = u0.dtype
    opt = make_optimizer(method, learning_rate)

    def f_of_u(u):
        return fn(params, (lo + span * u)[None], key)[0][0].astype(dtype)

    value_and_grad = jax.value_and_grad(f_of_u)

    def one(u0):
        def body(carry, _):
            u, state, best_u, best_f = carry
            f, g = value_and_grad(u)
            g = jnp.where(jnp.isfinite(g), g, 0.0)
            better = f < best_f
            best_u = jnp.where(better, u, best_u)
            best_f = jnp.where(better, f, best_f)
            upd, state = opt.update(g, state, u)
            u = optax.apply_updates(u, upd)
            return (u, state, best_u, best_f), f

        init = (u0, opt.init(u0), u0, jnp.asarray(jnp.inf, dtype))
        (u, _, best_u, best_f), hist = jax.lax.scan(body, init, None, length=steps)
        f_last = f_of_u(u)
        best_u = jnp.where(f_last < best_f, u, best_u)
        best_f = jnp.minimum(f_last, best_f)
        return best_u, best_f, jnp.concatenate([hist, f_last[None]])

    return jax.vmap(one)(u0)


def refine(
    problem: Problem,
    x0: np.ndarray,
    steps: int = 100,
    learning_rate: float = 0.01,
    method: str = "adam",
    key: jax.Array | None = None,
    dtype: Any = jnp.float64,
) -> RefineResult:
    """Polish designs x0 (n, D) by projected gradient descent on ``problem``'s objective.

    ``learning_rate`` is in units of the box width (Adam's step size). The objective is the
    problem's fixed-sample Monte-Carlo estimate, so the polish is deterministic.
    """
    key = jax.random.key(0) if key is None else key
    lo = jnp.asarray(problem.lower, dtype)
    span = jnp.asarray(problem.upper - problem.lower, dtype)
    make_optimizer(method, learning_rate)  # validate the method before tracing
    u0 = optax.projections.projection_box((jnp.asarray(x0, dtype) - lo) / span, 0.0, 1.0)
    bu, bf, hist = _polish(problem.fn, problem.params, key, lo, span, u0,
                           jnp.asarray(learning_rate, dtype), method, steps)  # fmt: skip
    # back to design units; the min/max only absorbs the last-ulp rounding of lo + span·u
    x = np.asarray(jnp.minimum(jnp.maximum(lo + span * bu, lo), jnp.asarray(problem.upper, dtype)))
    f = np.asarray(bf)
    h = np.asarray(hist)
    f0 = h[:, 0]
    return RefineResult(np.asarray(x0), f0, x, f, h, f0 - f)
