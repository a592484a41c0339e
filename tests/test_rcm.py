"""The planar RCM mechanism and its 3-DOF arm (Sensors 2023): mechanism identities, the
corrected Jacobian against autodiff and the printed one, η against an independent numpy
quadrature, the workspace volume, the constraints, the teleoperation replay and bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.app import pipeline
from designopt.app.config import validate
from designopt.cli.commands import main
from designopt.io import archive
from designopt.studies import streams
from designopt.studies.rcm import mechanism as m
from designopt.studies.rcm import objective as obj
from designopt.studies.rcm import paper, teleop, workspace
from designopt.studies.rcm.settings import RcmSettings

A, B, C = 120.0, 260.0, 250.0
RNG = np.random.default_rng(3)
D1 = RNG.uniform(22, 215, 4000)
D2 = RNG.uniform(35, 200, 4000)


# --------------------------------------------------------------------- mechanism


def test_rod_passes_through_R_everywhere_in_the_box():
    """eq. (3): A2, the tip D and R = (b, 0) lie on one line; R is at distance r from A2."""
    g1, g2 = np.meshgrid(np.linspace(22, 215, 101), np.linspace(35, 200, 101))
    r = np.hypot(g1 - A, g2)
    Rpt = np.asarray(m.rod_point(g1, g2, A, B, r))
    np.testing.assert_allclose(Rpt[..., 0], B, atol=1e-12 * B)
    np.testing.assert_allclose(Rpt[..., 1], 0.0, atol=1e-12 * B)
    D = np.asarray(m.fk(g1, g2, A, B, C))
    a2 = np.stack([g1 + B - A, g2], -1)
    cross = (a2[..., 0] - B) * (D[..., 1]) - (a2[..., 1]) * (D[..., 0] - B)
    assert np.abs(cross).max() < 1e-9  # mm²: collinear
    np.testing.assert_allclose(np.hypot(D[..., 0] - B, D[..., 1]), np.abs(C - r), atol=1e-10)


def test_jacobian_closed_form_matches_autodiff_and_eigenvalues():
    Jad = jax.vmap(lambda x, y: m.planar_jacobian_ad(x, y, A, B, C))(D1, D2)
    J = m.jacobian(D1, D2, A, C)
    np.testing.assert_allclose(J, Jad, atol=1e-13)
    ev = np.sort(np.linalg.eigvals(np.asarray(J)).real, axis=1)
    d = np.asarray(m.depth(D1, D2, A, C))
    other = -d / (C - d)
    expect = np.sort(np.stack([np.ones_like(other), other], 1), axis=1)
    np.testing.assert_allclose(ev, expect, atol=1e-12)
    s = np.linalg.svd(np.asarray(J), compute_uv=False)
    np.testing.assert_allclose(m.inv_cond(D1, D2, A, C), s[:, 1] / s[:, 0], atol=1e-13)
    np.testing.assert_allclose(
        np.linalg.det(np.asarray(J)), 1 - C / np.hypot(D1 - A, D2), atol=1e-12
    )


def test_singularity_gives_zero_not_nan():
    """D = R (r = c): det J = 0 and 1/k = 0, with finite gradients; also r = 0."""
    th = np.linspace(0.1, 3.0, 7)
    d1, d2 = A + C * np.cos(th), C * np.sin(th)
    ik = np.asarray(m.inv_cond(d1, d2, A, C))
    assert np.all(np.isfinite(ik)) and ik.max() < 1e-15  # r = c up to rounding
    assert float(m.inv_cond_r(jnp.asarray(C), C)) == 0.0
    np.testing.assert_allclose(
        np.asarray(m.fk(d1, d2, A, B, C)), np.tile([B, 0.0], (7, 1)), atol=1e-12
    )
    g = jax.grad(lambda x: m.inv_cond(x[0], x[1], A, C))(jnp.array([d1[2], d2[2]]))
    assert np.all(np.isfinite(np.asarray(g)))
    assert float(m.inv_cond_r(jnp.asarray(0.0), C)) == 0.0
    assert float(m.inv_cond_r(jnp.asarray(C / 2), C)) == 1.0  # isotropic at d = c/2
    x, y = m.ik(jnp.asarray(B), jnp.asarray(0.0), A, B, C)
    assert np.isfinite(float(x)) and np.isfinite(float(y))


def test_printed_E_fails_the_singularity_test_and_corrected_passes():
    """eq. (10)/§2.3: det J = 0 ⇔ D = R. The printed E = c/r gives det = 1 − c instead."""
    th = np.linspace(0.2, 2.9, 9)
    d1, d2 = A + C * np.cos(th), C * np.sin(th)  # D = R
    assert np.abs(np.linalg.det(np.asarray(m.jacobian(d1, d2, A, C)))).max() < 1e-12
    Jp = np.asarray(paper.jacobian_printed(d1, d2, A, C))
    np.testing.assert_allclose(np.linalg.det(Jp), 1 - C, rtol=1e-12)  # never 0 for c ≠ 1
    assert np.abs(np.linalg.det(Jp)).min() > 1.0
    Jad = jax.vmap(lambda x, y: m.planar_jacobian_ad(x, y, A, B, C))(D1, D2)
    assert np.abs(np.asarray(paper.jacobian_printed(D1, D2, A, C)) - np.asarray(Jad)).max() > 1.0
    np.testing.assert_allclose(
        paper.det_printed(D1, D2, A, C), np.linalg.det(np.asarray(Jad)), atol=1e-12
    )


def test_planar_ik_round_trip():
    D = m.fk(D1, D2, A, B, C)
    x, y = m.ik(D[:, 0], D[:, 1], A, B, C)
    np.testing.assert_allclose(x, D1, atol=1e-10)
    np.testing.assert_allclose(y, D2, atol=1e-10)


def test_arm_fk_matches_dh_table_and_the_composed_planar_mechanism():
    t1 = RNG.uniform(-0.66, 0.66, D1.size)
    L = 412.5
    P = np.asarray(m.arm_fk(t1, D1, D2, A, C, L))
    th2, d = m.arm_joints(D1, D2, A, C)
    _, pos = m.arm_dh().fk(jnp.asarray([[L]]), jnp.stack([t1, th2, d], -1))
    np.testing.assert_allclose(np.asarray(pos)[0], P, atol=1e-10)
    # composed: the planar tip D − R in the arm's vertical plane, turned by θ1 about z
    D = np.asarray(m.fk(D1, D2, A, B, C)) - np.array([B, 0.0])
    h = D[:, 1]  # planar y → horizontal (toward −x at θ1 = 0)
    P_ref = np.stack([h * np.cos(t1), h * np.sin(t1), D[:, 0] + L], -1)
    np.testing.assert_allclose(P, P_ref, atol=1e-10)


def test_arm_ik_round_trip_1e5_points():
    n = 100_000
    rng = np.random.default_rng(7)
    q = np.stack(
        [rng.uniform(-0.66, 0.66, n), rng.uniform(22, 215, n), rng.uniform(35, 200, n)], -1
    )
    P = jax.jit(jax.vmap(lambda q: m.arm_fk(q[0], q[1], q[2], A, C, 300.0)))(jnp.asarray(q))
    t1, d1, d2 = jax.jit(jax.vmap(lambda p: m.arm_ik(p, A, C, 300.0)))(P)
    P2 = m.arm_fk(t1, d1, d2, A, C, 300.0)
    assert float(jnp.max(jnp.linalg.norm(P2 - P, axis=1))) <= 1e-9
    np.testing.assert_allclose(np.stack([t1, d1, d2], -1), q, atol=1e-9)


def test_arm_volume_element_matches_autodiff():
    t1 = RNG.uniform(-0.66, 0.66, 500)
    Ja = jax.vmap(jax.jacfwd(lambda q: m.arm_fk(q[0], q[1], q[2], A, C, 0.0)))(
        jnp.stack([t1, D1[:500], D2[:500]], -1)
    )
    np.testing.assert_allclose(
        np.abs(np.linalg.det(np.asarray(Ja))), m.arm_det(D1[:500], D2[:500], A, C), rtol=1e-10
    )


def test_workspace_volume_against_quadrature():
    """V of the built arm ± SE vs ∫ d² cos θ2 dd dθ2 dθ1 over the image of the joint box,
    by a midpoint rule in spherical coordinates (d, θ2) with a box indicator."""
    ws = workspace.built(jax.random.key(5), 200_000)
    n = 2000
    d = np.linspace(0, C, n + 1)
    d = 0.5 * (d[1:] + d[:-1])
    th = np.linspace(-np.pi / 2, np.pi / 2, n + 1)
    th = 0.5 * (th[1:] + th[:-1])
    Dg, Tg = np.meshgrid(d, th, indexing="ij")
    r = C - Dg
    d1, d2 = A - r * np.sin(Tg), r * np.cos(Tg)
    inside = (d1 >= 22) & (d1 <= 215) & (d2 >= 35) & (d2 <= 200)
    ref = np.sum(inside * Dg**2 * np.cos(Tg)) * (d[1] - d[0]) * (th[1] - th[0]) * np.deg2rad(76)
    assert abs(float(ws.volume) - ref) < 4 * float(ws.volume_se) + 1e-3 * ref
    assert float(ws.d_min) > 0  # one-to-one on the built design


# ----------------------------------------------------------------------- η and reach


def _quad_eta(c, a=A, n=1500):
    """Independent numpy references: η over the joint box (joint and Cartesian measures,
    midpoint rule) and over the planar task cone (density ∝ d on [50, 200])."""
    g1 = 22 + (np.arange(n) + 0.5) * (193 / n)
    g2 = 35 + (np.arange(n) + 0.5) * (165 / n)
    G1, G2 = np.meshgrid(g1, g2)
    r = np.hypot(G1 - a, G2)
    ik = np.minimum(np.abs(c - r), r) / np.maximum(np.abs(c - r), r)
    w = np.abs(1 - c / r)
    dd = 50 + (np.arange(200_000) + 0.5) * (150 / 200_000)
    g = np.minimum(dd, c - dd) / np.maximum(dd, c - dd)
    return {"box_joint": ik.mean(), "box_cartesian": (ik * w).sum() / w.sum(),
            "cone_cartesian": (g * dd).sum() / dd.sum()}  # fmt: skip


@pytest.mark.parametrize("c", [230.0, 330.0])
def test_eta_matches_numpy_quadrature_within_4_se(c):
    s = RcmSettings(variables={"c": (200, 400)}, eta={"n_samples": 65536},
                    constraints={"eq19": False, "reach_min": None})  # fmt: skip
    ref = _quad_eta(c)
    for meas in ("joint", "cartesian"):
        sm = s.model_copy(update={"eta": s.eta.model_copy(update={"measure": meas})})
        P = obj.problem(sm, streams(0), jnp.float64)
        _, aux = P.evaluate(jnp.asarray([[c]]))
        key = f"box_{meas}"
        assert abs(float(aux["eta_box"][0]) - ref[key]) < 4 * float(aux["eta_box_se"][0]), (meas, c)
        if meas == "cartesian":
            assert abs(float(aux["eta_cone"][0]) - ref["cone_cartesian"]) < 4 * float(
                aux["eta_cone_se"][0]
            )


def test_reach_and_constraints_of_the_built_design():
    s = RcmSettings(eta={"n_samples": 32768})
    P = obj.problem(s, streams(0), jnp.float64)
    X = jnp.asarray([[120.0, 250.0], [120.0, 300.0], [90.0, 250.0]])
    _, aux = P.evaluate(X)
    reach = np.asarray(aux["reach"])
    assert reach[0] > 0.99 and reach[1] < 0.9
    np.testing.assert_allclose(np.asarray(aux["eq19_margin"]), [20.0, -5.0, -10.0], atol=1e-9)
    v = np.asarray(P.violation(X))
    assert v[0] == 0 and v[1] > 0 and v[2] > 0


def test_cone_3d_reach_uses_theta1():
    s = RcmSettings(variables={"c": (200, 400)}, cone={"dim": 3}, eta={"n_samples": 16384},
                    constraints={"eq19": False, "reach_min": None})  # fmt: skip
    P = obj.problem(s, streams(0), jnp.float64)
    _, aux = P.evaluate(jnp.asarray([[250.0]]))
    assert 0.9 < float(aux["reach"][0]) <= 1.0
    narrow = s.model_copy(
        update={"joints": s.joints.model_copy(update={"theta1_deg": (-10.0, 10.0)})}
    )
    _, aux2 = obj.problem(narrow, streams(0), jnp.float64).evaluate(jnp.asarray([[250.0]]))
    assert float(aux2["reach"][0]) < 0.8 * float(aux["reach"][0])


def test_optimum_is_feasible_and_beats_the_built_design(tmp_path):
    raw = {"study": {"name": "rcm", "eta": {"n_samples": 8192}},
           "optimizer": {"name": "ptpso", "n_particles": 24, "n_iters": 30, "n_runs": 2},
           "precision": "float64", "seed": 0}  # fmt: skip
    rep = pipeline.run(validate(raw, "t"), "t", "t", tmp_path / "r.h5")
    fin = rep.tree["final"]
    assert float(fin["violation"]) == 0.0
    a, c = fin["x"]
    assert a >= 0.5 * (c - 50) - 1e-9 and float(fin["reach"]) >= 0.99
    P = pipeline.build_problem(validate(raw, "t"), streams(0))
    f_built = float(P.evaluate(jnp.asarray([[120.0, 250.0]]))[0][0])
    assert float(fin["f"]) <= f_built


def test_penalty_option_runs_and_archives_the_violation(tmp_path):
    raw = {"study": {"name": "rcm", "eta": {"n_samples": 4096}},
           "optimizer": {"name": "cmaes", "n_particles": 12, "n_iters": 30,
                         "constraints": {"method": "penalty", "weight": 100.0}},
           "precision": "float64", "seed": 1}  # fmt: skip
    rep = pipeline.run(validate(raw, "t"), "t", "t", tmp_path / "p.h5")
    a = archive.read(tmp_path / "p.h5")
    assert "violation" in a["final"] and "history_v" not in a["optimizer"]
    assert float(a["final"]["violation"]) < 0.05
    assert rep.tree["optimizer"]["attrs"]["settings"] is not None
    assert a["attrs"]["config_resolved"]["optimizer"]["constraints"]["method"] == "penalty"


# ------------------------------------------------------------------------- teleop


def _replay(master, clutch, scale=1.0, q0=(0.0, 120.0, 130.0), limits=None):
    lo, hi = limits or ((-0.66, 22.0, 35.0), (0.66, 215.0, 200.0))
    q0 = jnp.asarray([q0[0], q0[1], q0[2]])
    return teleop.replay(jnp.asarray(master, float), jnp.asarray(clutch), q0,
                         jnp.asarray([A, C, 0.0]), jnp.eye(3), jnp.asarray(scale),
                         jnp.asarray(lo), jnp.asarray(hi))  # fmt: skip


def test_replay_follows_scaled_increments_and_clutch_holds():
    n = 200
    t = np.linspace(0, 1, n)
    master = np.stack([40 * t, 30 * np.sin(3 * t), 10 * t], -1)
    clutch = (t > 0.4) & (t < 0.6)
    out = _replay(master, clutch, scale=2.0)
    cmd = np.asarray(out.command)
    assert not np.asarray(out.clamped).any()
    dm = np.diff(master, axis=0)
    dm[clutch[1:]] = 0
    np.testing.assert_allclose(np.diff(cmd, axis=0), dm / 2, atol=1e-9)
    held = np.where(clutch)[0]
    np.testing.assert_allclose(cmd[held], np.tile(cmd[held[0]], (len(held), 1)), atol=1e-12)


def test_replay_clamps_out_of_workspace_targets_and_reports_it():
    master = np.stack([np.zeros(100), np.linspace(0, 400, 100), np.zeros(100)], -1)  # far sideways
    out = _replay(master, np.zeros(100, bool))
    cl = np.asarray(out.clamped)
    assert cl.any() and not cl[0]
    q = np.asarray(out.q)
    assert np.all(q[:, 0] <= 0.66 + 1e-12) and np.all(q[:, 0] >= -0.66 - 1e-12)
    # increments add to the clamped command: saturated rows are moved back by one increment
    np.testing.assert_allclose(float(np.max(out.clamp_dist)), 400 / 99, rtol=1e-6)
    assert abs(q[-1, 0]) == pytest.approx(0.66)


def test_shipped_trajectory_is_the_synthetic_one(tmp_path):
    shipped = teleop.read_csv("configs/data/rcm_master_square.csv")
    syn = teleop.synthetic()
    np.testing.assert_allclose(shipped.master, syn.master, atol=1e-6)
    np.testing.assert_array_equal(shipped.clutch, syn.clutch)


@pytest.mark.parametrize("body,line", [
    ("t,x,y,z\n0,0,0,0\n", 1),
    ("t,x,y,z,clutch\n0,0,0,0,0\n0.1,1,a,0,0\n", 3),
    ("t,x,y,z,clutch\n0,0,0,0,0\n0.1,1,1,0,0\n0.05,1,1,0,0\n", 4),
    ("t,x,y,z,clutch\n0,0,0,0,0\n0.1,1,1,0,2\n", 3),
    ("t,x,y,z,clutch\n0,0,0,0,0\n0.1,1,nan,0,0\n", 3),
    ("t,x,y,z,clutch\n0,0,0,0,0\n0.1,1,1,0\n", 3),
])  # fmt: skip
def test_malformed_trajectory_names_the_line(tmp_path, body, line):
    p = tmp_path / "m.csv"
    p.write_text(body)
    with pytest.raises(ValueError, match=f"line {line}"):
        teleop.read_csv(p)


def test_teleop_run_archives_the_replay(tmp_path, capsys):
    cfgp = tmp_path / "tele.yaml"
    traj = tmp_path / "m.csv"
    teleop.write_csv(teleop.synthetic(rate_hz=50.0), traj)
    cfgp.write_text("study:\n  name: rcm_teleop\n  trajectory: m.csv\n  delay_ms: 0\n")
    assert main(["run", str(cfgp), "--out", str(tmp_path / "t.h5"), "--no-figures", "--quiet"]) == 0
    a = archive.read(tmp_path / "t.h5")
    tt = a["teleop"]
    assert tt["q"].shape == (len(tt["t"]), 3)
    assert float(np.max(tt["error"])) < 1e-9  # no delay, nothing clamped: exact tracking
    assert main(["show", str(tmp_path / "t.h5")]) == 0
    assert "tracking error" in capsys.readouterr().out


# ------------------------------------------------------------------------ bad input


def _write(tmp_path, text, name="c.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text,needle", [
    ("study: {name: rcm, variables: {a: [60, 200], c: [-10, 300]}}\n",
     "key 'study.variables.c': lengths must be > 0"),
    ("study: {name: rcm, variables: {a: [60, 200]}, fixed: {c: 0}}\n",
     "key 'study.fixed.c': lengths must be > 0"),
    ("study: {name: rcm, eta: {workspace: sphere}}\n", "study.eta.workspace"),
    ("study: {name: rcm, joints: {d1: [22, 40], d2: [35, 50]}}\n", "joint box reaches at most"),
])  # fmt: skip
def test_bad_rcm_configs_exit_2_with_one_line(tmp_path, capsys, text, needle):
    p = _write(tmp_path, text + "optimizer: {n_particles: 4, n_iters: 2}\n")
    assert main(["run", str(p), "--out", str(tmp_path / "x.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and "Traceback" not in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "x.h5").exists()


def test_malformed_trajectory_exits_2_naming_the_line(tmp_path, capsys):
    (tmp_path / "bad.csv").write_text("t,x,y,z,clutch\n0,0,0,0,0\n0.1,1,1,0,7\n")
    p = _write(tmp_path, "study: {name: rcm_teleop, trajectory: bad.csv}\n")
    assert main(["run", str(p), "--out", str(tmp_path / "x.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "line 3" in err and "bad.csv" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "x.h5").exists()


def test_float32_problem_with_x64_enabled():
    """float32 configs run with JAX's 64-bit mode on (the tests' default): no dtype leak."""
    s = RcmSettings(eta={"n_samples": 2048})
    P = obj.problem(s, streams(0), jnp.float32)
    f, aux = P.evaluate(jnp.asarray([[120.0, 250.0]], jnp.float32))
    assert f.dtype == jnp.float32 and aux["reach"].dtype == jnp.float32
    assert 0.99 < float(aux["reach"][0]) <= 1.0
