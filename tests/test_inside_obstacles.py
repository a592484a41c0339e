"""Anatomy inside the patient (``inside: true`` obstacles, docs/planning.md) against the
closed form: with the tip on the target and the tool axis through the port, the
instrument inside the body is the segment from the port to the target, so a target is
reached exactly when the arm reaches it without the inside ball and that segment keeps
the ball's radius plus the tool's radius from its centre. Target by target, on a planar
chain (an inline URDF) and on a spatial one (the UR5 with its instrument)."""

from __future__ import annotations

import copy
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.app.config import validate
from designopt.core.keys import streams
from designopt.studies.serial import blocks, bodies

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parents[1]
TOOL_R = 0.005

PLANAR = """<?xml version="1.0"?>
<robot name="planar3r">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3.1" upper="3.1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 0 1"/><limit lower="-3.1" upper="3.1" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 0 1"/><limit lower="-3.1" upper="3.1" effort="1" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="l3"/><child link="tip"/>
    <origin xyz="0.35 0 0" rpy="0 1.5707963267948966 0"/></joint>
</robot>
"""


def _planar(tmp: Path) -> tuple[dict, list[float], dict]:
    (tmp / "planar.urdf").write_text(PLANAR)
    study = {
        "name": "serial",
        "chain": {"urdf": str(tmp / "planar.urdf"), "base": "base", "tip": "tip",
                  "set": {"j2.origin.x": "l1"}},  # fmt: skip
        "variables": {"l1": [0.45, 0.55]},
        "task": {"region": {"shape": "cylinder", "center": [0.78, 0.12, 0.0],
                            "axis": [0, 0, 1], "radius": 0.14, "height": 0.0},
                 "port": [0.6, 0.32, 0.0], "insertion": [0.02, 0.34]},  # fmt: skip
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": 256},
    }
    ball = {"shape": "ball", "center": [0.67, 0.24, 0.0], "radius": 0.03, "inside": True}
    return study, [0.5], ball


def _ur5(tmp: Path) -> tuple[dict, list[float], dict]:
    study = {
        "name": "serial",
        "chain": {"urdf": str(ROOT / "configs/robots/ur5/ur5_instrument.urdf"),
                  "base": "base_link", "tip": "instrument_tip",
                  "set": {"elbow_joint.origin.z": "a2"}},  # fmt: skip
        "variables": {"a2": [0.35, 0.5]},
        "task": {"region": {"shape": "box", "center": [0.45, 0.1, 0.05],
                            "size": [0.1, 0.1, 0.06]},
                 "port": [0.45, 0.1, 0.2], "insertion": [0.05, 0.25]},  # fmt: skip
        "indices": {"jacobian": "position", "norm": "2", "measure": "task", "n_samples": 256},
    }
    ball = {"shape": "ball", "center": [0.46, 0.11, 0.12], "radius": 0.02, "inside": True}
    return study, [0.425], ball


def _solve(study: dict, x: list[float], obstacles: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    s = copy.deepcopy(study)
    s["objective"] = {"reach": -1.0}
    s["collision"] = {"radius": 0.02, "self": False, "margin": 0.0, "tool_radius": TOOL_R,
                      "obstacles": obstacles}  # fmt: skip
    c = validate({"study": s, "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 1},
                  "precision": "float64", "seed": 5}, "test")  # fmt: skip
    out = blocks.solution(c.study, x, streams(c.seed))
    return out["target_p"], out["success"]


def _seg_point(a, b, c):
    d = b - a
    t = np.clip(np.sum((c - a) * d, -1) / np.sum(d * d, -1), 0, 1)
    return np.linalg.norm(a + t[..., None] * d - c, axis=-1)


@pytest.mark.parametrize("make", [_planar, _ur5], ids=["planar", "spatial"])
def test_a_target_is_reached_when_the_port_segment_clears_the_inside_ball(tmp_path, make):
    study, x, ball = make(tmp_path)
    # a far-away inside obstacle keeps the program's structure and checks nothing
    far = dict(ball, center=[9.0, 9.0, 9.0])
    p, alone = _solve(study, x, [far])
    p2, with_ball = _solve(study, x, [ball])
    np.testing.assert_array_equal(p, p2)
    port = np.asarray(study["task"]["port"])
    d = _seg_point(port, p, np.asarray(ball["center"]))
    need = ball["radius"] + TOOL_R
    clear = d >= need
    sure = np.abs(d - need) > 1e-6  # away from a tie (the IK's tolerance)
    assert alone.mean() > 0.4 and (~clear & alone).sum() >= 10  # the ball blocks some
    np.testing.assert_array_equal(with_ball[sure], (alone & clear)[sure])


def test_the_inside_part_is_the_chain_beyond_the_port_plane():
    """inside_pieces against a hand-built chain: a capsule crossing the plane keeps the
    part past the crossing, the later ones are whole, the earlier ones are out."""
    seg = jnp.asarray([[[0, 0, 1.0], [0, 0, 0.5]],   # outside (z > port)
                       [[0, 0, 0.5], [0, 0, -0.5]],  # crosses z = 0 at its middle
                       [[0, 0, -0.5], [0.2, 0, -0.7]]])  # fmt: skip
    port, z = jnp.asarray([0.0, 0, 0]), jnp.asarray([0.0, 0, -1])
    pieces, inside = bodies.inside_pieces(seg, port, z)
    np.testing.assert_array_equal(np.asarray(inside), [False, True, True])
    np.testing.assert_allclose(np.asarray(pieces[1]), [[0, 0, 0], [0, 0, -0.5]], atol=1e-15)
    np.testing.assert_allclose(np.asarray(pieces[2]), np.asarray(seg[2]))
    # nothing outside the plane: nothing is inside (no port crossing)
    _, none = bodies.inside_pieces(seg - jnp.asarray([0, 0, 2.0]), port, z)
    assert not np.any(np.asarray(none))


def test_an_inside_obstacle_needs_a_port(tmp_path, capsys):
    import yaml

    from designopt.cli.commands import main

    study, _, ball = _planar(tmp_path)
    del study["task"]["port"], study["task"]["insertion"]
    study["objective"] = {"reach": -1.0}
    study["collision"] = {"radius": 0.02, "obstacles": [ball]}
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump({"study": study, "precision": "float64"}))
    capsys.readouterr()
    assert main(["eval", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "collision.obstacles.0.inside" in err and "port" in err
