"""Task workspaces: the regions a surgical arm must reach, as YAML and as samples.

A task is a region (``cylinder``, ``box``, ``ball``, ``cone``, or a ``points`` file) and,
optionally, a cone of tool directions (``tool_axis``). :func:`sample` draws n targets
uniformly in the region's volume (area or length where a size is zero) and, with
``tool_axis``, tool z axes uniformly on the spherical cap of the given half-angle. The
draws come from one key (the run's ``samples`` stream), so every design of a swarm is
scored on the same targets (common random numbers). Lengths are in the chain's unit,
angles in degrees. docs/task.md explains the regions and the task indices.
"""

from __future__ import annotations

import csv
import math
from functools import partial
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import jax
import jax.numpy as jnp
import numpy as np
from pydantic import Discriminator, Field, Tag, ValidationInfo, field_validator, model_validator

from designopt.core import validation
from designopt.core.settings import Section

Vec3 = tuple[float, float, float]


def _unit(v: Vec3, what: str) -> Vec3:
    n = math.sqrt(sum(x * x for x in v))
    if not n > 0:
        raise ValueError(f"{what} must be a non-zero vector, got {list(v)}")
    return v


class Box(Section):
    """An axis-aligned box; a zero size makes it planar (or a segment, or a point)."""

    shape: Literal["box"] = Field(description="`box`: an axis-aligned box.")
    center: Vec3 = Field(description="The box's centre [x, y, z] (length unit).")
    size: Vec3 = Field(
        description="Edge lengths [sx, sy, sz] (length unit), each ≥ 0; a zero size makes it "
        "planar.",
    )

    @field_validator("size")
    @classmethod
    def _size(cls, v: Vec3) -> Vec3:
        if any(s < 0 for s in v):
            raise ValueError(f"sizes must be ≥ 0, got {list(v)}")
        if not any(s > 0 for s in v):
            raise ValueError(f"a box of size {list(v)} is one point; give a size > 0 in some "
                             "direction (or a points file for single targets)")  # fmt: skip
        return v


class Ball(Section):
    shape: Literal["ball"] = Field(description="`ball`: a solid ball.")
    center: Vec3 = Field(description="The ball's centre [x, y, z] (length unit).")
    radius: float = Field(gt=0, description="The ball's radius (length unit).")


class Cylinder(Section):
    """A solid cylinder about ``axis`` through ``center``; height 0 makes it a disk."""

    shape: Literal["cylinder"] = Field(description="`cylinder`: a solid cylinder (or a disk).")
    center: Vec3 = Field(description="The centre [x, y, z] of the cylinder (length unit).")
    axis: Vec3 = Field(
        (0.0, 0.0, 1.0),
        description="The cylinder's axis direction (a non-zero vector; normalised).",
    )
    radius: float = Field(gt=0, description="The cylinder's radius (length unit).")
    height: float = Field(
        0.0,
        ge=0,
        description="The cylinder's height along its axis (length unit); 0 makes it a disk.",
    )

    @field_validator("axis")
    @classmethod
    def _axis(cls, v: Vec3) -> Vec3:
        return _unit(v, "axis")


class Cone(Section):
    """The solid cone of half-angle ``half_angle`` (degrees, in (0, 90): at 90° its radius
    is infinite) about ``axis`` from ``apex`` (e.g. the remote centre of motion at the
    port), cut by the planes at axial depths ``depth`` = [d0, d1] (0 ≤ d0 < d1): a
    frustum, or the whole cone to d1."""

    shape: Literal["cone"] = Field(description="`cone`: a solid cone (or frustum) from its apex.")
    apex: Vec3 = Field(
        description="The cone's apex [x, y, z] (length unit), e.g. the remote centre of motion at "
        "the port.",
    )
    axis: Vec3 = Field(
        description="The cone's axis direction from the apex (a non-zero vector; normalised).",
    )
    half_angle: float = Field(description="Half-angle of the cone (deg), in (0, 90).")
    depth: tuple[float, float] = Field(
        description="[d0, d1]: the axial depths (length unit) that cut the cone, 0 ≤ d0 < d1 (d0 = "
        "0: the whole cone to d1).",
    )

    @field_validator("axis")
    @classmethod
    def _axis(cls, v: Vec3) -> Vec3:
        return _unit(v, "axis")

    @field_validator("half_angle")
    @classmethod
    def _angle(cls, v: float) -> float:
        if not 0 < v < 90:  # tan 90° = ∞: the region between the cut planes is unbounded
            raise ValueError(f"must be in (0, 90) degrees (at 90 the cone's radius is "
                             f"infinite), got {v}")  # fmt: skip
        return v

    @field_validator("depth")
    @classmethod
    def _depth(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 0 <= v[0] < v[1]:
            raise ValueError(f"needs 0 ≤ d0 < d1, got {list(v)}")
        return v


class Points(Section):
    """Target positions from a CSV file with a header row ``x,y,z`` (more columns are
    ignored), e.g. a recorded instrument trajectory; a relative path is read from the
    config file's folder. The points are the task's sample (``n_samples`` is ignored)."""

    points: str = Field(
        description="A CSV file with a header row `x,y,z` (other columns ignored), read from the "
        "config file's folder when relative: the targets themselves (`n_samples` is "
        "ignored).",
    )
    _xyz: np.ndarray | None = None

    @model_validator(mode="after")
    def _read(self, info: ValidationInfo) -> Points:
        ctx = info.context if isinstance(info.context, dict) else {}
        p = Path(self.points)
        if not p.is_absolute() and ctx.get("config_dir") is not None:
            p = Path(ctx["config_dir"]) / p
        self._xyz = read_points(p)
        if len(self._xyz) < 2:
            raise ValueError(f"points file {p}: {len(self._xyz)} target(s); a task needs at "
                             "least 2 (every index carries a standard error)")  # fmt: skip
        self.points = str(p)
        return self

    def xyz(self) -> np.ndarray:
        if self._xyz is None:
            self._xyz = read_points(Path(self.points))
        return self._xyz


def read_points(path: Path) -> np.ndarray:
    """(N, 3) points of a CSV file with columns x, y, z; ValueError naming the file and
    the row (from 1, after the header) otherwise."""
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"points file {path}: cannot read ({e})") from None
    if not rows:
        raise ValueError(f"points file {path}: empty; needs a header row x,y,z")
    head = [c.strip() for c in rows[0]]
    missing = [c for c in ("x", "y", "z") if c not in head]
    if missing:
        raise ValueError(f"points file {path}: header has no column(s) {missing}")
    idx = [head.index(c) for c in ("x", "y", "z")]
    out = []
    for i, r in enumerate(rows[1:], start=1):
        try:
            v = [float(r[j]) for j in idx]
        except (ValueError, IndexError):
            raise ValueError(f"points file {path}: row {i}: needs three numbers x, y, z") from None
        bad = validation.first_bad(v)
        if bad is not None:
            raise ValueError(f"points file {path}: row {i}: {bad[1]}")
        out.append(v)
    if not out:
        raise ValueError(f"points file {path}: no points after the header")
    return np.asarray(out, np.float64)


def _region_kind(v: Any) -> str:
    if isinstance(v, dict):
        return "points" if "points" in v else str(v.get("shape", ""))
    return "points" if isinstance(v, Points) else getattr(v, "shape", "")


Region = Annotated[
    Union[  # noqa: UP007
        Annotated[Box, Tag("box")], Annotated[Ball, Tag("ball")],
        Annotated[Cylinder, Tag("cylinder")], Annotated[Cone, Tag("cone")],
        Annotated[Points, Tag("points")],
    ],
    Discriminator(_region_kind, custom_error_type="region",
                  custom_error_message="unknown region: give shape box, ball, cylinder or "
                                       "cone, or points: FILE"),
]  # fmt: skip


class ToolAxis(Section):
    """The tool z axis drawn uniformly in the cone of half-angle ``cone`` (degrees, in
    [0, 180]) about ``direction``; 0 fixes it."""

    direction: Vec3 = Field(
        description="The cone's axis: the mean tool z direction (a non-zero vector; normalised).",
    )
    cone: float = Field(
        0.0,
        ge=0,
        le=180,
        description="Half-angle (deg) of the cone the tool z axis is drawn in uniformly; 0 fixes "
        "it to `direction`. The roll about it is free.",
    )

    @field_validator("direction")
    @classmethod
    def _dir(cls, v: Vec3) -> Vec3:
        return _unit(v, "direction")


class Task(Section):
    """The region, and at most one of: a cone of tool directions (``tool_axis``), or a
    port (``port``: the fixed point in the body wall the instrument passes through; each
    target's tool axis is then the unit vector from the port to the target, and
    ``insertion`` = [d0, d1] bounds the tool's depth past the port, |target − port|)."""

    region: Region = Field(
        description="Where the targets lie: `{shape: box | ball | cylinder | cone, ...}` or "
        "`{points: FILE}`.",
    )
    tool_axis: ToolAxis | None = Field(
        None,
        description="An optional cone of tool directions at every target (excludes `port`).",
    )
    port: Vec3 | None = Field(
        None,
        description="[x, y, z]: the fixed point the instrument passes through; each target's tool "
        "axis is the unit vector from the port to the target (excludes `tool_axis`).",
    )
    insertion: tuple[float, float] | None = Field(
        None,
        description="[d0, d1]: the tool's allowed depth |target − port| past the port (length "
        "unit), 0 ≤ d0 < d1.",
    )

    @field_validator("port")
    @classmethod
    def _port(cls, v: Vec3 | None) -> Vec3 | None:
        if v is not None:
            bad = validation.first_bad(list(v))
            if bad is not None:
                raise ValueError(bad[1])
        return v

    @field_validator("insertion")
    @classmethod
    def _insertion(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None:
            bad = validation.first_bad(list(v))
            if bad is not None:
                raise ValueError(bad[1])
            if not 0 <= v[0] < v[1]:
                raise ValueError(f"needs 0 ≤ d0 < d1 (the depth past the port), got {list(v)}")
        return v

    @model_validator(mode="after")
    def _one_axis_rule(self) -> Task:
        if self.port is not None and self.tool_axis is not None:
            raise ValueError("port and tool_axis exclude each other: with a port, each "
                             "target's tool axis is the line from the port to the target; "
                             "remove one of them")  # fmt: skip
        return self

    def depth_range(self) -> tuple[float, float]:
        """[d0, d1] of ``insertion``, else [0, ∞)."""
        return self.insertion if self.insertion is not None else (0.0, math.inf)


# --------------------------------------------------------------------------- samples


def _frame(axis: Vec3) -> np.ndarray:
    """An orthonormal (3, 3) whose last column is ``axis`` (normalised)."""
    z = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], -1)


def _arr(x: Any, dtype: Any) -> jax.Array:
    return jnp.asarray(np.asarray(x, dtype))


def region_params(region: Any, dtype=jnp.float64) -> dict[str, jax.Array]:
    """The region's numbers as arrays (so one compiled sampler serves any values), made on
    the host (``jnp.asarray`` of a list compiles a conversion program)."""
    if isinstance(region, Box):
        return {
            "center": _arr(region.center, dtype),
            "size": _arr(region.size, dtype),
        }
    if isinstance(region, Ball):
        return {
            "center": _arr(region.center, dtype),
            "radius": _arr(region.radius, dtype),
        }
    if isinstance(region, Cylinder):
        return {
            "center": _arr(region.center, dtype),
            "frame": _arr(_frame(region.axis), dtype),
            "radius": _arr(region.radius, dtype),
            "height": _arr(region.height, dtype),
        }
    if isinstance(region, Cone):
        return {
            "apex": _arr(region.apex, dtype),
            "frame": _arr(_frame(region.axis), dtype),
            "tan": _arr(math.tan(math.radians(region.half_angle)), dtype),
            "depth": _arr(region.depth, dtype),
        }
    if isinstance(region, Points):
        return {"points": _arr(region.xyz(), dtype)}
    raise TypeError(f"unknown region {type(region).__name__}")  # fmt: skip


def sample_region(kind: str, params: dict[str, jax.Array], key: jax.Array, n: int) -> jax.Array:
    """n points uniform in the region's volume (area, length), (n, 3)."""
    dt = next(iter(params.values())).dtype
    u = jax.random.uniform(key, (n, 3), dtype=dt)
    if kind == "box":
        return params["center"] + (u - 0.5) * params["size"]
    if kind == "ball":
        g = jax.random.normal(jax.random.fold_in(key, 1), (n, 3), dtype=dt)
        d = g / jnp.linalg.norm(g, axis=-1, keepdims=True)
        return params["center"] + params["radius"] * jnp.cbrt(u[:, :1]) * d
    if kind == "cylinder":
        r = params["radius"] * jnp.sqrt(u[:, 0])
        t = 2 * jnp.pi * u[:, 1]
        h = (u[:, 2] - 0.5) * params["height"]
        local = jnp.stack([r * jnp.cos(t), r * jnp.sin(t), h], -1)
        return params["center"] + local @ params["frame"].T
    if kind == "cone":
        d0, d1 = params["depth"][0], params["depth"][1]
        s = jnp.cbrt(d0**3 + u[:, 0] * (d1**3 - d0**3))  # axial depth, density ∝ s²
        r = s * params["tan"] * jnp.sqrt(u[:, 1])
        t = 2 * jnp.pi * u[:, 2]
        local = jnp.stack([r * jnp.cos(t), r * jnp.sin(t), s], -1)
        return params["apex"] + local @ params["frame"].T
    if kind == "points":
        return params["points"]
    raise ValueError(f"unknown region kind {kind!r}")


def sample_axes(direction: Vec3, cone_deg: float, key: jax.Array, n: int, dtype=jnp.float64):
    """n unit vectors uniform on the spherical cap of half-angle ``cone_deg`` about
    ``direction`` (n, 3): cos θ uniform in [cos c, 1], azimuth uniform."""
    c = jnp.cos(jnp.radians(jnp.asarray(cone_deg, dtype)))
    return _cap(jnp.asarray(_frame(direction), dtype), c, key, n)


def _cap(frame: jax.Array, cos_c: jax.Array, key: jax.Array, n: int) -> jax.Array:
    u = jax.random.uniform(key, (n, 2), dtype=frame.dtype)
    ct = 1.0 - u[:, 0] * (1.0 - cos_c)
    st = jnp.sqrt(jnp.maximum(1.0 - ct * ct, 0.0))
    t = 2 * jnp.pi * u[:, 1]
    local = jnp.stack([st * jnp.cos(t), st * jnp.sin(t), ct], -1)
    return local @ frame.T


def region_center_radius(region: Any) -> tuple[np.ndarray, float]:
    """The centre and radius of a ball that holds the task region."""
    if isinstance(region, Box):
        return np.asarray(region.center, np.float64), float(np.linalg.norm(region.size)) / 2
    if isinstance(region, Ball):
        return np.asarray(region.center, np.float64), float(region.radius)
    if isinstance(region, Cylinder):
        return np.asarray(region.center, np.float64), math.hypot(region.radius,
                                                                 region.height / 2)  # fmt: skip
    if isinstance(region, Cone):
        a = np.asarray(region.axis, np.float64) / np.linalg.norm(region.axis)
        d0, d1 = region.depth
        c = np.asarray(region.apex, np.float64) + a * (d0 + d1) / 2
        return c, math.hypot((d1 - d0) / 2, d1 * math.tan(math.radians(region.half_angle)))
    p = np.asarray(region.xyz(), np.float64)
    lo, hi = p.min(0), p.max(0)
    return (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2


def nearest_distance(region: Any, origin: Vec3 = (0.0, 0.0, 0.0)) -> float:
    """The distance from ``origin`` (the chain's base) to the region's nearest point:
    exact for a box, ball, cylinder and points; for a cone, to the ball that bounds the
    frustum (a lower bound: the region lies in that ball)."""
    o = np.asarray(origin, np.float64)
    if isinstance(region, Box):
        gap = np.abs(o - np.asarray(region.center)) - np.asarray(region.size) / 2
        return float(np.linalg.norm(np.maximum(gap, 0.0)))
    if isinstance(region, Ball):
        return max(float(np.linalg.norm(o - np.asarray(region.center))) - region.radius, 0.0)
    if isinstance(region, Cylinder):
        a = np.asarray(region.axis, np.float64) / np.linalg.norm(region.axis)
        v = o - np.asarray(region.center)
        t = float(v @ a)
        rho = float(np.linalg.norm(v - t * a))
        return math.hypot(max(abs(t) - region.height / 2, 0.0), max(rho - region.radius, 0.0))
    if isinstance(region, Cone):
        a = np.asarray(region.axis, np.float64) / np.linalg.norm(region.axis)
        d0, d1 = region.depth
        c = np.asarray(region.apex) + a * (d0 + d1) / 2
        r = math.hypot((d1 - d0) / 2, d1 * math.tan(math.radians(region.half_angle)))
        return max(float(np.linalg.norm(o - c)) - r, 0.0)
    if isinstance(region, Points):
        return float(np.min(np.linalg.norm(region.xyz() - o, axis=-1)))
    raise TypeError(f"unknown region {type(region).__name__}")


def kind(region: Any) -> str:
    """The region's kind: box, ball, cylinder, cone or points."""
    return _region_kind(region)


def targets(task: Task, key: jax.Array, n: int, dtype=jnp.float64):
    """(positions (N, 3), tool frames (N, 3, 3) or None): the task's samples. A tool
    frame's last column is the sampled tool axis, or with a port the unit vector from the
    port to the target (its roll is arbitrary: the IK leaves it free)."""
    ax = task.tool_axis
    frame = None if ax is None else _arr(_frame(ax.direction), dtype)
    cone = None if ax is None else _arr(ax.cone, dtype)
    # one jitted call (op by op, the sampling compiled some fifteen one-op programs)
    p, R = _targets(kind(task.region), region_params(task.region, dtype), key, n, frame, cone)
    if task.port is not None:
        R = port_frames(p, jnp.asarray(task.port, dtype))
    return p, R


@jax.jit
def port_frames(p: jax.Array, port: jax.Array) -> jax.Array:
    """Tool frames (..., 3, 3) whose z axis is the unit vector from ``port`` (..., 3) to
    the target ``p`` (..., 3); a target on the port gets z = (0, 0, 1) (its depth is 0:
    outside any insertion range but [0, d1], and unreached: see ``depth``)."""
    d = p - port
    n = jnp.linalg.norm(d, axis=-1, keepdims=True)
    ok = n > 0
    z = jnp.where(ok, d / jnp.where(ok, n, 1.0), jnp.asarray([0.0, 0.0, 1.0], p.dtype))
    return _frames_of(z)


def _frames_of(z: jax.Array) -> jax.Array:
    """Orthonormal frames (..., 3, 3) whose last column is the unit vector z (..., 3)."""
    dtype = z.dtype
    a = jnp.where(
        jnp.abs(z[..., :1]) < 0.9, jnp.array([1.0, 0, 0], dtype), jnp.array([0, 1.0, 0], dtype)
    )
    x = jnp.cross(a, z)
    x = x / jnp.linalg.norm(x, axis=-1, keepdims=True)
    return jnp.stack([x, jnp.cross(z, x), z], -1)


def depths(p: np.ndarray, port: Vec3) -> np.ndarray:
    """|p − port|: the tool's depth past the port at each target (N,)."""
    return np.linalg.norm(np.asarray(p, np.float64) - np.asarray(port, np.float64), axis=-1)


def check_port(task: Task, n: int = 8192, port: Any = None,
               where: str = "task.port", insertion: tuple[float, float] | None = None,
               insertion_key: str = "task.insertion") -> None:  # fmt: skip
    """ValueError naming ``task.insertion`` when no point of the region lies at a depth
    past the port within the insertion range (checked on n samples of the region, or
    every point of a points file): then no target could ever be reached. ``port``: one
    port (3,), or the ports (D, 3) of D designs, refused when none of them leaves a
    target in range (else ``task.port``). ``insertion`` (named ``insertion_key``): an
    arm's own range, else ``task.insertion``."""
    port = task.port if port is None else port
    if port is None:
        return
    ports = np.asarray(port, np.float64).reshape(-1, 3)
    if isinstance(task.region, Points):
        p = task.region.xyz()
    else:
        dt = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
        p = np.asarray(_targets(kind(task.region), region_params(task.region, dt),
                                jax.random.key(0), n, None, None)[0], np.float64)  # fmt: skip
    d = np.linalg.norm(p[None] - ports[:, None], axis=-1)  # (D, N)
    ins = task.insertion if insertion is None else insertion
    d0, d1 = (0.0, math.inf) if ins is None else ins
    if not np.any((d >= d0) & (d <= d1) & (d > 0)):
        key = insertion_key if ins is not None else where
        at = f"port {[float(f'{v:.6g}') + 0.0 for v in ports[0]]} ({where})" if len(ports) == 1 \
            else f"ports of {len(ports)} designs across the box ({where})"  # fmt: skip
        raise ValueError(
            f"{key}: no target of the region lies at a depth in [{d0:g}, {d1:g}] past the "
            f"{at}: the region's depths run from {d.min():.4g} to "
            f"{d.max():.4g} (the chain's length unit); move the port or widen the insertion"
        )


@partial(jax.jit, static_argnames=("region_kind", "n"))
def _targets(region_kind: str, rparams: dict[str, jax.Array], key: jax.Array, n: int,
             frame: jax.Array | None, cone: jax.Array | None):  # fmt: skip
    k_p, k_a = jax.random.split(key)
    p = sample_region(region_kind, rparams, k_p, n)
    if frame is None:
        return p, None
    return p, _frames_of(_cap(frame, jnp.cos(jnp.radians(cone)), k_a, p.shape[0]))
