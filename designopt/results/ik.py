"""The record of an inverse-kinematics command: group ``ik`` with q (N, n), success,
pos_err, rot_err, optionally iterations and poses (docs/archive.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from designopt.results.base import Record


@dataclass(eq=False)
class IKRecord(Record):
    KIND: ClassVar[str] = "ik"
    GROUPS: ClassVar[tuple[str, ...]] = ("ik",)

    @property
    def ik(self) -> dict[str, Any]:
        return self.groups["ik"]

    @property
    def q(self) -> np.ndarray:
        return np.asarray(self.ik["q"])

    @property
    def success(self) -> np.ndarray:
        return np.asarray(self.ik["success"], bool)

    def summary(self) -> list[str]:
        from designopt.ikreport import summary_lines

        return [self.timing_line(), *summary_lines(self.ik)]

    def csv_text(self) -> str:
        from designopt.ikreport import csv_text

        return csv_text(self.ik)
