"""Pareto fronts of a study's own indices (``study.objective.pareto``; docs/pareto.md).

Any study becomes multi-objective without code of its own: its swarm function already
returns every index, so the front's objectives are m of them, each minimised or
maximised (F = ±index, all minimised for the optimizer). A multi-objective optimizer
(the registry's ``nsga2``) searches the front in one vmapped program; then

1. the final populations of all runs are pooled and their non-dominated designs kept
   (feasible ones first, Deb's constrained domination);
2. those designs are re-scored on a fresh, larger sample set (``front.n_samples``, the
   named stream ``front`` folded from the root key, never seen by the optimizer;
   ``designopt.app.rescoring``), so every archived value is unbiased by the selection;
3. pairs of designs whose order in some objective is within 2 standard errors are marked
   ambiguous: which of the two is better there is not resolved by the samples;
4. with ``optimizer.n_runs`` ≥ 2, each run's recommended design (the compromise of its
   own non-dominated final population: ``app.rescoring.front_picks``) is re-scored in the
   same call, on the same stream, and the runs' agreement archived (``runs``).

The re-scoring is the one scoring of every quoted number (``designopt.app.quoted``:
``eval --fresh`` of a front design gives its archived values bit for bit), and each front
design gets the warnings a weighted run says of its final design (``quoted.warnings``),
with, for a task, its IK coverage figure (:func:`design_notes`).

With ``refine: {method: compass}`` each run's recommended design is first polished on
the search's samples (``app.polishing.front``); the polished designs are the runs'
recommendations and join the front's candidates.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import jax.numpy as jnp
import numpy as np

from designopt.app import polishing
from designopt.app import rescoring as rs
from designopt.app.config import linear, senses
from designopt.problems.base import Problem, na_worst

FRONT_STREAM = rs.FRONT_STREAM
"""The re-scoring samples: ``fold_in(key(seed), FRONT_STREAM)``, apart from the named
streams split from the root key (adding one there would change every other stream)."""
Z = rs.Z  # ambiguity: orders within Z standard errors


def signs(front: Mapping[str, Any]) -> np.ndarray:
    """+1 for a minimised objective, −1 for a maximised one (F = sign × value)."""
    return np.array([1.0 if s == "min" else -1.0 for s in senses(front).values()])


def weights(front: Mapping[str, Any], names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Each linear objective's weights as a (D,) vector over the problem's variables."""
    return {k: np.array([w.get(n, 0.0) for n in names]) for k, w in linear(front).items()}


def linear_units(front: Mapping[str, Any], units: Mapping[str, str]) -> dict[str, str]:
    """A linear objective's unit: its variables' common unit, else ``mixed``."""
    out = {}
    for k, w in linear(front).items():
        us = {units.get(v, "-") for v in w}
        out[k] = us.pop() if len(us) == 1 else "mixed"
    return out


def objective_problem(problem: Problem, front: Mapping[str, Any]) -> Problem:
    """The study's problem with F (M, m) = sign × the front's objectives (indices, or
    linear objectives X·w); the indices stay in aux (f too)."""
    names, sg = tuple(front), signs(front)
    lin = weights(front, problem.names)
    fn0 = problem.fn
    na = problem.na_range  # an n/a index ranks worst (the archive keeps its NaN)

    def objectives(scoring):  # scoring(params, X, key, *values) → (f, aux): → (F, aux)
        def fn(params, X, key, *values):
            f, aux = scoring(params, X, key, *values)
            aux = {"f": f, **aux, **{k: X @ jnp.asarray(w, X.dtype) for k, w in lin.items()}}
            F = jnp.stack([na_worst(aux[k], *na[k], g > 0) if k in na else aux[k]
                           for k, g in zip(names, sg, strict=True)], -1)  # fmt: skip
            return F * jnp.asarray(sg, F.dtype), aux

        return fn

    st = problem.staged  # its reduction gives the front's objectives too
    st = None if st is None else st._replace(reduce=objectives(st.reduce))
    return dataclasses.replace(problem, fn=objectives(fn0), n_objectives=len(names),
                               shard_samples=None, staged=st)  # fmt: skip


def reference(cfg: Any) -> np.ndarray | None:
    """The configured reference point in the minimised space (None: the optimizer's)."""
    ref = cfg.front.reference
    return None if ref is None else signs(cfg.study.pareto) * np.asarray(ref, np.float64)


def candidates(res: Any) -> np.ndarray:
    """Indices into the pooled final populations (runs × P) of the non-dominated designs:
    among the feasible ones when there are any, else among the least violating."""
    from designopt.numerics import pareto

    F = np.asarray(res.front.f, np.float64).reshape(-1, np.shape(res.front.f)[-1])
    V = np.asarray(res.front.v, np.float64).reshape(-1)
    pool = np.flatnonzero(V <= 0) if np.any(V <= 0) else np.flatnonzero(V == V.min())
    keep = pool[pareto.non_dominated(F[pool])]
    X = np.asarray(res.front.x, np.float64).reshape(len(V), -1)[keep]
    _, first = np.unique(X, axis=0, return_index=True)  # one copy of a repeated design
    return keep[np.sort(first)]


def ambiguous(F: np.ndarray, se: np.ndarray, z: float = Z) -> np.ndarray:
    """(p, 2) pairs (i < j) whose order in some objective is within ``z`` standard errors
    of their difference (|F_i − F_j| ≤ z √(se_i² + se_j²))."""
    d = np.abs(F[:, None, :] - F[None, :, :])
    s = z * np.sqrt(se[:, None, :] ** 2 + se[None, :, :] ** 2)
    close = np.any(d <= s, axis=-1)
    i, j = np.nonzero(np.triu(close, 1))
    return np.stack([i, j], -1).astype(np.int64)


def rescoring_problem(job: Any) -> tuple[Problem, int]:
    """The study's problem on the fresh ``front`` sample stream with ``front.n_samples``
    (default 4 × the study's own) samples per design; (problem, samples)."""
    return rs.problem(job, "front"), rs.plan(job, "front").n


def rescoring(job: Any) -> tuple[Any, dict[str, Any], int]:
    """(config, keys, samples) of the front's re-scoring (``app.rescoring.plan``): the
    config with ``front.n_samples`` samples per design (the study's
    ``Cost.samples_key``) and the named streams with ``samples`` the fresh ``front``
    stream."""
    fr = rs.plan(job, "front")
    return fr.cfg, fr.keys, fr.n


def groups(job: Any, problem: Problem, res: Any) -> dict[str, Any]:
    """The groups of a front's record: optimizer (hypervolume history of the best front
    found so far, the populations' hypervolume, final populations and archives), front
    (re-scored designs, objectives ± SE, every index ± SE, ambiguous pairs) and problem."""
    from designopt.app import quoted
    from designopt.app.scoring import check_finite, placement, problem_group, with_placement
    from designopt.numerics import pareto

    cfg, where = job.cfg, job.where
    front = cfg.study.pareto
    names, sg = list(front), signs(front)
    m = len(names)
    pop = res.front
    D = np.shape(pop.x)[-1]
    keep = candidates(res)
    X = np.asarray(pop.x, np.float64).reshape(-1, D)[keep]
    F_opt = np.asarray(pop.f, np.float64).reshape(-1, m)[keep]
    R = int(np.shape(pop.x)[0])
    X_runs, scale = rs.front_picks(res) if R >= 2 or cfg.refine is not None else (None, None)
    pick = "each run's recommended design: the compromise of its own non-dominated final population"
    polished, F_pol = None, None
    if cfg.refine is not None:  # each run's recommended design polished (compass)
        pol, F_pol, polished = polishing.front(problem, X_runs, scale, names, sg, cfg.refine)
        X_runs = pol.x
        pick += ", polished by a compass search on the search's samples (refine)"
        V = np.asarray(pop.v, np.float64).reshape(-1)
        ok = pol.v <= 0
        if np.all(V[keep] <= 0) and ok.any():  # the feasible polished designs join the front
            Xc, Fc = np.concatenate([X, pol.x[ok]]), np.concatenate([F_opt, F_pol[ok]])
            nd = np.flatnonzero(pareto.non_dominated(Fc))
            _, first = np.unique(Xc[nd], axis=0, return_index=True)
            nd = nd[np.sort(first)]
            X, F_opt, keep = Xc[nd], Fc[nd], nd
    verdict_group = None
    if cfg.final.race:  # the final stage: the front is formed from the race's survivors
        verdict_group, X, F_opt, n_cand = raced(job, res, X_runs, F_pol, polished is not None, sg)
        keep = np.arange(n_cand)
    X = X[pareto.thin(F_opt, cfg.front.max_points)]
    c, fresh, n_samples = rescoring(job)
    rescore = rs.problem(job, "front")
    n_front = len(X)
    n_samples = int(rescore.n_samples_used or n_samples)  # a points file: its points
    if R >= 2:  # each run's recommended design, scored in the same call on the same stream
        X = np.concatenate([X, X_runs])
    vals = quoted.blocked(rescore, X)  # the one scoring of quoted numbers (eval --fresh's)
    for k, w in weights(front, problem.names).items():  # exact: no samples behind them
        vals[k], vals[k + "_se"] = X @ w, np.zeros(len(X))
    na = problem.na_range
    check_finite(vals, where, "the re-scored front", problem.names, X, na=tuple(na))
    runs = None
    if R >= 2:
        runs = {k: v[n_front:] for k, v in vals.items()}, X[n_front:]
        vals, X = {k: v[:n_front] for k, v in vals.items()}, X[:n_front]
    F = np.stack([vals[k] for k in names], -1)  # n/a stays NaN in the archive
    se = np.stack([vals.get(k + "_se", np.zeros(len(X))) for k in names], -1)
    Fs = np.stack([np.asarray(na_worst(jnp.asarray(F[:, j]), *na[k], g > 0)) if k in na
                   else F[:, j] for j, (k, g) in enumerate(zip(names, sg, strict=True))],
                  -1)  # fmt: skip  # what the search ranked: an n/a value at its worst
    order = np.lexsort(Fs.T[::-1] * sg[::-1, None])
    X, F, se, Fs = X[order], F[order], se[order], Fs[order]
    vals = {k: v[order] for k, v in vals.items()}
    ref = np.asarray(res.ref_point, np.float64)  # minimised space
    Fmin = Fs * sg
    rank = pareto.front_ranks_np(Fmin, vals.get("violation"))
    hv = pareto.hypervolume(Fmin[rank == 0], ref)
    opt = {"hypervolume": res.history, "final_hypervolume": res.best_f,
           "converged_at": res.converged_at, "population_x": pop.x, "population_f": pop.f * sg,
           "population_v": pop.v, "population_rank": pop.rank,
           "attrs": {"settings": res.settings}}  # fmt: skip
    if res.history_population is not None:
        opt["population_hypervolume"] = res.history_population
    if res.archive is not None:  # the best front found (optimizer's samples), NaN: empty slot
        member = np.asarray(res.archive.v) == 0
        opt |= {"archive_x": np.where(member[..., None], res.archive.x, np.nan),
                "archive_f": np.where(member[..., None], res.archive.f * sg, np.nan),
                "archive_pruned": np.asarray(res.archive_pruned, np.int64)}  # fmt: skip
    if res.history_v is not None and problem.constraints is not None:
        opt |= {"history_v": res.history_v, "best_v": res.best_v}
    idx = {k: v for k, v in vals.items() if k not in ("f", "f_se")}  # the weighted f: moot
    fr = {"x": X, "f": F, "f_se": se, **idx, "rank": rank,
          "ambiguous": ambiguous(F, se),
          "attrs": {"objectives": names, "senses": list(senses(front).values()),
                    "reference": (ref * sg).tolist(), "hypervolume": hv,
                    "n_samples": n_samples, "n_candidates": int(len(keep)), "z": Z,
                    "units": linear_units(front, job.study.units(cfg.study))}}  # fmt: skip
    with_placement(fr, placement(job.study, cfg.study, X), None)  # ports, bases: (n, ...)
    tg = None
    if job.study.targets is not None and len(X):  # every front design at every target
        # the re-scoring's targets and seeds (their means are the front's indices), and
        # each design's IK coverage, all designs in one batch
        tg = job.study.targets(c.study, X, fresh, job.dtype)
    fr["attrs"] |= design_notes(job, X, idx, tg)
    out = {"optimizer": opt, "front": fr, "problem": problem_group(problem)}
    if polished is not None:
        out["refine"] = polished
    if verdict_group is not None:
        out["verdict"] = verdict_group
    if runs is not None:
        out["runs"] = runs_group(job, problem, runs[0], runs[1], names, sg, F, na, pick)
    if tg is not None:
        out["targets"] = tg
    return out


def raced(job: Any, res: Any, X_runs: np.ndarray | None, F_runs: np.ndarray | None,
          polished: bool, sg: np.ndarray) -> tuple[dict[str, Any], np.ndarray, np.ndarray, int]:  # fmt: skip
    """A front's final stage (``final.race``, ``designopt.app.verdict``): every run's
    non-dominated final-population designs, each run's recommended (or polished) design
    ``X_runs`` (with ``F_runs``, its search objectives, minimised, when polished), cleared
    and raced on the validation stream. Returns the ``verdict`` group, the race's
    surviving designs that are non-dominated on their validation means (those that
    missed no share constraint first), those means (minimised, as the search's F) and the
    number of candidates raced."""
    from designopt.app import verdict
    from designopt.numerics import pareto

    if X_runs is not None and F_runs is None:  # a run's pick: a final-population design
        D = np.shape(res.front.x)[-1]
        Xp = np.asarray(res.front.x, np.float64).reshape(-1, D)
        Fp = np.asarray(res.front.f, np.float64).reshape(len(Xp), -1)
        F_runs = Fp[[int(np.argmin(np.abs(Xp - x).sum(-1))) for x in X_runs]]
    Xc, _ = verdict.front_candidates(res, candidates(res), X_runs, F_runs)
    Xc = verdict.clear(job, Xc)
    pick = ["every run's non-dominated final-population designs"]
    if X_runs is not None:
        pick.append("each run's recommended design" + (", polished" if polished else ""))
    g = verdict.race_candidates(job, Xc, sources=pick)
    rows = verdict.survivors(g)
    status = np.asarray(g["status"]).astype(str)[rows]
    ok = ~(status == "missed").any(axis=1) if status.size else np.ones(len(rows), bool)
    pool = rows[ok] if ok.any() else rows
    Fp = np.asarray(g["mean"], np.float64)[pool] * sg
    nd = pool[pareto.non_dominated(Fp)]
    return g, np.asarray(g["x"], np.float64)[nd], np.asarray(g["mean"])[nd] * sg, len(Xc)


def design_notes(job: Any, X: np.ndarray, vals: Mapping[str, np.ndarray],
                 tg: Mapping[str, Any] | None) -> dict[str, Any]:  # fmt: skip
    """The front's attrs on its designs X (n, D) with their re-scored ``vals``, as a
    weighted run says them of its final design: ``warnings`` (each distinct line of
    ``quoted.warnings`` once, naming the designs it concerns) and, for a task, each
    design's IK coverage figure read from the front's ``targets`` group ``tg`` (the
    study's hook on the re-scoring's targets; its IK solves every design in one batch,
    ``quoted.read_coverages``): ``ik_better`` (n,), ``ik_better_n`` and ``coverage_lines``,
    the lines of the design whose share is the largest (the worst; its warning, if any,
    is among the warnings)."""
    from designopt.app import quoted

    n = len(X)
    covers = quoted.read_coverages(tg, n)
    per = [quoted.warnings(job, {k: np.asarray(v)[i] for k, v in vals.items()}, X[i],
                           covers[i]) for i in range(n)]  # fmt: skip
    out: dict[str, Any] = {}
    warns = quoted.grouped(per, "front design")
    if warns:
        out["warnings"] = warns
    if n and any(cv and "ik_better" in cv for cv in covers):
        share = [float(cv["ik_better"]) if cv else float("nan") for cv in covers]
        w = int(np.nanargmax(share))
        out |= {"ik_better": share, "ik_better_n": float(covers[w]["ik_better_n"]),
                "coverage_lines": [f"front design #{w}, the worst of the {n}: {ln}" if n > 1
                                   else ln for ln in covers[w]["lines"]]}  # fmt: skip
    return out


def runs_group(job: Any, problem: Problem, vals: dict[str, np.ndarray], X: np.ndarray,
               names: list[str], sg: np.ndarray, F_front: np.ndarray, na: Any,
               pick: str) -> dict[str, Any]:  # fmt: skip
    """The ``runs`` group of a front run: each run's recommended design on the front's
    fresh stream, compared with the reference run: the run whose design is the compromise
    of the re-scored ones (scaled by the re-scored front's ideal and nadir)."""
    vals = {k: v for k, v in vals.items() if k not in ("f", "f_se")}  # the weighted f: moot
    Fs = polishing.minimised(vals, names, sg, na)  # minimised, n/a at its worst
    Ff = F_front * sg
    scale = np.stack(
        [np.nanmin(np.concatenate([Ff, Fs]), 0), np.nanmax(np.concatenate([Ff, Fs]), 0)]
    )
    ref = rs.compromise(Fs, scale)
    fr = rs.plan(job, "front")
    return rs.runs_group(X, vals, names, list(senses(job.cfg.study.pareto).values()),
                                ref, problem.lower, problem.upper, problem.names, fr,
                                pick)  # fmt: skip
