"""Condition numbers against numpy.linalg.cond, singular inputs, and invariances."""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from designopt.kinematics import cond_2, cond_fro, inv_cond, inv_cond_fro, inv_cond_fro3


def test_random_matrices_match_numpy():
    rng = np.random.default_rng(0)
    for n in (2, 3, 4, 6):
        A = rng.normal(size=(200, n, n))
        np.testing.assert_allclose(cond_2(A), np.linalg.cond(A, 2), rtol=1e-9)
        np.testing.assert_allclose(cond_fro(A), np.linalg.cond(A, "fro"), rtol=1e-9)
        np.testing.assert_allclose(
            cond_fro(A, normalized=True), np.linalg.cond(A, "fro") / n, rtol=1e-9
        )


def test_near_singular_matrices_match_numpy():
    rng = np.random.default_rng(1)
    U, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    V, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    for smin in (1e-3, 1e-6, 1e-9):
        A = U @ np.diag([1.0, 0.5, smin]) @ V.T
        np.testing.assert_allclose(cond_2(A), np.linalg.cond(A, 2), rtol=1e-6)
        np.testing.assert_allclose(cond_fro(A), np.linalg.cond(A, "fro"), rtol=1e-6)


def test_closed_form_3x3_equals_svd_route():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(500, 3, 3))
    ref = 1.0 / np.linalg.cond(A, "fro")
    np.testing.assert_allclose(inv_cond_fro3(A), ref, rtol=1e-10)
    np.testing.assert_allclose(inv_cond_fro3(A, normalized=True), 3 * ref, rtol=1e-10)


def test_exactly_singular_gives_zero_not_nan():
    S = jnp.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    Z = jnp.zeros((3, 3))
    for M in (S, Z):
        for norm in ("fro", "2"):
            r = inv_cond(M, norm)
            assert float(r) == 0.0
        assert float(cond_2(M)) == np.inf and float(cond_fro(M)) == np.inf
    g = jax.grad(lambda M: inv_cond_fro3(M))(S)
    assert np.all(np.isfinite(g))
    g0 = jax.grad(lambda M: inv_cond_fro3(M))(Z)
    assert np.all(np.isfinite(g0))
    S4 = jnp.diag(jnp.array([1.0, 2.0, 0.0, 3.0]))
    assert float(inv_cond_fro(S4)) == 0.0 and float(inv_cond(S4, "2")) == 0.0


def test_identity_is_isotropic():
    for n in (3, 5):
        I = jnp.eye(n)
        assert float(inv_cond(I, "2")) == 1.0
        np.testing.assert_allclose(inv_cond_fro(I), 1.0 / n)
        np.testing.assert_allclose(inv_cond_fro(I, normalized=True), 1.0)


mats = arrays(
    np.float64, (3, 3), elements=st.floats(-10, 10, allow_nan=False, allow_subnormal=False)
)


@settings(max_examples=60, deadline=None)
@given(mats, st.floats(1e-3, 1e3))
def test_scaling_invariance_and_lower_bounds(A, s):
    if abs(np.linalg.det(A)) < 1e-6 * max(1.0, np.abs(A).max() ** 3):
        return
    k2, kf = float(cond_2(A)), float(cond_fro(A))
    np.testing.assert_allclose(float(cond_2(s * A)), k2, rtol=1e-7)
    np.testing.assert_allclose(float(cond_fro(s * A)), kf, rtol=1e-7)
    assert k2 >= 1.0 - 1e-12
    assert kf >= 3.0 - 1e-9
