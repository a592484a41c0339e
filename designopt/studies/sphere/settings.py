"""The ``study:`` section of a ``sphere_rcm`` config (docs/sphere.md lists every key).

The 2-DOF spherical remote-centre-of-motion mechanism of Lum, Warden, Rosen, Sinanan and
Hannaford's hybrid analysis: joint axis 1 (the base axis), joint axis 2 and the tool axis
all pass through the remote centre; the link angles α12 (axis 1 to axis 2) and α23 (axis
2 to the tool) are the design. Angles are in degrees in the config, radians inside.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from designopt.studies.base import Section, StudySettings, check_replicates, lo_hi

DESIGN_KEYS: tuple[str, ...] = ("alpha12", "alpha23")
"""The link angles (deg): α12 between joint axes 1 and 2, α23 between axis 2 and the tool."""
KINEMATIC_OPTIMUM = {"alpha12": 90.0, "alpha23": 90.0}
"""The kinematic optimum the hybrid-analysis paper reports; the default fixed values."""
OBJECTIVE_KEYS: tuple[str, ...] = ("gci", "reach", "arc_length")
"""Indices a weight may name: f = Σ w·index (mean-type terms and the design's arcs)."""


class Cone(Section):
    """The task: a cone of tool directions at the remote centre. ``half_angle_deg`` 30 is
    the 60° vertex-angle cone of the surgeon's tool motions (the dexterous workspace of
    the Lum et al. papers); ``axis_angle_deg`` is the angle between joint axis 1 and the
    cone's axis (90: the base axis perpendicular to the cone's axis, the placement that
    puts the isotropy optimum at (90°, 90°); docs/sphere.md)."""

    half_angle_deg: float = Field(
        30.0,
        gt=0,
        le=90,
        description="Half-angle β (deg) of the cone of tool directions (30: the 60° cone).",
    )
    axis_angle_deg: float = Field(
        90.0,
        ge=0,
        le=180,
        description="Angle γ (deg) between joint axis 1 and the cone's axis.",
    )


class Index(Section):
    """How the mean of 1/k over the cone is estimated: ``n_samples`` directions uniform
    on the cone's spherical cap (common to the whole swarm), ``chunk`` of them in flight,
    the sampler and its replicates (docs/indices.md)."""

    n_samples: int = Field(
        4096,
        ge=2,
        le=100_000_000,
        description="Directions per design, uniform on the cone's cap (shared by the swarm).",
    )
    chunk: int = Field(4096, ge=1, le=1_000_000, description="Directions in flight at a time.")
    sampler: Literal["uniform", "halton", "rqmc"] = Field(
        "rqmc",
        description="How the samples are drawn: `uniform` (i.i.d.), `halton` (one randomly shifted "
        "Halton set) or `rqmc` (R independently shifted Halton sets; standard errors "
        "from the replicates' spread).",
    )
    replicates: int | None = Field(
        None,
        ge=1,
        le=1024,
        description="R, the independent randomisations of the sampler: at least 2 with `rqmc` (16 "
        "unless given), 1 with `halton`; `uniform` accepts R ≥ 2 (i.i.d. groups).",
    )

    _replicates = field_validator("replicates")(check_replicates)


class Constraints(Section):
    """g ≤ 0 constraints. ``reach_min``: the Monte-Carlo share of the task cone reached
    (≥); ``reach_all_deg``: every direction within this angle of the cone's axis must be
    reachable, checked exactly (a direction at angle φ from axis 1 is reachable iff
    |α12 − α23| ≤ φ ≤ min(α12 + α23, 360° − α12 − α23)): the hybrid paper's "reach the
    whole abdomen" restriction in our reading (docs/sphere.md)."""

    reach_min: float | None = Field(
        None,
        gt=0,
        le=1,
        description="The Monte-Carlo share of the task cone reached must be at least this (null: "
        "none).",
    )
    reach_all_deg: float | None = Field(
        None,
        gt=0,
        lt=90,
        description="Every direction within this angle (deg) of the cone's axis must be reachable, "
        "checked exactly (null: none).",
    )


class SphereSettings(StudySettings):
    """A 2-DOF spherical RCM mechanism, scored by the isotropy of its Jacobian over a
    cone of tool directions."""

    name: Literal["sphere_rcm"] = Field(
        "sphere_rcm",
        description="`sphere_rcm`: the 2-DOF spherical RCM mechanism.",
    )
    variables: dict[str, tuple[float, float]] = Field(
        {"alpha12": (30.0, 150.0), "alpha23": (30.0, 150.0)},
        description="Link angles and their box {name: [lo, hi]} (deg, in (0, 180)): alpha12, "
        "alpha23.",
    )
    fixed: dict[str, float] = Field(
        {},
        description="Link angles (deg) that are not varied (default: 90, the kinematic optimum).",
    )
    cone: Cone = Field(
        Cone(),
        description="The task: a cone of tool directions at the remote centre.",
    )
    index: Index = Field(Index(), description="How the mean of 1/k over the cone is estimated.")
    objective: dict[str, float] = Field(
        {"gci": -1.0},
        description="{index: weight} of f = Σ w·index over `gci`, `reach`, `arc_length`.",
    )
    constraints: Constraints = Field(Constraints(), description="Constraints g ≤ 0 on the reach.")

    @field_validator("variables")
    @classmethod
    def _angles(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for k, (lo, hi) in v.items():
            if k not in DESIGN_KEYS:
                raise ValueError(f"{k}: unknown design variable; allowed {list(DESIGN_KEYS)}")
            lo_hi(k, (lo, hi))
            if not (0 < lo and hi < 180):
                raise ValueError(f"{k}: a link angle must lie strictly between 0 and 180 "
                                 f"degrees (0 and 180 fold the link onto its axis), got "
                                 f"[{lo:g}, {hi:g}]")  # fmt: skip
        return v

    @field_validator("fixed")
    @classmethod
    def _fixed(cls, v: dict[str, float]) -> dict[str, float]:
        for k, x in v.items():
            if k not in DESIGN_KEYS:
                raise ValueError(f"{k}: unknown link angle; allowed {list(DESIGN_KEYS)}")
            if not 0 < x < 180:
                raise ValueError(f"{k}: a link angle must lie strictly between 0 and 180 "
                                 f"degrees, got {x:g}")  # fmt: skip
        return v

    @field_validator("objective")
    @classmethod
    def _weights(cls, v: dict[str, float]) -> dict[str, float]:
        for k in v:
            if k not in OBJECTIVE_KEYS:
                raise ValueError(f"{k}: unknown index; weights may name {list(OBJECTIVE_KEYS)}")
        if not any(w != 0 for w in v.values()):
            raise ValueError(f"give at least one non-zero weight for {list(OBJECTIVE_KEYS)}")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> SphereSettings:
        both = sorted(set(self.variables) & set(self.fixed))
        if both:
            raise ValueError(f"fixed.{both[0]}: is a design variable too (variables: "
                             f"{list(self.variables)}); a link angle is either variable or "
                             "fixed")  # fmt: skip
        ext = self.constraints.reach_all_deg
        g = self.cone.axis_angle_deg
        if ext is not None and not ext < min(g, 180.0 - g):
            raise ValueError(
                f"constraints.reach_all_deg: a cone of {ext:g}° about an axis {g:g}° from "
                f"joint axis 1 contains that axis (or its opposite), which only α12 = α23 "
                f"(or α12 + α23 = 180°) reaches; give less than {min(g, 180.0 - g):g}°"
            )
        return self

    def design(self) -> dict[str, float]:
        """The link angles that are not varied: ``fixed``, else the kinematic optimum."""
        return {k: float(self.fixed.get(k, KINEMATIC_OPTIMUM[k])) for k in DESIGN_KEYS}

    def weights(self) -> dict[str, float]:
        """The objective's weights, every key of OBJECTIVE_KEYS (0 where not given)."""
        return {k: float(self.objective.get(k, 0.0)) for k in OBJECTIVE_KEYS}


INDEX_UNITS = {"f": "-", "gci": "-", "reach": "-", "gci_reached": "-", "arc_length": "rad"}
"""Units of every index (figures label their axes with them)."""


def units(s: SphereSettings) -> dict[str, str]:
    """Link angles in degrees; the indices dimensionless but the arcs (rad)."""
    return dict.fromkeys(s.variables, "deg") | INDEX_UNITS
