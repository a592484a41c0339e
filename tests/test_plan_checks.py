"""Issue 67, item 3: plans that refuse the impossible (designopt/studies/serial/plancheck.py).
Each config is the planning case (configs/port_placement.yaml) with the one key a new
user got wrong, as they wrote it: a port in millimetres, port variables in millimetres,
bases inside the abdomen, an organ marked ``inside`` outside the body wall, a task region
inside the organ. Each is refused by ``designopt run --dry-run`` with exit 2 and one line
naming the key (and, for a unit slip, the unit and the number to write); the correct
config passes. After a run: incision points closer than ``task.port_gap`` and the share
of the targets inside the anatomy are said (:func:`plancheck.warnings`), that share
checked against a NumPy count. No search runs; no JAX program compiles but the wall's
projection of one design's ports."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_bad_inputs import _refused  # one line, exit 2, no traceback
from test_bad_inputs_corpus import PORTS, _written

from designopt.app.config import validate
from designopt.studies.serial import plancheck

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def wired(monkeypatch):
    """The serial study's ``check`` with :func:`plancheck.check` wired in (before
    reach.check, whose region and port checks pass on every config below), and no
    cache marker: a config is checked on every call."""
    import designopt.studies as studies
    from designopt.app import config

    real = studies.get

    def get(name: str):
        st = real(name)
        if name != "serial":
            return st

        def check(s):
            plancheck.check(s)
            st.check(s)

        return dataclasses.replace(st, check=check)

    monkeypatch.setattr(studies, "get", get)
    monkeypatch.setattr(config, "_checked_marker", lambda cfg: None)


def _study(edit=None):
    raw = copy.deepcopy(PORTS)
    if edit is not None:
        edit(raw)
    return validate(raw, "port_placement.yaml", checks=False).study


def _arm(k: int):
    return lambda r: r["study"]["arms"][k]


def _obstacle(i: int):
    return lambda r: r["study"]["collision"]["obstacles"][i]


# (id, edit(raw), the key the line names, other words it holds)
MISTAKES = [
    ("port-in-mm", lambda r: _arm(0)(r).update(port=["-px", "py0", 300]),
     "study.arms.0.port.2", ["300 looks like millimetres", "the chain's unit is m", "write 0.3",
                             "299.8 m from task.body_wall"]),
    ("port-variables-in-mm",
     lambda r: r["study"]["variables"].update(px=[20, 140], py0=[-140, 140], py1=[-140, 140]),
     "study.variables.px", ["the box of px [20, 140] looks like millimetres", "write [0.02, 0.14]",
                            "the box of py0 [-140, 140]", "write [-0.14, 0.14]", "arms.0.port"]),
    ("bases-inside-the-abdomen", lambda r: r["study"]["variables"].update(b=[0, 0.1]),
     "study.arms.0.base", ["inside task.body_wall", "narrow the box of b, by"]),
    ("base-column-through-the-wall",  # the UR5's 0.089 m column from bases below the skin
     lambda r: r["study"]["variables"].update(b=[0.15, 0.8])
     or [a["base"]["xyz"].__setitem__(2, -0.08) for a in r["study"]["arms"]],
     "study.arms.0.base", ["the arm's base column (from the base at [-0.15, 0, -0.08] m to its "
                           "first joint, 0.08916 m long) passes through task.body_wall",
                           "in some designs of the box (e.g. b = 0.15, by = 0)",
                           "narrow the box of b, by"]),
    ("camera-port-in-mm",
     lambda r: r["study"]["task"].update(camera={"port": [0, -120, 300], "band": [0.04, 0.16]}),
     "study.task.camera.port.1", ["-120 looks like millimetres", "write -0.12",
                                  "300 looks like millimetres", "write 0.3"]),
    ("organ-outside-the-wall", lambda r: _obstacle(2)(r).update(xyz=[0, 0.5, 0.05]),
     "study.collision.obstacles.2", ["inside: true", "entirely outside task.body_wall"]),
    ("vessel-outside-the-wall",
     lambda r: _obstacle(1)(r).update(a=[-0.06, 0, 0.5], b=[0.06, 0, 0.5]),
     "study.collision.obstacles.1", ["entirely outside task.body_wall"]),
    ("region-inside-the-organ",
     lambda r: r["study"]["task"].update(region={"shape": "ball", "center": [0, -0.085, 0.05],
                                                 "radius": 0.01}),
     "study.task.region", ["every one of its 8192 sampled targets", "collision.obstacles.2"]),
]  # fmt: skip


@pytest.mark.parametrize("edit,key,words", [c[1:] for c in MISTAKES],
                         ids=[c[0] for c in MISTAKES])  # fmt: skip
def test_a_mistake_is_refused_naming_its_key(tmp_path, capsys, wired, edit, key, words):
    raw = copy.deepcopy(PORTS)
    edit(raw)
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(raw))
    before = _written(tmp_path)
    err = _refused(capsys, ["run", cfg, "--dry-run", "--quiet", "--out", tmp_path / "o" / "a.h5"],
                   str(cfg), f"key '{key}':", *words)  # fmt: skip
    assert err.count("key '") == 1, err
    assert _written(tmp_path) == before


def test_the_planning_case_passes_and_says_nothing():
    s = _study()
    plancheck.check(s)
    assert plancheck.inside_shares(s) == {1: 0.0, 2: 0.0}
    far = np.array([[-0.04, 0.0, 0.18], [0.04, 0.0, 0.18]])  # 8 cm apart
    assert plancheck.warnings(s, {"ports": far}) == []


@pytest.mark.parametrize("wall,port,words", [
    ({"shape": "halfspace", "point": [0, 0, 0.2], "normal": [0, 0, 1]}, ["-px", "py0", 300],
     ["300 looks like millimetres", "from the task region's centre"]),
    ({"shape": "mesh", "file": str(ROOT / "configs" / "data" / "abdomen.stl")},
     ["-px", "py0", 30], ["30 looks like centimetres", "write 0.3", "bounding box's diagonal"]),
    ({"shape": "ellipsoid", "center": [0, 0, 0.06], "radii": [0.2, 0.25, 0.12]},
     ["-px", "py0", 0.88], ["arms.0.port:", "check the port's coordinates and their unit"]),
])  # fmt: skip
def test_a_unit_slip_on_every_kind_of_wall(wall, port, words):
    """A half-space wall is measured from the task region; a mesh by its size; a port
    0.7 m above an ellipsoid (beyond its bounding box's 0.684 m diagonal) is far (refused),
    but no slip of a unit (0.88 is under plancheck.SLIP × the wall's 0.18 m reach along z)."""

    def edit(r):
        r["study"]["task"]["body_wall"] = wall
        _arm(0)(r)["port"] = port

    with pytest.raises(ValueError) as e:
        plancheck.check(_study(edit))
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_a_port_near_the_wall_and_bases_outside_it_pass():
    """A port point 0.12 m above the wall (the planning case's own) is no slip; bases in
    a box that keeps them outside the patient pass, one corner inside does not."""
    plancheck.check(_study(lambda r: _arm(1)(r).update(port=["px", "py1", 0.30])))
    with pytest.raises(ValueError, match=r"^arms\.0\.base: .* in some designs of the box \(e\.g\. "
                                         r"b = 0\.15, by = 0\)"):  # fmt: skip
        plancheck.check(_study(lambda r: r["study"]["variables"].update(b=[0.15, 0.8])))


def test_one_arm_standing_inside_the_anatomy():
    """One arm's base is the world's origin: inside an ``inside`` ball, the ball is named."""
    raw = yaml.safe_load((ROOT / "configs" / "urdf_puma560_port.yaml").read_text())
    raw["study"]["chain"]["urdf"] = str(ROOT / "configs" / "robots" / "puma560.urdf")
    raw["study"]["collision"]["obstacles"].append(
        {"shape": "ball", "center": [0.0, 0.0, 0.05], "radius": 0.1, "inside": True}
    )
    s = validate(raw, "urdf_puma560_port.yaml", checks=False).study
    with pytest.raises(ValueError, match=r"^collision\.obstacles\.1: the arm's base \(the world's "
                                         r"origin.* in every design of the box"):  # fmt: skip
        plancheck.check(s)


def test_the_port_gap_warning(tmp_path):
    s = _study()
    assert plancheck.port_gap(s) == pytest.approx(0.05)  # 5 cm in a chain in m
    near = np.array([[-0.015, 0.0, 0.18], [0.015, 0.0, 0.18]])  # 3 cm apart
    far = np.array([[-0.04, 0.0, 0.18], [0.04, 0.0, 0.18]])  # 8 cm apart
    (line,) = plancheck.warnings(s, {"ports": near})
    assert line.startswith("task.port_gap: the incision points of arms 0 and 1 are 0.03 m "
                           "apart, closer than 0.05 m"), line  # fmt: skip
    assert plancheck.warnings(s, {"ports": far}) == []
    wide = _study(lambda r: r["study"]["task"].update(port_gap=0.1))
    assert "closer than 0.1 m" in plancheck.warnings(wide, {"ports": far})[0]
    off = _study(lambda r: r["study"]["task"].update(port_gap=0))
    assert plancheck.port_gap(off) is None and plancheck.warnings(off, {"ports": near}) == []


def test_the_incisions_of_a_design_are_its_projected_ports():
    """Without the final record's ``ports`` (``eval``), the incisions come from the design
    ``x``: the ports the run places on the wall (Study.placement)."""
    from designopt.studies.serial import _placement

    s = _study()
    x = np.array([0.6, 0.0, 0.011, 0.0, 0.0])  # b, by, px, py0, py1: the ports 2.2 cm apart
    got = plancheck.incisions(s, {"x": x})
    want = _placement(s, x[None])["ports"][0]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    (line,) = plancheck.warnings(s, {"x": x})
    d = float(np.linalg.norm(want[0] - want[1]))
    assert f"are {d:.3g} m apart" in line and d < 0.05


def test_port_gap_is_an_index_equal_to_the_incisions_distance():
    """``port_gap``: the least distance between the arms' incision points, exact (SE 0),
    equal to the distance of the projected ports ``Study.placement`` archives (NumPy), a
    bound usable as a constraint, finite in value and gradient where the ports meet;
    no index where the arms share one port."""
    import jax
    import jax.numpy as jnp

    from designopt.studies.serial import _placement, incisions, taskindex
    from designopt.studies.serial.mechanism import build
    from designopt.studies.serial.settings import units

    s = _study(lambda r: r["study"]["constraints"].append({"index": "port_gap", "ge": 0.05}))
    assert "port_gap" in s.index_names() and units(s)["port_gap"] == "m"
    X = np.array([[0.6, 0.0, 0.011, 0.0, 0.0], [0.5, 0.1, 0.1, -0.12, 0.13],
                  [0.7, -0.1, 0.02, 0.1, -0.1], [0.6, 0.0, 0.0, 0.05, 0.05]])  # fmt: skip
    P = _placement(s, X)["ports"]  # (4, 2, 3)
    want = np.linalg.norm(P[:, 0] - P[:, 1], axis=-1)
    mech = build(s)
    params = taskindex.scene_params(s, jnp.float64, mech) | {
        "fixed": jnp.asarray(mech.fixed), "scale": jnp.asarray(mech.scale)}  # fmt: skip

    def gap(X):
        return incisions.port_gap(params, taskindex.design_full(params, X, jnp.float64), "ellipsoid")

    with jax.enable_x64(True):
        got = np.asarray(gap(jnp.asarray(X)))
        g = np.asarray(jax.grad(lambda X: gap(X).sum())(jnp.asarray(X)))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert want[-1] == 0.0 and want[0] < 0.05 < want[1]  # the last design's ports meet
    assert np.all(np.isfinite(g)) and np.any(g[0] != 0)

    def one_port(r):
        for a in r["study"]["arms"]:
            a.pop("port")
        r["study"]["task"]["port"] = ["px", "py0", 0.3]
        r["study"]["variables"].pop("py1")

    shared = _study(one_port)
    assert "port_gap" not in shared.index_names()


def test_the_share_of_targets_inside_the_anatomy_against_numpy():
    ball = {"shape": "ball", "center": [0.02, 0.01, 0.04], "radius": 0.02, "inside": True}
    s = _study(lambda r: _obstacle(1)(r).clear() or _obstacle(1)(r).update(ball))
    p = plancheck.region_samples(s.task.region)
    assert p.shape == (plancheck.SAMPLES, 3)
    want = float(np.mean(np.linalg.norm(p - np.array(ball["center"]), axis=-1) < ball["radius"]))
    got = plancheck.inside_shares(s)
    assert 0.05 < want < 0.95
    assert abs(got[1] - want) <= 1e-12 and got[2] == 0.0
    lines = plancheck.warnings(s, {"ports": np.array([[-0.1, 0, 0.15], [0.1, 0, 0.15]])})
    assert lines == [f"{100 * want:.3g} % of the task region's targets (8192 sampled) lie "
                     "inside collision.obstacles.1: they can never be reached"]  # fmt: skip
    plancheck.check(s)  # partly inside: a warning, not a refusal
    whole = dict(ball, center=[0.0, 0.0, 0.03], radius=0.06)
    with pytest.raises(ValueError, match=r"^task\.region: every one .*collision\.obstacles\.1"):
        plancheck.check(_study(lambda r: _obstacle(1)(r).clear() or _obstacle(1)(r).update(whole)))


@pytest.mark.parametrize("value,words", [
    (".nan", ["not a finite number"]),
    ("-0.01", ["must be ≥ 0.0, got -0.01"]),
])  # fmt: skip
def test_a_bad_port_gap_is_one_line(tmp_path, capsys, value, words):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(PORTS))
    _refused(capsys, ["run", cfg, "--dry-run", "--quiet", "--out", tmp_path / "o" / "a.h5",
                      "--set", f"study.task.port_gap={value}"],
             "key 'study.task.port_gap'", *words)  # fmt: skip
    assert _written(tmp_path) == [cfg]
