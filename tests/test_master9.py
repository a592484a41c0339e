"""Study A kinematics (seed 000 §III) against the paper's closed forms and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.kinematics import cond_fro, det3
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
    k = cond_fro(m.jacobian(q, d)[:, :3, :3])
    np.testing.assert_allclose(m.cond_fro_eq53(q[:, :3], d), k, rtol=1e-9)


def test_det_jv_closed_form():
    q = m.sample_joints(KEY, 300)
    d = m.default_design()
    np.testing.assert_allclose(
        m.det_jv(q[:, :3], d), det3(m.jacobian_v_closed(q[:, :3], d)), rtol=1e-9
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
