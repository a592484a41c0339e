"""YAML study configs, validated on load with pydantic (docs/configs.md)."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Union

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model, field_validator

from designopt.errors import ConfigError  # noqa: E402  (re-exported)
from designopt.parallel import ParallelSettings


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key given twice in one mapping (PyYAML would keep
    the last one silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict[Any, int] = {}
        for k_node, _ in node.value:
            k = self.construct_object(k_node, deep=deep)
            line = k_node.start_mark.line + 1
            if isinstance(k, (str, int, float, bool)) and k in seen:
                raise ConfigError(f"key '{k}' is given twice (lines {seen[k]} and {line})")
            if isinstance(k, (str, int, float, bool)):
                seen[k] = line
        return super().construct_mapping(node, deep=deep)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Constraints(_Strict):
    """How optimizers treat a study's constraints g ≤ 0: Deb's feasibility rules
    (default; docs/optimizers.md) or a quadratic penalty f + weight·Σ max(g, 0)²."""

    method: Literal["deb", "penalty"] = "deb"
    weight: float = Field(1000.0, gt=0, allow_inf_nan=False)


class Optimizer(_Strict):
    name: str = "ptpso"
    n_particles: int = Field(50, ge=2)
    n_iters: int = Field(40, ge=1)
    n_runs: int = Field(1, ge=1)
    bounds: Literal["clip", "reflect", "reinit"] = "clip"
    settings: dict[str, float | str] = {}
    constraints: Constraints = Constraints()


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


class Range(_Strict):
    """An evenly spaced list of values: ``{from: a, to: b, num: n}`` (both ends included)."""

    start: float = Field(alias="from")
    stop: float = Field(alias="to")
    num: int = Field(ge=1, le=1_000_000)

    def values(self) -> list[float]:
        import numpy as np

        return np.linspace(self.start, self.stop, self.num).tolist()


class Scan(_Strict):
    """Designs to score without optimising (``designopt scan``): a ``grid`` (Cartesian
    product) or ``list`` (zipped) over design variables; the other variables take
    ``design`` or, if absent there, the middle of their box."""

    mode: Literal["grid", "list"] = "grid"
    vary: dict[str, list[float] | Range]
    design: dict[str, float] = {}
    batch: int = Field(256, ge=1)  # designs per vmapped call

    @field_validator("vary")
    @classmethod
    def _nonempty(cls, v: dict[str, list[float] | Range]) -> dict[str, list[float] | Range]:
        if not v:
            raise ValueError("needs at least one design variable to vary")
        for k, vals in v.items():
            if isinstance(vals, list) and not vals:
                raise ValueError(f"{k}: needs at least one value")
        return v

    def lists(self) -> dict[str, list[float]]:
        return {k: (v.values() if isinstance(v, Range) else list(v)) for k, v in self.vary.items()}


class RunConfigBase(_Strict):
    """Everything but the ``study`` section, whose model comes from the study registry."""

    optimizer: Optimizer = Optimizer()
    refine: Refine | None = None
    sweep: Sweep | None = None
    scan: Scan | None = None
    precision: Literal["float32", "float64"] = "float64"
    seed: int = 0
    output: str | None = None  # default results/<study>/<study>.h5
    compile_cache: bool = True  # keep compiled programs between runs (CLI; --no-cache)
    overwrite: bool = False  # replace an existing archive at the output (CLI; --overwrite)
    max_minutes: float | None = Field(
        None, gt=0, allow_inf_nan=False
    )  # stop cleanly (--max-minutes)
    checkpoint_every_s: float = Field(10.0, ge=0, allow_inf_nan=False)  # checkpoint cadence
    parallel: ParallelSettings | None = None  # devices and the axis to shard (--devices)

    CONTROL_KEYS: ClassVar[tuple[str, ...]] = (
        "output",
        "compile_cache",
        "overwrite",
        "max_minutes",
        "checkpoint_every_s",
        "parallel",
    )
    """Keys that steer how a run is carried out, not what it computes: a resume may change them."""

    def output_path(self) -> str:
        name = self.study.name  # type: ignore[attr-defined]
        return self.output or f"results/{name}/{name}.h5"


@functools.cache
def _run_config(models: tuple[type[BaseModel], ...]) -> type[RunConfigBase]:
    union = models[0] if len(models) == 1 else Annotated[Union[models], Field(discriminator="name")]  # noqa: UP007
    return create_model("RunConfig", __base__=RunConfigBase, study=(union, ...))


def run_config_model() -> type[RunConfigBase]:
    """The run-config model: ``study`` is a union of every registered study's settings,
    discriminated by ``study.name``."""
    from designopt.studies import STUDIES

    return _run_config(tuple(s.settings for s in STUDIES.values()))


def load(path: str | Path, model: type[BaseModel] | None = None) -> tuple[Any, str]:
    """Parse and validate a config file (a run config unless ``model`` says otherwise);
    returns (config, the file's text)."""
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{p}: is a folder, not a config file")
    if not p.is_file():
        raise ConfigError(f"{p}: config file not found")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError(
            f"{p}: not a UTF-8 text file (byte {e.start}); a config is YAML text"
        ) from None
    except OSError as e:
        raise ConfigError(f"{p}: cannot read ({e.strerror})") from None
    try:
        raw = yaml.load(text, Loader=_UniqueKeyLoader) or {}
    except ConfigError as e:
        raise ConfigError(f"{p}: {e}") from None
    except yaml.YAMLError as e:
        msg = " ".join(str(e).split()).replace('in "<unicode string>", ', "")
        raise ConfigError(f"{p}: malformed YAML: {msg}") from None
    return validate(raw, str(p), model), text


def validate(raw: Any, where: str, model: type[BaseModel] | None = None) -> Any:
    """Validate a parsed config (a dict); ConfigError naming ``where`` and the key."""
    model = run_config_model() if model is None else model
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: top level must be a mapping of keys")
    if model is not None and issubclass(model, RunConfigBase) and "study" not in raw:
        from designopt.studies import STUDIES

        raise ConfigError(f"{where}: key 'study': missing; name a study, one of "
                          f"{sorted(STUDIES)} (`designopt studies` lists them)")  # fmt: skip
    try:
        return model.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(f"{where}: {error_text(e)}") from None


def error_text(e: ValidationError) -> str:
    """ "key 'a.b.c': message" for the first error (study tags dropped from the path)."""
    from designopt.studies import STUDIES

    err = e.errors()[0]
    loc = [str(x) for x in err["loc"]]
    if len(loc) > 1 and loc[0] == "study" and loc[1] in STUDIES:
        del loc[1]
    msg = err["msg"].removeprefix("Value error, ")
    if err["type"] in ("union_tag_invalid", "union_tag_not_found") and loc == ["study"]:
        name = err["input"].get("name") if isinstance(err["input"], dict) else None
        loc = ["study", "name"]
        msg = (f"unknown study {name!r}" if name is not None else "missing") + (
            f"; known: {sorted(STUDIES)} (`designopt studies` lists them)"
        )
    return f"key '{'.'.join(loc) or '(top level)'}': {msg}"
