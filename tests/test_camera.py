"""Issue 67, item 2: the endoscope (``study.task.camera``, designopt/studies/serial/camera.py)
and its index ``view_ok``. The planning case (configs/port_placement.yaml) with a camera
port above the task region, the scope held at a known depth so that its tip sits at the
centre of a ball of targets: the share seen is then a closed form, the band's shell
(w1³ − w0³)/ρ³ times the cone's solid-angle share (1 − cos θ)/2, and with a ball
occluder on the axis (every band target beyond it) (cos α − cos θ)/2 with sin α = a/e.
The targets seen are also checked one by one against NumPy. No IK runs."""

from __future__ import annotations

import copy
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml
from test_bad_inputs import _refused
from test_bad_inputs_corpus import PORTS, _written

from designopt.app.config import validate
from designopt.studies.serial import camera, taskindex
from designopt.studies.serial.mechanism import build
from designopt.studies.serial.settings import units

N = 20000
TIP = np.array([0.0, 0.0, 0.03])  # the ball's centre: 0.15 m below the incision (0, 0, 0.18)
RHO = 0.05


def _raw(band, fov, occluder=None):
    raw = copy.deepcopy(PORTS)
    st = raw["study"]
    st["indices"]["n_samples"] = N
    st["task"]["region"] = {"shape": "ball", "center": TIP.tolist(), "radius": RHO}
    st["task"]["camera"] = {"port": [0, 0, 0.3], "aim": [0, 0, -0.2], "fov": fov,
                            "band": list(band), "insertion": [0.15, 0.15]}  # fmt: skip
    st["collision"]["obstacles"] = [st["collision"]["obstacles"][0]]  # the skin only
    if occluder is not None:
        st["collision"]["obstacles"].append({"shape": "ball", "center": list(occluder[0]),
                                             "radius": occluder[1], "inside": True})  # fmt: skip
    return raw


def _seen(raw):
    s = validate(raw, "c.yaml", checks=False).study
    with jax.enable_x64(True):
        mech = build(s)
        params = taskindex.scene_params(s, jnp.float64, mech) | taskindex.targets(
            s, jax.random.key(7), jnp.float64) | {"fixed": jnp.asarray(mech.fixed),
                                                  "scale": jnp.asarray(mech.scale)}  # fmt: skip
        full = taskindex.design_full(params, jnp.asarray([[0.6, 0.0, 0.05, 0.0, 0.0]]),
                                     jnp.float64)  # fmt: skip
        inc, tip, z = (np.asarray(v)[0] for v in camera.pose(params, full, "ellipsoid"))
        got = np.asarray(camera.seen(params, full, "ellipsoid", params["target_p"]))[0]
    return s, inc, tip, z, got, np.asarray(params["target_p"])


@pytest.mark.parametrize("band,fov,occluder", [
    ((0.01, 0.04), 90.0, None),
    ((0.02, 0.045), 90.0, None),
    ((0.02, 0.045), 90.0, ((0.0, 0.0, 0.03 - 0.012), 0.004)),  # α = asin(1/3) < θ = 45°
])  # fmt: skip
def test_view_ok_is_the_closed_form_share_of_a_ball_of_targets(band, fov, occluder):
    s, inc, tip, z, got, p = _seen(_raw(band, fov, occluder))
    assert "view_ok" in s.index_names() and units(s)["view_ok"] == "-"
    np.testing.assert_allclose(inc, [0.0, 0.0, 0.18], atol=1e-12)  # the ellipsoid's top
    np.testing.assert_allclose(tip, TIP, atol=1e-12)
    np.testing.assert_allclose(z, [0.0, 0.0, -1.0], atol=1e-12)
    # NumPy, target by target
    v = p - TIP
    r = np.linalg.norm(v, axis=-1)
    th = math.radians(fov) / 2
    want = (r >= band[0]) & (r <= band[1]) & (-v[:, 2] >= r * math.cos(th))
    w0, w1 = band
    shell = (w1**3 - w0**3) / RHO**3
    if occluder is None:
        share = shell * (1 - math.cos(th)) / 2
    else:
        c, a = np.asarray(occluder[0]), occluder[1]
        t = np.clip(((c - TIP) @ v.T) / r**2, 0, 1)  # the sight line's point nearest c
        want &= np.linalg.norm(TIP + t[:, None] * v - c, axis=-1) > a
        e = float(np.linalg.norm(c - TIP))
        assert w0 >= e + a  # every band target lies beyond the occluder
        share = shell * (math.sqrt(1 - (a / e) ** 2) - math.cos(th)) / 2
    assert np.array_equal(got, want)
    se = math.sqrt(share * (1 - share) / N)
    assert abs(got.mean() - share) < 4 * se, (got.mean(), share, se)


def test_the_camera_port_is_a_design_variable_and_bad_input_is_one_line(tmp_path, capsys):
    raw = _raw((0.02, 0.1), 70.0)
    raw["study"]["task"]["camera"]["port"] = ["px", "-py0", 0.3]
    s = validate(raw, "c.yaml", checks=False).study
    assert s.task.camera.port == ("px", "-py0", 0.3)
    for key, value, words in [
        ("fov", 0, ["camera.fov", "got 0"]), ("fov", 200, ["camera.fov", "got 200"]),
        ("band", [0.1, 0.02], ["needs 0 ≤ near < far"]), ("band", [".nan", 0.1], ["band"]),
        ("insertion", [-1, 0.1], ["needs 0 ≤ d0 ≤ d1"]),
        ("port", ["cx", 0, 0.3], ["'cx' is neither a design variable"]),
        ("shaft", {"length": 0, "radius": 0.005}, ["camera.shaft.length", "got 0"]),
        ("shaft", {"length": 0.4, "radius": -1}, ["camera.shaft.radius", "got -1"]),
        ("shaft", {"length": 0.4}, ["camera.shaft.radius", "missing"]),
    ]:  # fmt: skip
        bad = _raw((0.02, 0.1), 70.0)
        bad["study"]["task"]["camera"][key] = value
        cfg = tmp_path / "c.yaml"
        cfg.write_text(yaml.safe_dump(bad).replace("'.nan'", ".nan"))
        before = _written(tmp_path)
        err = _refused(capsys, ["run", cfg, "--dry-run", "--quiet", "--out",
                                tmp_path / "o" / "a.h5"], "task.camera", *words)  # fmt: skip
        assert err.count("key '") == 1, err
        assert _written(tmp_path) == before


def test_the_camera_port_counts_in_port_gap_and_its_warning():
    """``port_gap`` is the least distance between any two incision points, the camera's
    included (``Study.placement``'s ports and camera, NumPy); the warning names it."""
    from designopt.studies.serial import _placement, incisions, plancheck

    raw = _raw((0.02, 0.1), 70.0)
    raw["study"]["task"]["camera"].update(port=[0, "py0", 0.3], insertion=[0.0, 0.2])
    s = validate(raw, "c.yaml", checks=False).study
    assert s.incision_count() == 3 and "port_gap" in s.index_names()
    X = np.array([[0.6, 0.0, 0.05, 0.0, 0.0], [0.6, 0.0, 0.02, 0.1, 0.0]])
    pl = _placement(s, X)
    P = np.concatenate([pl["ports"], pl["camera"][:, None, :3]], 1)  # (2, 3, 3)
    want = np.min([np.linalg.norm(P[:, i] - P[:, j], axis=-1)
                   for i, j in ((0, 1), (0, 2), (1, 2))], 0)  # fmt: skip
    with jax.enable_x64(True):
        mech = build(s)
        params = taskindex.scene_params(s, jnp.float64, mech) | {
            "fixed": jnp.asarray(mech.fixed), "scale": jnp.asarray(mech.scale)}  # fmt: skip
        full = taskindex.design_full(params, jnp.asarray(X), jnp.float64)
        got = np.asarray(incisions.port_gap(params, full, "ellipsoid"))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    # design 0: the camera (x = 0, py0 = 0) midway between instrument ports 7 cm apart
    d = float(np.linalg.norm(P[0, 0] - P[0, 2]))
    assert d < 0.05 and got[0] == pytest.approx(d)
    lines = plancheck.warnings(s, {"x": X[0]})
    assert any(ln.startswith(f"task.port_gap: the incision points of arm 0 and the camera are "
                             f"{d:.3g} m apart") for ln in lines), lines  # fmt: skip


def _segment_distance(p1, q1, p2, q2):
    """Exact distance between segments p1–q1 and p2–q2 (..., 3), NumPy (the closest
    points' parameters clamped to [0, 1], Ericson's construction)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = np.sum(d1 * d1, -1), np.sum(d2 * d2, -1)
    b, c, f = np.sum(d1 * d2, -1), np.sum(d1 * r, -1), np.sum(d2 * r, -1)
    den = a * e - b * b
    s = np.where(den > 1e-300, np.clip((b * f - c * e) / np.where(den > 1e-300, den, 1), 0, 1), 0)
    t = (b * s + f) / np.where(e > 1e-300, e, 1)
    s = np.where(t < 0, np.clip(-c / np.where(a > 1e-300, a, 1), 0, 1),
                 np.where(t > 1, np.clip((b - c) / np.where(a > 1e-300, a, 1), 0, 1), s))
    t = np.clip(t, 0, 1)
    return np.linalg.norm(p1 + d1 * s[..., None] - (p2 + d2 * t[..., None]), axis=-1)


def test_the_scope_shaft_keeps_every_kept_solution_clear():
    """``camera.shaft``: the scope from its tip 0.4 m back along its axis, between two
    instrument ports 4 cm apart. With it, every reached target's kept solution (each arm's
    capsules, the instrument included) keeps ``collision.margin`` from the scope (exact
    segment distances in NumPy), and its clearance is at most that distance, equal to it
    where the scope is the nearest thing; without it, at the same IK seeds, some kept
    solutions meet the scope."""
    from designopt.studies import streams
    from designopt.studies.serial import blocks, bodies

    def settings(shaft):
        raw = _raw((0.04, 0.16), 70.0)
        raw["study"]["indices"]["n_samples"] = 32  # tests/test_plan_sheet.py's targets
        raw["study"]["collision"] = copy.deepcopy(PORTS["study"]["collision"])
        raw["study"]["task"]["region"] = copy.deepcopy(PORTS["study"]["task"]["region"])
        cam = raw["study"]["task"]["camera"]
        cam.update(port=[0, 0.0, 0.3], aim=[0, 0, 0.03], insertion=[0, 0.2])
        if shaft:
            cam["shaft"] = {"length": 0.4, "radius": 0.005}
        return validate(raw, "c.yaml", checks=False).study

    X = np.array([[0.55, 0.0, 0.02, 0.0, 0.0]])  # the ports at x = ±0.02 m, y = 0
    jax.config.update("jax_enable_x64", True)
    out = {}
    for shaft in (True, False):
        s = settings(shaft)
        sol = blocks.solutions(s, X, streams(0), jnp.float64)
        with jax.enable_x64(True):
            mech = build(s)
            p = camera.camera_params(settings(True), jnp.float64) | {
                "scene_wall": taskindex.scene_params(s, jnp.float64, mech)["scene_wall"]}
            a, b, rs = (np.asarray(v) for v in camera.shaft(
                p, jnp.asarray(np.concatenate([X, np.zeros((1, 0))], 1)), "ellipsoid"))  # fmt: skip
        seg = sol["segments"][:, 0]  # (A, N, L, 2, 3), the kept solutions in the world
        r = np.asarray(bodies.geometry(s, mech).radii)
        d = _segment_distance(seg[..., 0, :], seg[..., 1, :], a[0], b[0]) - r - rs
        ok = sol["success"][:, 0]  # (A, N)
        out[shaft] = (ok, d.min(-1), sol["clearance"][:, 0], s.collision.margin)
    ok, d, c, margin = out[True]
    assert ok.sum() >= 8 and np.all(d[ok] >= margin - 1e-9)
    assert np.all(c[ok] <= d[ok] + 1e-9)
    assert np.any(np.abs(c[ok] - d[ok]) <= 1e-9)  # the scope is the nearest somewhere
    ok0, d0, _, _ = out[False]
    assert np.any(d0[ok0] < margin), "the scope would block no kept solution: no test"


def test_a_shaft_without_collisions_is_one_line(tmp_path, capsys):
    bad = _raw((0.02, 0.1), 70.0)
    bad["study"]["task"]["camera"]["shaft"] = {"length": 0.4, "radius": 0.005}
    bad["study"].pop("collision")
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(bad))
    _refused(capsys, ["run", cfg, "--dry-run", "--quiet"], "key 'study.task.camera.shaft'",
             "give study.collision")  # fmt: skip
