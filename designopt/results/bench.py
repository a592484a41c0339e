"""The record of an optimizer benchmark (``designopt bench``): per case and optimizer
entry the runs' histories and final values, per case the statistics."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from designopt.results.base import Record


@dataclass(eq=False)
class BenchRecord(Record):
    """Group ``bench/<case>/<entry>``: history, best_f, best_x, converged_at and attrs
    wall_s, compile_s, settings; ``bench/<case>`` attr ``stats`` (docs/archive.md)."""

    KIND: ClassVar[str] = "bench"
    GROUPS: ClassVar[tuple[str, ...]] = ("bench",)

    @property
    def cases(self) -> dict[str, dict[str, Any]]:
        return {c: g for c, g in self.groups["bench"].items() if c != "attrs"}

    def stats(self, case: str) -> dict[str, Any]:
        return self.cases[case]["attrs"]["stats"]

    def entries(self, case: str) -> dict[str, dict[str, Any]]:
        return {v: g for v, g in self.cases[case].items() if v != "attrs"}

    def summary(self) -> list[str]:
        lines = [self.timing_line()]
        for case in self.cases:
            st = self.stats(case)
            rows, up = st["rows"], bool(st.get("higher_is_better", False))
            best = (max if up else min)(rows, key=lambda v: rows[v]["mean"])
            if up:
                lines.append(f"  {case}: best hypervolume {best} ({rows[best]['mean']:.5f})")
            else:
                lines.append(f"  {case}: best mean {best} ({rows[best]['mean']:.3e})")
        return lines

    def case_names(self) -> list[str]:
        """The cases in the order the suite ran them (the config's functions, then their
        shifted copies; an archive gives its groups sorted by name)."""
        have = list(self.cases)
        ran = [c for c in self.hint("case_names", []) if c in have]
        return ran + [c for c in have if c not in ran]

    def histories(self, case: str) -> dict[str, np.ndarray]:
        """Each entry's best f so far per run and iteration (runs, T+1) for one case, in
        the config's order of the entries (that of the case's ``stats`` rows)."""
        ent = self.entries(case)
        order = [v for v in self.stats(case)["rows"] if v in ent]
        order += [v for v in ent if v not in order]
        return {v: np.asarray(ent[v]["history"]) for v in order}

    @property
    def n_runs(self) -> int:
        """Independent runs per entry (``bench.n_runs`` of the config)."""
        return int(self.raw_config()["bench"]["n_runs"])
