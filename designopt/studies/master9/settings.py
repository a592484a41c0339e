"""The ``study:`` section of a master9 config (docs/configs.md), validated by pydantic."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from designopt.studies.base import StudySettings, check_replicates

DESIGN_KEYS: tuple[str, ...] = ("a1", "a3", "d3", "a4", "a5", "d2", "d5", "d6")
"""The master's lengths (mm); mirrors ``mechanism.DESIGN_KEYS`` (kept import-light)."""


class Indices(BaseModel):
    """How the indices of seed 000 eq. (35)-(43) are estimated."""

    model_config = ConfigDict(extra="forbid")

    n_samples: int = Field(20_000, gt=1)
    chunk: int = Field(8_192, gt=0)  # (50, 8192) arrays stay in cache: 1.3-1.6× faster than 32768
    measure: Literal["cartesian", "joint"] = "cartesian"
    # rqmc in configs/master9.yaml; uniform here keeps tiny runs (short replicates) bitwise
    # equal under particle sharding (docs/indices.md)
    sampler: Literal["uniform", "halton", "rqmc"] = "uniform"
    replicates: int | None = Field(None, ge=1, le=1024)  # rqmc: 16 by default (docs/indices.md)
    backlash_deg: float | list[float] = 0.1
    norm: Literal["fro", "2"] = "fro"
    normalized: bool = False
    weights: list[float] = [4.0, 2.0, 1.0]

    _replicates = field_validator("replicates")(check_replicates)

    @field_validator("backlash_deg", "weights")
    @classmethod
    def _three(cls, v: float | list[float]) -> float | list[float]:
        if isinstance(v, list) and len(v) != 3:
            raise ValueError(f"needs one number or a list of 3, got {len(v)} values")
        return v


class Master9Settings(StudySettings):
    """Study A: the 9-DOF haptic master of seed 000."""

    name: Literal["master9"] = "master9"
    variables: dict[str, tuple[float, float]] = {
        "a1": (250, 350),
        "a3": (250, 350),
        "d3": (50, 150),
    }
    fixed: dict[str, float] = {}
    indices: Indices = Indices()
    n_norm: int = Field(64, gt=1)

    @field_validator("variables")
    @classmethod
    def _names(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for k in v:
            if k not in DESIGN_KEYS:
                raise ValueError(f"unknown design variable '{k}'; allowed {list(DESIGN_KEYS)}")
        return v

    @model_validator(mode="after")
    def _fixed_known(self) -> Master9Settings:
        bad = [k for k in self.fixed if k not in DESIGN_KEYS]
        if bad:
            raise ValueError(f"fixed: unknown length(s) {bad}; allowed {list(DESIGN_KEYS)}")
        both = sorted(set(self.fixed) & set(self.variables))
        if both:
            raise ValueError(
                f"fixed: {both} are design variables; a length is either variable or fixed"
            )
        return self
