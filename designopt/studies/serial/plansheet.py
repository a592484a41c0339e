"""The plan sheet (``plan.png``, docs/figures.md): a planning run's layout as a surgical
team reads it. The patient from above (x, y) and from the side (x or y, whichever
separates the incisions more, against z), in the patient's frame (the world) and in mm:
the body wall's outline (an ellipsoid's section, a mesh's silhouette, a plane's trace),
the anatomy (the obstacles ``inside`` the patient) and the task region, each incision
point (the port on the body wall, as the archive holds it: ``final/ports``, or one
front design's ``front/ports``) marked and labelled with its coordinates, the arms'
bases (an arrow at the view's edge where a base lies outside it: the view is zoomed on
the patient), the camera's incision point ``C`` and its scope to the tip
(``task.camera``), a dimension line between every pair of incisions (their distance in 3-D)
and the lines from the incisions to the task region's centre with the angle between
them. Under the drawing a table: each arm's incision point, how far the projection
onto the wall moved it, its base; then the distances, the instruments' angle as the
study measures it (the index ``instrument_angle``: the mean angle between arm 0's and
arm 1's tool axes over the target tuples both reach, ``taskindex.instrument_angles``)
and the index constraints with their verdicts.

:func:`plan_of` computes the numbers (:class:`Plan`), :func:`draw` the figure; tests
read both."""

from __future__ import annotations

import itertools
import math
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from designopt.figures import robot, save
from designopt.figures.canvas import plt
from designopt.studies.serial.drawing import ARM_COLOURS
from designopt.studies.serial.placement import placement
from designopt.studies.serial.settings import SerialSettings, length_unit

SKIN = "#fde0d2"  # the body wall's fill (opaque: a mesh's triangles do not add up)
SKIN_EDGE = "#d6604d"
LINE = "0.25"  # the lines from the incisions to the task's centre
CAMERA = "#238b45"  # the camera port and the scope
FONT = 9.0
VIEW_W, VIEW_H = 5.3, 5.0  # inches: each view's box


@dataclass
class Plan:
    """A plan's numbers, in the chain's length unit (``unit``; ``shown``: the unit the
    sheet prints, ``factor`` from one to the other): incision points ``ports`` (A, 3), the
    design's points before the projection onto the wall ``port_points`` (or None),
    ``bases`` (A, 6: x, y, z, roll, pitch, yaw in degrees) or None, ``distances``
    [(i, j, |p_i − p_j|)], ``line_angle`` the angle (deg) between the lines from
    incisions 0 and 1 to the region's centre (None: one port, or no region),
    ``angle`` the index ``instrument_angle`` (value, SE) in deg (None where not
    archived), ``band`` ``task.instrument_angle``, ``rows`` more (label, text) lines,
    ``camera`` the endoscope's incision point and tip (6,) or None, ``robots`` each arm's
    robot where the arms are different robots (``setup.robot_name``), ``arms`` the arm
    index of each row of ``ports`` (a camera arm, which goes through C, has no row)."""

    unit: str
    shown: str
    factor: float
    ports: np.ndarray
    port_points: np.ndarray | None = None
    bases: np.ndarray | None = None
    distances: list[tuple[int, int, float]] = field(default_factory=list)
    centre: np.ndarray | None = None
    line_angle: float | None = None
    angle: tuple[float, float | None] | None = None
    band: tuple[float, float] | None = None
    rows: list[str] = field(default_factory=list)
    camera: np.ndarray | None = None  # (6,): the endoscope's incision point and its tip
    robots: tuple[str, ...] = ()  # each arm's robot, where the arms are different robots
    arms: tuple[int, ...] = ()  # the arm of each row of ``ports`` (empty: row k is arm k)


def display_unit(unit: str) -> tuple[str, float]:
    """(unit printed, factor from the chain's unit): mm for a chain in m or mm."""
    return {"m": ("mm", 1000.0), "mm": ("mm", 1.0), "cm": ("mm", 10.0)}.get(unit, (unit, 1.0))


def region_centre(region: Any) -> np.ndarray | None:
    """The task region's centre: a box's, ball's or cylinder's centre, a cone's point
    at its mid depth; None for a points file."""
    if region is None:
        return None
    if hasattr(region, "center"):
        return np.asarray(region.center, np.float64)
    if hasattr(region, "apex"):
        ax = np.asarray(region.axis, np.float64)
        return np.asarray(region.apex, np.float64) + 0.5 * sum(region.depth) * ax / np.linalg.norm(
            ax
        )
    wire = robot.region_wire(region)
    return np.vstack(wire).mean(0) if wire else None


def _angle(u: np.ndarray, v: np.ndarray) -> float:
    c = float(u @ v / (np.linalg.norm(u) * np.linalg.norm(v)))
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def _fmt(v: Any, f: float, d: int = 1) -> str:
    return "(" + ", ".join(f"{float(c) * f + 0.0:.{d}f}" for c in v) + ")"


def plan_of(s: SerialSettings, g: Mapping[str, Any],
            indices: Mapping[str, tuple[float, float | None]] | None = None,
            objectives: Sequence[str] = ()) -> Plan:  # fmt: skip
    """The plan's numbers from archived placement values ``g`` (a final group, or one
    front design's values: ``ports`` (A, 3), ``port_points``, ``bases`` (A, 6)), the
    design's indices {name: (value, SE)} and the names of the run's objectives (their
    values are quoted)."""
    unit = length_unit(s)
    shown, f = display_unit(unit)
    ports = np.asarray(g["ports"], np.float64).reshape(-1, 3)
    pp = np.asarray(g["port_points"], np.float64).reshape(-1, 3) if "port_points" in g else None
    bases = np.asarray(g["bases"], np.float64).reshape(-1, 6) if "bases" in g else None
    holder = s.camera_arm()
    held = None  # the camera arm's base: a text row (its incision point is the camera's, C)
    if holder is not None and len(ports) == len(s.arms or ()):
        keep = np.asarray(s.instrument_arms())
        held = None if bases is None else bases[holder]
        ports, bases = ports[keep], None if bases is None else bases[keep]
        pp = None if pp is None else pp[keep]
    dist = [(i, j, float(np.linalg.norm(ports[i] - ports[j])))
            for i, j in itertools.combinations(range(len(ports)), 2)]  # fmt: skip
    c = region_centre(s.task.region if s.task is not None else None)
    la = None
    if c is not None and len(ports) >= 2 and min(np.linalg.norm(ports[:2] - c, axis=1)) > 0:
        la = _angle(ports[0] - c, ports[1] - c)
    ind = dict(indices or {})
    ang = ind.get("instrument_angle")
    ang = None if ang is None or not np.isfinite(ang[0]) else (float(ang[0]), ang[1])
    band = s.task.instrument_angle if s.task is not None else None
    plan = Plan(unit, shown, f, ports, pp, bases, dist, c, la, ang,
                None if band is None else (float(band[0]), float(band[1])))  # fmt: skip
    if holder is not None and len(ports) == len(s.instrument_arms()):
        plan.arms = tuple(s.instrument_arms())
    if "camera" in g:
        plan.camera = np.asarray(g["camera"], np.float64).reshape(6)
    from designopt.studies.serial import setup

    if setup.mixed(s):
        plan.robots = tuple(setup.robot_name(s, k) for k in range(setup.n_arms(s))
                            if k != holder)  # fmt: skip
    plan.rows = _rows(s, plan, ind, objectives)
    if plan.robots:  # which arm is which robot (the table's rows are the arms)
        plan.rows.insert(0, "robots: " + ", ".join(
            f"arm {k} (P{j}) {r}" for j, (k, r) in enumerate(zip(s.instrument_arms(), plan.robots,
                                                                  strict=False))))  # fmt: skip
    if holder is not None:  # the arm that holds the scope through C
        at = "" if held is None else (f", base {_fmt(held[:3], f)} {shown}, "
                                      f"yaw {held[5]:.1f} deg")  # fmt: skip
        plan.rows.insert(0 + bool(plan.robots), f"camera arm: arm {holder} "
                         f"({setup.robot_name(s, holder)}) holds the scope through C{at}")  # fmt: skip
    return plan


def _pm(v: tuple[float, float | None], d: int = 3) -> str:
    se = v[1]
    return f"{v[0]:.{d}f}" + ("" if se is None or not np.isfinite(se) else f" ± {se:.{d}f}")


def _rows(s: SerialSettings, p: Plan, ind: Mapping[str, tuple[float, float | None]],
          objectives: Sequence[str] = ()) -> list[str]:  # fmt: skip
    """The text rows under the table: distances, the angles, the objectives' indices and
    the index constraints' verdicts."""
    u, f = p.shown, p.factor
    out = []
    if p.distances:
        out.append("distance between incision points (3-D): " + ", ".join(
            f"P{i}–P{j} {d * f:.1f} {u}" for i, j, d in p.distances))  # fmt: skip
    if p.camera is not None:
        inc, tip = p.camera[:3], p.camera[3:]
        near = ", ".join(f"P{k} {np.linalg.norm(inc - q) * f:.1f} {u}" for k, q in enumerate(p.ports))
        seen = f"; it sees {_pm(ind['view_ok'])} of the targets (view_ok)" if "view_ok" in ind \
            else ""  # fmt: skip
        out.append(f"camera C: its tip at {_fmt(tip, f)} {u}, {np.linalg.norm(tip - inc) * f:.1f} "
                   f"{u} past its incision; from C to {near}{seen}")  # fmt: skip
    ang = []
    if p.angle is not None:
        a, se = p.angle
        band = f", asked {p.band[0]:g}–{p.band[1]:g} deg" if p.band is not None else ""
        ang.append(f"instruments' angle (the index instrument_angle: mean angle between the "
                   f"two tool axes over the target tuples both arms reach) {a:.1f}"
                   + ("" if se is None or not np.isfinite(se) else f" ± {se:.1f}")
                   + f" deg{band}")  # fmt: skip
    elif "instrument_angle" in ind:  # archived, but n/a: too few tuples to average over
        from designopt.studies.serial.taskindex import N_MIN

        n, of = (ind.get(f"instrument_angle_{k}", (None, None))[0] for k in ("n", "of"))
        cnt = f" ({n:.0f} of {of:.0f})" if n is not None and of is not None else ""
        ang.append(f"instruments' angle (the index instrument_angle): n/a, fewer than {N_MIN} "
                   f"target tuples both arms reach{cnt}")  # fmt: skip
    if p.line_angle is not None:
        ang.append(f"between the lines from P0 and P1 to the task's centre {p.line_angle:.1f} deg")
    if ang:
        out.append("; ".join(ang))
    names = [c.index for c in s.index_constraints()]
    shown = [k for k in dict.fromkeys([*objectives, *names]) if k in ind]
    if shown:
        out.append("indices (± SE): " + ", ".join(f"{k} {_pm(ind[k])}" for k in shown))
    for c in s.index_constraints():
        if c.index not in ind or not np.isfinite(ind[c.index][0]):
            continue
        v = ind[c.index][0]
        ok = (c.ge is None or v >= c.ge) and (c.le is None or v <= c.le)
        bound = " and ".join(x for x in (f"≥ {c.ge:g}" if c.ge is not None else "",
                                         f"≤ {c.le:g}" if c.le is not None else "") if x)  # fmt: skip
        out.append(f"constraint {c.index} {bound}: {v:.3f}, {'met' if ok else 'NOT MET'}")
    return out


# ------------------------------------------------------------------------ drawing


def _views(ports: np.ndarray) -> list[tuple[str, np.ndarray, tuple[str, str]]]:
    """(title, E (3, 2), axis names): the top view and the side view (x or y, whichever
    separates the incisions more, against z)."""
    side = 0 if np.ptp(ports[:, 0]) >= np.ptp(ports[:, 1]) else 1
    e = np.eye(3)
    return [("from above (x, y)", e[:, [0, 1]], ("x", "y")),
            (f"from the side ({'xy'[side]}, z)", e[:, [side, 2]], ("xy"[side], "z"))]  # fmt: skip


def _wall_points(wall: Any) -> np.ndarray:
    """Points that bound the body wall (none for a plane)."""
    if wall is None or wall.shape == "halfspace":
        return np.zeros((0, 3))
    return robot.obstacle_mesh(wall, np.zeros(3), 1.0)[0]


def _patient(s: SerialSettings, ports: np.ndarray) -> np.ndarray:
    """Every point the view must hold: the body wall, the anatomy, the region, the
    incisions."""
    wall = s.task.body_wall if s.task is not None else None
    pts = [ports, _wall_points(wall)]
    pts += [robot.obstacle_mesh(ob, np.zeros(3), 1.0)[0] for ob in _anatomy(s)]
    pts += robot.region_wire(s.task.region if s.task is not None else None)
    return np.vstack([p for p in pts if len(p)])


def _anatomy(s: SerialSettings) -> list[Any]:
    obs = s.collision.obstacles if s.collision is not None else []
    return [ob for ob in obs if getattr(ob, "inside", False)]


def _draw_wall(ax: Any, wall: Any, E: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> str:
    """The body wall in the view of E: an ellipsoid's section outline (filled), a
    mesh's silhouette (its projected triangles, filled), a plane's trace; returns what
    the legend calls it ("" when nothing is drawn: a plane seen face-on)."""
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Ellipse

    if wall is None:
        return ""
    if wall.shape == "ellipsoid":
        c, r = np.asarray(wall.center, np.float64), np.asarray(wall.radii, np.float64)
        k = [int(np.argmax(np.abs(E[:, j]))) for j in range(2)]
        ax.add_patch(Ellipse(tuple(c @ E), 2 * r[k[0]], 2 * r[k[1]], fc=SKIN, ec=SKIN_EDGE,
                             lw=1.6, zorder=0.5))  # fmt: skip
        return "body wall (ellipsoid section)"
    if wall.shape == "halfspace":
        n = np.asarray(wall.normal, np.float64) / np.linalg.norm(wall.normal)
        n2 = n @ E
        if np.linalg.norm(n2) < 0.3:
            return ""
        n2 /= np.linalg.norm(n2)
        t2 = np.array([-n2[1], n2[0]])
        c2 = np.asarray(wall.point, np.float64) @ E
        h = 10 * float(np.max(hi - lo))
        ax.plot(*np.stack([c2 - h * t2, c2 + h * t2]).T, color=SKIN_EDGE, lw=1.8, zorder=0.6)
        return "body wall (plane)"
    V, F = robot.obstacle_mesh(wall, np.zeros(3), 1.0)
    ax.add_collection(PolyCollection((V @ E)[F], facecolors=SKIN, edgecolors="none",
                                     zorder=0.5), autolim=False)  # fmt: skip
    H = robot.hull_2d(V @ E)
    ax.plot(*np.vstack([H, H[:1]]).T, color=SKIN_EDGE, lw=0.8, ls=":", zorder=0.6)
    return "body wall (mesh silhouette; dotted: its hull)"


def _draw_anatomy(ax: Any, s: SerialSettings, E: np.ndarray) -> None:
    from matplotlib.patches import Polygon

    for ob in _anatomy(s):
        V = robot.obstacle_mesh(ob, np.zeros(3), 1.0)[0]
        H = robot.hull_2d(V @ E)
        if len(H) >= 3:
            ax.add_patch(Polygon(H, closed=True, fc=robot.ANATOMY, alpha=0.7,
                                 ec=robot.ANATOMY_EDGE, lw=1.2, zorder=1.3))  # fmt: skip
        for line in robot.anatomy_lines(ob):
            p2 = line @ E
            ax.plot(p2[:, 0], p2[:, 1], color=robot.ANATOMY_EDGE, lw=2.4, zorder=1.35,
                    solid_capstyle="round")  # fmt: skip


def _fit(lo: np.ndarray, hi: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """The limits [lo, hi] widened about their middle to the box's width/height
    ``ratio``, so that equal scales fill the box."""
    w, h = hi - lo
    mid = 0.5 * (lo + hi)
    w, h = max(w, h * ratio), max(h, w / ratio)
    return mid - 0.5 * np.array([w, h]), mid + 0.5 * np.array([w, h])


def _edge(p: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Where the segment from p (inside the box [lo, hi]) towards q leaves it."""
    d = q - p
    t = 1.0
    for k in range(2):
        if d[k] > 0:
            t = min(t, (hi[k] - p[k]) / d[k])
        elif d[k] < 0:
            t = min(t, (lo[k] - p[k]) / d[k])
    return p + t * d


def draw(s: SerialSettings, plan: Plan, folder: Path, title: str) -> list[Path]:
    """``plan.png`` (and PDF) of ``plan`` into ``folder``; ``title``: at most two lines."""
    fig = figure(s, plan, title)
    return save(fig, folder, "plan")


def figure(s: SerialSettings, plan: Plan, title: str) -> Any:
    """The plan sheet as a matplotlib figure (module docstring)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    f, u = plan.factor, plan.shown
    ports = plan.ports
    A = len(ports)
    region = s.task.region if s.task is not None else None
    wall = s.task.body_wall if s.task is not None else None
    views = _views(ports)
    cam = plan.camera
    P = _patient(s, ports if cam is None else np.vstack([ports, cam.reshape(2, 3)]))
    rows = plan.rows
    table_h = 0.26 * (A + 1 + (plan.camera is not None)) + 0.2
    text_h = 0.19 * sum(len(textwrap.wrap(r, 150)) for r in rows) + 0.15
    W, view_h, top = 12.5, VIEW_H, 0.75
    bottom = 0.25 + table_h + text_h + 0.5  # the tables, the legend
    H = top + view_h + 0.55 + bottom
    fig = plt.figure(figsize=(W, H))
    fig.designopt_plan = plan  # the numbers drawn (tests read them)
    kinds: dict[str, Any] = {}
    for v, (vtitle, E, names) in enumerate(views):
        ax = fig.add_axes(((0.75 + v * 6.15) / W, (bottom + 0.55) / H, VIEW_W / W, VIEW_H / H))
        lo2, hi2 = (P @ E).min(0), (P @ E).max(0)
        span = float(np.max(hi2 - lo2)) or 1.0
        lo2, hi2 = lo2 - 0.08 * span, hi2 + 0.08 * span
        hi2[1] += 0.22 * span * A**0.5 if v == 0 else 0.06 * span  # room for the labels
        label = _draw_wall(ax, wall, E, lo2, hi2)
        if label:
            kinds[label] = Patch(fc=SKIN, ec=SKIN_EDGE, label=label)
        _draw_anatomy(ax, s, E)
        if _anatomy(s):
            kinds["anatomy"] = Patch(fc=robot.ANATOMY, ec=robot.ANATOMY_EDGE, alpha=0.7,
                                     label="anatomy (inside the patient)")  # fmt: skip
        if region is not None:
            robot.draw_region_2d(ax, region, E)
            kinds["region"] = Line2D([], [], color="#3182bd", lw=1.0, label="task region")
        lo, hi = _fit(lo2, hi2, VIEW_W / VIEW_H)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal", adjustable="box")  # the limits fit the box: equal scales
        p2 = ports @ E
        if plan.centre is not None:  # the instruments' lines to the task's centre
            c2 = plan.centre @ E
            for k in range(A):
                ax.plot(*np.stack([p2[k], c2]).T, color=LINE, lw=1.0, ls="--", zorder=2)
            kinds["line"] = Line2D([], [], color=LINE, lw=1.0, ls="--",
                                   label="incision to the task's centre")  # fmt: skip
            if v == 1 and plan.line_angle is not None:
                _arc(ax, c2, p2[0], p2[1], plan.line_angle, span)
        if plan.bases is not None:
            _bases(ax, plan, E, p2, lo, hi, span, v == 0, P)
            kinds["base"] = Line2D([], [], color="0.3", lw=1.0, ls=":", marker="s", ms=6,
                                   label="arm: base to incision (arrow: base off the view)")  # fmt: skip
        if cam is not None:  # the scope from its incision to its tip
            c2 = cam.reshape(2, 3) @ E
            ax.plot(*c2.T, color=CAMERA, lw=2.2, zorder=5.5, solid_capstyle="round")
            ax.plot(*c2[1], marker=".", ms=7, color=CAMERA, ls="none", zorder=5.6)
            ax.plot(*c2[0], marker="D", ms=8, mfc="white", mec=CAMERA, mew=1.8, ls="none",
                    zorder=6)  # fmt: skip
            kinds["camera"] = Line2D([], [], color=CAMERA, lw=2.2, marker="D", ms=7, mfc="white",
                                     mec=CAMERA, label="camera port C and the scope to its tip")  # fmt: skip
        for k in range(A):
            ax.plot(*p2[k], marker="o", ms=9, mfc="white", mec="k", mew=1.8, ls="none", zorder=6)
        kinds["port"] = Line2D([], [], marker="o", ms=8, mfc="white", mec="k", mew=1.6, ls="none",
                               label="incision point (port on the body wall)")  # fmt: skip
        if v == 0:
            _labels(ax, plan, p2, None if cam is None else cam[:3] @ E)
            _dimensions(ax, plan, p2, span)
        else:
            marks = [(f"P{k}", p2[k]) for k in range(A)]
            marks += [] if cam is None else [("C", cam[:3] @ E)]
            for name, q in marks:
                ax.annotate(name, q, xytext=(0, 9), textcoords="offset points",
                            ha="center", va="bottom", fontsize=FONT, weight="bold", zorder=7)  # fmt: skip
        ax.set_xlabel(f"{names[0]} [{u}]", fontsize=FONT + 0.5)
        ax.set_ylabel(f"{names[1]} [{u}]", fontsize=FONT + 0.5)
        from matplotlib.ticker import FuncFormatter, MaxNLocator

        for a_ in (ax.xaxis, ax.yaxis):
            a_.set_major_locator(MaxNLocator(6))
            a_.set_major_formatter(FuncFormatter(lambda x, _: f"{x * f:.0f}"))
        ax.tick_params(labelsize=FONT)
        ax.grid(alpha=0.25)
        ax.set_title(vtitle, fontsize=FONT + 1.5, y=1.0, pad=4)
    fig.legend(handles=list(kinds.values()), loc="lower center",
               bbox_to_anchor=(0.5, (bottom - 0.45) / H), ncol=min(len(kinds), 4),
               fontsize=FONT, framealpha=0.9)  # fmt: skip
    _table(fig, plan, W, H, bottom - 0.55, table_h)
    y = (bottom - 0.6 - table_h) / H
    for r in rows:
        for ln in textwrap.wrap(r, 150):
            fig.text(0.75 / W, y, ln, fontsize=FONT, va="top",
                     color="crimson" if "NOT MET" in r or r.startswith("warning:") else "black")  # fmt: skip
            y -= 0.19 / H
    lines = title.split("\n")[:2]
    fig.suptitle("\n".join(lines), fontsize=12.5, y=1 - 0.12 / H, va="top", weight="bold")
    return fig


def _labels(ax: Any, plan: Plan, p2: np.ndarray, c2: np.ndarray | None = None) -> None:
    """Each incision's label (``P0 (x, y, z) mm``; the camera's ``C``, at ``c2``) in the
    strip above the patient, an arrow to its mark; left to right as the incisions lie."""
    items = [(f"P{k} {_fmt(plan.ports[k], plan.factor)} {plan.shown}", p2[k], f"incision-{k}")
             for k in range(len(p2))]  # fmt: skip
    if c2 is not None and plan.camera is not None:
        items.append((f"C {_fmt(plan.camera[:3], plan.factor)} {plan.shown}", c2, "incision-camera"))
    A = len(items)
    order = np.argsort([q[0] for _, q, _ in items], kind="stable")
    per_row = 2 if A > 2 else A
    for slot, k in enumerate(order):
        col, row = slot % per_row, slot // per_row
        x = (col + 0.5) / per_row
        y = 0.975 - 0.075 * row
        text, q, gid = items[k]
        ax.annotate(text, q,
                    xytext=(x, y), textcoords="axes fraction", ha="center", va="top",
                    fontsize=FONT + 0.5, weight="bold", zorder=8, gid=gid,
                    bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": "0.3", "lw": 0.6},
                    arrowprops={"arrowstyle": "-", "color": "0.45", "lw": 0.7,
                                "shrinkA": 0, "shrinkB": 5})  # fmt: skip


def _dimensions(ax: Any, plan: Plan, p2: np.ndarray, span: float) -> None:
    """A dimension line beside each pair of incisions with their 3-D distance."""
    centre = p2.mean(0)
    for n, (i, j, d) in enumerate(plan.distances):
        a, b = p2[i], p2[j]
        t = b - a
        L = float(np.linalg.norm(t))
        if L < 1e-12:
            continue
        nrm = np.array([-t[1], t[0]]) / L
        c = plan.centre[:2] if plan.centre is not None else centre
        if (0.5 * (a + b) - c) @ nrm < -0.02 * span or (
            abs((0.5 * (a + b) - c) @ nrm) <= 0.02 * span and nrm[int(np.argmax(np.abs(nrm)))] < 0
        ):
            nrm = -nrm  # away from the task (the pair straddles it: to the right or up)
        off = (0.2 + 0.06 * n) * span * nrm
        for p in (a, b):
            ax.plot(*np.stack([p + 0.15 * off, p + 1.1 * off]).T, color="0.2", lw=0.7, zorder=5)
        ax.annotate("", a + off, b + off, arrowprops={"arrowstyle": "<|-|>", "color": "0.1",
                    "lw": 1.0, "shrinkA": 0, "shrinkB": 0, "mutation_scale": 9}, zorder=5)  # fmt: skip
        m = 0.5 * (a + b) + off
        ax.text(*m, f"{d * plan.factor:.1f} {plan.shown}", ha="center", va="center",
                fontsize=FONT + 0.5, zorder=8, gid=f"distance-{i}-{j}",
                bbox={"boxstyle": "round,pad=0.2", "fc": "#fff7bc", "ec": "0.3", "lw": 0.6})  # fmt: skip


def _arc(ax: Any, c: np.ndarray, a: np.ndarray, b: np.ndarray, angle: float, span: float) -> None:
    """An arc at the task's centre c between the view's lines to a and b, labelled with
    the angle between the 3-D lines."""
    from matplotlib.patches import Arc

    ta = math.degrees(math.atan2(*(a - c)[::-1]))
    tb = math.degrees(math.atan2(*(b - c)[::-1]))
    t0, t1 = (ta, tb) if (tb - ta) % 360 <= 180 else (tb, ta)
    r = 0.16 * span
    ax.add_patch(Arc(tuple(c), 2 * r, 2 * r, theta1=t0, theta2=t1, color="0.1", lw=1.0, zorder=5))
    mid = math.radians(t0 + ((t1 - t0) % 360) / 2)
    ax.text(c[0] + 1.45 * r * math.cos(mid), c[1] + 1.45 * r * math.sin(mid), f"{angle:.1f} deg",
            ha="center", va="center", fontsize=FONT, zorder=8, gid="line-angle",
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85})  # fmt: skip


def _bases(ax: Any, plan: Plan, E: np.ndarray, p2: np.ndarray, lo: np.ndarray, hi: np.ndarray,
           span: float, named: bool, patient: np.ndarray) -> None:  # fmt: skip
    """Each arm's base: a square where it lies in the view, else an arrow at the view's
    edge towards it; a dotted line from it to the arm's incision. A base that lies in
    the view but far along the line of sight (beyond the patient: the side view of an
    arm beside the table) is left out of that view."""
    n = np.cross(E[:, 0], E[:, 1])
    depth = patient @ n
    reach = 0.1 * float(np.ptp(patient, 0).max())
    for k, b in enumerate(plan.bases[:, :3]):  # type: ignore[index]
        col = ARM_COLOURS[k % len(ARM_COLOURS)]
        b2 = b @ E
        inside = bool(np.all(b2 >= lo) and np.all(b2 <= hi))
        behind = not depth.min() - reach <= b @ n <= depth.max() + reach
        if inside and behind:  # seen end-on: its line would cross the patient
            continue
        ax.plot(*np.stack([b2, p2[k]]).T, color=col, lw=1.3, ls=":", zorder=1.8)
        if inside:
            ax.plot(*b2, marker="s", ms=8, color=col, mec="k", ls="none", zorder=6)
            if named:
                ax.annotate(f"base {k}", b2, xytext=(0, -10), textcoords="offset points",
                            ha="center", va="top", fontsize=FONT, color=col)  # fmt: skip
            continue
        e = _edge(p2[k], b2, lo, hi)
        back = e - 0.07 * span * (b2 - p2[k]) / np.linalg.norm(b2 - p2[k])
        ax.annotate("", e, back, arrowprops={"arrowstyle": "-|>", "color": col, "lw": 2.0,
                    "mutation_scale": 14}, zorder=6)  # fmt: skip
        if named:  # kept inside the view: aligned on the edge it points at
            tol = 1e-9 * span
            ha = "left" if e[0] <= lo[0] + tol else "right" if e[0] >= hi[0] - tol else "center"
            top = e[1] >= hi[1] - tol
            ax.annotate(f"to base {k}", back, xytext=(0, -8 if top else 8),
                        textcoords="offset points", ha=ha, va="top" if top else "bottom",
                        fontsize=FONT, color=col, weight="bold", zorder=7)  # fmt: skip


def table_cells(plan: Plan) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the plan's table: each instrument arm's incision point (P0, P1,
    … named by its arm's index), its move onto the wall and its base; the camera's
    incision point C last."""
    u, f = plan.shown, plan.factor
    head = ["", f"incision point x, y, z [{u}]"]
    if plan.port_points is not None:
        head += [f"design's point x, y, z [{u}]", f"moved onto the wall [{u}]"]
    if plan.bases is not None:
        head += [f"base x, y, z [{u}]", "base roll, pitch, yaw [deg]"]
    cells = []
    for k, p in enumerate(plan.ports):
        row = [f"P{k}: arm {plan.arms[k] if plan.arms else k}", _fmt(p, f)]
        if plan.port_points is not None:
            row += [_fmt(plan.port_points[k], f),
                    f"{np.linalg.norm(p - plan.port_points[k]) * f:.1f}"]  # fmt: skip
        if plan.bases is not None:
            row += [_fmt(plan.bases[k][:3], f), _fmt(plan.bases[k][3:], 1.0)]
        cells.append(row)
    if plan.camera is not None:  # the camera's row: its incision point (its tip: the rows)
        cells.append(["C: camera", _fmt(plan.camera[:3], f)] + ["–"] * (len(head) - 2))
    return head, cells


def _table(fig: Any, plan: Plan, W: float, H: float, top: float, height: float) -> None:
    """Each arm's incision point, its move onto the wall and its base, as a table."""
    head, cells = table_cells(plan)
    ax = fig.add_axes((0.75 / W, (top - height) / H, (W - 1.5) / W, height / H))
    ax.set_axis_off()
    tab = ax.table(cellText=cells, colLabels=head, loc="upper center", cellLoc="center",
                   bbox=(0, 0, 1, 1))  # fmt: skip
    tab.auto_set_font_size(False)
    tab.set_fontsize(FONT)
    widths = [0.1] + [0.9 / (len(head) - 1)] * (len(head) - 1)
    for (r, c), cell in tab.get_celld().items():
        cell.set_width(widths[c])
        cell.set_edgecolor("0.6")
        if r == 0:
            cell.set_facecolor("#eeeeee")
            cell.get_text().set_weight("bold")


def title_of(what: str, s: SerialSettings) -> str:
    """The sheet's two title lines."""
    wall = s.task.body_wall.shape if s.task is not None and s.task.body_wall is not None else None
    shape = {"halfspace": "plane"}.get(wall, wall)
    where = f"on the {shape} body wall" if wall else "(no body wall)"
    return (
        f"Port plan: {what}\nincision points {where}, in the patient's frame; "
        "numbers in the table below"
    )


def verdict_rows(rec: Any, x: np.ndarray) -> list[str]:
    """The final stage's lines for the layout ``x`` (D,) of a run with ``final.race``
    (its archived ``verdict`` group): the race's one-line answer and this layout's own
    verdict (*best*, *equivalent*, *worse*) with its row in the race; [] without a race."""
    g = rec.groups.get("verdict") if hasattr(rec, "groups") else None
    if not g or "x" not in g:
        return []
    at = g.get("attrs", {})
    text = lambda v: v.decode() if isinstance(v, bytes) else str(v)  # noqa: E731
    summary = text(at.get("summary", ""))
    out = [f"final stage (the candidates raced on fresh samples): {summary}"
           + (f"; {text(at['tie_note'])}" if at.get("tie_note") else "")]  # fmt: skip
    X = np.atleast_2d(np.asarray(g["x"], np.float64))
    near = np.flatnonzero(np.all(np.isclose(X, np.asarray(x, np.float64), rtol=1e-9,
                                            atol=1e-12), axis=1))  # fmt: skip
    if near.size:
        j = int(near[0])
        v = text(np.atleast_1d(g["verdict"])[j])
        out.append(f"this layout in the final stage: {v} (candidate #{j} of {len(X)})")
    return out


def run_sheet(rec: Any) -> tuple[Plan, str]:
    """(the plan, the title) of a run's final design (its ``final/`` placement values)."""
    s: SerialSettings = rec.config.study
    x = np.asarray(list(rec.x.values()), np.float64)
    g = _placed(s, rec.groups.get("final", {}), x)
    obj = [k for k, w in s.objective.items() if not isinstance(w, bool) and k not in ("n_norm",)]
    plan = plan_of(s, g, rec.indices, obj)
    plan.rows += verdict_rows(rec, x)
    plan.rows += [f"warning: {w}" for w in rec.warnings]  # the final stage's, as the summary's
    return plan, title_of("the final design", s)


def run_plan(rec: Any, folder: Path) -> list[Path]:
    """``plan.png`` of a run's final design (:func:`run_sheet`)."""
    plan, title = run_sheet(rec)
    return draw(rec.config.study, plan, folder, title)


def front_sheet(rec: Any, picks: Sequence[tuple[str, int]]) -> tuple[Plan, str] | None:
    """(the plan, the title) of a front's recommended design: the knee of ``picks``
    (``figures.front.extremes_and_knee``; the first pick where there is no knee)."""
    if not picks:
        return None
    s: SerialSettings = rec.config.study
    name, i = next(((n, i) for n, i in picks if n == "knee"), picks[0])
    fr = rec.groups.get("front", {})
    g = _placed(s, {k: np.asarray(fr[k])[i] for k in ("ports", "port_points", "bases", "camera")
                    if k in fr}, rec.X[i])  # fmt: skip
    ind = {}
    for k, v in rec.values.items():
        v = np.asarray(v)
        if k.endswith("_se") or v.ndim != 1 or len(v) != len(rec.X):
            continue
        se = rec.values.get(f"{k}_se")
        ind[k] = (float(v[i]), None if se is None else float(np.asarray(se)[i]))
    plan = plan_of(s, g, ind, list(rec.objectives))
    plan.rows += verdict_rows(rec, np.asarray(rec.X[i], np.float64))
    return plan, title_of(f"the front's {name} (design {i} of {len(rec.X)})", s)


def front_plan(rec: Any, picks: Sequence[tuple[str, int]], folder: Path) -> list[Path]:
    """``plan.png`` of a front's recommended design (:func:`front_sheet`)."""
    sheet = front_sheet(rec, picks)
    if sheet is None:
        return []
    return draw(rec.config.study, sheet[0], folder, sheet[1])


def report_plan(rec: Any) -> dict[str, Any] | None:
    """The plan sheet for the HTML report (``Study.robot``'s ``plan``): {"title": the
    sheet's title, "png": the sheet as PNG bytes, "rows": its text rows}, for a run's
    final design or a front's knee; None where the run places no port."""
    import io

    from designopt.results import FrontRecord

    s: SerialSettings = rec.config.study
    if s.task is None or s.ports()[0] is None:  # no port: no plan to pin up
        return None
    if isinstance(rec, FrontRecord):
        from designopt.figures.front import extremes_and_knee

        sheet = front_sheet(rec, extremes_and_knee(rec))
        if sheet is None:
            return None
    else:
        sheet = run_sheet(rec)
    fig = figure(s, sheet[0], sheet[1])
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return {"title": sheet[1].replace("\n", "; "), "png": buf.getvalue(),
            "rows": list(sheet[0].rows)}


def _placed(s: SerialSettings, g: Mapping[str, Any], x: np.ndarray) -> dict[str, Any]:
    """The archived placement values, or (an archive from before they were archived)
    the study's own placement of design x."""
    if "ports" in g:
        return dict(g)
    pl = placement(s, np.atleast_2d(x)) or {}
    return {k: np.asarray(v)[0] for k, v in pl.items() if k != "attrs"}
