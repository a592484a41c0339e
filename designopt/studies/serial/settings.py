"""The ``study:`` section of a ``serial`` config: any serial chain described in YAML
(docs/configs.md), as a DH table or as a robot's URDF (docs/urdf.md). Angles (DH α, θ,
origin roll/pitch/yaw and R-joint limits) are in degrees, lengths in the user's unit (a
URDF's own unit for a URDF chain); every DH entry or URDF ``set`` value is a number or the
name of a design variable or fixed value.
"""

from __future__ import annotations

import math
import re
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any, Literal, NamedTuple, Union

from pydantic import (
    Discriminator,
    Field,
    PrivateAttr,
    Tag,
    ValidationInfo,
    field_validator,
    model_validator,
)

from designopt.core import validation
from designopt.core.errors import ConfigError
from designopt.kinematics.collision import Collision
from designopt.kinematics.ik import NEIGHBOUR_GROUP
from designopt.kinematics.task import Points, Task
from designopt.kinematics.wall import BodyWall
from designopt.studies.base import Section, StudySettings, check_replicates

ROWS = ("vx", "vy", "vz", "wx", "wy", "wz")
INDEX_NAMES = ("gci", "gcsei", "manipulability", "volume")
TASK_INDEX_NAMES = ("reach", "gci", "gci_q05", "manipulability", "joint_margin")
"""The indices under ``measure: task`` (docs/task.md)."""


_NUMBER = re.compile(r"^\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\s*$")


def _number_or_name(v: Any) -> Any:
    """A number that YAML read as text (``1e3``, ``4e-1``: YAML 1.1 takes an exponent
    without a dot for a word) as the number; names and everything else as given."""
    if isinstance(v, str) and _NUMBER.match(v):
        return float(v)
    if isinstance(v, list | tuple):
        return type(v)(_number_or_name(x) for x in v)
    return v


class Joint(Section):
    """One DH row: joint type, the four DH entries (α, θ in degrees) and the joint limits
    (degrees for R joints, length units for P joints)."""

    type: Literal["R", "P"] = Field(
        description="`R` (revolute: the joint adds to θ) or `P` (prismatic: adds to d).",
    )
    a: float | str = Field(
        0.0,
        description="DH length a: a number (length unit) or the name of a variable or fixed value.",
    )
    alpha: float | str = Field(
        0.0,
        description="DH twist α (deg): a number or the name of a variable or fixed value.",
    )
    d: float | str = Field(
        0.0,
        description="DH offset d: a number (length unit) or the name of a variable or fixed value.",
    )
    theta: float | str = Field(
        0.0,
        description="DH angle θ (deg): a number or the name of a variable or fixed value.",
    )
    limits: tuple[float, float] = Field(
        description="[lo, hi], lo < hi: the joint range sampled (deg for R joints, length unit for "
        "P).",
    )

    _numbers = field_validator("a", "alpha", "d", "theta", mode="before")(
        classmethod(lambda cls, v: _number_or_name(v))
    )

    @field_validator("limits")
    @classmethod
    def _lo_hi(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not v[0] < v[1]:
            raise ValueError(f"lower limit {v[0]} is not below upper limit {v[1]}")
        return v


class Chain(Section):
    convention: Literal["standard", "modified"] = Field(
        "standard",
        description="`standard` (T = Rz(θ) Tz(d) Tx(a) Rx(α)) or `modified` (Craig: T = Rx(α) "
        "Tx(a) Rz(θ) Tz(d)).",
    )
    joints: list[Joint] = Field(
        min_length=1,
        max_length=12,
        description="One DH row per joint (1 to 12).",
    )


class ImportedJoint(NamedTuple):
    """An active joint of a URDF chain, as a DH row shows it: type and limits (degrees
    for R joints, length units for P joints)."""

    name: str
    type: str
    limits: tuple[float, float]


@lru_cache(maxsize=16)
def _parsed(text: str, where: str):
    """The parsed URDF (kept: sweeps and archives validate the same text again)."""
    from designopt.kinematics import urdf

    return urdf.parse(text, where)


class UrdfChain(Section):
    """A chain read from a URDF file: the path ``base`` → ``tip`` with origin numbers bound
    by ``set`` (docs/urdf.md). ``urdf_path`` and ``urdf_text`` are filled in when the
    config is loaded (the resolved file and its text), so that an archive carries the
    robot it was run on and ``designopt export`` needs nothing else."""

    urdf: str = Field(
        min_length=1,
        description="The URDF file, read from the config file's folder when relative.",
    )
    base: str | None = Field(
        None,
        description="The link whose frame is the base frame (default: the root); an ancestor of "
        "`tip`.",
    )
    tip: str | None = Field(
        None,
        description="The end-effector link (default: the single leaf; required when there are "
        "several).",
    )
    set: dict[str, float | str] = Field(
        {},
        description="{<joint>.origin.<x|y|z|roll|pitch|yaw|length>: variable, fixed name or "
        "number}: origin entries bound to designs (lengths in the URDF's unit, angles "
        "in deg).",
    )
    limits: dict[str, tuple[float, float]] = Field(
        {},
        description="{joint: [lo, hi]} overriding the URDF's limits: deg for revolute and "
        "continuous joints, length unit for prismatic.",
    )
    urdf_path: str | None = Field(
        None,
        description="Filled in on load: the resolved URDF file (an archive carries it; do not "
        "set).",
    )
    urdf_text: str | None = Field(
        None,
        description="Filled in on load: the URDF's text, so an archive carries its robot (do not "
        "set).",
    )
    _imported: Any = PrivateAttr(default=None)

    @field_validator("set", mode="before")
    @classmethod
    def _flat(cls, v: Any) -> Any:
        """``set`` as nested YAML (``joint3: {origin: {x: a2}}``) is the dotted
        ``joint3.origin.x: a2``."""
        if not isinstance(v, dict):
            return v
        out: dict[Any, Any] = {}
        for k, x in v.items():
            items = ({f"{k}.{kk}": xx for kk, xx in cls._flat(x).items()}
                     if isinstance(x, dict) and x else {k: _number_or_name(x)})  # fmt: skip
            for kk, xx in items.items():
                if kk in out:
                    raise ValueError(f"{kk}: given twice (once dotted, once nested); give it once")
                out[kk] = xx
        return out

    @model_validator(mode="after")
    def _load(self, info: ValidationInfo) -> UrdfChain:
        from designopt.kinematics import urdf

        if self.urdf_text is None:
            p = Path(self.urdf).expanduser()
            if not p.is_absolute():
                ctx = info.context if isinstance(info.context, dict) else {}
                folder = ctx.get("config_dir")
                p = (Path(folder) if folder is not None else Path.cwd()) / p
            if p.is_dir():
                raise ConfigError(f"{p}: is a folder, not a URDF file (chain.urdf: {self.urdf})")
            if not p.is_file():
                raise ConfigError(f"{p}: URDF file not found (chain.urdf: {self.urdf}; a "
                                  "relative path is read from the config file's folder)")  # fmt: skip
            try:
                self.urdf_text = p.read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as e:
                raise ConfigError(f"{p}: cannot read the URDF ({e})") from None
            self.urdf_path = str(p.resolve())
        where = self.urdf_path or self.urdf
        robot = _parsed(self.urdf_text, where)
        for n, lim in self.limits.items():
            if not lim[0] < lim[1]:
                raise ValueError(f"limits.{n}: lower limit {lim[0]} is not below upper {lim[1]}")
        rad = {
            n: tuple(math.radians(x) for x in lim)
            if n in robot.joints and robot.joints[n].type != "prismatic" else tuple(lim)
            for n, lim in self.limits.items()
        }  # fmt: skip
        imp = urdf.import_path(robot, self.base, self.tip, rad)  # type: ignore[arg-type]
        self._imported = imp
        for key in self.set:
            urdf.parse_key(key, imp)
        return self

    @property
    def imported(self):
        """The imported path (``designopt.kinematics.urdf.Imported``)."""
        return self._imported

    def bound(self) -> dict[tuple[str, str], float | str]:
        """{(joint, field): number or name} of ``set``."""
        from designopt.kinematics.urdf import parse_key

        return {parse_key(k, self._imported): v for k, v in self.set.items()}

    @property
    def joints(self) -> tuple[ImportedJoint, ...]:
        """The active joints, in the units of a DH row."""
        imp = self._imported
        return tuple(
            ImportedJoint(
                n,
                t,
                (math.degrees(lo), math.degrees(hi)) if t == "R" else (lo, hi),
            )
            for n, t, lo, hi in zip(imp.active, imp.types, imp.lower, imp.upper, strict=True)
        )


def _chain_kind(v: Any) -> str:
    if isinstance(v, UrdfChain) or (isinstance(v, dict) and "urdf" in v):
        return "urdf"
    return "dh"


AnyChain = Annotated[
    Union[Annotated[Chain, Tag("dh")], Annotated[UrdfChain, Tag("urdf")]],  # noqa: UP007
    Discriminator(_chain_kind),
]


class SerialIndices(Section):
    """Which Jacobian, which condition number, which measure, how many samples."""

    jacobian: list[Literal["vx", "vy", "vz", "wx", "wy", "wz"]] | Literal["position", "full"] = (
        Field(
            "position",
            description="Rows of the 6×n geometric Jacobian (base frame): a list of vx vy vz "
            "wx wy wz, or `position` (vx vy vz) or `full` (all six).",
        )
    )
    norm: Literal["2", "fro"] = Field(
        "2",
        description="`2`: 1/k = σmin/σmax; `fro`: 1/k = 1/(‖J‖_F ‖J⁺‖_F).",
    )
    normalized: bool = Field(
        False,
        description="`fro` only: report k_F/m (m = min(rows, joints)) so that k ≥ 1.",
    )
    measure: Literal["joint", "cartesian", "task"] = Field(
        "joint",
        description="`joint` (uniform in the joint box), `cartesian` (weights |det J|; a square "
        "Jacobian) or `task` (targets of `study.task`, solved by IK).",
    )
    sampler: Literal["uniform", "halton", "rqmc"] = Field(
        "uniform",
        description="How the samples are drawn: `uniform` (i.i.d.), `halton` (one randomly shifted "
        "Halton set) or `rqmc` (R independently shifted Halton sets; standard errors "
        "from the replicates' spread).",
    )
    n_samples: int = Field(
        20_000,
        gt=1,
        description="Samples per design, shared by the swarm (task: targets; ignored for a points "
        "file).",
    )
    chunk: int = Field(
        16_384,
        gt=0,
        description="Samples per streamed chunk, bounding memory (task: targets solved at a time, "
        "1024 unless given).",
    )
    emitters: Literal["fusion", "elemental"] = Field(
        "fusion",
        description="Task: the code generator XLA's CPU backend compiles the IK's program with: "
        "`fusion` (XLA's default) or `elemental` (its classic emitters: about a third less "
        "compile; measured faster to run for the planning case, slower for a PUMA 560 task). "
        "The values agree to their last bits; other backends ignore it.",
    )
    length_scale: float = Field(
        1.0,
        gt=0,
        description="Characteristic length L (length unit) multiplying the angular rows, so that "
        "both blocks have length units.",
    )
    replicates: int | None = Field(
        None,
        ge=1,
        le=1024,
        description="R, the independent randomisations of the sampler: at least 2 with `rqmc` (16 "
        "unless given), 1 with `halton`; `uniform` accepts R ≥ 2 (i.i.d. groups).",
    )

    _replicates = field_validator("replicates")(check_replicates)

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


class _Bound(Section):
    """One side of a constraint: exactly one of ``le`` and ``ge``."""

    le: float | None = Field(
        None,
        allow_inf_nan=False,
        description="Upper bound: feasible when the value is ≤ le (give le or ge, not both).",
    )
    ge: float | None = Field(
        None,
        allow_inf_nan=False,
        description="Lower bound: feasible when the value is ≥ ge (give le or ge, not both).",
    )

    @model_validator(mode="after")
    def _one_side(self) -> _Bound:
        if (self.le is None) == (self.ge is None):
            raise ValueError("give exactly one of 'le' and 'ge'")
        return self


class LinearConstraint(_Bound):
    """A linear constraint on the design variables: Σ terms[name]·x[name] ≤ le (or ≥ ge),
    e.g. ``{terms: {l1: 1, l2: 1}, le: 1.2}`` bounds the total reach."""

    terms: dict[str, float] = Field(
        min_length=1,
        description="{design variable: coefficient}: the constrained value Σ terms·x.",
    )


class IndexConstraint(_Bound):
    """A bound on an index of the study, e.g. ``{index: reach, ge: 0.99}``: feasible when
    the index is ≥ ge (or ≤ le). Deb's rules or the penalty see g = ge − index (index − le)."""

    index: str = Field(
        description="The index bounded, e.g. `reach` (g = ge − index, or index − le).",
    )


def _constraint_kind(v: Any) -> str:
    if isinstance(v, IndexConstraint) or (isinstance(v, dict) and "index" in v):
        return "index bound"
    return "linear"


AnyConstraint = Annotated[
    Union[Annotated[LinearConstraint, Tag("linear")],  # noqa: UP007
          Annotated[IndexConstraint, Tag("index bound")]],
    Discriminator(_constraint_kind),
]  # fmt: skip


class TaskIK(Section):
    """The IK behind ``measure: task`` (``designopt.kinematics.ik.IKOptions``). The
    defaults keep the index's definition, the best free solution at every target
    (docs/task.md): 8 distinct converged solutions compared, each climbed 12 steps
    along its self-motion, and a second pass from 4 neighbours' solutions; a search may
    rank with cheaper settings (``optimizer.fidelity``). LM steps per seed, rounds of random seeds, FK-database size,
    seeds per target (nearest database entries spread over the arm's branches, then
    random draws), distinct converged solutions compared (``n_best``: the best by
    ``best``, the study's 1/k (``dexterity``) or the ``clearance``, is kept), the
    null-space climb of that score from each (``climb`` steps; 0: none), a second pass
    seeded with the kept solutions of each target's nearest neighbours (``neighbours``:
    how many; 0: none), tolerances (position ×
    the reach scale, orientation in rad), the damping (λ = damping_e·E + damping), and
    the scheduling (stall factor, Z-order window, steps per block, slots in flight)."""

    iters: int = Field(48, ge=1, le=1000, description="LM steps per seed at most.")
    rounds: int = Field(
        8,
        ge=1,
        le=100,
        description="Rounds of `n_random` uniform seed draws after the nearest database entries.",
    )
    n_db: int = Field(4096, ge=1, le=1_000_000, description="FK-database entries per design.")
    n_nearest: int = Field(
        4,
        ge=0,
        le=64,
        description="Seeds per target from its nearest database entries, tried first.",
    )
    n_random: int = Field(
        6,
        ge=0,
        le=64,
        description="Uniform random seeds per round (at least one seed in all).",
    )
    n_best: int = Field(
        8,
        ge=1,
        le=64,
        description="Distinct converged seeds compared per target; the one with the best `best` "
        "score is kept (1: the first).",
    )
    climb: int = Field(
        12,
        ge=0,
        le=200,
        description="Null-space ascent steps of the score from each candidate solution (0: none).",
    )
    neighbours: int = Field(
        4,
        ge=0,
        le=15,
        description="A second pass seeded with the kept solutions of this many nearest reached "
        "targets among each run of 16 (0: none).",
    )
    best: Literal["dexterity", "clearance"] = Field(
        "dexterity",
        description="The score `n_best` compares: `dexterity` (the study's 1/k) or `clearance` "
        "(needs `collision`).",
    )
    tol_pos: float = Field(
        1e-9,
        gt=0,
        le=1,
        description="A target is reached within tol_pos × the reach scale.",
    )
    tol_rot: float = Field(
        1e-9,
        gt=0,
        le=1,
        description="A target's orientation is reached within tol_rot (rad).",
    )
    damping: float = Field(
        1e-16,
        gt=0,
        le=1,
        description="The constant term of the damping λ = damping_e·½|e|² + damping.",
    )
    damping_e: float = Field(
        0.1,
        ge=0,
        le=100,
        description="The error-scaled term of the damping λ = damping_e·½|e|² + damping "
        "(Sugihara's).",
    )
    stall: float = Field(
        0.5,
        gt=0,
        le=1,
        description="Drop a seed whose least error fell by less than this factor in `block` steps.",
    )
    window: int = Field(
        32,
        ge=1,
        le=4096,
        description="Z-order neighbours among which the nearest database seeds are ranked.",
    )
    block: int = Field(4, ge=1, le=64, description="LM steps per block between checks.")
    slots: int = Field(
        0,
        ge=0,
        le=1_000_000,
        description="Targets in flight per call (0: automatic).",
    )

    @model_validator(mode="after")
    def _seeds(self) -> TaskIK:
        if self.n_nearest + self.n_random < 1:
            raise ValueError("n_nearest + n_random: give at least one seed per target")
        if self.n_nearest > self.n_db:
            raise ValueError(f"n_nearest ({self.n_nearest}) exceeds n_db ({self.n_db})")
        if self.n_nearest > self.window:
            raise ValueError(f"n_nearest ({self.n_nearest}) exceeds window ({self.window}): "
                             "the nearest seeds are ranked among that many entries")  # fmt: skip
        return self


Entry = float | str
"""A number, or the name of a design variable or fixed value."""


def _finite_entries(v: Any) -> Any:
    """A port's entries with every number finite and of a sane size (names are checked
    by the study)."""
    bad = validation.first_bad([x for x in v if not isinstance(x, str)])
    if bad is not None:
        raise ValueError(bad[1])
    return v


class CameraShaft(Section):
    """``study.task.camera.shaft``: the scope as a rigid rod from its tip back through its
    port, a capsule every arm's links and instrument keep ``collision.margin`` from."""

    length: float = Field(
        gt=0,
        allow_inf_nan=False,
        description="The scope's rigid length from its tip back (length unit): the part "
        "outside the port is where the instrument arms meet it.",
    )
    radius: float = Field(
        ge=0, allow_inf_nan=False, description="The scope's radius (length unit)."
    )


class Camera(Section):
    """``study.task.camera``: an endoscope through its own port, aimed at the task region
    (docs/planning.md, "The endoscope"). Its tip lies on the line from the incision
    point to ``aim``, at the depth that puts ``aim`` in the middle of the working band
    (within ``insertion``); a target is seen when it lies in the field-of-view cone and
    the band and the line of sight from the tip misses the anatomy (``view_ok``)."""

    port: tuple[Entry, Entry, Entry] = Field(
        description="[x, y, z]: the camera port (numbers, variable or fixed names, or "
        "`-name`), placed on `task.body_wall` like the arms' ports.",
    )
    fov: float = Field(
        70.0,
        gt=0,
        le=180,
        allow_inf_nan=False,
        description="The field of view's full angle (deg): a target is in view within half "
        "of it from the scope's axis (a laparoscope's is typically 70-90 deg).",
    )
    band: tuple[float, float] = Field(
        description="[near, far]: the working distances from the tip at which the image is "
        "sharp and bright enough (length unit), 0 ≤ near < far.",
    )
    aim: tuple[float, float, float] | None = Field(
        None,
        description="The point the scope looks at (length unit); unset: the task region's "
        "centre.",
    )
    insertion: tuple[float, float] | None = Field(
        None,
        description="[d0, d1]: the tip's depth past the port (length unit; d0 = d1 holds it at "
        "one depth); unset: [0, ∞).",
    )
    shaft: CameraShaft | None = Field(
        None,
        description="`{length, radius}`: the scope's rigid shaft from its tip back; the arms' "
        "collision checks keep clear of it (needs `study.collision`). Unset: not checked.",
    )

    _port_numbers = field_validator("port", mode="before")(
        classmethod(lambda cls, v: _number_or_name(v))
    )

    _port = field_validator("port")(classmethod(lambda cls, v: _finite_entries(v)))

    @field_validator("band")
    @classmethod
    def _band(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not (math.isfinite(v[0]) and math.isfinite(v[1]) and 0 <= v[0] < v[1]):
            raise ValueError(f"needs 0 ≤ near < far (lengths), got {list(v)}")
        return v

    @field_validator("insertion")
    @classmethod
    def _insertion(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not (math.isfinite(v[0]) and math.isfinite(v[1])
                                  and 0 <= v[0] <= v[1]):  # fmt: skip
            raise ValueError(f"needs 0 ≤ d0 ≤ d1 (lengths; d0 = d1: a fixed depth), got {list(v)}")
        return v

    @field_validator("aim")
    @classmethod
    def _aim(cls, v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if v is not None:
            bad = validation.first_bad(list(v))
            if bad is not None:
                raise ValueError(bad[1])
        return v


class SerialTask(Task):
    """``study.task``: the region, the optional tool-axis cone, the port (numbers, or the
    names of design variables or fixed values, or minus one), the body wall the ports lie
    on and the IK's settings."""

    port: tuple[Entry, Entry, Entry] | None = Field(  # type: ignore[assignment]
        None,
        description="[x, y, z]: the port the instrument passes through (numbers, names of "
        "variables or fixed values, or `-name`); each target's tool axis points from "
        "it to the target.",
    )
    body_wall: BodyWall | None = Field(
        None,
        description="The wall every port is projected onto: `{shape: halfspace | ellipsoid | mesh, "
        "...}` (docs/planning.md).",
    )
    instrument_angle: tuple[float, float] | None = Field(
        None,
        description="[lo, hi] (deg): the band of the angle between arms 0 and 1's instruments that "
        "`instrument_ok` counts.",
    )
    camera: Camera | None = Field(
        None,
        description="An endoscope through its own port, `{port, band, fov, aim, insertion}`: "
        "adds the index `view_ok`, the share of targets it sees (docs/planning.md).",
    )
    ik: TaskIK = Field(TaskIK(), description="The batched IK that solves every target.")
    replications: int = Field(
        8,
        ge=1,
        le=64,
        description="R, the independent replications of every task index's estimate: the "
        "targets fall into R interleaved groups (runs of 16 under `ik.neighbours`), each "
        "solved with its own FK database and IK seeds, and an index's SE is the spread of "
        "the groups' values (batch means), so it covers the IK's random choices too "
        "(docs/indices.md). 1: one database for all targets, i.i.d. SEs that leave the IK's "
        "draw out.",
    )
    port_gap: float | None = Field(
        None,
        ge=0,
        allow_inf_nan=False,
        description="The least distance between two incision points (length unit; 0: no "
        "check): closer ports get a `warning:` after a run and on `eval`. Unset: 5 cm in the "
        "chain's unit (m, cm or mm; no check under an undeclared unit): the common "
        "laparoscopic rule of thumb of trocars at least about 5 cm apart (robotic systems' "
        "port-placement guides ask for more, typically 6-10 cm: set it to your system's).",
    )

    @field_validator("instrument_angle")
    @classmethod
    def _band(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not (math.isfinite(v[0]) and math.isfinite(v[1])
                                  and 0 <= v[0] < v[1] <= 180):  # fmt: skip
            raise ValueError(f"needs 0 ≤ lo < hi ≤ 180 (degrees), got {list(v)}")
        return v

    @field_validator("port", mode="before")
    @classmethod
    def _port_numbers(cls, v: Any) -> Any:
        return _number_or_name(v)

    @field_validator("port")
    @classmethod
    def _port(cls, v: Any) -> Any:  # (overrides Task._port: names are checked by the study)
        return v if v is None else _finite_entries(v)


class Units(Section):
    """``study.units``: the unit the chain's lengths (and the task's coordinates) are in.
    A DH chain keeps whatever unit its numbers are in: name it (``{length: mm}``) and every
    printout and axis says it; undeclared, lengths are labelled ``L`` (the chain's own
    length unit). A URDF chain is in metres by the URDF specification."""

    length: str | None = Field(
        None,
        min_length=1,
        max_length=16,
        pattern=r"^[^\s\[\]]+$",
        description="The unit of the chain's lengths and the task's coordinates (e.g. `mm`, `m`), "
        "printed on every length; unset: `L` (a URDF chain is in m).",
    )


class ArmBase(Section):
    """Where an arm's base frame sits in the world (the task's frame): ``xyz`` (the
    chain's length unit) and ``rpy`` (degrees; R = Rz(yaw)·Ry(pitch)·Rx(roll), the URDF
    convention). Every entry is a number or the name of a design variable or fixed
    value, or minus one ("-b"), so the placement can be designed like any chain number
    (two arms at x = −b and x = b share the variable b)."""

    xyz: tuple[Entry, Entry, Entry] = Field(
        (0.0, 0.0, 0.0),
        description="The arm base's position [x, y, z] in the world (length unit): numbers, "
        "variable or fixed names, or `-name`.",
    )
    rpy: tuple[Entry, Entry, Entry] = Field(
        (0.0, 0.0, 0.0),
        description="The arm base's roll, pitch, yaw (deg; R = Rz(yaw)·Ry(pitch)·Rx(roll)): "
        "numbers, variable or fixed names, or `-name`.",
    )

    _numbers = field_validator("xyz", "rpy", mode="before")(
        classmethod(lambda cls, v: _number_or_name(v))
    )


class Arm(Section):
    """One of several arms: its base, its port (else ``task.port``, if any), its tool's
    insertion range and, for a set-up that mixes robots, its own robot: ``chain`` (else
    ``study.chain``) with its capsules' ``radius`` and ``tool_radius`` (else
    ``collision``'s). Arms of one robot are solved in one batch
    (``designopt.studies.serial.setup``)."""

    chain: AnyChain | None = Field(
        None,
        description="This arm's own robot: `{urdf: FILE, base, tip, set}` or a DH table (else "
        "`study.chain`); its names are the study's variables and fixed values.",
    )
    radius: float | list[float] | None = Field(
        None,
        description="This arm's capsule radius, one number or one per link (else "
        "`collision.radius`); with its own `chain`, for its links.",
    )
    tool_radius: float | None = Field(
        None,
        description="This arm's instrument radius past its port (else `collision.tool_radius`).",
    )
    role: Literal["instrument", "camera"] = Field(
        "instrument",
        description="`instrument` (reaches the task's targets) or `camera`: the arm holds "
        "the endoscope of `task.camera` (its tip at the scope's tip, its tool axis along the "
        "scope's, through the camera port) for the whole task; `view_ok` counts only what "
        "it holds, and its links count in the arms' collisions (docs/planning.md).",
    )
    base: ArmBase = Field(ArmBase(), description="Where this arm's base frame sits.")
    port: tuple[Entry, Entry, Entry] | None = Field(
        None,
        description="This arm's port (numbers, variable or fixed names, or `-name`; else "
        "`task.port`), placed on `task.body_wall` when one is given.",
    )
    insertion: tuple[float, float] | None = Field(
        None,
        description="[d0, d1]: this arm's tool depth past its port (else `task.insertion`).",
    )

    _port_numbers = field_validator("port", mode="before")(
        classmethod(lambda cls, v: _number_or_name(v))
    )

    @field_validator("radius", "tool_radius")
    @classmethod
    def _radii(cls, v: Any) -> Any:
        for i, x in enumerate(v if isinstance(v, list) else [] if v is None else [v]):
            if not (math.isfinite(x) and x > 0):
                at = f"entry {i}: " if isinstance(v, list) else ""
                raise ValueError(f"{at}needs a radius > 0 (length unit), got {x}")
        if isinstance(v, list) and not v:
            raise ValueError("needs at least one radius (or one number for every link)")
        return v

    @field_validator("insertion")
    @classmethod
    def _insertion(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not (math.isfinite(v[0]) and math.isfinite(v[1])
                                  and 0 <= v[0] < v[1]):  # fmt: skip
            raise ValueError(f"needs 0 ≤ d0 < d1 (the depth past the port), got {list(v)}")
        return v


ARM_INDEX_NAMES = ("reach_all", "arms_ok", "arms_free", "instrument_angle")
"""Indices of a multi-arm study beside ``reach_<k>`` per arm (docs/task.md)."""
COLLISION_INDEX_NAMES = ("clearance", "collision_free")
"""Indices under ``study.collision`` (docs/task.md)."""


class SerialSettings(StudySettings):
    """A user's serial mechanism: chain, design variables, indices, objective."""

    name: Literal["serial"] = Field(
        "serial",
        description="`serial`: your own serial chain, as a DH table or a URDF.",
    )
    variables: dict[str, tuple[float, float]] = Field(
        description="The design box {name: [lo, hi]}; every variable must appear in the chain "
        "(angles in deg).",
    )
    fixed: dict[str, float] = Field(
        {},
        description="{name: value} for names the chain uses that are not optimised.",
    )
    arms: list[Arm] | None = Field(
        None,
        min_length=2,
        max_length=8,
        description="2-8 arms, each with its own base and port (needs `collision`): copies of "
        "`chain`, or each its own robot (`arms.<k>.chain`, `radius`, `tool_radius`).",
    )
    chain: AnyChain = Field(  # type: ignore[assignment]
        None,
        description="The chain: `{convention, joints: [...]}` (DH) or `{urdf: FILE, ...}`; "
        "required unless every arm gives its own `arms.<k>.chain` (then arm 0's is the "
        "study's).",
        validate_default=False,
    )
    indices: SerialIndices = Field(
        SerialIndices(),
        description="Which Jacobian, which condition number, which measure, how many samples.",
    )
    objective: dict[str, float | bool | int] = Field(
        {"gci": -1.0},
        description="{index: weight} of the minimised f = Σ w·index; `normalize: true` maps each "
        "index to [0, 1] over `n_norm` (default 64) designs first.",
    )
    constraints: list[AnyConstraint] = Field(
        [],
        description="Linear constraints `{terms, le | ge}` on the variables and index bounds "
        "`{index, le | ge}`.",
    )
    task: SerialTask | None = Field(
        None,
        description="The task to reach under `indices.measure: task`: region, tool axis or port, "
        "IK.",
    )
    collision: Collision | None = Field(
        None,
        description="Link capsules and obstacles: adds `clearance` and `collision_free`.",
    )
    units: Units = Field(Units(), description="The length unit the chain is in.")

    @field_validator("units")
    @classmethod
    def _urdf_metres(cls, v: Units, info: ValidationInfo) -> Units:
        if isinstance(info.data.get("chain"), UrdfChain) and v.length not in (None, "m"):
            raise ValueError(f"length: a URDF's lengths are metres (the URDF specification), "
                             f"not {v.length!r}; remove units.length or give m")  # fmt: skip
        return v

    @field_validator("fixed")
    @classmethod
    def _fixed(cls, v: dict[str, float], info: ValidationInfo) -> dict[str, float]:
        both = sorted(set(v) & set(info.data.get("variables", {})))
        if both:
            raise ValueError(f"{both} are design variables; a name is either variable or fixed")
        return v

    @field_validator("chain")
    @classmethod
    def _names(cls, chain: Chain | UrdfChain, info: ValidationInfo) -> Chain | UrdfChain:
        known = set(info.data.get("variables", {})) | set(info.data.get("fixed", {}))
        kinds: dict[str, str] = _arm_names(info.data.get("arms"), known, info)
        if isinstance(chain, UrdfChain):
            return _urdf_names(chain, info, known, kinds)
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
        return chain  # names no entry uses: ``_unused`` (a port may use them too)

    @model_validator(mode="after")
    def _consistent(self, info: ValidationInfo) -> SerialSettings:
        if self.chain is None:  # every arm its own robot, or a missing chain
            if not self.arms or any(a.chain is None for a in self.arms):
                raise ValueError("chain: missing; give study.chain (the robot), or every arm "
                                 "its own arms.<k>.chain")  # fmt: skip
            _arm_names(self.arms, set(self.variables) | set(self.fixed), info)  # (_names's)
            self.chain = self.arms[0].chain
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
        self._check_task()
        self._unused()
        # (volume is checked below, with its own message)
        names = self.index_names() if ind.measure == "task" else INDEX_NAMES
        obj = self.objective
        for k, v in obj.items():
            if k in ("normalize",):
                if not isinstance(v, bool):
                    raise ValueError("objective.normalize: must be true or false")
            elif k == "n_norm":
                if isinstance(v, bool) or not isinstance(v, int) or v < 2:
                    raise ValueError("objective.n_norm: must be a whole number ≥ 2")
            elif k not in names:
                raise ValueError(f"objective.{k}: unknown index; weights may name "
                                 f"{list(names)}{self._measure_says()}")  # fmt: skip
            elif isinstance(v, bool):
                raise ValueError(f"objective.{k}: a weight must be a number")
        if not any(k in names for k in obj):
            raise ValueError(f"objective: give at least one weight for {list(names)}")
        for i, c in enumerate(self.constraints):
            if isinstance(c, IndexConstraint):
                if c.index not in self.index_names():
                    raise ValueError(f"constraints.{i}.index: unknown index '{c.index}'; "
                                     f"give one of {list(self.index_names())}"
                                     f"{self._measure_says()}")  # fmt: skip
                continue
            bad = sorted(set(c.terms) - set(self.variables))
            if bad:
                raise ValueError(
                    f"constraints.{i}.terms: {bad} are not design variables "
                    f"(variables: {sorted(self.variables)})"
                )
        if "volume" in obj and ind.measure != "task" and not self.has_volume():
            raise ValueError(
                "objective.volume: the workspace volume ∫ sqrt(det Jv Jvᵀ) dq needs a square "
                f"position Jacobian; indices.jacobian gives rows {[ROWS[r] for r in rows]} "
                f"for {n} joints"
            )
        return self

    def _check_task(self) -> None:
        ind = self.indices
        if ind.measure == "task":
            if self.task is None:
                raise ValueError("indices.measure: 'task' needs a study.task section (the "
                                 "region to reach; docs/task.md)")  # fmt: skip
            cam = self.task.camera
            if cam is not None and cam.shaft is not None and self.collision is None:
                raise ValueError("task.camera.shaft: the arms keep clear of the scope in their "
                                 "collision checks; give study.collision (the arms' capsules)")  # fmt: skip
            if ind.sampler != "uniform":
                raise ValueError(f"indices.sampler: measure 'task' draws its targets "
                                 f"uniformly in the task region; '{ind.sampler}' is for the "
                                 "joint and cartesian measures (give sampler: uniform)")  # fmt: skip
            G = NEIGHBOUR_GROUP
            reg = self.task.region
            N = len(reg.xyz()) if isinstance(reg, Points) else ind.n_samples
            if self.task.ik.neighbours and "chunk" in ind.model_fields_set \
                    and ind.chunk % G and ind.chunk < N:  # fmt: skip
                raise ValueError(f"indices.chunk: with task.ik.neighbours the targets are "
                                 f"solved in chunks of a multiple of {G} (a target's "
                                 f"neighbours are found in its run of {G}), got {ind.chunk}")  # fmt: skip
            if self.task.ik.best == "clearance" and self.collision is None:
                raise ValueError("task.ik.best: 'clearance' keeps the solution farthest from "
                                 "the obstacles: give study.collision, or best: dexterity")  # fmt: skip
        elif self.task is not None:
            raise ValueError(f"task: a task region is scored under indices.measure: task; "
                             f"this config's measure is '{ind.measure}' (set measure: task "
                             "or remove study.task)")  # fmt: skip
        for key in ("collision", "arms"):
            if getattr(self, key) is not None and ind.measure != "task":
                raise ValueError(f"{key}: is scored at the IK solutions of a task "
                                 "(indices.measure: task and a study.task section)")  # fmt: skip
        if self.arms is not None:
            if self.collision is None:
                raise ValueError("arms: several arms are checked against each other as "
                                 "capsules: give study.collision (at least the links' radius)")  # fmt: skip
            if self.task.tool_axis is not None:  # type: ignore[union-attr]
                raise ValueError("arms: the arms reach the task through their ports "
                                 "(arms.<k>.port or task.port) or by position; a "
                                 "task.tool_axis cone is for one arm")  # fmt: skip
            cams = [k for k, a in enumerate(self.arms) if a.role == "camera"]
            for k in cams:
                if self.task.camera is None:  # type: ignore[union-attr]
                    raise ValueError(f"arms.{k}.role: a camera arm holds the endoscope of "
                                     "task.camera; give task.camera (its port, band, fov)")  # fmt: skip
                for fld in ("port", "insertion"):
                    if getattr(self.arms[k], fld) is not None:
                        raise ValueError(f"arms.{k}.{fld}: a camera arm goes through "
                                         f"task.camera's port (task.camera.port, "
                                         f".insertion); remove arms.{k}.{fld}")  # fmt: skip
            if len(cams) > 1:
                raise ValueError(f"arms.{cams[1]}.role: one arm holds the endoscope (arm "
                                 f"{cams[0]} already does)")  # fmt: skip
            if len(cams) == len(self.arms):
                raise ValueError(f"arms.{cams[0]}.role: a set-up needs an instrument arm "
                                 "beside the camera arm")  # fmt: skip
            given = [a.port is not None for a in self.arms if a.role != "camera"]
            if any(given) and not all(given):
                raise ValueError("arms: give every arm its own port (arms.<k>.port) or none "
                                 "(then task.port, if given, is every arm's)")  # fmt: skip
            if all(given) and self.task.port is not None:  # type: ignore[union-attr]
                raise ValueError("arms: every arm has its own port; remove task.port")
            for k, a in enumerate(self.arms):
                if a.insertion is not None and self.ports()[k] is None:
                    raise ValueError(f"arms.{k}.insertion: is the tool's depth past a port; "
                                     f"give arms.{k}.port or task.port")  # fmt: skip
        if self.task is not None and self.task.instrument_angle is not None \
                and self.arms is not None and len(self.instrument_arms()) < 2:  # fmt: skip
            held = " beside the camera arm" if self.camera_arm() is not None else ""
            raise ValueError("task.instrument_angle: is the band of the angle between two "
                             f"instrument arms; the set-up has one{held}")  # fmt: skip
        if self.task is not None and self.task.instrument_angle is not None \
                and self.arms is None:  # fmt: skip
            raise ValueError("task.instrument_angle: is the band of the angle between two "
                             "arms' instruments; give study.arms")  # fmt: skip
        if self.task is not None and self.task.body_wall is not None \
                and all(p is None for p in self.ports()):  # fmt: skip
            raise ValueError("task.body_wall: places the ports on the patient's wall; give "
                             "task.port" + (" or every arm's port" if self.arms else ""))  # fmt: skip
        if self.task is not None and self.task.insertion is not None \
                and all(p is None for p in self.ports()):  # fmt: skip
            raise ValueError("task.insertion: is the tool's depth past a port; give "
                             "task.port" + (" or every arm's port" if self.arms else ""))  # fmt: skip
        c = self.collision
        for i, o in enumerate(c.obstacles if c is not None else []):
            if getattr(o, "inside", False) and all(p is None for p in self.ports()):
                raise ValueError(f"collision.obstacles.{i}.inside: an obstacle inside the "
                                 "patient meets the instrument past its port; give task.port"
                                 + (" or every arm's port" if self.arms else ""))  # fmt: skip
        if c is not None and c.links == "auto" and c.radius is None and \
                (self.arms is None or any(a.radius is None for a in self.arms)):  # fmt: skip
            raise ValueError("collision.radius: links: auto needs the capsules' radius (one "
                             "number, or one per link)"
                             + (", or every arm its own arms.<k>.radius" if self.arms else ""))  # fmt: skip
        if c is not None and isinstance(c.radius, list) and \
                (self.arms is None or any(a.chain is None for a in self.arms)):  # fmt: skip
            n = len(self.chain.joints)
            if len(c.radius) != n:
                raise ValueError(f"collision.radius: one radius per link ({n} links, one per "
                                 f"joint), got {len(c.radius)}")  # fmt: skip
        if c is not None and c.links == "urdf" and not isinstance(self.chain, UrdfChain):
            raise ValueError("collision.links: 'urdf' takes a URDF chain's <collision> "
                             "shapes; a DH chain uses links: auto with a radius")  # fmt: skip
        for k, a in enumerate(self.arms or []):
            self._check_arm_robot(k, a)

    def _check_arm_robot(self, k: int, a: Arm) -> None:
        """An arm's own robot (``arms.<k>.chain``, ``radius``, ``tool_radius``): in the
        study's length unit, its radii one per link, under ``links: urdf`` a URDF."""
        c, ch = self.collision, a.chain
        where = f"arms.{k}"
        if ch is None:
            if isinstance(a.radius, list) and len(a.radius) != len(self.chain.joints):
                raise ValueError(f"{where}.radius: one radius per link ({len(self.chain.joints)} "
                                 f"links of study.chain), got {len(a.radius)}")  # fmt: skip
            return
        if isinstance(ch, UrdfChain) and (length_unit(self) != "m"
                                          or self.units.length not in (None, "m")):  # fmt: skip
            raise ValueError(f"{where}.chain: a URDF's lengths are metres and every arm shares "
                             f"one length unit; the study's is {self.units.length or length_unit(self)} "
                             "(declare units: {length: m} if its DH numbers are metres)")  # fmt: skip
        if c is not None and c.links == "urdf" and not isinstance(ch, UrdfChain):
            raise ValueError(f"{where}.chain: collision.links 'urdf' takes a URDF chain's "
                             "<collision> shapes; a DH chain uses links: auto with a radius")  # fmt: skip
        n = len(ch.joints)
        r = a.radius if a.radius is not None else None if c is None else c.radius
        if c is not None and c.links == "urdf" and a.radius is not None:
            raise ValueError(f"{where}.radius: under links: urdf the URDF's <collision> shapes "
                             "give the radii; remove it")  # fmt: skip
        if isinstance(r, list) and len(r) != n:
            src = f"{where}.radius" if a.radius is not None else "collision.radius"
            hint = "" if a.radius is not None else f" (from {src}); give {where}.radius"
            raise ValueError(f"{where}.radius: one radius per link of this arm's chain ({n} "
                             f"links, one per joint), got {len(r)}{hint}")  # fmt: skip

    def _unused(self) -> None:
        """The task's port names are variables or fixed values (lengths); a variable or
        fixed value no entry (the chain's, an arm's base or port, ``task.port``) uses is
        an error: a typo would otherwise go unnoticed."""
        known = set(self.variables) | set(self.fixed)
        used = dict(_chain_kinds(self.chain))
        for k, a in enumerate(self.arms or []):
            for v, kind in ({} if a.chain is None else _chain_kinds(a.chain)).items():
                what = "set" if isinstance(a.chain, UrdfChain) else "DH entry"
                if v not in known:
                    raise ValueError(f"arms.{k}.chain: {what} name '{v}' is neither a design "
                                     f"variable nor a fixed value (variables: "
                                     f"{sorted(self.variables)}, fixed: {sorted(self.fixed)})")  # fmt: skip
                if used.setdefault(v, kind) != kind:
                    raise ValueError(f"arms.{k}.chain: '{v}' is used as an angle and as a length")
        for a in self.arms or []:
            for kind, row in (("length", a.base.xyz), ("angle", a.base.rpy),
                              ("length", a.port or ())):  # fmt: skip
                used |= {v.removeprefix("-"): kind for v in row if isinstance(v, str)}
        cam = None if self.task is None else self.task.camera
        rows = [("task.port", self.task.port or () if self.task is not None else ()),
                ("task.camera.port", cam.port if cam is not None else ())]  # fmt: skip
        for where, row in rows:
            for i, v in enumerate(row):
                if not isinstance(v, str):
                    continue
                v = v.removeprefix("-")
                if v not in known:
                    raise ValueError(f"{where}.{i}: '{v}' is neither a design variable (give "
                                     f"it bounds under variables) nor a fixed value (variables: "
                                     f"{sorted(self.variables)}, fixed: {sorted(self.fixed)})")  # fmt: skip
                if used.setdefault(v, "length") != "length":
                    raise ValueError(f"{where}.{i}: '{v}' is used as an angle and as a length")
        where = "chain.set entry" if isinstance(self.chain, UrdfChain) else \
            "DH entry of the chain"  # fmt: skip
        extra = " or arm base" if self.arms else ""
        if any(isinstance(v, str) for p in self.ports() if p is not None for v in p) or \
                (cam is not None and any(isinstance(v, str) for v in cam.port)):  # fmt: skip
            extra += " or port"
        unused = sorted(set(self.variables) - set(used))
        if unused:
            raise ValueError(f"design variable(s) {unused} appear in no {where}{extra}")
        unused = sorted(set(self.fixed) - set(used))
        if unused:
            raise ValueError(f"fixed value(s) {unused} appear in no {where}{extra}; use or "
                             "remove them")  # fmt: skip

    def designed_ports(self) -> bool:
        """Whether some port entry names a design variable or fixed value."""
        return any(isinstance(v, str) for p in self.ports() if p is not None for v in p)

    def needs_float64(self) -> str | None:
        if self.indices.measure == "task":
            return (f"indices.measure: 'task' solves inverse kinematics to "
                    f"{self.task.ik.tol_pos:g} of the reach")  # type: ignore[union-attr]  # fmt: skip
        return None

    def _measure_says(self) -> str:
        m = self.indices.measure
        return " under measure: task" if m == "task" else f" under measure: {m}"

    def has_volume(self) -> bool:
        rows = self.indices.rows()
        return len(rows) == len(self.chain.joints) and all(r < 3 for r in rows)

    def index_names(self) -> tuple[str, ...]:
        if self.indices.measure == "task":
            out = TASK_INDEX_NAMES
            if self.collision is not None:
                out += COLLISION_INDEX_NAMES
            if self.arms is not None:
                out += tuple(f"reach_{k}" for k in range(len(self.arms))) + ARM_INDEX_NAMES
                if len(self.instrument_arms()) < 2:  # one instrument beside the camera arm
                    out = tuple(k for k in out if k != "instrument_angle")
                if self.task.instrument_angle is not None:  # type: ignore[union-attr]
                    out += ("instrument_ok",)
                if self.has_port_gap():
                    out += ("port_gap",)
            if self.task.camera is not None:  # type: ignore[union-attr]
                out += ("view_ok",)
            return out
        return tuple(k for k in INDEX_NAMES if k != "volume" or self.has_volume())

    def incision_count(self) -> int:
        """The distinct incision points under ``measure: task``: each arm's own port (one
        for ``task.port``, which the arms share) and the camera's."""
        if self.indices.measure != "task" or self.task is None:
            return 0
        n = 0
        if self.ports()[0] is not None:
            n = 1 if self.shared_port() else len(self.instrument_arms())
        return n + (self.task.camera is not None)

    def shared_port(self) -> bool:
        """Whether every instrument arm goes through ``task.port`` (one incision; also with
        one arm) rather than each through its own ``arms.<k>.port``."""
        return self.arms is None or any(a.port is None for a in self.arms if a.role != "camera")

    def camera_arm(self) -> int | None:
        """The index of the arm that holds the endoscope (``arms.<k>.role: camera``)."""
        return next((k for k, a in enumerate(self.arms or []) if a.role == "camera"), None)

    def instrument_arms(self) -> tuple[int, ...]:
        """The indices of the arms that reach the task's targets (every arm but the camera
        arm; (0,) without ``arms``)."""
        if self.arms is None:
            return (0,)
        return tuple(k for k, a in enumerate(self.arms) if a.role != "camera")

    def has_port_gap(self) -> bool:
        """Whether ``port_gap`` (the least distance between two incision points: the arms'
        and the camera's) is an index: at least two of them (:meth:`incision_count`)."""
        return self.incision_count() > 1

    def weights(self) -> dict[str, float]:
        names = self.index_names()
        return {k: float(v) for k, v in self.objective.items() if k in names}

    def linear_constraints(self) -> list[LinearConstraint]:
        return [c for c in self.constraints if isinstance(c, LinearConstraint)]

    def index_constraints(self) -> list[IndexConstraint]:
        return [c for c in self.constraints if isinstance(c, IndexConstraint)]

    def angle_names(self) -> set[str]:
        if isinstance(self.chain, UrdfChain):
            return {
                v
                for (_, f), v in self.chain.bound().items()
                if isinstance(v, str) and f in ("roll", "pitch", "yaw")
            } | self._arm_angles()
        return {
            getattr(j, e)
            for j in self.chain.joints
            for e in ("alpha", "theta")
            if isinstance(getattr(j, e), str)
        } | self._arm_angles()

    def _arm_angles(self) -> set[str]:
        return {
            v.removeprefix("-") for a in self.arms or [] for v in a.base.rpy if isinstance(v, str)
        } | {v for a in self.arms or [] if a.chain is not None
             for v, kind in _chain_kinds(a.chain).items() if kind == "angle"}  # fmt: skip

    def insertions(self) -> list[tuple[float, float]]:
        """The insertion range [d0, d1] of each arm (one entry without ``arms``): its own,
        else ``task.insertion``, else [0, ∞)."""
        d = (0.0, math.inf) if self.task is None else self.task.depth_range()
        if self.arms is None:
            return [d]
        # the camera arm's tip is the scope's, whose depth camera.pose keeps in range
        return [(0.0, math.inf) if a.role == "camera" else a.insertion
                if a.insertion is not None else d for a in self.arms]  # fmt: skip

    def ports(self) -> list[tuple[Entry, Entry, Entry] | None]:
        """The port entries of each arm (one entry without ``arms``): its own, else
        ``task.port`` (numbers, or names of variables or fixed values: :func:`port_at`)."""
        tp = None if self.task is None else self.task.port
        if self.arms is None:
            return [tp]
        cam = None if self.task is None else self.task.camera
        return [cam.port if a.role == "camera" and cam is not None
                else a.port if a.port is not None else tp for a in self.arms]  # fmt: skip


def _arm_names(arms: list[Arm] | None, known: set[str], info: ValidationInfo) -> dict[str, str]:
    """{name: angle | length} of the names the arms' bases use; ValueError for a name
    that is neither a design variable (with its bounds) nor a fixed value."""
    kinds: dict[str, str] = {}
    for k, arm in enumerate(arms or []):
        entries = [(f"base.{fld}", kind, getattr(arm.base, fld))
                   for fld, kind in (("xyz", "length"), ("rpy", "angle"))]  # fmt: skip
        entries += [("port", "length", arm.port or ())]
        for fld, kind, row in entries:
            for i, v in enumerate(row):
                if not isinstance(v, str):
                    continue
                v = v.removeprefix("-")  # "-b": minus the variable b
                if v not in known:
                    raise ValueError(
                        f"arms.{k}.{fld}.{i}: '{v}' is neither a design variable (give "
                        f"it bounds under variables) nor a fixed value (variables: "
                        f"{sorted(info.data.get('variables', {}))}, fixed: "
                        f"{sorted(info.data.get('fixed', {}))})"
                    )
                if kinds.setdefault(v, kind) != kind:
                    raise ValueError(f"arms.{k}.{fld}.{i}: '{v}' is used as an angle "
                                     "and as a length")  # fmt: skip
    return kinds


def _chain_kinds(chain: Chain | UrdfChain) -> dict[str, str]:
    """{name: angle | length} of the names the chain's entries use."""
    if isinstance(chain, UrdfChain):
        return {v: "angle" if k.rsplit(".", 1)[-1] in ("roll", "pitch", "yaw") else "length"
                for k, v in chain.set.items() if isinstance(v, str)}  # fmt: skip
    return {getattr(j, e): "angle" if e in ("alpha", "theta") else "length"
            for j in chain.joints for e in ("a", "alpha", "d", "theta")
            if isinstance(getattr(j, e), str)}  # fmt: skip


def _urdf_names(chain: UrdfChain, info: ValidationInfo, known: set[str],
                kinds: dict[str, str] | None = None) -> UrdfChain:  # fmt: skip
    """Every ``set`` name is a variable or fixed value, used as an angle or as a length
    but not both; every variable appears in ``set`` (or an arm's base)."""
    kinds = dict(kinds or {})
    for key, v in chain.set.items():
        if not isinstance(v, str):
            continue
        if v not in known:
            raise ValueError(
                f"set.{key}: '{v}' is neither a design variable nor a fixed value "
                f"(variables: {sorted(info.data.get('variables', {}))}, "
                f"fixed: {sorted(info.data.get('fixed', {}))})"
            )
        kind = "angle" if key.rsplit(".", 1)[-1] in ("roll", "pitch", "yaw") else "length"
        if kinds.setdefault(v, kind) != kind:
            raise ValueError(f"set.{key}: '{v}' is used as an angle and as a length")
    return chain  # names no entry uses: SerialSettings._unused (a port may use them too)


def entry_value(s: SerialSettings, v: Entry, design: Any = None) -> float:
    """One base or port entry's number: a number, a fixed value, or a design variable's
    value in ``design`` (a mapping of the variables, config units; None: the middle of
    each variable's box), or minus one of these ("-b")."""
    if not isinstance(v, str):
        return float(v)
    name = v.removeprefix("-")
    if name in s.fixed:
        x = float(s.fixed[name])
    elif design is not None:
        x = float(design[name])
    else:
        lo, hi = s.variables[name]
        x = (float(lo) + float(hi)) / 2
    return -x if v.startswith("-") else x


def port_at(s: SerialSettings, k: int = 0, design: Any = None) -> tuple[float, float, float] | None:
    """Arm ``k``'s port entries as numbers for ``design`` (:func:`entry_value`), before
    any projection onto ``task.body_wall``; None without a port."""
    p = s.ports()[k]
    return None if p is None else tuple(entry_value(s, v, design) for v in p)  # type: ignore[return-value]


def length_unit(s: SerialSettings) -> str:
    """The chain's length unit: m for a URDF chain, the declared ``units.length`` of a DH
    chain, else ``L`` (undeclared)."""
    if isinstance(s.chain, UrdfChain):
        return "m"
    return s.units.length or "L"


def units(s: SerialSettings) -> dict[str, str]:
    """Angles in deg, lengths in the chain's length unit u (:func:`length_unit`: m for a
    URDF, the declared unit of a DH chain, else L);
    gci, gcsei dimensionless; the volume ∫|det Jv| dq in L^rows (an area for a planar
    Jacobian); the manipulability sqrt(det J Jᵀ) in L^(rows in L) for an all-revolute
    chain with no more rows than joints (angular rows count as L when ``length_scale``
    scales them), else "mixed" (prismatic columns or more rows than joints mix units).
    The task indices reach, gci_q05 and joint_margin are dimensionless shares."""
    u = length_unit(s)
    ang = s.angle_names()
    out = {k: "deg" if k in ang else u for k in s.variables}
    rows = s.indices.rows()
    n_len = sum(r < 3 or s.indices.length_scale != 1.0 for r in rows)
    all_r = all(j.type == "R" for j in s.chain.joints)
    if all_r and len(rows) <= len(s.chain.joints):
        man = "-" if n_len == 0 else (u if n_len == 1 else f"{u}^{n_len}")
    else:
        man = "mixed"
    vol = u if len(rows) == 1 else f"{u}^{len(rows)}"
    out["__length__"] = u
    if s.indices.measure == "task":
        out |= {"reach": "-", "gci": "-", "gci_q05": "-", "manipulability": man,
                "joint_margin": "-"}  # fmt: skip
        out |= {"clearance": u, "collision_free": "-"} if s.collision is not None else {}
        out |= {"instrument_angle": "deg", "instrument_ok": "-"} if s.arms is not None else {}
        out |= {"port_gap": u} if s.has_port_gap() else {}
        out |= {"view_ok": "-"} if s.task.camera is not None else {}  # type: ignore[union-attr]
        return out | {k: "-" for k in s.index_names() if k.startswith(("reach_", "arms_"))}
    return out | {"gci": "-", "gcsei": "-", "manipulability": man, "volume": vol}
