"""``designopt ik`` for any serial chain of the config (DH table or URDF): the study's
``Study.ik`` hook (:data:`HOOK`) on the generic batched IK
(``designopt.kinematics.ik.solve_design``: Sugihara's Levenberg–Marquardt, "Solvability-
unconcerned inverse kinematics by the Levenberg–Marquardt method", IEEE T-RO 2011, from
FK-database and random seeds with restarts).

The design is the middle of each variable's box unless ``--design NAME=VALUE`` gives it
(as ``designopt eval``), with the config's ``fixed`` values. Targets are in the chain's
own length unit. Solved in batches of :data:`BATCH` (fewer targets: the next power of two
from 64), the last padded by repeating its last target, so one compiled program serves
every batch. Archived per target: q (rad for R joints, the chain's unit for P joints),
success, pos_err, rot_err and inv_k (1/k, 2-norm, of the position block at the solution).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from designopt.kinematics.ikjob import IKHook, IKJob, IKSolution

BATCH = 1024
"""Targets per compiled call (a smaller file: the next power of two from 64)."""
COMMAND_OPTIONS = {"n_best": 4}
"""The command's solver settings where ``study.task.ik`` does not set them: the solver's
defaults (PUMA 560 poses from random joints in the limits: ≥ 99.9 % solved, see
``benchmarks/ik.py``), but each target goes on after its first converged seed until 4 have
converged (or its seeds run out), and the best-conditioned of them is kept: each target
is solved once here, and the designer wants the best configuration found."""


def options(s: Any) -> Any:
    """The solver's ``IKOptions``: :data:`COMMAND_OPTIONS`, then every key given in the
    config's ``study.task.ik``."""
    from designopt.kinematics import ik

    given = {}
    if s.task is not None:
        o = s.task.ik
        given = {k: getattr(o, k) for k in o.model_fields_set}
    return ik.IKOptions(**(COMMAND_OPTIONS | given))


def design(s: Any, given: dict[str, float], where: str) -> dict[str, float]:
    """Every design variable's value: ``--design`` or the middle of its box."""
    from designopt.studies.serial.commands import design_values

    return design_values(s, given, where)


def batch(n: int) -> int:
    """Targets per call for n targets: :data:`BATCH`, or the next power of two ≥ n (at
    least 64) when fewer, so small files of similar size share one program."""
    return min(BATCH, max(64, 1 << max(n - 1, 0).bit_length()))


@functools.cache
def _solver() -> Any:
    import jax

    from designopt.kinematics import ik

    return jax.jit(ik.solve_design, static_argnames=("model", "mode", "opts"))


def units(s: Any, names: list[str]) -> str:
    """The units text of the joints and errors: R joints rad, P joints and the position
    error in the chain's length unit (m for a URDF, the declared unit, else L), rot_err
    rad, inv_k dimensionless."""
    from designopt.studies.serial.settings import UrdfChain, length_unit

    urdf = isinstance(s.chain, UrdfChain)
    types = s.chain.imported.types if urdf else [j.type for j in s.chain.joints]
    rev = [n for n, t in zip(names, types, strict=True) if t == "R"]
    pri = [n for n, t in zip(names, types, strict=True) if t != "R"]
    u = length_unit(s)
    parts = ([", ".join(rev) + " rad"] if rev else []) + ([", ".join(pri) + f" {u}"] if pri else [])
    return "; ".join([*parts, f"pos_err {u}", "rot_err rad", "inv_k -"])


def solve(job: IKJob) -> IKSolution:
    """Every target of the job for the chain at ``job.design``, in padded batches."""
    import jax
    import jax.numpy as jnp

    from designopt.studies.serial.mechanism import build
    from designopt.studies.serial.settings import UrdfChain

    if not jax.config.jax_enable_x64:
        raise ValueError("the IK runs in float64: enable it (precision: float64)")
    s, mode = job.settings, job.mode
    mech = build(s)
    x = [job.design[k] for k in s.variables]
    X = jnp.asarray(np.concatenate([x, mech.fixed]) * mech.scale, jnp.float64)
    lo, hi = jnp.asarray(mech.lower, jnp.float64), jnp.asarray(mech.upper, jnp.float64)
    opts = options(s)
    p_all = np.asarray(job.targets.p, np.float64)
    R_all = job.targets.rotations(mode)
    N = len(p_all)
    B = batch(N)
    fn = _solver()
    keys = ("q", "success", "pos_err", "rot_err", "inv_k")
    out: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for i in range(0, N, B):
        n = min(B, N - i)
        pad = np.r_[np.arange(i, i + n), np.full(B - n, i + n - 1)]  # repeat the last target
        Rt = None if R_all is None else jnp.asarray(R_all[pad])
        r = fn(mech.model, X, jnp.asarray(p_all[pad]), Rt, lo, hi, job.key, mode, opts)
        for k in keys:
            out[k].append(np.asarray(getattr(r, k))[:n])
        if job.progress is not None:
            job.progress(n)
    arrays = {k: np.concatenate(v) for k, v in out.items()}
    if isinstance(s.chain, UrdfChain):
        names = list(s.chain.imported.active)
    else:
        names = [f"q{i + 1}" for i in range(mech.n)]
    attrs = {"solver": "levenberg_marquardt", "batch": B, "options": dict(opts._asdict())}
    return IKSolution(arrays, names, units(s, names), attrs)


HOOK = IKHook(solve=solve, design=design)
"""``designopt ik`` for the serial study (``Study.ik``): every mode (position, axis, pose)."""
