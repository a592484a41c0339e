"""The record of a Pareto-front run (``study.objective.pareto``; docs/pareto.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from designopt.results.base import Record, names

SHOWN = 12
"""Front designs printed by the summary (the archive holds them all)."""


@dataclass(eq=False)
class FrontRecord(Record):
    """Groups ``optimizer`` (hypervolume (runs, T+1), the final populations), ``front``
    (x (n, D), f and f_se (n, m) in the indices' own values, every index ± SE, rank,
    ambiguous pairs (p, 2); attrs objectives, senses, reference, hypervolume, n_samples)
    and ``problem``."""

    KIND: ClassVar[str] = "front"
    GROUPS: ClassVar[tuple[str, ...]] = ("optimizer", "front", "problem")

    @property
    def objectives(self) -> dict[str, str]:
        """Objective → sense (``min`` or ``max``)."""
        at = self.groups["front"]["attrs"]
        return dict(zip(names(at["objectives"]), names(at["senses"]), strict=True))

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
        skip = {"x", "f", "f_se", "rank", "ambiguous", "attrs"}
        return {k: np.asarray(v) for k, v in self.groups["front"].items() if k not in skip}

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
        """Hypervolume of each run's feasible population per iteration (runs, T+1)."""
        return np.asarray(self.groups["optimizer"]["hypervolume"])

    def summary(self) -> list[str]:
        at: Any = self.groups["front"]["attrs"]
        obj = self.objectives
        n, m = self.F.shape
        lines = [self.timing_line(),
                 f"Pareto front of {', '.join(f'{k} ({s})' for k, s in obj.items())}: {n} "
                 f"designs (of {at['n_candidates']} non-dominated candidates), re-scored on "
                 f"{at['n_samples']} fresh samples each",
                 f"hypervolume {self.hypervolume:.6g} against the reference point "
                 f"{np.round(self.reference, 6).tolist()}; {len(self.ambiguous)} pairs "
                 f"ambiguous (order within {at.get('z', 2):g} SE in some objective)"]  # fmt: skip
        head = "  ".join(f"{v:>10}" for v in self.names) + "  " + "  ".join(f"{k:>20}" for k in obj)
        lines.append("  " + head)
        rows = np.unique(np.linspace(0, n - 1, min(n, SHOWN)).round().astype(int))
        for i in rows:
            xs = "  ".join(f"{v:10.4g}" for v in self.X[i])
            fs = "  ".join(f"{self.F[i, j]:11.5g} ± {self.F_se[i, j]:6.1e}" for j in range(m))
            lines.append(f"  {xs}  {fs}")
        if len(rows) < n:
            lines.append(f"  ({len(rows)} of {n} designs shown, evenly along the front)")
        return lines

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
