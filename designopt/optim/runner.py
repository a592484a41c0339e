"""Run a PSO variant on any Problem: all runs as one vmap over keys, lax.scan over iterations.

Iterations are scanned in chunks (``chunk_iters``); the host sees the swarm only between
chunks, for a progress callback, which keeps the run one array program.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from designopt.optim import pso
from designopt.optim.variants import make_params, resolve
from designopt.problems.base import Problem

CONVERGENCE_TOL = 1e-6


class RunResult(NamedTuple):
    history: np.ndarray  # (n_runs, n_iters + 1) best-so-far value
    best_f: np.ndarray  # (n_runs,)
    best_x: np.ndarray  # (n_runs, D)
    converged_at: np.ndarray  # (n_runs,) iteration after which no improvement > tol
    history_x: np.ndarray  # (n_runs, n_iters + 1, D) best-so-far design
    settings: dict[str, Any]


def convergence_iteration(history: np.ndarray, tol: float = CONVERGENCE_TOL) -> np.ndarray:
    """SPEC §3.3: the iteration after which the best value never again improves by > tol."""
    h = np.asarray(history)
    gain = h[..., :-1] - h[..., 1:]
    gain = np.where(np.isfinite(gain), gain, np.inf)  # leaving +inf is an improvement
    big = gain > tol
    T = h.shape[-1] - 1
    last = T - np.argmax(big[..., ::-1], axis=-1)  # 1-based index of the last big gain
    return np.where(big.any(-1), last, 0)


@partial(jax.jit, static_argnames=("fn", "n_particles", "rule", "bounds", "n_iters", "length"))
def _advance(states, params, pparams, lower, upper, fn, n_particles, rule, bounds, n_iters, length):
    def one(s):
        ev = lambda X, k: fn(pparams, X, k)[0]  # noqa: E731

        def body(s, _):
            s = pso.step(s, params, ev, lower, upper, rule, bounds, n_iters)
            return s, (s.gbest_f, s.gbest_x)

        return jax.lax.scan(body, s, None, length=length)

    return jax.vmap(one)(states)


@partial(jax.jit, static_argnames=("fn", "n_particles"))
def _init(keys, params, pparams, lower, upper, fn, n_particles):
    ev = lambda X, k: fn(pparams, X, k)[0]  # noqa: E731
    return jax.vmap(lambda k: pso.init(k, ev, lower, upper, n_particles, params))(keys)


def run(
    name: str,
    problem: Problem,
    key: jax.Array,
    n_particles: int = 50,
    n_iters: int = 1000,
    n_runs: int = 100,
    bounds: str = "clip",
    dtype: Any = jnp.float64,
    chunk_iters: int | None = None,
    progress: Callable[[int], None] | None = None,
    **settings: Any,
) -> RunResult:
    """Run ``n_runs`` independent runs of variant ``name`` (p1..p7 or an alias) on ``problem``.

    ``settings`` override the variant's parameters (see ``designopt.optim.variants.BASE``).
    """
    if n_particles < 2 or n_iters < 1 or n_runs < 1:
        raise ValueError("n_particles must be ≥ 2, n_iters ≥ 1 and n_runs ≥ 1")
    if bounds not in pso.BOUNDS:
        raise ValueError(f"bounds must be one of {pso.BOUNDS}, got {bounds!r}")
    variant = resolve(name)
    params = make_params(name, dtype, **settings)
    lower = jnp.asarray(problem.lower, dtype)
    upper = jnp.asarray(problem.upper, dtype)
    keys = jax.random.split(key, n_runs)
    static = dict(fn=problem.fn, n_particles=n_particles)
    states = _init(keys, params, problem.params, lower, upper, **static)
    hf = [np.asarray(states.gbest_f)[:, None]]
    hx = [np.asarray(states.gbest_x)[:, None]]
    chunk = n_iters if chunk_iters is None else max(1, min(chunk_iters, n_iters))
    done = 0
    while done < n_iters:
        length = min(chunk, n_iters - done)
        states, (f, x) = _advance(
            states, params, problem.params, lower, upper, rule=variant.rule, bounds=bounds,
            n_iters=n_iters, length=length, **static,
        )  # fmt: skip
        hf.append(np.asarray(f))
        hx.append(np.asarray(x))
        done += length
        if progress is not None:
            progress(length)
    history = np.concatenate(hf, axis=1)
    history_x = np.concatenate(hx, axis=1)
    used = {k: float(getattr(params, k)) for k in pso.Params._fields}
    return RunResult(
        history=history,
        best_f=history[:, -1],
        best_x=history_x[:, -1],
        converged_at=convergence_iteration(history),
        history_x=history_x,
        settings={"variant": variant.name, "rule": variant.rule, "bounds": bounds, "source": variant.source,
                  "n_particles": n_particles, "n_iters": n_iters, "n_runs": n_runs, **used},
    )  # fmt: skip
