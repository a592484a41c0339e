"""Issue #52's closed-form check, shared by tests/test_best_solution.py and
benchmarks/best_solution.py: the tool's per-target 1/k (the kept IK solution of
``designopt``'s serial study at every target, as ``designopt eval`` scores it) against
the best free 1/k of :mod:`reference.ur5_closed_form` on the same targets.

Every case's config takes its targets from a points file (tests/data), so ``--seed``
changes the IK's random seeds alone and the oracle, which has none, is computed once per
case."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from reference import ur5_closed_form as cf

DATA = Path(__file__).resolve().parents[1] / "data"
UR5_CONFIG = DATA / "ur5_port.yaml"
PLANAR_CONFIG = DATA / "planar3r_task.yaml"
TOL = 1e-4
"""A target's 1/k matches the oracle's best when within this (issue #52)."""


@dataclass(frozen=True)
class Case:
    name: str
    config: Path
    design: dict[str, float]

    @property
    def planar(self) -> bool:
        return self.config == PLANAR_CONFIG


UR5 = {"a2": 0.425, "a3": 0.39225}
CASES = (
    Case("ur5_straight", UR5_CONFIG, UR5 | {"tilt": 0.0}),
    Case("ur5_short_arm", UR5_CONFIG, {"a2": 0.33, "a3": 0.28, "tilt": 0.0}),
    Case("ur5_tilted_25", UR5_CONFIG, UR5 | {"tilt": 25.0}),
    Case("planar3r", PLANAR_CONFIG, {"l1": 1.0, "l2": 0.8, "l3": 0.5}),
)
BY_NAME = {c.name: c for c in CASES}


def settings(case: Case, seed: int = 0) -> Any:
    import designopt

    return designopt.load_config(case.config, {"seed": seed})


def tool(case: Case, seed: int) -> dict[str, np.ndarray]:
    """The tool's solution at every target of the case at ``--seed`` (``blocks.solution``:
    the program ``eval`` and the run's ``targets`` group use), NumPy arrays."""
    from designopt.core.keys import streams
    from designopt.studies.serial import blocks

    cfg = settings(case, seed)
    return blocks.solution(cfg.study, case.design, streams(seed))


def oracle(case: Case, n_grid: int = 720, near: float = 0.01) -> dict[str, Any]:
    """The best free 1/k at every target of the case (the config's points), with what the
    check needs: ``best`` (N,), ``reached`` (N,), ``q``, ``p`` (N, 3) the targets and
    for the UR5 ``z`` the tool axes, ``ur`` the arm, ``free`` the collision check."""
    cfg = settings(case)
    s = cfg.study
    p = np.asarray(s.task.region.xyz(), np.float64)
    if case.planar:
        x = case.design
        lo = np.radians([j.limits[0] for j in s.chain.joints])
        hi = np.radians([j.limits[1] for j in s.chain.joints])
        ll = (x["l1"], x["l2"], x["l3"])
        o = cf.best_planar3r(p[:, :2], ll, lo, hi, n_grid=n_grid, near=near)
        return o | {"p": p, "l": ll}
    free, inside, info = cf.study_free(s, case.design, p)
    ur = cf.study_ur5(s, case.design)
    z = p - info["port"]
    z /= np.linalg.norm(z, axis=-1, keepdims=True)
    o = cf.best_axis(ur, p, z, free, n_grid=n_grid, near=near, reachable=inside)
    return o | {"p": p, "z": z, "ur": ur, "free": free, "inside": inside}


def compare(case: Case, sol: dict[str, np.ndarray], orc: dict[str, Any]) -> dict[str, Any]:
    """The numbers of the check for one seed's solution ``sol`` against the oracle."""
    ok = np.asarray(sol["success"], bool)
    v = np.asarray(sol["inv_k"], np.float64)
    best = orc["best"]
    d = v - best
    gci, om = float(v.mean()), float(best.mean())
    # the tool's kept joints, checked independently: on the target, and their 1/k
    q = np.asarray(sol["q"], np.float64)
    if case.planar:
        tip_err = np.linalg.norm(cf.planar3r_fk(q, orc["l"]) - orc["p"][:, :2], axis=-1)
        axis_err = np.zeros(len(q))
        own = cf.inv_k(cf.planar3r_jacobian(q, orc["l"]))
        free_ok = np.ones(len(q), bool)
    else:
        T = orc["ur"].chain.fk(q)
        tip_err = np.linalg.norm(T[:, :3, 3] - orc["p"], axis=-1)
        axis_err = np.linalg.norm(T[:, :3, 2] - orc["z"], axis=-1)
        own = orc["ur"].inv_k(q)
        free_ok = np.ones(len(q), bool)
        if ok.any():
            free_ok[ok] = orc["free"](q[ok], np.nonzero(ok)[0])
    n_ok = int(ok.sum())
    return {
        "gci": gci,
        "oracle": om,
        "gap": (om - gci) / om if om > 0 else math.nan,
        "reach": float(ok.mean()),
        "oracle_reach": float(np.mean(orc["reached"])),
        "n_reached": n_ok,
        "within": float(np.mean(np.abs(d[ok]) <= TOL)) if n_ok else math.nan,
        "worst": float(np.min(d[ok])) if n_ok else math.nan,  # the largest shortfall (< 0)
        "beats": int(np.sum(d[ok] > 1e-9)),  # the tool above the oracle: a bug in one of them
        "beat_by": float(np.max(d[ok])) if n_ok else math.nan,
        "missed": int(np.sum(orc["reached"] & ~ok)),  # the oracle reaches, the tool does not
        "extra": int(np.sum(ok & ~orc["reached"])),  # the tool reaches, the oracle does not
        "tip_err": float(np.max(tip_err[ok])) if n_ok else 0.0,
        "axis_err": float(np.max(axis_err[ok])) if n_ok else 0.0,
        "inv_k_err": float(np.max(np.abs(own - v)[ok])) if n_ok else 0.0,
        "not_free": int(np.sum(~free_ok[ok])),
    }
