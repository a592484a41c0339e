"""The record of a scan: designs scored without an optimiser (``designopt scan``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from designopt.results.base import Record, names


def best_lines(names: Sequence[str], X: np.ndarray, f: np.ndarray,
               violation: np.ndarray | None = None) -> list[str]:  # fmt: skip
    """The scored designs' summary: the lowest f; under constraints (g ≤ 0), the lowest
    f among the feasible designs, and the infeasible design with a lower f named apart."""

    def design(i: int) -> str:
        return ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, X[i], strict=True))

    f = np.asarray(f, np.float64)
    if violation is None:
        i = int(np.nanargmin(f))
        return [f"lowest f: {design(i)}: f = {f[i]:.5g}"]
    v = np.asarray(violation, np.float64)
    ok = v <= 0
    lines = [f"constraints: {int(ok.sum())} of {len(f)} designs feasible"]
    if ok.any():
        i = int(np.flatnonzero(ok)[np.nanargmin(f[ok])])
        lines.append(f"lowest f among the feasible: {design(i)}: f = {f[i]:.5g}")
        j = int(np.nanargmin(np.where(ok, np.inf, f))) if (~ok).any() else -1
        if j >= 0 and f[j] < f[i]:
            lines.append(f"  lower f only where infeasible: {design(j)}: f = {f[j]:.5g}, "
                         f"violated by {v[j]:.3g}")  # fmt: skip
    else:
        j = int(np.argmin(v))
        lines.append(f"no feasible design; least violation {v[j]:.3g} at {design(j)}: "
                     f"f = {f[j]:.5g}")  # fmt: skip
    return lines


@dataclass(eq=False)
class ScanRecord(Record):
    """Group ``scan``: names, x (n, D), varied, f and every index with ``_se`` (n,),
    attrs mode and shape; group ``problem`` (names, box, info)."""

    KIND: ClassVar[str] = "scan"
    GROUPS: ClassVar[tuple[str, ...]] = ("scan", "problem")

    @property
    def names(self) -> list[str]:
        return names(self.groups["scan"]["names"])

    @property
    def varied(self) -> list[str]:
        return names(self.groups["scan"]["varied"])

    @property
    def mode(self) -> str:
        return str(self.groups["scan"]["attrs"].get("mode", "grid"))

    @property
    def shape(self) -> list[int]:
        """Values per varied variable (a grid's shape)."""
        return [int(n) for n in self.groups["scan"]["attrs"]["shape"]]

    @property
    def X(self) -> np.ndarray:
        return np.asarray(self.groups["scan"]["x"], np.float64)

    @property
    def values(self) -> dict[str, np.ndarray]:
        """f and every index (and ``_se``) per design (n,)."""
        sc = self.groups["scan"]
        return {
            k: np.asarray(v) for k, v in sc.items() if k not in ("names", "x", "varied", "attrs")
        }

    def best_lines(self) -> list[str]:
        v = self.values
        return best_lines(self.names, self.X, v["f"], v.get("violation"))

    def summary(self) -> list[str]:
        return [self.timing_line(), f"{len(self.X)} designs", *self.best_lines()]
