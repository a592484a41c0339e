"""YAML study configs (docs/configs.md): parsed, overridden by dotted keys
(:func:`set_key`) and validated once, by :func:`validate`, the one entry of every input
check: finite numbers, the pydantic models (each study validates its own section), the
optimizer's settings and a Pareto front's indices. The validated config then flows down
unchanged."""

from __future__ import annotations

import functools
import re
import types
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Union, get_args, get_origin

import yaml
from pydantic import (
    BaseModel,
    Field,
    Tag,
    ValidationError,
    create_model,
    field_validator,
    model_validator,
)

from designopt.core import validation
from designopt.core.devices import ParallelSettings
from designopt.core.errors import ConfigError  # noqa: E402  (re-exported)
from designopt.core.settings import Section


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


_Strict = Section  # unknown keys are errors


class Constraints(_Strict):
    """How optimizers treat a study's constraints g ≤ 0: Deb's feasibility rules
    (default; docs/optimizers.md) or a quadratic penalty f + weight·Σ max(g, 0)²."""

    method: Literal["deb", "penalty"] = Field(
        "deb",
        description="How every optimizer treats the study's constraints g ≤ 0: `deb` (Deb's "
        "feasibility rules: feasible beats infeasible, then the smaller total "
        "violation Σ max(g, 0)) or `penalty` (f + weight·Σ max(g, 0)²).",
    )
    weight: float = Field(
        1000.0,
        gt=0,
        allow_inf_nan=False,
        description="The penalty weight μ of `method: penalty` (an array parameter: changing it "
        "recompiles nothing).",
    )


class Optimizer(_Strict):
    name: str = Field(
        "ptpso",
        description="The optimizer: an entry of the optimizer registry (e.g. `ptpso`, `cmaes`, "
        "`nsga2` for a Pareto front; docs/optimizers.md lists them).",
    )
    n_particles: int = Field(
        50,
        ge=2,
        description="Swarm or population size: designs scored per iteration (samples are shared by "
        "the swarm).",
    )
    n_iters: int = Field(40, ge=1, description="Iterations (generations) of every run.")
    n_runs: int = Field(
        1,
        ge=1,
        description="Independent runs, vmapped together; with 2 or more, each run's best design is "
        "re-scored and the summary says whether the runs agree.",
    )
    bounds: Literal["clip", "reflect", "reinit"] = Field(
        "clip",
        description="What happens to a design that leaves the box: `clip` to the bound, `reflect` "
        "off it, or `reinit` (drawn again uniformly in the box).",
    )
    settings: dict[str, float | str] = Field(
        {},
        description="The optimizer's own settings {name: value} (docs/optimizers.md lists each "
        "optimizer's); an unknown setting is an error.",
    )
    constraints: Constraints = Field(
        Constraints(),
        description="How the study's constraints are handled (Deb's rules or a penalty).",
    )
    # the objective as a program of its own between ask and tell, or inside the runner's
    # scan; auto: app.optimise.separate_objective's rule (docs/configs.md)
    objective_program: Literal["auto", "separate", "fused"] = Field(
        "auto",
        description="`separate`: the objective is a program of its own between each iteration's "
        "ask and tell; `fused`: compiled inside the runner's chunked scan; `auto`: "
        "separate up to 5000 iterations, fused beyond. The same search either way, "
        "equal up to rounding.",
    )
    fidelity: dict[str, float | int | str | bool] = Field(
        {},
        description="Study settings the search scores with instead of the study's own, as `--set` "
        "keys under `study.` (or nested), e.g. `{study.task.ik.n_best: 2}` for a "
        "cheaper IK. Only the search uses them: every quoted score (final design, "
        "front, `eval`, `scan`) is the study's own.",
    )

    @field_validator("fidelity", mode="before")
    @classmethod
    def _flat(cls, v: Any) -> Any:
        """Nested mappings (``{study: {task: {ik: {n_best: 2}}}}``, or what ``--set
        optimizer.fidelity.study.task.ik.n_best=2`` makes) as dotted keys."""
        if not isinstance(v, Mapping):
            return v
        out: dict[str, Any] = {}

        def walk(prefix: str, node: Mapping) -> None:
            for k, x in node.items():
                path = f"{prefix}.{k}" if prefix else str(k)
                if isinstance(x, Mapping) and x:
                    walk(path, x)
                else:
                    out[path] = x

        walk("", v)
        return out

    @field_validator("fidelity")
    @classmethod
    def _study_keys(cls, v: dict[str, Any]) -> dict[str, Any]:
        for k in v:
            if not k.startswith("study.") or k in ("study.name", "study.") or ".." in k:
                raise ValueError(f"{k}: a fidelity setting is a key of the study (study.…; "
                                 "not its name), as --set takes it")  # fmt: skip
        return v


class Refine(_Strict):
    """Optional polish after the search, on the search's own samples: a gradient polish
    (optax ``adam`` or ``sgd``, projected onto the design box) or a derivative-free
    ``compass`` search (``designopt.optim.compass``; a front's runs: their recommended
    designs)."""

    method: Literal["adam", "sgd", "compass"] = Field(
        "adam",
        description="The polish after the search, on the search's own samples (no `refine` "
        "section: no polish): optax gradient descent `adam` or `sgd`, or `compass`, a "
        "derivative-free compass search (the only polish of a Pareto front).",
    )
    steps: int = Field(
        100,
        ge=1,
        description="Gradient polish steps (one scan, all polished designs vmapped); `compass`: at "
        "most this many iterations.",
    )
    learning_rate: float = Field(
        0.01,
        gt=0,
        description="Gradient step size in units of the box width (designs are mapped to [0, 1]^D "
        "and projected back after each step).",
    )
    n_best: int = Field(
        1,
        ge=1,
        description="Polish the best designs of the n_best best runs (a front: every run's "
        "recommended design).",
    )
    step: float = Field(
        0.08,
        gt=0,
        le=0.5,
        description="`compass`: the first polls' step along each variable, as a share of its box "
        "width.",
    )
    tol: float = Field(
        0.002,
        gt=0,
        le=0.5,
        description="`compass`: a design stops when its step falls below this share of the box "
        "width.",
    )


class Sweep(_Strict):
    """Variations of numeric keys: ``grid`` (Cartesian product) or ``list`` (zipped)."""

    mode: Literal["grid", "list"] = Field(
        "grid",
        description="`grid`: the Cartesian product of the values; `list`: equal-length lists "
        "zipped (`designopt sweep` only).",
    )
    vary: dict[str, list[float]] = Field(
        description="{dotted key: [values]}: the numeric keys each member changes, with short "
        "forms such as `optimizer.<setting>` and the study's own (docs/configs.md, "
        "Sweeps).",
    )

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

    start: float = Field(alias="from", description="The first value of the range (included).")
    stop: float = Field(alias="to", description="The last value of the range (included).")
    num: int = Field(
        ge=1,
        le=1_000_000,
        description="How many evenly spaced values, both ends included.",
    )

    def values(self) -> list[float]:
        import numpy as np

        return np.linspace(self.start, self.stop, self.num).tolist()


class Scan(_Strict):
    """Designs to score without optimising (``designopt scan``): a ``grid`` (Cartesian
    product) or ``list`` (zipped) over design variables; the other variables take
    ``design`` or, if absent there, the middle of their box."""

    mode: Literal["grid", "list"] = Field(
        "grid",
        description="`grid`: the Cartesian product of the varied values; `list`: equal-length "
        "lists zipped.",
    )
    vary: dict[str, list[float] | Range] = Field(
        description="`designopt scan`: {design variable: [values] or {from, to, num}}, the values "
        "each varied variable takes.",
    )
    design: dict[str, float] = Field(
        {},
        description="Values of the design variables the scan does not vary (default: the middle of "
        "their box).",
    )
    batch: int = Field(
        256,
        ge=1,
        description="Designs per vmapped call (the last batch is padded, so one program is "
        "compiled).",
    )

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


MIN_FINAL_SAMPLES = 30
"""The fewest samples per design a final re-scoring may take (``final.n_samples``)."""


class Front(_Strict):
    """How a Pareto front (``study.objective.pareto``) is finished and measured."""

    n_samples: int | None = Field(
        None,
        gt=1,
        description="Monte-Carlo samples per design when the final front is re-scored on a fresh "
        "stream (default: 4 × the study's own).",
    )
    reference: list[float] | None = Field(
        None,
        description="The hypervolume's reference point, one value per objective in the indices' "
        "own values (default: the nadir of the first generation).",
    )
    max_points: int = Field(
        200,
        ge=2,
        description="At most this many front designs are re-scored and archived (the most crowded "
        "are thinned first).",
    )


class Final(_Strict):
    """How a run's final design is quoted (docs/configs.md, "Scores you can quote"): every
    final design (a weighted or constrained run's, each sweep member's) and, with
    ``optimizer.n_runs`` ≥ 2, each run's best design are re-scored together on a fresh,
    independent sample stream (``final``, folded from the root key), never seen by the
    search. The keys ``seed`` to ``alpha`` set the race that decides between candidate
    layouts on a validation stream (designopt.numerics.racing: paired differences on
    common samples, Holm's correction, an equivalence margin per objective, Wilson
    intervals for share constraints)."""

    MARGIN: ClassVar[float] = 0.01
    """The default equivalence margin of an index with values in [0, 1] (gci-like)."""
    SHARE_MARGIN: ClassVar[float] = 0.02
    """The default equivalence margin of a share (a fraction of targets, e.g. arms_ok)."""

    n_samples: int | None = Field(
        None,
        ge=MIN_FINAL_SAMPLES,
        description="Monte-Carlo samples per design when the final design (and each run's best) is "
        "re-scored on a fresh stream the search never saw (default: 4 × the study's "
        "own, at least 30; fewer is refused).",
    )
    seed: int = Field(
        20260,
        ge=0,
        le=validation.SEED_MAX,
        description="Key of the validation stream on which candidate layouts are raced: fixed by "
        "the config and independent of `seed` and `--seed`, so runs at any seed judge their "
        "candidates on the same targets; its samples are disjoint from the search's.",
    )
    max_samples: int = Field(
        1024,
        ge=MIN_FINAL_SAMPLES,
        description="The race's cap: at most this many validation samples per candidate (at "
        "least 30; fewer is refused). A candidate clearly worse stops earlier.",
    )
    stage: int = Field(
        128,
        ge=MIN_FINAL_SAMPLES,
        description="Validation samples added per stage of the race, to every candidate still "
        "undecided (at least 30, at most `max_samples`); the race looks at the data after "
        "each stage.",
    )
    margin: (
        Annotated[float, Field(gt=0, allow_inf_nan=False)]
        | dict[str, Annotated[float, Field(gt=0, allow_inf_nan=False)]]
        | None
    ) = Field(
        None,
        description="Equivalence margin per objective, in the index's own units: two layouts "
        "whose difference is shown to be smaller are equal for a surgeon. One number for "
        "every objective, or a mapping index name → margin (indices not named keep the "
        "default). Default: 0.01 for an index with values in [0, 1] (e.g. gci), 0.02 for a "
        "share (e.g. arms_ok). Must be > 0.",
    )
    radius: float = Field(
        0.02,
        ge=0,
        allow_inf_nan=False,
        description="Clearing radius: candidate designs closer than this in the box-normalised "
        "design space ((x − lower)/(upper − lower), Euclidean) are one candidate, the better "
        "one standing for both (0: only identical designs merge).",
    )
    race: bool = Field(
        False,
        description="Run the final stage: the search's candidate layouts (non-dominated or best "
        "few of every run, the polished ones) raced on the validation stream (`final.seed`), "
        "stage by stage up to `final.max_samples`, giving a verdict table (best / equivalent "
        "/ worse) and one recommendation or a tied set; a weighted run's final design is the "
        "race's best, a front is formed from the race's survivors (docs/planning.md, \"The "
        "final stage\").",
    )
    alpha: float = Field(
        0.05,
        gt=0,
        lt=0.5,
        allow_inf_nan=False,
        description="Family-wise error of the race's decisions of each kind (a layout worse; "
        "two layouts equivalent or a trade-off), split over the race's looks and "
        "Holm-corrected within each; share constraints are read from Wilson intervals at "
        "the per-look level.",
    )

    @model_validator(mode="after")
    def _stage_within_cap(self) -> Final:
        if self.stage > self.max_samples:
            raise ValueError(f"stage: {self.stage} samples per stage exceed max_samples "
                             f"({self.max_samples}); give at most {self.max_samples}")  # fmt: skip
        return self

    def margin_of(self, index: str, share: bool = False) -> float:
        """The equivalence margin of objective ``index`` (``share``: the index is a share,
        whose default is :attr:`SHARE_MARGIN`)."""
        default = self.SHARE_MARGIN if share else self.MARGIN
        if isinstance(self.margin, dict):
            return float(self.margin.get(index, default))
        return default if self.margin is None else float(self.margin)


class RunConfigBase(_Strict):
    """Everything but the ``study`` section, whose model comes from the study registry."""

    optimizer: Optimizer = Field(
        Optimizer(),
        description="The search: which optimizer, how large, how long, and its settings.",
    )
    refine: Refine | None = Field(
        None,
        description="An optional polish of the best designs after the search (absent: none).",
    )
    sweep: Sweep | None = Field(
        None,
        description="Variations of numeric keys, one run per member (`designopt sweep`).",
    )
    scan: Scan | None = Field(
        None,
        description="Designs to score without optimising (`designopt scan`).",
    )
    front: Front = Field(
        Front(),
        description="How a Pareto front (`study.objective.pareto`) is re-scored and measured.",
    )
    final: Final = Field(
        Final(),
        description="How a run's final design is re-scored on fresh samples for the quoted values.",
    )
    precision: Literal["float32", "float64"] = Field(
        "float64",
        description="Floating-point precision of the computation: `float32` or `float64` (some "
        "studies, e.g. a task, need float64).",
    )
    seed: int = Field(
        0,
        ge=0,
        le=validation.SEED_MAX,
        description="Root PRNG seed, split once into the named streams (optimizer, samples, "
        "normalisation, figures); `--seed` overrides.",
    )
    output: str | None = Field(
        None,
        description="Archive path (default: results/<study>/<study>.h5); `--out` overrides; a "
        "missing folder is created.",
    )
    compile_cache: bool = Field(
        True,
        description="Keep compiled programs (and mesh grids, parsed URDFs, passed checks) in the "
        "cache folder between runs of the CLI; `--no-cache` overrides. Results are "
        "identical either way.",
    )
    overwrite: bool = Field(
        False,
        description="Replace an existing archive at the output (`--overwrite`); without it an "
        "existing archive is refused.",
    )
    max_minutes: float | None = Field(
        None,
        gt=0,
        allow_inf_nan=False,
        description="Stop cleanly after this many minutes with a resumable checkpoint, exit 143 "
        "(`--max-minutes`; default: no limit).",
    )
    checkpoint_every_s: float = Field(
        10.0,
        ge=0,
        allow_inf_nan=False,
        description="Seconds between checkpoints of a running optimisation (one is also written at "
        "every stop).",
    )
    parallel: ParallelSettings | None = Field(
        None,
        description="Devices and the axis to shard (`--devices`; docs/scaling.md); absent: every "
        "device JAX sees, axis auto.",
    )

    CONTROL_KEYS: ClassVar[tuple[str, ...]] = (
        "output",
        "compile_cache",
        "overwrite",
        "max_minutes",
        "checkpoint_every_s",
        "parallel",
    )
    """Keys that steer how a run is carried out, not what it computes: a resume may change them."""

    @model_validator(mode="after")
    def _precision(self) -> RunConfigBase:
        why = self.study.needs_float64()  # type: ignore[attr-defined]
        if self.precision != "float64" and why:
            raise ValueError(f"precision: {why}: set precision: float64")
        return self

    def output_path(self) -> str:
        name = self.study.name  # type: ignore[attr-defined]
        return self.output or f"results/{name}/{name}.h5"


@functools.cache
def _run_config(models: tuple[type[BaseModel], ...]) -> type[RunConfigBase]:
    union = models[0] if len(models) == 1 else Annotated[Union[models], Field(discriminator="name")]  # noqa: UP007
    study = Field(
        ...,
        description="The study and its settings: `study.name` picks the study (`designopt "
        "studies` lists them) and with it the keys this section takes.",
    )
    return create_model("RunConfig", __base__=RunConfigBase, study=(union, study))


def run_config_model() -> type[RunConfigBase]:
    """The run-config model: ``study`` is a union of every registered study's settings,
    discriminated by ``study.name``."""
    from designopt.studies import STUDIES

    return _run_config(tuple(s.settings for s in STUDIES.values()))


def set_key(raw: dict[str, Any], key: str, value: Any, where: str = "config") -> None:
    """Set the dotted ``key`` of a parsed config to ``value`` before validation, making the
    sections on its way: the one way a config is overridden (the API's ``overrides``, the
    command line's flags, each member of a sweep), so an override is checked exactly like
    the file's own keys. A ``None`` value unsets the key (its default applies)."""
    if not isinstance(key, str) or not key:
        raise ConfigError(f"{where}: override key {key!r}: give a dotted key, e.g. 'seed'")
    node: Any = raw
    *head, last = key.split(".")
    for i, part in enumerate(head):
        if isinstance(node, list):  # an entry of a list (``study.arms.1.port``)
            nxt = node[int(part)] if part.isdigit() and int(part) < len(node) else None
            if nxt is None:
                raise ConfigError(f"{where}: override '{key}': '{'.'.join(head[: i + 1])}': "
                                  f"{_entries(part, len(node))}")  # fmt: skip
        else:
            nxt = node.get(part)
            if nxt is None:
                nxt = node[part] = {}
        if not isinstance(nxt, dict | list):
            raise ConfigError(f"{where}: override '{key}': '{'.'.join(head[: i + 1])}' is not a "
                              "section")  # fmt: skip
        node = nxt
    if isinstance(node, list):
        if not (last.isdigit() and int(last) < len(node)):
            raise ConfigError(f"{where}: override '{key}': '{last}': "
                              f"{_entries(last, len(node))}")  # fmt: skip
        node[int(last)] = value
    elif value is None:  # null: the key unset, its default applies
        node.pop(last, None)
    else:
        node[last] = value


def _entries(part: str, n: int) -> str:
    """Why ``part`` names no entry of a list of ``n``."""
    if part.isdigit():
        return f"the list has {n} entries (from 0)"
    return f"not an entry number: this key is a list of {n} entries, numbered from 0"


def parse(path: str | Path) -> tuple[Any, str]:
    """Read and parse a config file's YAML (not validated): (raw, the file's text);
    ConfigError naming the file for a missing, unreadable or malformed one."""
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
    return raw, text


def load(path: str | Path, model: type[BaseModel] | None = None,
         overrides: Mapping[str, Any] | None = None) -> tuple[Any, str]:  # fmt: skip
    """Parse a config file, set ``overrides`` (dotted key → value, :func:`set_key`) and
    validate it (a run config unless ``model`` says otherwise); returns (config, the
    file's text)."""
    raw, text = parse(path)
    for k, v in (overrides or {}).items():
        set_key(raw, k, v, str(path))
    return validate(raw, str(path), model, folder=Path(path).parent), text


def validate(raw: Any, where: str, model: type[BaseModel] | None = None,
             folder: str | Path | None = None, checks: bool = True) -> Any:  # fmt: skip
    """Validate a parsed config (a dict); ConfigError naming ``where`` and the key.
    Relative paths inside the config (a URDF, a points file) are read from ``folder``:
    the config file's folder (default: ``where``'s folder when ``where`` is a file, else
    the working directory); validators get it as the context key ``config_dir``.
    ``checks=False`` skips the study's own checks (``Study.check``: they evaluate the
    chain, compile small programs, build distance grids): for a config an archive holds,
    which passed them when it ran (``show``, ``report``)."""
    if folder is None:
        folder = Path(where).parent if Path(where).is_file() else Path.cwd()
    model = run_config_model() if model is None else model
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: top level must be a mapping of keys")
    if model is not None and issubclass(model, RunConfigBase) and "study" not in raw:
        from designopt.studies import STUDIES

        raise ConfigError(f"{where}: key 'study': missing; name a study, one of "
                          f"{sorted(STUDIES)} (`designopt studies` lists them)")  # fmt: skip
    validation.check_tree(raw, where)  # NaN, inf and huge numbers first: validators assume finite
    try:
        cfg = model.model_validate(raw, context={"config_dir": str(folder)})
    except ValidationError as e:
        raise ConfigError(f"{where}: {error_text(e, raw, model)}") from None
    validation.check_tree(cfg, where)  # numbers pydantic parsed from text ("1e999", "nan")
    if isinstance(cfg, RunConfigBase):
        check_optimizer(cfg, where)
        check_front(cfg, where)
        if checks:
            check_study(cfg, where)
    return cfg


def check_study(cfg: Any, where: str) -> None:
    """The study's own checks beyond its settings model (``Study.check``): a
    ``ValueError("<key>: <why>")`` becomes "<where>: key 'study.<key>': <why>". A study
    settings that passed them once (the same settings, the same files they name, the same
    designopt and JAX) is not checked again: a marker in the cache folder says so
    (:func:`_checked_marker`; the checks evaluate the chain, compile small programs and
    sample self-collision pairs: seconds on every warm run)."""
    from designopt.studies import get

    check = get(cfg.study.name).check
    if check is None:
        return
    marker = _checked_marker(cfg)
    if marker is not None and marker.is_file():
        return
    try:
        check(cfg.study)
    except ValueError as e:
        key, sep, why = str(e).partition(": ")
        raise ConfigError(
            f"{where}: key 'study.{key}': {why}" if sep else f"{where}: {e}"
        ) from None
    if marker is not None:  # (a folder that cannot be written: checked again next time)
        from designopt.core import exported

        exported.write_cached(marker, cfg.study.name.encode())


def _checked_marker(cfg: Any) -> Path | None:
    """The cache folder's marker of a study settings that passed ``Study.check``
    (None without a cache folder): named by ``core.exported.fingerprint`` of the settings
    (their JSON, every file they name, designopt's source, JAX's version and precision)."""
    from designopt.core import exported

    folder = exported.folder()
    if folder is None:
        return None
    base = Path(getattr(cfg.study, "config_dir", None) or ".")
    h = exported.fingerprint(cfg.study.model_dump(mode="json"), base)
    return folder / f"designopt-checked-{h[:40]}"


def check_optimizer(cfg: Any, where: str) -> None:
    """The optimizer's name, settings and swarm size, checked by the optimizer registry."""
    from designopt import optim

    o = cfg.optimizer
    for key, args in (("optimizer.name", (o.name, {})),
                      ("optimizer.settings", (o.name, dict(o.settings))),
                      ("optimizer.n_particles", (o.name, dict(o.settings), o.n_particles))):  # fmt: skip
        try:
            optim.validate(*args)
        except ValueError as e:
            raise ConfigError(f"{where}: key '{key}': {e}") from None


def check_front(cfg: Any, where: str) -> None:
    """A front's config: known indices, a multi-objective optimizer, a reference point of
    the right length; a multi-objective optimizer without a front is refused too."""
    from designopt import optim
    from designopt.studies import get

    front = cfg.study.pareto
    name = cfg.optimizer.name
    if front is not None and get(cfg.study.name).replay is not None:
        raise ConfigError(f"{where}: key 'study.objective.pareto': study "
                          f"'{cfg.study.name}' replays a trajectory; it has no front")  # fmt: skip
    if front is None:
        if optim.is_multi_objective(name):
            raise ConfigError(f"{where}: key 'optimizer.name': '{name}' optimises a Pareto "
                              "front; name its indices in study.objective.pareto "
                              "(docs/pareto.md)")  # fmt: skip
        return
    known = get(cfg.study.name).indices(cfg.study)
    for k, w in linear(front).items():
        for v in w:
            if v not in cfg.study.variables:
                raise ConfigError(f"{where}: key 'study.objective.pareto.{k}.{senses(front)[k]}"
                                  f".{v}': not a design variable; variables: "
                                  f"{list(cfg.study.variables)}")  # fmt: skip
    for k in front:
        if k in linear(front):
            continue
        if k not in known:
            raise ConfigError(f"{where}: key 'study.objective.pareto.{k}': unknown index; "
                              f"this study's indices: {list(known)}")  # fmt: skip
    if not optim.is_multi_objective(name):
        raise ConfigError(f"{where}: key 'optimizer.name': '{name}' is single-objective; a "
                          "front (study.objective.pareto) needs a multi-objective "
                          "optimizer: nsga2")  # fmt: skip
    if cfg.refine is not None and cfg.refine.method != "compass":
        raise ConfigError(f"{where}: key 'refine.method': '{cfg.refine.method}' is a gradient "
                          "polish of one objective; a front (study.objective.pareto) is "
                          "polished by 'compass' (each run's recommended design)")  # fmt: skip
    ref = cfg.front.reference
    if ref is not None and len(ref) != len(front):
        raise ConfigError(f"{where}: key 'front.reference': {len(ref)} values for "
                          f"{len(front)} objectives ({', '.join(front)})")  # fmt: skip


def senses(front: Mapping[str, Any]) -> dict[str, str]:
    """Objective → ``min`` or ``max`` (an index's sense, or a linear objective's key)."""
    return {k: (next(iter(s)) if isinstance(s, dict) else s) for k, s in front.items()}


def linear(front: Mapping[str, Any]) -> dict[str, dict[str, float]]:
    """The linear objectives of the design variables: name → {variable: weight}."""
    return {k: dict(next(iter(s.values()))) for k, s in front.items() if isinstance(s, dict)}


_MESSAGES = {
    "greater_than_equal": "must be ≥ {ge}",
    "greater_than": "must be > {gt}",
    "less_than_equal": "must be ≤ {le}",
    "less_than": "must be < {lt}",
    "int_parsing": "must be an integer",
    "int_type": "must be an integer",
    "int_from_float": "must be a whole number",
    "float_parsing": "must be a number",
    "float_type": "must be a number",
    "finite_number": "must be a finite number",
    "bool_parsing": "must be true or false",
    "bool_type": "must be true or false",
    "string_type": "must be text",
    "list_type": "must be a list",
    "tuple_type": "must be a list",
    "dict_type": "must be a mapping of keys",
    "model_type": "must be a mapping of keys",
    "model_attributes_type": "must be a mapping of keys",
    "too_short": "needs at least {min_length} item(s), got {actual_length}",
    "too_long": "takes at most {max_length} item(s), got {actual_length}",
    "extra_forbidden": "unknown key",
    "missing": "missing",
    "literal_error": "must be one of {expected}",
    "string_pattern_mismatch": "must be one word without spaces or brackets",
    "string_too_short": "must not be empty",
    "string_too_long": "takes at most {max_length} characters",
    "enum": "must be one of {expected}",
}
"""Pydantic's messages in the words of a config file (no type internals)."""

_STRUCTURE = {"list_type", "tuple_type", "dict_type", "model_type", "model_attributes_type",
              "float_type", "float_parsing", "int_type", "int_parsing", "string_type"}  # fmt: skip
"""Error types that say "the input is not of this union member's shape"."""

_TAGS = ("union_tag_invalid", "union_tag_not_found")
_NO_VALUE = {"missing", "extra_forbidden", "too_short", "too_long", "string_too_short",
             "string_too_long"}  # fmt: skip
"""Messages that say all without the value given (it is absent, or its length is said)."""


def _given(v: Any) -> str:
    """ ", got <v>" for a one-word value (YAML's spelling of null and booleans), else ""."""
    if v is None or isinstance(v, bool):
        return f", got {yaml.safe_dump(v).split(chr(10))[0]}"
    if isinstance(v, int | float) or (isinstance(v, str) and len(v) <= 40 and "\n" not in v):
        return f", got {v!r}"
    return ""


def _input_path(err: dict, raw: Any) -> tuple[list[str], int, list[tuple[tuple, Any]]]:
    """The parts of a pydantic error's location that are keys of the input, how deep
    into the input they reach, and the other parts, the *labels* (union members and
    validator tags such as ``list[float]``, ``Range`` or ``function-after[...]``), each as
    (the location before it, the label)."""
    out, node, depth, labels = [], raw, 0, []
    loc = err["loc"]
    for n, x in enumerate(loc):
        nxt = loc[n + 1] if n + 1 < len(loc) else None
        if isinstance(node, dict) and x in node and not isinstance(node[x], dict | list) \
                and isinstance(nxt, str) and nxt in node:  # fmt: skip
            labels.append((tuple(loc[:n]), x))  # a union tag named like a key beside it
        elif isinstance(node, dict) and x in node:
            node, depth = node[x], depth + 1
            out.append(str(x))
        elif isinstance(node, list | tuple) and isinstance(x, int):
            node, depth = (node[x], depth + 1) if 0 <= x < len(node) else (None, depth)
            out.append(str(x))
        elif n == len(loc) - 1 and err["type"] == "missing":
            out.append(str(x))  # the key that is missing
        else:
            labels.append((tuple(loc[:n]), x))
    return out, depth, labels


def most_telling(errs: list[dict], raw: Any) -> dict:
    """The error to show of pydantic's ``errs`` on the input ``raw``, for every union
    alike. First each union decides which of its members the input was meant for: of
    the members that failed at one place (errors whose locations part at a label), the
    one whose best error is the least about shape ("not a list", "not a mapping") and
    then reaches deepest into the input; the other members' errors are dropped. Of the
    rest, the first in pydantic's order (the fields' order): an error that a field's
    validator raises because an earlier field failed (a name "not a design variable"
    after ``variables`` was refused) comes after its cause and is never shown in its
    place. A key missing beside an unknown key of the same section (a misspelt key) is
    shown as the unknown key, the one the user wrote."""
    if len(errs) < 2:
        return errs[0]
    info = [_input_path(e, raw) for e in errs]

    def rank(i: int) -> tuple[bool, int]:
        return errs[i]["type"] not in _STRUCTURE, info[i][1]

    sites: dict[tuple, dict[Any, list[int]]] = {}
    for i, (_, _, labels) in enumerate(info):
        for where, label in labels:
            sites.setdefault(where, {}).setdefault(label, []).append(i)
    lost: set[int] = set()
    for members in sites.values():
        if len(members) < 2:
            continue
        best = max(members.values(), key=lambda ids: max(rank(i) for i in ids))
        lost |= {i for ids in members.values() if ids is not best for i in ids}
    keep = [e for i, e in enumerate(errs) if i not in lost]
    first = keep[0]
    if first["type"] == "missing":  # a key misspelt is missing and unknown: name what was written
        typo = [e for e in keep if e["type"] == "extra_forbidden"
                and tuple(e["loc"][:-1]) == tuple(first["loc"][:-1])]  # fmt: skip
        first = typo[0] if typo else first
    return first


def _shapes(err: dict, errs: list[dict], raw: Any) -> str:
    """ "must be a number or text": the shape error ``err`` with those of the other
    members of its union at the same place of the input (a value no member takes)."""
    path = _input_path(err, raw)[0]
    out: list[str] = []
    for e in errs:
        if e["type"] in _STRUCTURE and _input_path(e, raw)[0] == path:
            m = _MESSAGES[e["type"]].removeprefix("must be ")
            out += [] if m in out else [m]
    return "must be " + " or ".join(out)


def _strip(tp: Any) -> Any:
    while get_origin(tp) is Annotated:
        tp = get_args(tp)[0]
    return tp


def _union(tp: Any) -> list[Any] | None:
    """The members of a union type (``None`` left out; Annotated kept), else None."""
    tp = _strip(tp)
    if get_origin(tp) not in (Union, types.UnionType):
        return None
    members = [a for a in get_args(tp) if a is not type(None)]
    inner = _union(members[0]) if len(members) == 1 else None  # (A | B) | None
    return members if inner is None else inner


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _names_member(member: Any, label: Any) -> bool:
    """Whether a union's location label names this member: its ``Tag``, its class name,
    or the value of a ``Literal`` field (``Field(discriminator="name")``)."""
    if get_origin(member) is Annotated and any(
            isinstance(m, Tag) and m.tag == label for m in get_args(member)[1:]):  # fmt: skip
        return True
    tp = _strip(member)
    if not _is_model(tp):
        return False
    return tp.__name__ == label or any(
        get_origin(_strip(f.annotation)) is Literal and label in get_args(_strip(f.annotation))
        for f in tp.model_fields.values()
    )


def _type_at(model: Any, loc: tuple) -> Any:
    """The type a pydantic location points at in ``model`` (None where it cannot tell)."""
    tp, i = model, 0
    while i < len(loc):
        x = loc[i]
        members = _union(tp)
        if members is not None:
            if len(members) == 1:  # X | None: no label in the location
                tp = members[0]
                continue
            pick = [m for m in members if _names_member(m, x)]
            if len(pick) != 1:
                return None
            tp, i = pick[0], i + 1
            continue
        tp = _strip(tp)
        origin, args = get_origin(tp), get_args(tp)
        if _is_model(tp):
            f = next((f for n, f in tp.model_fields.items() if x in (n, f.alias)), None)
            if f is None:
                return None
            tp = f.annotation
        elif origin in (list, tuple) and isinstance(x, int) and args:
            tp = args[0] if origin is list or args[-1] is Ellipsis else \
                args[x] if x < len(args) else None  # fmt: skip
        elif origin is dict and len(args) == 2:
            tp = args[1]
        else:
            return None
        i += 1
    return tp


def _tag_key(model: Any, loc: tuple) -> str | None:
    """The key that picks the member of the tagged union at ``loc`` (e.g. a body wall's
    ``shape``): the field every member declares as a ``Literal`` of its own; None when
    the union's members do not tell."""
    members = [_strip(m) for m in _union(_type_at(model, loc)) or []]
    if len(members) < 2 or not all(_is_model(m) for m in members):
        return None
    for name, f in members[0].model_fields.items():
        ann = [_strip(m.model_fields[name].annotation) if name in m.model_fields else None
               for m in members]  # fmt: skip
        if all(get_origin(a) is Literal for a in ann):
            return f.alias or name
    return None


def _tag_error(err: dict, loc: list[str], model: Any) -> tuple[list[str], str]:
    """The key and message of a tagged union's unknown or missing tag: the key that
    names the member (``study.task.body_wall.shape``), the tags it takes."""
    ctx = err.get("ctx", {})
    expected = ctx.get("expected_tags") or ctx.get("expected") or ""
    disc = str(ctx.get("discriminator", ""))
    key = disc.strip("'") if disc[:1] == "'" and disc[-1:] == "'" else None
    if key is None and model is not None:
        key = _tag_key(model, err["loc"])
    given = err.get("input")
    if not isinstance(given, dict):
        what = f"{key}: one of {expected}" if key else f"one of {expected}"
        return loc, f"must be a mapping of keys with {what}"
    if key is None:
        return loc, f"must name one of {expected}"
    if key not in given:
        return [*loc, key], f"missing; give one of {expected}"
    return [*loc, key], f"must be one of {expected}, got {given[key]!r}"


def error_text(e: ValidationError, raw: Any = None, model: Any = None) -> str:
    """ "key 'a.b.c': message" for the most telling error (:func:`most_telling`): the
    deepest key the input got wrong, study tags, union members and validator names
    dropped from the path; pydantic's wording rewritten. ``model``: the model validated
    (to name the key of a tagged union whose tag is unknown or missing)."""
    from designopt.studies import STUDIES

    errs = e.errors()
    err = most_telling(errs, raw) if raw is not None else errs[0]
    if raw is not None:
        loc, _, _ = _input_path(err, raw)
    else:
        loc = [str(x) for x in err["loc"]]
    if len(loc) > 1 and loc[0] == "study" and loc[1] in STUDIES:
        del loc[1]
    msg = err["msg"].removeprefix("Value error, ")
    if err["type"] == "missing" and raw is not None and err["loc"] and isinstance(
            err["loc"][-1], int) and loc and loc[-1] == str(err["loc"][-1]):  # fmt: skip
        n = err["loc"][-1]
        loc = loc[:-1]
        err = {**err, "type": "too_few", "msg": f"needs at least {n + 1} values"}
        msg = err["msg"]
    if err["type"] in _MESSAGES and err["type"] not in ("literal_error",):
        try:
            msg = _MESSAGES[err["type"]].format(**err.get("ctx", {}))
        except (KeyError, IndexError):
            pass
        if raw is not None and err["type"] in _STRUCTURE:  # a value no member of a union takes
            msg = _shapes(err, errs, raw)
        if err["type"] not in _NO_VALUE:
            msg += _given(err.get("input"))
    elif err["type"] == "literal_error":
        msg = (
            _MESSAGES["literal_error"].format(expected=err.get("ctx", {}).get("expected", msg))
            + f", got {err['input']!r}"
        )
    if err["type"] in _TAGS and tuple(err["loc"]) == ("study",):  # the study's own name
        name = err["input"].get("name") if isinstance(err["input"], dict) else None
        loc = ["study", "name"]
        msg = (f"unknown study {name!r}" if name is not None else "missing") + (
            f"; known: {sorted(STUDIES)} (`designopt studies` lists them)"
        )
    elif err["type"] in _TAGS:
        loc, msg = _tag_error(err, loc, model)
    elif err["type"] not in _MESSAGES and err["type"] != "value_error" and model is not None \
            and isinstance(err.get("input"), dict):  # fmt: skip
        key = _tag_key(model, err["loc"])  # a union's own error for its tag (custom words)
        if key is not None:
            given = err["input"]
            loc, msg = [*loc, key], (f"{msg}; got {given[key]!r}" if key in given
                                     else f"missing ({msg})")  # fmt: skip
    head, sep, rest = msg.partition(": ")
    if not loc and sep and head.isidentifier():  # a whole-config check names its key first
        loc, msg = [head], rest
    elif raw is not None and sep and _KEY.match(head) and err["type"] not in _TAGS:
        # a section's check that names a key inside it ("limits.j2: ..."): the deepest key
        # at fault is that key (the location ends at the section, or at its union tag)
        first = head.split(".")[0]
        for base in (loc, loc[:-1]):
            if isinstance(_node(raw, base), dict) and first in _node(raw, base):
                loc, msg = [*base, *head.split(".", 1)], rest
                break
    if err["type"] == "extra_forbidden" and len(loc) > 1 and loc[0] == "study" \
            and msg == _MESSAGES["extra_forbidden"]:  # fmt: skip
        msg += _known_here(tuple(err["loc"]), model)
    return f"key '{'.'.join(loc) or '(top level)'}': {msg}"


def _known_here(loc: tuple, model: Any) -> str:
    """"; known here: a, b, …" for an unknown key at the pydantic location ``loc``: the
    keys of the section it sits in (every member's, for a union of sections), or ""
    where the section cannot be told."""
    tp = _type_at(model, loc[:-1]) if model is not None else None
    members = _union(tp) or [tp]
    names: list[str] = []
    for m in members:
        m = _strip(m)
        if not _is_model(m):
            return ""
        for n, f in m.model_fields.items():
            if (f.alias or n) not in names:
                names.append(f.alias or n)
    return f"; known here: {', '.join(names)}" if names else ""


_KEY = re.compile(r"^[A-Za-z_][\w\-]*(\.[\w\-]+)*$")


def _node(raw: Any, path: list[str]) -> Any:
    """The part of the parsed config at ``path`` (None when it is not there)."""
    node = raw
    for x in path:
        if isinstance(node, dict) and x in node:
            node = node[x]
        elif isinstance(node, list | tuple) and x.isdigit() and int(x) < len(node):
            node = node[int(x)]
        else:
            return None
    return node


def resolved_yaml(cfg: Any) -> str:
    """A validated config as YAML (every default filled in: the archive's
    ``config_resolved_yaml``)."""
    return yaml.safe_dump(cfg.model_dump(mode="json", by_alias=True), sort_keys=False)
