"""DH and elementary transforms against an independent numpy implementation."""

import jax.numpy as jnp
import numpy as np
import pytest
from kinref import DHChain, DHParams, ETChain

from designopt.kinematics import (
    ET,
    dh_modified,
    dh_standard,
    rotx,
    roty,
    rotz,
    trans,
)


def np_rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def np_rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def np_ry(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def np_t(x, y, z):
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


# PUMA 560 standard DH table (Corke), lengths in mm
PUMA = dict(
    a=np.array([0, 431.8, 20.3, 0, 0, 0]),
    d=np.array([0, 0, 150.05, 431.8, 0, 0]),
    alpha=np.array([np.pi / 2, 0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0]),
)


def test_elementary_rotations_match_numpy():
    t = 0.7
    np.testing.assert_allclose(rotx(t), np_rx(t), atol=1e-15)
    np.testing.assert_allclose(roty(t), np_ry(t), atol=1e-15)
    np.testing.assert_allclose(rotz(t), np_rz(t), atol=1e-15)
    np.testing.assert_allclose(trans(1.0, -2.0, 3.5), np_t(1, -2, 3.5), atol=0)


def test_dh_link_transforms_are_products_of_elementary_ones():
    rng = np.random.default_rng(1)
    for _ in range(20):
        th, d, a, al = rng.uniform(-3, 3, 4) * [1, 100, 100, 1]
        np.testing.assert_allclose(
            dh_standard(th, d, a, al),
            np_rz(th) @ np_t(0, 0, d) @ np_t(a, 0, 0) @ np_rx(al),
            atol=1e-12,
        )
        np.testing.assert_allclose(
            dh_modified(al, a, th, d),
            np_rx(al) @ np_t(a, 0, 0) @ np_rz(th) @ np_t(0, 0, d),
            atol=1e-12,
        )


def test_standard_chain_fk_matches_numpy_puma():
    chain = DHChain(("R",) * 6, "standard")
    p = DHParams(
        jnp.asarray(PUMA["alpha"]), jnp.asarray(PUMA["a"]), jnp.asarray(PUMA["d"]), jnp.zeros(6)
    )
    rng = np.random.default_rng(2)
    qs = rng.uniform(-np.pi, np.pi, (50, 6))
    T = chain.fk(p, qs)
    for q, Ti in zip(qs, np.asarray(T), strict=True):
        ref = np.eye(4)
        for i in range(6):
            ref = (
                ref
                @ np_rz(q[i])
                @ np_t(0, 0, PUMA["d"][i])
                @ np_t(PUMA["a"][i], 0, 0)
                @ np_rx(PUMA["alpha"][i])
            )
        np.testing.assert_allclose(Ti, ref, atol=1e-9)
    # the Robotics Toolbox's p560.fkine(qz) translation: (0.4521, -0.1500, 0.4318) m
    np.testing.assert_allclose(chain.fk(p, jnp.zeros(6))[:3, 3], [452.1, -150.05, 431.8], atol=1e-9)


def test_modified_and_standard_tables_describe_the_same_arm():
    """Π std_i = Π mod_i · Tx(a_n) Rx(α_n), with the modified table's (α, a) shifted down a row."""
    std = DHChain(("R", "R", "P", "R", "R", "R"), "standard")
    mod = DHChain(("R", "R", "P", "R", "R", "R"), "modified")
    al, a, d = PUMA["alpha"], PUMA["a"], PUMA["d"]
    ps = DHParams(jnp.asarray(al), jnp.asarray(a), jnp.asarray(d), jnp.zeros(6))
    pm = DHParams(
        jnp.asarray(np.r_[0.0, al[:-1]]),
        jnp.asarray(np.r_[0.0, a[:-1]]),
        jnp.asarray(d),
        jnp.zeros(6),
    )
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, (100, 6))
    tool = np_t(a[-1], 0, 0) @ np_rx(al[-1])
    np.testing.assert_allclose(std.fk(ps, q), np.asarray(mod.fk(pm, q)) @ tool, atol=1e-9)


def test_prismatic_joint_adds_to_d():
    chain = DHChain(("P",), "standard")
    p = DHParams(jnp.zeros(1), jnp.zeros(1), jnp.array([5.0]), jnp.zeros(1))
    np.testing.assert_allclose(chain.fk(p, jnp.array([2.5]))[:3, 3], [0, 0, 7.5])


def test_et_chain_matches_numpy_and_uses_params():
    chain = ETChain(
        (
            ET("Rx", param="alpha", scale=-1.0),
            ET("Rz", joint=0),
            ET("Tz", param="L"),
            ET("Ty", joint=1),
        )
    )
    q = np.array([0.3, 12.0])
    T = chain.fk({"alpha": 0.2, "L": 100.0}, q)
    ref = np_rx(-0.2) @ np_rz(0.3) @ np_t(0, 0, 100) @ np_t(0, 12, 0)
    np.testing.assert_allclose(T, ref, atol=1e-12)
    with pytest.raises(ValueError, match="L"):
        chain.fk({"alpha": 0.2}, q)


def test_chain_rejects_wrong_q_shape():
    chain = DHChain(("R",) * 6, "standard")
    p = DHParams(*(jnp.zeros(6),) * 4)
    with pytest.raises(ValueError, match="last dimension 6"):
        chain.fk(p, jnp.zeros(5))
