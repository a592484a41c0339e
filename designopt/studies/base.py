"""The Study protocol: what a study folder declares so that config, pipeline and CLI can
run it without knowing it (docs/architecture.md).

A study is one folder ``designopt/studies/<name>/`` (``mechanism``, ``objective``,
``figures``, optionally ``paper``) whose ``__init__`` builds one :class:`Study` and the
registry (``designopt.studies``) lists it. Everything the generic layers need goes through
these fields; the typed settings model flows down unchanged.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import numpy as np
from pydantic import Field, field_validator, model_validator

from designopt.core.keys import STREAMS, archived_keys, key_data, streams  # noqa: F401 (re-exported)
from designopt.core.settings import Section  # noqa: F401 (re-exported: studies' settings use it)
from designopt.kinematics.ikjob import IKHook
from designopt.problems.base import Problem


class StudySettings(Section):
    """Base of every study's settings model: unknown keys are errors.

    A subclass declares ``name: Literal["<study>"]`` (the config's discriminator),
    ``variables`` {name: (lo, hi)} and whatever else the study needs.
    """

    name: str = Field(
        description="The study (`designopt studies` lists them): picks the settings model of this "
        "section.",
    )
    variables: dict[str, tuple[float, float]] = Field(
        description="The design variables and their box {name: [lo, hi]}, lo < hi.",
    )
    pareto: dict[str, Any] | None = Field(
        None,
        description="Given as `objective: {pareto: {index: min | max, ...}}`: optimise the Pareto "
        "front of two or more indices instead of the weighted f (needs a "
        "multi-objective optimizer, nsga2); `name: {min: {variable: weight}}` is a "
        "linear objective of the variables.",
        json_schema_extra={"config_key": "objective.pareto"},  # its spelling in a config
    )

    @model_validator(mode="before")
    @classmethod
    def _front(cls, data: Any) -> Any:
        """Lift ``objective.pareto`` out of the study's own objective section: at least
        two indices, each ``min`` or ``max``, and no weights beside them."""
        if not isinstance(data, dict) or not isinstance(data.get("objective"), dict):
            return data
        obj = dict(data["objective"])
        if "pareto" not in obj:
            return data
        front = obj.pop("pareto")
        if obj:
            raise ValueError(f"objective: give weights or pareto, not both (also {sorted(obj)})")
        if not isinstance(front, dict) or len(front) < 2:
            n = len(front) if isinstance(front, dict) else 0
            raise ValueError(f"objective.pareto: a front needs at least 2 indices, got {n}")
        for k, sense in front.items():
            if isinstance(sense, dict):  # a linear objective {min | max: {variable: weight}}
                if len(sense) != 1 or next(iter(sense)) not in ("min", "max"):
                    raise ValueError(f"objective.pareto.{k}: a linear objective is "
                                     "{min: {variable: weight, ...}} or {max: {...}}")  # fmt: skip
                w = next(iter(sense.values()))
                if (
                    not isinstance(w, dict)
                    or not w
                    or not all(
                        isinstance(x, int | float) and not isinstance(x, bool) for x in w.values()
                    )
                ):
                    raise ValueError(f"objective.pareto.{k}: weights {{variable: number, ...}}")
            elif sense not in ("min", "max"):
                raise ValueError(
                    f"objective.pareto.{k}: sense must be 'min' or 'max', got {sense!r}"
                )
        out = {k: v for k, v in data.items() if k != "objective"}
        return out | {"pareto": dict(front)}

    @field_validator("variables")
    @classmethod
    def _box(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        """Every study's design box: at least one variable, each with lo < hi."""
        if not v:
            raise ValueError("needs at least one design variable")
        for k, (lo, hi) in v.items():
            if not lo < hi:
                raise ValueError(f"{k}: lower bound {lo} is not below upper bound {hi}")
        return v

    def needs_float64(self) -> str | None:
        """Why these settings cannot run in float32 (checked with ``precision`` when the
        config is validated, so a dry run refuses it too), or None."""
        return None

    def box(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """The design box: (names, lower (D,), upper (D,)) in the order of ``variables``."""
        names = tuple(self.variables)
        lo = np.array([self.variables[n][0] for n in names], np.float64)
        hi = np.array([self.variables[n][1] for n in names], np.float64)
        return names, lo, hi


@dataclass(frozen=True)
class Cost:
    """What a study's settings cost per design evaluation, for the pre-flight estimate
    (``Study.cost``): Monte-Carlo ``samples`` per design, ``chunk`` of them in flight at
    once, ``n_norm`` designs scored once at set-up; the ``*_key`` fields name the config
    keys a user lowers (printed in the estimate's messages). The memory a design costs:
    ``bytes_per_sample`` per design and sample in flight (float64's; a float32 job counts
    half), ``per_design`` beside them, and ``program``, the resident size of the study's
    own large compiled program, when it has one (docs/faults.md, "pre-flight"); ``designs``
    caps the designs in flight for a study that scores them in blocks (the task's IK:
    ``serial.blocks.DESIGNS``), 0 when every design of a call is in flight."""

    samples: int = 1
    chunk: int = 1
    n_norm: int = 1
    samples_key: str = "study.n_samples"
    chunk_key: str = "study.n_samples"
    norm_key: str | None = None
    bytes_per_sample: int = 128  # app.preflight.BYTES_PER_DESIGN_SAMPLE
    per_design: int = 0
    program: int = 0
    designs: int = 0  # designs in flight at most (a study scoring in blocks); 0: all


@dataclass(frozen=True)
class Command:
    """An extra subcommand a study declares (``Study.commands``): the CLI builds its
    subparser from the registry. ``arguments(parser)`` adds the arguments, ``run(args,
    ctx)`` returns the exit status; ``ctx.load(args)`` loads ``args.config`` as every
    command does (seed, devices, precision, compilation cache), ``ctx.progress(quiet)``
    gives the progress bar, ``ctx.design(items)`` reads ``--design NAME=VALUE`` items and
    ``ctx.load_record(path)`` reads an archive bound to its config. ``writes``: it writes files, so it runs under the output
    session with signal handling like ``run``."""

    name: str
    help: str
    arguments: Callable[[Any], None]
    run: Callable[[Any, Any], int]
    description: str = ""
    writes: bool = False


def lo_hi(name: str, v: tuple[float, float]) -> tuple[float, float]:
    """A (lo, hi) range with lo < hi; ValueError naming ``name`` otherwise."""
    if not v[0] < v[1]:
        raise ValueError(f"{name}: lower limit {v[0]} is not below upper limit {v[1]}")
    return v


def known_lengths(v: Mapping[str, Any], known: tuple[str, ...], lengths: tuple[str, ...],
                  what: str = "design variable") -> Mapping[str, Any]:  # fmt: skip
    """Every key of ``v`` is in ``known`` and the ``lengths`` among them are > 0 (for a
    range (lo, hi), its lo); ValueError naming the key otherwise."""
    for k, x in v.items():
        if k not in known:
            raise ValueError(f"unknown {what} '{k}'; allowed {list(known)}")
        lo = x[0] if isinstance(x, tuple | list) else x
        if k in lengths and not lo > 0:
            raise ValueError(
                f"{k}: lengths must be > 0, got {'lower bound ' if lo is not x else ''}{lo}"
            )
    return v


def check_replicates(v: int | None, info: Any) -> int | None:
    """The shared validator of a sampling section's ``replicates`` (its ``sampler`` and
    ``n_samples`` fields come first): ``rqmc`` needs at least 2, ``halton`` takes only 1,
    and every replicate at least 2 samples (docs/indices.md)."""
    sampler, n = info.data.get("sampler", "uniform"), info.data.get("n_samples")
    if v is None:
        return None
    if sampler == "rqmc" and v < 2:
        raise ValueError(f"must be at least 2 for sampler 'rqmc', got {v}")
    if sampler == "halton" and v != 1:
        raise ValueError("replicated Halton points are sampler 'rqmc'; 'halton' takes 1")
    if n is not None and v > 1 and n < 2 * v:
        raise ValueError(f"{v} replicates need n_samples ≥ {2 * v}, got {n}")
    return v


@dataclass(frozen=True)
class Study:
    """What a study declares.

    - ``settings``: its pydantic settings model (``name`` is the discriminator).
    - ``problem(settings, keys, dtype) -> Problem``: the swarm objective; ``keys`` holds the
      named streams (``samples``, ``normalisation``). ``Problem.fn`` returns
      (f, aux) with every index of ``indices`` and its ``*_se`` in aux.
    - ``summary``: the sub-objectives ``run``/``show`` print with ± SE.
    - ``figures(record, folder) -> [paths]``: the figures of a run (a ``RunRecord``; a
      replay study gets its ``ReplayRecord``).
    - ``sweep_aliases(settings) -> {short path: full path}``: sweep short forms.
    - ``indices(settings) -> names``: what ``eval``/``scan`` report (f included).
    - ``units(settings) -> {name: unit}``: every design variable and index (``"-"``:
      dimensionless); printed with designs and used for every figure axis
      (docs/figures.md).
    - ``tiny``: the ``study:`` section of a config that runs in seconds (contract tests).
    - ``replay(settings, keys, dtype, where) -> (groups, lines)``: for a study whose
      ``run`` is not a design optimisation (e.g. replaying a teleoperation trajectory);
      its ``problem`` is None; the pipeline archives the groups as a ``ReplayRecord``
      (kind "run") and prints ``lines``. None: optimise.
    - ``cost(settings) -> Cost``: the pre-flight estimate's inputs.
    - ``commands``: the study's own subcommands (``Command``), added by the CLI.
    - ``check``, ``warnings``: checks of the settings beyond their models, and the
      final design's warnings (below).
    - ``ik``: its inverse kinematics for ``designopt ik`` (``designopt.kinematics.ikjob.IKHook``).
    """

    name: str
    title: str
    settings: type[StudySettings]
    problem: Callable[[Any, Mapping[str, jax.Array], Any], Problem] | None
    summary: Callable[[Any], tuple[str, ...]]
    indices: Callable[[Any], tuple[str, ...]]
    figures: Callable[[Any, Path], list[Path]]  # (RunRecord or ReplayRecord, folder)
    sweep_aliases: Callable[[Any], dict[str, str]] = lambda s: {}
    units: Callable[[Any], dict[str, str]] = lambda s: {}
    extra_lines: Callable[[Any, Mapping[str, Any]], list[str]] = lambda s, fin: []
    example_config: str = ""
    tiny: dict[str, Any] = field(default_factory=dict)
    """A small ``study:`` section (seconds to run), used by the contract tests."""
    meta: dict[str, Any] = field(default_factory=dict)
    cost: Callable[[Any], Cost] = lambda s: Cost()
    """``cost(settings)``: Monte-Carlo samples, chunk and normalisation probes per design,
    for the pre-flight memory and time estimate (``designopt.app.preflight``)."""
    commands: tuple[Command, ...] = ()
    """Extra subcommands of this study (e.g. the serial ``chain``, ``export`` and ``view``)."""
    ik: IKHook | None = None
    """``designopt ik CONFIG --poses FILE``: the study's inverse kinematics (an
    ``designopt.kinematics.ikjob.IKHook``: the design solved for with ``--design`` overrides, the
    solver, its target modes and the study's own flags). None: the command refuses the
    study in one line."""
    cloud: Callable[[Any], dict[str, Any] | None] | None = None
    """``cloud(record)``: the workspace of a run's final design as a point cloud for the
    interactive report, {"xyz": (n, 3), "value": (n,), "label", "unit"} (e.g. coloured
    by 1/k); None: the study has none."""
    robot: Callable[[Any], Mapping[str, Any] | None] | None = None
    """``robot(record)``: the robot in 3-D for the interactive report, {"view":
    ``designopt.figures.html.View``} for a run (the final design, a slider through
    representative poses) or {"front": ``designopt.figures.html.FrontView``} for a Pareto
    front (the robot of the design hovered or clicked), either with an optional "plan"
    ({"title", "png": PNG bytes, "rows": text lines}: a planning run's plan sheet, shown
    as a section of its own); None: the study draws none."""
    front_figures: Callable[[Any, Sequence[tuple[str, int]], Path], list[Path]] | None = None
    """``front_figures(front record, picks, folder)``: the study's drawings of a front's
    chosen designs (``picks``: [(name, design number)], the extremes and the knee,
    ``designopt.figures.front.extremes_and_knee``) beside the generic front figures;
    None: the generic ones only."""
    targets: Callable[[Any, Any, Mapping[str, jax.Array], Any], dict[str, Any] | None] | None = None
    """``targets(settings, x, keys, dtype)``: the final design ``x`` (D,) (variables in
    order) at every target of a task run, for the archive's ``targets`` group (per arm and
    target: the joints, reached, 1/k, clearance; docs/archive.md); None: no such group.
    Given designs ``x`` (P, D) (a front's), every array but ``target_p`` gains a leading
    design axis. A 2-D array ``arm_values`` (A, K) (one row per arm; (P, A, K) for P
    designs) with attr ``arm_columns`` (K column headings) is written on every row of the
    arm in ``designopt show --csv``."""
    placement: Callable[[Any, np.ndarray], dict[str, Any] | None] | None = None
    """``placement(settings, X)``: where designs ``X`` (n, D) (variables in order, config
    units) put the robot in the world, as {name: (n, ...) array} plus ``"attrs"`` (e.g. a
    ``"units"`` mapping and ``"columns"``); None: nothing to say for these settings. The
    pipeline archives each array beside the indices (``final/<name>`` without the design
    axis, ``front/<name>`` with it; their names in the group's attr ``placement``),
    ``eval --json`` returns them, and the study's ``extra_lines`` (given the final group,
    or one front design's values) prints them. The serial study: each arm's port on the
    body wall (``ports`` (A, 3)), how far the projection moved it (``port_shift`` (A,))
    and each arm's base (``bases`` (A, 6): x, y, z, roll, pitch, yaw in degrees)."""
    replay: (
        Callable[[Any, Mapping[str, jax.Array], Any, str], tuple[dict[str, Any], list[str]]] | None
    ) = None
    check: Callable[[Any], None] | None = None
    """``check(settings)``: what the settings models cannot see alone, checked when the
    config is validated (a dry run refuses it too), e.g. a task region that no design in
    the box can reach. Raises ``ValueError("<key under study>: <why>")``."""
    warnings: Callable[[Any, Mapping[str, Any]], list[str]] = lambda s, fin: []
    """``warnings(settings, final)``: where the final design's results are far from what
    was asked (a task region barely reached, an index constraint missed): printed with the
    summary, archived (``final`` attr ``warnings``), shown by ``designopt show`` and
    marked on the study's figures."""
