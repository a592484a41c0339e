"""The record of an inverse-kinematics command (``designopt ik``, any study with
``Study.ik``): group ``ik`` with q (N, n), success, pos_err, rot_err, what the study's
solver adds (iterations, inv_k) and the targets as read (poses, or positions and axes);
attrs targets (the mode matched), design, joint_names, units (docs/archive.md)."""

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

    @property
    def targets(self) -> str:
        """What was matched: ``position``, ``axis`` or ``pose`` (``pose`` for archives
        written before the mode was recorded)."""
        return str(self.ik.get("attrs", {}).get("targets", "pose"))

    @property
    def design(self) -> dict[str, float]:
        """The design solved for ({name: value}; empty for archives without it)."""
        return {k: float(v) for k, v in dict(self.ik.get("attrs", {}).get("design") or {}).items()}

    @property
    def joint_names(self) -> list[str]:
        from designopt.ikreport import joint_names

        return joint_names(self.ik)

    def summary(self) -> list[str]:
        from designopt.ikreport import summary_lines

        return [self.timing_line(), *summary_lines(self.ik)]

    def csv_text(self) -> str:
        from designopt.ikreport import csv_text

        return csv_text(self.ik)
