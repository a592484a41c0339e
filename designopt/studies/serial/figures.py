"""Figures of a serial-study run: convergence of f and its indices along the best run,
1/k over two joints for the initial and final design (one colour scale), and the final
design's workspace coloured by 1/k.

The map's joints are q2, q3 for chains of three or more joints (q1 turns the whole arm
about the base axis and leaves 1/k unchanged), else q1, q2. The other joints are held at
:func:`held`: each at its mid-range or a quarter point (mid ± range/4), whichever gives the
final design the most dexterous slice, joint by joint, so a slice never sits on a
singularity such as the PUMA 560's wrist at q5 = 0. The figure states where they are.

Under ``indices.measure: task`` the joint-space map gives way to the task figure
(:func:`draw_task`): the task's targets coloured by 1/k at the final design's IK solution,
unreached targets as grey crosses; the report's cloud (:func:`cloud`) shows the same."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.figures import MAP_RESOLUTION, convergence, robot, save, style
from designopt.numerics import montecarlo as mc
from designopt.results import RunRecord
from designopt.studies.serial import blocks, drawing, taskindex
from designopt.studies.serial.mechanism import Mechanism, build
from designopt.studies.serial.objective import measures
from designopt.studies.serial.settings import ROWS, SerialSettings, UrdfChain, length_unit, units

RATES = ("reach",)
"""Success rates (``reach``, under ``measure: task``): clipped to [0, 1], Wilson band."""


def STUDY_UNITS(s: SerialSettings) -> dict[str, str]:  # noqa: N802
    return units(s)


def _full(mech: Mechanism, x: np.ndarray) -> np.ndarray:
    """(M, P) kernel parameters of designs x (M, variables)."""
    x = np.atleast_2d(np.asarray(x, np.float64))
    fixed = np.broadcast_to(mech.fixed, (x.shape[0], len(mech.fixed)))
    return (np.concatenate([x, fixed], -1) * mech.scale).astype(mc.out_dtype())


def _kernel(mech: Mechanism, s: SerialSettings):
    """jit(X (M, P), q (C, n)) → (1/k (M, C), tip positions (M, C, 3)), with the index
    kernel's Jacobian rows, length scale and norm."""
    rows = s.indices.rows()
    sc = np.array([1.0 if r < 3 else s.indices.length_scale for r in rows])

    def f(X, q):
        J = mech.model.jacobian(X, q, rows=rows) * jnp.asarray(sc, X.dtype)[:, None]
        return measures(J, s.indices.norm, s.indices.normalized)[0], mech.model.fk(X, q)[1]

    return jax.jit(f)


def inv_k(mech: Mechanism, s: SerialSettings, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """1/k of the configured Jacobian rows for one design x (variables) at q (C, n)."""
    return np.asarray(_kernel(mech, s)(_full(mech, x), q.astype(mc.out_dtype()))[0][0])


def _unit(mech: Mechanism, i: int, s: SerialSettings) -> tuple[float, str]:
    """(factor, unit) of active joint i on an axis: degrees, or the chain's length unit."""
    return (180 / np.pi, "deg") if _revolute(s, i) else (1.0, length_unit(s))


def _revolute(s: SerialSettings, i: int) -> bool:
    if isinstance(s.chain, UrdfChain):
        return s.chain.imported.types[i] == "R"
    return s.chain.joints[i].type == "R"


def map_joints(n: int) -> tuple[int, int]:
    """The two joints a map is drawn over (see the module docstring)."""
    return (1, 2) if n >= 3 else (0, min(1, n - 1))


def _grid(lo, hi, pair, held, n):
    ga, gb = np.linspace(lo[pair[0]], hi[pair[0]], n), np.linspace(lo[pair[1]], hi[pair[1]], n)
    A, B = np.meshgrid(ga, gb, indexing="xy")
    q = np.tile(held, (A.size, 1))
    q[:, pair[0]], q[:, pair[1]] = A.ravel(), B.ravel()
    return ga, gb, q


def held(mech: Mechanism, s: SerialSettings, X: np.ndarray, pair: tuple[int, int],
         n: int = 15) -> np.ndarray:  # fmt: skip
    """Where the joints off the map are held (rad / length): joint by joint, the mid-range
    or quarter point (mid ± range/4) with the largest mean 1/k of design ``X`` (1, P) over
    a coarse n×n slice."""
    lo, hi = mech.lower, mech.upper
    q = 0.5 * (lo + hi)
    kern = _kernel(mech, s)
    for j in (j for j in range(mech.n) if j not in pair):
        cands = q[j] + np.array([0.0, 0.25, -0.25]) * (hi[j] - lo[j])
        qs = []
        for v in cands:
            h = q.copy()
            h[j] = v
            qs.append(_grid(lo, hi, pair, h, n)[2])
        z = np.asarray(kern(X, np.concatenate(qs).astype(X.dtype))[0][0]).reshape(len(cands), -1)
        q[j] = cands[int(np.argmax(z.mean(axis=1) - 1e-9 * np.arange(len(cands))))]
    return q


def draw_run(rec: RunRecord, folder: Path, resolution: int = MAP_RESOLUTION) -> list[Path]:
    """Convergence, 1/k map (``resolution``² points) and workspace of a run record; under
    ``measure: task`` the task figure (:func:`draw_task`) instead of the map."""
    s: SerialSettings = rec.config.study
    mech = build(s)
    br = rec.best_run
    designs = {
        "initial (iteration 0)": rec.history_x[rec.best_run_index, 0],
        "final": np.asarray(list(rec.x.values()), np.float64),
    }
    out = []
    task = s.indices.measure == "task"
    # trials: the targets the search scored each design on (optimizer.fidelity may set
    # another count than the study's: n_samples_search), the study's own in older archives
    rates = {"reach": float(rec.n_samples_search or taskindex.n_targets(s))} if task else None
    out += convergence(br, ["f", *s.index_names()], folder, "Best run: objective and indices",
                       units=STUDY_UNITS(s), rates=rates, fidelity=rec.fidelity)  # fmt: skip
    if task:  # 1/k over a joint slice says little about a task
        sol = task_solution(rec)  # one solution for the task, workspace and robot figures
        if has_ports(s):  # an instrument held in a port: the targets, not random joints
            ws = draw_targets(rec, folder, sol)
        else:
            X = _full(mech, designs["final"])
            z, P = _kernel(mech, s)(X, _uniform_q(mech, rec, 4000).astype(X.dtype))
            ws = _workspace(np.asarray(P[0]), np.asarray(z[0]), s, folder, rec)
        out += draw_task(rec, folder, sol) + ws + draw_robot(rec, folder, sol)
        if has_ports(s):  # a planning run: the plan sheet (plansheet.py)
            from designopt.studies.serial import plansheet

            out += plansheet.run_plan(rec, folder)
        return out

    rows_txt = ", ".join(ROWS[r] for r in s.indices.rows())
    lo, hi = mech.lower, mech.upper
    X = _full(mech, np.stack(list(designs.values())))
    pair = map_joints(mech.n)
    n = resolution if mech.n >= 2 else 0  # the map needs two joints
    hq = held(mech, s, X[-1:], pair) if n else 0.5 * (lo + hi)
    ga, gb, qg = _grid(lo, hi, pair, hq, n)
    qc = _uniform_q(mech, rec, 4000)
    z, P = _kernel(mech, s)(X, np.concatenate([qg, qc]).astype(X.dtype))  # one XLA program
    z, P = np.asarray(z), np.asarray(P)
    m2 = ga.size * gb.size
    if mech.n >= 2:
        fa, ua = _unit(mech, pair[0], s)
        fb, ub = _unit(mech, pair[1], s)
        fig, axes = style.subplots(1, 2, figsize=(10, 4.0))
        ims = []
        for i, (ax, lab) in enumerate(zip(axes, designs, strict=True)):
            zi = z[i, :m2].reshape(gb.size, ga.size)
            ims.append(ax.pcolormesh(ga * fa, gb * fb, zi, shading="auto", cmap="viridis",
                                     rasterized=True))  # fmt: skip
            ax.set_xlabel(style.label(f"q{pair[0] + 1}", ua))
            ax.set_ylabel(style.label(f"q{pair[1] + 1}", ub))
            ax.set_title(f"{lab}: mean {zi.mean():.4g}", fontsize=9)
        style.shared_scale(fig, ims)
        fig.colorbar(ims[0], ax=list(axes), label=style.label("1/k", style.DIMENSIONLESS))
        others = [j for j in range(mech.n) if j not in pair]
        txt = style.held_text({f"q{j + 1}": f"{hq[j] * _unit(mech, j, s)[0]:.3g} "
                               f"{_unit(mech, j, s)[1]}" for j in others})  # fmt: skip
        fig.suptitle(f"1/k ({s.indices.norm}-norm; rows {rows_txt}) over q{pair[0] + 1}, "
                     f"q{pair[1] + 1}" + (f"\nother joints {txt}" if txt else
                                           "\n(q1 turns the whole arm: 1/k does not change along it)"),
                     fontsize=10)  # fmt: skip
        out += save(fig, folder, "dexterity_map")

    return out + _workspace(P[-1, m2:], z[-1, m2:], s, folder, rec) + draw_robot(rec, folder)


def _workspace(p: np.ndarray, c: np.ndarray, s: SerialSettings, folder: Path,
               rec: RunRecord | None = None) -> list[Path]:  # fmt: skip
    """The final design's tip positions p (C, 3) (in an arm's base frame) coloured by
    1/k c (C,), with the final design drawn at its home pose (``drawing.home``), every
    arm at its base in the world with its own tip positions where the study has several,
    the task region, obstacles and ports."""
    fig = style.figure(figsize=(5.8, 5.4))
    L = STUDY_UNITS(s).get("__length__", "L")
    arm, home_txt = [], ""
    region = s.task.region if s.task is not None else None
    if rec is not None:
        mech = build(s)
        q = drawing.home_q(s, mech)
        x = np.asarray(list(rec.x.values()), np.float64)
        arm = drawing.study_arms(s, mech, x, q, label="final design at its home pose")
        p, c = _in_world(p, c, [a.base for a in arm])
        home_txt = ("\nthe arm at its home pose (each joint at 0 where its limits\nallow, "
                    "else mid-range)")  # fmt: skip
        if s.arms is not None:
            home_txt = (f"\n(each of the {len(arm)} arms at its base) and the arms at their "
                        "home pose\n(each joint at 0 where its limits allow, else mid-range)")  # fmt: skip
    planar = np.ptp(p[:, 2]) <= 1e-9 * max(np.ptp(p[:, :2]), 1e-300)
    design = None if rec is None else dict(rec.x)
    scene = robot.Scene(arms=arm, region=region, **drawing.obstacles_and_ports(s, design),
                        targets=robot.Targets(p, c, np.ones(len(p), bool), size=1.5, alpha=1.0))  # fmt: skip
    if planar:
        ax = fig.add_subplot(1, 1, 1)
        sc = ax.scatter(p[:, 0], p[:, 1], s=2, c=c, cmap="viridis", rasterized=True)
        robot.draw_2d(ax, arm, np.eye(3)[:, :2])
        robot.draw_obstacles_2d(ax, scene, np.eye(3)[:, :2])
        if region is not None:
            robot.draw_region_2d(ax, region, np.eye(3)[:, :2])
        ax.set_aspect("equal", adjustable="datalim")
    else:
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        sc = robot.draw_3d(ax, scene, L, legend=False)
    ax.set_xlabel(style.label("x", L))
    ax.set_ylabel(style.label("y", L))
    fig.colorbar(sc, ax=ax, label=style.label("1/k", style.DIMENSIONLESS), shrink=0.7, pad=0.1)
    import textwrap

    clip = textwrap.wrap(robot.clipped_note([scene], L), 60)
    ax.set_title(f"final design: tip positions of {len(c) // max(len(arm), 1)} uniform joint "
                 "samples" + home_txt + ("\n(L: the chain's length unit)" if L == "L" else "")
                 + "".join(f"\n{ln}" for ln in clip), fontsize=9, y=1.0)  # fmt: skip
    handles = robot.legend_handles(robot.Scene(arms=arm, obstacles=scene.obstacles,
                                               ports=scene.ports))  # fmt: skip
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=7.5)
    return save(fig, folder, "workspace")


def _in_world(p: np.ndarray, c: np.ndarray, bases: list) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions p (C, 3) in an arm's base frame and their values c, placed by each
    base pose (4 × 4; None: the world) and stacked."""
    if all(T is None for T in bases):
        return p, c
    P = [p if T is None else p @ np.asarray(T)[:3, :3].T + np.asarray(T)[:3, 3] for T in bases]
    return np.vstack(P), np.tile(c, len(bases))


def has_ports(s: SerialSettings) -> bool:
    """Whether the study's instruments pass ports (``arms[k].port`` or ``task.port``)."""
    return s.task is not None and s.ports()[0] is not None


def _inside(scene: robot.Scene) -> list[np.ndarray]:
    """The vertices of the scene's anatomy (obstacles ``inside`` the patient)."""
    return [robot.obstacle_mesh(ob, np.zeros(3), 1.0)[0] for ob in scene.obstacles
            if getattr(ob, "inside", False)]  # fmt: skip


def draw_targets(rec: RunRecord, folder: Path,
                 sol_all: dict[str, np.ndarray] | None = None) -> list[Path]:  # fmt: skip
    """``workspace`` of a task whose instruments pass ports: the task's targets in the
    patient's frame (the world, where the region, ports and anatomy are given), coloured
    by 1/k at the final design's IK solution (several arms: the arms' mean where every
    arm reaches the target), the others as grey crosses, with the region, the ports and
    the anatomy (the view holds them all). A cloud of random joint draws would say
    nothing of an instrument held in a port."""
    import textwrap

    s: SerialSettings = rec.config.study
    sol_all = task_solution(rec) if sol_all is None else sol_all
    many = s.arms is not None
    sol = drawing.combined(sol_all) if many else sol_all
    p = np.asarray(sol["target_p"], np.float64)
    ok = np.asarray(sol["success"], bool)
    L = STUDY_UNITS(s).get("__length__", "L")
    around = drawing.obstacles_and_ports(s, dict(rec.x))
    outer = [ob for ob in around["obstacles"] if not getattr(ob, "inside", False)]
    around["obstacles"] = [ob for ob in around["obstacles"] if getattr(ob, "inside", False)]
    scene = robot.Scene(arms=[], region=s.task.region if s.task is not None else None,
                        targets=robot.Targets(p, np.asarray(sol["inv_k"], np.float64), ok,
                                              "1/k", size=14.0, alpha=0.9), **around)  # fmt: skip
    limits = np.vstack([robot.scene_points(scene), *_inside(scene)])
    fig = style.figure(figsize=(7.4, 6.6))
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    sc = robot.draw_3d(ax, scene, L, legend=False, limits=limits)
    if sc is not None:
        fig.colorbar(sc, ax=ax, label=style.label("1/k", style.DIMENSIONLESS), shrink=0.6,
                     pad=0.12)  # fmt: skip
    rows_txt = ", ".join(ROWS[r] for r in s.indices.rows())
    who = f"the mean of the {len(s.arms)} arms where every arm reaches it" if many else ""
    bad = int((~ok).sum())
    head = (f"the task's {len(p)} targets in the patient's frame, coloured by 1/k "
            f"({s.indices.norm}-norm; rows {rows_txt}) at the final design's IK solution"
            + (f" ({who})" if who else "") + f"; {'not reached by every arm' if many else 'unreached'}"
            f" (grey crosses): {bad} of {len(p)}; with the ports and the anatomy"
            + (f"; not drawn, so as not to hide them: the body wall and the obstacles outside "
               f"the patient ({len(outer)})" if outer else ""))  # fmt: skip
    clip = robot.clipped_note([scene], L, limits)
    ax.set_title("\n".join(textwrap.wrap(head, 80) + textwrap.wrap(clip, 80)), fontsize=8.5,
                 y=1.0)  # fmt: skip
    handles = robot.legend_handles(scene)
    if bad:
        from matplotlib.lines import Line2D

        handles.insert(0, Line2D([], [], marker="x", color="0.45", ls="none",
                                 label="not reached by every arm" if many else "unreached"))  # fmt: skip
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=7.5)
    return save(fig, folder, "workspace")


def _one_robot(rec: RunRecord, sol: dict[str, np.ndarray] | None) -> robot.Scene:
    """The final design in one panel where no link geometry is a design variable: every
    arm at the median tuple of targets (several arms, colliding pairs marked), one arm at
    its reached target of median 1/k, the home pose without a task; with the region,
    obstacles and ports; the panel's title says where."""
    s: SerialSettings = rec.config.study
    mech = build(s)
    x = np.asarray(list(rec.x.values()), np.float64)
    region = s.task.region if s.task is not None else None
    around = {"region": region, **drawing.obstacles_and_ports(s, dict(rec.x))}
    if sol is not None and s.arms is not None:
        tup = drawing.arm_tuples(s, mech, x, sol, final_keys(rec), counted=False)
        if tup:
            st = drawing.tuple_stats(s, mech, sol, final_keys(rec))
            label, arms, pairs, _ = tup[0]
            perm = drawing._tuples(s, mech, sol, final_keys(rec))[0]
            tg = [np.asarray(sol["target_p"])[perm[k][st.median]]
            for k in s.instrument_arms()]  # the camera arm's target is the scope's
            return robot.Scene(arms=arms, collisions=pairs, marks=[(t, "#d62728") for t in tg],
                               title=f"the final design at the {label}\n{st.text()}", **around)  # fmt: skip
    if sol is not None:
        label, Q, tg = drawing.representative(s, mech, sol)
        arms = drawing.study_arms(s, mech, x, Q if s.arms is not None else Q[0],
                                  label="final design", color="#ff7f0e")  # fmt: skip
        return robot.Scene(arms=arms, marks=[(t, "#d62728") for t in tg],
                           title=f"the final design at {label}", **around)  # fmt: skip
    q = drawing.home_q(s, mech)
    arms = drawing.study_arms(s, mech, x, q, label="final design", color="#ff7f0e")
    return robot.Scene(arms=arms, title="the final design at the home pose (each joint at 0 "
                       "where its limits allow, else mid-range)", **around)  # fmt: skip


def draw_robot(rec: RunRecord, folder: Path,
               sol: dict[str, np.ndarray] | None = None) -> list[Path]:  # fmt: skip
    """A URDF chain's original robot (the file's numbers in every ``set`` field) beside
    the final design at the same pose (the home pose), the changed numbers in m / deg;
    nothing for a DH chain (it has no original). Where no link geometry is a design
    variable (no ``set`` field: only bases or ports are), the two would be the same
    robot: one panel instead, the final design at the median tuple of targets
    (:func:`_one_robot`; ``sol``: the run's task solution, computed when None)."""
    s: SerialSettings = rec.config.study
    if not isinstance(s.chain, UrdfChain):
        return []
    mech = build(s)
    q = drawing.home(mech)
    design = dict(rec.x)
    x = np.asarray(list(design.values()), np.float64)
    region = s.task.region if s.task is not None else None
    import textwrap

    if not drawing.changes(s, design):  # no link length is a variable: one robot
        task = s.indices.measure == "task"
        sol = (task_solution(rec) if sol is None else sol) if task else None
        scene = _one_robot(rec, sol)
        note = drawing.meshes_note(s, design, q)
        head = (f"{Path(s.chain.urdf).name}: the final design ({_design(s, design)}); no link "
                "geometry is a design variable (only the bases and ports are), so the robot is "
                "the URDF's own")  # fmt: skip
        fig = robot.figure([scene], length_unit(s), "\n".join([head] + ([note] if note else [])),
                           size=7.0)  # fmt: skip
        return save(fig, folder, "robot")
    qa = drawing.home_q(s, mech)  # (every arm's own, with arms of several robots)
    orig = drawing.original_arms(s, mech, x, qa)  # every arm at its base in the world
    final = drawing.study_arms(s, mech, x, qa, label="final design", color="#ff7f0e")
    note = drawing.meshes_note(s, design, q)
    around = drawing.obstacles_and_ports(s, design)  # the patient and the port, where configured
    scenes = [robot.Scene(arms=orig, region=region, title="original: the URDF's own numbers",
                          **around),
              robot.Scene(arms=final, region=region, title="final design", **around)]  # fmt: skip
    title = (f"{Path(s.chain.urdf).name} at the home pose ({drawing.joint_values(s, q)}; each joint at 0 "
             "where its limits allow, else mid-range)")  # fmt: skip
    changed = "final design: " + drawing.changes_text(s, design).replace("\n", "; ")
    title = "\n".join(textwrap.wrap(title, 110) + textwrap.wrap(changed, 110)
                      + ([note] if note else []))  # fmt: skip
    fig = robot.figure(scenes, length_unit(s), title)
    return save(fig, folder, "robot")


def draw_front_robots(rec: Any, picks: Sequence[tuple[str, int]], folder: Path) -> list[Path]:
    """``front_robots``: the front's chosen designs (``figures.front.extremes_and_knee``:
    the two extremes and the knee) side by side on common axes, each with every arm at
    its base in the world, at one representative tuple of targets of its own IK
    solution on the front's re-scoring targets (:func:`front_stream`, where its values
    were measured; ``drawing.design_poses``; the home pose without a task), with the task
    region, obstacles and ports; the targets starred. A two-line title; the numbers
    (objectives, design variables, the pose drawn, incision points and bases) in a table
    and text rows under the panels. A planning study (instruments through ports) is
    zoomed on the patient: the view holds the task region, the ports, the anatomy and the
    starred targets, the robots clipped to it; its plan sheet (``plan.png``) follows."""
    s: SerialSettings = rec.config.study
    if not picks:
        return []
    mech = build(s)
    objs, cols, _ = front_columns(rec)
    region = s.task.region if s.task is not None else None
    u = length_unit(s)
    ang = s.angle_names()
    scenes, rows, notes = [], [], []
    fr = getattr(rec, "groups", {}).get("front", {})
    drawn = list(zip(picks, ("#2ca02c", "#ff7f0e", "#9467bd"), strict=False))
    poses = drawing.design_poses(*front_stream(rec), mech, rec.X[[i for (_, i), _ in drawn]])
    for ((name, i), col), (label, Q, tg) in zip(drawn, poses, strict=True):
        arms = drawing.study_arms(s, mech, rec.X[i], Q, color=col,  # several: "arm k"
                                  label=f"design {i}" if s.arms is None else "")  # fmt: skip
        around = {"region": region, **drawing.obstacles_and_ports(s, rec.X[i])}  # its ports
        scenes.append(robot.Scene(arms=arms, title=f"{name}: design {i}",
                                  marks=[(p, "#d62728") for p in tg], **around))  # fmt: skip
        rows.append([f"{name}: design {i}", *(f"{c[i]:.4g}" for c in cols),
                     *(f"{v:.4g}" for v in rec.X[i])])  # fmt: skip
        notes.append(f"{name} (design {i}): drawn at {label}")
        if "ports" in fr:  # the incision points and bases of this design, in numbers
            notes.append("    " + drawing.placement_text(s, {k: np.asarray(fr[k])[i] for k in
                                                         ("ports", "bases") if k in fr}))  # fmt: skip
    units = rec.units() if hasattr(rec, "units") else {}
    head = ["design", *(style.label(f"{k} ({sense})", units.get(k, "-")) for k, sense in objs),
            *(style.label(k, "deg" if k in ang else u) for k in s.variables)]  # fmt: skip
    where = ("at its tuple of targets of median gap between the arms (stars)" if s.arms is not None
             else "at its reached target of median 1/k (star)"
             ) if s.indices.measure == "task" else "at the home pose"  # fmt: skip
    title = (f"The front's extremes and knee ({len(rec.X)} designs; knee: farthest from the "
             f"extremes' line)\neach {where}")  # fmt: skip
    limits = None
    if has_ports(s):  # zoomed on the patient: region, ports, anatomy, the starred targets
        pts = [np.vstack([robot.scene_points(robot.Scene(arms=[], region=sc.region,
                                                         marks=sc.marks, ports=sc.ports)),
                          *_inside(sc)]) for sc in scenes]  # fmt: skip
        limits = np.vstack(pts)
        notes.append("the view holds the task region, the ports (white circles), the anatomy and "
                     "the starred targets; the robots, the body wall and the other obstacles are "
                     "cut at its edge (each arm's links within it drawn as thick lines)")  # fmt: skip
        title += "; zoomed on the patient"
    fig = robot.figure(scenes, u, title, size=5.6 if limits is not None else 5.0,
                       limits=limits, zoom=1.1 if limits is not None else 1.0,
                       table=(head, rows), notes=notes, min_width=10.0)  # fmt: skip
    out = save(fig, folder, "front_robots")
    if has_ports(s):  # a planning front: the plan sheet of its knee (plansheet.py)
        from designopt.studies.serial import plansheet

        out += plansheet.front_plan(rec, picks, folder)
    return out


def front_columns(rec: Any) -> tuple[list[tuple[str, str]], list[np.ndarray], list[str]]:
    """A front's objectives: (name, sense), their values in the indices' own terms (a
    ``max`` objective not negated: ``front/<name>`` where archived, else ``front/f``,
    which holds them so too; docs/pareto.md), their axis labels."""
    n = len(rec.X)
    objs = list(rec.objectives.items())
    cols = []
    for k, (name, _) in enumerate(objs):
        v = rec.values.get(name)
        cols.append(np.asarray(rec.F[:, k] if v is None or np.shape(v) != (n,) else v, np.float64))
    units = rec.units() if hasattr(rec, "units") else {}
    return objs, cols, [f"{name} ({sense}) [{units.get(name, '-')}]" for name, sense in objs]


def _design(s: SerialSettings, x: dict[str, float]) -> str:
    u = length_unit(s)
    ang = s.angle_names()
    return ", ".join(f"{k}\u00a0=\u00a0{v:.4g}\u00a0{'deg' if k in ang else u}"
                     for k, v in x.items())  # no break inside a value


def _uniform_q(mech: Mechanism, rec: RunRecord, n: int) -> np.ndarray:
    """n joint vectors uniform in the limits from the run's ``figures`` stream (NumPy: no
    threefry compile)."""
    rng = np.random.default_rng(np.asarray(jax.random.key_data(rec.keys()["figures"]), np.uint32))
    return mech.lower + (mech.upper - mech.lower) * rng.uniform(size=(n, mech.n))


def final_keys(rec: Any) -> Any:
    """The named keys of the samples the record's ``final/`` values are on (the fresh
    ``final`` stream, ``RunRecord.final_stream``; a record without one: its own)."""
    fs = getattr(rec, "final_stream", None)
    return fs()[1] if fs is not None else rec.keys()


def front_stream(rec: Any) -> tuple[SerialSettings, Any]:
    """(study settings, named keys) of the samples a front's ``front/`` values are on (the
    fresh ``front`` stream, ``FrontRecord.front_stream``; a record without one: its own):
    where its designs are drawn."""
    fs = getattr(rec, "front_stream", None)
    return fs() if fs is not None else (rec.config.study, rec.keys())


def task_solution(rec: RunRecord) -> dict[str, np.ndarray]:
    """The final design's per-target solution on the targets its ``final/`` values were
    measured on (``blocks.solution`` on ``RunRecord.final_stream``): targets, success,
    1/k, joints."""
    fs = getattr(rec, "final_stream", None)
    s, keys = fs() if fs is not None else (rec.config.study, rec.keys())
    return blocks.solution(s, rec.x, keys)


def plane(p: np.ndarray, rtol: float = 1e-9) -> tuple[np.ndarray, tuple[str, str]] | None:
    """The plane holding every point of p (N, 3) as (E (3, 2): orthonormal in-plane axes,
    their names), or None when the points span three dimensions (thicker than ``rtol`` ×
    their extent). A plane normal to a coordinate axis keeps the other two (x, y; x, z;
    y, z); another plane gets u, v, its principal directions."""
    c = p - p.mean(0)
    ext = float(np.max(np.ptp(p, 0))) if len(p) else 0.0
    _, _, vt = np.linalg.svd(c, full_matrices=True)
    if len(p) > 2 and np.max(np.abs(c @ vt[2])) > rtol * max(ext, 1e-300):
        return None
    n = vt[2]
    for k in range(3):
        if abs(abs(n[k]) - 1.0) <= 1e-9:
            keep = [i for i in range(3) if i != k]
            return np.eye(3)[:, keep], ("xyz"[keep[0]], "xyz"[keep[1]])
    return vt[:2].T, ("u", "v")


def _vec(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{a:.3g}" for a in v) + ")"


def _task_caption(rec: RunRecord, sol_all: dict[str, np.ndarray], sol: dict[str, np.ndarray],
                  L: str) -> str:  # fmt: skip
    """Title lines: the design, reach ± SE and gci ± SE of the solution ``sol_all`` (the
    archive's own when they differ), what is drawn (``sol``: with several arms, the
    targets every arm reaches)."""
    import textwrap

    s: SerialSettings = rec.config.study
    units = STUDY_UNITS(s)
    lead = (slice(None), None) if s.arms is not None else (None, None)  # (A, M = 1, N)
    per = {k: sol_all[k][lead].astype(np.float64) for k in ("success", "inv_k",
           "manipulability", "joint_margin")}  # fmt: skip
    est = jax.jit(taskindex.estimates, static_argnames="grp")(per, grp=taskindex.groups(s))
    est = {k: (float(v[0][0]), float(v[1][0])) for k, v in est.items()}
    des = ", ".join(f"{k} = {v:.4g} {units.get(k, L)}" for k, v in rec.x.items())
    line = f"reach {est['reach'][0]:.3f} ± {est['reach'][1]:.2g}, gci {est['gci'][0]:.3f} ± " \
           f"{est['gci'][1]:.2g} (± SE; unreached targets count 0)"  # fmt: skip
    arch = rec.indices
    if any(k in arch and abs(arch[k][0] - est[k][0]) > 1e-9 * max(1.0, abs(est[k][0]))
           for k in ("reach", "gci")):  # fmt: skip
        line += f"; archive: reach {arch['reach'][0]:.3f}, gci {arch['gci'][0]:.3f}"
    rows_txt = ", ".join(ROWS[r] for r in s.indices.rows())
    N, bad = len(sol["success"]), int(np.sum(~sol["success"]))
    what = (f"1/k ({s.indices.norm}-norm; rows {rows_txt}) at the IK solution of each of {N} "
            f"targets; " + (f"unreached (grey crosses): {bad}" if bad else "every target reached"))  # fmt: skip
    if s.arms is not None:
        what = (f"{len(s.arms)} arms: the mean 1/k of the arms ({s.indices.norm}-norm; rows "
                f"{rows_txt}) where every arm reaches the target, of {N}; not reached by "
                f"every arm (grey crosses): {bad}; the arms drawn at one tuple of targets "
                "(one per arm, as arms_ok draws them): the median by the arms' clearance, "
                "colliding pairs in red")  # fmt: skip
    ta = s.task.tool_axis  # type: ignore[union-attr]
    if ta is not None:
        what += f"; tool axis within {ta.cone:g}° of {_vec(np.asarray(ta.direction))}"
    warn = [ln for w in rec.warnings for ln in textwrap.wrap("WARNING: " + w, 90)]
    placed = drawing.placement_text(s, getattr(rec, "groups", {}).get("final", {}))
    placed_lines = textwrap.wrap("incision points and bases (world): " + placed, 90) if placed else []
    return "\n".join(textwrap.wrap("final design: " + des, 90) + placed_lines + [line]
                     + textwrap.wrap(what, 90) + warn)  # fmt: skip


def _task_panel(ax, a: np.ndarray, b: np.ndarray, c: np.ndarray, ok: np.ndarray, size: float):
    """Reached targets coloured by 1/k (the least drawn last, on top), unreached as grey
    crosses over them; returns the colour mappable."""
    o = np.argsort(-c[ok], kind="stable")
    sc = ax.scatter(a[ok][o], b[ok][o], c=c[ok][o], s=size, cmap="viridis", lw=0,
                    rasterized=True)  # fmt: skip
    if (~ok).any():
        ax.scatter(a[~ok], b[~ok], marker="x", s=2.5 * size + 6, c="0.45", lw=0.8,
                   rasterized=True, label="unreached")  # fmt: skip
    return sc


def _in_plane(pts: np.ndarray, p: np.ndarray, E: np.ndarray) -> bool:
    """Whether every point of pts lies in the plane through p's mean spanned by E."""
    n = np.cross(E[:, 0], E[:, 1])
    ext = max(float(np.ptp(np.vstack([pts, p]), 0).max()), 1e-300)
    return bool(np.all(np.abs((pts - p.mean(0)) @ n) <= 1e-9 * ext))


def draw_task(rec: RunRecord, folder: Path,
              sol_all: dict[str, np.ndarray] | None = None) -> list[Path]:  # fmt: skip
    """The task figure: every target of the run coloured by 1/k at the final design's IK
    solution, unreached targets as grey crosses; a planar task in its plane, a 3-D one as
    a top view (x, y) and a side view (x or y, whichever spreads more, against z), the
    least dexterous target on top along each line of sight. The region's outline is
    drawn in each view, and the final design at its worst-conditioned, median and
    best-conditioned targets (``drawing.representatives``): in the task's plane when
    the arms lie in it, else in a third, 3-D panel with the region, the tool-axis cone
    and the targets."""
    s: SerialSettings = rec.config.study
    sol_all = task_solution(rec) if sol_all is None else sol_all
    mech = build(s)
    x = np.asarray(list(rec.x.values()), np.float64)
    if s.arms is not None:  # every arm at one tuple of targets; targets where all reach
        sol = drawing.combined(sol_all)
        scene = drawing.arms_scene(s, mech, x, sol_all, final_keys(rec))
    else:
        sol = sol_all
        scene = drawing.task_scene(s, mech, x, sol)
    p, ok = sol["target_p"], sol["success"]
    c = sol["inv_k"]
    L = STUDY_UNITS(s).get("__length__", "L")
    N = len(ok)
    size = float(np.clip(6000.0 / max(N, 1), 2.0, 30.0))
    arm_pts = np.vstack([a.points() for a in scene.arms]) if scene.arms else p[:1]
    pl = plane(p)
    flat = pl is not None and _in_plane(arm_pts, p, pl[0])
    if pl is not None:
        E, names = pl
        uv = p @ E
        if flat:
            fig, ax = style.subplots(1, 1, figsize=(6.2, 6.2))
            axes = [ax]
        else:
            fig = style.figure(figsize=(12.5, 6.4))
            gs = fig.add_gridspec(1, 2, width_ratios=[1.0, 1.2])
            axes = [fig.add_subplot(gs[0, 0])]
        views = [(uv[:, 0], uv[:, 1], names, E)]
    else:
        side = 0 if np.ptp(p[:, 0]) >= np.ptp(p[:, 1]) else 1
        fig = style.figure(figsize=(17.0, 6.2))
        gs = fig.add_gridspec(1, 3, width_ratios=[1.0, 1.0, 1.35])
        axes = [fig.add_subplot(gs[0, k]) for k in range(2)]
        views = [(p[:, 0], p[:, 1], ("x", "y"), np.eye(3)[:, [0, 1]]),
                 (p[:, side], p[:, 2], ("xy"[side], "z"), np.eye(3)[:, [side, 2]])]  # fmt: skip
    scs = []
    for ax, (a, b, (na, nb), E_) in zip(axes, views, strict=True):
        scs.append(_task_panel(ax, a, b, c, ok, size))
        robot.draw_region_2d(ax, scene.region, E_)
        robot.draw_obstacles_2d(ax, scene, E_)
        if flat:
            robot.draw_2d(ax, scene.arms, E_, alpha=0.35)
            for pt, col in scene.marks:
                uvp = pt @ E_
                ax.plot(uvp[0], uvp[1], marker="*", ms=11, color=col, mec="k", mew=0.5, ls="none")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(style.label(na, L))
        ax.set_ylabel(style.label(nb, L))
        ax.grid(alpha=0.25)
    if pl is None:
        axes[0].set_title("top view (x, y); the least 1/k on top", fontsize=9, y=1.0)
        axes[1].set_title(f"side view ({'xy'[side]}, z); the least 1/k on top", fontsize=9,
                          y=1.0)  # fmt: skip
    elif names == ("u", "v"):
        axes[0].set_title(f"in the targets' plane: u = {_vec(E[:, 0])}, v = {_vec(E[:, 1])}",
                          fontsize=9, y=1.0)  # fmt: skip
    style.shared_scale(fig, scs, 0.0 if not ok.any() else None)
    if not flat:  # the arms in 3-D, with the region, the tool-axis cone and the targets
        ax3 = fig.add_subplot(gs[0, len(axes)], projection="3d")
        if s.arms is not None:
            scene.title = ("every arm at the " + scene.title.replace(": ", ":\n", 1)
                           if scene.arms else "no tuple every arm reaches: no arm drawn")  # fmt: skip
        else:
            scene.title = ("the final design at its worst-conditioned,\nmedian and "
                           "best-conditioned targets (stars)" if scene.arms else
                           "no target reached: no arm drawn")  # fmt: skip
        m3 = robot.draw_3d(ax3, scene, L, legend=False)
        if m3 is not None:
            style.shared_scale(fig, [*scs, m3], *scs[0].get_clim())
    fig.colorbar(scs[0], ax=axes, label=style.label("1/k", style.DIMENSIONLESS), shrink=0.85)
    handles = robot.legend_handles(scene)
    if (~ok).any():
        from matplotlib.lines import Line2D

        handles.insert(0, Line2D([], [], marker="x", color="0.45", ls="none", label="unreached"))
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=2 if flat else 4,
                   fontsize=8, framealpha=0.9)  # fmt: skip
    # a design far from what was asked (rec.warnings): the caption says so, in red
    import textwrap

    clip = textwrap.wrap(robot.clipped_note([scene], L), 90)  # far-away obstacles left out
    fig.suptitle("\n".join([_task_caption(rec, sol_all, sol, L), *clip]), fontsize=9,
                 color="crimson" if rec.warnings else "black")  # fmt: skip
    return save(fig, folder, "task")


def cloud(rec: RunRecord, n: int = 8000) -> dict[str, Any]:
    """The final design's workspace for the interactive report: tip positions of ``n``
    uniform joint samples (the run's ``figures`` stream), coloured by 1/k. Under
    ``measure: task``, the task's targets instead, coloured by 1/k at the final design's
    IK solution (NaN where unreached), with ``flag`` marking the unreached ones; with
    several arms, the arms' mean 1/k where every arm reaches the target
    (``drawing.combined``), the others flagged."""
    s: SerialSettings = rec.config.study
    length = STUDY_UNITS(s).get("__length__", "L")
    if s.indices.measure == "task":
        sol = task_solution(rec)
        many = s.arms is not None  # per arm (A, N): the targets every arm reaches
        sol = drawing.combined(sol) if many else sol
        ok = sol["success"]
        what = "the arms' mean 1/k" if many else "1/k"
        return {"xyz": np.asarray(sol["target_p"], np.float64),
                "value": np.where(ok, sol["inv_k"], np.nan).astype(np.float64),
                "label": f"{what} ({s.indices.norm}-norm) at the IK solution", "unit": "-",
                "xyz_unit": length, "flag": ~ok,
                "flag_label": "not reached by every arm" if many else "unreached",
                "title": f"the task's targets, coloured by {what} at the final design's IK "
                         "solution" + (f"s of its {len(s.arms)} arms (where every arm reaches "
                                       "the target)" if many else "")}  # fmt: skip
    mech = build(s)
    q = _uniform_q(mech, rec, n)
    X = _full(mech, np.asarray(list(rec.x.values()), np.float64))
    z, P = _kernel(mech, s)(X, q.astype(X.dtype))
    return {"xyz": np.asarray(P[0], np.float64), "value": np.asarray(z[0], np.float64),
            "label": f"1/k ({s.indices.norm}-norm)", "unit": "-", "xyz_unit": length}  # fmt: skip
