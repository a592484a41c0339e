"""The final stage: candidate layouts raced on a validation stream (``final.race``; issue
#66, docs/planning.md "The final stage").

A search ends with candidate designs scored on its own samples. With ``final.race: true``
they are scored again, stage by stage, on a validation stream the search never saw, and
:func:`designopt.numerics.racing.race` decides which is best, which are equal for a
surgeon (within ``final.margin``) and which are worse:

- **Candidates** (:func:`front_candidates`, :func:`run_candidates`): a front's
  non-dominated final-population designs of every run, each run's recommended design and
  the polished ones; a weighted or constrained run's best few designs of each run (the
  last :data:`BEST_PER_RUN` best-so-far designs, feasible first) and the polished ones.
  Ordered by the search's values (the best first) and cleared with ``final.radius``
  (``racing.clear``); at most :data:`MAX_CANDIDATES` (a front's thinned by crowding).
- **The validation stream**: ``fold_in(key(final.seed), VALIDATION_STREAM)``, which
  depends on ``final.seed`` alone (not on ``seed`` or ``--seed``): runs at any seed judge
  their candidates on the same targets. Stage s draws ``final.stage`` samples from
  ``fold_in(that key, s)`` (targets, FK database and IK seeds all come from the study's
  ``samples`` key) and scores the active candidates with the study's own settings in
  the quoted path's blocks (``quoted.blocked``): one stage is one i.i.d. replication, the
  same for every candidate (common random numbers within a stage). The race's unit is
  the stage: its per-candidate objective means, so the SE from the stage means is honest
  whatever the per-target SE, and the tests use Student's t with (stages − 1) degrees of
  freedom. A share constraint (``{index: instrument_ok, ge: 0.5}``) is counted per stage
  (successes of the stage's samples) and read from its Wilson interval. At most
  ``final.max_samples // final.stage`` stages (at least 2).
- **Margins**: ``final.margin_of(name, share=...)`` per objective (a share's default
  0.02, another index's 0.01).

The answer is the archive's ``verdict`` group (:func:`group`, docs/archive.md), printed in
the summary and shown in the HTML report. A tied set's note lists the variables in which
its layouts differ and names the pairs that are mirror images under the symmetry the
arms' entries show (:func:`mirror_pairs`: two arms mirrored by the sign of one axis; the
scene itself is taken to share it, not checked).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from designopt.app import quoted
from designopt.app import rescoring as rs
from designopt.core import concurrency
from designopt.core.errors import ConfigError
from designopt.numerics import pareto, racing

VALIDATION_STREAM = 0x56414C49  # "VALI"
"""The validation stream: ``fold_in(key(final.seed), VALIDATION_STREAM)``, then the stage."""
MAX_CANDIDATES = 12
"""At most this many candidates enter the race (a front's thinned by crowding)."""
BEST_PER_RUN = 8
"""A weighted or constrained run's candidates: the last this many best-so-far designs of
each run (the best few by the search's own ranking)."""


# ------------------------------------------------------------------------- checks


def objectives(cfg: Any) -> tuple[list[str], list[str]]:
    """The race's objectives and their senses: a front's (``study.objective.pareto``),
    else the weighted or constrained f (minimised)."""
    front = getattr(cfg.study, "pareto", None)
    if front is not None:
        from designopt.app.config import senses

        return list(front), list(senses(front).values())
    return ["f"], ["min"]


def n_stages(cfg: Any) -> int:
    """The race's cap in stages: ``final.max_samples // final.stage``."""
    return int(cfg.final.max_samples) // int(cfg.final.stage)


def check(job: Any) -> None:
    """Refuse, before any work, what the race cannot run with: a ``final.margin`` name
    that is no objective or index of the study (ConfigError naming
    ``final.margin.<name>``), a cap of fewer than 2 stages. Nothing with the race off."""
    cfg, where = job.cfg, job.where
    if not getattr(cfg.final, "race", False):
        return
    m = cfg.final.margin
    if isinstance(m, dict):
        variables = set(job.problem.names)
        known = (set(objectives(cfg)[0]) | set(job.study.units(cfg.study)) | {"f"}) - variables
        for k in m:
            if k not in known:
                raise ConfigError(f"{where}: key 'final.margin.{k}': not an index of this study; "
                                  f"its indices: {sorted(known)}")  # fmt: skip
    if n_stages(cfg) < 2:
        raise ConfigError(f"{where}: key 'final.max_samples': {cfg.final.max_samples} holds "
                          f"{n_stages(cfg)} stage(s) of final.stage = {cfg.final.stage}; the race "
                          "needs at least 2 (a paired SE from stage means)")  # fmt: skip


# ----------------------------------------------------------------- the validation stream


def validation_key(cfg: Any) -> jax.Array:
    """The validation stream's key: ``final.seed`` alone, folded with its own constant."""
    return jax.random.fold_in(jax.random.key(int(cfg.final.seed)), VALIDATION_STREAM)


def stage_problem(job: Any, s: int, like: Any = None) -> Any:
    """The study's problem (its own settings, ``final.stage`` samples per design) on stage
    ``s`` of the validation stream; ``like``: the search's problem, whose normalisation a
    weighted objective keeps."""
    from designopt.app.job import build_problem

    cfg = job.cfg
    cost = job.study.cost(cfg.study)
    c, _ = rs.sized(cfg, cost, int(cfg.final.stage), "final.stage", job.where,
                    norm=getattr(cfg.study, "pareto", None) is None)  # fmt: skip
    keys = dict(job.keys) | {"samples": jax.random.fold_in(validation_key(cfg), int(s))}
    p = build_problem(c, keys, job.where, job.dtype)
    return rs.same_normalisation(p, like) if like is not None and cfg.study.pareto is None else p


# ------------------------------------------------------------------------- candidates


def _ordered(X: np.ndarray, F: np.ndarray, V: np.ndarray, first: np.ndarray | None = None
             ) -> np.ndarray:  # fmt: skip
    """Priority order: feasible first, then by the search's (minimised) objectives; the
    rows ``first`` (the runs' recommended or polished designs) lead their ties."""
    F = np.nan_to_num(np.asarray(F, np.float64), nan=np.inf)
    lead = np.zeros(len(X)) if first is None else -np.asarray(first, np.float64)
    keys = [lead, *F.T[::-1], (np.asarray(V) > 0).astype(float)]
    return np.lexsort(keys)


def front_candidates(res: Any, keep: np.ndarray, X_runs: np.ndarray | None = None,
                     F_runs: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """A front's candidates: every run's non-dominated final-population designs (``keep``,
    indices into the pooled final populations: ``fronts.candidates``) and each run's
    recommended (or polished) design ``X_runs`` with its search objectives ``F_runs``
    (minimised); (X, F) in priority order, not yet cleared."""
    m = np.shape(res.front.f)[-1]
    D = np.shape(res.front.x)[-1]
    X = np.asarray(res.front.x, np.float64).reshape(-1, D)[keep]
    F = np.asarray(res.front.f, np.float64).reshape(-1, m)[keep]
    V = np.asarray(res.front.v, np.float64).reshape(-1)[keep]
    first = np.zeros(len(X))
    if X_runs is not None and F_runs is not None:
        X = np.concatenate([X, X_runs])
        F = np.concatenate([F, F_runs])
        V = np.concatenate([V, np.zeros(len(X_runs))])
        first = np.concatenate([first, np.ones(len(X_runs))])
    if len(X) > MAX_CANDIDATES:  # thin the search's non-dominated set by crowding
        rest = np.flatnonzero(first == 0)
        n_keep = max(MAX_CANDIDATES - int(first.sum()), 2)
        kept = rest[pareto.thin(F[rest], n_keep)]
        sel = np.sort(np.concatenate([kept, np.flatnonzero(first > 0)]))
        X, F, V, first = X[sel], F[sel], V[sel], first[sel]
    order = np.lexsort([*F.T[::-1], (V > 0).astype(float)])
    return X[order], F[order]


def run_candidates(res: Any, groups: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """A weighted or constrained run's candidates: the last :data:`BEST_PER_RUN`
    distinct best-so-far designs of each run (``history_x``, the best few by the search's
    own ranking), feasible first, and the polished designs (``refine``); (X, f) in
    priority order (the search's f, feasible first), not yet cleared."""
    H = np.asarray(res.history_x, np.float64)  # (R, T+1, D)
    f = np.asarray(res.history, np.float64)  # (R, T+1)
    v = (np.zeros_like(f) if res.history_v is None else np.asarray(res.history_v, np.float64))
    R, T1, D = H.shape
    Xs, fs, vs = [], [], []
    for r in range(R):
        _, first = np.unique(H[r], axis=0, return_index=True)
        rows = np.sort(first)[-BEST_PER_RUN:]
        Xs.append(H[r, rows])
        fs.append(f[r, rows])
        vs.append(v[r, rows])
    X, F, V = np.concatenate(Xs), np.concatenate(fs), np.concatenate(vs)
    pol = groups.get("refine")
    if pol is not None and "x" in pol:
        px = np.atleast_2d(np.asarray(pol["x"], np.float64))
        pf = np.asarray(pol.get("f", np.full(len(px), -np.inf)), np.float64).reshape(-1)
        if pf.size != len(px):
            pf = np.full(len(px), -np.inf)
        X, F, V = np.concatenate([X, px]), np.concatenate([F, pf]), np.concatenate(
            [V, np.zeros(len(px))])
    order = np.lexsort([F, (V > 0).astype(float)])
    return X[order][: 4 * MAX_CANDIDATES], F[order][: 4 * MAX_CANDIDATES]


# ------------------------------------------------------------------------- the race


def _constraints(cfg: Any) -> list[tuple[str, float, str]]:
    """The study's index constraints: (index, bound, sense)."""
    out = []
    for c in getattr(cfg.study, "constraints", None) or []:
        idx = getattr(c, "index", None)
        if idx is None:
            continue
        out.append((str(idx), float(c.ge if c.ge is not None else c.le),
                    ">=" if c.ge is not None else "<="))  # fmt: skip
    return out


def _counts(vals: dict[str, np.ndarray], k: str, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The (successes, trials) of a share index ``k``: its ``_n``/``_of`` counts, else
    value × n when every value is a multiple of 1/n (a share of the stage's n samples);
    None for an index that is no share."""
    if k + "_n" in vals and k + "_of" in vals:
        return np.asarray(vals[k + "_n"], np.float64), np.asarray(vals[k + "_of"], np.float64)
    v = np.asarray(vals.get(k), np.float64)
    if v is None or not np.all(np.isfinite(v)):
        return None
    kk = v * n
    if np.all(np.abs(kk - np.round(kk)) < 1e-6 * max(n, 1)) and np.all((v >= 0) & (v <= 1)):
        return np.round(kk), np.full(len(v), float(n))
    return None


def race_candidates(job: Any, X: np.ndarray, like: Any = None,
                    stage_fn: Callable[[int, np.ndarray], dict[str, np.ndarray]] | None = None,
                    sources: list[str] | None = None, per_call: int | None = None
                    ) -> dict[str, Any]:  # fmt: skip
    """Race the (cleared) candidates X (C, D) on the validation stream and return the
    archive's ``verdict`` group (:func:`group`). ``like``: the search's problem (a
    weighted objective's normalisation); ``stage_fn(s, X_active)``: every value of the
    active designs on stage s (default: ``quoted.blocked`` on :func:`stage_problem`,
    whose calls hold a block of designs each); ``per_call``: the designs one call of a
    given ``stage_fn`` holds (None: its stages are drawn one at a time, when asked)."""
    cfg = job.cfg
    names, sens = objectives(cfg)
    front = cfg.study.pareto is not None
    n = int(cfg.final.stage)
    cost = job.study.cost(cfg.study)
    if cost.samples <= 1:
        n = int(cost.samples)

    S = n_stages(cfg)
    width = concurrency.threads()  # calls at once (1 inside a worker thread)
    if stage_fn is None:
        p0 = stage_problem(job, 0, like)
        B = p0.staged.designs if p0.staged is not None else rs.BLOCK  # designs per call

        def stage_fn(s: int, Xa: np.ndarray) -> dict[str, np.ndarray]:
            return quoted.blocked(p0 if s == 0 else stage_problem(job, s, like), Xa)

    else:
        B = per_call

    def ahead(c: int) -> int:  # stages drawn at once: a stage of c designs is ⌈c / B⌉
        return 1 if B is None else max(1, width // -(-c // B))  # calls; width at once

    cons = _constraints(cfg)
    # stage → (the designs it was drawn for, their values). A stage is drawn ahead, beside
    # the one the race asks for, where a core would otherwise idle (a stage of at most B
    # designs is one call, on one core); the race then reads it for the designs still
    # active. A design's values do not depend on the others drawn with it (the blocks'
    # rows are independent), so the race decides as if each stage were drawn when asked;
    # a stage drawn ahead that the race does not reach is dropped.
    cache: dict[int, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    share_cons: list[tuple[str, float, str]] = []

    def draw(stages: list[int], active: np.ndarray) -> None:
        got = concurrency.map_calls([functools.partial(stage_fn, s, X[active]) for s in stages])
        for s, v in zip(stages, got, strict=True):
            cache[s] = (active, {k: np.asarray(a) for k, a in v.items()})

    def values(s: int, active: np.ndarray) -> dict[str, np.ndarray]:
        drawn, vals = cache.pop(s)
        if np.array_equal(drawn, active):
            return vals
        pos = np.searchsorted(drawn, active)  # the race's active designs only shrink
        return {k: v[pos] for k, v in vals.items()}

    t_first = time.perf_counter()
    draw(list(range(min(S, max(2, ahead(len(X)))))), np.arange(len(X)))  # the first call: 2
    first = cache[0][1]
    t_first = time.perf_counter() - t_first
    for k, b, sn in cons:  # which constraints are shares (counted per stage)
        if k in first and _counts(first, k, n) is not None:
            share_cons.append((k, b, sn))
    shares = {k for k in names if _counts(first, k, n) is not None}
    margin = [cfg.final.margin_of(k, share=k in shares) for k in names]
    maximize = [s == "max" for s in sens]

    def unit(s: int, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stage s (one unit of the race): the objectives' means (C_active, m), each share
        constraint's successes and trials (C_active, n_con)."""
        vals = values(s, active)
        cols = []
        for k, mx in zip(names, maximize, strict=True):
            v = np.asarray(vals[k], np.float64).copy()
            bad = ~np.isfinite(v)
            if bad.any():  # an n/a value (too few items): at its worst among the stage's
                ok = v[~bad]
                v[bad] = (ok.min() if mx else ok.max()) if ok.size else 0.0
            cols.append(v)
        cnt = [_counts(vals, k, n) for k, _, _ in share_cons]
        succ = np.stack([c[0] if c is not None else np.zeros(len(active)) for c in cnt]
                        + [np.zeros(len(active))], -1)[:, :-1]  # fmt: skip
        tri = np.stack([c[1] if c is not None else np.full(len(active), float(n)) for c in cnt]
                       + [np.zeros(len(active))], -1)[:, :-1]  # fmt: skip
        return np.stack(cols, -1), succ, tri

    def sample_fn(active: np.ndarray, st: racing.Stage) -> racing.Draw:
        need = [s for s in range(st.start, st.stop) if s not in cache]
        if need:  # with the stages after them that idle cores can draw beside them
            more = range(st.stop, min(S, st.stop + ahead(len(active)) - len(need)))
            draw([*need, *more], active)
        got = [unit(s, active) for s in range(st.start, st.stop)]
        V = np.stack([g[0] for g in got], 1)  # (C_active, units, m)
        if not share_cons:
            return racing.Draw(V)
        return racing.Draw(V, sum(g[1] for g in got), sum(g[2] for g in got))

    t0 = time.perf_counter()
    rr = racing.race(sample_fn, len(X), margin=margin, max_samples=S, stage=1, first=2,
                     alpha=float(cfg.final.alpha), maximize=maximize, primary=0,
                     bound=[b for _, b, _ in share_cons] or None,
                     sense=[sn for _, _, sn in share_cons] or ">=", student=True)  # fmt: skip
    g = group(job, X, rr, names, sens, share_cons, n, sources, front)
    # an index constraint that is no share of the stage's samples is not counted by the race
    raced = {c for c, _, _ in share_cons}
    g["attrs"]["constraints_not_raced"] = [k for k, _, _ in cons if k not in raced]
    g["attrs"]["wall_s"] = time.perf_counter() - t0 + t_first  # the race's scoring and decisions
    return g


def group(job: Any, X: np.ndarray, rr: racing.RaceResult, names: list[str], sens: list[str],
          share_cons: list[tuple[str, float, str]], n: int, sources: list[str] | None,
          front: bool) -> dict[str, Any]:  # fmt: skip
    """The archive's ``verdict`` group of a race ``rr`` over candidates X (C, D)."""
    from designopt.app.scoring import placement, with_placement

    cfg = job.cfg
    lo, hi = np.asarray(job.problem.lower, np.float64), np.asarray(job.problem.upper, np.float64)
    C = len(X)
    # each objective's two-sided interval at the race's alpha: Student's t of the stage means
    half = np.array([[racing.t_ppf(1 - rr.alpha / 2, max(int(k) - 1, 1)) for _ in names]
                     for k in rr.n_samples]) * rr.se  # fmt: skip
    tied = list(rr.tied)
    one_group = rr.summary.startswith("a tied set")
    note = ""
    sym = mirror_pairs(cfg, list(job.problem.names))
    if one_group and len(tied) > 1:
        note = racing.tie_note(X[tied], list(job.problem.names), lo, hi,
                               pairs=sym[0] if sym else None,
                               labels=[f"#{i}" for i in tied])  # fmt: skip
        if sym and "mirror images" in note:
            note += f" (under {sym[1]})"
    g: dict[str, Any] = {
        "x": np.asarray(X, np.float64),
        "mean": rr.mean, "se": rr.se, "half": half, "diff": rr.diff, "diff_se": rr.diff_se,
        "share": rr.share, "share_lo": rr.share_lo, "share_hi": rr.share_hi,
        "status": np.asarray(rr.status, dtype="S").reshape(C, -1),
        "verdict": np.asarray(rr.verdict, dtype="S"),
        "why": np.asarray(rr.why, dtype="S"),
        "settled": rr.settled.astype(np.int8),
        "n_stages": rr.n_samples.astype(np.int64),
        "n_samples": (rr.n_samples * n).astype(np.int64),
        "attrs": {"objectives": names, "senses": sens,
                  "constraints": [k for k, _, _ in share_cons],
                  "bounds": [b for _, b, _ in share_cons],
                  "constraint_senses": [s for _, _, s in share_cons],
                  "best": int(rr.best), "tied": tied, "summary": rr.summary,
                  "tie_note": note, "reason": rr.reason, "looks": int(rr.n_stages),
                  "alpha": float(rr.alpha), "z": float(rr.z),
                  "margin": [float(x) for x in rr.margin], "seed": int(cfg.final.seed),
                  "stage": int(n), "max_samples": int(cfg.final.max_samples),
                  "radius": float(cfg.final.radius), "stream": "validation",
                  "sources": list(sources or []), "front": bool(front),
                  "mirror": (f"{sym[1]}: " + ", ".join(f"{a} → {b}" for a, b in sym[0])
                             if sym else "none detected")},
    }  # fmt: skip
    with_placement(g, placement(job.study, cfg.study, X), None)
    return g


AXES = "xyz"


def _entries(arm: Any) -> list[Any] | None:
    """An arm's port entries, then its base position entries (None where it has none)."""
    d = arm.model_dump() if hasattr(arm, "model_dump") else dict(arm)
    port, base = d.get("port"), (d.get("base") or {}).get("xyz")
    if port is None or base is None:
        return None
    return [*port, *base]


def mirror_pairs(cfg: Any, names: list[str]) -> tuple[list[tuple[str, str]], str] | None:
    """The mirror symmetry the config shows (documented, simple): two arms whose port and
    base position entries agree slot by slot up to the sign of one axis (``-b`` and
    ``b``, ``-px`` and ``px``; numbers equal up to sign) are mirror images under the
    reflection of that axis with the arms trading places; a slot holding two different
    variables (``py0`` and ``py1``) makes them trade places in the image. Returns
    (``racing.mirror``'s pairs, the reflection, e.g. "x → −x") or None: fewer or more
    than two arms, or entries that do not match so. Only the arms' entries are read: the
    scene (the wall, the obstacles, the task region) is taken to share the symmetry, not
    checked."""
    arms = getattr(cfg.study, "arms", None)
    if not arms or len(arms) != 2:
        return None
    e0, e1 = _entries(arms[0]), _entries(arms[1])
    if e0 is None or e1 is None or len(e0) != len(e1) or len(e0) != 6:
        return None
    flipped: set[int] = set()
    pairs: dict[str, str] = {}
    for slot, (a, b) in enumerate(zip(e0, e1, strict=True)):
        ax = slot % 3
        if isinstance(a, str) and isinstance(b, str):
            na, nb = a.lstrip("-+ "), b.lstrip("-+ ")
            if na not in names or nb not in names:
                return None
            if a.startswith("-") != b.startswith("-"):
                flipped.add(ax)
            if na != nb:
                pairs[na], pairs[nb] = nb, na
        elif not isinstance(a, str) and not isinstance(b, str):
            if abs(float(a)) != abs(float(b)):
                return None
            if float(a) != float(b):
                flipped.add(ax)
        else:
            return None
    if len(flipped) != 1 or not all(pairs.get(v) == k for k, v in pairs.items()):
        return None
    ax = AXES[flipped.pop()]
    return sorted(pairs.items()), f"{ax} → −{ax}, the arms trading places"


def clear(job: Any, X: np.ndarray) -> np.ndarray:
    """The candidates X (priority order) cleared with ``final.radius``: those left."""
    keep, _ = racing.clear(X, job.problem.lower, job.problem.upper, float(job.cfg.final.radius))
    return X[keep][:MAX_CANDIDATES]


def survivors(g: dict[str, Any]) -> np.ndarray:
    """Rows of the verdict group not judged worse (the best first, then the others in
    their order)."""
    v = np.asarray(g["verdict"]).astype(str)
    rows = [int(i) for i in g["attrs"]["tied"]]
    return np.asarray(rows + [i for i in np.flatnonzero(v != "worse") if i not in rows], np.int64)


def best_x(g: dict[str, Any]) -> np.ndarray:
    """The race's best design."""
    return np.asarray(g["x"], np.float64)[int(g["attrs"]["best"])]


def samples_text(g: dict[str, Any]) -> str:
    """How many validation samples a race used (for a line of the summary)."""
    ns = np.asarray(g["n_samples"])
    return f"{int(ns.min())}–{int(ns.max())}" if ns.min() != ns.max() else f"{int(ns.max())}"


__all__ = ["VALIDATION_STREAM", "check", "clear", "front_candidates", "race_candidates",
           "run_candidates", "stage_problem", "validation_key"]  # fmt: skip
