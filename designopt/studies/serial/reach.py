"""Whether a serial study's results can mean anything: before optimising, a task region
that no design in the box can reach is refused (the reach of every design is bounded by
the sum of its link lengths along the chain, ``SerialModel.reach_bound``); after, the
final design's reach and index constraints are compared with what was asked, and what is
far off is said (``Study.warnings``)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from designopt.kinematics import collision as col
from designopt.kinematics import task as tk
from designopt.kinematics.urdf import rpy_matrix
from designopt.studies.serial import plancheck
from designopt.studies.serial.mechanism import build
from designopt.studies.serial.placement import entry_range, ports_of
from designopt.studies.serial.settings import SerialSettings, length_unit

REACH_WARNING = 0.95
"""A task run whose best design reaches a smaller share of its targets is warned about,
with or without a reach constraint."""
Z = 2.0
"""An index constraint is missed when the final value is beyond its bound by more than Z
standard errors (a miss within the Monte-Carlo noise is not called one)."""


def largest_reach(s: SerialSettings) -> float:
    """An upper bound of the tip's distance from the base over every design in the box
    and every configuration in the joint limits (the chain's length unit)."""
    mech = build(s)
    lo, hi = s.box()[1:]
    fixed = np.asarray(mech.fixed, np.float64)
    x_lo = np.concatenate([lo, fixed]) * mech.scale
    x_hi = np.concatenate([hi, fixed]) * mech.scale
    return mech.model.reach_bound(x_lo, x_hi, mech.lower, mech.upper)


def check(s: SerialSettings) -> None:
    """ValueError naming ``task.region`` when no design in the box can reach any point of
    the task region (with ``arms``: when some arm cannot, wherever the design box puts
    its base). A run's search settings (``optimizer.fidelity``: other IK settings, other
    samples) are checked once with the study's: what is checked reads neither."""
    if s.task is None:
        return
    d = s.model_dump(mode="json")
    d.pop("indices", None)
    d["task"].pop("ik", None)
    key = json.dumps(d, sort_keys=True, default=str)
    if key in _PASSED:
        return
    _check(s)
    while len(_PASSED) >= 16:
        _PASSED.pop(next(iter(_PASSED)))
    _PASSED[key] = None


_PASSED: dict[str, None] = {}  # the settings (without the IK's and the indices') checked


def _check(s: SerialSettings) -> None:
    if s.collision is not None:  # the meshes' grids, built beside the checks' compiles
        col.prefetch_grids(s.collision.obstacles)
    _check_reach(s)  # first: a region out of reach is the cause, whatever the ports say
    plancheck.check(s)  # a unit slip is named before _check_ports finds a port off the wall
    _check_ports(s)
    if s.collision is not None:
        from designopt.studies.serial import bodies, setup

        for g in setup.groups(s):  # each robot's arms (the study itself for one robot)
            bodies.check(g.settings, g.mech, g.arms)


def _check_reach(s: SerialSettings) -> None:
    """ValueError naming ``task.region`` when no design (some arm in no design) reaches
    any point of the task region (:func:`check`)."""
    from designopt.studies.serial import setup

    u = length_unit(s)
    far = largest_reach(s)
    if s.arms is not None:
        for k in range(len(s.arms)):
            far = largest_reach(setup.arm_view(s, k))  # its own robot's
            lo, hi = base_range(s, k)
            near = region_box_distance(s.task.region, lo, hi)
            if near > far * (1 + 1e-9) + 1e-12:
                where = ", ".join(f"{c} in [{a:.4g}, {b:.4g}]" if a < b else f"{c} = {a:.4g}"
                                  for c, a, b in zip("xyz", lo, hi, strict=True))  # fmt: skip
                raise ValueError(
                    f"task.region: arm {k} reaches no point of the task region in any "
                    f"design: its nearest point is {near:.4g} {u} from where the design "
                    f"box puts the arm's base ({where} {u}), and the longest design "
                    f"reaches at most {far:.4g} {u} (the sum of its link lengths along the "
                    "chain); check the region's position, the arms' bases and the chain's "
                    "length unit"
                )
        return
    near = tk.nearest_distance(s.task.region)
    if near > far * (1 + 1e-9) + 1e-12:
        raise ValueError(
            f"task.region: no design in the box reaches the task region: its nearest point "
            f"is {near:.4g} {u} from the base, and the longest design reaches at most "
            f"{far:.4g} {u} (the sum of its link lengths along the chain); check the "
            f"region's position and the chain's length unit"
        )


def base_range(s: SerialSettings, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(lower (3,), upper (3,)): the box that arm ``k``'s base origin stays in over the
    design box (each ``xyz`` entry's own range; the chain's length unit)."""
    r = [entry_range(s, v) for v in s.arms[k].base.xyz]  # type: ignore[index]
    return np.array([a for a, _ in r]), np.array([b for _, b in r])


def _fibonacci(n: int) -> np.ndarray:
    """n nearly uniform unit vectors (n, 3) (the Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5**0.5) * i
    rho = np.sqrt(1 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], -1)


def _support_min(region: Any, n: np.ndarray) -> np.ndarray:
    """min over the region of n·p for unit vectors n (K, 3) (a convex region's support
    function at −n, negated)."""
    if isinstance(region, tk.Box):
        return n @ np.asarray(region.center) - np.abs(n) @ (np.asarray(region.size) / 2)
    if isinstance(region, tk.Ball):
        return n @ np.asarray(region.center) - region.radius
    a = np.asarray(getattr(region, "axis", (0.0, 0.0, 1.0)), np.float64)
    a = a / np.linalg.norm(a)
    an = n @ a
    side = np.sqrt(np.maximum(1 - an * an, 0.0))
    if isinstance(region, tk.Cylinder):
        return n @ np.asarray(region.center) - region.height / 2 * np.abs(an) - region.radius * side
    if isinstance(region, tk.Cone):  # the frustum is the convex hull of its two end disks
        tan = np.tan(np.radians(region.half_angle))
        return np.min([n @ (np.asarray(region.apex) + d * a) - d * tan * side
                       for d in region.depth], 0)  # fmt: skip
    raise TypeError(f"unknown region {type(region).__name__}")


def region_box_distance(region: Any, lo: np.ndarray, hi: np.ndarray) -> float:
    """A lower bound of the distance between the task region and the axis-aligned box
    [lo, hi] (where an arm's base can be), exact for a points file and, for the convex
    regions, to the resolution of a search over directions: for every unit n,
    min_region n·p − max_box n·o is at most the distance (a separating plane), with
    equality at the best n; the best of 4,096 directions, refined three times."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    if isinstance(region, tk.Points):
        gap = np.maximum(np.abs(region.xyz() - c) - h, 0.0)
        return float(np.min(np.linalg.norm(gap, axis=-1)))

    def gap(n: np.ndarray) -> np.ndarray:
        return _support_min(region, n) - (n @ c + np.abs(n) @ h)

    n = _fibonacci(4096)
    g = gap(n)
    best, val = n[np.argmax(g)], float(np.max(g))
    rng = np.random.default_rng(0)
    for spread in (0.05, 0.005, 0.0005):  # rad: about the lattice's spacing, then finer
        m = best + spread * rng.normal(size=(512, 3))
        m /= np.linalg.norm(m, axis=-1, keepdims=True)
        gm = gap(m)
        if gm.max() > val:
            best, val = m[np.argmax(gm)], float(gm.max())
    return max(val, 0.0)


def _base_shapes(s: SerialSettings) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The base link's capsules (a, b, r) in the base frame, for the port-in-base check:
    the base origin (radius: the smallest configured radius under ``links: auto``, 0
    without ``collision``) and, under ``links: urdf``, every <collision> shape of the
    URDF's base link."""
    zero = np.zeros(3)
    c = s.collision
    if c is None:
        return [(zero, zero, 0.0)]
    if c.links != "urdf":
        r = min(c.radius) if isinstance(c.radius, list) else c.radius
        return [(zero, zero, float(r or 0.0))]
    from designopt.studies.serial import bodies

    g = bodies.geometry(s, build(s))
    imp = s.chain.imported  # type: ignore[union-attr]
    caps = [] if g is None or g.urdf is None else g.urdf[2]
    return [(zero, zero, 0.0)] + [(np.asarray(k.a, np.float64), np.asarray(k.b, np.float64),
                                   float(k.radius)) for k in caps if k.link == imp.base]  # fmt: skip


def _seg_point(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    dd = float(d @ d)
    t = 0.0 if dd == 0 else float(np.clip((p - a) @ d / dd, 0.0, 1.0))
    return float(np.linalg.norm(p - a - t * d))


PORT_DESIGNS = 64
"""Random designs (beside the middle and the corners of the ports' variables) over which
a port that the design moves is checked before a run."""
WALL_TOL = 1e-6
"""A port given as numbers lies on ``task.body_wall`` when within this share of the
wall's size (an ellipsoid's largest semi-axis, or 1 for a plane; a mesh wall's bounding-box
diagonal) of its surface."""


def port_designs(s: SerialSettings) -> list[dict[str, float] | None]:
    """The designs a port check runs over: None (the middle of the box) alone when no
    port entry names a variable; else the middle, the corners of the box of the
    variables the ports name (at most 64 of them) and :data:`PORT_DESIGNS` random
    designs (a fixed seed), the other variables at their middle."""
    if not s.designed_ports():
        return [None]
    names = sorted({v.removeprefix("-") for p in s.ports() if p is not None for v in p
                    if isinstance(v, str) and v.removeprefix("-") in s.variables})  # fmt: skip
    mid = {k: (float(lo) + float(hi)) / 2 for k, (lo, hi) in s.variables.items()}
    lo = np.array([float(s.variables[k][0]) for k in names])
    hi = np.array([float(s.variables[k][1]) for k in names])
    corners = np.array(np.meshgrid(*[[0.0, 1.0]] * len(names))).reshape(len(names), -1).T \
        if len(names) <= 6 else np.zeros((0, len(names)))  # fmt: skip
    u = np.concatenate([corners, np.random.default_rng(0).uniform(size=(PORT_DESIGNS, len(names)))])
    return [mid] + [mid | dict(zip(names, (lo + w * (hi - lo)).tolist(), strict=True)) for w in u]


def _check_ports(s: SerialSettings) -> None:
    """ValueError when a port given as numbers lies off ``task.body_wall``, when no
    design in the box (:func:`port_designs`) has its port leave a target within the
    insertion range, or when every such design puts the port on an arm's base (inside
    its base link: within a capsule radius of the base origin under ``links: auto``,
    inside a <collision> shape's capsule of the URDF's base link under ``links: urdf``,
    at the origin without collision capsules)."""
    shapes = None
    designs = port_designs(s)
    for k, entries in enumerate(s.ports()):
        if entries is None or k == s.camera_arm():  # the camera arm's is task.camera's
            continue
        arm = None if s.arms is None else s.arms[k]
        where = "task.port" if arm is None or arm.port is None else f"arms.{k}.port"
        ports = ports_of(s, k, designs)
        _on_wall(s, entries, ports[0], where)
        ins = getattr(arm, "insertion", None)
        kw = {} if ins is None else {"insertion": ins, "insertion_key": f"arms.{k}.insertion"}
        tk.check_port(s.task, port=ports, where=where, **kw)  # type: ignore[arg-type]
        xyz = (0.0, 0.0, 0.0) if arm is None else arm.base.xyz
        rpy = (0.0, 0.0, 0.0) if arm is None else arm.base.rpy
        if not all(isinstance(v, float | int) for v in (*xyz, *rpy)):
            continue  # a designed base: wherever the design puts it
        if shapes is None or s.arms is not None:
            from designopt.studies.serial import setup

            shapes = _base_shapes(setup.arm_view(s, k))  # its own robot's base link
        R = rpy_matrix(*(math.radians(float(v)) for v in rpy))
        t = np.asarray(xyz, np.float64)
        dist = [(np.array([_seg_point(p, R @ a + t, R @ b + t) for p in ports]), a, b, r)
                for a, b, r in shapes]  # fmt: skip
        hit = [(d <= max(r, 1e-9), a, b, r) for d, a, b, r in dist]
        if not np.all(np.any([h for h, *_ in hit], axis=0)):
            continue  # some design puts the port outside the base
        _, a, b, r = next(x for x in hit if x[0][0])
        p = ports[0]
        what = "" if r == 0 or not np.any(a) and not np.any(b) else \
            f" (a <collision> shape of its URDF base link, radius {r:.3g})"  # fmt: skip
        every = " in every design of the box" if len(ports) > 1 else ""
        raise ValueError(
            f"{where}: the port {_fmt(p)} lies inside the arm's base link{what}{every} "
            f"({float(np.linalg.norm(p - t)):.3g} from its base origin); the "
            "instrument must enter the body away from the base"
        )


def _fmt(p: Any) -> list[float]:
    return [float(f"{v:.6g}") + 0.0 for v in np.asarray(p, np.float64)]


def _on_wall(s: SerialSettings, entries: Any, projected: np.ndarray, where: str) -> None:
    """ValueError naming ``where`` when a port of numbers lies off ``task.body_wall``
    (by more than :data:`WALL_TOL` of the wall's size): a port the design moves is
    projected onto the wall, a port of numbers is taken as given."""
    wall = s.task.body_wall  # type: ignore[union-attr]
    if wall is None or any(isinstance(v, str) for v in entries):
        return
    p = np.asarray(entries, np.float64)
    if wall.shape == "mesh":  # the projection is exact (wall.mesh_closest): the mesh's size
        tri = wall.triangles()[0].reshape(-1, 3)
        tol = WALL_TOL * float(np.linalg.norm(tri.max(0) - tri.min(0)))
    else:
        tol = WALL_TOL * (max(wall.radii) if wall.shape == "ellipsoid" else 1.0)
    off = float(np.linalg.norm(p - projected))
    if off > tol:
        raise ValueError(
            f"{where}: the port {_fmt(p)} lies {off:.4g} {length_unit(s)} off task.body_wall "
            f"(its nearest point on the wall is {_fmt(projected)}); give a point on the "
            "wall, or design variables (a designed port is projected onto the wall)"
        )


def _num(final: Mapping[str, Any], k: str) -> float | None:
    """final[k] as a float (NaN kept), None when absent or not a number."""
    if k not in final:
        return None
    try:
        return float(np.asarray(final[k], np.float64).reshape(-1)[0])
    except (TypeError, ValueError, IndexError):
        return None


def _n_min() -> int:
    """The least denominator of a reported ratio index (``taskindex.N_MIN``, 30)."""
    from designopt.studies.serial import taskindex

    return int(getattr(taskindex, "N_MIN", 30))


def _counts(final: Mapping[str, Any], k: str, what: str, of_default: int | None) -> str:
    """``k of N <what>`` from the archived counts ``<k>_n`` / ``<k>_of`` where present."""
    n, of = _num(final, f"{k}_n"), _num(final, f"{k}_of")
    of = of if of is not None and math.isfinite(of) else of_default
    if n is None or not math.isfinite(n):
        return f"fewer than {_n_min()} {what}"
    return f"{n:.0f} of {of:.0f} {what}" if of is not None else f"{n:.0f} {what}"


def _design(s: SerialSettings, final: Mapping[str, Any]) -> dict[str, float] | None:
    """The final design's variables (config units) from ``final["x"]`` (in ``variables``
    order) or from entries named like the variables; None when neither is there."""
    names = list(s.variables)
    x = final.get("x")
    if x is not None:
        v = np.asarray(x, np.float64).reshape(-1)
        if len(v) == len(names):
            return dict(zip(names, (float(a) for a in v), strict=True))
    if all(_num(final, k) is not None for k in names):
        return {k: _num(final, k) for k in names}  # type: ignore[misc]
    return None


def _bases(s: SerialSettings, x: Mapping[str, float] | None) -> list[np.ndarray] | None:
    """Every arm's base origin at design ``x`` (None when an entry needs a variable and
    ``x`` is None)."""
    out = []
    for a in s.arms or []:
        p = []
        for v in a.base.xyz:
            if not isinstance(v, str):
                p.append(float(v))
                continue
            name = v.removeprefix("-")
            if name in s.fixed:
                w = float(s.fixed[name])
            elif x is not None and name in x:
                w = float(x[name])
            else:
                return None
            p.append(-w if v.startswith("-") else w)
        out.append(np.asarray(p) + 0.0)  # no -0
    return out


def warnings(s: SerialSettings, final: Mapping[str, Any]) -> list[str]:
    """What is far from what was asked in the final design's results: a task region
    reached at less than :data:`REACH_WARNING`, an index constraint missed by more than
    :data:`Z` standard errors; under ``collision`` and ``arms``: arms standing on one
    base, a design where every target or tuple collides (``collision_free``,
    ``arms_free`` or ``arms_ok`` 0 while something converged or was reached), and a
    ratio index that is n/a (its denominator under ``taskindex.N_MIN``). NaN values and
    missing keys are tolerated (a line is only said where its numbers are there)."""
    out = []

    def val(k: str) -> tuple[float, float]:
        v, se = _num(final, k), _num(final, k + "_se")
        return (math.nan if v is None else v), (0.0 if se is None else se)

    asked_reach = None
    for c in s.index_constraints():
        if c.index not in final:
            continue
        v, se = val(c.index)
        if c.index == "reach" and c.ge is not None:
            asked_reach = c.ge
        if not math.isfinite(v):
            continue  # n/a: said below
        if c.ge is not None and v < c.ge - Z * se:
            out.append(f"{c.index} = {v:.4g} ± {se:.2g}, asked ≥ {c.ge:g}: the constraint is "
                       "missed by this design")  # fmt: skip
        elif c.le is not None and v > c.le + Z * se:
            out.append(f"{c.index} = {v:.4g} ± {se:.2g}, asked ≤ {c.le:g}: the constraint is "
                       "missed by this design")  # fmt: skip
    if s.indices.measure == "task" and "reach" in final and asked_reach is None:
        v, se = val("reach")
        if math.isfinite(v) and v < REACH_WARNING:
            out.append(f"reach = {v:.3g} ± {se:.2g}: this design reaches "
                       f"{100 * v:.0f} % of the task region's targets (gci and the other "
                       "task indices count an unreached target as 0)")  # fmt: skip
    if s.arms is not None:
        out += _arm_warnings(s, final)
    if s.collision is not None:
        v = _num(final, "collision_free")
        if v is not None and math.isnan(v):
            k = _counts(final, "collision_free", "targets where the IK converged", None)
            out.append(f"collision_free: n/a ({k}; under {_n_min()}): too few to say what "
                       "share of them is free of collisions")  # fmt: skip
        elif v is not None and v == 0:
            out.append("collision_free = 0: at every target where the IK converged, its "
                       "solutions collide (clearance below the margin): no target is "
                       "reached; check the obstacles, the margin and the capsules "
                       "(designopt chain lists the pairs)")  # fmt: skip
    na = [k for k in s.weights() if (v := _num(final, k)) is not None and math.isnan(v)]
    if na:  # f is then a search value: the worst end of each n/a term's range
        out.append(f"f: its term(s) {', '.join(na)} n/a; f counts each at the worst end of "
                   "its range (the value a search ranks it by), not an estimate")  # fmt: skip
    return out + plancheck.warnings(s, final)  # incisions too close; targets in the anatomy


def _arm_warnings(s: SerialSettings, final: Mapping[str, Any]) -> list[str]:
    """Arms on one base; every tuple colliding; ``arms_free`` or ``instrument_angle`` n/a."""
    out = []
    bases = _bases(s, _design(s, final))
    if bases is not None:
        scale = max(1.0, *(float(np.abs(b).max()) for b in bases))
        same = [(i, j) for i in range(len(bases)) for j in range(i + 1, len(bases))
                if np.linalg.norm(bases[i] - bases[j]) <= 1e-9 * scale]  # fmt: skip
        u = length_unit(s)
        if same and len(same) == len(bases) * (len(bases) - 1) // 2:
            p = ", ".join(f"{v:.4g}" for v in bases[0])
            out.append(f"arms: every arm's base is at ({p}) {u} in the final design: the arms "
                       "stand on one base, inside one another")  # fmt: skip
        else:
            for i, j in same:
                p = ", ".join(f"{v:.4g}" for v in bases[i])
                out.append(f"arms: arms {i} and {j} stand on one base, both at ({p}) {u} in "
                           "the final design")  # fmt: skip
    reach_all = _num(final, "reach_all")
    free, ok = _num(final, "arms_free"), _num(final, "arms_ok")
    if free is not None and math.isnan(free):
        k = _counts(final, "arms_free", "tuples reached by every arm", None)
        out.append(f"arms_free: n/a ({k}; under {_n_min()}): too few to say what share of "
                   "them keeps the arms apart")  # fmt: skip
    ang = _num(final, "instrument_angle")
    if ang is not None and math.isnan(ang):
        k = _counts(final, "instrument_angle", "tuples reached by every arm", None)
        out.append(f"instrument_angle: n/a ({k}; under {_n_min()}): too few to say at what "
                   "angle the instruments meet")  # fmt: skip
    zero = "arms_free" if free is not None and free == 0 else \
        "arms_ok" if ok is not None and ok == 0 and (reach_all or 0) > 0 else None  # fmt: skip
    if zero is not None:
        out.append(f"{zero} = 0: in every tuple of targets that every arm reaches, the arms "
                   "touch (closer than the margin): the arms cannot work together in this "
                   "design")  # fmt: skip
    return out
