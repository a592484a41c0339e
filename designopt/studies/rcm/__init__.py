"""The planar RCM mechanism and its 3-DOF arm (the planar RCM mechanism paper, Sensors
2023): ``mechanism`` (planar FK/IK/Jacobian with the corrected E, the arm's DH model,
FK and IK), ``objective`` (η over stated workspaces, reach, constraints), ``workspace``
(the arm's Monte-Carlo workspace), ``teleop`` (the incremental master-slave mapping
replayed as one lax.scan), ``figures``, ``paper`` (the printed formulas). Two studies:
``rcm`` (design) and ``rcm_teleop`` (a trajectory replay).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt.studies.base import Cost, Study
from designopt.studies.rcm.settings import RcmSettings, TeleopSettings, units

SUMMARY = ("eta", "eta_box", "eta_cone", "eta_reach", "reach")
INDICES = ("f", "eta", "eta_box", "eta_cone", "eta_reach", "reach", "eq19_margin")


def _problem(settings: RcmSettings, keys, dtype):
    from designopt.studies.rcm import objective

    return objective.problem(settings, keys, dtype)


def _figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.rcm import figures

    return figures.draw_run(record, folder)


def _extra(s: RcmSettings, fin) -> list[str]:
    built = "a = 120, b = 260, c = 250 mm"
    return [
        f"  eq. (19) margin a − sin(apex/2)(c − d_min) = {float(fin['eq19_margin']):.2f} mm; "
        f"η over workspace '{s.eta.workspace}' ({s.eta.measure} measure, cone dim {s.cone.dim})",
        f"  built design for comparison: {built} (`designopt eval` it: docs/rcm.md)",
    ]


def _cost(s) -> Cost:
    """Monte-Carlo cost per design (pre-flight): the η samples, all in flight, a few
    scalars each (the planar closed forms fuse into the reductions; benchmarks/preflight.py
    on configs/rcm.yaml measured the default 128 B per design-sample 2.3× too high)."""
    n = s.eta.n_samples
    return Cost(n, n, 1, "study.eta.n_samples", "study.eta.n_samples", bytes_per_sample=16)


STUDY_RCM = Study(
    name="rcm",
    title="planar RCM mechanism (Sensors 2023): link lengths (a, c) for the best conditioning over the task cone",
    settings=RcmSettings,
    problem=_problem,
    summary=lambda s: SUMMARY,
    indices=lambda s: INDICES,
    figures=_figures,
    sweep_aliases=lambda s: {
        "study.n_samples": "study.eta.n_samples",
        **{f"design.{k}": f"study.fixed.{k}" for k in ("a", "b", "c") if k not in s.variables},
    },
    units=units,
    extra_lines=_extra,
    example_config="configs/rcm.yaml",
    cost=_cost,
    tiny={"name": "rcm", "eta": {"n_samples": 1024}},
    meta={"variables": "a, c (mm)", "indices": ", ".join(INDICES)},
)


def _replay(s, keys, dtype, where: str):
    from designopt.studies.rcm import replay

    return replay.run(s, dtype, where)


def _teleop_figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.rcm import figures

    return figures.draw_teleop(record, folder)


STUDY_TELEOP = Study(
    name="rcm_teleop",
    title="planar RCM arm (Sensors 2023): a master trajectory replayed through the incremental mapping",
    settings=TeleopSettings,
    problem=None,  # a replay: no design problem
    summary=lambda s: (),
    indices=lambda s: (),
    figures=_teleop_figures,
    example_config="configs/rcm_teleop.yaml",
    tiny={"name": "rcm_teleop", "trajectory": "data/rcm_master_square.csv"},
    meta={"variables": "none (a replay)", "indices": "tracking error, clamping"},
    replay=_replay,
)

STUDY = (STUDY_RCM, STUDY_TELEOP)
