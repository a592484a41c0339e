"""A study's link capsules do not depend on JAX's 64-bit mode (``bodies.geometry``): the
CLI runs a config's checks, which build the capsules first, before it turns 64-bit mode
on. In float32 a link of zero length (a Panda's between joints 5 and 6, whose origins
coincide) measured about 1e-8 m and was kept as a capsule; a later command that read
the checks' marker and skipped them built the capsules in float64 and dropped it: two
programs, and other clearances, for one config."""

from __future__ import annotations

import jax
import pytest

from designopt.app.config import validate
from designopt.studies.serial import bodies
from designopt.studies.serial.mechanism import build

# the Panda's kinematics (Franka Emika's URDF as example-robot-data ships it: joint
# origins and limits only; links without geometry)
_J = [  # name, type, parent, child, xyz, rpy, limits
    ("j1", "revolute", "l0", "l1", "0 0 0.333", "0 0 0", (-2.8973, 2.8973)),
    ("j2", "revolute", "l1", "l2", "0 0 0", "-1.5707963267948966 0 0", (-1.7628, 1.7628)),
    ("j3", "revolute", "l2", "l3", "0 -0.316 0", "1.5707963267948966 0 0", (-2.8973, 2.8973)),
    ("j4", "revolute", "l3", "l4", "0.0825 0 0", "1.5707963267948966 0 0", (-3.0718, -0.0698)),
    ("j5", "revolute", "l4", "l5", "-0.0825 0.384 0", "-1.5707963267948966 0 0", (-2.8973, 2.8973)),
    ("j6", "revolute", "l5", "l6", "0 0 0", "1.5707963267948966 0 0", (-0.0175, 3.7525)),
    ("j7", "revolute", "l6", "l7", "0.088 0 0", "1.5707963267948966 0 0", (-2.8973, 2.8973)),
    ("tcp", "fixed", "l7", "tcp", "0 0 0.2104", "0 0 -0.7853981633974483", None),
]  # fmt: skip


def _urdf() -> str:
    links = "".join(f'<link name="{n}"/>' for n in ["l0", "l1", "l2", "l3", "l4", "l5", "l6",
                                                      "l7", "tcp"])  # fmt: skip
    joints = ""
    for name, typ, par, ch, xyz, rpy, lim in _J:
        limit = "" if lim is None else f'<limit lower="{lim[0]}" upper="{lim[1]}" effort="1" velocity="1"/>'
        joints += (f'<joint name="{name}" type="{typ}"><origin xyz="{xyz}" rpy="{rpy}"/>'
                   f'<parent link="{par}"/><child link="{ch}"/><axis xyz="0 0 1"/>{limit}</joint>')  # fmt: skip
    return f'<?xml version="1.0"?><robot name="panda">{links}{joints}</robot>'


def _settings(tmp_path):
    (tmp_path / "panda.urdf").write_text(_urdf())
    raw = {
        "study": {
            "name": "serial",
            "chain": {"urdf": str(tmp_path / "panda.urdf"), "tip": "tcp", "set": {"j3.origin.length": "l3",
                                                          "j5.origin.length": "l5",
                                                          "tcp.origin.z": "l_tool"}},
            "variables": {"l3": [0.25, 0.40], "l5": [0.30, 0.45], "l_tool": [0.20, 0.40]},
            "task": {"region": {"shape": "box", "center": [0.5, 0.0, -0.15],
                                "size": [0.1, 0.1, 0.06]},
                     "port": [0.5, 0.0, -0.05], "insertion": [0.05, 0.3]},
            "collision": {"radius": 0.04, "self": True, "obstacles": [
                {"shape": "halfspace", "point": [0, 0, -0.05], "normal": [0, 0, 1]}]},
            "indices": {"measure": "task", "n_samples": 16},
            "objective": {"gci": -1.0},
        },
        "precision": "float64",
    }  # fmt: skip
    cfg = validate(raw, str(tmp_path / "c.yaml"), checks=False)
    return cfg.study


@pytest.mark.parametrize("x64", [False, True])
def test_the_capsules_are_the_same_in_either_mode(tmp_path, x64):
    s = _settings(tmp_path)
    mech = build(s)
    bodies._GEOMETRY.clear()
    with jax.enable_x64(x64):
        g = bodies.geometry(s, mech)
    bodies._GEOMETRY.clear()
    # the chain's links 0-6 (joint i to joint i + 1, the last to the tip): link 0
    # (base to joint 2: both at 0.333 m) and link 4 (joint 5 to joint 6) have zero length
    assert g.links == (1, 2, 3, 5, 6), g.links
