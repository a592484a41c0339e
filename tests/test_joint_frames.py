"""``SerialModel.joint_frames`` against a NumPy product of DH matrices (the drawing and the
``links: auto`` collision capsules stand on it)."""

import numpy as np

from designopt.kinematics import dh_model


def _dh(al, a, d, th):
    ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                     [0, sa, ca, d], [0, 0, 0, 1]])  # fmt: skip


def test_joint_frames_match_dh_products():
    al = [np.pi / 2, 0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0]
    m = dh_model("standard", "RRRRRR", al, [0, "a2", "a3", 0, 0, 0],
                 [0, 0, 0.15, "d4", 0, 0], [0] * 6)  # fmt: skip
    rng = np.random.default_rng(3)
    X = rng.uniform(0.1, 0.6, (2, 3))
    q = rng.uniform(-3, 3, (4, 6))
    P, A, R = (np.asarray(v) for v in m.joint_frames(X, q))
    assert P.shape == (2, 4, 7, 3) and A.shape == (2, 4, 6, 3) and R.shape == (2, 4, 3, 3)
    for i in range(2):
        a = [0, X[i, 0], X[i, 1], 0, 0, 0]
        d = [0, 0, 0.15, X[i, 2], 0, 0]
        for c in range(4):
            T = np.eye(4)
            for j in range(6):
                np.testing.assert_allclose(P[i, c, j], T[:3, 3], atol=1e-6)
                np.testing.assert_allclose(A[i, c, j], T[:3, 2], atol=1e-6)
                T = T @ _dh(al[j], a[j], d[j], q[c, j])
            np.testing.assert_allclose(P[i, c, 6], T[:3, 3], atol=1e-6)
            np.testing.assert_allclose(R[i, c], T[:3, :3], atol=1e-6)
    Rf, pf = m.fk(X, q)
    np.testing.assert_allclose(P[..., -1, :], pf, atol=1e-12)
