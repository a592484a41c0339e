"""Scoring designs: f and every index with its standard error for any number of designs
in vmapped batches of one size (one compiled program for any count), the finite-result
safety net, and the record of a finished optimisation (the best run's history scored,
the optional optax polish, the final design)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt import parallel
from designopt.errors import ConfigError
from designopt.prepare import dtype_of
from designopt.problems.base import Problem


def score(problem: Problem, X: np.ndarray, batch: int | None = None, plan: Any = None,
          eval_shape: tuple[int, int] | None = None, dtype: Any = None
          ) -> dict[str, np.ndarray]:  # fmt: skip
    """f and every index (with standard errors) of designs X (n, D), in vmapped batches of
    a fixed size (the last one padded), so one compiled program serves any n. ``plan``
    (``designopt.parallel.scoring_plan``) splits each batch's designs over its devices.
    ``eval_shape`` (a run's ``RunResult.eval_shape``) and ``dtype`` (the run's): batches
    of that shape through the run's own compiled objective (``evaluate_batch``), so
    scoring a run's designs compiles nothing new."""
    X = np.asarray(X, np.float64)
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
        rows = lambda x: parallel.shard_rows(plan, x)  # noqa: E731
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
    from designopt.problems.base import evaluate_batch

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


_SCORERS: dict[Any, Any] = {}


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


def check_finite(values: Mapping[str, Any], where: str, what: str,
                 names: Sequence[str] = (), X: np.ndarray | None = None) -> None:  # fmt: skip
    """ConfigError (exit 2, nothing written) when a result holds NaN or inf: numbers a
    config let through that the arithmetic cannot take (lengths so large their powers
    overflow in the run's precision). ``X`` (n, D): name the first design affected."""
    for k, v in values.items():
        a = np.asarray(v) if k != "attrs" else np.zeros(0)
        if a.dtype.kind != "f" or np.all(np.isfinite(a)):
            continue
        at = ""
        if X is not None and a.ndim >= 1:
            i = int(np.flatnonzero(~np.isfinite(a.reshape(len(a), -1)).all(-1))[0])
            at = " at " + ", ".join(f"{n} = {x:g}" for n, x in zip(names, X[i], strict=True))
        raise ConfigError(f"{where}: {what}: {k} is not finite{at}; the config's numbers are "
                          "outside what the arithmetic can take (e.g. lengths so large that "
                          "their powers overflow); nothing written")  # fmt: skip


def problem_group(problem: Problem) -> dict[str, Any]:
    """The archive's ``problem`` group: names, box, info, normalisation bounds."""
    g: dict[str, Any] = {"names": np.array(problem.names, dtype="S"), "lower": problem.lower,
                         "upper": problem.upper, "attrs": {"info": problem.info}}  # fmt: skip
    if problem.norm_bounds is not None:
        g["norm_bounds"] = np.asarray(problem.norm_bounds)
    return g


def run_groups(cfg: Any, problem: Problem, res: Any) -> dict[str, Any]:
    """The groups of one (unbatched) run's record: optimizer, best_run, problem, final
    and, with a ``refine`` section, refine (docs/archive.md)."""
    from designopt.refine import refine

    bv = getattr(res, "best_v", None)
    # the best run by Deb's rules: least violation first, then the smallest f
    if cfg.optimizer.constraints.method != "deb":
        bv = None
    best = int(np.lexsort((res.best_f, bv))[0]) if bv is not None else int(np.argmin(res.best_f))
    tree: dict[str, Any] = {
        "optimizer": {
            "history": res.history, "best_f": res.best_f, "best_x": res.best_x,
            "converged_at": res.converged_at, "history_x": res.history_x,
            "attrs": {"settings": res.settings},
        },
        "problem": problem_group(problem),
    }  # fmt: skip
    deb = cfg.optimizer.constraints.method == "deb"  # a penalty run tracks no violation
    if deb and getattr(res, "history_v", None) is not None and problem.constraints is not None:
        tree["optimizer"] |= {"history_v": res.history_v, "best_v": res.best_v}
    x_final = res.best_x[best][None]
    stage = "optimizer"
    if cfg.refine is not None:
        r = cfg.refine
        order = np.argsort(res.best_f)[: r.n_best]
        rr = refine(problem, res.best_x[order], r.steps, r.learning_rate, r.method,
                    dtype=dtype_of(cfg))  # fmt: skip
        tree["refine"] = {
            "run_index": order, "x0": rr.x0, "f0": rr.f0, "x": rr.x, "f": rr.f,
            "history": rr.history, "gain": rr.gain,
            "attrs": {"method": r.method, "steps": r.steps, "learning_rate": r.learning_rate},
        }  # fmt: skip
        i = int(np.argmin(rr.f))
        keeps_feasible = problem.constraints is None or float(
            np.asarray(problem.violation(rr.x[i : i + 1]))[0]
        ) <= float(0.0 if bv is None else bv[best])
        if rr.f[i] < res.best_f[best] and keeps_feasible:
            x_final, stage = rr.x[i][None], "refine"
    # the best run's history and the final design in one call (one compiled program)
    hist_x = res.history_x[best]
    sc = score(problem, np.concatenate([hist_x, x_final]),
               eval_shape=getattr(res, "eval_shape", None), dtype=res.history_x.dtype)  # fmt: skip
    tree["best_run"] = {k: v[:-1] for k, v in sc.items()} | {
        "iteration": np.arange(res.history.shape[-1]),
        "attrs": {"run_index": best},
    }
    fin = {k: v[-1] for k, v in sc.items()}
    tree["final"] = fin | {"x": x_final[0], "attrs": {"stage": stage,
                           "n_samples_used": int(problem.n_samples_used)}}  # fmt: skip
    return tree
