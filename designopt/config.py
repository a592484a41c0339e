"""YAML study configs, validated on load with pydantic (docs/configs.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator


class ConfigError(Exception):
    """A user mistake in a config: the message names the file and the key."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Indices(_Strict):
    n_samples: int = Field(20_000, gt=1)
    chunk: int = Field(32_768, gt=0)
    measure: Literal["cartesian", "joint"] = "cartesian"
    sampler: Literal["uniform", "halton"] = "uniform"
    backlash_deg: float | list[float] = 0.1
    norm: Literal["fro", "2"] = "fro"
    normalized: bool = False
    weights: list[float] = [4.0, 2.0, 1.0]


class Study(_Strict):
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
    def _bounds(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for k, (lo, hi) in v.items():
            if not lo < hi:
                raise ValueError(f"variables.{k}: lower bound {lo} is not below upper bound {hi}")
        return v


class Optimizer(_Strict):
    name: str = "ptpso"
    n_particles: int = Field(50, ge=2)
    n_iters: int = Field(40, ge=1)
    n_runs: int = Field(1, ge=1)
    bounds: Literal["clip", "reflect", "reinit"] = "clip"
    settings: dict[str, float] = {}


class RunConfig(_Strict):
    study: Study = Study()
    optimizer: Optimizer = Optimizer()
    precision: Literal["float32", "float64"] = "float64"
    seed: int = 0
    output: str = "results/master9/master9.h5"


def load(path: str | Path) -> tuple[RunConfig, str]:
    """Parse and validate a config file; returns (config, the file's text)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: config file not found")
    text = p.read_text()
    try:
        raw = yaml.safe_load(text) or {}
    except yaml.YAMLError as e:
        raise ConfigError(f"{p}: malformed YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(raw, dict):
        raise ConfigError(f"{p}: top level must be a mapping of keys")
    try:
        cfg = RunConfig.model_validate(raw)
    except ValidationError as e:
        err = e.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        raise ConfigError(f"{p}: key '{loc}': {err['msg']}") from None
    return cfg, text


def study_dict(cfg: RunConfig) -> dict[str, Any]:
    s = cfg.study
    ind = s.indices.model_dump()
    return {
        "variables": {k: list(v) for k, v in s.variables.items()},
        "fixed": s.fixed,
        "indices": ind,
        "n_norm": s.n_norm,
        "dtype": cfg.precision,
        "seed": cfg.seed,
    }
