"""Scoring a run: the finite-result safety net and the groups of a finished optimisation
(the best run's history scored, the optional optax polish, the final design). Designs
are scored by ``designopt.problems.evaluate.score``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.app import polishing
from designopt.core.errors import ConfigError
from designopt.problems.base import Problem
from designopt.problems.evaluate import score


def check_finite(values: Mapping[str, Any], where: str, what: str,
                 names: Sequence[str] = (), X: np.ndarray | None = None,
                 na: Sequence[str] = ()) -> None:  # fmt: skip
    """ConfigError (exit 2, nothing written) when a result holds NaN or inf: numbers a
    config let through that the arithmetic cannot take (lengths so large their powers
    overflow in the run's precision). ``X`` (n, D): name the first design affected.
    ``na``: indices that may be n/a (``Problem.na_range``): NaN is their honest value
    there (and their SE's), inf is not."""
    for k, v in values.items():
        a = np.asarray(v) if k != "attrs" else np.zeros(0)
        if k.removesuffix("_se") in na and a.dtype.kind == "f":
            a = np.nan_to_num(a, nan=0.0, posinf=np.inf, neginf=-np.inf)
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


def run_groups(cfg: Any, problem: Problem, res: Any, dtype: Any) -> dict[str, Any]:
    """The groups of one (unbatched) run's record: optimizer, best_run, problem, final
    and, with a ``refine`` section, refine (docs/archive.md); ``dtype`` the run's."""
    from designopt.optim.polish import refine

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
        if r.method == "compass":  # derivative-free, feasible first (app.polishing)
            rr = polishing.runs(problem, res.best_x[order], r)
            how = {"step": r.step, "tol": r.tol, "max_iterations": r.steps}
        else:
            rr = refine(problem, res.best_x[order], r.steps, r.learning_rate, r.method,
                        dtype=dtype)  # fmt: skip
            how = {"steps": r.steps, "learning_rate": r.learning_rate}
        tree["refine"] = {
            "run_index": order, "x0": rr.x0, "f0": rr.f0, "x": rr.x, "f": rr.f,
            "history": rr.history, "gain": rr.gain, "attrs": {"method": r.method, **how},
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


def placement(study: Any, settings: Any, X: np.ndarray) -> dict[str, Any]:
    """What ``study.placement`` says designs ``X`` (n, D) put in the world (arrays (n,
    ...), e.g. the serial study's ports and bases), with their names in ``attrs``
    (``placement``) beside the study's own attrs; {} when the study has none."""
    if study.placement is None:
        return {}
    out = study.placement(settings, np.atleast_2d(np.asarray(X, np.float64)))
    if not out:
        return {}
    at = dict(out.pop("attrs", {}))
    return {k: np.asarray(v) for k, v in out.items()} | {"attrs": at | {"placement": list(out)}}


def with_placement(group: dict[str, Any], placed: dict[str, Any], row: int | None) -> None:
    """Add ``placed`` (:func:`placement`) to an archive group in place: design ``row``'s
    values (a final group), or every design's (``row`` None: a front's); the names go to
    the group's attr ``placement``, the study's column headings and titles of each (its
    attrs ``columns`` and ``titles``) to ``placement_columns`` and ``placement_titles``."""
    if not placed:
        return
    at = placed["attrs"]
    for k in at["placement"]:
        group[k] = placed[k] if row is None else placed[k][row]
    ga = group.setdefault("attrs", {})
    ga["placement"] = list(at["placement"])
    for k in ("columns", "titles"):  # the study's headings of each array's last axis
        if k in at:
            ga[f"placement_{k}"] = dict(at[k])
