"""Scores you can quote: designs a search chose, re-scored on a fresh sample stream.

A search ranks designs by Monte-Carlo estimates on its own samples (common random
numbers, shared by the whole swarm), so the design it keeps is, among many scored on the
same samples, the one whose samples were luckiest: its search value is biased by the
selection. Every design a run returns is therefore scored again, on a fresh,
independent stream of more samples that the search never saw, and that value is the one
quoted (docs/archive.md, docs/configs.md "Scores you can quote"):

- a Pareto front's designs: the stream ``front`` (``front.n_samples``; docs/pareto.md);
- a run's final design and, with ``optimizer.n_runs`` ≥ 2, each run's best design, all in
  one batched call: the stream ``final`` (``final.n_samples``).

Each stream is ``fold_in(key(seed), CONSTANT)``, apart from the named streams split from
the root key (adding one there would change every other stream). The re-scoring keeps
the run's normalisation: a weighted objective's probed bounds (``Problem.norm_bounds``,
``params["bounds"]``) are the search's, not probed again on the fresh samples, so the
fresh f is the same function of the indices as the search's f.

Runs that agree (:func:`agreement`): each run's design, re-scored on the one common
stream, is compared with the reference run's (the best run; a front's: the run whose
recommended design is the compromise of the re-scored ones), objective by objective,
within Z standard errors of their difference; the variables along which the agreeing
designs spread over more than FLAT of their box are the flat directions.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.core import concurrency
from designopt.core.errors import ConfigError
from designopt.problems.base import Problem
from designopt.problems.evaluate import score
from designopt.results.base import SEARCH_LABEL

FRONT_STREAM = 0x46524F4E  # "FRON"
"""A front's re-scoring samples: ``fold_in(key(seed), FRONT_STREAM)``."""
FINAL_STREAM = 0x46494E41  # "FINA"
"""A run's final re-scoring samples: ``fold_in(key(seed), FINAL_STREAM)``."""
STREAMS = {"front": FRONT_STREAM, "final": FINAL_STREAM}
Z = 2.0
"""Two estimates differ when they are more than Z standard errors of their difference
apart (the optimism warning, the runs' agreement, a front's ambiguous pairs)."""
FLAT = 0.10
"""A flat direction: a variable along which the agreeing runs' designs spread over more
than this share of its box."""
MIN_DEFAULT = 30
"""The default re-scoring is 4 × the study's samples, and at least this many."""
BLOCK = 8
"""Designs per scoring call of a quoted number (:func:`blocked`) for a problem scored in
one program (a study with its own block program, ``Problem.staged``, scores in its
blocks): every call holds this many rows, the last one padded with copies of its last
design."""


@dataclasses.dataclass
class Fresh:
    """A re-scoring's plan: the ``section`` (``front`` or ``final``) whose ``n_samples``
    it takes, the config ``cfg`` with that many samples per design (the study's
    ``Cost.samples_key``), the named ``keys`` with ``samples`` the fresh stream, ``n``
    (samples per design) and ``n_search`` (the search's); ``problem`` once built
    (:func:`problem`)."""

    section: str
    cfg: Any
    keys: dict[str, Any]
    n: int
    n_search: int
    problem: Problem | None = None


def samples(job: Any, section: str) -> int:
    """Samples per design of the re-scoring: ``<section>.n_samples`` or 4 × the study's
    own (a final re-scoring: at least :data:`MIN_DEFAULT`)."""
    return _samples(job.cfg, job.study.cost(job.cfg.study), section)


def _samples(cfg: Any, cost: Any, section: str) -> int:
    n = getattr(cfg, section).n_samples
    if n:
        return int(n)
    n = 4 * int(cost.samples)
    return max(n, MIN_DEFAULT) if section == "final" else n


def plan(job: Any, section: str = "front") -> Fresh:
    """The re-scoring of ``section`` for ``job`` (:func:`stream`), cached on the job (a
    sweep's members share it)."""
    cache = job.__dict__.setdefault("_fresh", {})
    if section not in cache:
        cache[section] = stream(job.cfg, job.study, job.keys, section, job.where)
    return cache[section]


def stream(cfg: Any, study: Any, keys: Mapping[str, Any], section: str = "final",
           where: str = "config") -> Fresh:  # fmt: skip
    """The re-scoring of ``section`` for the validated ``cfg`` of ``study`` with the named
    ``keys``: its config (the study's samples key set to ``<section>.n_samples``; a study
    scoring in blocks keeps its chunk, so the re-scoring runs in the search's own block
    program; a normalised objective probes only the fewest designs, as its bounds are
    replaced by the run's) and its keys (``samples``: the fresh stream). A sample count
    the study refuses: ConfigError naming ``<section>.n_samples``."""
    cost = study.cost(cfg.study)
    n = _samples(cfg, cost, section)
    c, n = sized(cfg, cost, n, f"{section}.n_samples", where,
                 norm=section == "final" and cfg.study.pareto is None)  # fmt: skip
    fresh = dict(keys) | {"samples": jax.random.fold_in(jax.random.key(cfg.seed),
                                                        STREAMS[section])}  # fmt: skip
    return Fresh(section, c, fresh, n, int(cost.samples))


def sized(cfg: Any, cost: Any, n: int, key: str, where: str = "config",
          norm: bool = False) -> tuple[Any, int]:  # fmt: skip
    """``cfg`` with ``n`` samples per design (the study's ``Cost.samples_key``; a study
    scoring in blocks keeps its chunk; ``norm``: a normalised objective probes only the
    fewest designs, its bounds being replaced by the run's) and the samples it scores
    (a closed-form study: its own). A count the study refuses: ConfigError naming
    ``key``."""
    from designopt.app import sweeps

    c = cfg
    keep = {cost.chunk_key: int(cost.chunk)} if cost.designs else {}
    if norm and cost.norm_key:
        keep[cost.norm_key] = 2  # the probe's bounds are replaced by the run's: probe little
    if cost.samples > 1:
        try:
            # the study's own checks passed for the run's config: only sample counts differ
            c = sweeps.apply(cfg, {cost.samples_key: n} | keep, where, checks=False)
        except (ValueError, ConfigError) as e:
            why = str(e).removeprefix(where + ": ")
            raise ConfigError(f"{where}: key '{key}': {why}") from None
    else:
        n = int(cost.samples)  # a closed-form study: the same numbers on any samples
    return c, n


def blocked(prob: Problem, X: np.ndarray) -> dict[str, np.ndarray]:
    """Every value of designs X (n, D) on ``prob``, scored in calls of :data:`BLOCK`
    designs (a staged problem: of its own block), each padded with copies of its last
    design: one compiled program for any n, and row i's values those of design i alone."""
    X = np.atleast_2d(np.asarray(X, np.float64))
    B = prob.staged.designs if prob.staged is not None else BLOCK

    def one(i: int) -> dict[str, np.ndarray]:
        Xi = X[i : i + B]
        k = len(Xi)
        if k < B:
            Xi = np.concatenate([Xi, np.repeat(Xi[-1:], B - k, 0)])
        return {key: np.asarray(v)[:k] for key, v in score(prob, Xi, batch=B).items()}

    # the blocks side by side on the CPU's cores (designopt.core.concurrency)
    parts = concurrency.map_calls([functools.partial(one, i) for i in range(0, len(X), B)],
                                  key=("blocked", prob.staged or prob.fn, X.shape[1]))  # fmt: skip
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def problem(job: Any, section: str = "front", like: Problem | None = None) -> Problem:
    """The study's problem on the fresh stream of ``section`` (:func:`plan`); with
    ``like`` (the search's problem) it keeps ``like``'s normalisation: the bounds of a
    weighted objective (``params["bounds"]``, ``norm_bounds``) are the search's, so f is
    the search's function of the indices, on other samples."""
    from designopt.app.job import build_problem

    fr = plan(job, section)
    if fr.problem is None:
        p = build_problem(fr.cfg, fr.keys, job.where, job.dtype)
        if like is not None:
            p = same_normalisation(p, like)
        fr.problem = p
    return fr.problem


def same_normalisation(p: Problem, like: Problem) -> Problem:
    """``p`` with the normalisation bounds of ``like`` (both the study's problem of one
    objective): ``params["bounds"]`` (where ``designopt.problems.normalise`` has studies
    keep them for the trace) and ``norm_bounds`` replaced. A study that archives bounds
    but keeps none in ``params["bounds"]``: ValueError (its fresh f could not be the
    search's function of the indices)."""
    if like.norm_bounds is None:
        return p
    b = np.asarray(like.norm_bounds)
    params = p.params
    if not (isinstance(params, Mapping) and "bounds" in params and "bounds" in like.params):
        raise ValueError("the study's problem archives normalisation bounds but keeps none in "
                         "params['bounds']: its re-scoring cannot keep the run's")  # fmt: skip
    old = jnp.asarray(params["bounds"])
    if old.shape != b.shape:
        raise ValueError(f"normalisation bounds of shape {old.shape}, the run's {b.shape}")
    new = jnp.asarray(like.params["bounds"], old.dtype)
    return dataclasses.replace(p, params=dict(params) | {"bounds": new}, norm_bounds=b)


# ----------------------------------------------------------------------- agreement


def agreement(F: np.ndarray, se: np.ndarray, X: np.ndarray, lower: np.ndarray,
              upper: np.ndarray, ref: int, z: float = Z, flat: float = FLAT
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Which runs agree with run ``ref``: F, se (R, m) the runs' objectives and standard
    errors on one common stream, X (R, D) their designs. Run r agrees when on every
    objective |F[r] − F[ref]| ≤ z √(se[r]² + se[ref]²) (an n/a value, NaN, agrees with
    nothing); ``span`` (D,) is the spread (max − min) of the agreeing designs over the
    box's width, and a variable is flat where it exceeds ``flat``. Returns (agree (R,)
    bool, span (D,), flat (D,) bool)."""
    F, se = np.atleast_2d(np.asarray(F, np.float64)), np.atleast_2d(np.asarray(se, np.float64))
    se = np.nan_to_num(se, nan=0.0)  # an exact objective (a linear one): SE 0
    d = np.abs(F - F[ref])
    tol = z * np.sqrt(se**2 + se[ref] ** 2)
    agree = np.all(d <= tol, axis=-1)
    agree[ref] = True
    Xa = np.asarray(X, np.float64)[agree]
    width = np.asarray(upper, np.float64) - np.asarray(lower, np.float64)
    span = (Xa.max(0) - Xa.min(0)) / width
    return agree, span, span > flat


def compromise(F: np.ndarray, scale: np.ndarray | None = None) -> int:
    """The row of F (n, m), all minimised, nearest the ideal point (each column's
    minimum) in objectives scaled to [0, 1] over ``scale`` (2, m: ideal and nadir; default
    F's own): a front's recommended design. NaN rows come last."""
    F = np.atleast_2d(np.asarray(F, np.float64))
    lo, hi = (np.nanmin(F, 0), np.nanmax(F, 0)) if scale is None else np.asarray(scale)
    span = np.where(hi > lo, hi - lo, 1.0)
    d = np.sqrt(np.sum(((F - lo) / span) ** 2, -1))
    return int(np.argmin(np.where(np.isfinite(d), d, np.inf)))


def runs_group(X: np.ndarray, vals: Mapping[str, np.ndarray], objectives: Sequence[str],
               senses: Sequence[str], ref: int, lower: np.ndarray, upper: np.ndarray,
               names: Sequence[str], fr: Fresh, rule: str) -> dict[str, Any]:  # fmt: skip
    """The archive's ``runs`` group: each run's design ``x`` (R, D) and every index ± SE
    on the common fresh stream, ``agree`` (R,) 0/1, ``span`` (D,) and attrs (the
    reference run, the objectives compared, z, the flat threshold and variables, the
    samples and stream, how each run's design was picked)."""
    F = np.stack([np.asarray(vals[k], np.float64) for k in objectives], -1)
    se = np.stack([np.asarray(vals.get(k + "_se", np.zeros(len(X))), np.float64)
                   for k in objectives], -1)  # fmt: skip
    agree, span, flat = agreement(F, se, X, lower, upper, ref)
    return {"x": np.asarray(X, np.float64), **{k: np.asarray(v) for k, v in vals.items()},
            "agree": agree.astype(np.int8), "span": span,
            "attrs": {"reference": int(ref), "objectives": list(objectives),
                      "senses": list(senses), "z": Z, "flat_share": FLAT,
                      "flat": [n for n, f in zip(names, flat, strict=True) if f],
                      "n_samples": int(fr.n), "stream": fr.section, "pick": rule}}  # fmt: skip


# ------------------------------------------------------------------ a run's final


def optimism(search: Mapping[str, Any], fresh: Mapping[str, Any], keys: Sequence[str],
             n_search: int, n_fresh: int, samples_key: str,
             fidelity: Mapping[str, Any] | None = None) -> list[str]:  # fmt: skip
    """A ``warning:`` line for each of ``keys`` (minimised: f) whose value on the search's
    samples and on the fresh ones differ by more than Z √(se_search² + se_fresh²).
    ``fidelity``: the settings the search scored with instead of the study's
    (``optimizer.fidelity``), which the line then names as part of the gap."""
    out = []
    for k in keys:
        if k not in search or k not in fresh:
            continue
        a, b = float(np.asarray(search[k])), float(np.asarray(fresh[k]))
        sa = float(np.asarray(search.get(k + "_se", 0.0)))
        sb = float(np.asarray(fresh.get(k + "_se", 0.0)))
        s = math.hypot(sa, sb)
        if not all(map(math.isfinite, (a, b, s))):
            continue
        if abs(b - a) <= (Z * s if s > 0 else 1e-12 * max(1.0, abs(a))):
            continue
        apart = f"{abs(b - a) / s:.1f} SE apart (> {Z:g})" if s > 0 else "apart, with no SE"
        how = (
            "optimistic: the search kept the design its own samples favoured most"
            if a < b
            else "pessimistic: its samples were unkind to this design"
        )
        if fidelity:
            sets = ", ".join(f"{k}={v}" for k, v in fidelity.items())
            how = (f"{'optimistic' if a < b else 'pessimistic'}: the search scored with "
                   f"optimizer.fidelity ({sets}), so the gap holds what those settings "
                   "change as well as its samples' luck")  # fmt: skip
        out.append(f"{k} = {b:.5g} ± {sb:.2g} on {n_fresh} fresh samples per design, "
                   f"{a:.5g} ± {sa:.2g} {SEARCH_LABEL} ({n_search}): {apart}; the "
                   f"search's value is {how}; the fresh value is quoted (more samples, "
                   f"{samples_key}, narrow the gap)")  # fmt: skip
    return out


def final_groups(job: Any, problem: Problem, res: Any, groups: dict[str, Any],
                 ref: int | None = None) -> dict[str, Any]:  # fmt: skip
    """A run's groups (``scoring.run_groups``, the final design on the search's samples)
    with the final design re-scored on the fresh ``final`` stream (one batched call with
    every run's best design when ``optimizer.n_runs`` ≥ 2): ``final`` holds the fresh
    values, ``best_run/final`` the search's (``SEARCH_LABEL``), ``runs`` each run's
    design on the common stream with the agreement; the optimism lines go to
    ``final`` attrs ``optimism`` (the caller adds them to its warnings). ``ref``: the
    best run (default ``best_run`` attrs ``run_index``)."""
    fr = plan(job, "final")
    fresh = problem_for(job, problem)
    fin = groups["final"]
    x_final = np.asarray(fin["x"], np.float64)
    R = int(np.shape(res.best_x)[0])
    runs = R >= 2
    best = np.array(res.best_x, np.float64)
    pick = "each run's best design (optimizer/best_x)"
    pol = groups.get("refine")
    if runs and pol is not None and pol["attrs"].get("method") == "compass":
        # the polished designs stand for their runs (a compass step is never worse)
        best[np.asarray(pol["run_index"], np.int64)] = pol["x"]
        pick += ", polished by a compass search on the search's samples (refine)"
    X = np.concatenate([best, x_final[None]]) if runs else x_final[None]
    vals = blocked(fresh, X)  # the one scoring of quoted numbers (eval --fresh's)
    own = {k: v for k, v in fin.items() if k not in ("x", "attrs")}  # the search's values
    at = dict(fin.get("attrs", {}))
    fid = dict(job.cfg.optimizer.fidelity)
    search_at = {"samples": SEARCH_LABEL, "n_samples": int(problem.n_samples_used),
                 "stage": at.get("stage", "optimizer")}  # fmt: skip
    if fid:  # the settings the search scored with (archived as JSON)
        search_at["fidelity"] = json.dumps(fid)
    groups["best_run"]["final"] = own | {"attrs": search_at}
    new = {k: v[-1] for k, v in vals.items()}
    at |= {"n_samples_used": int(fresh.n_samples_used or fr.n), "samples": "fresh",
           "stream": "final", "n_samples_search": int(problem.n_samples_used)}  # fmt: skip
    cost = job.study.cost(job.cfg.study)
    at["optimism"] = optimism(own, new, ["f"], int(problem.n_samples_used),
                              at["n_samples_used"], cost.samples_key, fid)  # fmt: skip
    groups["final"] = new | {"x": x_final, "attrs": at}
    if runs:
        ref = int(groups["best_run"]["attrs"]["run_index"]) if ref is None else ref
        groups["runs"] = runs_group(X[:R], {k: v[:R] for k, v in vals.items()}, ["f"], ["min"],
                                    ref, problem.lower, problem.upper, problem.names, fr,
                                    pick)  # fmt: skip
        groups["runs"]["attrs"]["n_samples"] = at["n_samples_used"]
    return groups


def problem_for(job: Any, like: Problem) -> Problem:
    """The fresh ``final`` problem of ``job``, keeping ``like``'s normalisation."""
    return problem(job, "final", like)


def front_picks(res: Any) -> tuple[np.ndarray, np.ndarray]:
    """Each run's recommended design of a front run (one or more runs): the
    compromise (:func:`compromise`) of the run's own non-dominated final population
    (among its feasible designs when it has any, else its least violating, as the pooled
    front picks), its objectives on the search's samples scaled by the ideal and nadir of
    all runs' non-dominated sets together. Returns (X (R, D), that scale (2, m):
    ideal and nadir, minimised)."""
    from designopt.numerics import pareto

    pop = res.front
    R, P, m = np.shape(pop.f)
    F = np.asarray(pop.f, np.float64)  # minimised space
    V = np.asarray(pop.v, np.float64).reshape(R, P)
    Xp = np.asarray(pop.x, np.float64).reshape(R, P, -1)
    nd = []
    for r in range(R):
        pool = (
            np.flatnonzero(V[r] <= 0) if np.any(V[r] <= 0) else np.flatnonzero(V[r] == V[r].min())
        )
        nd.append(pool[pareto.non_dominated(F[r, pool])])
    allF = np.concatenate([F[r, nd[r]] for r in range(R)])
    scale = np.stack([np.nanmin(allF, 0), np.nanmax(allF, 0)])
    rows = np.array([nd[r][compromise(F[r, nd[r]], scale)] for r in range(R)])
    return Xp[np.arange(R), rows], scale
