"""Is the printed ± of the task indices what another seed gives? (issue #65, item 1)

One fixed design per case is scored at S seeds (``designopt.evaluate``, one process, so
the block program compiles once per case; ``--seed s`` changes the targets' draw and the
IK's database and seeds). For every index read at the IK's solutions (gci, gci_q05,
manipulability, joint_margin, clearance, reach, the multi-arm shares) it prints the mean
over the seeds, the SD across the seeds, the RMS of the printed SE, and their ratio
SD / RMS(SE): about 1 when the SE is honest (its own noise at S = 16 seeds: the SD's
relative error is about 1/√(2(S − 1)) = 18 %), far above 1 when the SE leaves a shared
draw out. Issue #65 asks for a ratio ≤ 1.5 on every index of every case.

Cases:
- ``planning``: configs/port_placement.yaml (two UR5s with instruments through ports in a
  mesh abdomen, collision, its own IK settings) at the planned layout of docs/planning.md
  (b=0.5085 by=-0.018 px=0.021 py0=-0.119 py1=0.126: every target reached), 128 targets;
- ``naive``: the same at the naive layout its header names (b=0.6 by=0 px=0.03 py0=0
  py1=0: a third of the targets reached);
- ``planar3r``: tests/data/planar3r_task.yaml's planar 3R (l = 1, 0.8, 0.5) on its disk's
  bounding box drawn afresh per seed (the file's fixed points replaced by a box region of
  zero height), default IK settings, 128 targets (no port: a planar arm cannot hold a
  tool axis through a port);
- ``ur5_port``: tests/data/ur5_port.yaml's UR5 with its straight instrument through a port
  (collision, the vessel inside), its tissue box drawn afresh per seed, default IK
  settings, 128 targets;
- ``panda_port``: a Franka Panda (7 joints, Franka's kinematics written out as a URDF
  here, a 0.3 m straight instrument after the flange) through a port, default IK
  settings, 128 targets.

    python benchmarks/se_honesty.py                          # every case, 16 seeds
    python benchmarks/se_honesty.py --only planar3r --seeds 8
    python benchmarks/se_honesty.py --tree /tmp/old   # the numbers of the designopt package
                                                     # under /tmp/old (e.g. before a change)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

IK_READ = ("gci", "gci_q05", "manipulability", "joint_margin", "clearance", "reach",
           "reach_0", "reach_1", "reach_all", "collision_free", "arms_ok", "arms_free",
           "instrument_ok", "instrument_angle")  # fmt: skip

PANDA_URDF = """<?xml version="1.0"?>
<robot name="panda_instrument">
  <link name="panda_link0"/>
{links}
</robot>
"""
# (xyz, rpy, limits (rad)) of Franka Emika's panda_joint1..7 (franka_description)
PANDA_JOINTS = [
    ((0, 0, 0.333), (0, 0, 0), (-2.8973, 2.8973)),
    ((0, 0, 0), (-math.pi / 2, 0, 0), (-1.7628, 1.7628)),
    ((0, -0.316, 0), (math.pi / 2, 0, 0), (-2.8973, 2.8973)),
    ((0.0825, 0, 0), (math.pi / 2, 0, 0), (-3.0718, -0.0698)),
    ((-0.0825, 0.384, 0), (-math.pi / 2, 0, 0), (-2.8973, 2.8973)),
    ((0, 0, 0), (math.pi / 2, 0, 0), (-0.0175, 3.7525)),
    ((0.088, 0, 0), (math.pi / 2, 0, 0), (-2.8973, 2.8973)),
]


def panda_urdf() -> str:
    parts = []
    for i, (xyz, rpy, (lo, hi)) in enumerate(PANDA_JOINTS, 1):
        parts.append(
            f'  <link name="panda_link{i}"/>\n'
            f'  <joint name="panda_joint{i}" type="revolute">\n'
            f'    <parent link="panda_link{i - 1}"/><child link="panda_link{i}"/>\n'
            f'    <origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>\n'
            f'    <axis xyz="0 0 1"/><limit lower="{lo}" upper="{hi}" effort="87" velocity="2"/>\n'
            f'  </joint>')
    parts.append('  <link name="instrument_tip"/>\n'
                 '  <joint name="instrument_joint" type="fixed">\n'
                 '    <parent link="panda_link7"/><child link="instrument_tip"/>\n'
                 '    <origin xyz="0 0 0.407" rpy="0 0 0"/>\n'
                 '  </joint>')  # fmt: skip
    return PANDA_URDF.format(links="\n".join(parts))


def cases(tmp: Path) -> dict[str, tuple[str, dict, dict]]:
    """name -> (config path, overrides, design)."""
    (tmp / "panda.urdf").write_text(panda_urdf())
    (tmp / "panda_port.yaml").write_text(json.dumps({
        "study": {"name": "serial",
                  "chain": {"urdf": "panda.urdf", "base": "panda_link0", "tip": "instrument_tip",
                            "set": {"panda_joint5.origin.y": "l5"}},
                  "variables": {"l5": [0.3, 0.45]},
                  "task": {"region": {"shape": "box", "center": [0.5, 0.0, 0.15],
                                      "size": [0.08, 0.08, 0.06]},
                           "port": [0.48, 0.0, 0.35], "insertion": [0.05, 0.40]},
                  "indices": {"jacobian": "position", "norm": "2", "measure": "task",
                              "n_samples": 128},
                  "objective": {"gci": -1.0}},
        "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 1, "n_runs": 1},
        "precision": "float64", "seed": 0}))  # fmt: skip
    return {
        "planning": (str(ROOT / "configs/port_placement.yaml"), {},
                     {"b": 0.5085, "by": -0.018, "px": 0.021, "py0": -0.119, "py1": 0.126}),
        "naive": (str(ROOT / "configs/port_placement.yaml"), {},
                  {"b": 0.6, "by": 0.0, "px": 0.03, "py0": 0.0, "py1": 0.0}),
        "planar3r": (str(ROOT / "tests/data/planar3r_task.yaml"),
                     {"study.task.region": {"shape": "box", "center": [1.2, 0.3, 0.0],
                                            "size": [1.0, 1.0, 0.0]},
                      "study.task.ik": {}, "study.indices.n_samples": 128},
                     {"l1": 1.0, "l2": 0.8, "l3": 0.5}),
        "ur5_port": (str(ROOT / "tests/data/ur5_port.yaml"),
                     {"study.task.region": {"shape": "box", "center": [0.60, 0.0, 0.10],
                                            "size": [0.10, 0.10, 0.06]},
                      "study.task.ik": {}, "study.indices.n_samples": 128},
                     {"a2": 0.425, "a3": 0.39225, "tilt": 0.0}),
        "panda_port": (str(tmp / "panda_port.yaml"), {}, {"l5": 0.384}),
    }


def measure(path: str, over: dict, design: dict, seeds: int, seed0: int = 0
            ) -> dict[str, dict[str, float]]:  # fmt: skip
    import designopt

    rows: dict[str, list[tuple[float, float]]] = {}
    t0 = time.perf_counter()
    times = []
    for s in range(seed0, seed0 + seeds):
        cfg = designopt.load_config(path, over | {"seed": s})
        t = time.perf_counter()
        res = designopt.evaluate(cfg, design)
        times.append(time.perf_counter() - t)
        for k in IK_READ:
            if k in res and k + "_se" in res:
                rows.setdefault(k, []).append((float(res[k][0]), float(res[k + "_se"][0])))
    out = {}
    for k, vs in rows.items():
        v = np.array([a for a, _ in vs])
        se = np.array([b for _, b in vs])
        if not np.all(np.isfinite(v)):
            continue
        sd = float(np.std(v, ddof=1))
        rms = float(np.sqrt(np.mean(se**2)))
        out[k] = {"mean": float(np.mean(v)), "sd": sd, "rms_se": rms,
                  # the same value at every seed with SE 0 (an index stuck at 0, say) has
                  # nothing to cover: no ratio
                  "ratio": sd / rms if rms > 0 else math.nan if sd == 0 else math.inf}  # fmt: skip
    out["_time"] = {"first_s": times[0], "warm_s": float(np.median(times[1:])) if seeds > 1
                    else math.nan, "total_s": time.perf_counter() - t0}  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", action="append", help="a case (repeatable)")
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--seed0", type=int, default=0, help="the first seed (then seed0 + 1, ...)")
    ap.add_argument("--set", action="append", default=[], help="KEY=VALUE (YAML) for every case")
    ap.add_argument("--json", help="write the numbers here")
    ap.add_argument("--tree", help="import designopt from this folder (it holds designopt/), "
                                   "not the installed one")  # fmt: skip
    a = ap.parse_args()
    if a.tree:  # ahead of an editable install's finder, which sys.path alone does not pass
        sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
        sys.path.insert(0, str(Path(a.tree).resolve()))
    import designopt

    print(f"# designopt from {Path(designopt.__file__).parent}")
    import yaml

    extra = {}
    for kv in a.set:
        k, _, v = kv.partition("=")
        extra[k] = yaml.safe_load(v)
    print(f"# {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; {a.seeds} seeds per case "
          f"from {a.seed0}")
    result = {}
    with tempfile.TemporaryDirectory() as d:
        cs = cases(Path(d))
        for name, (path, over, design) in cs.items():
            if a.only and name not in a.only:
                continue
            r = measure(path, over | extra, design, a.seeds, a.seed0)
            result[name] = r
            t = r.pop("_time")
            print(f"\n## {name}  (first eval {t['first_s']:.1f} s incl. compile, "
                  f"then {t['warm_s']:.2f} s per seed)")  # fmt: skip
            print(f"{'index':16s} {'mean':>10s} {'SD(seeds)':>10s} {'RMS SE':>10s} {'ratio':>6s}")
            for k, v in r.items():
                flag = "" if not v["ratio"] > 1.5 else "  > 1.5"
                print(f"{k:16s} {v['mean']:10.4g} {v['sd']:10.3g} {v['rms_se']:10.3g} "
                      f"{v['ratio']:6.2f}{flag}")  # fmt: skip
            r["_time"] = t
            sys.stdout.flush()
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
