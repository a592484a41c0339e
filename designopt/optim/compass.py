"""Derivative-free polish: a compass (coordinate pattern) search on fixed samples.

A search ends with designs near, not at, a local optimum of its own Monte-Carlo estimate.
Where that estimate is not differentiable (an index read at IK solutions that switch
branch, targets that leave the reach, a collision flag) the gradient polish
(:mod:`designopt.optim.polish`) has nothing to follow. A compass search needs only
values: from each start it polls the 2D points ±h along each variable (h a share of the
variable's box width), moves to the best poll that improves, and halves h when none does,
until h falls below ``tol`` (Kolda, Lewis and Torczon, "Optimization by direct search",
2003). On common random numbers (the same samples for every design) the objective is one
deterministic function, so starts in one basin end at one local optimum, up to ``tol``.

The polls of every start are scored together, one batched call per iteration (a host
loop over iterations only: ``evaluate`` may itself be a pipeline of compiled programs).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np


class CompassResult(NamedTuple):
    x0: np.ndarray  # (n, D) starting designs
    f0: np.ndarray  # (n,) their values
    x: np.ndarray  # (n, D) polished designs
    f: np.ndarray  # (n,)
    history: np.ndarray  # (n, iterations + 1) each start's value after each iteration
    v0: np.ndarray  # (n,) the starts' constraint violations (0: feasible)
    v: np.ndarray  # (n,) the polished designs' violations
    step: np.ndarray  # (n,) the last step, a share of each variable's box width
    iterations: int  # iterations run (each one batched call)
    evaluations: int  # designs scored, the starts included


Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def _values(evaluate: Evaluate, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(violation ≥ 0, value) of designs X (k, D); NaN ranks last."""
    v, f = evaluate(X)
    v = np.nan_to_num(np.maximum(np.asarray(v, np.float64).reshape(len(X)), 0.0), nan=np.inf)
    f = np.nan_to_num(np.asarray(f, np.float64).reshape(len(X)), nan=np.inf)
    return v, f


def compass(evaluate: Evaluate, x0: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            step: float = 0.08, tol: float = 0.002, max_iters: int = 100) -> CompassResult:
    """Minimise ``evaluate`` (X (k, D) → (violation (k,), value (k,)), Deb's rules: the
    lower violation first (≤ 0: feasible), then the lower value) from each row of ``x0``
    (n, D) within the box [lower, upper] by a compass search: poll x ± h·(upper − lower)
    along each variable, move to the best poll that is better, else halve h; a start
    stops when h < ``tol``, all stop after ``max_iters`` iterations. A poll that the box
    clips is taken at the box's face. Deterministic for a deterministic ``evaluate``."""
    x = np.array(x0, np.float64, copy=True, ndmin=2)
    lo, hi = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    n, D = x.shape
    width = hi - lo
    v, f = _values(evaluate, x)
    v0, f0 = v.copy(), f.copy()
    h = np.full(n, float(step))
    hist = [f.copy()]
    evaluations = n
    moves = np.concatenate([np.eye(D), -np.eye(D)])  # (2D, D)
    it = 0
    while it < max_iters:
        act = np.flatnonzero(h >= tol)
        if not len(act):
            break
        polls = np.clip(x[act, None, :] + h[act, None, None] * moves[None] * width, lo, hi)
        vp, fp = (a.reshape(len(act), 2 * D) for a in _values(evaluate, polls.reshape(-1, D)))
        evaluations += polls.shape[0] * polls.shape[1]
        b = np.lexsort((fp, vp), axis=-1)[:, 0]  # each start's best poll
        rows = np.arange(len(act))
        vb, fb = vp[rows, b], fp[rows, b]
        better = (vb < v[act]) | ((vb == v[act]) & (fb < f[act]))
        moved, stay = act[better], act[~better]
        x[moved] = polls[better, b[better]]
        v[moved], f[moved] = vb[better], fb[better]
        h[stay] /= 2.0
        it += 1
        hist.append(f.copy())
    return CompassResult(np.array(x0, np.float64, ndmin=2), f0, x, f, np.stack(hist, 1), v0, v,
                         h, it, evaluations)  # fmt: skip
