"""``designopt ik CONFIG --poses FILE``: inverse kinematics of the chain of any study that
declares ``Study.ik`` (an :class:`IKHook`), for every target of a CSV or HDF5 file
(README.md, docs/archive.md).

Targets file (rows counted from 1, the first row after the header):

- CSV with a header row, any column order: ``x,y,z`` (positions), ``x,y,z,ax,ay,az``
  (positions and unit tool axes, the tool frame's z axis), ``x,y,z,qw,qx,qy,qz``
  (positions and unit quaternions) or ``T00,T01,…,T33`` (row-major 4×4 poses);
- HDF5 with a dataset ``poses`` (N, 4, 4).

Lengths are in the chain's own length unit. ``--mode position|axis|pose`` solves for
fewer rows than the file gives (e.g. positions only from full poses); asking for more
than it gives is an error. Every row is checked first (NaN/inf, a non-unit quaternion or
axis, a rotation not orthonormal, a reflection, a bad bottom row): one ConfigError naming
the file and the row (exit 2 from the CLI), nothing written.

The study's hook does everything that is the study's own (its design, solver, joint names
and units, extra options such as a trajectory mode); this module reads and checks the
targets, picks the mode, claims the outputs, archives an ``IKRecord`` through
``archive.save`` and prints its summary. It reaches studies through the registry only.
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from designopt.errors import ConfigError

MODES = ("position", "axis", "pose")
"""What a target fixes, weakest first (the generic solver's modes,
``designopt.kinematics.ik.MODES``)."""
POSITION_COLUMNS = ("x", "y", "z")
AXIS_COLUMNS = ("x", "y", "z", "ax", "ay", "az")
QUAT_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
MATRIX_COLUMNS = tuple(f"T{i}{j}" for i in range(4) for j in range(4))
FORMATS = ((MATRIX_COLUMNS, "pose"), (QUAT_COLUMNS, "pose"), (AXIS_COLUMNS, "axis"),
           (POSITION_COLUMNS, "position"))  # fmt: skip
"""The CSV headers (any column order) and what each gives."""
DEFAULT_TOL = 1e-6
"""Unit quaternions and axes and orthonormal rotations to this, unless the study says."""
PROGRESS_MIN = 20_000
"""Targets from which a progress bar shows."""


# ---------------------------------------------------------------------------- targets


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
    bad = ~np.all(np.isfinite(vals), -1)
    if bad.any():
        raise ConfigError(f"{path}: row {int(np.argmax(bad)) + 1}: NaN or inf in the target")
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
    if not p.is_file():
        raise ConfigError(f"{p}: poses file not found")
    return _read_h5(p, tol) if p.suffix.lower() in (".h5", ".hdf5") else _read_csv(p, tol)


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


# ---------------------------------------------------------------------------- the hook


@dataclass(frozen=True)
class IKJob:
    """What a study's solver gets: its validated ``settings``, the ``design`` (the
    hook's ``design`` resolved it), the checked ``targets`` and the ``mode`` to solve,
    a PRNG ``key`` (the ``samples`` stream of the config's seed), the values of the
    study's own options (``IKHook.arguments``) and a ``progress(n)`` callback."""

    settings: Any
    design: dict[str, float]
    targets: Targets
    mode: str
    key: Any
    options: Mapping[str, Any] = field(default_factory=dict)
    progress: Callable[[int], None] | None = None


@dataclass(frozen=True)
class IKSolution:
    """A solver's answer: ``arrays`` with per-target ``q`` (N, n), ``success``,
    ``pos_err``, ``rot_err`` and whatever else it has (``iterations``, ``inv_k``), the
    joints' names, the units text (``"q1, q2 rad; q3 mm; pos_err mm; rot_err rad"``),
    extra ``ik`` attrs and lines printed before the summary."""

    arrays: dict[str, np.ndarray]
    joint_names: list[str]
    units: str
    attrs: dict[str, Any] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class IKHook:
    """A study's inverse kinematics (``Study.ik``), for ``designopt ik``.

    - ``design(settings, given, where) -> {name: value}``: the design to solve for,
      ``given`` the ``--design NAME=VALUE`` values (ConfigError naming ``where`` for an
      unknown name);
    - ``solve(job) -> IKSolution`` (float64 is on; a ValueError names the target);
    - ``modes``: the target modes it solves (of :data:`MODES`);
    - ``arguments(parser)``: the study's own optional flags (each with a default), given
      to ``solve`` as ``job.options``; the same flag given for another study is refused;
    - ``tol(settings)``: the tolerance of unit quaternions, axes and orthonormal rows."""

    solve: Callable[[IKJob], IKSolution]
    design: Callable[[Any, dict[str, float], str], dict[str, float]]
    modes: tuple[str, ...] = MODES
    arguments: Callable[[Any], None] | None = None
    tol: Callable[[Any], float] = lambda s: DEFAULT_TOL


def _own_options(hook: IKHook) -> dict[str, Any]:
    """{dest: default} of a hook's own flags."""
    if hook.arguments is None:
        return {}
    tmp = argparse.ArgumentParser(add_help=False)
    hook.arguments(tmp)
    return vars(tmp.parse_args([]))


def _hooks() -> dict[str, IKHook]:
    from designopt.studies import STUDIES

    return {n: st.ik for n, st in STUDIES.items() if getattr(st, "ik", None) is not None}


# ---------------------------------------------------------------------------- command


def add_parser(sub: Any) -> None:
    """Add ``designopt ik`` to the CLI's subparsers: the generic flags, then each
    study's own flags (``IKHook.arguments``) under its name."""
    hooks = _hooks()
    k = sub.add_parser(
        "ik",
        help="inverse kinematics of a study's chain for the targets of a CSV or HDF5 file",
        description="Solve the inverse kinematics of the config's chain for every target "
        "of a file: CSV with a header row and the columns x,y,z (positions), "
        "x,y,z,ax,ay,az (positions and tool axes), x,y,z,qw,qx,qy,qz or T00..T33 "
        "(row-major 4x4 poses); or HDF5 with a dataset 'poses' (N, 4, 4); lengths in the "
        "chain's unit. Writes ik/q, ik/success, ik/pos_err, ik/rot_err and what the "
        "study's solver adds (README.md, docs/archive.md). Studies with inverse "
        "kinematics: " + (", ".join(hooks) or "none") + ".",
    )
    k.add_argument("config", help="config (YAML) of a study with inverse kinematics")
    k.add_argument("--poses", required=True, metavar="PATH", help="targets file (.csv or .h5)")
    k.add_argument("--mode", choices=MODES, default=None,
                   help="what to match: position, axis (position + tool z axis) or pose; "
                        "default the most the file gives and the study solves")  # fmt: skip
    k.add_argument("--design", action="append", default=[], metavar="NAME=VALUE",
                   help="a design value (repeat; others: the config's design)")  # fmt: skip
    k.add_argument("--out", default=None, metavar="PATH",
                   help="archive path (default results/<study>/<poses name>_ik.h5)")  # fmt: skip
    k.add_argument("--csv", action="store_true",
                   help="also write the joints, one row per target, to <archive stem>_joints.csv")  # fmt: skip
    k.add_argument("--seed", type=int, default=None, help="override the config's seed")
    k.add_argument("--overwrite", action="store_true", help="replace an existing archive")
    k.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")
    k.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    for name, hook in hooks.items():
        if hook.arguments is not None:
            hook.arguments(k.add_argument_group(f"study '{name}'"))
    k.set_defaults(func=cmd_ik, writes=True)


def _foreign(args: argparse.Namespace, study: str) -> dict[str, Any]:
    """This study's own option values; another study's flag given is a ConfigError."""
    hooks = _hooks()
    mine = _own_options(hooks[study])
    for other, hook in hooks.items():
        for dest, default in _own_options(hook).items():
            if other != study and dest not in mine and getattr(args, dest, default) != default:
                raise ConfigError(f"--{dest.replace('_', '-')}: an option of study '{other}', "
                                  f"not of study '{study}'")  # fmt: skip
    return {d: getattr(args, d, v) for d, v in mine.items()}


def cmd_ik(args: argparse.Namespace) -> int:
    """``designopt ik CONFIG --poses PATH [...]``: read and check the targets, solve them
    with the study's hook, archive an IKRecord (``--csv``: the joints too), print."""
    import jax

    from designopt import archive, ikreport, output
    from designopt.cmdsetup import load_args, parse_design
    from designopt.prepare import base_attrs
    from designopt.results import IKRecord
    from designopt.studies import STUDIES, streams
    from designopt.timing import Stopwatch

    cfg, text = load_args(args)
    name = cfg.study.name
    hook = getattr(STUDIES[name], "ik", None)
    if hook is None:
        have = ", ".join(f"'{n}'" for n in _hooks()) or "none"
        raise ConfigError(f"{args.config}: study '{name}' has no inverse kinematics "
                          f"(studies with it: {have})")  # fmt: skip
    opts = _foreign(args, name)
    if cfg.precision != "float64":
        raise ConfigError(f"{args.config}: key 'precision': the IK needs float64 "
                          "(errors of 1e-9); set precision: float64")  # fmt: skip
    jax.config.update("jax_enable_x64", True)
    design = hook.design(cfg.study, parse_design(args.design), args.config)
    poses = Path(args.poses)
    targets = read_targets(poses, hook.tol(cfg.study))
    mode = choose_mode(targets, args.mode, hook.modes, name, poses)
    out = Path(args.out or f"results/{name}/{poses.stem}_ik.h5")
    output.claim(out, args.overwrite)
    csv_out = ikreport.csv_path(out) if args.csv else None
    if csv_out is not None:
        output.claim(csv_out, args.overwrite)
    keys = streams(cfg.seed)
    show = not args.quiet and len(targets) >= PROGRESS_MIN
    from tqdm import tqdm

    bar = tqdm(total=len(targets), desc="ik", unit="target", disable=not show)
    with Stopwatch() as sw, bar:
        job = IKJob(cfg.study, design, targets, mode, keys["samples"], opts, bar.update)
        try:
            sol = hook.solve(job)
        except ValueError as e:
            raise ConfigError(f"{poses}: {e}") from None
    attrs = {"targets": mode, "poses_file": str(poses), "n": len(targets), "design": design,
             "joint_names": list(sol.joint_names), "units": sol.units} | sol.attrs  # fmt: skip
    tree = {"ik": {**sol.arrays, **targets.tree(), "attrs": attrs}}
    root = base_attrs("ik", cfg, text, keys, args.config) | {
        "wall_time_s": sw.wall, "compile_time_s": sw.compile, "run_time_s": sw.run}  # fmt: skip
    rec = IKRecord(root, tree, cfg)
    archive.save(out, rec, overwrite=args.overwrite)
    if csv_out is not None:
        output.write_file(csv_out, rec.csv_text().encode(), "joints CSV")
    if not args.quiet:
        for line in sol.lines:
            print(line)
        for line in rec.summary()[1:]:
            print(line)
        print(f"wall {sw.wall:.1f} s = compile {sw.compile:.1f} s + run {sw.run:.1f} s")
        print(f"wrote {out}" + (f" and {csv_out}" if csv_out is not None else ""))
    return 0
