"""Arms of different robots in one set-up (issue #67, items 1 and 2): a Franka Panda and a
UR5, each with its own instrument, through two ports in the mesh abdomen, and a second UR5
that holds the endoscope (configs/mixed_setup.yaml, at 32 targets).

Checked against independent references: the shipped Panda's joints against the URDF that
example-robot-data installs; every kept solution's forward kinematics in pinocchio, arm
by arm (its tip on its target, its instrument through its own incision point); each arm
of the mixed set-up against the same arm in a set-up of two copies of its robot (the
per-target values bit for bit, so reach_k is each arm's alone); the camera arm's pose
(pinocchio: its tip on the scope's tip, its axis through the camera port, one pose per
replication group) and its part in arms_ok and view_ok; the archive's per-arm joint names
and the CSV's rows."""

from __future__ import annotations

import copy
import csv
import io
import json
import sysconfig
import xml.etree.ElementTree as ET
from pathlib import Path

import jax
import numpy as np
import pytest

from designopt.app import config as C
from designopt.core.errors import ConfigError
from designopt.core.keys import streams

ROOT = Path(__file__).resolve().parents[1]
CFG = ROOT / "configs" / "mixed_setup.yaml"
DESIGN = np.array([[0.55, 0.0, 0.03, -0.1, 0.1, 0.6]])  # b, by, px, py0, py1, c
N = 32
ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"


def _raw() -> dict:
    raw, _ = C.parse(CFG)
    raw["study"]["indices"]["n_samples"] = N
    raw["study"]["task"]["ik"]["climb"] = 0  # (the shipped 8 refine 1/k: not checked here)
    return raw


def _settings(raw: dict):
    return C.validate(raw, str(CFG), folder=CFG.parent).study


@pytest.fixture(scope="module")
def x64():
    before = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", True)
    yield
    jax.config.update("jax_enable_x64", before)


@pytest.fixture(scope="module")
def mixed(x64):
    """(settings, the targets group ``Study.targets`` archives for DESIGN)."""
    from designopt.studies.serial import STUDY

    s = _settings(_raw())
    return s, STUDY.targets(s, DESIGN[0], streams(0), jax.numpy.float64)


def test_the_shipped_panda_is_example_robot_datas():
    from designopt.kinematics import urdf

    path = ROBOTS / "panda_description/urdf/panda.urdf"
    if not path.is_file():
        pytest.skip("example-robot-data is not installed (the peers extra installs it)")
    ours = urdf.parse((ROOT / "configs/robots/panda/panda_instrument.urdf").read_text(), "ours")
    root = ET.parse(path).getroot()
    theirs = {j.get("name"): j for j in root.iter("joint")}
    names = [f"panda_joint{i}" for i in range(1, 9)]
    for n in names:
        j, t = ours.joints[n], theirs[n]
        o = t.find("origin")
        assert np.allclose(j.xyz, [float(v) for v in o.get("xyz").split()], atol=0, rtol=0)
        assert np.allclose(j.rpy, [float(v) for v in o.get("rpy").split()], atol=0, rtol=0)
        assert j.type == t.get("type")
        if t.get("type") == "revolute":
            lim = t.find("limit")
            assert j.limits == (float(lim.get("lower")), float(lim.get("upper")))
            assert np.array_equal(j.axis, [float(v) for v in t.find("axis").get("xyz").split()])


def test_each_arm_is_its_own_robot_in_pinocchio(mixed):
    """Every reached target of each arm: pinocchio's FK of the archived joints (the arm's
    own, the NaN padding cut) at the arm's base puts the instrument tip on the target and
    its axis through the arm's incision point."""
    pin = pytest.importorskip("pinocchio")
    from designopt.studies.serial import placement, setup

    s, tg = mixed
    pl = placement.placement(s, DESIGN)
    ports, bases = np.asarray(pl["ports"])[0], np.asarray(pl["bases"])[0]  # (A, 3), (A, 6)
    from designopt.studies.serial.placement import camera_at

    files = ["robots/panda/panda_instrument.urdf", "robots/ur5/ur5_instrument.urdf",
             "robots/ur5/ur5_instrument.urdf"]  # fmt: skip
    q, ok, p = np.asarray(tg["q"]), np.asarray(tg["success"], bool), np.asarray(tg["target_p"])
    assert q.shape == (3, N, 7) and ok[0].sum() >= N // 2 and ok[1].sum() >= N // 2
    cam = camera_at(s, DESIGN)[0]  # the camera's incision point, then its tip
    assert ok[2].all()  # the camera arm holds the scope in every replication
    ports = np.concatenate([ports[:2], cam[None, :3]])
    p = np.stack([p, p, np.broadcast_to(cam[3:6], p.shape)])  # arm k's targets
    for k, f in enumerate(files):
        model = pin.buildModelFromUrdf(str(ROOT / "configs" / f))
        data = model.createData()
        fid = model.getFrameId("instrument_tip")
        n = model.nq
        assert n == setup.mechanisms(s)[k].n and np.isnan(q[k, :, n:]).all()
        R0 = pin.rpy.rpyToMatrix(*np.radians(bases[k, 3:]))
        for i in np.flatnonzero(ok[k]):
            pin.framesForwardKinematics(model, data, q[k, i, :n])
            T = data.oMf[fid]
            tip = R0 @ T.translation + bases[k, :3]
            axis = R0 @ T.rotation[:, 2]
            assert np.linalg.norm(tip - p[k, i]) < 1e-6
            off = ports[k] - tip  # the incision point lies on the instrument's line
            assert np.linalg.norm(off - (off @ axis) * axis) < 1e-5
            assert off @ axis < 0  # behind the tip, on the flange's side


def test_each_arm_equals_its_robot_in_a_set_up_of_copies(mixed):
    """The Panda of the mixed set-up and arm 0 of two Pandas (likewise the UR5 and arm 1
    of two UR5s) at the same bases and ports: the same solutions, bit for bit (the twins
    without the camera arm: an instrument arm's solutions do not depend on it)."""
    from designopt.studies.serial import blocks

    s, tg = mixed
    raw = _raw()
    raw["study"]["arms"] = raw["study"]["arms"][:2]  # the twins without the camera arm
    raw["study"]["variables"].pop("c")  # (its base's variable): its own group, no part here
    arms = raw["study"]["arms"]
    for k in (0, 1):
        twin = copy.deepcopy(raw)
        for j in (0, 1):
            twin["study"]["arms"][j] |= {key: arms[k][key] for key in ("chain", "radius")}
        sol = blocks.solutions(_settings(twin), DESIGN[:, :5], streams(0))
        n = np.asarray(sol["q"]).shape[-1]
        assert np.array_equal(np.asarray(sol["success"])[k, 0], np.asarray(tg["success"])[k] > 0)
        assert np.array_equal(np.asarray(sol["q"])[k, 0], np.asarray(tg["q"])[k, :, :n])
        assert np.array_equal(np.asarray(sol["inv_k"])[k, 0], np.asarray(tg["inv_k"])[k])


def test_the_archive_and_the_csv_name_each_arms_joints(mixed):
    from designopt.results.run import targets_csv_text

    s, tg = mixed
    at = tg["attrs"]
    assert at["arm_robots"] == ["panda_instrument.urdf", "ur5_instrument.urdf",
                                "ur5_instrument.urdf (camera)"]  # fmt: skip
    names = json.loads(at["arm_joints"])
    assert names[0] == [f"panda_joint{i}" for i in range(1, 8)]
    assert names[1][0] == "shoulder_pan_joint" and len(names[1]) == 6
    assert at["joints"] == [f"q{i}" for i in range(1, 8)] and at["q_units"] == ["rad"] * 7
    rows = list(csv.reader(io.StringIO(targets_csv_text(tg))))
    head = rows[0]
    assert head[:3] == ["arm", "robot", "target"] and "q7 [deg]" in head
    q7 = head.index("q7 [deg]")
    ur5 = [r for r in rows[1:] if r[0] == "1" and r[6] == "1"]
    panda = [r for r in rows[1:] if r[0] == "0" and r[6] == "1"]
    assert ur5 and panda and all(r[1] == "ur5_instrument.urdf" and r[q7] == "" for r in ur5)
    assert all(r[q7] != "" for r in panda)
    cam = [r for r in rows[1:] if r[0] == "2"]
    assert len(cam) == N and all(r[1] == "ur5_instrument.urdf (camera)" for r in cam)
    i = int(panda[0][2])
    assert float(panda[0][q7]) == pytest.approx(np.degrees(np.asarray(tg["q"])[0, i, 6]), abs=0)


@pytest.mark.parametrize("edit,says", [
    (lambda a: a[1].update(robot="ur5"), "known here: chain, radius, tool_radius, role, base"),
    (lambda a: a[1].update(radius=[0.05] * 5), "arms.1.radius': one radius per link of this "
     "arm's chain (6 links"),
    (lambda a: a[0]["chain"].update(set={"panda_joint4.origin.x": "nope"}), "arms.0.chain': set "
     "name 'nope' is neither a design variable nor a fixed value"),
    (lambda a: a[1].pop("radius"), "collision.radius': links: auto needs the capsules' radius "
     "(one number, or one per link), or every arm its own arms.<k>.radius"),
    (lambda a: [x.pop("chain") for x in a], "chain: missing; give study.chain (the robot), or "
     "every arm its own arms.<k>.chain"),
    (lambda a: a[1].update(radius=-0.1), "needs a radius > 0"),
    (lambda a: a[2].update(port=[0, 0.16, 0.3]), "arms.2.port': a camera arm goes through "
     "task.camera's port"),
    (lambda a: (a[1].update(role="camera"), a[1].pop("port")), "arms.2.role': one arm holds the endoscope (arm 1 "
     "already does)"),
    (lambda a: a[2].update(role="scope"), "arms.2.role"),
])  # fmt: skip
def test_a_mistake_in_an_arms_robot_is_one_line(edit, says):
    raw = _raw()
    edit(raw["study"]["arms"])
    with pytest.raises(ConfigError, match=says.replace("(", r"\(").replace(")", r"\)")):
        C.validate(raw, str(CFG), folder=CFG.parent, checks=False)


def test_a_camera_arm_needs_the_camera():
    raw = _raw()
    raw["study"]["task"].pop("camera")
    raw["study"]["constraints"] = raw["study"]["constraints"][:1]
    with pytest.raises(ConfigError, match=r"arms.2.role': a camera arm holds the endoscope of "
                                          r"task.camera; give task.camera"):  # fmt: skip
        C.validate(raw, str(CFG), folder=CFG.parent, checks=False)


def test_an_instrument_angle_needs_two_instrument_arms():
    raw = _raw()
    raw["study"]["arms"].pop(1)
    raw["study"]["arms"][0]["base"]["xyz"] = [-0.55, "by", 0]  # (b was the other arm's too)
    raw["study"]["arms"][0]["port"] = [-0.03, "py0", 0.30]
    for k in ("b", "px", "py1"):
        raw["study"]["variables"].pop(k)
    with pytest.raises(ConfigError, match="task.instrument_angle': is the band of the angle "
                                          "between two instrument arms; the set-up has one "
                                          "beside the camera arm"):  # fmt: skip
        C.validate(raw, str(CFG), folder=CFG.parent, checks=False)


def test_a_urdf_arm_needs_the_study_in_metres():
    raw = _raw()
    raw["study"]["chain"] = {"convention": "standard", "joints": [
        {"type": "R", "a": 0.3, "limits": [-90, 90]}, {"type": "R", "a": 0.3, "limits": [-90, 90]}]}
    raw["study"]["units"] = {"length": "mm"}
    raw["study"]["arms"][1].pop("chain")
    raw["study"]["arms"][1]["radius"] = 0.05
    with pytest.raises(ConfigError, match="arms.0.chain': a URDF's lengths are metres"):
        C.validate(raw, str(CFG), folder=CFG.parent, checks=False)


def test_the_camera_arm_holds_one_pose_per_replication_and_counts_in_the_tuples(mixed):
    """The camera arm (arm 2) solves the scope's pose once per replication group: every
    target of a group carries that group's joints. Its links count in arms_ok: the
    set-up without it is never below it tuple by tuple, its capsules moved onto arm 0's
    leave no tuple free, and an arm that cannot hold the scope leaves none reached."""
    from designopt.kinematics import ik
    from designopt.studies.serial import blocks, taskindex

    s, tg = mixed
    q = np.asarray(tg["q"])[2, :, :6]  # the UR5's six joints (the seventh column is NaN)
    R, run = taskindex.groups(s)
    lab = np.asarray(ik.group_of(np.arange(N), R, run))
    assert len(np.unique(lab)) >= 2
    for g in np.unique(lab):
        rows = q[lab == g]
        assert np.array_equal(rows, np.broadcast_to(rows[0], rows.shape))
    assert len({tuple(r) for r in q}) > 1  # the groups' draws differ (their own databases)
    sol = blocks.solutions(s, DESIGN, streams(0))
    _, params = blocks.host_params(s, streams(0), jax.numpy.float64)
    per = {k: jax.numpy.asarray(np.asarray(v, np.float64)) for k, v in sol.items()
           if k not in ("target_p", "target_R")}  # fmt: skip
    key = jax.random.fold_in(params["sample_key"], 2)
    r = params["scene_geometry"]["radii"]
    m = params["scene_geometry"]["margin"]

    def arms_ok(p, radii):
        ok, seg = taskindex._tuples(p, key, taskindex.labels(N, (R, run)))
        est = taskindex.estimates(p, key, radii, m, None, (R, run), (0, 1))
        return np.asarray(est["arms_ok"][0])[0], np.asarray(ok)

    three, _ = arms_ok(per, r)
    two = taskindex.estimates({k: v[:2] for k, v in per.items()}, key, r[:2], m, None,
                              (R, run))["arms_ok"][0]  # fmt: skip
    assert three <= float(two[0]) and float(two[0]) > 0
    assert three == pytest.approx(float(taskindex.estimates_of(s, None, per, params)["arms_ok"][0][0]))
    on0 = dict(per)
    on0["segments"] = per["segments"].at[2].set(per["segments"][0])
    assert arms_ok(on0, r.at[2].set(r[0]))[0] == 0
    held = dict(per)
    held["success"] = per["success"].at[2].set(0.0)
    assert arms_ok(held, r)[0] == 0


def test_the_plan_table_names_each_port_by_its_arm_when_the_camera_arm_sits_between():
    """The plan sheet's table numbers the incision points P0, P1, … over the instrument
    arms, but each row names its own arm: with the camera arm listed as arm 1, P1 is arm
    2's; the camera arm has no P row (it goes through C) and its base is a text row."""
    from designopt.studies.serial import plansheet

    raw = _raw()
    arms = raw["study"]["arms"]
    arms.insert(1, arms.pop(2))  # instrument, camera, instrument
    cfg = C.validate(raw, str(CFG), folder=CFG.parent, checks=False)
    s = cfg.study
    assert s.camera_arm() == 1 and s.instrument_arms() == (0, 2)
    ports = np.array([[-0.1, 0.0, 0.3], [0.0, 0.16, 0.3], [0.1, 0.05, 0.3]])
    bases = np.array([[-0.6, 0, 0, 0, 0, 0], [0, 0.6, 0, 0, 0, -90], [0.6, 0, 0, 0, 0, 180.0]])
    plan = plansheet.plan_of(s, {"ports": ports, "bases": bases,
                                 "camera": np.r_[ports[1], 0.0, 0.1, 0.05]})  # fmt: skip
    head, cells = plansheet.table_cells(plan)
    assert [c[0] for c in cells] == ["P0: arm 0", "P1: arm 2", "C: camera"]
    assert cells[1][1] == "(100.0, 50.0, 300.0)" and cells[1][2] == "(600.0, 0.0, 0.0)"
    assert any(r.startswith("camera arm: arm 1 ") and "(0.0, 600.0, 0.0)" in r for r in plan.rows)
    assert plan.distances == [(0, 1, pytest.approx(np.linalg.norm(ports[0] - ports[2])))]
