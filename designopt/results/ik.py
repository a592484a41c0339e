"""The record of an inverse-kinematics command (``designopt ik``, any study with
``Study.ik``): group ``ik`` with q (N, n), success, pos_err, rot_err, what the study's
solver adds (iterations, inv_k) and the targets as read (poses, or positions and axes);
attrs targets (the mode matched), design, joint_names, units (docs/archive.md)."""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from designopt.results.base import Record

N_FAILED_SHOWN = 5
"""How many failed poses the summary names by row."""


def joint_names(ik: Mapping[str, Any]) -> list[str]:
    """The joints' column names: attr ``joint_names``, else q1 … qn."""
    names = ik.get("attrs", {}).get("joint_names")
    n = np.asarray(ik["q"]).shape[-1]
    if names is not None and len(names) == n:
        return [str(x.decode() if isinstance(x, bytes) else x) for x in names]
    return [f"q{i + 1}" for i in range(n)]


def summary_lines(ik: Mapping[str, Any]) -> list[str]:
    """Success count and rate, what was matched and the design, the worst errors (and
    1/k, iterations) of the solved poses, the first failed poses by row (rows counted
    from 1, as in the poses file)."""
    ok = np.asarray(ik["success"], bool)
    pe, re = np.asarray(ik["pos_err"], np.float64), np.asarray(ik["rot_err"], np.float64)
    units = ik.get("attrs", {}).get("units", "")
    n, n_ok = len(ok), int(ok.sum())
    lines = [f"{n} poses: {n_ok} solved ({100 * n_ok / max(n, 1):.2f} %), {n - n_ok} failed "
             "(unreachable or not converged)"]  # fmt: skip
    at = ik.get("attrs", {})
    if at.get("targets") or at.get("design"):
        des = ", ".join(f"{k} = {float(v):.6g}" for k, v in dict(at.get("design") or {}).items())
        lines.append(f"matched: {at.get('targets', 'pose')}" + (f"; design: {des}" if des else ""))
    if n_ok:
        i, j = int(np.argmax(np.where(ok, pe, -np.inf))), int(np.argmax(np.where(ok, re, -np.inf)))
        lines.append(f"worst errors of the solved: position {pe[i]:.3g} (row {i + 1}), "
                     f"orientation {re[j]:.3g} (row {j + 1})" + (f"; units: {units}" if units else ""))  # fmt: skip
        if "iterations" in ik:
            it = np.asarray(ik["iterations"])[ok]
            lines.append(f"iterations of the solved: median {np.median(it):.0f}, max {it.max()}")
        if "inv_k" in ik:
            ik_ok = np.asarray(ik["inv_k"], np.float64)[ok]
            r = int(np.flatnonzero(ok)[np.argmin(ik_ok)])
            lines.append(f"1/k (position block) of the solved: median {np.median(ik_ok):.3g}, "
                         f"least {ik_ok.min():.3g} (row {r + 1})")  # fmt: skip
    bad = np.flatnonzero(~ok)
    if len(bad):
        shown = ", ".join(f"{r + 1} (position error {pe[r]:.3g})" for r in bad[:N_FAILED_SHOWN])
        more = f" and {len(bad) - N_FAILED_SHOWN} more" if len(bad) > N_FAILED_SHOWN else ""
        lines.append(f"failed rows: {shown}{more}")
    return lines


def unit_map(text: str) -> dict[str, str]:
    """{name: unit} of an IK archive's ``units`` attr (``"q1, q2 rad; q3 m; pos_err m;
    rot_err rad; inv_k -"``)."""
    out: dict[str, str] = {}
    for part in str(text or "").split(";"):
        names, _, unit = part.strip().rpartition(" ")
        for n in names.split(","):
            if n.strip() and unit:
                out[n.strip()] = unit
    return out


def csv_text(ik: Mapping[str, Any]) -> str:
    """One row per pose: row (from 1), success, the joints, pos_err, rot_err (and
    iterations, inv_k), each column headed with its unit (``q1 [deg]``); angles in
    degrees (the archive keeps radians), lengths in the chain's unit; full float precision
    (``repr``)."""
    names = joint_names(ik)
    units = unit_map(ik.get("attrs", {}).get("units", ""))
    q = np.asarray(ik["q"], np.float64)
    cols = {"success": np.asarray(ik["success"], bool).astype(int)}
    cols |= {nm: q[:, i] for i, nm in enumerate(names)}
    cols |= {"pos_err": np.asarray(ik["pos_err"]), "rot_err": np.asarray(ik["rot_err"])}
    if "iterations" in ik:
        cols["iterations"] = np.asarray(ik["iterations"]).astype(int)
    if "inv_k" in ik:
        cols["inv_k"] = np.asarray(ik["inv_k"], np.float64)
    head = ["row"]
    for k in list(cols):
        u = units.get(k)
        if u == "rad":  # every angle a user reads is in degrees
            cols[k], u = np.rad2deg(np.asarray(cols[k], np.float64)), "deg"
        head.append(f"{k} [{u}]" if u and u != "-" else k)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for r in range(len(q)):
        w.writerow([r + 1, *(repr(c[r].item()) for c in cols.values())])
    return buf.getvalue()


def csv_path(archive: str | Path) -> Path:
    """Where ``--csv`` writes the joints: ``<archive stem>_joints.csv`` beside it."""
    p = Path(archive)
    return p.with_name(f"{p.stem}_joints.csv")


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
        return joint_names(self.ik)

    def summary(self) -> list[str]:
        return [self.timing_line(), *summary_lines(self.ik)]

    def csv_text(self) -> str:
        return csv_text(self.ik)
