"""Every number a run quotes, from one place (issue #65, items 3-5).

A run's final values (and each run's best design), a front's re-scored designs (and each
run's recommended design), ``designopt eval --fresh``, the archive and the HTML report,
which reads the archive, all come from :func:`score`: the designs scored with the
config's own study settings (never ``optimizer.fidelity``'s) on the run kind's fresh
stream (:func:`section`: ``final`` for a weighted or constrained run, ``front`` for a
Pareto front; ``designopt.app.rescoring.plan``), in calls of a fixed number of designs
(:func:`blocked`), so a design's values do not depend on which designs were scored
beside it: ``eval --fresh`` of one design gives the quoted numbers bit for bit.

Every ``warning:`` said of a scored design, whatever the run kind (the final design of a
weighted or constrained run or of a sweep's member, each design of a front, each design
of ``eval``), is decided by :func:`warnings`: the study's lines on its values
(``Study.warnings``), a line for each n/a index (``results.base.na_warnings``), the
IK coverage's (the study's ``targets`` hook, attr ``warnings``) and the caller's own
(a final design's optimism lines). :func:`coverage` gives a design's IK coverage figure
(a task's: ``ik_better``, its summary ``lines`` and ``warnings``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.app import rescoring
from designopt.problems.base import Problem
from designopt.results.base import na_warnings

BLOCK = rescoring.BLOCK
blocked = rescoring.blocked
"""Every value of designs on a problem, in calls of a fixed number of designs
(``rescoring.blocked``): the scoring of every quoted number."""


def section(cfg: Any) -> str:
    """The fresh stream a run of ``cfg`` quotes its values on: ``front`` for a Pareto
    front (``front.n_samples``), else ``final`` (``final.n_samples``)."""
    return "front" if getattr(cfg.study, "pareto", None) is not None else "final"


def problem(job: Any, like: Problem | None = None) -> Problem:
    """The study's problem (the config's own settings) on the quoted stream of ``job``'s
    run kind; ``like``: the search's problem, whose normalisation a weighted objective
    keeps (``rescoring.problem``)."""
    sec = section(job.cfg)
    return rescoring.problem(job, sec, like if sec == "final" else None)


def score(job: Any, X: np.ndarray, like: Problem | None = None) -> dict[str, np.ndarray]:
    """The quoted values of designs X (n, D) of ``job``: :func:`blocked` on
    :func:`problem` (the config's own settings, the run kind's fresh stream)."""
    return blocked(problem(job, like), X)


def stream(job: Any) -> rescoring.Fresh:
    """The quoted stream's plan (its config, keys and samples per design)."""
    return rescoring.plan(job, section(job.cfg))


def coverage(job: Any, settings: Any, x: np.ndarray, keys: Mapping[str, Any]) -> dict[str, Any]:
    """The IK coverage figure of design ``x`` (D,) on the samples of ``keys`` with the
    study settings ``settings`` (the study's ``targets`` hook for one design: attrs
    ``ik_better``, ``ik_better_n``, ``lines``, ``warnings``); {} for a study or a
    measure without one."""
    return coverages(job, settings, np.asarray(x, np.float64)[None], keys)[0]


def coverages(job: Any, settings: Any, X: np.ndarray, keys: Mapping[str, Any]
              ) -> list[dict[str, Any]]:  # fmt: skip
    """:func:`coverage` of designs X (P, D), all from one call of the study's ``targets``
    hook (its IK solves every design in one batch)."""
    X = np.atleast_2d(np.asarray(X, np.float64))
    if job.study.targets is None:
        return [{} for _ in X]
    tg = job.study.targets(settings, X if len(X) > 1 else X[0], keys, job.dtype)
    return read_coverages(tg, len(X))


def read_coverages(tg: Mapping[str, Any] | None, n: int) -> list[dict[str, Any]]:
    """The IK coverage figures of ``n`` designs as :func:`coverage` gives them, read from
    the study's ``targets`` answer for them ``tg`` (a front's archived ``targets`` group:
    no solve); {} for each where it holds none."""
    at = dict((tg or {}).get("attrs", {}))
    if "ik_better" not in at:
        return [{} for _ in range(n)]
    if n == 1 and "coverage_lines" not in at:  # one design's attrs
        out = {k: at[k] for k in ("ik_better", "ik_better_n")}
        for k in ("lines", "warnings"):
            v = at.get(k, [])
            out[k] = [v] if isinstance(v, str) else [str(w) for w in v]
        return [out]
    share = np.atleast_1d(np.asarray(at["ik_better"], np.float64))
    lines, warns = list(at["coverage_lines"]), list(at["coverage_warnings"])
    return [{"ik_better": float(share[i]), "ik_better_n": float(at["ik_better_n"]),
             "lines": [str(lines[i])], "warnings": [str(warns[i])] if warns[i] else []}
            for i in range(n)]  # fmt: skip


def warnings(job: Any, values: Mapping[str, Any], x: Any = None,
             cover: Mapping[str, Any] | None = None, extra: Sequence[str] = ()) -> list[str]:  # fmt: skip
    """The ``warning:`` lines of one scored design, for every run kind: the study's on
    its ``values`` (``Study.warnings``; ``x``: the design, which some lines read), a line
    for each n/a index no study line speaks of, ``extra`` (a final design's optimism
    lines) and the IK coverage's (``cover``: :func:`coverage`, or a ``targets`` group's
    attrs)."""
    vals = dict(values)
    if x is not None:
        vals["x"] = np.asarray(x, np.float64)
    own = list(job.study.warnings(job.cfg.study, vals))
    if section(job.cfg) == "front":  # a front's weighted f is moot: no line of it
        own = [w for w in own if not w.startswith("f: ")]
    cw = (cover or {}).get("warnings", [])
    return na_warnings(vals, own) + list(extra) + ([cw] if isinstance(cw, str) else list(cw))


def grouped(per_design: Sequence[Sequence[str]], label: str = "design") -> list[str]:
    """One line for each distinct warning of several designs (a front's), naming the
    designs it concerns (``#i``, their rows), in the order first said."""
    seen: dict[str, list[int]] = {}
    for i, ws in enumerate(per_design):
        for w in ws:
            seen.setdefault(w, []).append(i)
    out = []
    for w, rows in seen.items():
        who = ", ".join(f"#{i}" for i in rows)
        many = "s" if len(rows) > 1 else ""
        out.append(f"{label}{many} {who}: {w}")
    return out
