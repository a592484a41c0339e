"""The ``refine: {method: compass}`` polish of a run's designs (designopt.optim.compass),
on the search's own samples (common random numbers: one deterministic function of the
design), so that runs that ended in one basin end at one local optimum:

- a weighted or constrained run: the best designs of the ``refine.n_best`` best runs,
  by f under Deb's rules (the least violation first);
- a front: each run's recommended design (the compromise of its own non-dominated final
  population, ``rescoring.front_picks``), by its scaled distance to the ideal point of
  the runs' non-dominated final populations, feasible designs first: the compromise the
  run recommends, made locally the best compromise.

The fresh re-scoring (``app.rescoring``) then quotes the polished designs; the search's
samples chose them, so their values there stay labelled so.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax.numpy as jnp
import numpy as np

from designopt.optim.compass import CompassResult, compass
from designopt.optim.polish import RefineResult
from designopt.problems.base import Problem, na_worst
from designopt.problems.evaluate import score
from designopt.results.base import SEARCH_LABEL


def minimised(vals: dict[str, np.ndarray], names: Sequence[str], sg: np.ndarray,
              na: Any) -> np.ndarray:  # fmt: skip
    """F (n, m): the objectives ``names`` of scored values, each × its sign (all
    minimised), an n/a value (NaN) at the worst end of its range, as the search ranks it."""
    cols = []
    for k, g in zip(names, sg, strict=True):
        v = np.asarray(vals[k], np.float64)
        if k in na:
            v = np.asarray(na_worst(jnp.asarray(v), *na[k], g > 0))
        cols.append(v * g)
    return np.stack(cols, -1)


def _violation(vals: dict[str, np.ndarray], n: int) -> np.ndarray:
    return np.asarray(vals.get("violation", np.zeros(n)), np.float64)


def _batch(X0: np.ndarray, problem: Problem) -> int:
    """The scoring batch of a polish: every start's 2D polls."""
    return int(np.atleast_2d(X0).shape[0] * 2 * problem.dim)


def _scored(problem: Problem, X: np.ndarray, B: int) -> dict[str, np.ndarray]:
    """``score`` of designs X (n ≤ B, D) padded to B rows with copies of the last one, so
    that every call of a polish (the starts, the polls of however many starts are still
    moving) runs one compiled shape; a task's scoring solves a copy once (its IK's
    representatives). The values of the n designs."""
    n = len(X)
    Xp = np.concatenate([X, np.repeat(X[-1:], B - n, 0)]) if n < B else X
    return {k: np.asarray(v)[:n] for k, v in score(problem, Xp, batch=B).items()}


def runs(problem: Problem, X0: np.ndarray, r: Any) -> RefineResult:
    """Designs X0 (n, D) of a weighted or constrained run polished on ``problem``'s
    samples by f, feasible first (``refine`` settings ``r``)."""

    B = _batch(X0, problem)

    def evaluate(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v = _scored(problem, X, B)
        return _violation(v, len(X)), np.asarray(v["f"], np.float64)

    c = compass(evaluate, X0, problem.lower, problem.upper, r.step, r.tol, r.steps)
    return RefineResult(c.x0, c.f0, c.x, c.f, c.history, c.f0 - c.f)


def front(problem: Problem, X0: np.ndarray, scale: np.ndarray, names: Sequence[str],
          sg: np.ndarray, r: Any) -> tuple[CompassResult, np.ndarray, dict[str, Any]]:  # fmt: skip
    """Each run's recommended design X0 (R, D) of a front polished on the search's
    samples by its distance to the ideal point in objectives scaled to [0, 1] over
    ``scale`` (2, m: ideal and nadir, minimised), feasible first. Returns (the compass
    result, F (R, m) of the polished designs on the search's samples, the archive's
    ``refine`` group)."""
    lo, hi = np.asarray(scale, np.float64)
    span = np.where(hi > lo, hi - lo, 1.0)
    na = problem.na_range

    B = _batch(X0, problem)

    def evaluate(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v = _scored(problem, X, B)
        F = minimised(v, names, sg, na)
        return _violation(v, len(X)), np.sqrt(np.sum(((F - lo) / span) ** 2, -1))

    c = compass(evaluate, X0, problem.lower, problem.upper, r.step, r.tol, r.steps)
    F = minimised(_scored(problem, c.x, B), names, sg, na)
    group = {"x0": c.x0, "x": c.x, "d0": c.f0, "d": c.f, "violation0": c.v0, "violation": c.v,
             "history": c.history, "step": c.step, "ideal": lo * sg, "nadir": hi * sg,
             "attrs": {"method": "compass", "designs": "each run's recommended design",
                       "value": "distance to the ideal point, objectives scaled to [0, 1] "
                                "by the runs' non-dominated final populations (ideal, "
                                "nadir: in the objectives' own values)",
                       "objectives": list(names), "samples": SEARCH_LABEL, "first_step": float(r.step),
                       "tol": float(r.tol), "max_iterations": int(r.steps),
                       "iterations": int(c.iterations), "evaluations": int(c.evaluations)}}  # fmt: skip
    return c, F, group
