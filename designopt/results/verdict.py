"""The final stage's verdict table, as text (``verdict`` group; designopt.app.verdict,
docs/planning.md "The final stage")."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.results.base import names as _names


def _strs(a: Any) -> np.ndarray:
    return np.vectorize(lambda v: v.decode() if isinstance(v, bytes) else str(v),
                        otypes=[object])(np.asarray(a))  # fmt: skip


def lines(g: Mapping[str, Any] | None, variables: Sequence[str],
          units: Mapping[str, str] | None = None) -> list[str]:  # fmt: skip
    """The verdict table: one row per candidate (its variables, each objective ± its
    interval, the paired difference from the best ± SE, each share constraint's status,
    validation samples used, verdict), then where each candidate puts the robot (the
    study's placement), then ONE line: the race's summary with the tie note. [] without
    a verdict."""
    if not g:
        return []
    at = g["attrs"]
    objs = _names(at["objectives"])
    cons = _names(at.get("constraints", []))
    X = np.atleast_2d(np.asarray(g["x"], np.float64))
    mean, half = np.asarray(g["mean"], np.float64), np.asarray(g["half"], np.float64)
    diff, dse = np.asarray(g["diff"], np.float64), np.asarray(g["diff_se"], np.float64)
    verdict = _strs(g["verdict"])
    status = _strs(g["status"]).reshape(len(X), -1) if cons else np.zeros((len(X), 0), object)
    ns = np.asarray(g["n_samples"], np.int64)
    settled = np.asarray(g.get("settled", np.ones(len(X))), bool)
    units = dict(units or {})
    head = ["  #"] + [f"{v:>9}" for v in variables]
    for k in objs:
        u = units.get(k, "-")
        lab = k if u in ("-", "") else f"{k} [{u}]"
        head += [f"{lab:>19}", f"{'Δ ' + k + ' (± SE)':>21}"]
    head += [f"{c:>13}" for c in cons] + [f"{'samples':>7}", "verdict"]
    rows = []
    for i in range(len(X)):
        r = [f"{i:3d}"] + [f"{x:9.4g}" for x in X[i]]
        for j in range(len(objs)):
            r.append(f"{mean[i, j]:9.4f} ± {half[i, j]:7.4f}")
            r.append(f"{diff[i, j]:+10.4f} ± {dse[i, j]:8.4f}")
        r += [f"{str(status[i, c]):>13}" for c in range(len(cons))]
        unsettled = str(verdict[i]) == "equivalent" and not settled[i]
        r += [f"{int(ns[i]):7d}", str(verdict[i]) + ("*" if unsettled else "")]
        rows.append("  ".join(r))
    out = [f"the final stage: {len(X)} candidate layouts raced on the validation stream "
           f"(final.seed = {at['seed']}, {at['stage']} samples a stage, at most "
           f"{at['max_samples']}; margins "
           + ", ".join(f"{k} {m:g}" for k, m in zip(objs, at["margin"], strict=True))
           + f"; ± the {100 * (1 - float(at['alpha'])):g} % interval of the stage means)"]  # fmt: skip
    out += ["  " + "  ".join(head)] + ["  " + r for r in rows]
    # where each candidate puts the robot: the study's placement of points (e.g. a chain's
    # ports and bases; not the design's own points, which its variables give)
    place = [k for k in _names(at.get("placement", [])) if k in g and not k.endswith("_points")
             and np.ndim(g[k]) == 3]  # fmt: skip
    for i in range(len(X)):
        parts = []
        for k in place:
            a = np.asarray(g[k], np.float64)[i]
            pts = np.atleast_2d(a)
            parts.append(f"{k} " + " ".join("(" + ", ".join(f"{v:.3f}" for v in p) + ")"
                                            for p in pts))  # fmt: skip
        if parts:
            out.append(f"  #{i}: " + "; ".join(parts))
    if cons:
        out.append("  " + "; ".join(f"{c} {s} {b:g}" for c, s, b in
                                    zip(cons, _names(at["constraint_senses"]), at["bounds"],
                                        strict=True))  # fmt: skip
                   + ": met / missed when the Wilson interval clears / misses the bound, "
                   "else at its bound")
    skipped = _names(at.get("constraints_not_raced", []) or [])
    if skipped:
        out.append(f"  not raced (no share of the stage's samples): {', '.join(skipped)}; read "
                   "them in the quoted values")  # fmt: skip
    if any(str(v) == "equivalent" and not st for v, st in zip(verdict, settled, strict=True)):
        out.append("  * not shown equivalent within the cap: the data cannot separate it from "
                   "the best (more samples, final.max_samples, may)")  # fmt: skip
    note = str(at.get("tie_note", "") or "")
    end = f"verdict: {at['summary']} (best: #{int(at['best'])}"
    end += f"; {note})" if note else ")"
    reason = {"cap": "the cap stopped the race", "decided": "every pair decided",
              "one left": "one candidate left"}.get(str(at.get("reason")), str(at.get("reason")))
    out.append(f"{end}; {reason} after {int(np.max(g['n_stages']))} stages")
    return out
