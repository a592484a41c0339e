"""Study A kinematics (seed 000 §III) against the paper's closed forms and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.kinematics import cond
from designopt.studies.master9 import mechanism as m

KEY = jax.random.key(0)


def random_designs(key, n):
    lo = np.array([250, 250, 50, 0, 20, 10, 20, 40.0])
    hi = np.array([350, 350, 150, 40, 100, 60, 80, 120.0])
    x = jax.random.uniform(key, (n, 8), jnp.float64, lo, hi)
    return {k: x[:, i] for i, k in enumerate(m.DESIGN_KEYS)}


def test_chain_fk_equals_closed_forms_eq3_eq4_random_designs():
    k1, k2 = jax.random.split(KEY)
    q = m.sample_joints(k1, 2000)
    d = random_designs(k2, 2000)  # one design per configuration
    np.testing.assert_allclose(m.fk(q, d), m.fk_closed(q, d), atol=1e-9)


def test_decoupling_R_from_wrist_P_from_position_joints():
    d = m.default_design()
    q = m.sample_joints(KEY, 500)
    q_alt = m.sample_joints(jax.random.key(1), 500)
    T = m.fk(q, d)
    T_pos_changed = m.fk(q.at[:, :3].set(q_alt[:, :3]), d)
    T_wrist_changed = m.fk(q.at[:, 3:].set(q_alt[:, 3:]), d)
    np.testing.assert_allclose(T[:, :3, :3], T_pos_changed[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(T[:, :3, 3], T_wrist_changed[:, :3, 3], atol=1e-9)


def test_printed_R23_is_a_typo():
    """eq. (3) prints R23 = -c6 s8 - c7 c9; the chain says -c6 s8 - c7 c8 s6."""
    q = np.array([0.1, 0.2, 0.3, 0.7, 0.4, -0.3, 1.1])
    T = np.asarray(m.fk(q, m.default_design()))
    c6, s6, c7, c8, s8, c9 = (
        np.cos(0.7),
        np.sin(0.7),
        np.cos(0.4),
        np.cos(-0.3),
        np.sin(-0.3),
        np.cos(1.1),
    )
    assert abs(T[1, 2] - (-c6 * s8 - c7 * c9)) > 0.1
    assert abs(T[1, 2] - (-c6 * s8 - c7 * c8 * s6)) < 1e-12


def test_jacobian_linear_block_matches_finite_differences():
    d = m.default_design()
    q = m.sample_joints(KEY, 50)
    J = np.asarray(m.jacobian(q, d))
    h = 1e-6
    for j in range(7):
        e = np.zeros(7)
        e[j] = h
        fd = (np.asarray(m.fk(q + e, d))[:, :3, 3] - np.asarray(m.fk(q - e, d))[:, :3, 3]) / (2 * h)
        np.testing.assert_allclose(J[:, :3, j], fd, atol=1e-5)


def test_jacobian_angular_block_matches_finite_differences_of_R():
    d = m.default_design()
    q = np.asarray(m.sample_joints(KEY, 20))
    J = np.asarray(m.jacobian(q, d))
    h = 1e-6
    for j in range(7):
        e = np.zeros(7)
        e[j] = h
        dR = (np.asarray(m.fk(q + e, d))[:, :3, :3] - np.asarray(m.fk(q - e, d))[:, :3, :3]) / (
            2 * h
        )
        W = dR @ np.swapaxes(np.asarray(m.fk(q, d))[:, :3, :3], 1, 2)
        w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], -1)
        np.testing.assert_allclose(J[:, 3:, j], w, atol=1e-7)


def test_jacobian_equals_eq33_eq34_with_typos_fixed():
    k1, k2 = jax.random.split(jax.random.key(5))
    q = m.sample_joints(k1, 1000)
    d = random_designs(k2, 1000)
    np.testing.assert_allclose(m.jacobian(q, d), m.jacobian_closed(q, d), atol=1e-9)
    J = np.asarray(m.jacobian(q, d))
    assert np.abs(J[:, :3, 3:]).max() == 0 and np.abs(J[:, 3:, :3]).max() < 1e-12  # eq. (32)


def test_jacobian_linear_block_independent_of_a5_d2_d5_d6():
    q = m.sample_joints(KEY, 200)
    d = m.default_design()
    d2 = {**d, "a5": 7.0, "d2": 99.0, "d5": -13.0, "d6": 250.0}
    np.testing.assert_allclose(
        m.jacobian(q, d)[:, :3, :3], m.jacobian(q, d2)[:, :3, :3], atol=1e-10
    )
    np.testing.assert_array_equal(
        m.jacobian_v_closed(q[:, :3], d), m.jacobian_v_closed(q[:, :3], d2)
    )


def test_eq53_frobenius_condition_number_with_a4_for_d4():
    k1, k2 = jax.random.split(jax.random.key(7))
    q = m.sample_joints(k1, 500)
    d = random_designs(k2, 500)
    k = cond(m.jacobian(q, d)[:, :3, :3])
    np.testing.assert_allclose(m.cond_fro_eq53(q[:, :3], d), k, rtol=1e-9)


def test_det_jv_closed_form():
    q = m.sample_joints(KEY, 300)
    d = m.default_design()
    np.testing.assert_allclose(
        m.det_jv(q[:, :3], d), np.linalg.det(m.jacobian_v_closed(q[:, :3], d)), rtol=1e-9
    )


def test_ik_joint_round_trip_with_q6_given():
    q = m.sample_joints(jax.random.key(3), 5000)
    d = m.default_design()
    # the position IK keeps the det J_v > 0 sheet where both elbow branches are in limits
    keep = np.asarray(m.det_jv(q[:, :3], d) > 0)
    q = q[keep]
    qi = m.ik(m.fk(q, d), d, q6=q[:, 3])
    np.testing.assert_allclose(qi, q, atol=1e-9)


def test_ik_pose_round_trip_with_redundancy_rule():
    k1, k2 = jax.random.split(jax.random.key(4))
    q = m.sample_joints(k1, 5000)
    d = random_designs(k2, 5000)
    T = m.fk(q, d)
    qi, ok = m.ik(T, d, full_output=True)
    assert bool(ok.all())
    np.testing.assert_allclose(m.fk(qi, d), T, atol=1e-8)
    lim = m.JOINT_LIMITS
    assert np.all((np.asarray(qi) >= lim[:, 0] - 1e-9) & (np.asarray(qi) <= lim[:, 1] + 1e-9))
    # the rule keeps q8 at 0 where it can (far from the q8 = ±90° wrist singularity)
    assert np.median(np.abs(np.asarray(qi)[:, 5])) < 1e-12


def test_ik_unreachable_pose_gives_nan_and_mask():
    d = m.default_design()
    T = np.asarray(m.fk(jnp.zeros(7), d)).copy()
    T[:3, 3] = [5000.0, 0.0, 0.0]
    q, ok = m.ik(T, d, full_output=True)
    assert not bool(ok) and np.all(np.isnan(np.asarray(q)))


def test_batching_single_vs_batch_vs_vmap_over_designs():
    q = m.sample_joints(KEY, 16)
    designs = random_designs(jax.random.key(9), 4)
    batch = m.jacobian(q, designs | {k: v[:, None] for k, v in designs.items()})  # (4, 16, 6, 7)
    vm = jax.vmap(lambda dd: m.jacobian(q, dd))(designs)
    np.testing.assert_allclose(batch, vm, atol=1e-12)
    d0 = {k: float(v[1]) for k, v in designs.items()}
    single = jnp.stack([m.jacobian(q[i], d0) for i in range(3)])
    np.testing.assert_allclose(single, batch[1, :3], atol=1e-12)
    np.testing.assert_allclose(m.fk(q[5], d0), m.fk(q, d0)[5], atol=1e-12)


def test_bad_input_raises_value_error_naming_the_problem():
    d = m.default_design()
    with pytest.raises(ValueError, match="a3"):
        m.fk(jnp.zeros(7), {k: v for k, v in d.items() if k != "a3"})
    with pytest.raises(ValueError, match="unknown"):
        m.fk(jnp.zeros(7), {**d, "a9": 1.0})
    with pytest.raises(ValueError, match=r"\(\.\.\., 7\)"):
        m.fk(jnp.zeros(6), d)
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        m.ik(jnp.zeros((3, 3)), d)


# --------------------------------------------------------------- IK branches and q_ref


# jitted, and the tests below share shapes: one compile per shape instead of op-by-op
_ik = jax.jit(m.ik, static_argnames="full_output")
_branches = jax.jit(m.ik_branches, static_argnames="within_limits")
_fk = jax.jit(m.fk)


def _paper(design):
    return {**m.default_design(), **design}


def _wrapped_err(a, b):
    return np.abs(np.asarray(m._wrap(jnp.asarray(a) - jnp.asarray(b))))


@pytest.mark.parametrize("name", ["PAPER_INITIAL", "PAPER_FINAL"])
def test_ik_q_ref_joint_round_trip_on_the_whole_joint_box(name):
    """ik(fk(q), q_ref=q) == q for every sample of the joint box. Without q_ref (and q6
    given), 2.8 % of the initial design's box, the det J_v < 0 part where the other elbow is
    within limits too, came back on the other elbow; with neither, q6 is never q's own."""
    d = _paper(getattr(m, name))
    q = m.sample_joints(jax.random.key(12), 20_000)
    T = _fk(q, d)
    qi, ok = _ik(T, d, q_ref=q, full_output=True)
    assert bool(ok.all())
    assert _wrapped_err(qi, q).max() < 1e-8
    np.testing.assert_allclose(_fk(qi, d), T, atol=1e-8)


@pytest.fixture(scope="module")
def initial_1000():
    """1000 configurations of the initial design, their poses and their IK branches."""
    d = _paper(m.PAPER_INITIAL)
    q = m.sample_joints(jax.random.key(13), 1000)
    T = _fk(q, d)
    qb, ok = _branches(T, d, q6=q[:, 3])
    return d, q, T, qb, np.asarray(ok)


def test_ik_branches_other_elbow_is_a_solution_and_limits_are_applied(initial_1000):
    d, q, T, qb, ok = initial_1000
    assert qb.shape == (1000, 8, 7) and ok.shape == (1000, 8)
    assert not ok[:, [1, 3, 4, 5, 6, 7]].any()  # q3 = π - asin and the flipped wrist
    assert (ok[:, 0] | ok[:, 2]).all()
    both = ok[:, 0] & ok[:, 2]
    assert 0.01 < both.mean() < 0.2  # the fold of the initial design lies inside the box
    lim = m.JOINT_LIMITS
    qbn = np.asarray(qb)
    inside = np.all((qbn >= lim[:, 0] - 1e-9) & (qbn <= lim[:, 1] + 1e-9), -1)
    np.testing.assert_array_equal(inside, ok)
    # every reachable branch solves the pose, within limits or not
    qa, reach = _branches(T, d, q6=q[:, 3], within_limits=False)
    reach = np.asarray(reach)
    assert reach[:, :4].all()  # both elbows, both wrists
    for b in range(8):
        err = np.abs(np.asarray(_fk(qa[:, b], d) - T)).max((-1, -2))
        assert err[reach[:, b]].max(initial=0.0) < 1e-8
    # the two elbows are distinct and have det J_v of opposite signs where both are valid
    det = np.asarray(m.det_jv(qb[:, [0, 2], :3], d))
    assert np.all(det[both, 0] * det[both, 1] < 0)
    assert _wrapped_err(qb[both, 0], qb[both, 2]).max(-1).min() > 1e-6


def test_q_ref_picks_the_branch_closest_to_it(initial_1000):
    d, q, T, qb, ok = initial_1000
    both = ok[:, 0] & ok[:, 2]
    qa, qo = qb[:, 0], qb[:, 2]
    for src, dst in ((qa, qo), (qo, qa)):
        step = m._wrap(dst - src)
        got = _ik(T, d, q_ref=src + 0.6 * step)
        np.testing.assert_allclose(got[both] - dst[both], 0, atol=1e-8)
        got = _ik(T, d, q_ref=src + 0.4 * step)
        np.testing.assert_allclose(got[both] - src[both], 0, atol=1e-8)
    # with q6 given, q_ref still chooses the elbow
    got = _ik(T, d, q6=q[:, 3], q_ref=qo)
    np.testing.assert_allclose(got[both] - qo[both], 0, atol=1e-8)
    # the redundant q6: a reference off the solution set gets the nearest solution, no
    # farther than the one with q_ref's own q6, and a local minimum along the self-motion
    q_ref = q.at[:, 3].add(0.2).at[:, 4].add(-0.1)
    qi, oki = _ik(T, d, q_ref=q_ref, full_output=True)
    assert bool(oki.all())
    np.testing.assert_allclose(qi[:, :3], q[:, :3], atol=1e-8)
    np.testing.assert_allclose(_fk(qi, d), T, atol=1e-8)

    def dist(q6):  # distance of the within-limits wrist solution for q6 (inf if none)
        qw = np.asarray(_branches(T, d, q6=q6, within_limits=False)[0][:, 0, 3:])
        lim = m.JOINT_LIMITS[3:]
        okw = np.all((qw >= lim[:, 0] - 1e-9) & (qw <= lim[:, 1] + 1e-9), -1)
        return np.where(okw, np.sum(_wrapped_err(qw, q_ref[:, 3:]) ** 2, -1), np.inf)

    d0 = dist(qi[:, 3])
    assert np.all(d0 <= dist(q_ref[:, 3]) + 1e-12)
    for h in (-1e-3, 1e-3):
        assert np.all(d0 <= dist(qi[:, 3] + h) + 1e-12)


def test_q_ref_broadcasts_keeps_dtype_and_checks_its_shape(initial_1000):
    d, q, T, _, _ = initial_1000
    # poses (2, 1) against references (1, 3): every pose with every reference
    qs = _ik(T[:2, None], d, q_ref=q[None, :3])
    assert qs.shape == (2, 3, 7)
    np.testing.assert_allclose(qs[[0, 1], [0, 1]], q[:2], atol=1e-9)
    np.testing.assert_allclose(_fk(qs, d), jnp.broadcast_to(T[:2, None], (2, 3, 4, 4)), atol=1e-8)
    q32 = q.astype(jnp.float32)
    out = jax.eval_shape(lambda T, r: m.ik(T, d, q_ref=r), T.astype(jnp.float32), q32)
    assert out.dtype == jnp.float32 and out.shape == (1000, 7)
    with pytest.raises(ValueError, match=r"q_ref must have shape \(\.\.\., 7\)"):
        m.ik(T, d, q_ref=jnp.zeros(6))


# ----------------------------------------------- the chain on the frame kernel vs numpy


def _np_dh_modified(alpha, a, theta, d):
    """Rx(α) Tx(a) Rz(θ) Tz(d) in numpy, one link (Craig's convention, eq. 1)."""
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _np_master9(q, x):
    """Independent numpy FK (4×4) and geometric Jacobian (6×7) of the reconstructed
    Table 1: the product of the 9 link transforms, then the chain Jacobian from the frames
    (z_i × (p_9 − p_i); z_i) mapped to the active joints through q4 = −q3, q5 = −q1 − q2."""
    q1, q2, q3, q6, q7, q8, q9 = q
    hp = np.pi / 2
    rows = [  # α_{i-1}, a_{i-1}, θ_i, d_i
        (0.0, 0.0, q1, 0.0),
        (0.0, x["a1"], q2 - hp, -x["d2"]),
        (-hp, 0.0, q3, x["d3"]),
        (0.0, x["a3"], -q3, 0.0),
        (hp, x["a4"], -q1 - q2, x["d5"]),
        (0.0, x["a5"], q6 - hp, x["d6"]),
        (-hp, 0.0, q7, 0.0),
        (hp, 0.0, q8 + hp, 0.0),
        (hp, 0.0, q9 - hp, 0.0),
    ]
    T = np.eye(4)
    frames = []
    for r in rows:
        T = T @ _np_dh_modified(*r)
        frames.append(T)
    p_n = T[:3, 3]
    Jc = np.zeros((6, 9))
    for i, Ti in enumerate(frames):
        z, p = Ti[:3, 2], Ti[:3, 3]
        Jc[:3, i] = np.cross(z, p_n - p)
        Jc[3:, i] = z
    C = np.zeros((9, 7))
    for i, j in [(0, 0), (1, 1), (2, 2), (5, 3), (6, 4), (7, 5), (8, 6)]:
        C[i, j] = 1.0
    C[3, 2] = -1.0
    C[4, 0] = C[4, 1] = -1.0
    return T, Jc @ C


def test_kernel_fk_and_jacobian_equal_a_numpy_dh_product():
    """mechanism.fk/jacobian (the frame kernel with the joint couplings) against the numpy
    product of the DH link matrices, random designs (all 8 lengths) and joints, float64."""
    rng = np.random.default_rng(11)
    lo = np.array([250, 250, 50, 0, 20, 10, 20, 40.0])
    hi = np.array([350, 350, 150, 40, 100, 60, 80, 120.0])
    n = 64
    X = rng.uniform(lo, hi, (n, 8))
    q = rng.uniform(m.JOINT_LIMITS[:, 0], m.JOINT_LIMITS[:, 1], (n, 7))
    d = {k: jnp.asarray(X[:, i]) for i, k in enumerate(m.DESIGN_KEYS)}
    T, J = np.asarray(m.fk(q, d)), np.asarray(m.jacobian(q, d))
    assert T.dtype == J.dtype == np.float64
    for i in range(n):
        Tr, Jr = _np_master9(q[i], dict(zip(m.DESIGN_KEYS, X[i], strict=True)))
        # rotations and J_w to 1e-12; positions and J_v (mm, |p| < 1000) to 1e-12 relative
        np.testing.assert_allclose(T[i, :3, :3], Tr[:3, :3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(T[i, :3, 3], Tr[:3, 3], rtol=0, atol=1e-12 * 1e3)
        np.testing.assert_allclose(J[i, :3], Jr[:3], rtol=0, atol=1e-12 * 1e3)
        np.testing.assert_allclose(J[i, 3:], Jr[3:], rtol=0, atol=1e-12)
    # design values broadcast against q's leading dims: (4, 1) designs × (5, 7) joints
    TM = np.asarray(m.fk(q[:5], {k: v[:4, None] for k, v in d.items()}))
    assert TM.shape == (4, 5, 4, 4)
    Tr, _ = _np_master9(q[3], dict(zip(m.DESIGN_KEYS, X[2], strict=True)))
    np.testing.assert_allclose(TM[2, 3], Tr, rtol=0, atol=1e-9)
