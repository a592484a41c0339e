"""Target files of ``designopt ik`` (README.md, docs/archive.md), read and checked.

Rows are counted from 1, the first row after the header:

- CSV with a header row, any column order: ``x,y,z`` (positions), ``x,y,z,ax,ay,az``
  (positions and unit tool axes, the tool frame's z axis), ``x,y,z,qw,qx,qy,qz``
  (positions and unit quaternions) or ``T00,T01,…,T33`` (row-major 4×4 poses);
- HDF5 with a dataset ``poses`` (N, 4, 4).

Every row is checked (NaN/inf, a magnitude above 1e9 (``MAX_MAGNITUDE``), a non-unit
quaternion or axis, a rotation not orthonormal, a reflection, a bad bottom row): one
ConfigError naming the file and the row, nothing written.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from designopt.core.errors import ConfigError
from designopt.core.validation import MAX_MAGNITUDE, problem
from designopt.kinematics.poses import DEFAULT_TOL, Targets, check_poses, quat_to_pose

POSITION_COLUMNS = ("x", "y", "z")
AXIS_COLUMNS = ("x", "y", "z", "ax", "ay", "az")
QUAT_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
MATRIX_COLUMNS = tuple(f"T{i}{j}" for i in range(4) for j in range(4))
FORMATS = ((MATRIX_COLUMNS, "pose"), (QUAT_COLUMNS, "pose"), (AXIS_COLUMNS, "axis"),
           (POSITION_COLUMNS, "position"))  # fmt: skip
"""The CSV headers (any column order) and what each gives."""


def _numbers(vals: np.ndarray, cols: tuple[str, ...], path: Path) -> None:
    """Every value finite and at most MAX_MAGNITUDE in magnitude (designopt.core.validation:
    a target at 1e308 is finite, its square is not); a ConfigError naming the first row
    (from 1) and its column otherwise."""
    bad = ~np.isfinite(vals) | (np.abs(vals) > MAX_MAGNITUDE)
    if bad.any():
        i, k = (int(x) for x in np.argwhere(bad)[0])
        v = float(vals[i, k])
        if not np.isfinite(v):
            raise ConfigError(f"{path}: row {i + 1}: NaN or inf in the target ({cols[k]} = {v})")
        raise ConfigError(f"{path}: row {i + 1}: {cols[k]} = {problem(v)}")


def _unit_rows(v: np.ndarray, tol: float, path: Path, why: str, sym: str) -> None:
    """Every row of v a unit vector to ``tol``; a ConfigError naming the first other."""
    n = np.linalg.norm(v, axis=-1)
    off = np.abs(n - 1.0) > tol
    if off.any():
        i = int(np.argmax(off))
        raise ConfigError(f"{path}: row {i + 1}: {why} "
                          f"(|{sym}| = {n[i]:.9g}; tolerance {tol:g})")  # fmt: skip


def _read_csv(path: Path, tol: float) -> Targets:
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            lines = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: cannot read the poses file ({e})") from None
    lines = [ln for ln in lines if ln and any(c.strip() for c in ln)]
    if not lines:
        raise ConfigError(f"{path}: empty file; needs a header row and one target per row")
    head = [c.strip() for c in lines[0]]
    cols = next((c for c, _ in FORMATS if sorted(head) == sorted(c)), None)
    if cols is None:
        raise ConfigError(f"{path}: header {head}: give the columns "
                          + " or ".join(",".join(c) for c, _ in FORMATS) + " (any order)")  # fmt: skip
    order = [head.index(c) for c in cols]
    if len(lines) == 1:
        raise ConfigError(f"{path}: no targets after the header row")
    vals = np.empty((len(lines) - 1, len(cols)))
    for i, ln in enumerate(lines[1:]):
        if len(ln) != len(head):
            raise ConfigError(f"{path}: row {i + 1}: {len(ln)} values, the header has {len(head)}")
        try:
            vals[i] = [float(ln[k]) for k in order]
        except ValueError:
            raise ConfigError(f"{path}: row {i + 1}: a value is not a number: {ln}") from None
    _numbers(vals, cols, path)
    if cols is MATRIX_COLUMNS:
        return _checked(vals.reshape(-1, 4, 4), tol, path)
    if cols is QUAT_COLUMNS:
        _unit_rows(vals[:, 3:], tol, path, "quaternion is not a unit quaternion", "q")
        return _checked(quat_to_pose(vals), tol, path)
    if cols is AXIS_COLUMNS:
        _unit_rows(vals[:, 3:], tol, path, "tool axis (ax, ay, az) is not a unit vector", "a")
        return Targets(vals[:, :3].copy(), axis=vals[:, 3:].copy())
    return Targets(vals.copy())


def _read_h5(path: Path, tol: float) -> Targets:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if "poses" not in f:
                raise ConfigError(f"{path}: no dataset 'poses' (N, 4, 4); has {sorted(f)}")
            T = np.asarray(f["poses"][()], np.float64)
    except OSError as e:
        raise ConfigError(f"{path}: cannot read the HDF5 file ({e})") from None
    if T.ndim != 3 or T.shape[1:] != (4, 4) or len(T) == 0:
        raise ConfigError(f"{path}: dataset 'poses' must have shape (N, 4, 4), got {T.shape}")
    _numbers(T.reshape(len(T), 16), MATRIX_COLUMNS, path)
    return _checked(T, tol, path)


def _checked(T: np.ndarray, tol: float, path: Path) -> Targets:
    bad = check_poses(T, tol)
    if bad:
        i, why = bad[0]
        more = f" ({len(bad) - 1} more rows with problems)" if len(bad) > 1 else ""
        raise ConfigError(f"{path}: row {i + 1}: {why}{more}")
    return Targets(T[:, :3, 3].copy(), R=T[:, :3, :3].copy())


def read_targets(path: str | Path, tol: float = DEFAULT_TOL) -> Targets:
    """The targets of a CSV or HDF5 file (module docstring), every row checked: a
    ConfigError naming the file and the first bad row (from 1) otherwise."""
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{p}: is a folder, not a poses file (--poses)")
    if not p.is_file():
        raise ConfigError(f"{p}: poses file not found")
    return _read_h5(p, tol) if p.suffix.lower() in (".h5", ".hdf5") else _read_csv(p, tol)
