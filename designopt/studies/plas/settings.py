"""The ``study:`` section of a ``plas`` config (seed 004; docs/plas.md lists every key).

Lengths in mm, angles in degrees. The joint ranges are the master's workspace over which
the mismatch is averaged; the mapping of eq. (27)-(29) puts master and slave at the same
configuration, so the ranges must lie within the slave's joint limits.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from designopt.studies.base import Section, StudySettings, check_replicates, lo_hi

MASTER_KEYS: tuple[str, ...] = ("a2p", "a3p", "d6")
"""Mirrors ``mechanism.MASTER_KEYS`` (kept import-light): a2', a3' (offset between the
master's joints 3 and 4; 0 on the built master), d6."""
BUILT = {"a2p": 138.0, "a3p": 0.0, "d6": 60.0}
JOINTS = ("theta2", "theta3", "theta4")


class JointBox(Section):
    """(lo, hi) in degrees for θ2, θ3, θ4."""

    theta2: tuple[float, float] = Field(description="[lo, hi] of θ2 (deg).")
    theta3: tuple[float, float] = Field(description="[lo, hi] of θ3 (deg).")
    theta4: tuple[float, float] = Field(description="[lo, hi] of θ4 (deg).")

    @field_validator("theta2", "theta3", "theta4")
    @classmethod
    def _lo_hi(cls, v: tuple[float, float], info) -> tuple[float, float]:
        return lo_hi(info.field_name, v)

    def rows(self) -> list[tuple[float, float]]:
        return [getattr(self, j) for j in JOINTS]


class Slave(Section):
    """The slave lengths the mapping uses (seed 004 §3.4), mm."""

    a2: float = Field(50.0, description="The slave's length a2 (mm, > 0).")
    a3: float = Field(15.0, description="The slave's length a3 (mm, ≥ 0).")
    d5: float = Field(30.0, description="The slave's length d5 (mm, > 0).")

    @field_validator("a2", "a3", "d5")
    @classmethod
    def _positive(cls, v: float, info) -> float:
        if info.field_name == "a3" and v < 0 or info.field_name != "a3" and v <= 0:
            raise ValueError(
                f"{info.field_name}: a length must be {'≥' if info.field_name == 'a3' else '>'} 0 mm, got {v}"
            )
        return v


class Mismatch(Section):
    """How the workspace mismatch is estimated."""

    n_samples: int = Field(
        4096,
        gt=1,
        description="Samples of the master's workspace per design (shared by the swarm).",
    )
    chunk: int = Field(4096, gt=0, description="Samples per step of the memory-bounded scan.")
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
    n_path: int = Field(
        8,
        ge=1,
        le=64,
        description="Points of the midpoint rule along the straight joint path from home to θ (the "
        "position mismatch).",
    )
    joint_rate_deg_s: float = Field(
        30.0,
        gt=0,
        description="Norm (deg/s) of the master's joint-rate vector behind the velocity mismatch.",
    )

    _replicates = field_validator("replicates")(check_replicates)

    def plan(self):
        """The sample layout (``designopt.numerics.montecarlo.Plan``; one stream unless rqmc or
        replicates are asked for)."""
        from designopt.numerics import montecarlo as mc

        if self.sampler != "rqmc" and self.replicates in (None, 1):
            c = min(self.chunk, self.n_samples)
            return mc.Plan(self.sampler, 1, -(-self.n_samples // c), c)
        return mc.plan(self.n_samples, self.chunk, self.sampler, self.replicates)

    def n_used(self) -> int:
        return self.plan().n_used


class Constraints(Section):
    """Reach within ±tolerance of the built master; mapping factors within the range the
    slave motors can follow (our default, docs/plas.md)."""

    reach_tolerance: float = Field(
        0.2,
        gt=0,
        lt=1,
        description="The reach a2' + a3' + d6 must lie within ± this share of the built master's.",
    )
    factor_range: tuple[float, float] = Field(
        (0.5, 3.0),
        description="[lo, hi], 0 < lo < hi: the range the mapping factors must stay in (what the "
        "slave motors can follow).",
    )
    n_grid: int = Field(
        9,
        ge=2,
        le=41,
        description="Grid points per joint on which the factor range is checked.",
    )

    @field_validator("factor_range")
    @classmethod
    def _fr(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 0 < v[0] < v[1]:
            raise ValueError(f"needs 0 < lo < hi, got {list(v)}")
        return v


class Objective(Section):
    """Weights of f = Σ w · index / (index of the built master)."""

    velocity: float = Field(
        1.0,
        ge=0,
        description="Weight of the velocity mismatch (relative to the built master's).",
    )
    position: float = Field(
        0.0,
        ge=0,
        description="Weight of the position mismatch (relative to the built master's).",
    )
    inertia: float = Field(
        0.0,
        ge=0,
        description="Weight of the inertia (relative to the built master's).",
    )

    @model_validator(mode="after")
    def _some(self) -> Objective:
        if self.velocity + self.position + self.inertia <= 0:
            raise ValueError("give at least one positive weight (velocity, position, inertia)")
        return self


class Counterbalance(Section):
    """§2.1.2: M, L (links beyond joint 4 and their lever), r, l, tilt θ. ``L_per_d6``:
    how much L grows per mm of d6 beyond the built 60 mm (our model, docs/plas.md)."""

    M_g: float = Field(
        240.5,
        gt=0,
        description="M (g): the mass of the links beyond joint 4 (§2.1.2; 240.5 g).",
    )
    L_mm: float = Field(188.0, gt=0, description="L (mm): their lever arm at the built d6.")
    r_mm: float = Field(
        90.0, ge=0, description="r (mm) in m(θ) = M(L·cosθ − r·sinθ) / (r·sinθ + l·cosθ) (§2.1.2)."
    )
    l_mm: float = Field(
        34.0,
        gt=0,
        description="l (mm): the counterweight's lever in m(θ) and I = M·L² + m·l² (§2.1.2).",
    )
    theta_deg: float = Field(
        25.0,
        gt=-90,
        lt=90,
        description="The tilt θ (deg) of §2.1.2, in (−90, 90).",
    )
    L_per_d6: float = Field(
        1.0,
        ge=0,
        description="How much L grows per mm of d6 beyond the built 60 mm (our model, "
        "docs/plas.md).",
    )


class PlasSettings(StudySettings):
    """Study D: the PLAS all-joints master of seed 004."""

    name: Literal["plas"] = Field("plas", description="`plas`: the PLAS all-joints master.")
    variables: dict[str, tuple[float, float]] = Field(
        {"a2p": (80.0, 240.0), "d6": (30.0, 120.0)},
        description="Optimised master lengths and their box {name: [lo, hi]} (mm): any of a2p, "
        "a3p, d6.",
    )
    fixed: dict[str, float] = Field(
        {},
        description="The other master lengths (mm; default: the built master's, a2p 138, a3p 0, d6 "
        "60).",
    )
    slave: Slave = Field(Slave(), description="The slave lengths of the mapping.")
    slave_limits_deg: JointBox = Field(
        JointBox(theta2=(-90, 90), theta3=(-90, 90), theta4=(-90, 90)),
        description="The slave's joint limits (deg; assumed ±90).",
    )
    joint_ranges_deg: JointBox = Field(
        JointBox(theta2=(-30, 30), theta3=(-60, 60), theta4=(-30, 30)),
        description="The master workspace the mismatch is averaged over (deg; within the slave's "
        "limits).",
    )
    mismatch: Mismatch = Field(Mismatch(), description="How the workspace mismatch is estimated.")
    constraints: Constraints = Field(
        Constraints(),
        description="Feasibility: the reach and the mapping factors' range.",
    )
    objective: Objective = Field(
        Objective(),
        description="Weights of f = Σ w · index / (the built master's index).",
    )
    counterbalance: Counterbalance = Field(
        Counterbalance(),
        description="The counterbalance model of §2.1.2 (the inertia index).",
    )

    @field_validator("variables")
    @classmethod
    def _lengths(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for k, (lo, _hi) in v.items():
            if k not in MASTER_KEYS:
                raise ValueError(f"unknown design variable '{k}'; allowed {list(MASTER_KEYS)}")
            if lo < 0 or (k != "a3p" and lo <= 0):
                raise ValueError(
                    f"{k}: a length must be {'≥' if k == 'a3p' else '>'} 0 mm, got lower bound {lo}"
                )
        return v

    @field_validator("fixed")
    @classmethod
    def _fixed(cls, v: dict[str, float]) -> dict[str, float]:
        for k, x in v.items():
            if k not in MASTER_KEYS:
                raise ValueError(f"unknown master length '{k}'; allowed {list(MASTER_KEYS)}")
            if x < 0 or (k != "a3p" and x <= 0):
                raise ValueError(
                    f"{k}: a length must be {'≥' if k == 'a3p' else '>'} 0 mm, got {x}"
                )
        return v

    @model_validator(mode="after")
    def _consistent(self) -> PlasSettings:
        both = sorted(set(self.fixed) & set(self.variables))
        if both:
            raise ValueError(
                f"fixed: {both} are design variables; a length is either variable or fixed"
            )
        for j, (lo, hi), (slo, shi) in zip(JOINTS, self.joint_ranges_deg.rows(),
                                           self.slave_limits_deg.rows(), strict=True):  # fmt: skip
            if lo < slo or hi > shi:
                raise ValueError(
                    f"joint_ranges_deg.{j}: [{lo:g}, {hi:g}] exceeds the slave's limits "
                    f"[{slo:g}, {shi:g}] (slave_limits_deg.{j}); the mapping puts the slave "
                    "at the master's configuration"
                )
        t2 = self.joint_ranges_deg.theta2
        t3 = self.joint_ranges_deg.theta3
        if max(abs(t2[0]), abs(t2[1])) >= 90 or max(abs(t2[0] + t3[0]), abs(t2[1] + t3[1])) > 90:
            raise ValueError(
                "joint_ranges_deg: needs |θ2| < 90° and |θ2 + θ3| ≤ 90° (beyond, the slave's "
                "joint-2 term of v_y in eq. (27) vanishes and the factor k2 is undefined)"
            )
        return self

    def design(self) -> dict[str, float]:
        """The master lengths that are not varied (built values unless ``fixed``)."""
        return {k: float(self.fixed.get(k, BUILT[k])) for k in MASTER_KEYS}


INDEX_UNITS = {"f": "-", "vel_rel": "-", "vel_reduction": "-", "vel_abs": "mm/s",
               "vel_max": "mm/s", "pos_mean": "mm", "pos_max": "mm", "k2_min": "-", "k2_max": "-",
               "k3_min": "-", "k3_max": "-", "k4": "-", "reach": "mm", "counterweight": "g",
               "inertia": "g·cm²"}  # fmt: skip
"""Units of every index (figures label their axes with them)."""
