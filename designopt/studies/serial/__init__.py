"""The generic ``serial`` study: any serial chain described in YAML (a DH table or a
robot's URDF, design variables, joint limits), scored by dexterity, manipulability and workspace volume on the
generic frame kernel (``designopt.kinematics.kernel``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt.studies.base import Cost, Study
from designopt.studies.serial import ikhook
from designopt.studies.serial.commands import COMMANDS
from designopt.studies.serial.settings import INDEX_NAMES, TASK_INDEX_NAMES, SerialSettings, units


def _problem(settings: SerialSettings, keys, dtype):
    from designopt.studies.serial import objective

    return objective.problem(settings, keys, dtype)


def _figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.serial import figures

    return figures.draw_run(record, folder)


def _cloud(record: Any) -> dict[str, Any]:
    from designopt.studies.serial import figures

    return figures.cloud(record)


def _aliases(s: SerialSettings) -> dict[str, str]:
    out = {f"study.{k}": f"study.indices.{k}" for k in ("n_samples", "length_scale")}
    out |= {f"design.{k}": f"study.fixed.{k}" for k in s.fixed}
    out |= {f"objective.{k}": f"study.objective.{k}" for k in s.weights()}
    return out


def _cost(s) -> Cost:
    """Monte-Carlo cost per design (pre-flight): the index samples, ``chunk`` in flight,
    and the normalisation probes when the objective normalises. Under ``measure: task``
    a sample is a target (``front.n_samples`` counts targets too) and a chunk holds the
    IK solutions compared per target (and its place in the queue)."""
    ind, n_norm = s.indices, s.objective.get("n_norm")
    if ind.measure == "task":
        from designopt.studies.serial import taskindex

        kept = s.task.ik.n_best + 1  # the solutions compared, and the queue
        n, c = taskindex.n_targets(s), taskindex.chunk(s) * kept
    else:
        n, c = ind.n_samples, min(ind.chunk, ind.n_samples)
    return Cost(
        n,
        c,
        int(n_norm or 1),
        "study.indices.n_samples",
        "study.indices.chunk",
        "study.objective.n_norm" if n_norm is not None else None,
    )


STUDY = Study(
    name="serial",
    title="any serial chain from YAML (DH table or URDF, with named design variables)",
    settings=SerialSettings,
    problem=_problem,
    summary=lambda s: s.index_names(),
    indices=lambda s: ("f", *s.index_names()),
    figures=_figures,
    sweep_aliases=_aliases,
    units=units,
    example_config="configs/planar2r.yaml",
    cost=_cost,
    commands=COMMANDS,
    ik=ikhook.HOOK,
    cloud=_cloud,
    tiny={
        "name": "serial",
        "chain": {
            "convention": "modified",
            "joints": [
                {"type": "R", "a": 0, "alpha": 0, "d": 0, "theta": 0, "limits": [-150, 150]},
                {"type": "R", "a": "l1", "alpha": 90, "d": "h", "theta": 0, "limits": [-90, 90]},
                {"type": "P", "a": "l2", "alpha": -90, "d": 0.2, "theta": 0, "limits": [0.1, 0.5]},
            ],
        },
        "variables": {"l1": [0.2, 1.0], "l2": [0.05, 0.5]},
        "fixed": {"h": 0.1},
        "indices": {
            "jacobian": "position",
            "norm": "fro",
            "normalized": True,
            "measure": "cartesian",
            "n_samples": 2048,
        },
        "objective": {"gci": -1.0, "volume": -0.5, "normalize": True, "n_norm": 8},
    },
    meta={
        "variables": "any names used in study.chain (DH a, d, alpha, theta, or a URDF "
        "chain's set values)",
        "indices": ", ".join(INDEX_NAMES) + " (volume for square position Jacobians); "
        "under measure: task " + ", ".join(TASK_INDEX_NAMES),
    },
)
