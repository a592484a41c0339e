"""Study B: the da Vinci patient-side arm (the da Vinci patient-side arm IK paper,
Applied Sciences 2019).

``mechanism`` (the chain of eq. 1-3 on the generic kernel, H, joint ranges), ``ik`` (the
batched production IK: damped Newton / LM with database seeds, trajectory mode, the
closed form used for checks), ``paper`` (the paper's scan + Newton method, Table 2),
``objective`` (dexterity and IK success over the surgical cone against l_IJ and β),
``figures``, ``ikcli`` (its ``designopt ik`` hook, ``Study.ik``), ``settings`` (the config section).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt.studies.base import Cost, Study
from designopt.studies.davinci.ikcli import IK
from designopt.studies.davinci.settings import UNITS, DavinciSettings

INDICES = ("f", "gci", "coverage", "ik_success", "reach")
SUMMARY = ("gci", "coverage", "ik_success", "reach")
INDEX_UNITS = dict.fromkeys(INDICES, "-")
"""Units of every index: all dimensionless (f, GCI, and rates in [0, 1])."""


def _problem(settings: DavinciSettings, keys, dtype):
    from designopt.studies.davinci import objective

    return objective.problem(settings, keys, dtype)


def _figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.davinci import figures

    return figures.draw_run(record, folder)


def _aliases(s: DavinciSettings) -> dict[str, str]:
    out = {f"study.{k}": f"study.indices.{k}" for k in ("n_samples", "n_ik", "length_mm")}
    out |= {f"study.{k}": f"study.workspace.{k}" for k in ("cone_deg", "tool_cone_deg")}
    out |= {f"objective.{k}": f"study.objective.{k}" for k in ("gci", "ik_success")}
    out |= {f"design.{k}": f"study.fixed.{k}" for k in UNITS if k not in s.variables}
    return out


def _cost(s) -> Cost:
    """Monte-Carlo cost per design (pre-flight): the GCI's joint samples, all in flight;
    its batched IK compiles to a large program (some 570 MB resident once compiled,
    measured with benchmarks/preflight.py on configs/davinci.yaml)."""
    n = s.indices.n_samples
    return Cost(n, n, 1, "study.indices.n_samples", "study.indices.n_samples",
                program=550 << 20)  # fmt: skip


STUDY = Study(
    name="davinci",
    title="da Vinci patient-side arm (Applied Sciences 2019): wrist offset and tilt for "
    "dexterity and IK success around the RCM point",
    settings=DavinciSettings,
    problem=_problem,
    summary=lambda s: SUMMARY,
    indices=lambda s: INDICES,
    figures=_figures,
    sweep_aliases=_aliases,
    units=lambda s: {k: UNITS[k] for k in s.variables} | INDEX_UNITS,
    example_config="configs/davinci.yaml",
    cost=_cost,
    ik=IK,
    tiny={
        "name": "davinci",
        "indices": {"n_samples": 256, "n_ik": 32, "solver": "closed_form"},
    },
    meta={
        "variables": "alpha_deg, beta_deg, l_QH, l_IJ (deg, mm; default l_IJ, beta_deg)",
        "indices": ", ".join(INDICES),
    },
)
