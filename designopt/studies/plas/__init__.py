"""Study D: the all-joints master of the Y-type single-port robot PLAS (seed 004, SPEC §6).

``mechanism`` (the slave and master chains on the generic kernel, the mapping factors of
eq. 28, the counterbalance), ``objective`` (the workspace mismatch as a constrained
Problem), ``figures`` (mismatch maps, factors, counterbalance), ``paper`` (the seed's
printed closed forms and numbers, for the tests), ``settings`` (the config section).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt.studies.base import Cost, Study
from designopt.studies.plas.settings import INDEX_UNITS, MASTER_KEYS, PlasSettings

SUMMARY = ("vel_rel", "vel_reduction", "vel_abs", "pos_mean")
INDICES = ("f", "vel_rel", "vel_reduction", "vel_abs", "vel_max", "pos_mean", "pos_max",
           "k2_min", "k2_max", "k3_min", "k3_max", "k4", "reach", "counterweight", "inertia")  # fmt: skip


def _problem(settings: PlasSettings, keys, dtype):
    from designopt.studies.plas import objective

    return objective.problem(settings, keys, dtype)


def _figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.plas import figures

    return figures.draw_run(record, folder)


def _aliases(s: PlasSettings) -> dict[str, str]:
    out = {f"study.{k}": f"study.mismatch.{k}" for k in ("n_samples", "n_path", "joint_rate_deg_s")}
    out |= {f"objective.{k}": f"study.objective.{k}" for k in ("velocity", "position", "inertia")}
    out |= {f"design.{k}": f"study.fixed.{k}" for k in MASTER_KEYS if k not in s.variables}
    return out


def _extra(s: PlasSettings, fin) -> list[str]:
    return [
        f"  max mismatch over the samples (no SE, docs/plas.md): |Δv| {float(fin['vel_max']):.3g} mm/s, "
        f"|Δp| {float(fin['pos_max']):.3g} mm",
        f"  reach {float(fin['reach']):.1f} mm; factors k2 ∈ [{float(fin['k2_min']):.3f}, "
        f"{float(fin['k2_max']):.3f}], k3 ∈ [{float(fin['k3_min']):.3f}, {float(fin['k3_max']):.3f}], "
        f"k4 = {float(fin['k4']):.3f}",
        f"  counterweight {float(fin['counterweight']):.1f} g, inertia {float(fin['inertia']):.4g} g·cm²",
    ]


def _cost(s) -> Cost:
    """Monte-Carlo cost per design (pre-flight): the mismatch samples, ``chunk`` in flight."""
    m = s.mismatch
    return Cost(
        m.n_samples,
        min(m.chunk, m.n_samples),
        1,
        "study.mismatch.n_samples",
        "study.mismatch.chunk",
    )


STUDY = Study(
    name="plas",
    title="PLAS all-joints master (DGIST MS thesis 2015): master lengths for the least tip-velocity mismatch",
    settings=PlasSettings,
    problem=_problem,
    summary=lambda s: SUMMARY,
    indices=lambda s: INDICES,
    figures=_figures,
    sweep_aliases=_aliases,
    units=lambda s: dict.fromkeys(s.variables, "mm") | INDEX_UNITS,
    extra_lines=_extra,
    example_config="configs/plas.yaml",
    cost=_cost,
    tiny={
        "name": "plas",
        "mismatch": {"n_samples": 256, "chunk": 128, "n_path": 2},
        "constraints": {"n_grid": 3},
    },  # fmt: skip
    meta={
        "variables": ", ".join(MASTER_KEYS) + " (mm; default a2p, d6)",
        "indices": ", ".join(INDICES),
    },
)
