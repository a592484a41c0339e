"""The 2-DOF spherical RCM study (sphere_rcm) and the Raven II-style arm config
(configs/raven2.yaml): FK, Jacobian and IK against numpy, autodiff and finite
differences; 1/k against numpy's SVD and the closed forms; the index at (90°, 90°)
against its closed form; the optimizer reaching the paper's kinematic optimum; bad input;
the Raven chain against the control code's own DH convention, its RCM and link angles."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

import designopt
from designopt.app.config import validate
from designopt.core.errors import ConfigError
from designopt.studies import get, streams
from designopt.studies.serial.mechanism import build
from designopt.studies.serial.settings import SerialSettings
from designopt.studies.sphere import closedform, objective, paper
from designopt.studies.sphere import mechanism as m

ROOT = Path(__file__).resolve().parents[1]
RNG = np.random.default_rng(47)
N = 2000
TH1 = RNG.uniform(-np.pi, np.pi, N)
TH2 = RNG.uniform(-np.pi, np.pi, N)
A12 = np.deg2rad(RNG.uniform(15, 165, N))
A23 = np.deg2rad(RNG.uniform(15, 165, N))


# ------------------------------------------------------------- independent numpy references


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack(
        [np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2
    )


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    o, z = np.ones_like(t), np.zeros_like(t)
    return np.stack(
        [np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


def np_axes(th1, th2, a12, a23):
    """(z1, z2, u) by rotation matrices: frame 1 = Rz(θ1)Rx(α12), tool = frame 1·Rz(θ2)Rx(α23)."""
    F1 = _rz(th1) @ _rx(a12)
    F2 = F1 @ _rz(th2) @ _rx(a23)
    z1 = np.broadcast_to([0.0, 0.0, 1.0], F1.shape[:-2] + (3,))
    return z1, F1[..., :, 2], F2[..., :, 2]


def np_jacobian(th1, th2, a12, a23):
    z1, z2, u = np_axes(th1, th2, a12, a23)
    return np.stack([np.cross(z1, u), np.cross(z2, u)], -1)


def np_inv_cond(J):
    s = np.linalg.svd(J, compute_uv=False)
    return s[..., 1] / s[..., 0]


def cap_directions(n, half, gamma, rng):
    """Directions uniform on the cap (numpy, own construction: a rotation of z-capped ones)."""
    ct = rng.uniform(np.cos(half), 1.0, n)
    st = np.sqrt(1 - ct**2)
    ps = rng.uniform(0, 2 * np.pi, n)
    v = np.stack([st * np.cos(ps), st * np.sin(ps), ct], -1)  # about +z
    Ry = np.array(
        [[np.cos(gamma), 0, np.sin(gamma)], [0, 1, 0], [-np.sin(gamma), 0, np.cos(gamma)]]
    )
    return v @ Ry.T  # the cap's axis at angle γ from z in the xz plane


# ---------------------------------------------------------------------------- kinematics


def test_fk_matches_rotation_matrices_and_the_generic_dh_kernel():
    u = np.asarray(m.direction(TH1, TH2, A12, A23))
    z1, z2, un = np_axes(TH1, TH2, A12, A23)
    np.testing.assert_allclose(u, un, atol=1e-14)
    z1j, z2j, _ = (np.asarray(x) for x in m.axes(TH1, TH2, A12, A23))
    np.testing.assert_allclose(z2j, z2, atol=1e-14)
    np.testing.assert_allclose(np.einsum("ni,ni->n", z1j, z2j), np.cos(A12), atol=1e-14)
    np.testing.assert_allclose(np.einsum("ni,ni->n", z2j, u), np.cos(A23), atol=1e-14)
    # cos φ = c12 c23 − s12 s23 cos θ2
    np.testing.assert_allclose(u[:, 2], np.cos(A12) * np.cos(A23)
                               - np.sin(A12) * np.sin(A23) * np.cos(TH2), atol=1e-14)  # fmt: skip
    # the same chain as a standard-DH table (a = d = 0) on the package's frame kernel
    from designopt.kinematics.kernel import dh_model

    model = dh_model("standard", ["R", "R"], alpha=["a12", "a23"], a=[0.0, 0.0], d=[0.0, 0.0],
                     theta=[0.0, 0.0], variables=["a12", "a23"])  # fmt: skip
    X = np.stack([A12[:50], A23[:50]], -1)
    R, _ = model.fk(X, np.stack([TH1[:50], TH2[:50]], -1))  # (M, C, 3, 3): all pairs
    diag = np.asarray(R)[np.arange(50), np.arange(50), :, 2]
    np.testing.assert_allclose(diag, u[:50], atol=1e-14)


def test_jacobian_against_autodiff_finite_differences_and_numpy():
    J = np.asarray(m.jacobian(TH1, TH2, A12, A23))
    np.testing.assert_allclose(J, np_jacobian(TH1, TH2, A12, A23), atol=1e-14)
    k = slice(0, 200)
    Jad = np.asarray(jax.vmap(m.jacobian_ad)(TH1[k], TH2[k], A12[k], A23[k]))
    np.testing.assert_allclose(J[k], Jad, atol=1e-14)
    h = 1e-6  # central differences: error ~h²/6 ≈ 2e-13, rounding ~eps/h ≈ 1e-10
    fd1 = (np_axes(TH1 + h, TH2, A12, A23)[2] - np_axes(TH1 - h, TH2, A12, A23)[2]) / (2 * h)
    fd2 = (np_axes(TH1, TH2 + h, A12, A23)[2] - np_axes(TH1, TH2 - h, A12, A23)[2]) / (2 * h)
    np.testing.assert_allclose(J, np.stack([fd1, fd2], -1), atol=1e-9)
    # both columns ⟂ u: the Jacobian maps into the tangent plane of the tool direction
    u = np.asarray(m.direction(TH1, TH2, A12, A23))
    assert np.abs(np.einsum("ni,nij->nj", u, J)).max() < 1e-14


def test_ik_both_branches_reproduce_the_direction():
    u = np.asarray(m.direction(TH1, TH2, A12, A23))
    th1, th2, ok = (np.asarray(x) for x in m.ik(jnp.asarray(u), A12, A23))
    assert ok.all()
    for b in (0, 1):
        back = np_axes(th1[:, b], th2[:, b], A12, A23)[2]
        np.testing.assert_allclose(back, u, atol=1e-11)
    # the original solution is one of the two branches (angles mod 2π)
    d = lambda a, b: np.abs(np.angle(np.exp(1j * (a - b))))  # noqa: E731
    err = np.minimum(d(th1[:, 0], TH1) + d(th2[:, 0], TH2), d(th1[:, 1], TH1) + d(th2[:, 1], TH2))
    far = np.abs(np.sin(TH2)) > 1e-6  # θ2 = 0, π: one branch, θ1 then exact too
    assert err[far].max() < 1e-9


def test_reach_is_the_band_and_unreachable_counts_zero():
    rng = np.random.default_rng(5)
    u = rng.normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    a12, a23 = np.deg2rad(70.0), np.deg2rad(40.0)
    _, g, ok = (np.asarray(x) for x in objective.pointwise(jnp.asarray(u), jnp.asarray([a12]),
                                                            jnp.asarray([a23])))  # fmt: skip
    phi = np.arccos(u[:, 2])
    lo, hi = (float(x) for x in m.reach_band(a12, a23))
    assert (lo, hi) == pytest.approx((np.deg2rad(30), np.deg2rad(110)), abs=1e-15)
    np.testing.assert_array_equal(ok[0], (phi >= lo) & (phi <= hi))
    assert np.all(g[0][~ok[0]] == 0.0) and np.all(g[0][ok[0]] > 0)
    # the reached directions' 1/k against numpy's SVD at the numpy IK-free Jacobian of the
    # branch's angles: and the closed form of 1/k as a function of φ alone
    np.testing.assert_allclose(g[0][ok[0]], np.asarray(m.inv_cond_phi(u[ok[0], 2], a12, a23)),
                               atol=1e-12)  # fmt: skip


def test_inv_cond_against_numpy_svd_closed_form_and_both_branches_agree():
    rng = np.random.default_rng(11)
    a12 = np.deg2rad(rng.uniform(20, 160, 40))
    a23 = np.deg2rad(rng.uniform(20, 160, 40))
    u = cap_directions(500, np.deg2rad(45), np.deg2rad(80), rng)
    per, g, ok = (np.asarray(x) for x in objective.pointwise(jnp.asarray(u), jnp.asarray(a12),
                                                              jnp.asarray(a23)))  # fmt: skip
    th1, th2, _ = (np.asarray(x) for x in m.ik(jnp.asarray(u)[None], a12[:, None], a23[:, None]))
    ref = np_inv_cond(np_jacobian(th1, th2, a12[:, None, None], a23[:, None, None]))
    sel = ok[..., None] & np.ones((1, 1, 2), bool)
    np.testing.assert_allclose(per[sel], ref[sel], atol=1e-12)
    # the two branches are mirror images: the same 1/k
    np.testing.assert_allclose(per[ok][:, 0], per[ok][:, 1], atol=1e-12)
    closed = np.asarray(m.inv_cond_phi(u[None, :, 2], a12[:, None], a23[:, None]))
    np.testing.assert_allclose(g[ok], closed[ok], atol=1e-12)
    assert ok.any() and (~ok).any()


def test_right_angles_give_sin_phi_everywhere():
    """At (90°, 90°) the columns are orthogonal with norms sin φ and 1: 1/k = sin φ."""
    rng = np.random.default_rng(2)
    u = rng.normal(size=(20000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = np.deg2rad(90.0)
    _, g, ok = (np.asarray(x) for x in objective.pointwise(jnp.asarray(u), jnp.asarray([r]),
                                                            jnp.asarray([r])))  # fmt: skip
    assert ok.all()
    np.testing.assert_allclose(g[0], closedform.inv_cond_right_angles(np.arccos(u[:, 2])),
                               atol=1e-12)  # fmt: skip
    th1, th2, _ = m.ik(jnp.asarray(u), r, r)
    J = np.asarray(m.jacobian(th1[:, 0], th2[:, 0], r, r))
    np.testing.assert_allclose(np.einsum("ni,ni->n", J[..., 0], J[..., 1]), 0.0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(J[..., 1], axis=-1), 1.0, atol=1e-14)


def test_singular_directions_give_zero_not_nan_with_finite_gradients():
    r = jnp.asarray(np.deg2rad(90.0))
    axis = jnp.asarray([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])  # along joint axis 1: singular
    _, g, ok = objective.pointwise(axis, jnp.asarray([r]), jnp.asarray([r]))
    assert np.all(np.asarray(ok)) and np.all(np.asarray(g) == 0.0)
    # α12 = α23: axis 1 itself is reached at θ2 = 0 (singular), edge of the band
    a = jnp.asarray([np.deg2rad(50.0)])
    _, g, ok = objective.pointwise(axis[:1], a, a)
    assert bool(ok[0, 0]) and float(g[0, 0]) == 0.0

    def mean(a12, a23, u):
        return objective.pointwise(u, a12, a23)[1].mean()

    grad = jax.jit(jax.grad(mean, argnums=(0, 1)))
    for uu in (axis, jnp.asarray(cap_directions(256, np.deg2rad(30), np.deg2rad(90), RNG))):
        for a in ((90.0, 90.0), (50.0, 50.0), (60.0, 30.0), (120.0, 100.0)):
            x = jnp.asarray(np.deg2rad(a))
            gr = grad(x[:1], x[1:], uu)
            assert all(np.all(np.isfinite(np.asarray(v))) for v in gr), a


# ------------------------------------------------------------------- the index and closed form


def test_closed_forms_agree_with_each_other_and_scipy():
    from scipy import integrate

    b = np.deg2rad(30.0)
    series = closedform.mean_perpendicular_cone(b)
    assert series == pytest.approx(closedform.mean_right_angles_quad(b, np.pi / 2), abs=1e-13)
    v, _ = integrate.dblquad(lambda psi, t: np.sqrt(1 - (np.sin(t) * np.cos(psi)) ** 2) * np.sin(t),
                             0, b, 0, 2 * np.pi, epsabs=1e-13, epsrel=1e-13)  # fmt: skip
    assert series == pytest.approx(v / (2 * np.pi * (1 - np.cos(b))), abs=1e-12)
    assert closedform.mean_axis_cone(b) == pytest.approx(
        closedform.mean_right_angles_quad(b, 0.0), abs=1e-13)  # fmt: skip
    # any γ: the quadrature against a plain numpy Monte Carlo of sin φ on the cap
    rng = np.random.default_rng(0)
    for g in (20.0, 60.0, 135.0):
        u = cap_directions(200_000, b, np.deg2rad(g), rng)
        s = np.sqrt(1 - u[:, 2] ** 2)
        q = closedform.mean_right_angles_quad(b, np.deg2rad(g))
        assert abs(s.mean() - q) < 4 * s.std() / np.sqrt(len(s)), g
    assert series == pytest.approx(0.9669002207464, abs=1e-12)  # β = 30°, γ = 90°


def _index(over: dict, seed: int, designs) -> dict:
    st = get("sphere_rcm")
    raw = {"name": "sphere_rcm"} | over
    s = st.settings.model_validate(raw)
    P = st.problem(s, streams(seed), jnp.float64)
    f, aux = jax.jit(P.fn)(P.params, jnp.asarray(designs, jnp.float64), None)
    return {"f": np.asarray(f)} | {k: np.asarray(v) for k, v in aux.items()}


@pytest.mark.parametrize("gamma", [90.0, 0.0, 60.0])
def test_index_at_right_angles_matches_its_closed_form(gamma):
    """The Monte-Carlo index (IK → Jacobian → 1/k) at (90°, 90°) against the closed form
    of the cone's placement, within 4 SE, on independent sample streams."""
    ref = closedform.mean_right_angles(np.deg2rad(30.0), np.deg2rad(gamma))
    z = []
    for seed in range(3):
        r = _index({"cone": {"axis_angle_deg": gamma},
                    "index": {"n_samples": 16384, "sampler": "rqmc", "replicates": 16}},
                   seed, [[90.0, 90.0]])  # fmt: skip
        assert r["reach"][0] == 1.0 and r["gci_reached"][0] == r["gci"][0]
        z.append((r["gci"][0] - ref) / r["gci_se"][0])
        assert r["f"][0] == -r["gci"][0] and r["f_se"][0] == r["gci_se"][0]
    assert np.all(np.abs(z) < 4), z
    assert 0 < r["gci_se"][0] < 3e-4  # precise enough to tell a 1e-3 bias


def test_reach_and_hybrid_terms_against_numpy():
    """reach: the share of the cap in the band, against a numpy Monte Carlo; arc_length and
    the weighted f; the exact band constraint against the reach of the wider cone."""
    rng = np.random.default_rng(9)
    des = np.array([[51.0, 54.0], [75.0, 52.0], [40.0, 100.0], [120.0, 130.0]])
    r = _index({"index": {"n_samples": 65536, "sampler": "uniform"},
                "objective": {"gci": -1.0, "reach": 0.25, "arc_length": 0.5}}, 1, des)  # fmt: skip
    u = cap_directions(400_000, np.deg2rad(30), np.deg2rad(90), rng)
    phi = np.arccos(u[:, 2])
    for i, (a, b) in enumerate(np.deg2rad(des)):
        lo, hi = abs(a - b), min(a + b, 2 * np.pi - a - b)
        share = np.mean((phi >= lo) & (phi <= hi))
        se = np.hypot(r["reach_se"][i], np.sqrt(share * (1 - share) / len(phi)))
        assert abs(r["reach"][i] - share) <= 4 * se + 1e-12, (des[i], r["reach"][i], share)
        assert r["arc_length"][i] == pytest.approx(a + b, abs=1e-14)
    f = -r["gci"] + 0.25 * r["reach"] + 0.5 * r["arc_length"]
    np.testing.assert_allclose(r["f"], f, atol=1e-12)
    # (51°, 54°) reaches only 81 % of the 60° cone perpendicular to axis 1
    assert r["reach"][0] == pytest.approx(0.8064, abs=0.01)
    # the band constraint: feasible exactly when every direction of the wider cone is reached
    st = get("sphere_rcm")
    for ext, gam in ((30.0, 75.0), (45.0, 60.0)):
        s = st.settings.model_validate({"name": "sphere_rcm", "cone": {"axis_angle_deg": gam},
                                        "constraints": {"reach_all_deg": ext}})  # fmt: skip
        P = st.problem(s, streams(0), jnp.float64)
        X = rng.uniform(30, 150, (300, 2))
        a12, a23 = objective.design_columns(s, P.params, jnp.asarray(X))
        g = np.asarray(objective.band_margins(P.params, a12, a23))
        v = cap_directions(20000, np.deg2rad(ext), np.deg2rad(gam), rng)
        ph = np.arccos(v[:, 2])
        lo, hi = (np.asarray(t) for t in m.reach_band(a12, a23))
        full = np.all((ph[None] >= lo[:, None]) & (ph[None] <= hi[:, None]), 1)
        feas = np.all(g <= 0, 1)
        # the sampled cone misses only a sliver at its edge: agreement but for the designs
        # within 0.05° of the boundary
        near = np.abs(g).min(1) * 180 < 0.05
        np.testing.assert_array_equal(feas[~near], full[~near])


def test_optimizer_ends_at_the_kinematic_optimum():
    """PTPSO, 12 particles × 25 iterations × 2 runs on 2048 directions: the final design
    lies within 1° of the paper's (90°, 90°) in both link angles."""
    cfg = designopt.load_config(ROOT / "configs" / "sphere_rcm.yaml", {
        "study.index.n_samples": 2048, "optimizer.n_particles": 12, "optimizer.n_iters": 25,
        "optimizer.n_runs": 2})  # fmt: skip
    rec = designopt.run(cfg)
    x = np.array([rec.x["alpha12"], rec.x["alpha23"]])
    assert np.all(np.abs(x - np.array(paper.KINEMATIC_OPTIMUM)) < 1.0), x
    ref = closedform.mean_perpendicular_cone(np.deg2rad(30.0))
    gci, se = rec.indices["gci"]
    assert abs(gci - ref) < 4 * se + 1e-4, (gci, se, ref)


# ------------------------------------------------------------------------------- bad input


def _raw(**study) -> dict:
    return {"study": {"name": "sphere_rcm"} | study,
            "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 2}, "precision": "float64"}  # fmt: skip


@pytest.mark.parametrize("study,key,words", [
    ({"variables": {"alpha12": [0, 90], "alpha23": [30, 150]}}, "study.variables",
     "strictly between 0 and 180"),
    ({"variables": {"alpha12": [30, 180]}}, "study.variables", "strictly between 0 and 180"),
    ({"variables": {"alpha12": [90, 30]}}, "study.variables", "not below"),
    ({"variables": {"alpha13": [30, 90]}}, "study.variables", "unknown design variable"),
    ({"fixed": {"alpha12": 200}}, "study.fixed", "strictly between 0 and 180"),
    ({"fixed": {"alpha12": 75}}, "study.fixed", "either variable or fixed"),
    ({"cone": {"half_angle_deg": 0}}, "study.cone.half_angle_deg", ""),
    ({"cone": {"half_angle_deg": 120}}, "study.cone.half_angle_deg", ""),
    ({"cone": {"axis_angle_deg": -5}}, "study.cone.axis_angle_deg", ""),
    ({"cone": {"apex": 30}}, "study.cone.apex", ""),
    ({"index": {"n_samples": 1}}, "study.index.n_samples", ""),
    ({"index": {"sampler": "rqmc", "replicates": 1}}, "study.index.replicates", "at least 2"),
    ({"objective": {"gcii": -1}}, "study.objective", "unknown index"),
    ({"objective": {"gci": 0}}, "study.objective", "non-zero weight"),
    ({"constraints": {"reach_min": 1.5}}, "study.constraints.reach_min", ""),
    ({"cone": {"axis_angle_deg": 45}, "constraints": {"reach_all_deg": 60}},
     "study.constraints.reach_all_deg", "contains that axis"),
])  # fmt: skip
def test_bad_input_is_one_line_naming_the_key(study, key, words):
    with pytest.raises(ConfigError) as e:
        validate(_raw(**study), "bad.yaml")
    msg = str(e.value)
    assert f"key '{key}" in msg and "\n" not in msg and words in msg, msg


# ------------------------------------------------------------------------- the Raven II arm

RAVEN = ROOT / "configs" / "raven2.yaml"
# The control code's numbers (github.com/uw-biorobotics/raven2 at d2307c5), restated here
# to check the config's transcription: r2_kinematics.h (La12, La23, d4, Lw), the right
# arm's rows of r2_kinematics.cpp (alphas, aas, ds, robot_thetas) and its joint → DH
# offsets (TH1_J0_R … TH6A_J5_R), in the code's own (Craig) convention below.
CODE = {"La12": 75.0, "La23": 52.0, "d4": -0.47, "Lw": 0.013,
        "offsets": (25.0, 0.0, 0.0, 0.0, -90.0, 0.0)}  # fmt: skip


def code_fk(q: np.ndarray, la12: float, la23: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """The control code's FK of the right arm (getFKTransform: rotation rows
    [cθ, −sθ, 0], [sθ cα, cθ cα, −sα], [sθ sα, cθ sα, cα], origin (a, −sα d, cα d)),
    from the joints q = (J0, J1, ins, J3, J4, J5) (rad, m): T06 and every frame."""
    d2r = np.pi / 180
    alpha = [np.pi, la12 * d2r, la23 * d2r, 0.0, np.pi / 2, np.pi / 2]
    a = [0.0, 0.0, 0.0, 0.0, 0.0, CODE["Lw"]]
    off = np.array(CODE["offsets"]) * d2r
    theta = [q[0] + off[0], q[1] + off[1], -np.pi / 2, q[3] + off[3], q[4] + off[4], q[5] + off[5]]
    d = [0.0, 0.0, q[2], CODE["d4"], 0.0, 0.0]
    T = np.eye(4)
    frames = []
    for i in range(6):
        ct, st, ca, sa = np.cos(theta[i]), np.sin(theta[i]), np.cos(alpha[i]), np.sin(alpha[i])
        A = np.array([[ct, -st, 0, a[i]], [st * ca, ct * ca, -sa, -sa * d[i]],
                      [st * sa, ct * sa, ca, ca * d[i]], [0, 0, 0, 1.0]])  # fmt: skip
        T = T @ A
        frames.append(T.copy())
    return T, frames


def _raven(n_joints: int = 6) -> SerialSettings:
    raw = yaml.safe_load(RAVEN.read_text())["study"]
    raw["chain"]["joints"] = raw["chain"]["joints"][:n_joints]
    return SerialSettings.model_validate(raw)


def _fk(s: SerialSettings, design: dict, q: np.ndarray):
    mech = build(s)
    full = np.concatenate([[design[k] for k in s.variables], mech.fixed]) * mech.scale
    R, p = mech.model.fk(full, q)
    J = mech.model.jacobian(full, q)
    return np.asarray(R), np.asarray(p), np.asarray(J), mech


def _joints(mech, n: int, rng) -> np.ndarray:
    lo, hi = np.asarray(mech.lower), np.asarray(mech.upper)
    return lo + (hi - lo) * rng.random((n, len(lo)))


def test_raven_config_is_the_control_codes_chain():
    """The serial study's modified DH is the code's Craig convention (row i: α_{i−1},
    a_{i−1}, θ_i, d_i): no conversion; the config's FK equals the code's at random joints
    within the limits, at the as-built angles and at another design."""
    rng = np.random.default_rng(4)
    s = _raven()
    for la12, la23 in ((75.0, 52.0), (60.0, 95.0)):
        mech = build(s)
        q = _joints(mech, 200, rng)
        R, p, _, _ = _fk(s, {"La12": la12, "La23": la23}, q)
        for i in range(len(q)):
            T, _ = code_fk(q[i], la12, la23)
            np.testing.assert_allclose(R[i], T[:3, :3], atol=1e-13)
            np.testing.assert_allclose(p[i], T[:3, 3], atol=1e-13)
    lim = np.array([j.limits for j in s.chain.joints])
    np.testing.assert_array_equal(lim, [[0, 90], [45, 135], [0.23, 0.56], [-182, 182], [-75, 75],
                                        [-89, 89]])  # fmt: skip


def test_raven_keeps_its_tool_axis_through_the_rcm():
    """For random shoulder, elbow and insertion (and roll), frames 3 and 4 lie on one line
    through the origin along their common z axis (the insertion axis): the RCM; the jaw
    frame stays within the wrist length of that line."""
    rng = np.random.default_rng(8)
    des = {"La12": 75.0, "La23": 52.0}
    s3, s4, s6 = _raven(3), _raven(4), _raven(6)
    q = _joints(build(s6), 500, rng)
    R3, p3, _, _ = _fk(s3, des, q[:, :3])
    R4, p4, _, _ = _fk(s4, des, q[:, :4])
    _, p6, _, _ = _fk(s6, des, q)
    z3, z4 = R3[..., 2], R4[..., 2]
    np.testing.assert_allclose(z3, z4, atol=1e-14)  # roll turns about the insertion axis
    assert np.abs(np.cross(p3, z3)).max() < 1e-14  # the insertion axis through the origin
    assert np.abs(np.cross(p4, z4)).max() < 1e-14
    # the wrist point's signed depth along the axis is insertion + d4
    np.testing.assert_allclose(np.einsum("ni,ni->n", p4, z4), q[:, 2] + CODE["d4"], atol=1e-14)
    off = p6 - np.einsum("ni,ni->n", p6, z4)[:, None] * z4
    assert np.linalg.norm(off, axis=1).max() <= CODE["Lw"] + 1e-14
    # the same for the code's own frames
    for i in range(20):
        _, fr = code_fk(q[i], 75.0, 52.0)
        for F in fr[2:4]:
            assert np.linalg.norm(np.cross(F[:3, 3], F[:3, 2])) < 1e-14


@pytest.mark.parametrize("design", [(75.0, 52.0), (60.0, 95.0)])
def test_raven_link_angles_are_the_angles_between_joint_axes(design):
    """From the geometric Jacobian of the configured chain: the revolute columns' ω are the
    joint axes z1, z2, the prismatic column's v is z3: ∠(z1, z2) = La12, ∠(z2, z3) = La23."""
    rng = np.random.default_rng(6)
    s = _raven()
    q = _joints(build(s), 300, rng)
    _, _, J, _ = _fk(s, {"La12": design[0], "La23": design[1]}, q)
    z1, z2, z3 = J[:, 3:, 0], J[:, 3:, 1], J[:, :3, 2]
    assert np.abs(J[:, 3:, 2]).max() == 0.0  # insertion: no angular velocity
    ang = lambda a, b: np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", a, b), -1, 1)))  # noqa: E731
    np.testing.assert_allclose(ang(z1, z2), design[0], atol=1e-9)
    np.testing.assert_allclose(ang(z2, z3), design[1], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(z3, axis=1), 1.0, atol=1e-14)


def test_raven_design_question_prefers_right_angles_to_the_as_built():
    """configs/raven2.yaml: the instrument's angular-velocity isotropy over the joint box,
    the as-built (75°, 52°) against (90°, 90°) (the run's optimum, docs/sphere.md)."""
    cfg = designopt.load_config(RAVEN, {"study.indices.n_samples": 2048})
    r = designopt.evaluate(cfg, {"La12": np.array([75.0, 90.0]), "La23": np.array([52.0, 90.0])})
    g, se = r["gci"], r["gci_se"]
    assert g[1] - g[0] > 10 * np.hypot(*se), (g, se)
    # with the wrist at zero its three axes are orthonormal, so 1/k there is the closed form
    # sqrt(1 / (2 + |cos La12|)) for any elbow angle and insertion (docs/sphere.md)
    s = _raven()
    mech = build(s)
    rng = np.random.default_rng(1)
    q = _joints(mech, 100, rng)
    q[:, 3:] = 0.0
    for la12 in (75.0, 90.0, 50.0):
        _, _, J, _ = _fk(s, {"La12": la12, "La23": 52.0}, q)
        sv = np.linalg.svd(J[:, 3:, :], compute_uv=False)
        np.testing.assert_allclose(sv[:, -1] / sv[:, 0],
                                   np.sqrt(1 / (2 + abs(np.cos(np.deg2rad(la12))))), atol=1e-12)  # fmt: skip


def test_gci_reached_is_na_over_a_handful_of_reached_directions(capsys):
    """A ratio over the reached directions is not reported on fewer than 30 of them: the
    (30°, 30.5°) design reaches 2 of 4,096 directions of the default cone."""
    import json

    from designopt.cli.commands import main

    capsys.readouterr()
    assert main(["eval", "configs/sphere_rcm.yaml", "--design", "alpha12=30",
                 "alpha23=30.5", "--json"]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["gci_reached"] is None and out["gci_reached_se"] is None
    assert out["gci_reached_n"] == 2 and out["gci_reached_of"] == 4096
    assert out["reach"] == 2 / 4096
