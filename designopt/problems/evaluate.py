"""Scoring designs: f and every index with its standard error for any number of designs,
in vmapped batches of one size (one compiled program for any count), or in the shape of
a run's objective calls (``evaluate_batch``: the very program the run compiled)."""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.core import concurrency, devices
from designopt.problems.base import Problem, evaluate_batch


def score(problem: Problem, X: np.ndarray, batch: int | None = None, plan: Any = None,
          eval_shape: tuple[int, int] | None = None, dtype: Any = None
          ) -> dict[str, np.ndarray]:  # fmt: skip
    """f and every index (with standard errors) of designs X (n, D), in vmapped batches of
    a fixed size (the last one padded), so one compiled program serves any n. ``plan``
    (``designopt.core.devices.scoring_plan``) splits each batch's designs over its devices.
    ``eval_shape`` (a run's ``RunResult.eval_shape``) and ``dtype`` (the run's): batches
    of that shape through the run's own compiled objective (``evaluate_batch``), so
    scoring a run's designs compiles nothing new."""
    X = np.asarray(X, np.float64)
    if problem.staged is not None and plan is None:  # one program per structure
        f, aux, v = staged_scores(problem, X, dtype=dtype)
        return {"f": f} | aux | ({} if problem.constraints is None else {"violation": v})
    # the run's program where at least half of its rows are real designs (a sweep's run
    # shape holds all members' runs: padding a member's few designs to it costs more)
    if eval_shape is not None and plan is None and 2 * len(X) >= eval_shape[0] * eval_shape[1]:
        return _score_groups(problem, X, eval_shape, dtype)
    n = X.shape[0]
    b = n if batch is None else max(1, min(batch, n))
    fn = _scorer(problem.fn, problem.constraints)
    params, key, host, rows = problem.params, jax.random.key(0), np.asarray, jnp.asarray
    if plan is not None:
        b = -(-b // plan.n_devices) * plan.n_devices
        params, key, host = plan.put(params), plan.put(key), plan.host
        rows = lambda x: devices.shard_rows(plan, x)  # noqa: E731
    outs = []
    for i in range(0, n, b):
        Xi = X[i : i + b]
        pad = b - Xi.shape[0]
        if pad:
            Xi = np.concatenate([Xi, np.repeat(Xi[-1:], pad, 0)])
        f, sub = fn(params, rows(Xi), key)
        outs.append({"f": host(f)[: b - pad]} | {k: host(v)[: b - pad] for k, v in sub.items()})
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


def _score_groups(problem: Problem, X: np.ndarray, shape: tuple[int, int],
                  dtype: Any) -> dict[str, np.ndarray]:  # fmt: skip
    """``score`` through ``evaluate_batch`` in batches of G·rows designs (G groups of
    rows, the last batch padded with its last design), every group with key 0."""

    G, r = shape
    n, D = X.shape
    b = G * r
    keys = jnp.broadcast_to(jax.random.key(0), (G,))
    dt = X.dtype if dtype is None else np.dtype(dtype)
    outs = []
    for i in range(0, n, b):
        Xi = X[i : i + b]
        m = Xi.shape[0]
        if m < b:
            Xi = np.concatenate([Xi, np.repeat(Xi[-1:], b - m, 0)])
        f, aux, v = evaluate_batch(problem.params, jnp.asarray(Xi.reshape(G, r, D), dt), keys,
                                   fn=problem.fn, constraints=problem.constraints)  # fmt: skip
        if problem.constraints is not None:
            aux = aux | {"violation": v}
        flat = lambda a, m=m: np.asarray(a).reshape((b,) + a.shape[2:])[:m]  # noqa: E731
        outs.append({"f": flat(f)} | {k: flat(a) for k, a in aux.items()})
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


def staged_scores(problem: Problem, X: Any, params: Any = None, dtype: Any = None
                  ) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:  # fmt: skip
    """(f, aux, v) of designs X (n, D) through the problem's two stages
    (``Problem.staged``): blocks of ``staged.designs`` rows (the last one padded with its
    last design), each block's ``values`` (the study's fixed-shape programs), then the
    block's ``reduce`` with the total constraint violation (one jitted program per
    (reduce, constraints), key 0). ``params``: the problem's unless given (a runner's
    placed copy); ``dtype``: of the designs (the run's)."""
    st = problem.staged
    assert st is not None
    params = problem.params if params is None else params
    X = np.asarray(X)
    X = X.astype(X.dtype if dtype is None else np.dtype(dtype))
    n, B = X.shape[0], st.designs
    red = _reducer(st.reduce, problem.constraints)
    key = jax.random.key(0)

    def block(Xi: np.ndarray) -> Any:
        Xj = jnp.asarray(Xi)
        return red(params, Xj, key, st.values(params, Xj))

    rows = []
    for i in range(0, n, B):
        Xi = X[i : i + B]
        if len(Xi) < B:
            Xi = np.concatenate([Xi, np.repeat(Xi[-1:], B - len(Xi), 0)])
        rows.append(Xi)
    # the blocks side by side on the CPU's cores (each call of the IK's program runs on one)
    outs = concurrency.map_calls([functools.partial(block, Xi) for Xi in rows],
                                 key=("staged", st.values, red, X.shape[1:], X.dtype.str))  # fmt: skip
    f = np.concatenate([np.asarray(o[0]) for o in outs])[:n]
    aux = {k: np.concatenate([np.asarray(o[1][k]) for o in outs])[:n] for k in outs[0][1]}
    v = np.concatenate([np.asarray(o[2]) for o in outs])[:n]
    return f, aux, v


_SCORERS: dict[Any, Any] = {}


def _reducer(reduce: Callable, constraints: Callable | None) -> Callable:
    """``reduce`` and the total violation of ``constraints``, jitted (cached per pair).
    Its first call for a shape waits while another thread makes the first call of a
    reducer of the same code at the same shapes (:func:`_first_alone`): two problems of
    one study (a race's stages, drawn side by side) compile one program, the second
    reading it from the compilation cache, instead of both compiling it at once."""
    key = ("staged", reduce, constraints)
    if key not in _SCORERS:
        from designopt.problems.base import violation_of

        def run(params, X, k, values):
            f, aux = reduce(params, X, k, values)
            return f, aux, violation_of(constraints, params, X, aux)

        code = tuple(getattr(c, "__code__", c) for c in (reduce, constraints))
        _SCORERS[key] = _first_alone(jax.jit(run), code)
    return _SCORERS[key]


_FIRST: dict[Any, threading.Event] = {}
_FIRST_LOCK = threading.Lock()


def _first_alone(fn: Callable, code: Any) -> Callable:
    """``fn`` whose first call for arguments of given shapes runs alone among the
    functions of the same ``code``: a later one waits until it has returned."""

    def call(*args: Any) -> Any:
        leaves, tree = jax.tree_util.tree_flatten(args)
        sig = (code, tree, tuple((np.shape(a), str(getattr(a, "dtype", type(a).__name__)))
                                 for a in leaves))  # fmt: skip
        with _FIRST_LOCK:
            done = _FIRST.get(sig)
            mine = done is None
            if mine:
                done = _FIRST[sig] = threading.Event()
        if not mine:
            done.wait()
            return fn(*args)
        try:
            return jax.block_until_ready(fn(*args))
        finally:
            done.set()

    return call


def _scorer(fn: Callable, constraints: Callable | None = None) -> Callable:
    """fn jitted (cached per function); with constraints, ``violation`` (Σ max(g, 0), 0
    when feasible) joins the indices."""
    key = (fn, constraints)
    if key not in _SCORERS:
        if constraints is None:
            _SCORERS[key] = jax.jit(fn)
        else:
            from designopt.problems.base import scored

            def with_violation(params, X, k):
                f, sub, v = scored(fn, constraints, params, X, k)
                return f, sub | {"violation": v}

            _SCORERS[key] = jax.jit(with_violation)
    return _SCORERS[key]
