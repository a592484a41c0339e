"""The record of a Pareto-front run (``study.objective.pareto``; docs/pareto.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from designopt.results.base import SEARCH_LABEL, Record, names, runs_lines
from designopt.results.verdict import lines as verdict_lines

SHOWN = 12
"""Front designs printed by the summary (the archive holds them all)."""
WIDTH = 150
"""Characters per summary line before the index columns continue in a block below."""
_PM = 21  # a value ± SE column: 11 + " ± " + 7


@dataclass(eq=False)
class FrontRecord(Record):
    """Groups ``optimizer`` (hypervolume (runs, T+1) of the best front found so far,
    population_hypervolume, the final populations and archives), ``front`` (x (n, D), f
    and f_se (n, m) in the indices' own values, every index ± SE, rank, ambiguous pairs
    (p, 2); attrs objectives, senses, reference, hypervolume, n_samples) and
    ``problem``."""

    KIND: ClassVar[str] = "front"
    GROUPS: ClassVar[tuple[str, ...]] = ("optimizer", "front", "problem")

    @property
    def objectives(self) -> dict[str, str]:
        """Objective → sense (``min`` or ``max``)."""
        at = self.groups["front"]["attrs"]
        return dict(zip(names(at["objectives"]), names(at["senses"]), strict=True))

    def front_stream(self) -> tuple[Any, dict[str, Any]]:
        """(study settings, named keys) of the samples ``front/`` is on, for drawing a
        front design where its quoted values were measured (a task's targets): the fresh
        ``front`` stream with ``front.n_samples`` (from the binder); unbound: the run's
        own (``config.study``, ``keys()``)."""
        made = self.hint("front_stream")
        return made() if made is not None else (self.config.study, self.keys())

    @property
    def X(self) -> np.ndarray:
        """The front's designs (n, D), sorted by the first objective."""
        return np.asarray(self.groups["front"]["x"], np.float64)

    @property
    def F(self) -> np.ndarray:
        """Their objective values (n, m), re-scored on fresh samples."""
        return np.asarray(self.groups["front"]["f"], np.float64)

    @property
    def F_se(self) -> np.ndarray:
        return np.asarray(self.groups["front"]["f_se"], np.float64)

    @property
    def designs(self) -> list[dict[str, float]]:
        """Each front design as {variable: value}."""
        return [dict(zip(self.names, row.tolist(), strict=True)) for row in self.X]

    @property
    def values(self) -> dict[str, np.ndarray]:
        """Every index and ``_se`` of the front's designs (n,)."""
        skip = {"x", "f", "f_se", "rank", "ambiguous", "attrs", *self.placement}
        return {k: np.asarray(v) for k, v in self.groups["front"].items() if k not in skip}

    @property
    def placement(self) -> list[str]:
        """The names of what the study places in the world per design (``front/<name>``
        (n, ...), e.g. the serial study's ``ports`` and ``bases``; attr ``placement``)."""
        return [str(k) for k in self.groups["front"].get("attrs", {}).get("placement", []) or []]

    def run_line(self) -> str:
        """The samples behind each re-scored value (printed after a run)."""
        return f"samples per design (the re-scoring): {self.n_samples}"

    @property
    def indices(self) -> list[str]:
        """The study's indices archived beside the objectives (not traded, but computed
        for every front design: e.g. the reach of a task front of gci and length), the
        study's summary indices first, then the rest by name, the violation last."""
        vals = self.values
        def companion(k: str) -> bool:  # an index's SE, a ratio's counts (_n of _of)
            stem, _, tail = k.rpartition("_")
            return tail in ("se", "n", "of") and stem in vals

        own = [k for k in vals if not companion(k)]
        rest = [k for k in own if k not in self.objectives]
        first = [k for k in self.hint("summary", ()) if k in rest and k != "violation"]
        later = sorted((k for k in rest if k not in first), key=lambda k: (k == "violation", k))
        return first + later

    @property
    def ambiguous(self) -> np.ndarray:
        """(p, 2) pairs whose order in some objective is within 2 SE."""
        return np.asarray(self.groups["front"]["ambiguous"], np.int64).reshape(-1, 2)

    @property
    def hypervolume(self) -> float:
        """Of the re-scored front, against ``reference``."""
        return float(self.groups["front"]["attrs"]["hypervolume"])

    @property
    def reference(self) -> np.ndarray:
        return np.asarray(self.groups["front"]["attrs"]["reference"], np.float64)

    @property
    def history(self) -> np.ndarray:
        """Hypervolume per run and iteration (runs, T+1) of the non-dominated set of every
        feasible design evaluated so far (the optimizer's archive; never decreasing). In
        archives written before the optimizer kept one: the feasible population's."""
        return np.asarray(self.groups["optimizer"]["hypervolume"])

    @property
    def population_history(self) -> np.ndarray | None:
        """Hypervolume of each run's feasible population per iteration (runs, T+1); it
        may fall when survival drops a non-dominated design. None in older archives."""
        h = self.groups["optimizer"].get("population_hypervolume")
        return None if h is None else np.asarray(h)

    def _history_line(self) -> list[str]:
        H = np.atleast_2d(np.asarray(self.history, np.float64))
        if not H.size or not np.isfinite(H[:, -1]).all():
            return []
        P = self.population_history
        what = "the final populations" if P is None else "the best front found so far"
        fid = ", scored with optimizer.fidelity" if self.config.optimizer.fidelity else ""
        line = (f"search: hypervolume of {what} {np.median(H[:, -1]):.6g} (median of {len(H)} "
                f"runs, the optimizer's samples{fid})")  # fmt: skip
        if P is not None:
            line += f"; of the final populations {np.median(np.atleast_2d(P)[:, -1]):.6g}"
        cut = self.groups["optimizer"].get("archive_pruned")
        if cut is not None and np.any(np.asarray(cut) > 0):
            line += "; archive full: a lower bound"
        return [line]

    def _table(self, rows: np.ndarray) -> list[str]:
        """The shown designs: number, variables, objectives ± SE, then every other index
        ± SE (continued in blocks below when a line would pass ``WIDTH``)."""
        vals = self.values
        units = self.units()

        def head(k: str, w: int) -> str:  # the name with its unit (none for "-")
            u = units.get(k, "-")
            return f"{k if u in ('-', '') else f'{k} [{u}]':>{w}}"

        def pm(v: np.ndarray, se: np.ndarray | None):
            def one(i: int) -> str:  # n/a (NaN: a ratio over too few items) as "n/a"
                if np.isnan(v[i]):
                    return f"{'n/a':>11}".ljust(_PM)
                if se is None or not np.isfinite(se[i]):
                    return f"{v[i] + 0.0:11.5g}".ljust(_PM)
                return f"{v[i] + 0.0:11.5g} ± {se[i]:7.1e}"

            return one

        cols = [
            (head(n, 10), lambda i, a=a: f"{self.X[i, a]:10.4g}") for a, n in enumerate(self.names)
        ]
        cols += [(head(k, _PM), pm(self.F[:, j], self.F_se[:, j]))
                 for j, k in enumerate(self.objectives)]  # fmt: skip
        first = len(cols)
        for k in self.indices:
            se = vals.get(k + "_se")
            se = None if se is None else np.asarray(se, np.float64)
            cols.append((head(k, _PM), pm(np.asarray(vals[k], np.float64), se)))
        num = ("  #", lambda i: f"{i:3d}")
        blocks, cur, width = [], [num], 3
        for c, col in enumerate(cols):
            w = len(col[0]) + 2
            if c >= first and width + w > WIDTH and len(cur) > 1:
                blocks.append(cur)
                cur, width = [num], 3
            cur.append(col)
            width += w
        blocks.append(cur)
        out = []
        for b, block in enumerate(blocks):
            if b == 1:
                out.append("  … the same designs, continued:")
            out.append("  " + "  ".join(h for h, _ in block))
            out += [("  " + "  ".join(f(i).rjust(len(h)) for h, f in block)).rstrip() for i in rows]
        return out

    def summary(self) -> list[str]:
        at: Any = self.groups["front"]["attrs"]
        obj = self.objectives
        n = len(self.F)
        lines = [self.timing_line(),
                 f"Pareto front of {', '.join(f'{k} ({s})' for k, s in obj.items())}: {n} "
                 f"designs (of {at['n_candidates']} "
                 f"{'candidates raced in the final stage' if 'verdict' in self.groups else 'non-dominated candidates'}), re-scored on "
                 f"{at['n_samples']} fresh samples each",
                 f"hypervolume {self.hypervolume:.6g} against the reference point "
                 f"{np.round(self.reference, 6).tolist()}; {len(self.ambiguous)} pairs "
                 f"ambiguous (order within {at.get('z', 2):g} SE in some objective)"]  # fmt: skip
        if n and self.hypervolume == 0:  # a zero that says nothing about the front
            lines.append("  (a hypervolume of 0: no design of the front is better than the "
                         "reference point in every objective; where the reference is the "
                         "first generation's worst, that generation already held the "
                         "front's value in some objective)")  # fmt: skip
        lines += self._history_line()
        rows = np.unique(np.linspace(0, n - 1, min(n, SHOWN)).round().astype(int))
        others = self.indices
        if others:
            lines.append(f"the front's designs with their objectives and every other index of "
                         f"the study ({', '.join(others)}), re-scored ± SE:")  # fmt: skip
        lines += self._table(rows)
        if len(rows) < n:
            lines.append(f"  ({len(rows)} of {n} designs shown, evenly along the front)")
        per = self.hint("design_lines")  # the study's placement of each design, in numbers
        if per:
            lines.append("where the shown designs put the robot:")
            for i in rows:
                lines.append(f"  #{i}: {per[i][0].strip()}")
                lines += [f"      {ln.strip()}" for ln in per[i][1:]]
        pol = self.groups.get("refine")
        if pol is not None and "d0" in pol:  # refine: {method: compass}
            at = pol["attrs"]
            d0, d = (", ".join(f"{x:.4g}" for x in np.atleast_1d(pol[k])) for k in ("d0", "d"))
            lines.append(f"polish: {at.get('designs', 'designs')}, by a compass search "
                         f"{SEARCH_LABEL}: distance to the ideal point (objectives scaled to "
                         f"[0, 1]) {d0} → {d} ({int(at['iterations'])} iterations, "
                         f"{int(at['evaluations'])} designs scored)")  # fmt: skip
        lines += self.coverage_lines
        lines += runs_lines(self.runs, self.names, self.units())
        lines += verdict_lines(self.groups.get("verdict"), self.names, self.units())
        warns = self.warnings
        lines += [f"warning: {w}" for w in warns[:SHOWN]]
        if len(warns) > SHOWN:  # a front trading reach: a line per design; all archived
            lines.append(f"  ({len(warns) - SHOWN} more warnings of the front's designs in "
                         "the archive: front attr warnings, and on the HTML report)")  # fmt: skip
        return lines

    @property
    def warnings(self) -> list[str]:
        """What a weighted run would say of its final design, said of each front design
        it concerns (each distinct line once, naming the designs: ``front`` attr
        ``warnings``; ``designopt.app.quoted.warnings``); empty when none."""
        w = self.groups["front"].get("attrs", {}).get("warnings", [])
        return [w] if isinstance(w, str) else [str(x) for x in w]

    @property
    def coverage_lines(self) -> list[str]:
        """A task front's IK coverage figure: the lines of its worst design (``front``
        attr ``coverage_lines``; each design's share in attr ``ik_better``)."""
        w = self.groups["front"].get("attrs", {}).get("coverage_lines", [])
        return [w] if isinstance(w, str) else [str(x) for x in w]

    @property
    def runs(self) -> dict[str, Any] | None:
        """Each run's recommended design (the compromise of its own non-dominated final
        population) re-scored with the front (``runs``: ``x`` (R, D), every index ± SE
        (R,), ``agree`` (R,), ``span`` (D,), attrs) with ``optimizer.n_runs`` ≥ 2; None
        otherwise."""
        return self.groups.get("runs")

    @property
    def n_samples(self) -> int:
        """Samples per design of the re-scoring that gave ``F`` and ``F_se``."""
        return int(self.groups["front"]["attrs"]["n_samples"])

    @property
    def rank(self) -> np.ndarray:
        """Each front design's non-domination rank (n,) after re-scoring (0: on the
        re-scored front; constrained domination where the study has a violation)."""
        return np.asarray(self.groups["front"]["rank"], np.int64)

    def units(self) -> dict[str, str]:
        """Every variable's, index's and objective's unit: the study's, and the linear
        objectives' own (their variables' common unit)."""
        own = dict(self.groups["front"]["attrs"].get("units", {}) or {})
        return {**self.hint("units", {}), **own}
