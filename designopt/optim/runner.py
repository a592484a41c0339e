"""Run a PSO variant on any Problem: all runs as one vmap over keys, lax.scan over iterations.

Iterations are scanned in chunks (``chunk_iters``); the host sees the swarm only between
chunks (progress bar, checkpoint), which keeps the run one array program. ``run_batch``
adds a second vmap over a list of settings (a sweep), all members on the same keys.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from designopt.optim import pso
from designopt.optim.variants import make_params, resolve, stack_params
from designopt.problems.base import Problem

CONVERGENCE_TOL = 1e-6


class RunResult(NamedTuple):
    history: np.ndarray  # ([B,] n_runs, n_iters + 1) best-so-far value
    best_f: np.ndarray  # ([B,] n_runs)
    best_x: np.ndarray  # ([B,] n_runs, D)
    converged_at: np.ndarray  # ([B,] n_runs) iteration after which no improvement > tol
    history_x: np.ndarray  # ([B,] n_runs, n_iters + 1, D) best-so-far design
    settings: dict[str, Any]


class Checkpoint(NamedTuple):
    """Everything needed to continue a run bit-for-bit: the swarm state as numpy arrays
    (the PRNG key as its raw key data), the histories so far and the iterations done."""

    state: dict[str, np.ndarray]
    history: np.ndarray
    history_x: np.ndarray
    done: int


def convergence_iteration(history: np.ndarray, tol: float = CONVERGENCE_TOL) -> np.ndarray:
    """SPEC §3.3: the iteration after which the best value never again improves by > tol."""
    h = np.asarray(history)
    gain = h[..., :-1] - h[..., 1:]
    gain = np.where(np.isfinite(gain), gain, np.inf)  # leaving +inf is an improvement
    big = gain > tol
    T = h.shape[-1] - 1
    last = T - np.argmax(big[..., ::-1], axis=-1)  # 1-based index of the last big gain
    return np.where(big.any(-1), last, 0)


def _over_runs(f, batched: bool):
    """vmap f(state_or_key, params) over runs, and over settings too when ``batched``."""
    runs = lambda S, p: jax.vmap(lambda s: f(s, p))(S)  # noqa: E731
    return jax.vmap(runs) if batched else runs


@partial(jax.jit, static_argnames=("fn", "bounds", "n_iters", "length", "batched", "draws"))
def _advance(states, params, pparams, lower, upper, fn, bounds, n_iters, length, batched=False,
             draws="uniform"):  # fmt: skip
    ev = lambda X, k: fn(pparams, X, k)[0]  # noqa: E731

    def one(s, p):
        def body(s, _):
            s = pso.step(s, p, ev, lower, upper, bounds, n_iters, draws)
            return s, (s.gbest_f, s.gbest_x)

        return jax.lax.scan(body, s, None, length=length)

    return _over_runs(one, batched)(states, params)


@partial(jax.jit, static_argnames=("fn", "n_particles", "batched"))
def _init(keys, params, pparams, lower, upper, fn, n_particles, batched=False):
    ev = lambda X, k: fn(pparams, X, k)[0]  # noqa: E731
    one = lambda k, p: pso.init(k, ev, lower, upper, n_particles, p)  # noqa: E731
    return _over_runs(one, batched)(keys, params)


def _to_numpy(states: pso.State) -> dict[str, np.ndarray]:
    d = {k: np.asarray(v) for k, v in states._asdict().items() if k != "key"}
    d["key"] = np.asarray(jax.random.key_data(states.key))
    return d


def _from_numpy(d: dict[str, np.ndarray]) -> pso.State:
    vals = {k: jnp.asarray(v) for k, v in d.items() if k != "key"}
    return pso.State(**vals, key=jax.random.wrap_key_data(jnp.asarray(d["key"])))


def _drive(variant, params, problem, key, n_particles, n_iters, n_runs, bounds, dtype,
           chunk_iters, progress, checkpoint, resume, batched, B, draws):  # fmt: skip
    if n_particles < 2 or n_iters < 1 or n_runs < 1:
        raise ValueError("n_particles must be ≥ 2, n_iters ≥ 1 and n_runs ≥ 1")
    if bounds not in pso.BOUNDS:
        raise ValueError(f"bounds must be one of {pso.BOUNDS}, got {bounds!r}")
    if draws not in pso.DRAWS:
        raise ValueError(f"draws must be one of {pso.DRAWS}, got {draws!r}")
    lower = jnp.asarray(problem.lower, dtype)
    upper = jnp.asarray(problem.upper, dtype)
    keys = jax.random.split(key, n_runs)
    if batched:
        keys = jnp.broadcast_to(keys, (B, n_runs))  # common random numbers across settings
    fn = problem.fn
    if resume is None:
        states = _init(keys, params, problem.params, lower, upper, fn, n_particles, batched)
        hf = [np.asarray(states.gbest_f)[..., None]]
        hx = [np.asarray(states.gbest_x)[..., None, :]]
        done = 0
    else:
        states = _from_numpy(resume.state)
        hf, hx, done = [np.asarray(resume.history)], [np.asarray(resume.history_x)], resume.done
        if hf[0].shape[-1] != done + 1:
            raise ValueError("checkpoint history does not match its iteration count")
        if progress is not None:
            progress(done)
    chunk = n_iters if chunk_iters is None else max(1, min(chunk_iters, n_iters))
    while done < n_iters:
        length = min(chunk, n_iters - done)
        states, (f, x) = _advance(
            states,
            params,
            problem.params,
            lower,
            upper,
            fn,
            bounds,
            n_iters,
            length,
            batched,
            draws,
        )
        hf.append(np.asarray(f))
        hx.append(np.asarray(x))
        done += length
        if progress is not None:
            progress(length)
        if checkpoint is not None and done < n_iters:
            hist, hist_x = np.concatenate(hf, axis=-1), np.concatenate(hx, axis=-2)
            hf, hx = [hist], [hist_x]
            checkpoint(Checkpoint(_to_numpy(states), hist, hist_x, done))
    history = np.concatenate(hf, axis=-1)
    history_x = np.concatenate(hx, axis=-2)
    return RunResult(
        history=history,
        best_f=history[..., -1],
        best_x=history_x[..., -1, :],
        converged_at=convergence_iteration(history),
        history_x=history_x,
        settings=_settings_record(variant, bounds, n_particles, n_iters, n_runs, params, draws),
    )


def _settings_record(
    variant, bounds, n_particles, n_iters, n_runs, params, draws
) -> dict[str, Any]:
    used = {k: np.asarray(getattr(params, k)).tolist() for k in pso.Params._fields if k != "rule"}
    return {"variant": variant.name, "rule": variant.rule, "bounds": bounds,
            "source": variant.source, "n_particles": n_particles, "n_iters": n_iters,
            "n_runs": n_runs, "draws": draws, **used}  # fmt: skip


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
    checkpoint: Callable[[Checkpoint], None] | None = None,
    resume: Checkpoint | None = None,
    draws: str = "uniform",
    **settings: Any,
) -> RunResult:
    """Run ``n_runs`` independent runs of variant ``name`` (p1..p7 or an alias) on ``problem``.

    ``settings`` override the variant's parameters (see ``designopt.optim.variants.BASE``).
    ``draws`` picks how r1, r2, r3 are drawn: ``"uniform"`` (default) or ``"splitmix"``
    (counter-based SplitMix64 seeded from the key, several times faster on CPU;
    ``pso._splitmix_pair``).
    ``checkpoint`` is called between chunks with a :class:`Checkpoint`; passing one back
    as ``resume`` continues the run and gives exactly the uninterrupted result.
    """
    variant = resolve(name)
    params = make_params(name, dtype, **settings)
    return _drive(variant, params, problem, key, n_particles, n_iters, n_runs, bounds, dtype,
                  chunk_iters, progress, checkpoint, resume, False, 1, draws)  # fmt: skip


def run_batch(
    name: str,
    problem: Problem,
    key: jax.Array,
    members: Sequence[dict[str, float]],
    n_particles: int = 50,
    n_iters: int = 1000,
    n_runs: int = 100,
    bounds: str = "clip",
    dtype: Any = jnp.float64,
    chunk_iters: int | None = None,
    progress: Callable[[int], None] | None = None,
    checkpoint: Callable[[Checkpoint], None] | None = None,
    resume: Checkpoint | None = None,
    draws: str = "uniform",
) -> RunResult:
    """Run the variant once per settings dict in ``members``, all as one vmapped program.

    Every member uses the same run keys (common random numbers), so member i equals
    ``run(name, ..., **members[i])`` up to floating-point reassociation. Results carry a
    leading member axis.
    """
    if not members:
        raise ValueError("members must hold at least one settings dict")
    variant = resolve(name)
    params = stack_params([make_params(name, dtype, **m) for m in members])
    return _drive(variant, params, problem, key, n_particles, n_iters, n_runs, bounds, dtype,
                  chunk_iters, progress, checkpoint, resume, True, len(members), draws)  # fmt: skip
