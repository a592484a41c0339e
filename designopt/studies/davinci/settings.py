"""The ``study:`` section of a ``davinci`` config (docs/davinci.md lists every key).

Angles in degrees, lengths in mm. Design variables are any of ``alpha_deg``,
``beta_deg``, ``l_QH``, ``l_IJ`` (the arm parameters of Table 1 of the da Vinci
patient-side arm IK paper, Applied Sciences 2019); the others keep Table 1's values
unless ``fixed`` overrides them.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from designopt.studies.base import Section, StudySettings, check_replicates, known_lengths, lo_hi

KEYS: tuple[str, ...] = ("alpha_deg", "beta_deg", "l_QH", "l_IJ")
TABLE1: dict[str, float] = {"alpha_deg": 20.0, "beta_deg": 30.45, "l_QH": 784.29, "l_IJ": 10.0}
UNITS: dict[str, str] = {"alpha_deg": "deg", "beta_deg": "deg", "l_QH": "mm", "l_IJ": "mm"}


class Workspace(Section):
    """The surgical workspace around the RCM point H.

    Shaft directions fill a cone of half-angle ``cone_deg`` about the axis the Table 1
    arm's shaft has at (q1, q2) = ``axis_q_deg`` (a fixed world direction, so the task
    does not move with the design); insertion depth ``depth_mm`` from H. Dexterity is
    averaged over joint samples whose shaft lies in the cone (q1, q2 from the direction,
    q3 the depth) with the wrist joints uniform over ``wrist_deg`` (q4, q5, q6). The IK
    task poses put the jaw point J at depth along a cone direction, the jaw's pointing
    direction within ``tool_cone_deg`` of it and the jaw axis at a uniform angle about it."""

    cone_deg: float = Field(
        30.0,
        gt=0,
        le=80,
        description="Half-angle (deg) of the cone the shaft directions fill.",
    )
    axis_q_deg: tuple[float, float] = Field(
        (0.0, -67.5),
        description="(q1, q2) in deg at which the Table 1 arm's shaft gives the cone's axis (a "
        "fixed world direction).",
    )
    depth_mm: tuple[float, float] = Field(
        (50.0, 250.0),
        description="[lo, hi]: the insertion depth (mm) from the RCM point H, within [0, 315].",
    )
    wrist_deg: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] = Field(
        ((-180.0, 180.0), (-80.0, 80.0), (-80.0, 80.0)),
        description="The ranges (deg) of the wrist joints q4, q5, q6 the samples are uniform over, "
        "within their joint ranges.",
    )
    tool_cone_deg: float = Field(
        45.0,
        ge=0,
        le=90,
        description="Half-angle (deg) within which the IK task poses' jaw direction lies about the "
        "shaft direction.",
    )

    @field_validator("depth_mm")
    @classmethod
    def _depth(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo_hi("depth_mm", v)
        if v[0] < 0 or v[1] > 315:
            raise ValueError(f"must lie within the insertion range [0, 315] mm, got {list(v)}")
        return v

    @field_validator("wrist_deg")
    @classmethod
    def _wrist(cls, v):
        lim = ((-180, 180), (-90, 90), (-90, 90))
        for j, ((lo, hi), (llo, lhi)) in enumerate(zip(v, lim, strict=True)):
            lo_hi(f"wrist_deg.q{j + 4}", (lo, hi))
            if lo < llo or hi > lhi:
                raise ValueError(
                    f"q{j + 4}: [{lo:g}, {hi:g}] exceeds the joint range [{llo}, {lhi}] deg"
                )
        return v


class Indices(Section):
    """How dexterity and the IK success rate are estimated."""

    n_samples: int = Field(
        4096,
        gt=1,
        description="Joint samples per design for the GCI (shared by the swarm).",
    )
    n_ik: int = Field(512, gt=1, description="Task poses per design for the IK success rate.")
    length_mm: float = Field(
        100.0,
        gt=0,
        description="Characteristic length (mm) of the 6×6 Jacobian: the angular rows are scaled "
        "by it.",
    )
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
    solver: Literal["lm", "closed_form"] = Field(
        "lm",
        description="Which IK the success rate measures: `lm` (the batched Levenberg-Marquardt "
        "solver) or `closed_form`.",
    )

    _replicates = field_validator("replicates")(check_replicates)


class Objective(Section):
    """f = −(w_gci · GCI + w_ik · IK success rate): minimised."""

    gci: float = Field(
        1.0,
        ge=0,
        description="Weight w_gci of the GCI in f = −(w_gci·GCI + w_ik·IK success rate).",
    )
    ik_success: float = Field(1.0, ge=0, description="Weight w_ik of the IK success rate in f.")

    @model_validator(mode="after")
    def _some(self) -> Objective:
        if self.gci + self.ik_success <= 0:
            raise ValueError("give at least one positive weight (gci, ik_success)")
        return self


class IKSettings(Section):
    """The production IK solver (``designopt ik``; docs/davinci.md)."""

    first_iter: int = Field(
        4,
        ge=1,
        le=100,
        description="LM iterations of the first pass over every pose (from its nearest "
        "database seed).",
    )
    continue_iter: int = Field(
        6,
        ge=1,
        le=200,
        description="LM iterations of the short pass that continues the poses not yet solved.",
    )
    max_iter: int = Field(
        60,
        ge=1,
        le=500,
        description="LM iterations of each later rescue pass (the failed poses only).",
    )
    warm_iter: int = Field(
        2,
        ge=1,
        le=100,
        description="Trajectory mode: LM iterations from the solution predicted from the "
        "previous poses.",
    )
    retries: int = Field(
        1,
        ge=0,
        le=4,
        description="Extra seeds (the next database entries) for poses that failed.",
    )
    success_pos_mm: float = Field(
        1e-9,
        gt=0,
        description="Position error (mm) below which a pose counts as solved.",
    )
    success_rot_rad: float = Field(
        1e-9,
        gt=0,
        description="Orientation error (rad) below which a pose counts as solved.",
    )
    grid_deg: float = Field(
        10.0,
        gt=0,
        le=45,
        description="Step (deg) of q1 and q2 in the FK seed database.",
    )
    grid_q3_mm: float = Field(
        15.0,
        gt=0,
        le=100,
        description="Step (mm) of the insertion q3 in the seed database.",
    )
    grid_wrist_deg: float = Field(
        15.0,
        gt=0,
        le=45,
        description="Step (deg) of q4 and q5 in the seed database.",
    )
    grid_q6_deg: float = Field(
        10.0,
        gt=0,
        le=45,
        description="Step (deg) of q6 in the seed database.",
    )
    q_prev: tuple[float, float, float, float, float, float] | None = Field(
        None,
        description="Previous configuration (deg; q3 in mm) for the branch choice of a cold solve.",
    )
    batch: int = Field(65536, ge=1, description="Poses per compiled call.")
    orthonormal_tol: float = Field(
        1e-6,
        gt=0,
        description="How far a target pose's rotation may be from orthonormal before the pose "
        "is refused.",
    )
    arm: dict[str, float] = Field(
        {},
        description="Arm parameters for `designopt ik` {alpha_deg, beta_deg, l_QH, l_IJ} (Table 1 "
        "unless given here or in `fixed`).",
    )

    @field_validator("arm")
    @classmethod
    def _arm(cls, v: dict[str, float]) -> dict[str, float]:
        return known_lengths(v, KEYS, ("l_QH", "l_IJ"), "arm parameter")


class DavinciSettings(StudySettings):
    """The da Vinci patient-side arm (Applied Sciences 2019): wrist design and IK settings."""

    name: Literal["davinci"] = Field(
        "davinci",
        description="`davinci`: the da Vinci patient-side arm (Applied Sciences 2019).",
    )
    variables: dict[str, tuple[float, float]] = Field(
        {"l_IJ": (2.0, 30.0), "beta_deg": (15.0, 45.0)},
        description="Design variables and their box {name: [lo, hi]}: any of alpha_deg, beta_deg "
        "(deg), l_QH, l_IJ (mm).",
    )
    fixed: dict[str, float] = Field(
        {},
        description="Arm parameters that are not varied (deg or mm; default: Table 1's values).",
    )
    workspace: Workspace = Field(
        Workspace(),
        description="The surgical workspace around the RCM point H.",
    )
    indices: Indices = Field(
        Indices(),
        description="How dexterity and the IK success rate are estimated.",
    )
    objective: Objective = Field(Objective(), description="Weights of the minimised f.")
    ik: IKSettings = Field(
        IKSettings(),
        description="The production IK solver (`designopt ik`; docs/davinci.md).",
    )

    @field_validator("variables")
    @classmethod
    def _vars(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        return known_lengths(v, KEYS, ("l_QH", "l_IJ"))

    @field_validator("fixed")
    @classmethod
    def _fixed(cls, v: dict[str, float]) -> dict[str, float]:
        return known_lengths(v, KEYS, ("l_QH", "l_IJ"), "arm parameter")

    @model_validator(mode="after")
    def _consistent(self) -> DavinciSettings:
        both = sorted(set(self.fixed) & set(self.variables))
        if both:
            raise ValueError(
                f"fixed: {both} are design variables; a parameter is either variable or fixed"
            )
        return self

    def ik_arm(self) -> dict[str, float]:
        """The arm ``designopt ik`` solves for: Table 1, then ``fixed``, then ``ik.arm``."""
        return {k: float(self.ik.arm.get(k, self.fixed.get(k, TABLE1[k]))) for k in KEYS}

    def design(self) -> dict[str, float]:
        """Arm parameters that are not varied (Table 1 unless ``fixed``), config units."""
        return {k: float(self.fixed.get(k, TABLE1[k])) for k in KEYS if k not in self.variables}
