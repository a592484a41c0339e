"""inv_cond / cond against numpy.linalg (cond, svd, det), singular inputs, invariances."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from designopt.kinematics import cond, inv_cond


def cond_2_(A):
    return cond(A, "2")


def cond_fro_(A, normalized=False):
    return cond(A, "fro", normalized)


def test_random_matrices_match_numpy():
    rng = np.random.default_rng(0)
    for n in (2, 3, 4, 6):
        A = rng.normal(size=(200, n, n))
        kf = np.linalg.cond(A, "fro")
        np.testing.assert_allclose(cond_2_(A), np.linalg.cond(A, 2), rtol=1e-9)
        if n <= 3:  # closed forms on the entries (adjugate)
            np.testing.assert_allclose(cond_fro_(A), kf, rtol=1e-9)
            np.testing.assert_allclose(cond_fro_(A, normalized=True), kf / n, rtol=1e-9)
        else:  # Gram route (LDLᵀ): relative error of 1/k grows like κ²·eps
            np.testing.assert_allclose(inv_cond(A), 1 / kf, rtol=1e-9, atol=1e-11)
            np.testing.assert_allclose(
                inv_cond(A, normalized=True), n / kf, rtol=1e-9, atol=n * 1e-11
            )


def test_near_singular_matrices_match_numpy():
    rng = np.random.default_rng(1)
    U, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    V, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    for smin in (1e-3, 1e-6, 1e-9):
        A = U @ np.diag([1.0, 0.5, smin]) @ V.T
        np.testing.assert_allclose(cond_2_(A), np.linalg.cond(A, 2), rtol=1e-6)
        np.testing.assert_allclose(cond_fro_(A), np.linalg.cond(A, "fro"), rtol=1e-6)


def test_closed_form_3x3_equals_svd_route():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(500, 3, 3))
    ref = 1.0 / np.linalg.cond(A, "fro")
    np.testing.assert_allclose(inv_cond(A, "fro"), ref, rtol=1e-10)
    np.testing.assert_allclose(inv_cond(A, "fro", normalized=True), 3 * ref, rtol=1e-10)


def test_exactly_singular_gives_zero_not_nan():
    S = jnp.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    Z = jnp.zeros((3, 3))
    for M in (S, Z):
        for norm in ("fro", "2"):
            r = inv_cond(M, norm)
            assert float(r) == 0.0
        assert float(cond_2_(M)) == np.inf and float(cond_fro_(M)) == np.inf
    g = jax.grad(lambda M: inv_cond(M) + inv_cond(M, "2"))(S)
    assert np.all(np.isfinite(g))
    g0 = jax.grad(lambda M: inv_cond(M) + inv_cond(M, "2"))(Z)
    assert np.all(np.isfinite(g0))
    S4 = jnp.diag(jnp.array([1.0, 2.0, 0.0, 3.0]))
    assert float(inv_cond(S4)) == 0.0 and float(inv_cond(S4, "2")) == 0.0


def test_identity_is_isotropic():
    for n in (3, 5):
        I = jnp.eye(n)
        assert float(inv_cond(I, "2")) == 1.0
        np.testing.assert_allclose(inv_cond(I), 1.0 / n)
        np.testing.assert_allclose(inv_cond(I, normalized=True), 1.0)


mats = arrays(
    np.float64, (3, 3), elements=st.floats(-10, 10, allow_nan=False, allow_subnormal=False)
)


@settings(max_examples=60, deadline=None)
@given(mats, st.floats(1e-3, 1e3))
def test_scaling_invariance_and_lower_bounds(A, s):
    if abs(np.linalg.det(A)) < 1e-6 * max(1.0, np.abs(A).max() ** 3):
        return
    k2, kf = float(cond_2_(A)), float(cond_fro_(A))
    np.testing.assert_allclose(float(cond_2_(s * A)), k2, rtol=1e-7)
    np.testing.assert_allclose(float(cond_fro_(s * A)), kf, rtol=1e-7)
    assert k2 >= 1.0 - 1e-12
    assert kf >= 3.0 - 1e-9


def _np_fro(J):
    return 1 / (np.linalg.norm(J, axis=(-2, -1)) * np.linalg.norm(np.linalg.pinv(J), axis=(-2, -1)))


def test_volume_is_the_product_of_singular_values():
    """with_volume: σ_1⋯σ_m (|det J| when square) for every route (closed forms m ≤ 3,
    Jacobi m ≥ 4), non-square included; the 1/k returned beside it is inv_cond's."""
    rng = np.random.default_rng(3)
    both = jax.jit(
        lambda J: (inv_cond(J, "fro", with_volume=True), inv_cond(J, "2", with_volume=True))
    )
    for shape in [(1, 3), (2, 2), (3, 3), (2, 5), (6, 3), (4, 4), (5, 7)]:
        J = rng.normal(size=(30,) + shape)
        s = np.linalg.svd(J, compute_uv=False)
        (rf, vol), (r2, vol2) = both(J)
        np.testing.assert_allclose(vol, np.prod(s, -1), rtol=1e-10)
        np.testing.assert_allclose(vol2, np.prod(s, -1), rtol=1e-10)
        np.testing.assert_allclose(rf, 1 / np.linalg.cond(J, "fro") if shape[0] == shape[1]
                                   else _np_fro(J), rtol=1e-8)  # fmt: skip
        np.testing.assert_allclose(r2, s[:, -1] / s[:, 0], rtol=1e-8)
        if shape[0] == shape[1]:
            np.testing.assert_allclose(vol, np.abs(np.linalg.det(J)), rtol=1e-10)
    S = jnp.asarray([[1.0, 2.0], [2.0, 4.0]])
    r, vol = inv_cond(S, "2", with_volume=True)
    assert float(r) == 0.0 and float(vol) == 0.0
    g = jax.grad(lambda M: sum(inv_cond(M, "2", with_volume=True)))(S)
    assert np.all(np.isfinite(g))


def test_bad_arguments():
    with pytest.raises(ValueError, match="norm"):
        inv_cond(jnp.eye(3), "inf")
    with pytest.raises(ValueError, match="r, n"):
        inv_cond(jnp.ones(3))
