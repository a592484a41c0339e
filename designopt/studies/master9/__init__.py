"""Study A: the 9-DOF haptic master of seed 000 (SPEC §3).

``mechanism`` (kinematics, closed forms, IK), ``indices`` (the swarm index kernel),
``objective`` (the composite objective of eq. 43 as a Problem), ``figures`` (Fig. 12-15),
``volume`` (point-cloud volume cross-checks), ``settings`` (the config section).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt.studies.base import Cost, Study
from designopt.studies.master9.settings import DESIGN_KEYS, Indices, Master9Settings

SUMMARY = ("f_k", "f_l", "f_p", "gci", "gcsei", "gpi")
INDICES = ("f", "f_k", "f_l", "f_p", "gci", "gcsei", "gpi", "volume", "L")


INDEX_UNITS = {"f": "-", "f_k": "-", "f_l": "-", "f_p": "mm", "gci": "-", "gcsei": "-",
               "gpi": "mm", "volume": "mm³", "L": "mm"}  # fmt: skip
"""Units of every index (figures label their axes with them)."""


def _problem(settings: Master9Settings, keys, dtype):
    from designopt.studies.master9 import objective

    return objective.problem(settings, keys, dtype)


def _figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.master9 import figures

    return figures.draw_run(record, folder)


def _cloud(record: Any) -> dict[str, Any]:
    from designopt.studies.master9 import figures

    return figures.cloud(record)


def _aliases(s: Master9Settings) -> dict[str, str]:
    out = {f"study.{k}": f"study.indices.{k}" for k in Indices.model_fields}
    out |= {f"design.{k}": f"study.fixed.{k}" for k in DESIGN_KEYS}  # variables: refused later
    out |= {f"study.fixed.{k}": f"study.fixed.{k}" for k in DESIGN_KEYS}
    return out


def _cost(s: Master9Settings) -> Cost:
    """Samples per design, the chunk in flight and the normalisation probes, with the
    config keys a user lowers (the pre-flight estimate). Its memory per design and sample
    in flight, ``bytes_per_sample`` (float64's; a float32 job counts half): 8 B, as XLA
    fuses a chunk's kinematics into its reductions (64 designs × 262144 samples: 5 B of
    temporaries by ``memory_analysis()`` in float64, 7 B of peak resident set in float32;
    at the shipped 64 × 8192 either is a few MB)."""
    n = s.indices.n_samples
    return Cost(samples=n, chunk=min(n, s.indices.chunk), n_norm=s.n_norm,
                samples_key="study.indices.n_samples", chunk_key="study.indices.chunk",
                norm_key="study.n_norm", bytes_per_sample=8)  # fmt: skip


def _extra(s: Master9Settings, fin) -> list[str]:
    return [f"  V     = {float(fin['volume']):.4e} ± {float(fin['volume_se']):.1e} mm³   "
            f"L = {float(fin['L']):.3f} mm"]  # fmt: skip


STUDY = Study(
    name="master9",
    title="9-DOF haptic master for laparoscopic robots (IEEE Access 2019): (a1, a3, d3), eq. (43)",
    settings=Master9Settings,
    problem=_problem,
    summary=lambda s: SUMMARY,
    indices=lambda s: INDICES,
    figures=_figures,
    sweep_aliases=_aliases,
    units=lambda s: dict.fromkeys(s.variables, "mm") | INDEX_UNITS,
    extra_lines=_extra,
    cost=_cost,
    cloud=_cloud,
    example_config="configs/master9.yaml",
    tiny={"name": "master9", "indices": {"n_samples": 2048}, "n_norm": 8},
    meta={
        "variables": ", ".join(DESIGN_KEYS) + " (mm; default a1, a3, d3)",
        "indices": ", ".join(INDICES),
    },
)
