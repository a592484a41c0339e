"""Study B: the da Vinci patient-side arm (Applied Sciences 2019): chain, RCM property,
the paper's Table 2, the production IK, the closed form, the design study's indices."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from kinref import ETChain

from designopt.studies.davinci import ik, paper
from designopt.studies.davinci import mechanism as m

X = jnp.asarray(m.table1())
RNG = np.random.default_rng(7)


def random_q(n, rng=RNG, margin=0.0):
    lo, hi = m.LOWER.copy(), m.UPPER.copy()
    lo[[0, 1, 3, 4, 5]] += margin
    hi[[0, 1, 3, 4, 5]] -= margin
    return rng.uniform(lo, hi, (n, 6))


@pytest.fixture(scope="module")
def db():
    return _DB


_SOLVE = jax.jit(lambda T, d: ik.solve(X, d, T))
_DB = jax.jit(ik.build_database)(X)
_SOLVE_PREV = jax.jit(lambda T, d, q: ik.solve(X, d, T, q_prev=q))


@pytest.fixture(scope="module")
def solve64():
    """One compiled cold solver: batches of up to 64 poses (padded)."""

    def run(T, d):
        T = np.asarray(T)
        n = len(T)
        r = _SOLVE(jnp.asarray(np.concatenate([T, np.broadcast_to(T[-1:], (64 - n, 4, 4))])), d)
        return jax.tree.map(lambda a: a[:n], r)

    return run


# ------------------------------------------------------------------------ chain


def test_rcm_point_is_fixed_and_where_we_read_it():
    q = random_q(500)
    _, p2 = m.frame_model(2).fk(X, jnp.asarray(q))
    H = np.asarray(m.rcm_point(X))
    assert np.abs(np.asarray(p2) - H).max() <= 1e-12
    # our reading of Table 1 puts H at (0, 268.243, -736.992) mm
    np.testing.assert_allclose(H, [0.0, 268.243, -736.992], atol=6e-4)
    # and H moves neither with q1, q2, q3 nor with anything after them
    q2 = q.copy()
    q2[:, :3] = random_q(500)[:, :3]
    _, p2b = m.frame_model(2).fk(X, jnp.asarray(q2))
    assert np.abs(np.asarray(p2b) - np.asarray(p2)).max() <= 1e-12


def test_shaft_passes_through_h_and_wrist_frames_share_the_shaft_tip():
    q = random_q(300)
    R2, p2 = (np.asarray(a) for a in m.frame_model(2).fk(X, jnp.asarray(q)))
    _, p3 = m.frame_model(3).fk(X, jnp.asarray(q))
    # I = H + q3 · (y axis of frame 2): the shaft line passes through H
    np.testing.assert_allclose(np.asarray(p3), p2 + q[:, 2:3] * R2[:, :, 1], atol=1e-12)
    for k in (4, 5):
        _, pk = m.frame_model(k).fk(X, jnp.asarray(q))
        np.testing.assert_allclose(np.asarray(pk), np.asarray(p3), atol=1e-12)
    # the jaw point J sits l_IJ from I
    _, p6 = m.ARM.fk(X, jnp.asarray(q))
    np.testing.assert_allclose(np.linalg.norm(np.asarray(p6) - np.asarray(p3), axis=-1), 10.0,
                               rtol=1e-13)  # fmt: skip


def test_kernel_fk_equals_the_elementary_transform_product_and_jacobian_autodiff():
    q = jnp.asarray(random_q(20))
    ref = ETChain(m.ELEMENTS).fk(dict(zip(m.DESIGN_KEYS, X, strict=True)), q)
    np.testing.assert_allclose(np.asarray(m.pose(X, q)), np.asarray(ref), atol=1e-12)
    J = np.asarray(m.ARM.jacobian(X, q))

    def tip(qi):
        T = ETChain(m.ELEMENTS).fk(dict(zip(m.DESIGN_KEYS, X, strict=True)), qi)
        return T[:3, 3], T[:3, :3]

    for i in (0, 7, 13):
        dp, dR = jax.jacfwd(tip)(q[i])
        R = tip(q[i])[1]
        W = np.einsum("ijk,lj->ilk", np.asarray(dR), np.asarray(R))  # dR Rᵀ: skew(ω) per joint
        w = np.stack([W[2, 1], W[0, 2], W[1, 0]])
        np.testing.assert_allclose(J[i, :3], np.asarray(dp), atol=1e-10)
        np.testing.assert_allclose(J[i, 3:], w, atol=1e-12)


# --------------------------------------------------------------------- Table 2


def test_paper_method_reproduces_table2():
    T = m.pose(X, jnp.asarray(paper.to_rad(paper.TABLE2_DEG)))
    r = jax.jit(jax.vmap(lambda t: paper.solve(X, t)))(T)
    out = paper.to_deg(np.asarray(r.q))
    assert np.all(np.asarray(r.success))
    assert np.abs(out - paper.TABLE2_DEG).max() <= 1e-9  # deg and mm
    assert np.all(np.asarray(r.pos_err) <= 1e-9) and np.all(np.asarray(r.rot_err) <= 1e-9)
    assert np.all(np.asarray(r.step_deg) >= paper.TABLE2_STEP_DEG)  # no finer step needed
    # within the joint ranges each Table 2 pose has exactly one solution
    assert np.all(np.asarray(r.n_solutions) == 1)


def test_production_solver_and_closed_form_reproduce_table2(db, solve64):
    q_in = paper.to_rad(paper.TABLE2_DEG)
    T = m.pose(X, jnp.asarray(q_in))
    r = solve64(T, db)
    assert np.all(np.asarray(r.success))
    assert np.abs(paper.to_deg(np.asarray(r.q)) - paper.TABLE2_DEG).max() <= 1e-9
    qc, ok = ik.closed_form(X, T)
    assert np.all(np.asarray(ok))
    assert np.abs(paper.to_deg(np.asarray(qc)) - paper.TABLE2_DEG).max() <= 1e-9


def test_reduced_equation_vanishes_only_at_the_solution():
    q = paper.to_rad(paper.TABLE2_DEG[0])
    T = m.pose(X, jnp.asarray(q))
    F = [float(paper.reduced(X, T, jnp.asarray(q[0]), b).F) for b in (0, 1)]
    assert min(abs(f) for f in F) < 1e-9
    assert abs(float(paper.reduced(X, T, jnp.asarray(q[0] + 0.05), 0).F)) > 1e-3


# ------------------------------------------------------------- production IK


def test_cold_solves_round_trip_to_1e9(db, solve64):
    q = random_q(64)
    T = m.pose(X, jnp.asarray(q))
    r = solve64(T, db)
    ok = np.asarray(r.success)
    assert ok.mean() >= 0.98  # random joint sets include near-singular ones
    R, p = m.ARM.fk(X, r.q)
    pe, re = ik.pose_errors(R, p, T)
    assert np.all(np.asarray(pe)[ok] <= 1e-9) and np.all(np.asarray(re)[ok] <= 1e-9)
    # one solution within limits: the output is the input joint set
    assert np.abs(np.asarray(r.q)[ok] - q[ok]).max() <= 1e-6
    assert np.all(np.asarray(r.q) >= m.LOWER - 1e-12) and np.all(np.asarray(r.q) <= m.UPPER + 1e-12)


def _joint(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@settings(max_examples=40, deadline=None)
@given(st.tuples(_joint(-math.pi / 2, math.pi / 2), _joint(-3 * math.pi / 4, 0.0), _joint(1.0, 315.0),
                 _joint(-math.pi, math.pi), _joint(-1.48, 1.48), _joint(-math.pi / 2, math.pi / 2)))  # fmt: skip
def test_fk_ik_round_trip_property(q):
    """FK∘IK over joint sets within the limits (|q5| ≤ 85°, q3 ≥ 1 mm: away from the wrist
    and RCM singularities, where poses stay solvable but joints are ill-conditioned)."""
    q = np.asarray(q)[None]
    T = m.pose(X, jnp.asarray(q))
    r = _SOLVE(jnp.broadcast_to(T, (64, 4, 4)), _DB)
    assert bool(r.success[0])
    assert float(r.pos_err[0]) <= 1e-9 and float(r.rot_err[0]) <= 1e-9
    R, p = m.ARM.fk(X, r.q[0])
    pe, re = ik.pose_errors(R, p, T[0])
    assert float(pe) <= 1e-9 and float(re) <= 1e-9
    dq = np.asarray(r.q[0]) - q[0]
    dq[3] = math.remainder(dq[3], 2 * math.pi)  # q4 = ±180° is one configuration
    assert np.abs(dq).max() <= 1e-6


def test_unreachable_poses_report_failure_never_a_wrong_success(db, solve64):
    rng = np.random.default_rng(3)
    H = np.asarray(m.rcm_point(X))
    # random rotations at random points around H: many unreachable
    A = rng.normal(size=(64, 3, 3))
    Q, Rr = np.linalg.qr(A)
    Q = Q * np.sign(np.diagonal(Rr, axis1=1, axis2=2))[:, None, :]
    Q[np.linalg.det(Q) < 0, :, 0] *= -1
    T = np.zeros((64, 4, 4))
    T[:, :3, :3], T[:, 3, 3] = Q, 1.0
    T[:, :3, 3] = H + rng.uniform(-400, 400, (64, 3))
    T[:4, :3, 3] = H + [
        [0, 0, 2000],
        [0, -400, 0],
        [500, 500, 500],
        [0, 0, 0.0],
    ]  # far / beyond 315 mm
    r = solve64(jnp.asarray(T), db)
    _, reach = ik.closed_form(X, jnp.asarray(T))
    ok, reach = np.asarray(r.success), np.asarray(reach)
    assert not ok[:3].any()
    assert not (ok & ~reach).any()  # never a success the geometry says is impossible
    assert (~ok).sum() >= 20  # the test covers failures
    R, p = m.ARM.fk(X, r.q)
    pe, re = ik.pose_errors(R, p, jnp.asarray(T))
    assert np.all(np.asarray(pe)[ok] <= 1e-9) and np.all(np.asarray(re)[ok] <= 1e-9)
    assert np.all(np.asarray(pe)[~ok] > 1e-9) or np.all(np.isfinite(np.asarray(r.q)))


def test_nan_pose_is_a_failure_in_the_jitted_solver(db, solve64):
    T = np.array(m.pose(X, jnp.asarray(random_q(3))))
    T[1, 2, 3] = np.nan
    T[2, 0, 0] = np.inf
    r = solve64(T, db)
    assert np.asarray(r.success).tolist() == [True, False, False]


@pytest.mark.slow
def test_previous_configuration_picks_the_branch_and_closed_form_shows_one_in_limits(db):
    q = random_q(64, np.random.default_rng(5), margin=0.1)
    T = m.pose(X, jnp.asarray(q))
    r = _SOLVE_PREV(T, db, jnp.asarray(q + 0.05))
    assert np.all(np.asarray(r.success))
    np.testing.assert_allclose(np.asarray(r.q), q, atol=1e-7)
    # the other wrist branch (jaw offset mirrored) needs |q5| > 90°: outside the range
    qc, ok = ik.closed_form(X, T)
    assert np.all(np.asarray(ok))
    np.testing.assert_allclose(np.asarray(qc), q, atol=1e-7)


@pytest.mark.slow
def test_trajectory_mode_equals_cold_solving(db, solve64):
    S, P = 96, 4
    t = np.arange(S) / 1000.0  # 1 kHz
    base = random_q(P, np.random.default_rng(11), margin=0.3)
    amp = np.array([0.2, 0.2, 20.0, 0.5, 0.4, 0.4])
    q = base[None] + amp * np.sin(2 * np.pi * 3.0 * t[:, None, None] + np.arange(6))  # (S, P, 6)
    q[..., 2] = np.clip(q[..., 2], 1.0, 314.0)
    q[..., 3] = np.remainder(q[..., 3] + np.pi, 2 * np.pi) - np.pi
    T = m.pose(X, jnp.asarray(q.reshape(-1, 6))).reshape(S, P, 4, 4)
    tr = jax.jit(lambda T: ik.solve_trajectory(X, db, T))(T)
    flat = np.asarray(T).reshape(-1, 64, 4, 4)
    cold = [solve64(flat[i], db) for i in range(len(flat))]
    cq = np.concatenate([np.asarray(c.q) for c in cold])
    assert np.all(np.asarray(tr.success)) and all(np.all(np.asarray(c.success)) for c in cold)
    np.testing.assert_allclose(np.asarray(tr.q).reshape(-1, 6), cq, atol=1e-8)
    np.testing.assert_allclose(np.asarray(tr.q), q, atol=1e-7)
    assert np.median(np.asarray(tr.iterations)[1:]) <= 3  # warm starts converge at once


def test_check_poses_names_bad_rows():
    T = np.array(m.pose(X, jnp.asarray(random_q(5))))
    T[1, 0, 0] = np.nan
    T[3, :3, :3] *= 1 + 1e-5
    bad = ik.check_poses(T, 1e-6)
    assert [i for i, _ in bad] == [1, 3]
    assert "NaN" in bad[0][1] and "orthonormal" in bad[1][1]


# ---------------------------------------------------------------- design study


def test_gci_depends_on_l_ij_not_on_beta_and_coverage_on_beta():
    from designopt.app.config import validate
    from designopt.app.pipeline import evaluate

    raw = {"study": {"name": "davinci", "workspace": {"cone_deg": 60, "depth_mm": [20, 250]},
                     "indices": {"n_samples": 512, "n_ik": 64, "solver": "closed_form"}},
           "precision": "float64"}  # fmt: skip
    cfg = validate(raw, "test")
    r = evaluate(cfg, {"l_IJ": np.array([2.0, 2.0, 20.0, 2.0]),
                       "beta_deg": np.array([30.45, 45.0, 30.45, 33.0])})  # fmt: skip
    # the first two axes are perpendicular through H for every β: 1/k does not see β
    # where the cone is covered, only through the joint ranges (coverage)
    assert r["gci"][2] > r["gci"][0] + 3 * r["gci_se"][0]  # same samples for both
    assert r["coverage"][0] == 1.0 and r["coverage"][1] < 1.0 and r["coverage"][3] == 1.0
    assert abs(r["gci"][3] - r["gci"][0]) <= 1e-10
    assert np.all(r["reach"] <= 1.0) and np.all(r["gci"] > 0)
    assert math.isfinite(float(r["f"][0]))
