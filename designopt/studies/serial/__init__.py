"""The generic ``serial`` study: any serial chain described in YAML (a DH table or a
robot's URDF, design variables, joint limits), scored by dexterity, manipulability and workspace volume on the
generic frame kernel (``designopt.kinematics.kernel``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt.studies.base import Cost, Study
from designopt.studies.serial import ikhook, reach
from designopt.studies.serial.commands import COMMANDS
from designopt.studies.serial.placement import placement as _placement
from designopt.studies.serial.settings import INDEX_NAMES, TASK_INDEX_NAMES, SerialSettings, units


def _problem(settings: SerialSettings, keys, dtype):
    from designopt.studies.serial import objective

    return objective.problem(settings, keys, dtype)


def _figures(record: Any, folder: Path) -> list[Path]:
    from designopt.studies.serial import figures

    return figures.draw_run(record, folder)


def _cloud(record: Any) -> dict[str, Any]:
    from designopt.studies.serial import figures

    return figures.cloud(record)


def _robot(record: Any) -> dict[str, Any] | None:
    from designopt.studies.serial import report

    return report.report(record)


def _front_figures(record: Any, picks: Any, folder: Path) -> list[Path]:
    from designopt.studies.serial import figures

    return figures.draw_front_robots(record, picks, folder)


def _targets(s: SerialSettings, x: Any, keys: Any, dtype: Any) -> dict[str, Any] | None:
    """The final design at every target of a task run (``Study.targets``): per arm (A = 1
    without ``arms``) and target ``success`` (A, N) 0/1, ``q`` (A, N, n) in the kernel's
    units (rad for a revolute joint, the chain's length unit for a prismatic one),
    ``inv_k`` and, under ``collision``, ``clearance`` (A, N), beside ``target_p`` (N, 3)
    in the world frame; the run's own targets and IK seeds (``blocks.solution``, the
    program the figures use). ``arm_values`` (A, K): each arm's port and base
    (:func:`_placement`), written on every row of ``show --csv``. Designs ``x`` (P, D)
    (a front's): every array but ``target_p`` with a leading design axis P. Attrs
    ``ik_better`` and ``ik_better_n``: the IK's coverage figure (``blocks.coverage``, all
    designs in one batched solve); for one design with its summary ``lines`` and
    ``warnings`` (a share above ``blocks.COVERAGE_WARN``), for several ``ik_better`` (P,)
    with each design's line (``coverage_lines``) and warning (``coverage_warnings``, ""
    where none)."""
    if s.indices.measure != "task":
        return None
    import numpy as np

    from designopt.studies.serial.drawing import joint_names
    from designopt.studies.serial.settings import length_unit

    xa = np.asarray([x[k] for k in s.variables] if hasattr(x, "keys") else x, np.float64)
    many = xa.ndim == 2
    X = np.atleast_2d(xa)
    from designopt.studies.serial import blocks

    sol = blocks.solutions(s, X, keys, dtype)  # (A, P, N, ...)

    def per_design(v: Any) -> Any:  # (A, P, N, ...) → (P, A, N, ...), or (A, N, ...)
        v = np.moveaxis(np.asarray(v), 1, 0)
        return v if many else v[0]

    out = {"target_p": sol["target_p"], "success": per_design(sol["success"]).astype(np.int8),
           "q": per_design(sol["q"]), "inv_k": per_design(sol["inv_k"])}  # fmt: skip
    if "clearance" in sol:
        out["clearance"] = per_design(sol["clearance"])
    u = length_unit(s)
    types = [j.type for j in s.chain.joints]
    out["attrs"] = {"joints": list(joint_names(s)), "types": types, "length_unit": u,
                    "q_units": ["rad" if t == "R" else u for t in types]}  # fmt: skip
    from designopt.studies.serial import setup

    if setup.mixed(s):  # arms of several robots: q (…, n_max) padded with NaN
        out["attrs"] |= setup.joint_attrs(s)
    # how often a second, independent set of IK seeds finds a better solution: every
    # design's in one batched solve (blocks.coverage)
    cov = blocks.coverage(s, X, keys, sol, dtype)
    per = [blocks.coverage_lines(s, {"ik_better": float(b), "ik_better_n": cov["ik_better_n"]})
           for b in cov["ik_better"]]  # fmt: skip
    if not many:  # attrs ik_better, ik_better_n, lines, warnings
        lines, warns = per[0]
        out["attrs"] |= {"ik_better": float(cov["ik_better"][0]),
                         "ik_better_n": cov["ik_better_n"], "lines": lines} | \
            ({"warnings": warns} if warns else {})  # fmt: skip
    else:  # per design: ik_better (P,), its line and its warning ("" where none)
        out["attrs"] |= {"ik_better": [float(b) for b in cov["ik_better"]],
                         "ik_better_n": cov["ik_better_n"],
                         "coverage_lines": [ln[0] for ln, _ in per],
                         "coverage_warnings": [w[0] if w else "" for _, w in per]}  # fmt: skip
    pl = _placement(s, X)
    if pl is not None:
        cols, vals = [], []
        if "ports" in pl:
            cols += [f"port_{c} [{u}]" for c in "xyz"]
            vals.append(pl["ports"])
        if "bases" in pl:
            cols += [f"base_{c} [{u}]" for c in "xyz"]
            cols += [f"base_{c} [deg]" for c in ("roll", "pitch", "yaw")]
            vals.append(pl["bases"])
        av = np.concatenate(vals, -1)  # (P, A, K)
        out["arm_values"] = av if many else av[0]
        out["attrs"]["arm_columns"] = cols
    return out


def _vec(v: Any, fmt: str = ".4f") -> str:
    return "(" + ", ".join(f"{float(c) + 0.0:{fmt}}" for c in v) + ")"


def _extra_lines(s: SerialSettings, fin: Any) -> list[str]:
    """``Study.extra_lines``: each arm's incision point and base in numbers (world frame),
    from the values ``_placement`` archived (a final group, or one front design's)."""
    import numpy as np

    from designopt.studies.serial.settings import length_unit

    if "ports" not in fin and "bases" not in fin and "camera" not in fin:
        return []
    u = length_unit(s)
    wall = None if s.task is None or s.task.body_wall is None else s.task.body_wall.shape
    ports = None if "ports" not in fin else np.asarray(fin["ports"], np.float64).reshape(-1, 3)
    bases = None if "bases" not in fin else np.asarray(fin["bases"], np.float64).reshape(-1, 6)
    A = len(ports) if ports is not None else len(bases) if bases is not None else 0
    words = [w for w, v in (("ports", ports), ("bases", bases), ("the camera", fin.get("camera")))
             if v is not None]  # fmt: skip
    what = " and ".join([", ".join(words[:-1]), words[-1]] if len(words) > 1 else words)
    head = f"  {what} in the world frame ({u}; angles in deg)" + (
        f"; a port is the incision point, the design's point projected onto the {wall} "
        "body wall" if ports is not None and wall is not None else "")  # fmt: skip
    lines = [head + ":"]
    for k in range(A):
        arm = "  arm" if A == 1 and s.arms is None else f"  arm {k}"
        arm += " (holds the camera)" if k == s.camera_arm() else ""
        parts = []
        if ports is not None:
            txt = f"port {_vec(ports[k])} {u}"
            if wall is not None and "port_shift" in fin:
                sh = float(np.asarray(fin["port_shift"], np.float64).reshape(-1)[k])
                pt = np.asarray(fin.get("port_points", ports), np.float64).reshape(-1, 3)[k]
                txt += f", {sh:.4f} {u} from the design's point {_vec(pt)}"
            parts.append(txt)
        if bases is not None:
            parts.append(f"base xyz {_vec(bases[k][:3])} {u}, rpy {_vec(bases[k][3:], '.2f')} deg")
        lines.append(f"{arm}: " + "; ".join(parts))
    if "camera" in fin:
        cam = np.asarray(fin["camera"], np.float64).reshape(6)
        lines.append(f"  camera: port {_vec(cam[:3])} {u}, its tip at {_vec(cam[3:])} {u}, "
                     f"{float(np.linalg.norm(cam[3:] - cam[:3])):.4f} {u} in")  # fmt: skip
    return lines


def _aliases(s: SerialSettings) -> dict[str, str]:
    out = {f"study.{k}": f"study.indices.{k}" for k in ("n_samples", "length_scale")}
    out |= {f"design.{k}": f"study.fixed.{k}" for k in s.fixed}
    out |= {f"objective.{k}": f"study.objective.{k}" for k in s.weights()}
    return out


def _cost(s) -> Cost:
    """Monte-Carlo cost per design (pre-flight): the index samples, ``chunk`` in flight,
    and the normalisation probes when the objective normalises. Under ``measure: task``
    a sample is a target (``front.n_samples`` counts targets too), a chunk holds
    ``indices.chunk`` targets (1024 unless given) and a block :data:`blocks.DESIGNS`
    designs (``designs``: the block program, ``blocks``, holds no more in flight).

    The memory behind them goes to the pre-flight as ``Cost`` attributes (it has no fields
    for them; ``designopt.app.preflight.extra``), bytes measured with XLA's
    ``memory_analysis()`` and the peak resident set on a 2-core CPU (float64; docs/faults.md):

    - ``bytes_per_sample``: per design and sample of a chunk, about three float64 copies
      of the Jacobian block (820 B measured for 6 × 6, 30-60 B for 2 × 2); per design and
      target of a task, the solver's state and final check per kept solution, the study's
      Jacobian and its condition number: 8 B × (n_best + 1) × (9 + 2 · rows · joints)
      (1.9 kB measured for the PUMA's 6 × 6 with n_best 2, 0.4 kB for a planar 2R);
    - ``per_design`` (task): the FK database, n_db entries of joints, pose and Z-order
      key, 8 B × (joints + 6) each (91 B measured for 6 joints);
    - ``program`` (task): compiling the batched IK, 250 MiB for the database, seeds,
      final check and the runtime's arenas, plus 40 MiB + 4.6 MiB × joints × residual
      rows (3 position, 6 with a tool axis) per term of ``ik._phases`` (4096, 512, 64
      slots: three for a swarm). The terms were measured when the LM step was compiled
      once per slot phase (0.45 GB for the planar 2R, 0.64-0.7 GB with two phases and
      0.83-0.97 GB with three for the PUMA 560 with a tool axis); the step is one copy
      now (busy chunks of B/8 slots, issue #36), so the estimate errs high. All of it
      is scaled by the block program's slots over those 4096: a block of 16 designs ×
      256 targets runs 1024 slots, of 16 × 1024 targets 4096 (issue #46), and
      ``tests/test_preflight.py`` checks it within 1.5× of a measured peak.

    With ``arms`` every arm solves every target: the per-target and per-design bytes are
    A times one arm's (plus the arms' kept capsules, 48 B per joint and target)."""
    from designopt.studies.serial import setup

    ind, n_norm = s.indices, s.objective.get("n_norm")
    n_q, rows = setup.n_joints(s), len(ind.rows())  # (the longest chain of a mixed set-up)
    if ind.measure == "task":
        from designopt.kinematics import ik
        from designopt.studies.serial import taskindex

        o = s.task.ik
        from designopt.studies.serial import blocks

        n, c = taskindex.n_targets(s), taskindex.chunk(s)
        r = 3 if taskindex.mode(s) == "position" else 6
        items = blocks.DESIGNS * c  # the block program's (design, target) pairs
        slots = min(items, o.slots or max(1024, min(4096, items // 4)))  # ik.solve's
        phases = len(ik._phases(slots))
        A = 1 if s.arms is None else len(s.arms)  # each arm solves every target
        seg = 0 if s.arms is None else 8 * 6 * n_q  # the arms' kept capsules
        mem = {
            "bytes_per_sample": A * (8 * (o.n_best + 1) * (9 + 2 * rows * n_q) + seg),
            "per_design": A * 8 * (n_q + 6) * o.n_db,
            # measured at 4096 slots; the block's 1024 compile in about a quarter
            "program": int((250 + phases * (40 + 4.6 * n_q * r)) * slots / 4096 * (1 << 20)),
            "designs": blocks.DESIGNS,
        }
    else:
        n, c = ind.n_samples, min(ind.chunk, ind.n_samples)
        mem = {"bytes_per_sample": 24 * rows * n_q}
    return Cost(n, c, int(n_norm or 1), "study.indices.n_samples", "study.indices.chunk",
                "study.objective.n_norm" if n_norm is not None else None, **mem)  # fmt: skip


STUDY = Study(
    name="serial",
    title="any serial chain from YAML (DH table or URDF, with named design variables)",
    settings=SerialSettings,
    problem=_problem,
    summary=lambda s: s.index_names(),
    indices=lambda s: ("f", *s.index_names()),
    figures=_figures,
    sweep_aliases=_aliases,
    units=units,
    example_config="configs/planar2r.yaml",
    cost=_cost,
    commands=COMMANDS,
    ik=ikhook.HOOK,
    cloud=_cloud,
    robot=_robot,
    targets=_targets,
    placement=_placement,
    extra_lines=_extra_lines,
    front_figures=_front_figures,
    check=reach.check,
    warnings=reach.warnings,
    tiny={
        "name": "serial",
        "chain": {
            "convention": "modified",
            "joints": [
                {"type": "R", "a": 0, "alpha": 0, "d": 0, "theta": 0, "limits": [-150, 150]},
                {"type": "R", "a": "l1", "alpha": 90, "d": "h", "theta": 0, "limits": [-90, 90]},
                {"type": "P", "a": "l2", "alpha": -90, "d": 0.2, "theta": 0, "limits": [0.1, 0.5]},
            ],
        },
        "variables": {"l1": [0.2, 1.0], "l2": [0.05, 0.5]},
        "fixed": {"h": 0.1},
        "indices": {
            "jacobian": "position",
            "norm": "fro",
            "normalized": True,
            "measure": "cartesian",
            "n_samples": 2048,
        },
        "objective": {"gci": -1.0, "volume": -0.5, "normalize": True, "n_norm": 8},
    },
    meta={
        "variables": "any names used in study.chain (DH a, d, alpha, theta, or a URDF "
        "chain's set values)",
        "indices": ", ".join(INDEX_NAMES) + " (volume for square position Jacobians); "
        "under measure: task " + ", ".join(TASK_INDEX_NAMES),
    },
)
