"""``designopt chain`` (print a serial chain as imported and check a URDF import against
the parser's own forward kinematics), ``designopt export`` (a run's best design written
back into the user's URDF; docs/urdf.md shows both) and ``designopt view`` (the robot
drawn as configured, without optimising; docs/figures.md)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from designopt.core.errors import ConfigError
from designopt.studies.serial.mechanism import set_values

N_CHECK = 8
"""Random joint configurations of the import check."""


def _serial(cfg: Any, where: str, command: str = "chain"):
    s = cfg.study
    if getattr(s, "name", None) != "serial":
        raise ConfigError(f"{where}: key 'study.name': `designopt {command}` needs a serial "
                          f"study, got '{s.name}'")  # fmt: skip
    return s


def design_values(s: Any, given: dict[str, float], where: str) -> dict[str, float]:
    """Every design variable's value: ``given`` or the middle of its box."""
    bad = sorted(set(given) - set(s.variables))
    if bad:
        raise ConfigError(f"{where}: --design {bad[0]}: not a design variable "
                          f"(variables: {', '.join(s.variables)})")  # fmt: skip
    return {k: given.get(k, 0.5 * (lo + hi)) for k, (lo, hi) in s.variables.items()}


def _fmt(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x: .6g}" for x in np.asarray(v).ravel()) + "]"


def _pose_lines(label: str, R: np.ndarray, p: np.ndarray, u: str) -> list[str]:
    """The tip pose: p in the chain's length unit ``u``, R's rows, and R as roll, pitch,
    yaw in degrees (URDF's fixed-axis x-y-z convention)."""
    rpy = np.degrees(_rpy(np.asarray(R, np.float64)))
    return [f"{label}: p = {_fmt(p)} {u}",
            f"{' ' * len(label)}  R = {_fmt(R[0])} {_fmt(R[1])} {_fmt(R[2])}"
            f" (rpy {_fmt(rpy)} deg)"]  # fmt: skip


def _rpy(R: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad) of R = Rz(yaw) Ry(pitch) Rx(roll), URDF's convention."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if math.hypot(R[0, 0], R[1, 0]) < 1e-12:  # gimbal lock: yaw folded into roll
        return np.array([math.atan2(-R[1, 2], R[1, 1]), pitch, 0.0])
    return np.array([math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])])


def chain_arguments(c: argparse.ArgumentParser) -> None:
    """The arguments of ``designopt chain``."""
    c.add_argument("config", help="config (YAML) with a serial study, e.g. configs/urdf_arm.yaml")
    c.add_argument("--q", default=None, metavar="Q1,Q2,...",
                   help="joint values (degrees for revolute, length units for prismatic)")  # fmt: skip
    c.add_argument("--design", action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                   help="a design variable's value (repeat; others: middle of their box)")  # fmt: skip
    c.add_argument("--seed", type=int, default=None, help="seed of the random check poses")
    c.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")


def export_arguments(x: argparse.ArgumentParser) -> None:
    """The arguments of ``designopt export``."""
    x.add_argument("archive")
    x.add_argument("--urdf", required=True, metavar="OUT.urdf", help="the URDF file to write")
    x.add_argument("--overwrite", action="store_true", help="replace an existing file")


def cmd_chain(args: argparse.Namespace, ctx: Any) -> int:
    """Print the chain as imported, its FK at zero and at ``--q``, and (URDF) the largest
    difference to yourdfpy's FK at random joint values."""
    loaded = ctx.load(args)
    import jax

    jax.config.update("jax_enable_x64", True)
    cfg, _ = loaded
    where = args.config
    s0 = _serial(cfg, where)
    design = design_values(s0, ctx.design(args.design), where)
    from designopt.studies.serial import setup

    if not setup.mixed(s0):
        return _chain_of(s0, design, args, cfg.seed)
    if args.q is not None:
        raise ConfigError(f"--q {args.q}: the arms are different robots ("
                          + ", ".join(setup.robot_name(s0, k) for k in range(setup.n_arms(s0)))
                          + "), so one joint vector fits none of them all; leave --q out")  # fmt: skip
    status = 0
    for g in setup.groups(s0):  # each robot of the set-up, once
        arms = ", ".join(str(k) for k in g.arms)
        print(f"arm{'s' if len(g.arms) > 1 else ''} {arms}: {setup.robot_name(s0, g.arms[0])}")
        status = max(status, _chain_of(g.settings, design, args, cfg.seed))
    return status


def _chain_of(s: Any, design: dict[str, float], args: argparse.Namespace, seed: int) -> int:
    """:func:`cmd_chain` for one robot (``s``: the study, or an arm's view of it)."""
    from designopt.studies.serial.mechanism import build
    from designopt.studies.serial.settings import UrdfChain, length_unit

    q = _parse_q(args.q, tuple(j.type for j in s.chain.joints))
    mech = build(s)
    n = mech.n
    full = np.concatenate([[design[k] for k in s.variables], mech.fixed]) * mech.scale
    urdf_chain = isinstance(s.chain, UrdfChain)
    u = length_unit(s)  # m for a URDF; every angle printed in degrees
    lines: list[str] = []
    if urdf_chain:
        imp = s.chain.imported
        rob = imp.robot
        lines.append(f"URDF {s.chain.urdf_path} (robot '{rob.name}'): {imp.base} -> {imp.tip}, "
                     f"{len(imp.path)} joints on the path, {n} active")  # fmt: skip
        bound = s.chain.bound()
        for j in imp.path:
            lim = ""
            if j.name in imp.active:
                i = imp.active.index(j.name)
                lo, hi = imp.lower[i], imp.upper[i]
                if imp.types[i] == "R":
                    lim = f" limits [{math.degrees(lo):.4g}, {math.degrees(hi):.4g}] deg"
                else:
                    lim = f" limits [{lo:.4g}, {hi:.4g}] {u}"
                lim = f" q{i + 1}" + lim
            mim = f" mimics {j.mimic[0]} (x{j.mimic[1]:g} {j.mimic[2]:+g})" if j.mimic else ""
            axis = f" axis {_fmt(j.axis)}" if j.type != "fixed" else ""
            lines.append(f"  {j.name:<16} {j.type:<10} {j.parent} -> {j.child}{axis}{lim}{mim}")
            lines.append(f"  {'':<16} origin xyz {_fmt(j.xyz)} {u} rpy "
                         f"{_fmt(np.degrees(np.asarray(j.rpy, np.float64)))} deg")  # fmt: skip
            for (jn, f), v in bound.items():
                if jn == j.name:
                    unit = " deg" if f in ("roll", "pitch", "yaw") else f" {u}"
                    what = (f"variable {v} = {design[v]:.6g}{unit}" if v in s.variables else
                            f"fixed {v} = {s.fixed[v]:.6g}{unit}" if isinstance(v, str) else
                            f"fixed {v:.6g}{unit}")  # fmt: skip
                    lines.append(f"  {'':<16} origin.{f}: {what}")
        lines.append(f"off the path (ignored): {len(rob.joints) - len(imp.path)} joints")
    else:
        lines.append(f"DH chain ({s.chain.convention}), {n} joints; lengths a, d in {u}, "
                     "angles alpha, theta in deg")  # fmt: skip
        for i, j in enumerate(s.chain.joints):
            lim = "deg" if j.type == "R" else u
            lines.append(f"  q{i + 1}: {j.type} a={j.a} alpha={j.alpha} d={j.d} theta={j.theta} "
                         f"limits {list(j.limits)} {lim}")  # fmt: skip
    units = {k: ("deg" if k in s.angle_names() else u) for k in design}
    lines.append("design: " + ", ".join(f"{k} = {v:g} {units[k]}" for k, v in design.items()))
    R0, p0 = (np.asarray(a) for a in mech.model.fk(full, np.zeros(n)))
    lines += _pose_lines("FK at q = 0", R0, p0, u)
    if q is not None:
        Rq, pq = (np.asarray(a) for a in mech.model.fk(full, q))
        lines += _pose_lines(f"FK at --q {args.q} (deg, {u})", Rq, pq, u)
    status = 0
    if urdf_chain:
        err = check_import(s, design, mech, full, seed)
        ok = err < 1e-9
        lines.append(f"check against yourdfpy's FK at {N_CHECK} random joint values in the "
                     f"limits: max |ΔT| = {err:.2e} ({'OK' if ok else 'MISMATCH'})")  # fmt: skip
        status = 0 if ok else 1
    if s.collision is not None:  # the capsules, the pairs checked and what sets the clearance
        from designopt.studies.serial import bodies

        lines += bodies.pair_lines(s, mech, design, q)
    print("\n".join(lines))
    return status


def _parse_q(text: str | None, types: tuple[str, ...]) -> np.ndarray | None:
    """--q as active joint values (rad for R joints, length units for P joints)."""
    if text is None:
        return None
    n = len(types)
    try:
        qv = [float(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError(f"--q {text}: expected {n} numbers separated by commas") from None
    if len(qv) != n or not all(math.isfinite(x) for x in qv):
        raise ConfigError(f"--q {text}: expected {n} finite numbers (one per active joint)")
    return np.array([math.radians(x) if t == "R" else x for x, t in zip(qv, types, strict=True)])


def check_import(s: Any, design: dict[str, float], mech: Any, full: np.ndarray,
                 seed: int) -> float:  # fmt: skip
    """Largest |Δ| over the 4×4 tip transform between the kernel and yourdfpy (reading the
    URDF with this design's values written in), at random joint values in the box."""
    from designopt.kinematics import urdf

    text = urdf.export_text(s.chain.urdf_text, set_values(s, design), s.chain.urdf_path or "")
    ref = urdf.Reference(text)
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(mech.lower), np.asarray(mech.upper)
    Q = lo + (hi - lo) * rng.random((N_CHECK, mech.n))
    R, p = (np.asarray(a) for a in mech.model.fk(full, Q))
    err = 0.0
    for i, q in enumerate(Q):
        T = ref.fk(s.chain.imported, q)
        err = max(err, float(np.abs(R[i] - T[:3, :3]).max()), float(np.abs(p[i] - T[:3, 3]).max()))
    return err


def _best(rec: Any, where: str) -> tuple[list[str], np.ndarray]:
    """The design to export: a run's final design, a scan's lowest f (feasible)."""
    from designopt.results import RunRecord, ScanRecord

    if isinstance(rec, RunRecord):
        return rec.names, np.asarray(list(rec.x.values()), np.float64)
    if isinstance(rec, ScanRecord):
        v = rec.values
        f = np.asarray(v["f"], np.float64)
        if "violation" in v:
            ok = np.asarray(v["violation"]) <= 0
            if not ok.any():
                raise ConfigError(f"{where}: no feasible design in the scan to export")
            f = np.where(ok, f, np.inf)
        return rec.names, rec.X[int(np.nanargmin(f))]
    raise ConfigError(f"{where}: a '{rec.kind}' archive; export takes a run or scan archive")


def cmd_export(args: argparse.Namespace, ctx: Any) -> int:
    """Write the URDF of a run (final design) or scan (lowest f) archive."""
    from designopt.io import writer
    from designopt.kinematics import urdf
    from designopt.studies.serial.settings import UrdfChain

    where = args.archive
    rec = ctx.load_record(where)
    if rec.study != "serial":
        raise ConfigError(f"{where}: not an archive of a serial study")
    s = rec.config.study
    if not isinstance(s.chain, UrdfChain):
        raise ConfigError(f"{where}: the run's chain is a DH table, not a URDF (chain.urdf)")
    names, x = _best(rec, where)
    design = dict(zip(names, (float(v) for v in x), strict=True))
    text = urdf.export_text(
        s.chain.urdf_text or "", set_values(s, design), s.chain.urdf_path or where
    )
    out = Path(args.urdf)
    if out.is_dir():
        raise ConfigError(f"--urdf {out}: is a folder, not a file; give a file name such as "
                          f"{out / 'robot.urdf'}")  # fmt: skip
    if out.exists() and not getattr(args, "overwrite", False):
        raise ConfigError(f"output '{out}': a file is already there; give --overwrite to "
                          "replace it, or another --urdf")  # fmt: skip
    writer.check(out, overwrite=getattr(args, "overwrite", False), make=True)
    writer.write_file(out, text.encode("utf-8"), "URDF")
    print(f"{out}: {s.chain.urdf} with " + ", ".join(
        f"{k} = {v:.6g}" for k, v in design.items()))  # fmt: skip
    return 0


def view_arguments(v: argparse.ArgumentParser) -> None:
    """The arguments of ``designopt view``."""
    v.add_argument("config", help="config (YAML) with a serial study, e.g. configs/puma560.yaml")
    v.add_argument("--design", action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                   help="a design variable's value (repeat; others: middle of their box)")  # fmt: skip
    v.add_argument("--q", default=None, metavar="Q1,Q2,...",
                   help="joint values (degrees for revolute, length units for prismatic); "
                        "default: the home pose (0 where the limits allow, else mid-range)")  # fmt: skip
    v.add_argument("--out", default=None, metavar="PATH.png",
                   help="the figure (the PDF beside it); default: <config stem>_view.png "
                        "beside the config's output archive")  # fmt: skip
    v.add_argument(
        "--html",
        default=None,
        metavar="OUT.html",
        help="also write a self-contained 3-D view (offline, plotly embedded)",
    )
    v.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")


def _in_limits(q: np.ndarray, s: Any, mech: Any, text: str) -> None:
    """--q within the joint limits (to 1e-9), else one line naming the joint."""
    from designopt.studies.serial.drawing import joint_names
    from designopt.studies.serial.settings import length_unit

    for i, (name, j) in enumerate(zip(joint_names(s), s.chain.joints, strict=True)):
        lo, hi = mech.lower[i], mech.upper[i]
        tol = 1e-9 * max(1.0, hi - lo)
        if not lo - tol <= q[i] <= hi + tol:
            f, u = (180 / math.pi, "deg") if j.type == "R" else (1.0, length_unit(s))
            raise ConfigError(f"--q {text}: {name} = {q[i] * f:.6g} {u} is outside its limits "
                              f"[{lo * f:.6g}, {hi * f:.6g}] {u}")  # fmt: skip


def _outputs(args: argparse.Namespace, cfg: Any) -> tuple[Path, Path | None]:
    """(the figure's PNG, the HTML page or None), checked before anything is drawn: the
    PNG by default ``<config stem>_view.png`` beside the config's output archive."""
    stem = f"{Path(args.config).stem}_view"
    png = Path(args.out) if args.out else Path(cfg.output_path()).with_name(f"{stem}.png")
    html = Path(args.html) if args.html else None
    for flag, path, suffixes in (("--out", png, (".png",)), ("--html", html, (".html", ".htm"))):
        if path is None:
            continue
        if path.is_dir():
            raise ConfigError(f"{flag} {path}: is a folder; give a file name such as "
                              f"{path / (stem + suffixes[0])}")  # fmt: skip
        if path.suffix.lower() not in suffixes:
            raise ConfigError(f"{flag} {path}: give a{'n' * (flag == '--html')} "
                              f"{suffixes[0]} file name"
                              + (" (the PDF is written beside it)" if flag == "--out" else ""))  # fmt: skip
    return png, html


def _view_title(s: Any, design: dict[str, float], q: np.ndarray, at_home: bool,
                solved: str = "") -> list[str]:  # fmt: skip
    """The view's title as its lines, unwrapped (the figure wraps them to its width, the
    HTML page joins them with "; "): the chain, the design, the pose (``solved``: what
    the arms were solved for, in place of ``q``), the changed URDF numbers, the meshes,
    the arms' bases."""
    from designopt.studies.serial import drawing
    from designopt.studies.serial.settings import UrdfChain, length_unit

    u = length_unit(s)
    units = {k: ("deg" if k in s.angle_names() else u) for k in design}
    dtext = ", ".join(f"{k}\u00a0=\u00a0{v:.6g}\u00a0{units[k]}" for k, v in design.items())  # no break
    urdf_chain = isinstance(s.chain, UrdfChain)
    what = (f"{Path(s.chain.urdf).name} ({s.chain.imported.base} -> {s.chain.imported.tip})" if urdf_chain
            else f"DH chain ({s.chain.convention}, {len(s.chain.joints)} joints)")  # fmt: skip
    from designopt.studies.serial import setup

    mixed = setup.mixed(s)
    if mixed:  # arms of several robots: each its own, at its own home pose
        A = setup.n_arms(s)
        what = ", ".join(f"arm {k}: {setup.robot_name(s, k)}" for k in range(A))
        qs = np.atleast_2d(q)
        pose = "; ".join(f"arm {k} at " + drawing.joint_values(v, qs[k][: len(v.chain.joints)])
                         for k, v in ((k, setup.arm_view(s, k)) for k in range(A)))  # fmt: skip
        pose += " (home poses: each joint at 0 where its limits allow, else mid-range)"
    else:
        pose = "at " + drawing.joint_values(s, q) + (
            " (home pose: each joint at 0 where its limits allow, else mid-range)"
            if at_home else "")  # fmt: skip
    lines = [f"{what}: design {dtext}", solved or pose]
    if s.arms is not None:
        lines.append(f"{len(s.arms)} arms, each at its base in the world (study.arms)"
                     + ("" if solved or mixed else ", every arm at this pose"))  # fmt: skip
    if urdf_chain and not mixed:
        lines.append("set numbers: " + drawing.changes_text(s, design).replace("\n", "; "))
    note = None if mixed else drawing.meshes_note(s, design, q)
    if note:
        lines.append(note)
    return lines


def _solved_pose(s: Any, mech: Any, x: np.ndarray, seed: int) -> dict[str, Any] | None:
    """The arms of a config whose instruments pass ports, solved for its task's targets
    (``blocks.solution`` on the config's targets, from the ``samples`` stream of its
    seed, as a run draws them): several arms at the tuple of targets of median gap
    between the arms (``drawing.arm_tuples``; colliding arms red, their closest points
    marked), one arm at its reached target of median 1/k. A dict (``text``: what was
    solved, ``Q`` (A, n), ``pairs``, ``colliding`` per arm, ``marks``), or None with no
    port. Where nothing is reached, ``Q`` is None and ``text`` says so."""
    import jax

    from designopt.core.keys import streams
    from designopt.studies.serial import blocks, drawing

    if s.task is None or s.ports()[0] is None or s.indices.measure != "task":
        return None
    keys = streams(seed)
    design = dict(zip(s.variables, x.tolist(), strict=True))
    jax.config.update("jax_enable_x64", True)  # the task's IK runs in float64
    sol = blocks.solution(s, design, keys)
    N = int(np.asarray(sol["target_p"]).shape[0])
    if s.arms is None:
        label, Q, tg = drawing.representative(s, mech, sol)
        if not tg:
            return {"text": f"the IK reached none of the task's {N} targets: the arm at the "
                            "home pose", "Q": None}  # fmt: skip
        return {"text": f"solved for the task's {N} targets (IK): the arm at {label}", "Q": Q,
                "pairs": [], "colliding": [False], "marks": tg}  # fmt: skip
    tup = drawing.arm_tuples(s, mech, x, sol, keys, counted=False)
    if not tup:
        return {"text": f"the IK found no tuple of the task's {N} targets every arm reaches: "
                        "the arms at the home pose", "Q": None}  # fmt: skip
    st = drawing.tuple_stats(s, mech, sol, keys)
    label, arms_, pairs, qs = tup[0]
    perm = drawing._tuples(s, mech, sol, keys)[0]
    marks = [np.asarray(sol["target_p"])[perm[k][st.median]]
            for k in s.instrument_arms()]  # the camera arm's target is the scope's
    return {"text": f"solved for the task's {N} targets (IK, one target per arm): every arm "
                    f"at the {label}; {st.text()}", "Q": np.stack(qs), "pairs": pairs,
            "colliding": [a.colliding for a in arms_], "marks": marks}  # fmt: skip


def _changed(s: Any, design: dict[str, float]) -> bool:
    """Whether the design changes a URDF chain's own numbers (the original is drawn)."""
    from designopt.studies.serial import drawing
    from designopt.studies.serial.settings import UrdfChain

    return isinstance(s.chain, UrdfChain) and any(
        abs(a - b) > 1e-12 * max(1.0, abs(b)) for _, a, b, _ in drawing.changes(s, design))


def _task_around(s: Any, design: Any = None) -> dict[str, Any]:
    """What the view draws around the robot: the task region, the tool-axis cone, the
    obstacles and the ports (of ``design``: ports may be design variables), as
    ``figures.robot.Scene`` keywords."""
    from designopt.figures import robot
    from designopt.studies.serial import drawing

    region = s.task.region if s.task is not None else None
    cone = None
    if region is not None:
        rp = robot.scene_points(robot.Scene(arms=[], region=region))
        cone = drawing.cone(s, rp, 0.4 * float(np.ptp(rp, 0).max()) if len(rp) > 1 else 0.1)
    return {"region": region, "cone": cone, **drawing.obstacles_and_ports(s, design)}


def cmd_view(args: argparse.Namespace, ctx: Any) -> int:
    """Draw the chain as configured, without optimising: a figure (PNG + PDF) of the robot
    at ``--design`` (else the middle of the box) and ``--q`` (else the home pose), every
    arm at its base in the world where the study has several, the URDF's original robot
    beside it where the design changes the file's numbers, the task region, tool-axis
    cone, obstacles and ports where the config has them; ``--html``: a 3-D page too. A
    config whose instruments pass ports is drawn, without ``--q``, at its task: the arms
    solved for its targets (:func:`_solved_pose`: the tuple of median gap between the
    arms, collisions marked), not at the home pose through the patient."""
    loaded = ctx.load(args)
    import jax

    jax.config.update("jax_enable_x64", True)
    from designopt.figures import robot, save
    from designopt.io import writer
    from designopt.studies.serial import drawing
    from designopt.studies.serial.mechanism import build
    from designopt.studies.serial.settings import length_unit

    cfg, _ = loaded
    where = args.config
    s = _serial(cfg, where, "view")
    design = design_values(s, ctx.design(args.design), where)
    mech = build(s)
    from designopt.studies.serial import setup

    if args.q is not None and setup.mixed(s):
        raise ConfigError(f"--q {args.q}: the arms are different robots ("
                          + ", ".join(setup.robot_name(s, k) for k in range(setup.n_arms(s)))
                          + "), so one joint vector fits none of them all; leave --q out "
                          "to see each arm at the task")  # fmt: skip
    q = _parse_q(args.q, tuple(j.type for j in s.chain.joints))
    if q is not None:
        _in_limits(q, s, mech, args.q)
    at_home = q is None
    q = drawing.home_q(s, mech) if q is None else q
    png, html = _outputs(args, cfg)
    for p in (png, html):
        if p is not None:
            writer.check(p, overwrite=True)
    x = np.asarray([design[k] for k in s.variables], np.float64)
    around = _task_around(s, design)
    solved = _solved_pose(s, mech, x, cfg.seed) if at_home else None  # ports: at the task
    Q = q if solved is None or solved["Q"] is None else solved["Q"]
    mine = _marked(drawing.study_arms(s, mech, x, Q, label="this design", color="#ff7f0e"),
                   solved)  # fmt: skip
    extra = {} if solved is None or solved["Q"] is None else {
        "collisions": solved["pairs"], "marks": [(p, "#d62728") for p in solved["marks"]]}
    scenes = [robot.Scene(arms=mine, title="this design", **around, **extra)]
    if _changed(s, design):
        scenes.insert(0, robot.Scene(arms=drawing.original_arms(s, mech, x, Q), **around,
                                     title="original: the URDF's own numbers"))  # fmt: skip
    lines = _view_title(s, design, q, at_home and solved is None,
                        "" if solved is None else solved["text"])  # fmt: skip
    fig = robot.figure(scenes, length_unit(s), "\n".join(lines))  # wrapped to its width
    written = [png.parent / p.name for p in  # printed as given (a bare name: its folder is ".")
               writer.publish_figures(lambda d: save(fig, d, png.stem), png.absolute().parent,
                                      swap=False)]  # fmt: skip
    if html is not None:
        from designopt.figures import html as page

        view = view_of(s, mech, x, Q, "; ".join(lines), len(scenes) > 1, around, solved)
        doc = page.document([page.robot_section(view)], f"designopt view: {Path(where).name}")
        writer.write_file(html, doc.encode("utf-8"), "HTML view")
        written.append(html)
    for p in written:
        print(p)
    return 0


def _marked(arms: list[Any], solved: dict[str, Any] | None) -> list[Any]:
    """The arms with their ``colliding`` flags from a solved pose (red where they collide)."""
    from dataclasses import replace

    if solved is None or solved["Q"] is None:
        return arms
    return [replace(a, colliding=bool(c)) for a, c in zip(arms, solved["colliding"], strict=True)]


def view_of(s: Any, mech: Any, x: np.ndarray, q: np.ndarray, title: str, original: bool,
            around: dict[str, Any], solved: dict[str, Any] | None = None) -> Any:  # fmt: skip
    """The view's 3-D robot (``designopt.figures.html.View``): every arm of this design
    at ``q`` ((n,) or one row per arm), at its base, the original robot as a reference,
    with ``around`` (region, cone, obstacles, ports); a solved pose (``solved``) marks
    its targets and colliding arms. ``title``: one line (its parts joined by "; ")."""
    from designopt.figures import html as page
    from designopt.figures import robot
    from designopt.studies.serial import drawing
    from designopt.studies.serial.report import _budget
    from designopt.studies.serial.settings import length_unit

    A = 1 if s.arms is None else len(s.arms)
    ref = drawing.original_arms(s, mech, x, q, budget=_budget(2 * A)) if original else []
    mine = _marked(drawing.study_arms(s, mech, x, q, label="this design", color="#ff7f0e",
                                      budget=_budget(A + len(ref))), solved)  # fmt: skip
    q = np.asarray(q, np.float64)
    Q = np.broadcast_to(q, (len(mine), q.shape[-1]))
    scene = robot.Scene(arms=ref, **around)
    if solved is not None and solved["Q"] is not None:
        scene.collisions = solved["pairs"]
        scene.marks = [(p, "#d62728") for p in solved["marks"]]
    return page.View(title=title + "; drag to rotate", unit=length_unit(s), scene=scene,
                     poses=[page.Pose("this pose", mine,
                                      [drawing.hover(s, a.label, qa, None, k if A > 1 else None)
                                       for k, (a, qa) in enumerate(zip(mine, Q, strict=True))])],
                     note=("faint: the original robot (the URDF's numbers); " if ref else "")
                     + "hover the joints for their values")  # fmt: skip


def _commands() -> tuple[Any, ...]:
    from designopt.studies.base import Command

    chain = Command(
        name="chain",
        help="print a serial study's chain as imported (URDF or DH) and check it",
        description="Print the chain of a serial study as imported: joints, types, axes, "
        "limits, which numbers are design variables, the forward kinematics of the zero "
        "pose and of --q; for a URDF chain, cross-check the import against the URDF "
        "parser's own forward kinematics at random joint values (docs/urdf.md).",
        arguments=chain_arguments,
        run=cmd_chain,
    )
    export = Command(
        name="export",
        help="write the best design of a run archive back as URDF",
        description="Write the URDF of a serial study's run (or scan) archive with the best "
        "design's values in the chain's `set` fields and nothing else changed (docs/urdf.md).",
        arguments=export_arguments,
        run=cmd_export,
        writes=True,
    )
    view = Command(
        name="view",
        help="draw a serial study's robot as configured (PNG + PDF; --html: a 3-D page)",
        description="Draw the chain of a serial study without optimising: the robot at "
        "--design (else the middle of each variable's box) and --q (else the home pose: each "
        "joint at 0 where its limits allow, else mid-range; degrees for revolute joints), with "
        "the task region where the config has one and, for a URDF chain, the URDF's own robot "
        "beside it where the design changes its numbers; --html also writes an offline 3-D "
        "page (docs/figures.md).",
        arguments=view_arguments,
        run=cmd_view,
        writes=True,
    )
    return chain, export, view


COMMANDS = _commands()
"""``designopt chain``, ``designopt export`` and ``designopt view``, declared in
``Study.commands``."""
