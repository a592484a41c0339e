"""The ``study:`` section of an ``rcm`` config (the planar RCM mechanism paper, Sensors
2023; docs/rcm.md lists every key). Lengths in mm, angles in degrees."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from designopt.studies.base import Section, StudySettings, check_replicates, known_lengths, lo_hi

DESIGN_KEYS = ("a", "c")
"""What the design can vary; b only moves R and changes neither η nor reach (eq. 17-18)."""
WORKSPACES = ("box", "cone", "reach")
BUILT = {"a": 120.0, "b": 260.0, "c": 250.0}


class Joints(Section):
    """Joint ranges (Table 2): θ1 in degrees, d1 and d2 in mm."""

    theta1_deg: tuple[float, float] = Field((-38.0, 38.0), description="[lo, hi] of θ1 (deg).")
    d1: tuple[float, float] = Field(
        (22.0, 215.0),
        description="[lo, hi] of the prismatic joint d1 (mm).",
    )
    d2: tuple[float, float] = Field(
        (35.0, 200.0),
        description="[lo, hi] of the prismatic joint d2 (mm), above 0.",
    )

    @field_validator("theta1_deg", "d1", "d2")
    @classmethod
    def _range(cls, v: tuple[float, float], info) -> tuple[float, float]:
        return lo_hi(info.field_name, v)

    @field_validator("d2")
    @classmethod
    def _d2_positive(cls, v: tuple[float, float]) -> tuple[float, float]:
        if v[0] <= 0:
            raise ValueError(f"d2: the range must lie above 0 (the rod direction is undefined "
                             f"at d2 = 0), got {list(v)}")  # fmt: skip
        return v


class Cone(Section):
    """The task cone at R: full apex angle and insertion-depth range (seed 003 §2.4:
    60°, 50-200 mm). ``dim`` 2 is its section in the mechanism's plane (a sector), 3 the
    cone of the 3-DOF arm around the instrument's home direction, 1 its axis alone (depth
    uniform along the rod; the reading that reproduces the paper's Fig. 4a, docs/rcm.md)."""

    apex_deg: float = Field(
        60.0,
        gt=0,
        lt=180,
        description="The task cone's full apex angle (deg) at R.",
    )
    depth: tuple[float, float] = Field(
        (50.0, 200.0),
        description="[lo, hi]: the insertion depth (mm) beyond R, lo > 0.",
    )
    dim: Literal[1, 2, 3] = Field(
        2,
        description="2: the cone's section in the mechanism's plane (a sector); 3: the 3-DOF arm's "
        "cone; 1: its axis alone (depth uniform).",
    )

    @field_validator("depth")
    @classmethod
    def _depth(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo_hi("depth", v)
        if v[0] <= 0:
            raise ValueError(f"depth: must be > 0 (the tip beyond R), got {list(v)}")
        return v


class Eta(Section):
    """The global conditioning index η = mean of 1/k over a workspace (eq. 12).

    ``workspace``: ``box`` (the joint box), ``cone`` (the task cone, sampled uniformly in
    Cartesian space and mapped by IK) or ``reach`` (the part of the cone the joint box
    reaches). ``measure``: ``cartesian`` (uniform in the tip's space) or ``joint``
    (uniform in (d1, d2)); the other is the change of variables by |det J|.
    """

    workspace: Literal["box", "cone", "reach"] = Field(
        "cone",
        description="Where η is averaged: `box` (the joint box), `cone` (the task cone, mapped by "
        "IK) or `reach` (the part of the cone the joint box reaches).",
    )
    measure: Literal["cartesian", "joint"] = Field(
        "cartesian",
        description="`cartesian` (uniform in the tip's space) or `joint` (uniform in (d1, d2)).",
    )
    n_samples: int = Field(65_536, ge=2, description="Samples per design.")
    sampler: Literal["uniform", "halton", "rqmc"] = Field(
        "uniform",
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
    """Design constraints g ≤ 0: eq. (19) a ≥ sin(apex/2)·(c − depth_min), and the joint
    box reaching at least ``reach_min`` of the task cone's samples."""

    eq19: bool = Field(True, description="Impose eq. (19), a ≥ sin(apex/2)·(c − depth_min).")
    reach_min: float | None = Field(
        0.99,
        gt=0,
        le=1,
        description="The joint box must reach at least this share of the task cone's samples "
        "(null: no reach constraint).",
    )


class RcmSettings(StudySettings):
    """The planar RCM mechanism: design variables among (a, c); the rest fixed."""

    name: Literal["rcm"] = Field(
        "rcm",
        description="`rcm`: the planar RCM mechanism (Sensors 2023).",
    )
    variables: dict[str, tuple[float, float]] = Field(
        {"a": (60.0, 200.0), "c": (200.0, 400.0)},
        description="Design variables and their box {name: [lo, hi]} (mm): a and/or c.",
    )
    fixed: dict[str, float] = Field(
        {},
        description="Lengths (mm) of a, b, c that are not varied (default: the built design, Table "
        "1).",
    )
    joints: Joints = Field(Joints(), description="Joint ranges (Table 2).")
    cone: Cone = Field(Cone(), description="The task cone at R.")
    eta: Eta = Field(Eta(), description="How the global conditioning index η is estimated.")
    constraints: Constraints = Field(Constraints(), description="Design constraints g ≤ 0.")

    @field_validator("variables")
    @classmethod
    def _known(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        """(b only moves R and changes neither η nor reach, so it is no variable.)"""
        return known_lengths(v, DESIGN_KEYS, DESIGN_KEYS)

    @field_validator("fixed")
    @classmethod
    def _fixed(cls, v: dict[str, float]) -> dict[str, float]:
        return known_lengths(v, tuple(BUILT), tuple(BUILT), "fixed length")

    @model_validator(mode="after")
    def _consistent(self) -> RcmSettings:
        both = sorted(set(self.variables) & set(self.fixed))
        if both:
            raise ValueError(
                f"fixed: {both} are design variables; a name is either variable or fixed"
            )
        return self

    def design(self) -> dict[str, float]:
        """Fixed values: ``fixed`` over the built design (Table 1)."""
        return BUILT | self.fixed


class Arm(Section):
    """The 3-DOF arm's lengths, mm: a, b, c (Table 1) and L, the height of R above the
    base frame (Table 3; not printed in the paper, 0 puts R at the origin)."""

    a: float = Field(120.0, gt=0, description="Length a (mm, Table 1).")
    b: float = Field(260.0, gt=0, description="Length b (mm, Table 1).")
    c: float = Field(250.0, gt=0, description="Length c (mm, Table 1).")
    L: float = Field(
        0.0,
        description="Height L (mm) of R above the base frame (0 puts R at the origin).",
    )


class TeleopSettings(StudySettings):
    """A master trajectory replayed through the incremental mapping (eq. 33; docs/rcm.md).

    ``trajectory``: a CSV ``t,x,y,z,clutch`` (s, mm, 0/1), relative paths from the
    config's folder. ``scale``: s for an s:1 master-to-slave ratio. ``master_to_slave_deg``:
    fixed-axis angles (x, y, z) of the rotation R_SG⁻¹·R_MG. ``q0``: the slave's start
    (θ1 in degrees, d1, d2 in mm). ``delay_ms``: the servo delay (the paper measured
    60-80 ms).
    """

    name: Literal["rcm_teleop"] = Field(
        "rcm_teleop",
        description="`rcm_teleop`: a master trajectory replayed through the incremental mapping.",
    )
    variables: dict[str, tuple[float, float]] = Field(
        {},
        description="Must be empty: a replay has no design variables (give lengths under `arm`).",
    )
    arm: Arm = Field(Arm(), description="The 3-DOF arm's lengths.")
    joints: Joints = Field(Joints(), description="Joint ranges (Table 2).")
    trajectory: str = Field(
        description="The master trajectory: a CSV `t,x,y,z,clutch` (s, mm, 0/1), read from the "
        "config file's folder when relative.",
    )
    scale: float = Field(
        2.0,
        gt=0,
        allow_inf_nan=False,
        description="s of an s:1 master-to-slave motion ratio.",
    )
    master_to_slave_deg: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0),
        description="Fixed-axis angles (x, y, z; deg) of the rotation from the master's frame to "
        "the slave's.",
    )
    q0: tuple[float, float, float] = Field(
        (0.0, 120.0, 130.0),
        description="The slave's start: θ1 (deg), d1, d2 (mm), within the joint ranges.",
    )
    delay_ms: float = Field(
        70.0,
        ge=0,
        le=10_000,
        description="The servo delay (ms; the paper measured 60-80 ms).",
    )

    @field_validator("variables")
    @classmethod
    def _box(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        if v:
            raise ValueError("a replay has no design variables; give the lengths under 'arm'")
        return v

    @model_validator(mode="after")
    def _start(self) -> TeleopSettings:
        j = self.joints
        for name, x, (lo, hi) in zip(("theta1", "d1", "d2"), self.q0,
                                     (j.theta1_deg, j.d1, j.d2), strict=True):  # fmt: skip
            if not lo <= x <= hi:
                raise ValueError(f"q0: {name} = {x} lies outside its range [{lo}, {hi}]")
        return self


INDEX_UNITS = {"f": "-", "eta": "-", "eta_box": "-", "eta_cone": "-", "eta_reach": "-",
               "reach": "-", "eq19_margin": "mm"}  # fmt: skip
"""Units of every index (figures label their axes with them; reach is a fraction)."""


def units(s: RcmSettings | TeleopSettings) -> dict[str, str]:
    """Every design variable's unit (mm) and every index's."""
    return dict.fromkeys(s.variables, "mm") | INDEX_UNITS
