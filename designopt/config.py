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


class Refine(_Strict):
    """Optional gradient polish after PSO (optax), projected onto the design box."""

    method: Literal["adam", "sgd"] = "adam"
    steps: int = Field(100, ge=1)
    learning_rate: float = Field(0.01, gt=0)  # step size in units of the box width
    n_best: int = Field(1, ge=1)  # polish the best design of the n_best best runs


class Sweep(_Strict):
    """Variations of numeric keys: ``grid`` (Cartesian product) or ``list`` (zipped)."""

    mode: Literal["grid", "list"] = "grid"
    vary: dict[str, list[float]]

    @field_validator("vary")
    @classmethod
    def _nonempty(cls, v: dict[str, list[float]]) -> dict[str, list[float]]:
        if not v:
            raise ValueError("needs at least one key to vary")
        for k, vals in v.items():
            if not vals:
                raise ValueError(f"{k}: needs at least one value")
        return v


class RunConfig(_Strict):
    study: Study = Study()
    optimizer: Optimizer = Optimizer()
    refine: Refine | None = None
    sweep: Sweep | None = None
    precision: Literal["float32", "float64"] = "float64"
    seed: int = 0
    output: str = "results/master9/master9.h5"


BENCH_FUNCTIONS = ("griewank", "rastrigin", "ackley", "sphere", "rosenbrock", "schwefel226")
# "acceptable" final values for the success rate (our choice, D = 30 scale)
DEFAULT_SUCCESS = {"griewank": 0.1, "rastrigin": 100.0, "ackley": 0.1, "sphere": 0.01,
                   "rosenbrock": 100.0, "schwefel226": 3000.0}  # fmt: skip


class Bench(_Strict):
    functions: list[Literal[BENCH_FUNCTIONS]] = ["griewank", "rastrigin", "ackley", "sphere"]  # type: ignore[valid-type]
    dim: int = Field(30, ge=1)
    shifted: bool = True  # also run every function with a seeded shift of its optimum
    shift_seed: int = 1
    variants: list[str] = ["p1", "p2", "p3", "p4", "p5", "p6", "p7"]
    reference: str = "p3"  # Mann-Whitney of every other variant against this one
    n_particles: int = Field(50, ge=2)
    n_iters: int = Field(1000, ge=1)
    n_runs: int = Field(100, ge=2)
    bounds: Literal["clip", "reflect", "reinit"] = "clip"
    draws: Literal["uniform", "splitmix"] = "uniform"
    success: dict[str, float] = {}
    settings: dict[str, dict[str, float]] = {}  # per-variant overrides


class BenchConfig(_Strict):
    bench: Bench = Bench()
    precision: Literal["float32", "float64"] = "float32"
    seed: int = 0
    output: str = "results/bench/pso_benchmark.h5"


def load(path: str | Path, model: type[BaseModel] = RunConfig) -> tuple[Any, str]:
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
        cfg = model.model_validate(raw)
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
