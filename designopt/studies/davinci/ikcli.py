"""The da Vinci patient-side arm's inverse kinematics for ``designopt ik`` (the da Vinci
patient-side arm IK paper, Applied Sciences 2019; docs/davinci.md): the study's
``Study.ik`` hook (:data:`IK`) on its own solver (``ik``: damped Newton / LM from database
seeds, ``--trajectory`` warm starts).

The generic command (``designopt.cli.ik``, ``designopt.io.poses``) reads and checks the poses (CSV ``T00..T33`` or
``x,y,z,qw,qx,qy,qz`` in mm, HDF5 ``poses`` (N, 4, 4)) and archives ``ik/q`` (N, 6; q1,
q2, q4, q5, q6 in rad, q3 in mm), ``ik/success``, ``ik/iterations``, ``ik/pos_err`` (mm)
and ``ik/rot_err`` (rad). ``solve_poses`` is the Python API; ``read_poses`` reads a file
of full poses.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from designopt.core.errors import ConfigError
from designopt.io.poses import MATRIX_COLUMNS, QUAT_COLUMNS
from designopt.io.poses import read_targets as _read_targets
from designopt.kinematics import poses
from designopt.kinematics.ikjob import IKHook, IKJob, IKSolution
from designopt.kinematics.poses import quat_to_pose
from designopt.studies.base import known_lengths

JOINT_NAMES = ["q1", "q2", "q3", "q4", "q5", "q6"]  # archived as ik attr joint_names
UNITS = "q1, q2, q4, q5, q6 rad; q3 mm; pos_err mm; rot_err rad"
__all__ = ["IK", "JOINT_NAMES", "MATRIX_COLUMNS", "QUAT_COLUMNS", "quat_to_pose", "read_poses",
           "solve_poses"]  # fmt: skip


def read_poses(path: str | Path, tol: float = 1e-6) -> np.ndarray:
    """Poses (N, 4, 4) from a CSV or HDF5 file of full poses, every row checked
    (``designopt.io.poses.read_targets``): a ConfigError naming the file and the row."""
    t = _read_targets(path, tol)
    if t.R is None:
        raise ConfigError(f"{path}: the arm's IK needs full poses (T00..T33 or "
                          "x,y,z,qw,qx,qy,qz); the file gives positions only")  # fmt: skip
    return t.poses()


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
    bad = poses.check_poses(T, settings.ik.orthonormal_tol)
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


# ---------------------------------------------------------------------------- hook


def _design(s: Any, given: dict[str, float], where: str) -> dict[str, float]:
    """The arm solved for: ``ik_arm()`` (Table 1, ``fixed``, ``ik.arm``), then
    ``--design`` values of alpha_deg, beta_deg, l_QH, l_IJ."""
    try:
        known_lengths(given, tuple(s.ik_arm()), ("l_QH", "l_IJ"), "arm parameter")
    except ValueError as e:
        raise ConfigError(f"{where}: --design: {e}") from None
    return s.ik_arm() | {k: float(v) for k, v in given.items()}


def _arguments(k: argparse.ArgumentParser) -> None:
    """The arm's own flag of ``designopt ik``."""
    k.add_argument("--trajectory", action="store_true",
                   help="solve in row order, each pose warm-started from the previous solution")  # fmt: skip


def _solve(job: IKJob) -> IKSolution:
    """Every pose of the job with ``solve_poses`` (cold, or ``--trajectory``)."""
    s = job.settings
    if job.design != s.ik_arm():
        s = s.model_copy(update={"ik": s.ik.model_copy(update={"arm": dict(job.design)})})
    trajectory = bool(job.options.get("trajectory", False))
    res = solve_poses(s, job.targets.poses(), trajectory, job.progress)
    mode = "trajectory" if trajectory else "cold"
    return IKSolution(res, JOINT_NAMES, UNITS, attrs={"mode": mode, "arm": dict(job.design)},
                      lines=[f"mode: {mode}"])  # fmt: skip


IK = IKHook(solve=_solve, design=_design, modes=("pose",), arguments=_arguments,
            tol=lambda s: s.ik.orthonormal_tol)  # fmt: skip
"""``designopt ik`` for the arm, declared as ``Study.ik``."""
