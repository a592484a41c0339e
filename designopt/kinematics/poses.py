"""Targets of inverse kinematics and the pose maths they need: positions, unit tool axes
and full poses (``Targets``), frames from axes, poses from unit quaternions, the check
that a 4×4 matrix is a rigid transform, and the choice of what to solve (``choose_mode``).
Reading target files is ``designopt.io.poses``; the solvers' protocol is
``designopt.kinematics.ikjob``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from designopt.core.errors import ConfigError

MODES = ("position", "axis", "pose")
"""What a target fixes, weakest first (the generic solver's modes,
``designopt.kinematics.ik.MODES``)."""
DEFAULT_TOL = 1e-6
"""Unit quaternions and axes and orthonormal rotations to this, unless the study says."""

@dataclass(frozen=True)
class Targets:
    """The targets of a file: positions ``p`` (N, 3) and, when the file gives them, full
    rotations ``R`` (N, 3, 3) or unit tool axes ``axis`` (N, 3)."""

    p: np.ndarray
    R: np.ndarray | None = None
    axis: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.p)

    @property
    def given(self) -> str:
        """What the file gives: ``pose``, ``axis`` or ``position``."""
        return "pose" if self.R is not None else "axis" if self.axis is not None else "position"

    def poses(self) -> np.ndarray:
        """(N, 4, 4) poses (a file with full poses only)."""
        if self.R is None:
            raise ValueError(f"the file gives {DESCRIBE[self.given]}, not full poses")
        T = np.zeros((len(self), 4, 4))
        T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = self.R, self.p, 1.0
        return T

    def rotations(self, mode: str) -> np.ndarray | None:
        """The target rotations a solver of ``mode`` reads: None for ``position``; for
        ``axis`` frames whose z column is the tool axis (the other two columns complete
        it and are not matched); for ``pose`` R."""
        if mode == "position":
            return None
        if mode == "pose" or self.axis is None:
            return self.R
        return axis_frames(self.axis)

    def tree(self) -> dict[str, np.ndarray]:
        """What the archive keeps of the targets as read: ``poses`` (N, 4, 4), else
        ``positions`` (N, 3) and, from an axis file, ``axes`` (N, 3)."""
        if self.R is not None:
            return {"poses": self.poses()}
        return {"positions": self.p} | ({} if self.axis is None else {"axes": self.axis})


DESCRIBE = {"position": "positions only (x,y,z)",
            "axis": "positions and tool axes (x,y,z,ax,ay,az)",
            "pose": "full poses"}  # fmt: skip


def axis_frames(a: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations whose z column is the unit axis a (N, 3): x ⟂ z from the world
    axis least parallel to z, y = z × x."""
    a = np.asarray(a, np.float64)
    helper = np.where(np.abs(a[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    x = np.cross(helper, a)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    return np.stack([x, np.cross(a, x), a], -1)


def quat_to_pose(rows: np.ndarray) -> np.ndarray:
    """(N, 7) rows x, y, z, qw, qx, qy, qz (unit quaternions) → (N, 4, 4) poses."""
    p, (w, x, y, z) = rows[:, :3], rows[:, 3:].T
    R = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)  # fmt: skip
    T = np.zeros((len(rows), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, p, 1.0
    return T


def check_poses(T: np.ndarray, tol: float = DEFAULT_TOL) -> list[tuple[int, str]]:
    """(row index from 0, problem) for every pose of T (N, 4, 4) that is not a rigid
    transform: NaN/inf, a rotation block not orthonormal to ``tol`` or with det −1, a
    bottom row other than (0, 0, 0, 1). Empty list: all fine."""
    T = np.asarray(T, np.float64)
    bad: list[tuple[int, str]] = []
    fin = np.all(np.isfinite(T.reshape(len(T), -1)), -1)
    R = np.where(fin[:, None, None], T[:, :3, :3], 0.0)
    dev = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max((-1, -2))
    det = np.linalg.det(R)
    bottom = np.abs(np.where(fin[:, None], T[:, 3, :], 0.0) - [0, 0, 0, 1]).max(-1)
    for i in np.flatnonzero(~fin | (dev > tol) | (det < 0) | (bottom > tol)):
        if not fin[i]:
            why = "NaN or inf in the pose"
        elif dev[i] > tol:
            why = f"rotation not orthonormal (|RᵀR − I| = {dev[i]:.2g} > {tol:g})"
        elif det[i] < 0:
            why = "rotation has det −1 (a reflection)"
        else:
            why = "bottom row is not (0, 0, 0, 1)"
        bad.append((int(i), why))
    return bad


def choose_mode(targets: Targets, asked: str | None, modes: tuple[str, ...], study: str,
                path: Path) -> str:  # fmt: skip
    """The mode to solve: ``asked`` (``--mode``), else the strongest the study solves
    that the file gives. ConfigError when the study does not solve it or the file does
    not give it."""
    given = MODES.index(targets.given)
    if asked is None:
        ok = [m for m in modes if MODES.index(m) <= given]
        if not ok:
            raise ConfigError(f"{path}: the file gives {DESCRIBE[targets.given]}; study "
                              f"'{study}' solves {' or '.join(modes)} targets")  # fmt: skip
        return max(ok, key=MODES.index)
    if asked not in modes:
        raise ConfigError(f"--mode {asked}: study '{study}' solves {' or '.join(modes)} targets")
    if MODES.index(asked) > given:
        raise ConfigError(f"{path}: --mode {asked} needs {DESCRIBE[asked]}; the file gives "
                          f"{DESCRIBE[targets.given]}")  # fmt: skip
    return asked
