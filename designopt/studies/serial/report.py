"""The serial study's robot in the interactive report (``Study.robot``): the final design
of a run in its task with a slider through representative poses, or a Pareto front's
designs beside their robots (docs/figures.md, "The robot in the report"). What is drawn
is ``drawing``'s; this module picks the poses and designs."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.figures.robot import Scene
from designopt.studies.serial import blocks, figures  # noqa: F401  (blocks: tests patch it)
from designopt.studies.serial.drawing import (
    arms,
    design_poses,
    home,
    home_q,
    hover,
    meshes_note,
    obstacles_and_ports,
    original_arms,
    placement_text,
    slider_targets,
    study_arms,
    task_scene,
)
from designopt.studies.serial.figures import final_keys, task_solution
from designopt.studies.serial.mechanism import Mechanism, build
from designopt.studies.serial.settings import SerialSettings, UrdfChain, length_unit


def _budget(n: int) -> int | None:
    """Mesh triangles per robot when ``n`` robots share the report's budget (None
    below 200 a robot: too coarse to show, the meshes are left out)."""
    from designopt.figures.html.robot import TRIANGLES

    b = TRIANGLES // max(n, 1)
    return b if b >= 200 else None


def _poses(s: SerialSettings, mech: Mechanism, x: np.ndarray, Q: np.ndarray,
           labels: Sequence[str], inv_k: Sequence[float | None],
           marks: Sequence[np.ndarray | None]):  # fmt: skip
    from designopt.figures.html.robot import Pose

    row = arms(s, mech, [x], Q, labels=["final design"], colors=["#ff7f0e"],
               budget=_budget(len(Q)))[0]  # fmt: skip
    return [Pose(lab, [a], [hover(s, lab, q, k)], m)
            for lab, a, q, k, m in zip(labels, row, Q, inv_k, marks, strict=True)]  # fmt: skip


def run_view(rec: Any):
    """The report's view of a run's final design (``designopt.figures.html.View``).
    Under a task: the region, the tool-axis cone, the targets by 1/k and a slider
    through the reached targets at the 1/k :data:`QUANTILES`, the arm at each one's
    solution. Otherwise: the home pose, then the worst, median and best 1/k of the
    workspace figure's uniform joint samples."""
    from designopt.figures.html.robot import View

    s: SerialSettings = rec.config.study
    mech = build(s)
    x = np.asarray(list(rec.x.values()), np.float64)
    u = length_unit(s)
    q0 = home(mech)
    scene = Scene(arms=[], region=s.task.region if s.task is not None else None,
                  **obstacles_and_ports(s, x))  # fmt: skip
    if s.arms is not None:  # every arm at tuples of targets: the median, tightest, loosest
        from designopt.figures.html.robot import Pose
        from designopt.studies.serial.drawing import arm_tuples, arms_scene, tuple_stats

        fkeys = final_keys(rec)  # where final/'s values were measured
        sol_all = task_solution(rec)
        scene.targets = arms_scene(s, mech, x, sol_all, fkeys, budget=None).targets
        tup = arm_tuples(s, mech, x, sol_all, fkeys, budget=None)
        poses = [Pose(lab, row, [hover(s, a.label, q, None, k)
                                 for k, (a, q) in enumerate(zip(row, qs, strict=True))])
                 for lab, row, _, qs in tup]  # fmt: skip
        if not poses:
            q0 = home_q(s, mech)
            row = study_arms(s, mech, x, q0, budget=None)
            poses = [Pose("home pose", row, [hover(s, a.label, q0 if q0.ndim == 1 else q0[k], None, k)
                                             for k, a in enumerate(row)])]  # fmt: skip
        what = ("tuples of targets (one per arm): the median gap (first), the tightest (next "
                "step) and the loosest; " + tuple_stats(s, mech, sol_all, fkeys).text())
    elif s.indices.measure == "task":
        sol = task_solution(rec)
        p = np.asarray(sol["target_p"], np.float64)
        ts = task_scene(s, mech, x, sol, budget=None)
        scene.cone, scene.targets = ts.cone, ts.targets
        picks = slider_targets(sol)
        if picks:
            Q = np.stack([sol["q"][i] for _, i in picks])
            poses = _poses(s, mech, x, Q, [lab for lab, _ in picks],
                           [float(sol["inv_k"][i]) for _, i in picks], [p[i] for _, i in picks])  # fmt: skip
            what = "the reached targets at 1/k quantiles 0, 10, 25, 50, 75, 90, 100 %"
        else:
            poses = _poses(s, mech, x, q0[None], ["home pose"], [None], [None])
            what = "no target reached: the home pose"
    else:
        Qs = figures._uniform_q(mech, rec, 4000)
        z = figures.inv_k(mech, s, x, Qs)
        o = np.argsort(z, kind="stable")
        pick = [o[0], o[(len(o) - 1) // 2], o[-1]]
        Q = np.vstack([q0[None], Qs[pick]])
        labels = ["home pose"] + [f"{n} 1/k of 4000 samples" for n in ("worst", "median", "best")]
        kz = [float(figures.inv_k(mech, s, x, q0[None])[0])] + [float(z[i]) for i in pick]
        poses = _poses(s, mech, x, Q, labels, kz, [None] * 4)
        what = "the home pose and the worst, median and best 1/k of the workspace's joint samples"
    title = f"the final design ({_design_text(s, rec.x)}) at {what}; drag to rotate"
    note = meshes_note(s, dict(rec.x), q0, _budget(len(poses)))
    placed = placement_text(s, getattr(rec, "groups", {}).get("final", {}))
    if placed:  # the ports and bases drawn, in numbers
        note = (note + "; " if note else "") + placed
    return View(title=title, unit=u, scene=scene, poses=poses,
                note=(note + "; " if note else "") + "home pose: each joint at 0 where its "
                "limits allow, else mid-range")  # fmt: skip


def _design_text(s: SerialSettings, x: Mapping[str, float]) -> str:
    u = length_unit(s)
    ang = s.angle_names()
    return ", ".join(f"{k} = {v:.4g} {'deg' if k in ang else u}" for k, v in x.items())


def front_view(rec: Any):
    """The report's front view (``designopt.figures.html.FrontView``): the front's
    first two objectives and each design's robot, every arm at its base in the world,
    at a representative tuple of targets of its own solution on the front's re-scoring
    targets (``drawing.design_poses``; the home pose without a task), with the task
    region, obstacles and ports; the original
    robot of a URDF chain (at the home pose, the first design's bases) for reference."""
    from designopt.figures.html.robot import FrontView

    s: SerialSettings = rec.config.study
    mech = build(s)
    q0 = home(mech)
    X = rec.X
    n = len(X)
    objs, cols, labels = (v[:2] for v in figures.front_columns(rec))
    A = 1 if s.arms is None else len(s.arms)
    budget = _budget(A * (n + 1))
    poses = design_poses(*figures.front_stream(rec), mech, X)  # where front/ was measured
    robots = [study_arms(s, mech, X[i], Q, label="design", color="#ff7f0e", budget=budget)
              for i, (_, Q, _) in enumerate(poses)]  # fmt: skip
    ref = original_arms(s, mech, X[0], home_q(s, mech), budget=budget) \
        if isinstance(s.chain, UrdfChain) else []  # fmt: skip
    hov = []
    for i in range(n):
        d = dict(zip(s.variables, X[i], strict=True))
        objtxt = ", ".join(f"{name} = {c[i]:.4g}" for (name, _), c in zip(objs, cols, strict=True))
        fr = rec.groups["front"]
        placed = placement_text(s, {k: np.asarray(fr[k])[i] for k in ("ports", "bases")
                                     if k in fr})  # fmt: skip
        hov.append(f"{_design_text(s, d)}; {objtxt}" + (f"; {placed}" if placed else "")
                   + f"; drawn at {poses[i][0]}")  # fmt: skip
    where = ("at one representative tuple of targets of its own IK solution on the front's "
             "re-scoring targets (one arm: the reached target of median 1/k; several: the "
             "tuple of median gap between the arms, one target per arm as arms_ok draws them)"
             if s.indices.measure == "task" else
             "at the home pose (each joint at 0 where its limits allow, else mid-range)")  # fmt: skip
    note = (f"each design {where}" + ("; faint: the original robot (the URDF's numbers) at "
                                      "the home pose" if ref else ""))  # fmt: skip
    mn = meshes_note(s, dict(zip(s.variables, X[0], strict=True)), q0, budget)
    return FrontView(title=f"Pareto front ({n} designs)", unit=length_unit(s), x=cols[0],
                     y=cols[1], xlabel=labels[0], ylabel=labels[1], robots=robots, hover=hov,
                     x_se=rec.F_se[:, 0], y_se=rec.F_se[:, 1],  # the front's ± (F's order)
                     reference=ref, region=s.task.region if s.task is not None else None,
                     note=note + (f"; {mn}" if mn else ""), **_front_scene(s, X))  # fmt: skip


def _front_scene(s: SerialSettings, X: Any) -> dict[str, Any]:
    """The obstacles, ports and endoscopes a front's view draws: ports that the design
    moves differ from design to design, so every front design's are drawn then."""
    around = obstacles_and_ports(s)
    cam = s.task.camera if s.task is not None else None
    moved = cam is not None and any(isinstance(v, str) for v in cam.port)
    if not (s.designed_ports() or moved):
        return around
    each = [obstacles_and_ports(s, x) for x in np.asarray(X, np.float64)]
    ports = [p for a in each for p in a["ports"]]
    scopes = {(tuple(a), tuple(b)): (a, b) for e in each for a, b in e["scopes"]}
    return around | {"ports": [np.asarray(p) for p in dict.fromkeys(tuple(p) for p in ports)],
                     "scopes": list(scopes.values())}  # fmt: skip


def report(rec: Any) -> dict[str, Any] | None:
    """``Study.robot``: the run's view or the front's, and for a planning run its plan
    sheet (``plan``: ``plansheet.report_plan``) (None for other records)."""
    from designopt.results import FrontRecord, RunRecord
    from designopt.studies.serial.plansheet import report_plan

    if isinstance(rec, FrontRecord):
        return {"front": front_view(rec), "plan": report_plan(rec)}
    if isinstance(rec, RunRecord):
        return {"view": run_view(rec), "plan": report_plan(rec)}
    return None
