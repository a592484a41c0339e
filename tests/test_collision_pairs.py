"""Self-collision pairs that mean something, the port's exemption, ports and several arms
under ``links: urdf``, and the multi-arm reach bound and warnings (issue #45 parts 3-4;
docs/task.md, docs/urdf.md).

References are independent NumPy computations: a planar chain's forward kinematics and
exact 2-D segment distances for the pair rule; yourdfpy's link frames and densely
sampled segment distances for the clearance terms of the UR5; hand-made capsules for the
port's cut; dense samples of the regions for the distance between a region and the box
an arm's base can be in."""

from __future__ import annotations

import copy
import math
import sysconfig
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from designopt.app.config import validate
from designopt.core.errors import ConfigError
from designopt.core.keys import streams
from designopt.kinematics import task as tk
from designopt.studies.serial import bodies, objective, reach
from designopt.studies.serial.mechanism import build

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
UR5 = ROBOTS / "ur_description/urdf/ur5_robot.urdf"
PANDA = ROBOTS / "panda_description/urdf/panda.urdf"
needs_erd = pytest.mark.skipif(not (UR5.is_file() and PANDA.is_file()),
                               reason="example-robot-data is not installed")  # fmt: skip


def _run_cfg(study: dict, seed: int = 3) -> dict:
    return {"study": study, "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 1},
            "precision": "float64", "seed": seed}  # fmt: skip


def _indices(cfg: dict, X: np.ndarray) -> dict[str, np.ndarray]:
    c = validate(copy.deepcopy(cfg), "test")
    prob = objective.problem(c.study, streams(c.seed), jnp.float64)
    f, aux = jax.jit(prob.fn)(prob.params, jnp.asarray(X, jnp.float64), jax.random.key(0))
    return {k: np.asarray(v) for k, v in aux.items()}


# ------------------------------------------------------------- the pair rule (E)

LENGTHS = [1.0, 0.05, 1.0, 0.09, 1.0]  # a short link before link 2 and before link 4
LIMITS = [[-180, 180], [-20, 20], [-20, 20], [-170, 170], [-170, 170]]
R_LINK = 0.04


def _planar_study() -> dict:
    joints = [{"type": "R", "a": ("l0" if i == 0 else v), "alpha": 0, "d": 0, "theta": 0,
               "limits": LIMITS[i]} for i, v in enumerate(LENGTHS)]  # fmt: skip
    return {
        "name": "serial",
        "chain": {"convention": "standard", "joints": joints},
        "variables": {"l0": [0.99, 1.01]},
        "task": {"region": {"shape": "ball", "center": [2.0, 0.5, 0.0], "radius": 0.2}},
        "collision": {"radius": R_LINK, "self": True},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": 64},
        "objective": {"gci": -1.0},
    }


def _seg2(p0, p1, q0, q1):
    """Exact distance between 2-D segments (..., 2) each: 0 where they cross, else the
    least of the four end-to-segment distances."""

    def pt(p, a, b):
        d = b - a
        t = np.clip(np.sum((p - a) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-300), 0, 1)
        return np.linalg.norm(a + t[..., None] * d - p, axis=-1)

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    r, s = p1 - p0, q1 - q0
    den = cross(r, s)
    ok = np.abs(den) > 1e-300
    t = np.where(ok, cross(q0 - p0, s) / np.where(ok, den, 1), -1)
    u = np.where(ok, cross(q0 - p0, r) / np.where(ok, den, 1), -1)
    hit = ok & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    d = np.minimum(np.minimum(pt(p0, q0, q1), pt(p1, q0, q1)),
                   np.minimum(pt(q0, p0, p1), pt(q1, p0, p1)))  # fmt: skip
    return np.where(hit, 0.0, d)


def test_pair_rule_on_a_planar_chain_matches_a_numpy_enumeration():
    """Five planar links: the pair across the 0.05 link always overlaps (2r = 0.08), the
    pair across the 0.09 link is always within 0.25·2r of touching ("always near"), pairs
    that the ±20° joints keep apart are never near, the rest are checked; the sampled
    distance bands lie within an independent enumeration's (200,000 configurations)."""
    s = validate(_run_cfg(_planar_study()), "test").study
    mech = build(s)
    g = bodies.geometry(s, mech)
    near = 0.25 * 2 * R_LINK
    # NumPy: joint origins of the planar chain, cumulative angles
    rng = np.random.default_rng(5)
    lim = np.radians(np.asarray(LIMITS, float))
    ang = np.cumsum(rng.uniform(lim[:, 0], lim[:, 1], (200_000, 5)), -1)
    P = np.zeros((6, 200_000, 2))
    for k in range(5):
        P[k + 1] = P[k] + LENGTHS[k] * np.stack([np.cos(ang[:, k]), np.sin(ang[:, k])], -1)
    want: dict[str, set] = {"always": set(), "near": set(), "never": set(), "pairs": set()}
    bands = {}
    for i in range(5):
        for j in range(i + 2, 5):
            d = _seg2(P[i], P[i + 1], P[j], P[j + 1]) - 2 * R_LINK
            bands[(i, j)] = (d.min(), d.max())
            if np.mean(d < 0) >= bodies.ALWAYS:
                want["always"].add((i, j))
            elif d.max() < near:
                want["near"].add((i, j))
            elif d.min() >= near:
                want["never"].add((i, j))
            else:
                want["pairs"].add((i, j))
    assert (0, 2) in want["always"] and (2, 4) in want["near"] and want["never"] and want["pairs"]
    for k in want:
        assert set(getattr(g, k)) == want[k], (k, getattr(g, k), want[k], bands)
    for i, j, lo, hi in g.bands:  # a sample's band lies within the enumeration's (and l0 ≈ 1)
        assert bands[(i, j)][0] - 0.02 <= lo <= hi <= bands[(i, j)][1] + 0.02, (i, j)
    text = "\n".join(bodies.pair_lines(s, mech))
    assert "always near         link 3 × link 5" in text
    assert "always in collision link 1 × link 3" in text


@needs_erd
@pytest.mark.parametrize("robot, dropped", [
    ("ur5", [("wrist_1_link", "wrist_3_link")]),
    ("panda", [("panda_link5", "panda_link7"), ("panda_link6", "panda_hand")]),
])  # fmt: skip
def test_ur5_and_panda_leave_out_their_always_near_shape_pairs(robot, dropped):
    """The shapes with one short link between them (a UR5's wrists 1 and 3; a Panda's
    links 5 and 7, link 6 and the hand) are within a few millimetres whatever the joints:
    left out as always near, with their bands below NEAR·(r_i + r_j)."""
    s = validate(_run_cfg(_robot_study(robot, 64)), "test").study
    g = bodies.geometry(s, build(s))
    names = [(g.names[i], g.names[j]) for i, j in g.near]
    assert names == dropped
    band = {(i, j): (lo, hi) for i, j, lo, hi in g.bands}
    for i, j in g.near:
        assert band[(i, j)][1] < bodies.NEAR * (g.radii[i] + g.radii[j])
        assert band[(i, j)][1] < 0.011  # metres: never a centimetre apart
    assert not set(g.near) & set(g.pairs)


def _robot_study(robot: str, n: int) -> dict:
    if robot == "ur5":
        chain = {"urdf": str(UR5), "base": "base_link", "tip": "tool0",
                 "set": {"elbow_joint.origin.z": "a2", "wrist_1_joint.origin.z": "a3"}}  # fmt: skip
        var = {"a2": [0.25, 0.60], "a3": [0.25, 0.60]}
        center = [0.45, 0.1, 0.2]
    else:
        chain = {"urdf": str(PANDA), "base": "panda_link0", "tip": "panda_hand_tcp",
                 "set": {"panda_joint3.origin.length": "l3",
                         "panda_joint5.origin.length": "l5"}}  # fmt: skip
        var = {"l3": [0.2, 0.45], "l5": [0.25, 0.5]}
        center = [0.45, 0.0, 0.3]
    return {
        "name": "serial", "chain": chain, "variables": var,
        "task": {"region": {"shape": "box", "center": center, "size": [0.2, 0.2, 0.2]},
                 "ik": {"n_best": 1, "climb": 0, "neighbours": 0}},
        "collision": {"links": "urdf", "self": True},
        "indices": {"jacobian": "position", "norm": "2", "measure": "task", "n_samples": n},
        "objective": {"gci": -1.0},
    }  # fmt: skip


def _seg3(a0, a1, b0, b1, n: int = 4001) -> float:
    """Segment–segment distance: a dense sample of the first segment, each point's exact
    distance to the second (within |a1 − a0|/(2(n − 1)) of the true distance)."""
    t = np.linspace(0, 1, n)[:, None]
    p = a0 + t * (a1 - a0)
    d = b1 - b0
    u = np.clip((p - b0) @ d / max(float(d @ d), 1e-300), 0, 1)
    return float(np.min(np.linalg.norm(b0 + u[:, None] * d - p, axis=1)))


@needs_erd
def test_ur5_clearance_terms_match_yourdfpy_frames_and_numpy_distances():
    """pair_lines' clearance at a design and configuration: the least kept pair's signed
    distance, recomputed from yourdfpy's link frames (the design written into the URDF)
    and a dense NumPy segment distance, and the least term is the least of all kept
    pairs."""
    from designopt.kinematics import urdf as U
    from designopt.studies.serial.mechanism import set_values

    s = validate(_run_cfg(_robot_study("ur5", 64)), "test").study
    mech = build(s)
    g = bodies.geometry(s, mech)
    x = {"a2": 0.5, "a3": 0.33}
    q = np.radians([20.0, -70.0, 100.0, -40.0, 60.0, 10.0])
    lines = bodies.pair_lines(s, mech, x, q, top=len(g.pairs))
    imp = s.chain.imported
    ref = U.Reference(U.export_text(s.chain.urdf_text, set_values(s, x), "ur5")).u
    ref.update_cfg(np.array([dict(zip(imp.active, q, strict=True)).get(n, 0.0)
                             for n in ref.actuated_joint_names]))  # fmt: skip
    caps = g.urdf[2]
    ends = []
    for c in caps:
        T = ref.get_transform(c.link, imp.base)
        ends.append((T[:3, :3] @ c.a + T[:3, 3], T[:3, :3] @ c.b + T[:3, 3], c.radius))
    lab = bodies.capsule_labels(g)
    want = {f"{lab[i]} × {lab[j]}": _seg3(ends[i][0], ends[i][1], ends[j][0], ends[j][1])
            - ends[i][2] - ends[j][2] for i, j in g.pairs}  # fmt: skip
    got = {}
    for ln in lines:
        if ln.startswith("  ") and " m  " in ln and "sampled" not in ln:
            v, what = ln.strip().split(" m  ", 1)
            got[what] = float(v)
    assert set(got) == set(want)
    for k, v in want.items():
        assert abs(got[k] - v) <= 1e-4 + 1e-3 * abs(v), (k, got[k], v)  # printed to 4 digits
    least = min(want.values())
    head = next(ln for ln in lines if "clearance" in ln)
    assert f"clearance {least:+.4g} m" in head


@needs_erd
@pytest.mark.slow
def test_ur5_clearance_varies_with_the_design():
    """With the always-near wrist pair left out, the UR5's clearance follows the design
    (docs/urdf.md measured 6 mm at the URDF's lengths and 78 mm at a2 = 0.6, a3 = 0.55;
    it was pinned to 3-6 mm by the wrists before)."""
    cfg = _run_cfg(_robot_study("ur5", 32))
    out = _indices(cfg, np.array([[0.425, 0.39225], [0.6, 0.55]]))
    assert out["reach"].min() > 0.9
    c, se = out["clearance"], out["clearance_se"]
    assert c[1] - c[0] > 0.02 and c[1] > 4 * c[0], (c, se)


# ------------------------------------------------------------- the port's cut (B)

SKIN = {"shape": "halfspace", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}
PORT = np.array([2.0, 0.0, 0.0])
Z = np.array([0.0, 0.0, -1.0])  # the tool axis, into the patient


def _clear(seg, radii) -> float:
    from designopt.kinematics.collision import Collision

    g = bodies.Geometry(tuple(range(len(radii))), tuple(radii), (), (), 0.0, False, 10.0)
    obst = Collision(links="auto", radius=0.01, obstacles=[SKIN]).params()
    return float(bodies.obstacle_and_self(g, obst, jnp.asarray(seg), jnp.asarray(PORT),
                                          jnp.asarray(Z)))  # fmt: skip


def test_port_cut_exempts_only_the_distal_part_beyond_the_port():
    """An elbow that dips below the skin away from the port is checked in full (it is in
    the patient, not in the port); the instrument through the port is cut 2r before the
    plane; links wholly beyond the plane after it are not checked; a capsule's ends may
    come in either order."""
    r = 0.02
    up = np.array([[[0.0, 0, 0.5], [1.0, 0, 0.3]], [[1.0, 0, 0.3], [2.0, 0, 0.3]],
                   [[2.0, 0, 0.3], [2.0, 0, -0.1]], [[2.0, 0, -0.1], [2.3, 0, -0.2]]])  # fmt: skip
    radii = (0.05, 0.05, r, r)
    # the tool's kept piece ends 2r above the skin: clearance r; the wrist link beyond
    # the plane (the last) is not checked though it lies inside the half-space
    assert _clear(up, radii) == pytest.approx(r, abs=1e-12)
    dip = up.copy()
    dip[0, 1] = dip[1, 0] = [1.0, 0, -0.1]  # the elbow 0.1 below the skin, 1 from the port
    assert _clear(dip, radii) == pytest.approx(-0.1 - 0.05, abs=1e-12)
    flipped = up[:, ::-1].copy()  # URDF shapes: no direction
    assert _clear(flipped, radii) == pytest.approx(r, abs=1e-12)
    tilted = up.copy()  # the tool leaning 45°: the kept end 2r·cos 45° above the skin
    tilted[2] = [[1.7, 0, 0.3], [2.1, 0, -0.1]]
    want = 2 * r * math.cos(math.pi / 4) - r
    assert _clear(tilted, radii) == pytest.approx(want, abs=1e-12)
    beyond = up - np.array([0, 0, 1.0])  # the whole arm beyond the plane: nothing exempt
    assert _clear(beyond, radii) == pytest.approx(-1.2 - r, abs=1e-12)  # the wrist link


# ---------------------------------------------- links: urdf with a port (A)

PUMA_SHAPES = {  # link -> <collision> elements (sizes in m)
    "base_link": '<origin xyz="0 0 0"/><geometry><sphere radius="0.1"/></geometry>',
    "link2": '<origin xyz="0.22 0 0" rpy="0 1.5707963267948966 0"/>'
             '<geometry><cylinder radius="0.05" length="0.3"/></geometry>',
    "link4": '<origin xyz="0 0 0.2"/><geometry><cylinder radius="0.04" length="0.3"/></geometry>',
    "tool0": '<origin xyz="0 0 -0.1"/><geometry><cylinder radius="0.005" length="0.2"/></geometry>',
}  # fmt: skip


def _puma_port(tmp_path, shapes=PUMA_SHAPES) -> dict:
    text = (ROOT / "configs/robots/puma560.urdf").read_text()
    for link, col in shapes.items():
        text = text.replace(f'<link name="{link}"/>',
                            f'<link name="{link}"><collision>{col}</collision></link>', 1)  # fmt: skip
    (tmp_path / "puma.urdf").write_text(text)
    cfg = yaml.safe_load((ROOT / "configs/urdf_puma560_port.yaml").read_text())
    cfg["study"]["chain"]["urdf"] = str(tmp_path / "puma.urdf")
    cfg["study"]["collision"] = {"links": "urdf", "self": True,
                                 "obstacles": cfg["study"]["collision"]["obstacles"]}  # fmt: skip
    cfg["study"]["indices"]["n_samples"] = 32
    return cfg


@pytest.mark.slow
def test_puma_links_urdf_with_a_port_evaluates(tmp_path):
    """configs/urdf_puma560_port.yaml with links: urdf (no radius) on the PUMA with
    collision shapes: validated (the port-in-base check reads the base link's shapes)
    and evaluated; the instrument's shape through the port does not count as touching
    the skin, every reached target's clearance is ≥ 0."""
    cfg = _puma_port(tmp_path)
    out = _indices(cfg, np.array([[0.43, 0.43, 0.4]]))
    assert out["reach"][0] > 0.5
    assert np.isfinite(out["clearance"][0]) and out["clearance"][0] > 0
    assert out["collision_free"][0] > 0.5


def test_puma_links_urdf_port_refusals(tmp_path):
    """The PUMA with collision shapes, links: urdf and a port validates; a port inside a <collision> shape of the URDF's base link is refused naming
    task.port; the shipped PUMA (no <collision> shapes) with links: urdf is refused
    naming collision.links, not a TypeError."""
    validate(_puma_port(tmp_path), "test")  # was a TypeError: no radius under links: urdf
    shapes = dict(PUMA_SHAPES)
    shapes["base_link"] = ('<origin xyz="0.25 0.05 -0.1" rpy="0 1.5707963267948966 0"/>'
                           '<geometry><cylinder radius="0.12" length="0.5"/></geometry>')  # fmt: skip
    cfg = _puma_port(tmp_path, shapes)
    with pytest.raises(ConfigError, match=r"task.port'?: the port .* inside the arm's base "
                                          r"link \(a <collision> shape"):  # fmt: skip
        validate(cfg, "test")
    cfg = yaml.safe_load((ROOT / "configs/urdf_puma560_port.yaml").read_text())
    cfg["study"]["chain"]["urdf"] = str(ROOT / "configs/robots/puma560.urdf")
    cfg["study"]["collision"] = {"links": "urdf"}
    with pytest.raises(ConfigError, match="collision.links.*no <collision> shape"):
        validate(cfg, "test")


# ------------------------------------------------------ several arms' reach (C)


def _cone_points(reg, n, rng):
    a = np.asarray(reg.axis) / np.linalg.norm(reg.axis)
    e1 = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    d = rng.uniform(*reg.depth, n)
    rho = d * math.tan(math.radians(reg.half_angle)) * np.sqrt(rng.uniform(size=n))
    t = rng.uniform(0, 2 * np.pi, n)
    return (np.asarray(reg.apex) + d[:, None] * a + rho[:, None] * (np.cos(t)[:, None] * e1
            + np.sin(t)[:, None] * e2))  # fmt: skip


def _cylinder_points(reg, n, rng):
    a = np.asarray(reg.axis) / np.linalg.norm(reg.axis)
    e1 = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    h = rng.uniform(-reg.height / 2, reg.height / 2, n)
    rho = reg.radius * np.sqrt(rng.uniform(size=n))
    t = rng.uniform(0, 2 * np.pi, n)
    return (np.asarray(reg.center) + h[:, None] * a + rho[:, None] * (np.cos(t)[:, None] * e1
            + np.sin(t)[:, None] * e2))  # fmt: skip


@pytest.mark.parametrize("region", [
    {"shape": "box", "center": [1.0, 2.0, 0.5], "size": [0.3, 0.2, 0.0]},
    {"shape": "ball", "center": [-1.0, 2.0, 1.5], "radius": 0.3},
    {"shape": "cylinder", "center": [0.5, -1.5, 1.0], "axis": [1, 1, 0.3], "radius": 0.2,
     "height": 0.4},
    {"shape": "cone", "apex": [1.5, 1.0, 2.0], "axis": [0.2, 0, -1], "half_angle": 30,
     "depth": [0.1, 0.4]},
])  # fmt: skip
def test_region_box_distance_is_a_tight_lower_bound(region):
    """The distance between a region and a box of base positions: never above the least
    distance between dense samples of both (a lower bound), and within 1 % of it; for a
    box of one point it is tk.nearest_distance's (exact but for the cone, whose bounding
    ball it beats)."""
    from pydantic import TypeAdapter

    reg = TypeAdapter(tk.Region).validate_python(region)
    rng = np.random.default_rng(2)
    lo, hi = np.array([-0.4, -0.2, 0.0]), np.array([0.1, 0.3, 0.2])
    got = reach.region_box_distance(reg, lo, hi)
    if region["shape"] == "box":
        pts = np.asarray(reg.center) + rng.uniform(-0.5, 0.5, (100_000, 3)) * np.asarray(reg.size)
    elif region["shape"] == "ball":
        u = rng.normal(size=(100_000, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        pts = np.asarray(reg.center) + reg.radius * u * rng.uniform(size=(100_000, 1)) ** (1 / 3)
    elif region["shape"] == "cylinder":
        pts = _cylinder_points(reg, 100_000, rng)
    else:
        pts = _cone_points(reg, 100_000, rng)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    sampled = np.min(np.linalg.norm(np.maximum(np.abs(pts - c) - h, 0), axis=1))
    assert 0.99 * sampled <= got <= sampled + 1e-9
    o = np.array([0.3, -0.2, 0.1])
    point = reach.region_box_distance(reg, o, o)
    exact = tk.nearest_distance(reg, tuple(o))
    if region["shape"] == "cone":
        assert exact <= point
    else:
        assert point == pytest.approx(exact, rel=1e-7, abs=1e-9)


def test_two_arms_with_an_unreachable_region_are_refused():
    """configs/two_arms_front.yaml as shipped validates; its region 50 m away is refused
    naming task.region and the arm; a region within reach of arm 0's base range only is
    refused naming arm 1."""
    path = ROOT / "configs/two_arms_front.yaml"
    cfg = yaml.safe_load(path.read_text())
    validate(copy.deepcopy(cfg), str(path))
    far = copy.deepcopy(cfg)
    far["study"]["task"]["region"]["center"] = [50.0, 0.0, 0.25]
    with pytest.raises(ConfigError, match=r"task.region'?: arm 0 reaches no point.*50\.\d+ m"):
        validate(far, str(path))
    side = copy.deepcopy(cfg)  # bases at x ∈ [-0.9, -0.35] and [0.35, 0.9]; reach ≤ 1.55
    side["study"]["task"]["region"]["center"] = [-2.2, 0.0, 0.25]
    side["study"]["task"]["region"]["size"] = [0.2, 0.2, 0.1]
    with pytest.raises(ConfigError, match="task.region'?: arm 1 reaches no point"):
        validate(side, str(path))


def test_the_cli_refuses_an_unreachable_two_arm_task_with_exit_2(tmp_path):
    from designopt.cli.commands import main

    cfg = yaml.safe_load((ROOT / "configs/two_arms_front.yaml").read_text())
    cfg["study"]["task"]["region"]["center"] = [50.0, 0.0, 0.25]
    p = tmp_path / "far.yaml"
    p.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(p), "--dry-run", "--out", str(tmp_path / "x.h5")]) == 2


# ----------------------------------------------------------------- warnings (D)


def _two_arms():
    cfg = yaml.safe_load((ROOT / "configs/two_arms_front.yaml").read_text())
    return validate(cfg, "two_arms").study


def test_warnings_on_arms_collisions_and_na_ratios():
    s = _two_arms()
    fine = {"reach": 1.0, "reach_se": 0.01, "reach_all": 0.9, "arms_ok": 0.5,
            "arms_free": 0.55, "arms_free_n": 230.0, "arms_free_of": 256.0,
            "collision_free": 0.9, "collision_free_n": 400.0, "x": [0.6, 0.45, 0.45]}  # fmt: skip
    assert reach.warnings(s, fine) == []
    na = fine | {"arms_free": math.nan, "arms_free_se": math.nan, "arms_free_n": 12.0}
    w = reach.warnings(s, na)
    assert w == ["arms_free: n/a (12 of 256 tuples reached by every arm; under 30): too few "
                 "to say what share of them keeps the arms apart"]  # fmt: skip
    bare = {k: v for k, v in na.items() if not k.startswith("arms_free_")}
    assert "fewer than 30 tuples reached by every arm" in reach.warnings(s, bare)[0]
    zero = fine | {"arms_ok": 0.0, "arms_free": 0.0}
    assert any(x.startswith("arms_free = 0: in every tuple") for x in reach.warnings(s, zero))
    only_ok = {k: v for k, v in zero.items() if k != "arms_free"}
    assert any(x.startswith("arms_ok = 0:") for x in reach.warnings(s, only_ok))
    assert reach.warnings(s, only_ok | {"reach_all": 0.0}) == []  # nothing reached: no tuple
    cf = reach.warnings(s, fine | {"collision_free": 0.0})
    assert any(x.startswith("collision_free = 0: at every target") for x in cf)
    cna = reach.warnings(s, fine | {"collision_free": math.nan, "collision_free_n": 7.0,
                                    "collision_free_of": 512.0})  # fmt: skip
    assert any(x.startswith("collision_free: n/a (7 of 512 targets where the IK converged; "
                            "under 30)") for x in cna)  # fmt: skip
    one = reach.warnings(s, fine | {"x": np.array([0.0, 0.45, 0.45])})  # b = 0
    assert one == ["arms: every arm's base is at (0, 0, 0) m in the final design: the arms "
                   "stand on one base, inside one another"]  # fmt: skip
    assert reach.warnings(s, {}) == []  # nothing to judge: no line, no error
    assert reach.warnings(s, {"reach": np.float64("nan"), "arms_free": np.array(math.nan)})
