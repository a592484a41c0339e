"""The robot in the interactive report (docs/figures.md, "The robot in the report"): a
rotatable 3-D view of the arm in its task, with a slider through representative poses
(plotly frames), and, for a Pareto front, the front beside the robot: hovering or
clicking a design draws that design's robot (precomputed at one common pose; a small
handler in the page's script restyles the robot's traces, so the page stays offline).

Geometry comes from ``designopt.figures.robot`` (capsules, axes, frames, region); every
arm is a fixed set of traces (capsule mesh, centre line with its joints, joint axes, the
frames' x, y, z, the URDF meshes when there are any), so a frame or a design changes
their coordinates only. The centre line's points are the joint origins themselves (the
base origin first): ``tests/test_robot_view.py`` reads them back against the kinematics.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.html.model import PageSection, Plot, Z, _Ids, esc
from designopt.figures.html.plots import _layout
from designopt.figures.robot import (
    ANATOMY_EDGE,
    COLLIDING,
    FRAME_COLOURS,
    SCOPE,
    Arm,
    Scene,
    anatomy_lines,
    axis_arrows,
    capsules,
    clip_note,
    clipped_obstacles,
    cone_rays,
    is_wall,
    obstacle_colour,
    obstacle_name,
    radii,
    region_faces,
    region_wire,
    scene_points,
    triads,
    view_box,
)

HEIGHT = 760
"""Pixels of a front's plot and of its robot's view (side by side, one height)."""
VIEW_HEIGHT = 780
"""Pixels of the robot's view in its task (the page's width)."""
SCENE = {"x": [0.0, 1.0], "y": [0.0, 0.8]}
"""The front robot's scene in its plot area: the design's label above it."""
LABEL_WIDTH = 72
"""Characters a line of the front robot's design label."""
TRIANGLES = 20_000
"""Mesh triangles of a page's robot views, all frames and designs together (a study
decimates its meshes to this budget, ``designopt.kinematics.meshes.decimate``)."""


@dataclass
class Pose:
    """One slider position: its ``label``, the arms, each arm's hover text (joint values,
    1/k) and the target it reaches (``mark``, or None)."""

    label: str
    arms: list[Arm]
    hover: list[str]
    mark: np.ndarray | None = None


@dataclass
class View:
    """The robot in its task: ``scene`` holds what stays (region, cone, targets, and
    reference arms such as the original robot), ``poses`` what the slider moves."""

    title: str
    unit: str
    scene: Scene
    poses: list[Pose]
    note: str = ""


@dataclass
class FrontView:
    """A front beside its robots: objective values ``x``, ``y`` (n,) with their axis
    labels, one robot (list of arms, each at its base in the world) per design at one
    pose per design (a representative tuple of targets, or the home pose), each design's
    hover text, reference arms (the original robot of a URDF chain), and what stays:
    the task region, obstacles, ports and endoscopes; ``x_se``, ``y_se`` (n,) the objectives'
    standard errors (None: no bars; drawn ± 2 SE like the front's own plot)."""

    title: str
    unit: str
    x: np.ndarray
    y: np.ndarray
    xlabel: str
    ylabel: str
    robots: list[list[Arm]]
    hover: list[str]
    reference: list[Arm] = field(default_factory=list)
    region: Any = None
    note: str = ""
    obstacles: list[Any] = field(default_factory=list)
    ports: list[np.ndarray] = field(default_factory=list)
    scopes: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    x_se: np.ndarray | None = None
    y_se: np.ndarray | None = None

    def shown_reference(self) -> list[Arm]:
        """The reference arms worth drawing: none when every design's arms have the
        reference's link geometry (:func:`same_links`: no link of the chain is a design
        variable, e.g. a planning case that moves only ports and bases)."""
        ref = list(self.reference)
        if ref and all(len(rb) == len(ref) and all(same_links(a, b) for a, b in zip(ref, rb, strict=True))
                       for rb in self.robots):  # fmt: skip
            return []
        return ref


def _link_invariants(arm: Arm) -> np.ndarray:
    """What an arm's link geometry fixes whatever its joint values and base: the first
    joint's origin and axis in the base frame, then per joint i the angle between its axis
    and the next's (cosine), the part of the step to the next origin (the tip last)
    across a prismatic joint's axis (the whole step across a revolute one: its length
    and its component along the joint's own axis) and that part along the next axis."""
    O = np.asarray(arm.origins, np.float64)
    A = np.asarray(arm.axes, np.float64)
    A = A / np.maximum(np.linalg.norm(A, axis=1, keepdims=True), 1e-300)
    n = len(A)
    out = [O[0], A[0]] if n else [O[:1].ravel()]
    for i in range(n):
        v = O[i + 1] - O[i]
        prismatic = i < len(arm.types) and arm.types[i] == "P"
        w = v - (v @ A[i]) * A[i] if prismatic else v
        row = [np.linalg.norm(w), 0.0 if prismatic else v @ A[i]]
        if i + 1 < n:
            row += [A[i] @ A[i + 1], w @ A[i + 1]]
        out.append(np.asarray(row))
    return np.concatenate(out)


def same_links(a: Arm, b: Arm, rtol: float = 1e-6) -> bool:
    """Whether arms ``a`` and ``b`` (any joint values, any bases) have the same link
    geometry: the same joints (number and types) and :func:`_link_invariants`."""
    if len(a.axes) != len(b.axes) or a.types != b.types:
        return False
    ia, ib = _link_invariants(a), _link_invariants(b)
    scale = max(a.length(), b.length(), 1e-300)
    return ia.shape == ib.shape and bool(np.all(np.abs(ia - ib) <= rtol * scale + 1e-12))


def _segments(segs: Sequence[np.ndarray]) -> np.ndarray:
    """Polylines joined into one array with NaN rows between them (plotly's gaps)."""
    out = []
    for s in segs:
        out += [np.asarray(s, np.float64), np.full((1, 3), np.nan)]
    return np.vstack(out) if out else np.zeros((0, 3))


def _xyz(P: np.ndarray) -> dict[str, np.ndarray]:
    return {"x": P[:, 0], "y": P[:, 1], "z": P[:, 2]}


def arm_geometry(arm: Arm, r: float) -> list[dict[str, Any]]:
    """The coordinates of :func:`arm_traces`' traces, in order (what a frame updates)."""
    V, _ = capsules(arm, r, keep_all=True)
    L = max(4 * r, 0.08 * arm.length())
    tri = triads(arm, 0.75 * L)
    out = [_xyz(V), _xyz(arm.points()), _xyz(_segments(axis_arrows(arm, L)))]
    out += [_xyz(_segments([tri[0, k], tri[1, k]])) for k in range(3)]
    if arm.meshes:
        from designopt.figures.robot import merge

        out.append(_xyz(merge(list(arm.world().meshes))[0]))
    return out


def _look(arm: Arm) -> dict[str, Any]:
    """The capsules' colour and name of an arm (red and "(colliding)" when it collides)."""
    return {"color": COLLIDING if arm.colliding else arm.color,
            "name": esc(arm.label + (" (colliding)" if arm.colliding else "")) or "arm"}  # fmt: skip


def arm_traces(arm: Arm, r: float, hover: str, legend: bool = True,
               opacity: float = 0.55) -> list[dict[str, Any]]:  # fmt: skip
    """Plotly traces of one arm: capsules (mesh3d), the centre line with its joints
    (hover: ``hover``), joint axes, the frames' x, y, z axes, the meshes (mesh3d)."""
    geo = arm_geometry(arm, r)
    _, F = capsules(arm, r, keep_all=True)
    look = _look(arm)
    col, name = look["color"], look["name"]
    grp = esc(arm.label) or "arm"
    trs: list[dict[str, Any]] = [
        {"type": "mesh3d", **geo[0], "i": F[:, 0], "j": F[:, 1], "k": F[:, 2], "color": col,
         "opacity": opacity, "flatshading": True, "name": name, "legendgroup": grp,
         "showlegend": legend, "hoverinfo": "skip",
         "lighting": {"ambient": 0.55, "diffuse": 0.8, "specular": 0.2}},
        {"type": "scatter3d", "mode": "lines+markers", **geo[1], "name": grp + ": joints",
         "legendgroup": grp, "showlegend": False, "hovertemplate": hover,
         "line": {"color": "#222", "width": 4}, "marker": {"size": 3, "color": "#222"}},
        {"type": "scatter3d", "mode": "lines", **geo[2], "name": "joint axes",
         "legendgroup": grp, "showlegend": False, "hoverinfo": "skip",
         "line": {"color": "#333", "width": 5}},
    ]  # fmt: skip
    for k in range(3):
        trs.append({"type": "scatter3d", "mode": "lines", **geo[3 + k],
                    "name": f"frame {'xyz'[k]}", "legendgroup": grp, "showlegend": False,
                    "hoverinfo": "skip", "line": {"color": FRAME_COLOURS[k], "width": 6}})  # fmt: skip
    if arm.meshes:
        from designopt.figures.robot import merge

        _, Fm = merge(list(arm.world().meshes))
        trs.append({"type": "mesh3d", **geo[-1], "i": Fm[:, 0], "j": Fm[:, 1], "k": Fm[:, 2],
                    "color": "#a8a8a8", "opacity": 0.6, "flatshading": True,
                    "name": grp + ": meshes", "legendgroup": grp, "showlegend": False,
                    "hoverinfo": "skip"})  # fmt: skip
    return trs


def _static(scene: Scene, unit: str, box: tuple[np.ndarray, np.ndarray]) -> list[dict[str, Any]]:
    """Region (faces and wireframe), obstacles (clipped to the view ``box`` (lo, hi)),
    ports, tool-axis cone, targets, reference arms."""
    out: list[dict[str, Any]] = []
    V, F = region_faces(scene.region)
    if len(F):
        out.append({"type": "mesh3d", **_xyz(V), "i": F[:, 0], "j": F[:, 1], "k": F[:, 2],
                    "color": "#9ecae1", "opacity": 0.12, "name": "task region",
                    "hoverinfo": "skip", "showlegend": False})  # fmt: skip
    wire = region_wire(scene.region)
    if wire:
        out.append({"type": "scatter3d", "mode": "lines", **_xyz(_segments(wire)),
                    "name": "task region", "hoverinfo": "skip",
                    "line": {"color": "#3182bd", "width": 2}})  # fmt: skip
    for k, ob, Vo, Fo in clipped_obstacles(scene.obstacles, *box)[0]:  # clipped to the view
        inside = getattr(ob, "inside", False)  # the anatomy: opaque, lit, outlined
        out.append({"type": "mesh3d", **_xyz(Vo), "i": Fo[:, 0], "j": Fo[:, 1], "k": Fo[:, 2],
                    "color": obstacle_colour(ob),
                    "opacity": 0.85 if inside else 0.12 if is_wall(ob) else 0.2,
                    "name": obstacle_name(k, ob), "hoverinfo": "name", "showlegend": True,
                    "legendgroup": f"obstacle{k}"}
                   | ({"flatshading": True, "lighting": {"ambient": 0.45, "diffuse": 0.9,
                                                         "specular": 0.3}} if inside else {}))  # fmt: skip
        for line in anatomy_lines(ob):  # a thin vessel stays visible at any scale
            P = np.clip(line, *box)
            out.append({"type": "scatter3d", "mode": "lines", **_xyz(P),
                        "name": obstacle_name(k, ob), "legendgroup": f"obstacle{k}",
                        "showlegend": False, "hoverinfo": "name",
                        "line": {"color": ANATOMY_EDGE, "width": 9}})  # fmt: skip
    if scene.ports:
        out.append({"type": "scatter3d", "mode": "markers",
                    **_xyz(np.asarray(scene.ports, np.float64)), "name": "port",
                    "marker": {"size": 6, "color": "white",
                               "line": {"color": "black", "width": 3}}})  # fmt: skip
    if scene.scopes:
        out.append({"type": "scatter3d", "mode": "lines",
                    **_xyz(_segments([np.stack(ab) for ab in scene.scopes])), "name": "endoscope",
                    "line": {"color": SCOPE, "width": 6}})  # fmt: skip
    if scene.cone is not None:
        out.append({"type": "scatter3d", "mode": "lines", **_xyz(_segments(cone_rays(scene.cone))),
                    "name": f"tool z axes within {scene.cone.half_angle:g}°", "hoverinfo": "skip",
                    "line": {"color": "#8c564b", "width": 2, "dash": "dash"}})  # fmt: skip
    t = scene.targets
    if t is not None:
        ok = np.asarray(t.ok, bool)
        xyz = np.asarray(t.xyz, np.float64)
        where = f"x %{{x:.4~g}}, y %{{y:.4~g}}, z %{{z:.4~g}} {esc(unit)}"
        if ok.any():
            out.append({"type": "scatter3d", "mode": "markers", **_xyz(xyz[ok]),
                        "name": f"targets ({esc(t.label)})",
                        "marker": {"size": 2, "color": np.asarray(t.value, np.float64)[ok],
                                   "colorscale": "Viridis", "opacity": 0.6,
                                   "colorbar": {"title": {"text": esc(style.label(t.label, "-"))},
                                                "len": 0.6, "thickness": 12}},
                        "hovertemplate": f"{where}<br>{esc(t.label)} = %{{marker.color:.4~g}}"
                                         "<extra></extra>"})  # fmt: skip
        if (~ok).any():
            out.append({"type": "scatter3d", "mode": "markers", **_xyz(xyz[~ok]),
                        "name": "unreached", "marker": {"size": 2.5, "symbol": "cross",
                                                        "color": "#6b6b6b"},
                        "hovertemplate": f"{where}<br>unreached<extra></extra>"})  # fmt: skip
    if scene.marks:  # the targets a solved pose reaches
        out.append({"type": "scatter3d", "mode": "markers",
                    **_xyz(np.asarray([p for p, _ in scene.marks], np.float64)),
                    "name": "the arms' targets", "hoverinfo": "skip",
                    "marker": {"size": 7, "symbol": "diamond-open",
                               "color": [c for _, c in scene.marks], "line": {"width": 2}}})  # fmt: skip
    if scene.collisions:  # colliding pairs: their closest points joined
        out.append({"type": "scatter3d", "mode": "lines+markers",
                    **_xyz(_segments([np.stack(ab) for ab in scene.collisions])),
                    "name": "colliding pair", "hoverinfo": "name",
                    "line": {"color": COLLIDING, "width": 6},
                    "marker": {"size": 5, "symbol": "x", "color": COLLIDING}})  # fmt: skip
    rs = radii(scene.arms)
    for arm, r in zip(scene.arms, rs, strict=True):
        out += arm_traces(arm, r, f"<b>{esc(arm.label)}</b><extra></extra>", opacity=0.25)
    return out


def _box(scene: Scene, arms: Sequence[Arm]) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """The view ((lo, hi), :func:`designopt.figures.robot.view_box`) of a scene and of
    the arms drawn in it later (frames, designs), and the points it holds."""
    P = np.vstack([scene_points(scene), *(scene_points(Scene(arms=[a])) for a in arms)])
    return view_box(P), P


def _scene_layout(unit: str, box: tuple[np.ndarray, np.ndarray], points: np.ndarray,
                  **kw: Any) -> dict[str, Any]:  # fmt: skip
    """A 3-D scene on the fixed ranges of the view ``box`` (lo, hi), one scale on all
    three axes, the camera a little back so that no corner is cut; a planar scene
    (``points`` in one horizontal plane) seen from above."""
    lo, hi = box
    span = hi - lo
    ax = {"backgroundcolor": "#fafafa", "gridcolor": "#dcdcdc", "showbackground": True}
    out = {a: ax | {"title": {"text": esc(style.label(a[0], unit))},
                    "range": [float(lo[k]), float(hi[k])]}
           for k, a in enumerate(("xaxis", "yaxis", "zaxis"))}  # fmt: skip
    r = span / span.max()
    P = points[np.all(np.isfinite(points), 1)]
    flat = len(P) > 0 and np.ptp(P[:, 2]) < 0.2 * (float(np.ptp(P, 0).max()) or 1.0)
    eye = {"x": 0.3, "y": -1.0, "z": 1.9} if flat else {"x": 1.3, "y": 1.3, "z": 0.9}
    return out | {"aspectmode": "manual",
                  "aspectratio": {"x": float(r[0]), "y": float(r[1]), "z": float(r[2])},
                  "camera": {"eye": eye}} | kw  # fmt: skip


def _mark_trace(p: np.ndarray | None) -> dict[str, Any]:
    P = np.full((1, 3), np.nan) if p is None else np.asarray(p, np.float64)[None]
    return {"type": "scatter3d", "mode": "markers", **_xyz(P), "name": "the pose's target",
            "marker": {"size": 7, "symbol": "diamond-open", "color": "#d62728",
                       "line": {"width": 2}}, "hoverinfo": "skip"}  # fmt: skip


def view_plot(view: View, ids: _Ids) -> Plot:
    """The 3-D robot in its task with a slider through ``view.poses``."""
    box, points = _box(view.scene, [a for p in view.poses for a in p.arms])
    static = _static(view.scene, view.unit, box)
    first = view.poses[0]
    rs = radii([a for p in view.poses for a in p.arms] + list(view.scene.arms))
    r = rs[0]
    dyn: list[dict[str, Any]] = []
    for k, arm in enumerate(first.arms):
        dyn += arm_traces(arm, arm.radius or r, first.hover[k])
    marked = any(p.mark is not None for p in view.poses)
    if marked:  # the target each pose reaches
        dyn.append(_mark_trace(first.mark))
    n0 = len(static)
    idx = list(range(n0, n0 + len(dyn)))
    frames = []
    for p in view.poses:
        upd: list[dict[str, Any]] = []
        for k, arm in enumerate(p.arms):
            geo = arm_geometry(arm, arm.radius or r)
            geo[1] = geo[1] | {"hovertemplate": p.hover[k]}
            geo[0] = geo[0] | _look(arm)  # a colliding arm red in its frame only
            upd += geo
        if marked:
            m = _mark_trace(p.mark)
            upd.append({k: m[k] for k in ("x", "y", "z")})
        frames.append({"name": p.label, "data": upd, "traces": idx})
    lay = _layout(esc(view.title), scene=_scene_layout(view.unit, box, points), height=VIEW_HEIGHT)
    lay["legend"] |= {"x": 0.0, "y": 1.0, "xanchor": "left", "yanchor": "top"}
    lay["uirevision"] = "robot"
    if len(view.poses) > 1:
        anim = {"mode": "immediate", "frame": {"duration": 0, "redraw": True},
                "transition": {"duration": 0}}  # fmt: skip
        ends = max(len(view.poses[0].label), len(view.poses[-1].label))
        x0 = float(np.clip(0.0026 * ends + 0.01, 0.02, 0.25))  # the end steps' labels in view
        lay["sliders"] = [{"active": 0, "currentvalue": {"prefix": "pose: ", "font": {"size": 12}},
                           "pad": {"t": 8, "b": 4}, "len": 1 - 2 * x0, "x": x0,
                           "steps": [{"method": "animate", "label": esc(p.label),
                                      "args": [[p.label], anim]} for p in view.poses]}]  # fmt: skip
    return Plot(ids("robot"), {"data": static + dyn, "layout": lay, "frames": frames}, wide=True)


def front_plots(fv: FrontView, ids: _Ids) -> list[Plot]:
    """The front (objective values, customdata: the design's number) and the robot of
    the design hovered or clicked, precomputed for every design (the page's script
    restyles the robot's traces: ``link``)."""
    n = len(fv.x)
    fid = ids("robot-front")
    custom = np.arange(n, dtype=np.float64)[:, None]
    front = {"type": "scatter", "mode": "markers", "x": np.asarray(fv.x, np.float64),
             "y": np.asarray(fv.y, np.float64), "customdata": custom, "name": "front",
             "text": [esc(h) for h in fv.hover],
             "hovertemplate": "<b>design %{customdata[0]}</b><br>%{text}<extra></extra>",
             "marker": {"size": 9, "color": "#1f77b4", "line": {"width": 0.5, "color": "#333"}}}  # fmt: skip
    bars = fv.x_se is not None and fv.y_se is not None
    for a, se in (("error_x", fv.x_se), ("error_y", fv.y_se)):
        if bars:  # ± 2 SE, as the front's own plot
            front[a] = {"type": "data", "array": Z * np.asarray(se, np.float64), "visible": True,
                        "thickness": 1, "width": 0, "color": "#999"}  # fmt: skip
    what = "; bars ± 2 SE" if bars else ""
    lay = _layout(esc(f"{fv.title}{what}: hover or click a design to draw its robot beside"),
                  esc(fv.xlabel), esc(fv.ylabel), showlegend=False, height=HEIGHT)  # fmt: skip
    lay["margin"] = lay["margin"] | {"b": 64}
    fplot = Plot(fid, {"data": [front], "layout": lay})
    scene = front_scene(fv)
    box, points = _box(scene, [a for rb in fv.robots for a in rb])
    static = _static(scene, fv.unit, box)
    rs = radii([a for rb in fv.robots for a in rb] + fv.shown_reference())
    r = rs[0]
    dyn: list[dict[str, Any]] = []
    for arm in fv.robots[0]:
        dyn += arm_traces(arm, arm.radius or r, "design 0<extra></extra>")
    idx = list(range(len(static), len(static) + len(dyn)))
    designs = []
    for i, robot in enumerate(fv.robots):
        geo = [g for arm in robot for g in arm_geometry(arm, arm.radius or r)]
        upd: dict[str, list[Any]] = {"x": [g["x"] for g in geo], "y": [g["y"] for g in geo],
                                     "z": [g["z"] for g in geo]}  # fmt: skip
        designs.append(
            {"data": upd, "layout": {"annotations[0].text": _label(i, fv.hover[i])}}
        )
    lay = _layout(esc("the robot of the design hovered or clicked on the front (common axes: "
                      "the designs compare by size)"),
                  scene=_scene_layout(fv.unit, box, points, domain=SCENE), height=HEIGHT)  # fmt: skip
    # the design's label on top, the legend under the scene (the margin grows to hold it)
    lay["legend"] |= {"orientation": "h", "x": 0.0, "y": -0.01, "xanchor": "left",
                      "yanchor": "top"}  # fmt: skip
    lay["uirevision"] = "robot"
    lay["annotations"] = [{"text": _label(0, fv.hover[0]), "xref": "paper",
                           "yref": "paper", "x": 0.0, "y": 1.0, "xanchor": "left",
                           "yanchor": "top", "showarrow": False, "font": {"size": 11},
                           "align": "left", "bgcolor": "rgba(255,255,255,0.8)"}]  # fmt: skip
    rplot = Plot(ids("robot-design"), {"data": static + dyn, "layout": lay,
                                       "link": {"source": fid, "traces": idx,
                                                "designs": designs}})  # fmt: skip
    return [fplot, rplot]


def front_scene(fv: FrontView) -> Scene:
    """What stays beside a front's robots: the reference arms, region, obstacles, ports."""
    return Scene(arms=fv.shown_reference(), region=fv.region, obstacles=list(fv.obstacles),
                 ports=list(fv.ports), scopes=list(fv.scopes))  # fmt: skip


def clipped(view: View | None = None, front: FrontView | None = None) -> str:
    """What the views leave out of their obstacles (``figures.robot.clip_note``)."""
    parts = []
    if view is not None:
        parts.append((view.scene, [a for p in view.poses for a in p.arms], view.unit))
    if front is not None:
        parts.append((front_scene(front), [a for rb in front.robots for a in rb], front.unit))
    return clip_note([n for sc, arms, u in parts
                      for n in clipped_obstacles(sc.obstacles, *_box(sc, arms)[0], u)[1]])  # fmt: skip


def _note(v: View | FrontView) -> str:
    """A view's note, less its parts (``; ``) on the faint original robot where that is
    not drawn (:meth:`FrontView.shown_reference`)."""
    if not isinstance(v, FrontView) or not v.reference or v.shown_reference():
        return v.note
    return "; ".join(p for p in v.note.split("; ") if "original robot" not in p)


def _label(i: int, hover: str) -> str:
    """The robot's label of design i: its hover text, one part (``; ``) a line, a long
    part wrapped at ``LABEL_WIDTH`` characters (the label stays within the plot)."""
    parts = f"design {i}: {hover}".split("; ")
    return "<br>".join(esc(line) for part in parts
                       for line in textwrap.wrap(part, LABEL_WIDTH, subsequent_indent="  ") or [""])  # fmt: skip


def robot_section(view: View | None = None, front: FrontView | None = None,
                  ids: _Ids | None = None) -> PageSection:  # fmt: skip
    """The page's "Robot" section: the view in its task and/or the front's robots; a
    note names the obstacles clipped to the view (far away, or cut at its edge)."""
    ids = ids or _Ids()
    sec = PageSection("robot", "Robot")
    for v in (view, front):
        if v is not None and v.note:
            sec.items.append(f"<p class='note'>{esc(_note(v))}</p>")
    note = clipped(view, front)
    if note:
        sec.items.append(f"<p class='note'>{esc(note)}</p>")
    if view is not None:
        sec.items.append(view_plot(view, ids))
    if front is not None:
        sec.items += front_plots(front, ids)
    return sec
