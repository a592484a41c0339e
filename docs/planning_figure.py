"""Draw docs/img/planning_naive_vs_best.png: the planning case (configs/port_placement.yaml)
with the naive layout (both ports on a line straight above the target) beside the one
its run found, each arm at the median tuple of targets of its own IK solution, with the
abdomen, the ports, the vessel and the organ. Run from the repository's root."""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def main() -> Path:
    jax.config.update("jax_enable_x64", True)
    from test_planning import BEST, NAIVE

    from designopt.app.config import validate
    from designopt.core.keys import streams
    from designopt.figures import robot
    from designopt.studies.serial import blocks, drawing
    from designopt.studies.serial.mechanism import build
    from designopt.studies.serial.settings import length_unit

    path = ROOT / "configs/port_placement.yaml"
    c = validate(yaml.safe_load(path.read_text()), str(path))
    s, keys = c.study, streams(c.seed)
    mech = build(s)
    scenes = []
    for name, d in (("naive: ports on a line above the target", NAIVE),
                    ("planned: the run's front design", BEST)):  # fmt: skip
        x = np.asarray([d[k] for k in s.variables], np.float64)
        sol = blocks.solution(s, x, keys)
        sc = drawing.arms_scene(s, mech, x, sol, keys)
        tup = drawing.arm_tuples(s, mech, x, sol, keys)
        label, arms, pairs, _ = tup[1] if len(tup) > 1 else tup[0]  # the median tuple
        ok = np.asarray(sol["success"]).reshape(len(s.arms), -1).all(0).mean()
        scenes.append(robot.Scene(**{**sc.__dict__, "arms": arms, "collisions": pairs,
                                     "title": f"{name}\nboth arms reach {100 * ok:.0f} % "
                                     f"of the targets; {label}"}))  # fmt: skip
    fig = robot.figure(scenes, length_unit(s), "Two UR5s through ports on the abdominal wall "
                       "(skin colour), a vessel and an organ inside (red)")  # fmt: skip
    out = ROOT / "docs/img/planning_naive_vs_best.png"
    fig.savefig(out, dpi=110, bbox_inches="tight")
    return out


if __name__ == "__main__":
    print(main())
