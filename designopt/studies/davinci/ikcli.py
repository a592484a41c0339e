"""``designopt ik``: inverse kinematics of the da Vinci patient-side arm for a user's
poses (the da Vinci patient-side arm IK paper, Applied Sciences 2019; docs/davinci.md).

Input: a CSV file with a header row, columns ``T00,T01,…,T33`` (the row-major 4×4
pose, mm) or ``x,y,z,qw,qx,qy,qz`` (position in mm, unit quaternion), or an HDF5 file
with a dataset ``poses`` (N, 4, 4). Rows are counted from 1 (the first row after the
header). Output: an archive with ``ik/q`` (N, 6; q1, q2, q4, q5, q6 in rad, q3 in mm),
``ik/success``, ``ik/iterations``, ``ik/pos_err`` (mm) and ``ik/rot_err`` (rad).

``designopt.cli`` parses the arguments and calls :func:`cmd_ik`; ``solve_poses`` is the
Python API.
"""

from __future__ import annotations

import argparse
import csv
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from designopt.errors import ConfigError

MATRIX_COLUMNS = tuple(f"T{i}{j}" for i in range(4) for j in range(4))
QUAT_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
PROGRESS_MIN = 20_000  # poses from which a progress bar shows
JOINT_NAMES = ["q1", "q2", "q3", "q4", "q5", "q6"]  # archived as ik attr joint_names


# ---------------------------------------------------------------------------- input


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


def _read_csv(path: Path, tol: float) -> np.ndarray:
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            lines = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: cannot read the poses file ({e})") from None
    lines = [ln for ln in lines if ln and any(c.strip() for c in ln)]
    if not lines:
        raise ConfigError(f"{path}: empty file; needs a header row and one pose per row")
    head = [c.strip() for c in lines[0]]
    if sorted(head) == sorted(MATRIX_COLUMNS):
        cols = MATRIX_COLUMNS
    elif sorted(head) == sorted(QUAT_COLUMNS):
        cols = QUAT_COLUMNS
    else:
        raise ConfigError(
            f"{path}: header {head}: give the columns {','.join(MATRIX_COLUMNS)} or "
            f"{','.join(QUAT_COLUMNS)} (any order)"
        )
    order = [head.index(c) for c in cols]
    if len(lines) == 1:
        raise ConfigError(f"{path}: no poses after the header row")
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
        raise ConfigError(f"{path}: row {int(np.argmax(bad)) + 1}: NaN or inf in the pose")
    if cols is QUAT_COLUMNS:
        nq = np.linalg.norm(vals[:, 3:], axis=-1)
        off = np.abs(nq - 1.0) > tol
        if off.any():
            i = int(np.argmax(off))
            raise ConfigError(f"{path}: row {i + 1}: quaternion is not a unit quaternion "
                              f"(|q| = {nq[i]:.9g}; tolerance {tol:g})")  # fmt: skip
        return quat_to_pose(vals)
    return vals.reshape(-1, 4, 4)


def _read_h5(path: Path) -> np.ndarray:
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
    return T


def read_poses(path: str | Path, tol: float = 1e-6) -> np.ndarray:
    """Poses (N, 4, 4) from a CSV or HDF5 file, checked (``ik.check_poses``): NaN/inf, a
    rotation not orthonormal to ``tol``, a reflection or a bad bottom row is a ConfigError
    naming the file and the row."""
    from designopt.studies.davinci.ik import check_poses

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: poses file not found")
    T = _read_h5(p) if p.suffix.lower() in (".h5", ".hdf5") else _read_csv(p, tol)
    bad = check_poses(T, tol)
    if bad:
        i, why = bad[0]
        more = f" ({len(bad) - 1} more rows with problems)" if len(bad) > 1 else ""
        raise ConfigError(f"{p}: row {i + 1}: {why}{more}")
    return T


# ---------------------------------------------------------------------------- solve


def solve_poses(settings: Any, T: np.ndarray, trajectory: bool = False,
                progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """IK of poses T (N, 4, 4) for the arm of ``settings`` (a DavinciSettings; float64
    must be enabled). Cold: every pose from the database (closest to ``ik.q_prev`` when
    given), in batches of ``ik.batch`` (the last padded, so one program serves all).
    ``trajectory``: in row order, each pose warm-started from the previous solution.
    ValueError naming the first pose (from 1) that is not a finite rigid transform."""
    import jax
    import jax.numpy as jnp

    from designopt.studies.davinci import ik, objective
    from designopt.studies.davinci.settings import KEYS

    if not jax.config.jax_enable_x64:
        raise ValueError("the IK runs in float64: enable it (precision: float64)")
    T = np.asarray(T, np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N, 4, 4), got {T.shape}")
    bad = ik.check_poses(T, settings.ik.orthonormal_tol)
    if bad:
        raise ValueError(f"pose {bad[0][0] + 1}: {bad[0][1]}")
    arm = settings.ik_arm()
    scale = {"alpha_deg": math.pi / 180, "beta_deg": math.pi / 180}
    X = jnp.asarray([arm[k] * scale.get(k, 1.0) for k in KEYS])
    o = objective.solver_options(settings)
    db = jax.jit(ik.build_database, static_argnums=1)(X, objective.solver_grid(settings))
    N, B = len(T), min(settings.ik.batch, len(T))
    qp = settings.ik.q_prev
    out: dict[str, list[np.ndarray]] = {
        k: [] for k in ("q", "success", "iterations", "pos_err", "rot_err")
    }
    if trajectory:
        fn = jax.jit(lambda T, q0: ik.solve_trajectory(X, db, T[:, None], q0[None], o))
        q_start = None if qp is None else _q_rad(qp)
        for i in range(0, N, B):
            Tk = T[i : i + B]
            n = len(Tk)
            if q_start is None:
                q_start = np.asarray(ik.seed(X, db, jnp.asarray(Tk[:1])))[0]
            if n < B:  # hold the last pose: one compiled program for every segment
                Tk = np.concatenate([Tk, np.broadcast_to(Tk[-1:], (B - n, 4, 4))])
            r = fn(jnp.asarray(Tk), jnp.asarray(q_start))
            r = jax.tree.map(lambda a, n=n: np.asarray(a)[:n, 0], r)
            ok = np.flatnonzero(r.success)
            q_start = r.q[ok[-1]] if len(ok) else q_start
            _collect(out, r)
            if progress is not None:
                progress(n)
    else:
        fn = jax.jit(lambda T, qprev: ik.solve(X, db, T, qprev, o))
        for i in range(0, N, B):
            Tk = T[i : i + B]
            n = len(Tk)
            if n < B:  # pad with the last pose: one compiled program for every batch
                Tk = np.concatenate([Tk, np.broadcast_to(Tk[-1:], (B - n, 4, 4))])
            qprev = None if qp is None else jnp.broadcast_to(jnp.asarray(_q_rad(qp)), (B, 6))
            r = jax.tree.map(lambda a, n=n: np.asarray(a)[:n], fn(jnp.asarray(Tk), qprev))
            _collect(out, r)
            if progress is not None:
                progress(n)
    return {k: np.concatenate(v) for k, v in out.items()}


def _q_rad(q_deg) -> np.ndarray:
    q = np.radians(np.asarray(q_deg, np.float64))
    q[2] = q_deg[2]
    return q


def _collect(out: dict[str, list[np.ndarray]], r: Any) -> None:
    for k in out:
        out[k].append(np.asarray(getattr(r, k)))


# ---------------------------------------------------------------------------- command


def arguments(k: argparse.ArgumentParser) -> None:
    """The arguments of ``designopt ik``."""
    k.add_argument(
        "config", help="config (YAML) with a davinci study, e.g. configs/davinci_ik.yaml"
    )
    k.add_argument("--poses", required=True, metavar="PATH", help="poses file (.csv or .h5)")
    k.add_argument("--out", default=None, metavar="PATH",
                   help="archive path (default results/davinci/<poses name>_ik.h5)")  # fmt: skip
    k.add_argument("--trajectory", action="store_true",
                   help="solve in row order, each pose warm-started from the previous solution")  # fmt: skip
    k.add_argument("--csv", action="store_true",
                   help="also write the joints, one row per pose, to <archive stem>_joints.csv")  # fmt: skip
    k.add_argument("--overwrite", action="store_true", help="replace an existing archive")
    k.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")
    k.add_argument("--quiet", action="store_true", help="no progress bar, no summary")


def cmd_ik(args: argparse.Namespace, ctx: Any = None) -> int:
    """``designopt ik CONFIG --poses PATH [--out PATH] [--trajectory] [--quiet]``;
    ``ctx.load`` loads the config as every command does (with its compilation cache)."""
    import jax

    from designopt import archive, config, ikreport, output
    from designopt.prepare import base_attrs
    from designopt.results import IKRecord
    from designopt.studies import streams
    from designopt.timing import Stopwatch

    cfg, text = ctx.load(args) if ctx is not None else config.load(args.config)
    if cfg.study.name != "davinci":
        raise ConfigError(f"{args.config}: key 'study.name': `designopt ik` solves the da Vinci "
                          f"arm; this config's study is '{cfg.study.name}'")  # fmt: skip
    if cfg.precision != "float64":
        raise ConfigError(f"{args.config}: key 'precision': the IK needs float64 "
                          "(errors of 1e-9 mm); set precision: float64")  # fmt: skip
    jax.config.update("jax_enable_x64", True)
    poses = Path(args.poses)
    T = read_poses(poses, cfg.study.ik.orthonormal_tol)
    out = Path(args.out or f"results/davinci/{poses.stem}_ik.h5")
    output.claim(out, getattr(args, "overwrite", False))
    csv_out = ikreport.csv_path(out) if getattr(args, "csv", False) else None
    if csv_out is not None:
        output.claim(csv_out, getattr(args, "overwrite", False))
    show = not args.quiet and len(T) >= PROGRESS_MIN
    from tqdm import tqdm

    with Stopwatch() as sw, tqdm(total=len(T), desc="ik", unit="pose", disable=not show) as bar:
        try:
            res = solve_poses(cfg.study, T, args.trajectory, bar.update)
        except ValueError as e:
            raise ConfigError(f"{poses}: {e}") from None
    mode = "trajectory" if args.trajectory else "cold"
    tree = {"ik": {**res, "poses": T,
                   "attrs": {"mode": mode, "poses_file": str(poses), "n": len(T),
                             "arm": cfg.study.ik_arm(), "joint_names": JOINT_NAMES,
                             "units": "q1, q2, q4, q5, q6 rad; q3 mm; pos_err mm; rot_err rad"}}}  # fmt: skip
    attrs = base_attrs("ik", cfg, text, streams(cfg.seed), args.config) | {
        "wall_time_s": sw.wall, "compile_time_s": sw.compile, "run_time_s": sw.run}  # fmt: skip
    rec = IKRecord(attrs, tree, cfg)
    archive.save(out, rec, overwrite=getattr(args, "overwrite", False))
    if csv_out is not None:
        output.write_file(csv_out, rec.csv_text().encode(), "joints CSV")
    if not args.quiet:
        print(f"mode: {mode}")
        for line in rec.summary()[1:]:
            print(line)
        print(f"wall {sw.wall:.1f} s = compile {sw.compile:.1f} s + run {sw.run:.1f} s")
        print(f"wrote {out}" + (f" and {csv_out}" if csv_out is not None else ""))
    return 0


def _command() -> Any:
    from designopt.studies.base import Command

    return Command(
        name="ik",
        help="inverse kinematics of the da Vinci arm for poses from a CSV or HDF5 file",
        description="Solve the da Vinci patient-side arm's inverse kinematics (Applied "
        "Sciences 2019) for every pose of a file: CSV with a header row and columns "
        "T00..T33 (row-major 4x4, mm) or x,y,z,qw,qx,qy,qz; or HDF5 with a dataset "
        "'poses' (N, 4, 4). Writes ik/q (q3 in mm, the others in rad), ik/success, "
        "ik/iterations, ik/pos_err (mm) and ik/rot_err (rad).",
        arguments=arguments,
        run=cmd_ik,
        writes=True,
    )


IK = _command()
"""``designopt ik``, declared in ``Study.commands``."""
