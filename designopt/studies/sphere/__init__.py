"""The 2-DOF spherical remote-centre-of-motion mechanism of Lum, Warden, Rosen, Sinanan and
Hannaford's hybrid analysis (docs/sphere.md): the link angles (α12, α23) for the best
isotropy of the tool direction's Jacobian over a cone of tool directions.

``mechanism`` (FK, the 3×2 Jacobian, the closed-form IK with both branches, the reachable
band), ``objective`` (the Monte-Carlo mean of 1/k over the cone, reach, the hybrid's arc
length, the reach constraints), ``closedform`` (the index at (90°, 90°) in closed form),
``paper`` (the published numbers), ``figures``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from designopt.studies.base import Cost, Study
from designopt.studies.sphere.settings import SphereSettings, units

SUMMARY = ("gci", "reach", "gci_reached")
INDICES = ("f", "gci", "reach", "gci_reached", "arc_length")


def _problem(settings: SphereSettings, keys, dtype):
    from designopt.studies.sphere import objective

    return objective.problem(settings, keys, dtype)


def _figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.sphere import figures

    return figures.draw_run(record, folder)


def _extra(s: SphereSettings, fin) -> list[str]:
    from designopt.studies.sphere import closedform, paper

    c = s.cone
    ref = closedform.mean_right_angles(
        math.radians(c.half_angle_deg), math.radians(c.axis_angle_deg)
    )
    return [
        f"  cone: half-angle {c.half_angle_deg:g}°, axis {c.axis_angle_deg:g}° from joint axis 1; "
        f"arcs α12 + α23 = {math.degrees(float(fin['arc_length'])):.2f}°",
        f"  at (90°, 90°) the index is {ref:.6f} in closed form (docs/sphere.md); the paper's "
        f"kinematic optimum {paper.KINEMATIC_OPTIMUM}, hybrid {paper.HYBRID_OPTIMUM}, "
        f"Raven II as built {paper.RAVEN_II} (deg)",
    ]


def _warnings(s: SphereSettings, fin) -> list[str]:
    """``gci_reached`` n/a (fewer than ``objective.N_MIN`` of the cone's directions
    reached) says so, with the counts; any other n/a index gets the generic line
    (``results.base.na_warnings``)."""
    from designopt.results.base import na_indices, na_warnings
    from designopt.studies.sphere.objective import N_MIN

    own = []
    if "gci_reached" in na_indices(fin):
        n, of = fin.get("gci_reached_n"), fin.get("gci_reached_of")
        k = (f"{float(n):.0f} of {float(of):.0f}" if n is not None and of is not None
             else f"fewer than {N_MIN} of the")  # fmt: skip
        own.append(f"gci_reached: n/a ({k} tool directions reached; under {N_MIN}): too few "
                   "to say how isotropic the mechanism is where it reaches; gci counts every "
                   "unreached direction as 0")  # fmt: skip
    return na_warnings(fin, own)


def _cost(s: SphereSettings) -> Cost:
    """Monte-Carlo cost per design (pre-flight): the directions, ``chunk`` in flight, each
    two IK branches with their 3×2 Jacobians (about 40 floats)."""
    ix = s.index
    return Cost(ix.n_samples, min(ix.chunk, ix.n_samples), 1, "study.index.n_samples",
                "study.index.chunk", bytes_per_sample=320)  # fmt: skip


STUDY = Study(
    name="sphere_rcm",
    title="2-DOF spherical RCM (Lum et al., hybrid analysis): link angles (α12, α23) for the "
    "best isotropy over a cone of tool directions",
    settings=SphereSettings,
    problem=_problem,
    summary=lambda s: SUMMARY,
    indices=lambda s: INDICES,
    figures=_figures,
    sweep_aliases=lambda s: {
        "study.n_samples": "study.index.n_samples",
        **{
            f"design.{k}": f"study.fixed.{k}"
            for k in ("alpha12", "alpha23")
            if k not in s.variables
        },
    },
    units=units,
    extra_lines=_extra,
    warnings=_warnings,
    example_config="configs/sphere_rcm.yaml",
    cost=_cost,
    tiny={"name": "sphere_rcm", "index": {"n_samples": 512, "sampler": "rqmc", "replicates": 4}},
    meta={"variables": "alpha12, alpha23 (deg)", "indices": ", ".join(INDICES)},
)
