"""Study D (seed 004, PLAS master): the kernel chains against the seed's closed forms, the
mapping factors and the §4.1 numbers, the counterbalance, the workspace mismatch against an
independent numpy reference, the constraints, and bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.app import pipeline
from designopt.app.config import validate
from designopt.cli.commands import main
from designopt.studies import streams
from designopt.studies.plas import mechanism as m
from designopt.studies.plas import objective as obj
from designopt.studies.plas import paper as P

RNG = np.random.default_rng(4)
T = RNG.uniform(-1.4, 1.4, (64, 4))  # (θ2, θ3, θ4, θ5)
SL = m.slave_row()
BUILT = m.master_rows({})


def _cfg(study=None, **over):
    raw = {"study": {"name": "plas", "mismatch": {"n_samples": 2048, "chunk": 1024, "n_path": 4},
                     "constraints": {"n_grid": 5}} | (study or {}),
           "optimizer": {"name": "ptpso", "n_particles": 6, "n_iters": 3, "n_runs": 1},
           "precision": "float64", "seed": 1} | over  # fmt: skip
    return validate(raw, "test")


@pytest.fixture(scope="module")
def prob():
    cfg = _cfg()
    return cfg, pipeline.build_problem(cfg, streams(cfg.seed))


# ------------------------------------------------------------------------ chains


def test_master_table3_reconstruction_is_eq5_and_eq9():
    q = np.zeros((64, 6))
    q[:, 1:5] = T
    R, p = m.MASTER_FULL.fk(np.array([[P.A2P, P.D6]]), q)
    E = P.eq5(*T.T)
    np.testing.assert_allclose(np.asarray(R[0]), E[:, :3, :3], atol=1e-13)
    np.testing.assert_allclose(np.asarray(p[0]), E[:, :3, 3], atol=1e-11)
    # eq. (9): the same position and tool axis written in frame 2 (= base turned by θ2)
    F = P.eq9_frame2(T[:, 1], T[:, 2], T[:, 3])
    c, s = np.cos(T[:, 0]), np.sin(T[:, 0])
    for col in (2, 3):
        v = F[:, :3, col]
        rot = np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], -1)
        np.testing.assert_allclose(rot, E[:, :3, col], atol=1e-11)
    # as printed, eq. (5) is not a rotation: the S2·C3 sign slip of its y row
    Rp = P.eq5(*T.T, as_printed=True)[:, :3, :3]
    assert np.abs(np.einsum("nji,njk->nik", Rp, Rp) - np.eye(3)).max() > 0.1
    # eq. (18): the x and z rows of J1 (θ columns) are the kernel's Jacobian
    J = np.asarray(m.MASTER_FULL.jacobian(np.array([[P.A2P, P.D6]]), q, rows=(0, 1, 2)))[0]
    J1 = P.eq18_j1(T[:, 0], T[:, 1], T[:, 2])
    np.testing.assert_allclose(J[:, [0, 2], :5], J1[:, [0, 2], :5], atol=1e-11)


def test_slave_table1_reaches_the_reduced_tip():
    q = np.zeros((64, 6))
    q[:, 1:4] = T[:, :3]
    q[:, 4] = P.D5
    _, p = m.SLAVE_FULL.fk(np.array([[P.A2, P.A3, 0.0]]), q)
    p1 = np.asarray(p[0]) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0.0]])  # in frame 1
    ref = P.eq22_slave(T[:, 0], T[:, 1], np.pi / 2 - T[:, 2])
    np.testing.assert_allclose(p1, ref, atol=1e-11)


def test_reduced_models_fk_and_velocities_are_eq22_eq25_eq26():
    q = jnp.asarray(T)
    _, ps = m.SLAVE.fk(SL, q)
    _, pm = m.MASTER.fk(BUILT, q)
    np.testing.assert_allclose(ps[0], P.eq22_slave(*T[:, :3].T), atol=1e-11)
    np.testing.assert_allclose(pm[0], P.master_reduced(*T[:, :3].T), atol=1e-11)
    rates = RNG.normal(size=(64, 3))
    Js = np.asarray(m.SLAVE.jacobian(SL, q, rows=(0, 1, 2), cols=(0, 1, 2)))[0]
    Jm = np.asarray(m.MASTER.jacobian(BUILT, q, rows=(0, 1, 2), cols=(0, 1, 2)))[0]
    np.testing.assert_allclose(np.einsum("nij,nj->ni", Js, rates),
                               P.eq25_slave_velocity(T[:, :3], rates), atol=1e-10)  # fmt: skip
    np.testing.assert_allclose(np.einsum("nij,nj->ni", Jm, rates),
                               P.eq26_master_velocity(T[:, :3], rates), atol=1e-10)  # fmt: skip


# --------------------------------------------------------------- mapping factors


def test_factors_are_eq28_and_the_jacobian_row_ratios():
    th = T[:, :3] * np.array([0.5, 0.6, 0.9])  # inside |θ2|, |θ2 + θ3| < 90°
    k = np.stack(m.mapping_factors(jnp.asarray(BUILT[0]), jnp.asarray(SL[0]), jnp.asarray(th)), -1)
    np.testing.assert_allclose(k, np.stack(P.eq28_factors(*th.T), -1), rtol=1e-13)
    Js = np.asarray(m.SLAVE.jacobian(SL, m.q4(jnp.asarray(th)), rows=(1, 2), cols=(0, 1, 2)))[0]
    Jm = np.asarray(m.MASTER.jacobian(BUILT, m.q4(jnp.asarray(th)), rows=(1, 2), cols=(0, 1, 2)))[0]
    ratio = np.stack(
        [Jm[:, 0, 0] / Js[:, 0, 0], Jm[:, 0, 1] / Js[:, 0, 1], Jm[:, 1, 2] / Js[:, 1, 2]], -1
    )
    np.testing.assert_allclose(k, ratio, rtol=1e-12)  # eq. (27): v_y for 2, 3; v_z for 4


@pytest.mark.parametrize("joint,slave_deg,tol_deg,travel,tol_mm", [
    (2, 62.5, 0.05, 103.6, 0.1),   # 62.53°; 103.67 mm (the seed truncates)
    (3, 40.0, 0.5, 31.4, 0.05),    # "about 40": exactly 40.00°; 31.42 mm
    (4, 60.0, 1e-9, 31.4, 0.05),   # 60°; 31.42 mm
])  # fmt: skip
def test_single_joint_motions_reproduce_fig20_22(joint, slave_deg, tol_deg, travel, tol_mm):
    """Master joint from 0 to 30°, the others at 0; the slave follows θ'_s = k θ'_m with
    eq. (28) from ``mechanism`` and both tip paths come from the kernel chains."""
    n = 601
    t = np.linspace(0.0, np.deg2rad(30.0), n)
    th = np.zeros((n, 3))
    th[:, joint - 2] = t
    k = np.asarray(m.mapping_factors(jnp.asarray(BUILT[0]), jnp.asarray(SL[0]), jnp.asarray(th)))[
        joint - 2
    ]
    ts = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(t))])
    ths = np.zeros((n, 3))
    ths[:, joint - 2] = ts
    _, pm = m.MASTER.fk(BUILT, m.q4(jnp.asarray(th)))
    _, ps = m.SLAVE.fk(SL, m.q4(jnp.asarray(ths)))
    path = [np.sum(np.linalg.norm(np.diff(np.asarray(p[0]), axis=0), axis=1)) for p in (pm, ps)]
    assert abs(np.rad2deg(ts[-1]) - slave_deg) <= tol_deg
    assert abs(path[0] - travel) <= tol_mm and abs(path[1] - travel) <= tol_mm
    assert abs(path[0] - path[1]) < 1e-3  # "both tips travel the same distance"
    assert P.single_joint_motion(joint)[0] == pytest.approx(np.rad2deg(ts[-1]), abs=1e-3)


def test_vy_vz_match_exactly_and_vx_has_eq29_error_zero_only_at_theta3_0():
    th = T[:, :3] * np.array([0.5, 0.6, 0.9])
    designs = np.array([[138.0, 0.0, 60.0], [100.0, 0.0, 90.0], [120.0, 10.0, 70.0]])
    rates = RNG.normal(size=(64, 3))
    Js = np.asarray(m.SLAVE.jacobian(SL, m.q4(jnp.asarray(th)), rows=(0, 1, 2), cols=(0, 1, 2)))[0]
    Jm = np.asarray(
        m.MASTER.jacobian(designs, m.q4(jnp.asarray(th)), rows=(0, 1, 2), cols=(0, 1, 2))
    )
    K = np.asarray(obj.factors(jnp.asarray(designs), jnp.asarray(SL[0]), jnp.asarray(th)))
    vs = np.einsum("nij,mnj->mni", Js, K * rates)
    vm = np.einsum("mnij,nj->mni", Jm, rates)
    np.testing.assert_allclose(vs[..., 1:], vm[..., 1:], atol=1e-10)  # v_y, v_z exact
    err = P.eq29_error(*th.T)  # built master, as printed
    np.testing.assert_allclose(
        vs[0, :, 0] - vm[0, :, 0], err * rates[:, 0], atol=1e-10
    )  # v_x: sign as printed
    # eq. (29) = S3·(a2(a3' + d6C4) − a2'(a3 + d5C4)) / (C23(a3 + d5C4) + a2C2): zero at θ3 = 0
    g = np.deg2rad(np.linspace(-60, 60, 25))
    G2, G3, G4 = np.meshgrid(g / 2, g, g / 2, indexing="ij")
    e = P.eq29_error(G2, G3, G4)
    assert np.all(np.abs(e[:, 12, :]) < 1e-12)  # θ3 = 0
    assert np.all(np.abs(np.delete(e, 12, axis=1)) > 1e-3)  # nowhere else on the grid


def test_counterbalance_about_460_g():
    mass = float(m.counterbalance_mass(240.5, 18.8, 9.0, 3.4, np.deg2rad(25.0)))
    assert mass == pytest.approx(P.eq1_counterbalance())
    assert abs(mass - 460.0) <= 0.01 * 460.0  # 462.3 g; the seed: "about 460 g"
    I = float(m.counterbalance_inertia(240.5, 18.8, mass, 3.4))  # noqa: E741
    assert I == pytest.approx(240.5 * 18.8**2 + mass * 3.4**2)
    m_d, i_d = obj.counterbalance(
        jnp.asarray([60.0, 80.0]),
        {"M": 240.5, "L": 188.0, "r": 90.0, "l": 34.0, "theta": np.deg2rad(25.0), "L_per_d6": 1.0},
    )
    assert float(m_d[0]) == pytest.approx(mass) and float(i_d[0]) == pytest.approx(I)
    assert float(i_d[1]) > float(i_d[0])  # a longer handle costs inertia


# ------------------------------------------------------------- workspace mismatch


def numpy_mismatch(design, n=200_000, seed=11, rate_deg=30.0, n_path=4):
    """vel_rel, vel_abs and pos_mean of a master design (a2', a3', d6) from the printed
    closed forms (eq. 22, 25, 26, 28 and the reduced master), independent samples."""
    a2p, a3p, d6 = design
    rng = np.random.default_rng(seed)
    box = np.deg2rad([[-30, 30], [-60, 60], [-30, 30]])
    th = box[:, 0] + (box[:, 1] - box[:, 0]) * rng.uniform(size=(n, 3))
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)

    def fac(t):
        C2, C23, C4 = np.cos(t[:, 0]), np.cos(t[:, 0] + t[:, 1]), np.cos(t[:, 2])
        A, B = a3p + d6 * C4, P.A3 + P.D5 * C4
        return np.stack(
            [(C23 * A + a2p * C2) / (C23 * B + P.A2 * C2), A / B, d6 / P.D5 + 0 * C4], -1
        )

    def vm_fn(t, r):  # eq. (26) with the offset a3'
        S2, C2 = np.sin(t[:, 0]), np.cos(t[:, 0])
        S23, C23 = np.sin(t[:, 0] + t[:, 1]), np.cos(t[:, 0] + t[:, 1])
        S4, C4 = np.sin(t[:, 2]), np.cos(t[:, 2])
        A = a3p + d6 * C4
        return np.stack([(-S23 * A - a2p * S2) * r[:, 0] - S23 * A * r[:, 1] - d6 * S4 * C23 * r[:, 2],
                         (C23 * A + a2p * C2) * r[:, 0] + C23 * A * r[:, 1] - d6 * S4 * S23 * r[:, 2],
                         d6 * C4 * r[:, 2]], -1)  # fmt: skip

    vm = vm_fn(th, u)
    vs = P.eq25_slave_velocity(th, fac(th) * u)
    dv = np.linalg.norm(vs - vm, axis=1)
    w = np.linalg.norm(vm, axis=1)
    kbar = sum(fac((j + 0.5) / n_path * th) for j in range(n_path)) / n_path
    ts = kbar * th

    def pm(t):
        C4 = np.cos(t[:, 2])
        A = a3p + d6 * C4
        return np.stack([a2p * np.cos(t[:, 0]) + A * np.cos(t[:, 0] + t[:, 1]),
                         a2p * np.sin(t[:, 0]) + A * np.sin(t[:, 0] + t[:, 1]), d6 * np.sin(t[:, 2])], -1)  # fmt: skip

    z = np.zeros((1, 3))
    dp = (P.eq22_slave(*ts.T) - P.eq22_slave(*z.T)) - (pm(th) - pm(z))
    e = np.linalg.norm(dp, axis=1)
    R = dv.sum() / w.sum()
    r_se = np.std(dv - R * w, ddof=1) / np.sqrt(n) / w.mean()
    rate = np.deg2rad(rate_deg)
    return {"vel_rel": (R, r_se), "vel_abs": (rate * dv.mean(), rate * dv.std(ddof=1) / np.sqrt(n)),
            "pos_mean": (e.mean(), e.std(ddof=1) / np.sqrt(n))}  # fmt: skip


@pytest.mark.parametrize("design", [(138.0, 0.0, 60.0), (100.0, 0.0, 90.0)])
def test_mismatch_against_numpy_reference_within_4_se(prob, design):
    cfg, Pb = prob
    X = np.array([[design[0], design[2]]])
    f, sub = jax.jit(Pb.fn)(Pb.params, jnp.asarray(X), jax.random.key(0))
    ref = numpy_mismatch(design)
    for k in ("vel_rel", "vel_abs", "pos_mean"):
        v, se = float(sub[k][0]), float(sub[k + "_se"][0])
        rv, rse = ref[k]
        assert se > 0 and abs(v - rv) < 4 * np.hypot(se, rse), (k, v, se, rv, rse)
    assert float(sub["vel_max"][0]) >= float(sub["vel_abs"][0]) and "vel_max_se" not in sub
    if design == (138.0, 0.0, 60.0):  # the built master is the reference: f = 1, no reduction
        assert float(f[0]) == pytest.approx(1.0, rel=1e-12)
        assert abs(float(sub["vel_reduction"][0])) < 1e-12


def test_scale_invariance_reduction_and_constraints(prob):
    cfg, Pb = prob
    X = jnp.asarray([[138.0, 60.0], [100.0, 90.0], [120.0, 108.0], [220.0, 110.0]])
    f, sub = jax.jit(Pb.fn)(Pb.params, X, jax.random.key(0))
    # the relative velocity mismatch depends on the shape only (d6/a2'), not on the size
    assert float(sub["vel_rel"][2]) == pytest.approx(float(sub["vel_rel"][1]), rel=1e-10)
    red = float(sub["vel_reduction"][1])
    assert red > 0.5 and float(sub["vel_reduction_se"][1]) < 0.01
    assert red == pytest.approx(1 - float(sub["vel_rel"][1]) / float(sub["vel_rel"][0]), rel=1e-12)
    v = np.asarray(Pb.violation(X))
    assert v[0] == 0 and v[1] == 0  # built and (100, 90): reach 198, 190 mm
    assert v[2] > 0 and v[3] > 0  # k4 = 3.6 > 3; reach 330 mm > 1.2 × 198
    G = np.asarray(Pb.constraints(Pb.params, X))
    assert G[3, 0] == pytest.approx((330 - 1.2 * 198) / 198)


def test_run_config_and_scan_config_load():
    from designopt.app.config import load

    for p in ("configs/plas.yaml", "configs/plas_scan.yaml"):
        cfg, _ = load(p)
        assert cfg.study.name == "plas"


# --------------------------------------------------------------------- bad input

BASE = """
study:
  name: plas
  variables: {a2p: [80, 240], d6: [30, 120]}
  slave: {a2: 50, a3: 15, d5: 30}
  joint_ranges_deg: {theta2: [-30, 30], theta3: [-60, 60], theta4: [-30, 30]}
  mismatch: {n_samples: 256, chunk: 256}
optimizer: {name: ptpso, n_particles: 4, n_iters: 2, n_runs: 1}
scan:
  vary: {a2p: [100, 138]}
precision: float64
output: OUT
"""


@pytest.mark.parametrize("old,new,needle", [
    ("slave: {a2: 50,", "slave: {a2: -50,", "study.slave.a2"),
    ("a2p: [80, 240]", "a2p: [-80, 240]", "study.variables"),
    ("theta4: [-30, 30]}", "theta4: [-30, 120]}", "exceeds the slave's limits"),
    ("theta3: [-60, 60]", "theta3: [-80, 80]", "|θ2 + θ3| ≤ 90°"),
])  # fmt: skip
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, old, new, needle):
    assert old in BASE
    p = tmp_path / "c.yaml"
    p.write_text(BASE.replace(old, new, 1).replace("OUT", str(tmp_path / "a.h5")))
    for cmd in (["run", str(p), "--quiet"], ["scan", str(p), "--quiet"],
                ["eval", str(p), "--design", "a2p=138"]):  # fmt: skip
        assert main(cmd) == 2
        err = capsys.readouterr().err
        assert needle in err and str(p) in err and err.count("\n") == 1, err
    assert not any(q.suffix == ".h5" for q in tmp_path.iterdir())
