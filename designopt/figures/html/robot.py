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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.html.model import PageSection, Plot, _Ids, esc
from designopt.figures.html.plots import _layout
from designopt.figures.robot import (
    COLLIDING,
    FRAME_COLOURS,
    Arm,
    Scene,
    axis_arrows,
    capsules,
    cone_rays,
    radii,
    region_faces,
    region_wire,
    triads,
)

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
    labels, one robot (list of arms) per design at one common pose, each design's hover
    text, reference arms (the original robot of a URDF chain)."""

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


def arm_traces(arm: Arm, r: float, hover: str, legend: bool = True,
               opacity: float = 0.55) -> list[dict[str, Any]]:  # fmt: skip
    """Plotly traces of one arm: capsules (mesh3d), the centre line with its joints
    (hover: ``hover``), joint axes, the frames' x, y, z axes, the meshes (mesh3d)."""
    geo = arm_geometry(arm, r)
    _, F = capsules(arm, r, keep_all=True)
    col = COLLIDING if arm.colliding else arm.color
    name = esc(arm.label + (" (colliding)" if arm.colliding else "")) or "arm"
    grp = name
    trs: list[dict[str, Any]] = [
        {"type": "mesh3d", **geo[0], "i": F[:, 0], "j": F[:, 1], "k": F[:, 2], "color": col,
         "opacity": opacity, "flatshading": True, "name": name, "legendgroup": grp,
         "showlegend": legend, "hoverinfo": "skip",
         "lighting": {"ambient": 0.55, "diffuse": 0.8, "specular": 0.2}},
        {"type": "scatter3d", "mode": "lines+markers", **geo[1], "name": name + ": joints",
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
                    "name": name + ": meshes", "legendgroup": grp, "showlegend": False,
                    "hoverinfo": "skip"})  # fmt: skip
    return trs


def _static(scene: Scene, unit: str) -> list[dict[str, Any]]:
    """Region (faces and wireframe), tool-axis cone, targets, reference arms."""
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
    if scene.obstacles or scene.ports:
        from designopt.figures.robot import obstacle_mesh, scene_points

        pts = scene_points(scene)
        centre, ext = pts.mean(0), float(np.ptp(pts, 0).max()) or 1.0
        for k, ob in enumerate(scene.obstacles):
            Vo, Fo = obstacle_mesh(ob, centre, ext)
            out.append({"type": "mesh3d", **_xyz(Vo), "i": Fo[:, 0], "j": Fo[:, 1],
                        "k": Fo[:, 2], "color": "#7f7f7f", "opacity": 0.2,
                        "name": f"obstacle {k}: {ob.shape}", "hoverinfo": "name",
                        "showlegend": True})  # fmt: skip
        if scene.ports:
            out.append({"type": "scatter3d", "mode": "markers",
                        **_xyz(np.asarray(scene.ports, np.float64)), "name": "port",
                        "marker": {"size": 6, "color": "white",
                                   "line": {"color": "black", "width": 3}}})  # fmt: skip
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
    rs = radii(scene.arms)
    for arm, r in zip(scene.arms, rs, strict=True):
        out += arm_traces(arm, r, f"<b>{esc(arm.label)}</b><extra></extra>", opacity=0.25)
    return out


def _scene_layout(unit: str, traces: Sequence[dict[str, Any]], **kw: Any) -> dict[str, Any]:
    """A 3-D scene on fixed ranges that hold every point of ``traces`` (and of the
    frames and designs drawn there later, passed in as traces too), one scale on all
    three axes, the camera a little back so that no corner is cut."""
    P = np.vstack([np.c_[np.asarray(t["x"], np.float64), np.asarray(t["y"], np.float64),
                         np.asarray(t["z"], np.float64)] for t in traces if "x" in t])  # fmt: skip
    P = P[np.all(np.isfinite(P), 1)]
    lo, hi = (P.min(0), P.max(0)) if len(P) else (np.zeros(3), np.ones(3))
    ext = float((hi - lo).max()) or 1.0
    pad = 0.05 * ext
    lo, hi = lo - pad, hi + pad
    span = np.maximum(hi - lo, 0.15 * ext)
    mid = (lo + hi) / 2
    ax = {"backgroundcolor": "#fafafa", "gridcolor": "#dcdcdc", "showbackground": True}
    out = {a: ax | {"title": {"text": esc(style.label(a[0], unit))},
                    "range": [float(mid[k] - span[k] / 2), float(mid[k] + span[k] / 2)]}
           for k, a in enumerate(("xaxis", "yaxis", "zaxis"))}  # fmt: skip
    r = span / span.max()
    flat = (hi - lo)[2] - 2 * pad < 0.2 * ext  # a planar scene: seen from above
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
    static = _static(view.scene, view.unit)
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
            upd += geo
        if marked:
            m = _mark_trace(p.mark)
            upd.append({k: m[k] for k in ("x", "y", "z")})
        frames.append({"name": p.label, "data": upd, "traces": idx})
    every = static + dyn + [t for f in frames for t in f["data"]]
    lay = _layout(esc(view.title), scene=_scene_layout(view.unit, every), height=640)
    lay["legend"] |= {"x": 0.0, "y": 1.0, "xanchor": "left", "yanchor": "top"}
    lay["uirevision"] = "robot"
    if len(view.poses) > 1:
        anim = {"mode": "immediate", "frame": {"duration": 0, "redraw": True},
                "transition": {"duration": 0}}  # fmt: skip
        lay["sliders"] = [{"active": 0, "currentvalue": {"prefix": "pose: ", "font": {"size": 12}},
                           "pad": {"t": 8, "b": 4}, "len": 0.96, "x": 0.02,
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
    lay = _layout(esc(f"{fv.title}: hover or click a design to draw its robot beside"),
                  esc(fv.xlabel), esc(fv.ylabel), showlegend=False, height=520)  # fmt: skip
    fplot = Plot(fid, {"data": [front], "layout": lay})
    scene = Scene(arms=list(fv.reference), region=fv.region)
    static = _static(scene, fv.unit)
    rs = radii([a for rb in fv.robots for a in rb] + list(fv.reference))
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
            {"data": upd, "layout": {"annotations[0].text": esc(f"design {i}: {fv.hover[i]}")}}
        )
    every = static + dyn + [{"x": x, "y": y, "z": z} for d in designs
                            for x, y, z in zip(d["data"]["x"], d["data"]["y"], d["data"]["z"], strict=True)]  # fmt: skip
    lay = _layout(esc("the robot of the design hovered or clicked on the front (common axes: "
                      "the designs compare by size)"),
                  scene=_scene_layout(fv.unit, every), height=520)  # fmt: skip
    lay["legend"] |= {"orientation": "h", "x": 0.0, "y": 0.0, "xanchor": "left",
                      "yanchor": "bottom"}  # fmt: skip  # the design's label goes on top
    lay["uirevision"] = "robot"
    lay["annotations"] = [{"text": esc(f"design 0: {fv.hover[0]}"), "xref": "paper",
                           "yref": "paper", "x": 0.0, "y": 1.0, "xanchor": "left",
                           "yanchor": "top", "showarrow": False, "font": {"size": 11},
                           "align": "left", "bgcolor": "rgba(255,255,255,0.8)"}]  # fmt: skip
    rplot = Plot(ids("robot-design"), {"data": static + dyn, "layout": lay,
                                       "link": {"source": fid, "traces": idx,
                                                "designs": designs}})  # fmt: skip
    return [fplot, rplot]


def robot_section(view: View | None = None, front: FrontView | None = None,
                  ids: _Ids | None = None) -> PageSection:  # fmt: skip
    """The page's "Robot" section: the view in its task and/or the front's robots."""
    ids = ids or _Ids()
    sec = PageSection("robot", "Robot")
    for v in (view, front):
        if v is not None and v.note:
            sec.items.append(f"<p class='note'>{esc(v.note)}</p>")
    if view is not None:
        sec.items.append(view_plot(view, ids))
    if front is not None:
        sec.items += front_plots(front, ids)
    return sec
