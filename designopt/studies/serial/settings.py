"""The ``study:`` section of a ``serial`` config: any serial chain described in YAML
(docs/configs.md). Angles (DH α, θ and R-joint limits) are in degrees, lengths in the
user's unit; every DH entry is a number or the name of a design variable or fixed value.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from designopt.studies.base import Section, StudySettings

ROWS = ("vx", "vy", "vz", "wx", "wy", "wz")
INDEX_NAMES = ("gci", "gcsei", "manipulability", "volume")


class Joint(Section):
    """One DH row: joint type, the four DH entries (α, θ in degrees) and the joint limits
    (degrees for R joints, length units for P joints)."""

    type: Literal["R", "P"]
    a: float | str = 0.0
    alpha: float | str = 0.0
    d: float | str = 0.0
    theta: float | str = 0.0
    limits: tuple[float, float]

    @field_validator("limits")
    @classmethod
    def _lo_hi(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not v[0] < v[1]:
            raise ValueError(f"lower limit {v[0]} is not below upper limit {v[1]}")
        return v


class Chain(Section):
    convention: Literal["standard", "modified"] = "standard"
    joints: list[Joint] = Field(min_length=1, max_length=12)


class SerialIndices(Section):
    """Which Jacobian, which condition number, which measure, how many samples."""

    jacobian: list[Literal["vx", "vy", "vz", "wx", "wy", "wz"]] | Literal["position", "full"] = (
        "position"
    )
    norm: Literal["2", "fro"] = "2"
    normalized: bool = False  # fro only: report k_F/m (m = min(rows, joints)) so that k >= 1
    measure: Literal["joint", "cartesian"] = "joint"
    sampler: Literal["uniform", "halton"] = "uniform"
    n_samples: int = Field(20_000, gt=1)
    chunk: int = Field(16_384, gt=0)
    length_scale: float = Field(1.0, gt=0)  # multiplies the angular rows (full Jacobian)

    @field_validator("jacobian")
    @classmethod
    def _rows(cls, v: Any) -> Any:
        if isinstance(v, list):
            if not v:
                raise ValueError("needs at least one row")
            if len(set(v)) != len(v):
                raise ValueError(f"repeated rows in {v}")
        return v

    def rows(self) -> tuple[int, ...]:
        if self.jacobian == "position":
            return (0, 1, 2)
        if self.jacobian == "full":
            return tuple(range(6))
        return tuple(sorted(ROWS.index(r) for r in self.jacobian))


class LinearConstraint(Section):
    """A linear constraint on the design variables: Σ terms[name]·x[name] ≤ le (or ≥ ge),
    e.g. ``{terms: {l1: 1, l2: 1}, le: 1.2}`` bounds the total reach."""

    terms: dict[str, float] = Field(min_length=1)
    le: float | None = Field(None, allow_inf_nan=False)
    ge: float | None = Field(None, allow_inf_nan=False)

    @model_validator(mode="after")
    def _one_side(self) -> LinearConstraint:
        if (self.le is None) == (self.ge is None):
            raise ValueError("give exactly one of 'le' and 'ge'")
        return self


class SerialSettings(StudySettings):
    """A user's serial mechanism: chain, design variables, indices, objective."""

    name: Literal["serial"] = "serial"
    variables: dict[str, tuple[float, float]]
    fixed: dict[str, float] = {}
    chain: Chain
    indices: SerialIndices = SerialIndices()
    objective: dict[str, float | bool | int] = {"gci": -1.0}
    constraints: list[LinearConstraint] = []

    @field_validator("fixed")
    @classmethod
    def _fixed(cls, v: dict[str, float], info: ValidationInfo) -> dict[str, float]:
        both = sorted(set(v) & set(info.data.get("variables", {})))
        if both:
            raise ValueError(f"{both} are design variables; a name is either variable or fixed")
        return v

    @field_validator("chain")
    @classmethod
    def _names(cls, chain: Chain, info: ValidationInfo) -> Chain:
        known = set(info.data.get("variables", {})) | set(info.data.get("fixed", {}))
        kinds: dict[str, str] = {}
        for i, j in enumerate(chain.joints):
            for e in ("a", "alpha", "d", "theta"):
                v = getattr(j, e)
                if isinstance(v, str):
                    if v not in known:
                        raise ValueError(
                            f"joints.{i}.{e}: '{v}' is neither a design variable nor a fixed "
                            f"value (variables: {sorted(info.data.get('variables', {}))}, "
                            f"fixed: {sorted(info.data.get('fixed', {}))})"
                        )
                    kind = "angle" if e in ("alpha", "theta") else "length"
                    if kinds.setdefault(v, kind) != kind:
                        raise ValueError(
                            f"joints.{i}.{e}: '{v}' is used as an angle and as a length"
                        )
        unused = sorted(set(info.data.get("variables", {})) - set(kinds))
        if unused:
            raise ValueError(f"design variable(s) {unused} appear in no DH entry of the chain")
        return chain

    @model_validator(mode="after")
    def _consistent(self) -> SerialSettings:
        n = len(self.chain.joints)
        rows = self.indices.rows()
        ind = self.indices
        if ind.measure == "cartesian" and len(rows) != n:
            raise ValueError(
                f"indices.measure: 'cartesian' weights by |det J| and needs a square Jacobian; "
                f"indices.jacobian gives {len(rows)} rows for {n} joints"
            )
        if ind.normalized and ind.norm != "fro":
            raise ValueError("indices.normalized: applies to norm 'fro' only")
        obj = self.objective
        for k, v in obj.items():
            if k in ("normalize",):
                if not isinstance(v, bool):
                    raise ValueError("objective.normalize: must be true or false")
            elif k == "n_norm":
                if isinstance(v, bool) or not isinstance(v, int) or v < 2:
                    raise ValueError("objective.n_norm: must be a whole number ≥ 2")
            elif k not in INDEX_NAMES:
                raise ValueError(
                    f"objective.{k}: unknown index; weights may name {list(INDEX_NAMES)}"
                )
            elif isinstance(v, bool):
                raise ValueError(f"objective.{k}: a weight must be a number")
        if not any(k in INDEX_NAMES for k in obj):
            raise ValueError(f"objective: give at least one weight for {list(INDEX_NAMES)}")
        for i, c in enumerate(self.constraints):
            bad = sorted(set(c.terms) - set(self.variables))
            if bad:
                raise ValueError(
                    f"constraints.{i}.terms: {bad} are not design variables "
                    f"(variables: {sorted(self.variables)})"
                )
        if "volume" in obj and not self.has_volume():
            raise ValueError(
                "objective.volume: the workspace volume ∫ sqrt(det Jv Jvᵀ) dq needs a square "
                f"position Jacobian; indices.jacobian gives rows {[ROWS[r] for r in rows]} "
                f"for {n} joints"
            )
        return self

    def has_volume(self) -> bool:
        rows = self.indices.rows()
        return len(rows) == len(self.chain.joints) and all(r < 3 for r in rows)

    def index_names(self) -> tuple[str, ...]:
        return tuple(k for k in INDEX_NAMES if k != "volume" or self.has_volume())

    def weights(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.objective.items() if k in INDEX_NAMES}

    def angle_names(self) -> set[str]:
        return {
            getattr(j, e)
            for j in self.chain.joints
            for e in ("alpha", "theta")
            if isinstance(getattr(j, e), str)
        }
