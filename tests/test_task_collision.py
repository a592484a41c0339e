"""Collision-aware task indices, ports and several arms (docs/task.md) against independent
closed-form enumerations in NumPy: a planar 2R arm's two elbow solutions per target, its
link capsules checked against a ball, and two facing 2R arms over a shared disk."""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.app.config import validate
from designopt.core.keys import streams
from designopt.studies.serial import objective

R_LINK = 0.05
BALL = {"shape": "ball", "center": [0.9, 0.55, 0.0], "radius": 0.15}
DISK = {"shape": "cylinder", "center": [1.1, 0.0, 0.0], "axis": [0, 0, 1], "radius": 0.5,
        "height": 0.0}  # fmt: skip


def _config(n: int, **study) -> dict:
    s = {
        "name": "serial",
        "chain": {"convention": "standard", "joints": [
            {"type": "R", "a": "l1", "limits": [-180, 180]},
            {"type": "R", "a": "l2", "limits": [-180, 180]},
        ]},  # fmt: skip
        "variables": {"l1": [0.3, 1.5], "l2": [0.3, 1.5]},
        "task": {"region": DISK, "ik": {"n_best": 2}},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": n},
        "objective": {"gci": -1.0},
        "collision": {"radius": R_LINK, "obstacles": [BALL]},
    }
    s.update(study)
    return {"study": s, "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 1},
            "precision": "float64", "seed": 3}  # fmt: skip


def _indices(cfg: dict, X: np.ndarray) -> dict[str, np.ndarray]:
    c = validate(copy.deepcopy(cfg), "test")
    prob = objective.problem(c.study, streams(c.seed), jnp.float64)
    f, aux = jax.jit(prob.fn)(prob.params, jnp.asarray(X, jnp.float64), jax.random.key(0))
    return {k: np.asarray(v) for k, v in aux.items()}


# ------------------------------------------------------------------ NumPy oracles


def _seg_point(a, b, c):
    """Distance from points c (..., 3) to segments [a, b] (..., 3)."""
    d = b - a
    t = np.clip(np.sum((c - a) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-300), 0, 1)
    return np.linalg.norm(a + t[..., None] * d - c, axis=-1)


def _disk(n: int, rng, x0: float = DISK["center"][0]) -> np.ndarray:
    r = DISK["radius"] * np.sqrt(rng.uniform(size=n))
    t = 2 * np.pi * rng.uniform(size=n)
    return np.stack([x0 + r * np.cos(t), r * np.sin(t), np.zeros(n)], -1)


def _elbows(p: np.ndarray, l1: float, l2: float, up_only: bool = False):
    """Both elbow solutions (or the q2 ≥ 0 one): (reachable (N,), elbow points (S, N, 3),
    tips (N, 3)) of a planar 2R at its base frame's origin."""
    x, y = p[:, 0], p[:, 1]
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    ok = np.abs(c2) <= 1
    q2 = np.arccos(np.clip(c2, -1, 1))
    out = []
    for s in (1.0,) if up_only else (1.0, -1.0):
        q1 = np.arctan2(y, x) - np.arctan2(l2 * np.sin(s * q2), l1 + l2 * np.cos(s * q2))
        out.append(np.stack([l1 * np.cos(q1), l1 * np.sin(q1), np.zeros_like(q1)], -1))
    return ok, np.stack(out), p


def _free_of_ball(elbow: np.ndarray, tip: np.ndarray) -> np.ndarray:
    c = np.asarray(BALL["center"])
    gap = R_LINK + BALL["radius"]
    base = np.zeros_like(tip)
    return (_seg_point(base, elbow, c) >= gap) & (_seg_point(elbow, tip, c) >= gap)


def test_reach_with_a_ball_obstacle_matches_the_two_elbow_enumeration():
    """reach = the share of the disk where some elbow solution keeps both capsules off the
    ball; within 4 SE of 2e5 enumerated targets at three designs, one of them blocked by
    the ball over part of the disk. clearance ≥ 0 where reached, collision_free ≤ 1."""
    X = np.array([[1.0, 0.6], [0.8, 0.8], [1.2, 0.45]])
    got = _indices(_config(4096), X)
    rng = np.random.default_rng(0)
    p = _disk(200_000, rng)
    blocked_somewhere = False
    for m, (l1, l2) in enumerate(X):
        ok, elbows, tip = _elbows(p, l1, l2)
        free = ok & (_free_of_ball(elbows[0], tip) | _free_of_ball(elbows[1], tip))
        want = free.mean()
        blocked_somewhere |= bool(np.mean(ok & ~free) > 0.01)
        assert abs(got["reach"][m] - want) <= 4 * got["reach_se"][m] + 1e-12, (m, got, want)
        assert 0 < got["collision_free"][m] <= 1
        assert got["clearance"][m] >= 0
    assert blocked_somewhere  # the obstacle matters for at least one design


def test_without_the_obstacle_reach_is_the_annulus_share():
    X = np.array([[1.0, 0.6]])
    cfg = _config(2048)
    cfg["study"]["collision"] = {"radius": R_LINK, "obstacles": []}
    got = _indices(cfg, X)
    ok, _, _ = _elbows(_disk(200_000, np.random.default_rng(1)), 1.0, 0.6)
    assert abs(got["reach"][0] - ok.mean()) <= 4 * got["reach_se"][0]
    assert got["collision_free"][0] == 1.0


def _two_arms(n: int) -> dict:
    cfg = _config(n)
    s = cfg["study"]
    for j in s["chain"]["joints"][1:]:
        j["limits"] = [0, 180]  # one elbow branch: the kept solution is the only one
    s["task"] = {"region": {**DISK, "center": [0.0, 0.0, 0.0]}, "ik": {"n_best": 1}}
    s["collision"] = {"radius": R_LINK, "self": False}
    s["arms"] = [{"base": {"xyz": [-0.8, 0, 0], "rpy": [0, 0, 0]}},
                 {"base": {"xyz": ["gap", 0, 0], "rpy": [0, 0, 180]}}]  # fmt: skip
    s["fixed"] = {"gap": 0.8}
    s["objective"] = {"reach_all": -1.0}
    return cfg


def test_two_facing_arms_reach_all_and_arms_free_match_the_enumeration():
    """Two 2R arms (elbow-up branch only) facing each other across a shared disk:
    reach_all (both arms reach the target) and arms_free (independent target pairs both
    reached: the share whose arms keep clear of each other) against the same
    enumeration over 2e5 targets and target pairs."""
    X = np.array([[0.9, 0.7], [0.75, 0.5]])
    got = _indices(_two_arms(4096), X)
    rng = np.random.default_rng(2)
    p = _disk(200_000, rng, 0.0)
    p2 = _disk(200_000, rng, 0.0)
    for m, (l1, l2) in enumerate(X):
        def arm(pts, side, l1=l1, l2=l2):  # the arm's reach and its capsules in the world
            if side == 0:
                local = pts - np.array([-0.8, 0, 0])
            else:
                local = (pts - np.array([0.8, 0, 0])) * np.array([-1, -1, 1])
            ok, elbow, _ = _elbows(local, l1, l2, up_only=True)
            e = elbow[0]
            if side == 0:
                base, e = np.array([-0.8, 0, 0]), e + np.array([-0.8, 0, 0])
            else:
                base, e = np.array([0.8, 0, 0]), e * np.array([-1, -1, 1]) + np.array([0.8, 0, 0])
            return ok, np.stack([np.broadcast_to(base, e.shape), e, pts], 1)  # (N, 3, 3)

        ok0, _ = arm(p, 0)
        ok1, _ = arm(p, 1)
        want_all = np.mean(ok0 & ok1)
        assert abs(got["reach_all"][m] - want_all) <= 4 * got["reach_all_se"][m], (m, got)
        for k, okk in enumerate((ok0, ok1)):
            assert abs(got[f"reach_{k}"][m] - okk.mean()) <= 4 * got[f"reach_{k}_se"][m]
        a_ok, a_pts = arm(p, 0)
        b_ok, b_pts = arm(p2, 1)
        both = a_ok & b_ok
        gap = np.full(len(p), np.inf)
        for i in range(2):
            for j in range(2):
                gap = np.minimum(gap, _seg_seg(a_pts[:, i], a_pts[:, i + 1],
                                               b_pts[:, j], b_pts[:, j + 1]))  # fmt: skip
        want_free = np.mean((gap >= 2 * R_LINK)[both])
        assert 0 < want_free < 1  # the arms do meet in part of the shared disk
        assert abs(got["arms_free"][m] - want_free) <= 4 * got["arms_free_se"][m], (m, got)
        want_ok = np.mean((gap >= 2 * R_LINK) & both)  # unconditional: over every tuple
        assert abs(got["arms_ok"][m] - want_ok) <= 4 * got["arms_ok_se"][m], (m, got)
        assert got["arms_free_of"][m] == 4096 and got["arms_free_n"][m] > 30


def _seg_seg(a0, a1, b0, b1, n: int = 64, block: int = 4096):
    """Segment–segment distance by dense sampling of the first segment (exact point-to-
    segment distance for each sample): within |a1 − a0|/(2n) of the true distance. In
    blocks of segment pairs: the same numbers (each pair's own arithmetic), four times
    faster than one (n, 2e5, 3) array that fits no cache."""
    out = np.empty(len(a0))
    t = np.linspace(0, 1, n)[:, None, None]
    for s in range(0, len(a0), block):
        e = slice(s, s + block)
        pts = a0[None, e] + t * (a1[e] - a0[e])[None]
        out[e] = np.min(_seg_point(b0[None, e], b1[None, e], pts), 0)
    return out


@pytest.mark.parametrize("bad, says", [
    ({"collision": {"radius": 0.05, "obstacles": [{"shape": "cone"}]}}, "shape"),
    ({"collision": {"radius": -0.05}}, "radius"),
    ({"collision": {"radius": [0.05]}}, "one radius per link"),
    ({"arms": [{"base": {"xyz": [0, 0, 0]}}]}, "arms"),
    ({"arms": [{"base": {"xyz": ["bx", 0, 0]}}, {}]}, "'bx' is neither a design variable"),
    ({"collision": {"radius": 0.05, "obstacles": [
        {"shape": "halfspace", "point": [0, 0, 1], "normal": [0, 0, 1]}]}},
     "obstacles.0.*link 1 overlaps this halfspace in every configuration"),
    ({"task": {"region": DISK, "port": [1.1, 0, 0.5], "insertion": [0.8, 0.9]}},
     "insertion.: no target of the region lies at a depth in"),
    ({"task": {"region": DISK, "port": [0, 0, 0.01]}}, "inside the arm's base link"),
    ({"task": {"region": DISK, "insertion": [0.1, 0.2]}}, "insertion.*is the tool's depth past a port"),
])  # fmt: skip
def test_bad_collision_and_arms_sections_name_their_key(bad, says):
    from designopt.core.errors import ConfigError

    cfg = _config(64)
    cfg["study"].update(bad)
    with pytest.raises(ConfigError, match=says):
        validate(cfg, "test")


def test_port_and_tool_axis_exclude_each_other():
    from designopt.core.errors import ConfigError

    cfg = _config(64)
    cfg["study"]["task"]["port"] = [1.0, 0.0, 0.5]
    cfg["study"]["task"]["tool_axis"] = {"direction": [0, 0, -1]}
    with pytest.raises(ConfigError, match="port and tool_axis exclude each other"):
        validate(cfg, "test")


def test_the_tool_axis_passes_through_the_port_on_a_urdf_arm():
    """configs/urdf_puma560_port.yaml: at every reached target yourdfpy's FK of the URDF
    (the design written into it) puts the tool tip on the target, its z axis on the line
    from the port (within the IK's tolerance), pointing into the body, at a depth within
    the insertion range; the links before the port stay above the skin."""
    from pathlib import Path

    import yaml

    from designopt.kinematics import urdf as U
    from designopt.studies.serial import blocks
    from designopt.studies.serial.commands import set_values

    path = Path(__file__).parents[1] / "configs" / "urdf_puma560_port.yaml"
    cfg = yaml.safe_load(path.read_text())
    cfg["study"]["indices"]["n_samples"] = 64
    c = validate(cfg, str(path))
    s = c.study
    x = {"a2": 0.43, "d4": 0.43, "l_tool": 0.4}
    sol = blocks.solution(s, x, streams(c.seed))
    ok = sol["success"]
    assert ok.mean() > 0.5
    ref = U.Reference(U.export_text(s.chain.urdf_text, set_values(s, x), "port"))
    port = np.asarray(s.task.port)
    d0, d1 = s.task.insertion
    for i in np.flatnonzero(ok):
        T = ref.fk(s.chain.imported, sol["q"][i])
        p, z = T[:3, 3], T[:3, 2]
        target = sol["target_p"][i]
        assert np.linalg.norm(p - target) <= 1e-6
        assert np.linalg.norm(np.cross(port - p, z)) <= 1e-6  # the axis line meets the port
        assert z @ (target - port) > 0
        assert d0 <= np.linalg.norm(target - port) <= d1
    assert np.all(sol["clearance"][ok] >= 0)


PLANAR_URDF = """<?xml version="1.0"?>
<robot name="planar2r">
  <link name="base"/>
  <link name="l1"><collision><origin xyz="0.5 0 0" rpy="0 1.5707963267948966 0"/>
    <geometry><cylinder radius="0.05" length="1.0"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.3 0 0" rpy="0 1.5707963267948966 0"/>
    <geometry><cylinder radius="0.05" length="0.6"/></geometry></collision></link>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3.14159265" upper="3.14159265" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="1.0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.14159265" upper="3.14159265" effort="1" velocity="1"/></joint>
  <joint name="jt" type="fixed"><parent link="l2"/><child link="tip"/>
    <origin xyz="0.6 0 0"/></joint>
</robot>
"""


def test_urdf_collision_shapes_score_like_the_same_capsules_from_joint_origins(tmp_path):
    """links: urdf with a cylinder along each link of a planar 2R URDF (capsules of the
    same radius, end to end) gives the reach of links: auto on the same chain."""
    (tmp_path / "planar.urdf").write_text(PLANAR_URDF)
    cfg = _config(2048)
    s = cfg["study"]
    s["chain"] = {"urdf": str(tmp_path / "planar.urdf"), "tip": "tip",
                  "set": {"jt.origin.x": "l2"}}  # fmt: skip
    s["variables"] = {"l2": [0.3, 1.5]}
    s["indices"]["jacobian"] = ["vx", "vy"]
    auto = _indices(cfg, np.array([[0.6]]))
    s["collision"] = {"links": "urdf", "obstacles": [BALL]}
    got = _indices(cfg, np.array([[0.6]]))
    assert abs(got["reach"][0] - auto["reach"][0]) <= 2 * got["reach_se"][0]
    assert abs(got["clearance"][0] - auto["clearance"][0]) <= 1e-6 + 2 * got["clearance_se"][0]
    ok, elbows, tip = _elbows(_disk(200_000, np.random.default_rng(4)), 1.0, 0.6)
    want = np.mean(ok & (_free_of_ball(elbows[0], tip) | _free_of_ball(elbows[1], tip)))
    assert abs(got["reach"][0] - want) <= 4 * got["reach_se"][0]
    s["collision"]["radius"] = 0.05
    from designopt.core.errors import ConfigError

    with pytest.raises(ConfigError, match="URDF's <collision> shapes give the radii"):
        validate(copy.deepcopy(cfg), "test")
