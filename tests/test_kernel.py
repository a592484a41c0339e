"""The frame kernel (designopt.kinematics.kernel) against autodiff, closed forms, numpy and
the Robotics Toolbox; inv_cond against numpy; the reference's DHParams batching (#16 item 5).
The autodiff references (4×4 products, jax.jacfwd) are in tests/kinref.py."""

import math
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from kinref import DHChain, DHParams, ETChain, geometric_jacobian, position_jacobian

from designopt.kinematics import ET, inv_cond
from designopt.kinematics.kernel import dh_model, et_model
from designopt.studies.master9 import mechanism as m9

HP = np.pi / 2
FOLD = 1e-12
"""rad: the kernel takes a constant angle this close to a multiple of π/2 as that exact
quarter turn (a signed permutation; ``kernel._Walk.trig``, docs/kinematics.md)."""


def snapped(angle: float) -> float:
    """A drawn constant angle as the kernel reads it: within :data:`FOLD` of a quarter
    turn, the quarter turn. The property tests draw through this, so that their autodiff
    reference computes what the kernel is meant to (hypothesis likes angles like 4.6e-13
    rad, which the kernel folds to 0 by design); the rule itself, and the bound it keeps,
    are tested in :func:`test_a_constant_angle_within_the_fold_is_the_quarter_turn`."""
    r = math.remainder(angle, HP)
    return angle - r if abs(r) < FOLD else angle


# ------------------------------------------------------------------ helpers


def master9_model(variables=("a1", "a3", "d3")):
    """master9 (SPEC §3.1) as a kernel model: 7 active joints → 9 chain joints."""
    C = np.zeros((9, 7))
    for i, j in [(0, 0), (1, 1), (2, 2), (5, 3), (6, 4), (7, 5), (8, 6)]:
        C[i, j] = 1.0
    C[3, 2] = -1.0  # q4 = -q3
    C[4, 0] = C[4, 1] = -1.0  # q5 = -q1 - q2
    fx = m9.FIXED_DEFAULTS

    def v(name):
        return name if name in variables else fx[name]

    return dh_model(
        "modified",
        ("R",) * 9,
        alpha=[0, 0, -HP, 0, HP, 0, -HP, HP, HP],
        a=[0, "a1", 0, "a3", v("a4"), v("a5"), 0, 0, 0],
        d=[0, ("d2", -1.0) if "d2" in variables else -fx["d2"], "d3", 0, v("d5"), v("d6"), 0, 0, 0],
        theta=[0, -HP, 0, 0, 0, -HP, 0, HP, -HP],
        variables=variables,
        coupling=C,
    )


def designs(M, rng):
    return np.stack(
        [rng.uniform(250, 350, M), rng.uniform(250, 350, M), rng.uniform(50, 150, M)], 1
    )


def ref_jacobian(fk, q, params):
    """(…, 6, n) geometric Jacobian by jax.jacfwd of a 4×4 FK (vee(dR Rᵀ) for ω);
    DHParams leaves (M, 1, n) keep their joint axis (explicit: n may equal C)."""
    return geometric_jacobian(fk, q, params, event_ndim=1)


# ------------------------------------------------------ random DH chains vs autodiff


@st.composite
def dh_chains(draw):
    n = draw(st.integers(1, 8))
    conv = draw(st.sampled_from(["standard", "modified"]))
    types = tuple(draw(st.sampled_from("RP")) for _ in range(n))
    fl = st.floats(-2.0, 2.0, allow_nan=False, allow_subnormal=False)
    ang = st.floats(-np.pi, np.pi, allow_nan=False, allow_subnormal=False)
    table = {
        "alpha": [snapped(draw(ang)) for _ in range(n)],
        "a": [draw(fl) for _ in range(n)],
        "d": [draw(fl) for _ in range(n)],
        "theta": [snapped(draw(ang)) for _ in range(n)],
    }
    is_var = {k: [draw(st.booleans()) for _ in range(n)] for k in table}
    coupled = draw(st.booleans())
    seed = draw(st.integers(0, 2**31 - 1))
    return n, conv, types, table, is_var, coupled, seed


def _build_random(n, conv, types, table, is_var, coupled, seed):
    rng = np.random.default_rng(seed)
    names, where, cols = [], [], {}
    for k in ("alpha", "a", "d", "theta"):
        cols[k] = []
        for i in range(n):
            if is_var[k][i]:
                names.append(f"{k}{i}")
                where.append((k, i))
                cols[k].append(f"{k}{i}")
            else:
                cols[k].append(table[k][i])
    M, C = 3, 4
    base = np.array([table[k][i] for k, i in where])
    X = base[None, :] + rng.normal(scale=0.3, size=(M, len(names)))
    if coupled:
        nA = max(1, n - 1)
        Cm = rng.integers(-1, 2, size=(n, nA)).astype(float)
        off = rng.uniform(-1, 1, n)
        coupling = (Cm, off)
    else:
        nA, Cm, off, coupling = n, np.eye(n), np.zeros(n), None
    q = rng.uniform(-np.pi, np.pi, (C, nA))
    model = dh_model(conv, types, variables=tuple(names), coupling=coupling, **cols)
    # reference: DHChain + jacfwd, per design, with the coupling applied inside fk
    P = {k: np.broadcast_to(np.asarray(table[k], float), (M, n)).copy() for k in table}
    for j, (k, i) in enumerate(where):
        P[k][:, i] = X[:, j]
    params = DHParams(*(jnp.asarray(P[k])[:, None, :] for k in ("alpha", "a", "d", "theta")))
    chain = DHChain(types, conv)

    def fk(qa, p):
        return chain.fk(p, jnp.asarray(Cm) @ qa + jnp.asarray(off))

    return model, X, q, fk, params


@settings(max_examples=10, deadline=None)
@given(dh_chains())
def test_random_dh_chains_match_autodiff_in_both_paths(spec):
    model, X, q, fk, params = _build_random(*spec)
    Jref = np.asarray(ref_jacobian(fk, jnp.asarray(q), params))  # (M, C, 6, nA)
    Tref = np.asarray(
        jax.vmap(lambda p: jax.vmap(lambda x: fk(x, p))(jnp.asarray(q)))(
            jax.tree_util.tree_map(lambda x: x[:, 0], params)
        )
    )
    for mdl in (model, model.per_design()):
        R, p, J = mdl.fk_jacobian(X, q)
        np.testing.assert_allclose(J, Jref, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(R, Tref[..., :3, :3], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(p, Tref[..., :3, 3], rtol=1e-12, atol=1e-12)


def test_a_constant_angle_within_the_fold_is_the_quarter_turn():
    """The chain hypothesis found on 2026-11-29 (modified DH, 8 joints, the last
    prismatic, coupled joints, a twist of 4.6e-13 rad, everything else 0): the kernel
    gives exactly what it gives for a twist of 0, and the exact chain differs from that
    by no more than the twist moves it. To first order, a twist δ ≤ FOLD rotates the rest
    of the chain by δ about its frame: R's entries move by ≤ δ, a position by ≤ δ × its
    lever r, a chain column z × (p_n − p_i) by ≤ δ·r (z turned) + 2δ·r (both ends
    moved), and a coupled joint's column, a sum of chain columns with coefficients in
    {−1, 0, 1}, by ≤ n times that; r ≤ the reach, bounded here by the largest |p| and
    column norm. (Measured: |ΔJ| = 1.44e-11 = 5.2 δ·r; the bound 3·8·FOLD·r = 1.45e-10.)"""
    tiny = 4.599405195003031e-13
    types = ("R",) * 7 + ("P",)
    zero = [0.0] * 8
    spec = (8, "modified", types, {"alpha": zero[:7] + [tiny], "a": zero, "d": zero,
                                   "theta": zero},
            {k: [False] * 8 for k in ("alpha", "a", "d", "theta")}, True, 0)  # fmt: skip
    model, X, q, fk, params = _build_random(*spec)
    model0, *_ = _build_random(*spec[:3], spec[3] | {"alpha": zero}, *spec[4:])
    R, p, J = model.fk_jacobian(X, q)
    R0, p0, J0 = model0.fk_jacobian(X, q)
    for a, b in ((R, R0), (p, p0), (J, J0)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    Jref = np.asarray(ref_jacobian(fk, jnp.asarray(q), params))
    Tref = np.asarray(jax.vmap(lambda x: fk(x, jax.tree_util.tree_map(lambda v: v[0, 0], params)))(
        jnp.asarray(q)))  # fmt: skip
    reach = max(1.0, np.max(np.linalg.norm(Tref[:, :3, 3], axis=-1)),
                np.max(np.linalg.norm(Jref[..., :3, :], axis=-2)))  # fmt: skip
    assert 0 < np.max(np.abs(J - Jref)) <= 3 * 8 * FOLD * reach
    assert np.max(np.abs(p - Tref[:, :3, 3])) <= FOLD * reach
    assert np.max(np.abs(R - Tref[:, :3, :3])) <= FOLD


@st.composite
def et_chains(draw):
    n_el = draw(st.integers(1, 8))
    els, j, names = [], 0, []
    for i in range(n_el):
        kind = draw(st.sampled_from(["Rx", "Ry", "Rz", "Tx", "Ty", "Tz"]))
        joint = None
        if draw(st.booleans()):
            joint, j = j, j + 1
        param = None
        if draw(st.booleans()):
            param = f"p{i}"
            names.append(param)
        const = draw(st.floats(-1.5, 1.5, allow_nan=False, allow_subnormal=False))
        if kind[0] == "R":
            const = snapped(const)
        scale = draw(st.sampled_from([1.0, -1.0, 0.5]))
        els.append(ET(kind, joint, param, const, scale))
    return tuple(els), tuple(names), draw(st.integers(0, 2**31 - 1))


@settings(max_examples=10, deadline=None)
@given(et_chains())
def test_random_et_chains_match_autodiff(spec):
    els, names, seed = spec
    chain = ETChain(els)
    if chain.n == 0:
        return
    rng = np.random.default_rng(seed)
    model = et_model(chain.elements, variables=names)
    X = rng.uniform(-1, 1, (2, len(names)))
    q = rng.uniform(-2, 2, (3, chain.n))
    params = {nm: jnp.asarray(X[:, i])[:, None] for i, nm in enumerate(names)}
    Jref = np.asarray(geometric_jacobian(lambda x, p: chain.fk(p, x), jnp.asarray(q), params))
    Jref = np.broadcast_to(Jref, (2,) + Jref.shape[-3:])
    for mdl in (model, model.per_design()):
        np.testing.assert_allclose(mdl.jacobian(X, q), Jref, rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------- master9 closed forms


def test_master9_matches_closed_forms():
    model = master9_model()
    assert model.n_active == 7 and model.n_chain == 9 and model.shares_rotations
    rng = np.random.default_rng(0)
    X = designs(5, rng)
    q = np.asarray(m9.sample_joints(jax.random.key(0), 64))
    D = {**m9.FIXED_DEFAULTS, "a1": X[:, 0:1], "a3": X[:, 1:2], "d3": X[:, 2:3]}
    R, p, J = model.fk_jacobian(X, q)
    T = m9.fk_closed(q, D)
    np.testing.assert_allclose(R, T[..., :3, :3], atol=1e-12)
    np.testing.assert_allclose(p, T[..., :3, 3], rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(J, m9.jacobian_closed(q, D), rtol=1e-12, atol=1e-10)
    Jv = m9.jacobian_v_closed(q[:, :3], D)
    r, det = model.inv_cond(X, q, rows=(0, 1, 2), cols=(0, 1, 2), with_det=True)
    np.testing.assert_allclose(r, inv_cond(Jv), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(det, m9.det_jv(q[:, :3], D), rtol=1e-11, atol=1e-6)
    # all 8 lengths as variables (d2 enters as -d2): same numbers
    names = ("a1", "a3", "d3", "a4", "a5", "d2", "d5", "d6")
    full = master9_model(names)
    Xf = np.concatenate([X, np.tile([m9.FIXED_DEFAULTS[k] for k in names[3:]], (5, 1))], 1)
    np.testing.assert_allclose(full.jacobian(Xf, q), J, rtol=1e-12, atol=1e-10)


def test_master9_float32_agrees_with_closed_form():
    model = master9_model()
    rng = np.random.default_rng(1)
    X = designs(8, rng)
    q = np.asarray(m9.sample_joints(jax.random.key(1), 500))
    D = {**m9.FIXED_DEFAULTS, "a1": X[:, 0:1], "a3": X[:, 1:2], "d3": X[:, 2:3]}
    r = model.inv_cond(X.astype(np.float32), q.astype(np.float32), rows=(0, 1, 2), cols=(0, 1, 2))
    assert r.dtype == jnp.float32
    np.testing.assert_allclose(r, inv_cond(m9.jacobian_v_closed(q[:, :3], D)), atol=1e-5)


def test_master9_singular_boundary_gives_zero_and_finite_gradients():
    model = master9_model()
    X = np.array([[324.238, 317.076, 50.0]])
    q = np.zeros((3, 7))
    q[0, 2] = HP  # q3 = 90°: cos q3 = 0, det J_v = 0
    q[1, 2] = -HP
    a3c3, a4, d3 = 317.076, 10.0, 50.0
    q[2, 1] = np.arctan2(a3c3 + a4, d3)  # the elbow fold (a3 c3 + a4) c2 = d3 s2
    for norm in ("fro", "2"):
        r = model.inv_cond(X, q, rows=(0, 1, 2), cols=(0, 1, 2), norm=norm)
        assert np.all(np.asarray(r) == 0.0), (norm, r)
        gx, gq = jax.grad(
            lambda X, q, norm=norm: model.inv_cond(
                X, q, rows=(0, 1, 2), cols=(0, 1, 2), norm=norm
            ).sum(),
            argnums=(0, 1),
        )(jnp.asarray(X), jnp.asarray(q))
        assert np.all(np.isfinite(gx)) and np.all(np.isfinite(gq))


def test_planar_2r_singular_at_q2_zero():
    model = dh_model(
        "standard",
        "RR",
        alpha=[0, 0],
        a=["l1", "l2"],
        d=[0, 0],
        theta=[0, 0],
        variables=("l1", "l2"),
    )
    X = jnp.array([[1.0, 0.7], [2.0, 1.0]])
    q = jnp.array([[0.3, 0.0], [0.3, 1.0]])
    for norm in ("fro", "2"):
        f = lambda X, q, norm=norm: model.inv_cond(X, q, rows=(0, 1), norm=norm)  # noqa: E731
        r = f(X, q)
        assert np.all(np.asarray(r[:, 0]) == 0.0) and np.all(np.asarray(r[:, 1]) > 0)
        gx, gq = jax.grad(lambda X, q, f=f: f(X, q).sum(), argnums=(0, 1))(X, q)
        assert np.all(np.isfinite(gx)) and np.all(np.isfinite(gq))
    # 2-norm 1/k of the planar 2R at q2: σ from the textbook det = l1 l2 sin q2
    J = model.jacobian(X, q, rows=(0, 1))
    np.testing.assert_allclose(
        np.linalg.det(np.asarray(J[:, 1])), [0.7 * np.sin(1.0), 2 * np.sin(1.0)]
    )


# --------------------------------------------------------------- PUMA 560 vs numpy

PUMA = dict(  # standard DH, mm (Corke's p560 / Craig's textbook values)
    alpha=[HP, 0.0, -HP, HP, -HP, 0.0],
    a=[0.0, 431.8, 20.32, 0.0, 0.0, 0.0],
    d=[0.0, 0.0, 149.09, 433.07, 0.0, 0.0],
)


def np_dh_std(theta, d, a, alpha):
    ct, st_, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st_ * ca, st_ * sa, a * ct],
            [st_, ct * ca, -ct * sa, a * st_],
            [0, sa, ca, d],
            [0, 0, 0, 1.0],
        ]
    )


def np_jacobian(q, a, d, alpha):
    """Textbook geometric Jacobian from numpy frames (standard DH, revolute)."""
    T = np.eye(4)
    zs, ps = [], []
    for i in range(len(q)):
        zs.append(T[:3, 2].copy())
        ps.append(T[:3, 3].copy())
        T = T @ np_dh_std(q[i], d[i], a[i], alpha[i])
    pn = T[:3, 3]
    J = np.zeros((6, len(q)))
    for i in range(len(q)):
        J[:3, i] = np.cross(zs[i], pn - ps[i])
        J[3:, i] = zs[i]
    return T, J


def puma_model(variables=("a2", "a3", "d3", "d4")):
    return dh_model(
        "standard",
        "RRRRRR",
        alpha=PUMA["alpha"],
        a=[0, "a2", "a3", 0, 0, 0],
        d=[0, 0, "d3", "d4", 0, 0],
        theta=[0] * 6,
        variables=variables,
    )


def test_puma560_matches_numpy_frames():
    model = puma_model()
    X = np.array([[431.8, 20.32, 149.09, 433.07], [400.0, 30.0, 120.0, 450.0]])
    rng = np.random.default_rng(5)
    q = rng.uniform(-np.pi, np.pi, (40, 6))
    R, p, J = model.fk_jacobian(X, q)
    for mi, (a2, a3, d3, d4) in enumerate(X):
        a, d = [0, a2, a3, 0, 0, 0], [0, 0, d3, d4, 0, 0]
        for ci in range(len(q)):
            T, Jn = np_jacobian(q[ci], a, d, PUMA["alpha"])
            np.testing.assert_allclose(R[mi, ci], T[:3, :3], atol=1e-12)
            np.testing.assert_allclose(p[mi, ci], T[:3, 3], atol=1e-9)
            np.testing.assert_allclose(J[mi, ci], Jn, atol=1e-9)
    # Corke's p560 at qz: tip at (a2 + a3... ) = (452.12, -149.09, 433.07) mm
    _, p0 = model.fk(X[:1], np.zeros((1, 6)))
    np.testing.assert_allclose(p0[0, 0], [431.8 + 20.32, -149.09, 433.07], atol=1e-9)


def test_puma560_matches_robotics_toolbox():
    rtb = pytest.importorskip("roboticstoolbox")
    robot = rtb.models.DH.Puma560()
    a = [L.a * 1000 for L in robot.links]
    d = [L.d * 1000 for L in robot.links]
    model = dh_model(
        "standard",
        "RRRRRR",
        alpha=[L.alpha for L in robot.links],
        a=a,
        d=d,
        theta=[L.offset for L in robot.links],
        variables=(),
    )
    rng = np.random.default_rng(6)
    q = rng.uniform(-np.pi, np.pi, (20, 6))
    J = np.asarray(model.jacobian(np.zeros((1, 0)), q))[0]
    for ci in range(len(q)):
        Jr = robot.jacob0(q[ci])
        Jr[:3] *= 1000.0
        np.testing.assert_allclose(J[ci], Jr, atol=1e-8)


# --------------------------------------------------------------- swarm & API shape


def test_swarm_row_equals_single_design_bit_for_bit():
    model = master9_model()
    rng = np.random.default_rng(2)
    X = designs(7, rng)
    q = np.asarray(m9.sample_joints(jax.random.key(3), 33))
    f = jax.jit(
        lambda X, q: (
            model.fk_jacobian(X, q) + (model.inv_cond(X, q, rows=(0, 1, 2), cols=(0, 1, 2)),)
        )
    )
    full = f(X, q)
    for i in (0, 3, 6):
        one = f(X[i : i + 1], q)
        for a, b in zip(full, one, strict=True):
            assert np.array_equal(np.asarray(a[i]), np.asarray(b[0]))
        one_d = jax.jit(model.jacobian)(X[i], q)  # 1-D X: one design
        assert np.array_equal(np.asarray(one_d), np.asarray(full[2][i]))
    # eager (op by op) evaluation too
    e7, e1 = model.jacobian(X[:3], q[:5]), model.jacobian(X[1:2], q[:5])
    assert np.array_equal(np.asarray(e7[1]), np.asarray(e1[0]))
    pm = puma_model()
    Xp = np.array([[431.8, 20.32, 149.09, 433.07], [400.0, 30.0, 120.0, 450.0]])
    qp = rng.uniform(-3, 3, (17, 6))
    g = jax.jit(pm.jacobian)
    assert np.array_equal(np.asarray(g(Xp, qp)[1]), np.asarray(g(Xp[1:], qp)[0]))


def test_rows_cols_selection_and_char_length():
    model = puma_model()
    X = np.array([[431.8, 20.32, 149.09, 433.07]])
    q = np.random.default_rng(3).uniform(-3, 3, (5, 6))
    J = model.jacobian(X, q)
    assert J.shape == (1, 5, 6, 6)
    np.testing.assert_array_equal(model.jacobian(X, q, rows=(0, 1)), J[..., :2, :])
    np.testing.assert_array_equal(
        model.jacobian(X, q, rows=(5, 3), cols=(4, 0)), J[..., [5, 3], :][..., [4, 0]]
    )
    Jc = model.jacobian(X, q, char_length=500.0)
    np.testing.assert_allclose(Jc[..., :3, :], J[..., :3, :] / 500.0, rtol=1e-14, atol=1e-15)
    np.testing.assert_array_equal(Jc[..., 3:, :], J[..., 3:, :])
    with pytest.raises(ValueError, match="rows"):
        model.jacobian(X, q, rows=(6,))
    with pytest.raises(ValueError, match="X must have shape"):
        model.jacobian(np.zeros((1, 3)), q)
    with pytest.raises(ValueError, match="not in variables"):
        dh_model("standard", "R", alpha=[0], a=["zz"], d=[0], theta=[0], variables=("l",))


def test_jit_grad_and_angle_variables():
    """A twist as a design variable: per-design frames; grad through X matches autodiff."""
    model = dh_model(
        "standard",
        "RRR",
        alpha=["tw", 0.0, HP],
        a=["l1", "l2", 0.1],
        d=[0.2, 0.0, "l3"],
        theta=[0.0, ("off", 1.0, 0.3), 0.0],
        variables=("l1", "l2", "l3", "tw", "off"),
    )
    assert not model.shares_rotations
    X = jnp.array([[1.0, 0.8, 0.3, 0.4, -0.2], [1.2, 0.5, 0.1, -0.3, 0.1]])
    q = jnp.array([[0.1, 0.2, 0.3], [1.0, -1.0, 0.5]])

    def ref(X, q):
        P = DHParams(
            jnp.stack([X[:, 3], jnp.zeros(2), jnp.full(2, HP)], -1)[:, None],
            jnp.stack([X[:, 0], X[:, 1], jnp.full(2, 0.1)], -1)[:, None],
            jnp.stack([jnp.full(2, 0.2), jnp.zeros(2), X[:, 2]], -1)[:, None],
            jnp.stack([jnp.zeros(2), X[:, 4] + 0.3, jnp.zeros(2)], -1)[:, None],
        )
        return geometric_jacobian(lambda x, p: DHChain(("R",) * 3, "standard").fk(p, x), q, P)

    np.testing.assert_allclose(jax.jit(model.jacobian)(X, q), jax.jit(ref)(X, q), atol=1e-12)
    g = jax.jit(jax.grad(lambda X: jnp.sum(model.jacobian(X, q) ** 2)))(X)
    gr = jax.jit(jax.grad(lambda X: jnp.sum(ref(X, q) ** 2)))(X)
    np.testing.assert_allclose(g, gr, rtol=1e-10, atol=1e-12)


def test_da_vinci_like_et_chain():
    """The da Vinci chain of SPEC §4 (RCM point H fixed) with lengths and β as variables."""
    al = np.deg2rad(20.0)
    chain = ETChain(
        (
            ET("Rx", const=-(np.pi - al)),
            ET("Rz", joint=0),
            ET("Tz", param="l_QH"),
            ET("Rx", param="beta", scale=-1.0, const=HP),
            ET("Ry", const=HP),
            ET("Rz", joint=1),
            ET("Ty", joint=2),
            ET("Rx", const=-HP),
            ET("Rz", joint=3),
            ET("Rx", const=HP),
            ET("Rz", joint=4),
            ET("Ty", param="l_IJ"),
            ET("Ry", const=HP),
            ET("Rz", joint=5),
        )
    )
    model = et_model(chain.elements, variables=("l_QH", "l_IJ", "beta"))
    X = np.array([[784.29, 10.0, np.deg2rad(30.45)], [700.0, 12.0, 0.5]])
    rng = np.random.default_rng(4)
    q = rng.uniform(-1, 1, (6, 6))
    q[:, 2] = rng.uniform(0, 315, 6)
    params = {k: jnp.asarray(X[:, i])[:, None] for i, k in enumerate(model.variables)}
    Jref = geometric_jacobian(lambda x, p: chain.fk(p, x), jnp.asarray(q), params)
    np.testing.assert_allclose(model.jacobian(X, q), Jref, rtol=1e-12, atol=1e-9)
    # the RCM point: the origin after the insertion element does not move with q1, q2, q3
    rcm = et_model(chain.elements[:6], variables=("l_QH", "beta"))
    _, p = rcm.fk(X[:, [0, 2]], q[:, :2])
    np.testing.assert_allclose(p, np.broadcast_to(p[:, :1], p.shape), atol=1e-9)


def test_float32_without_x64():
    """Library code runs in float32 with JAX's x64 mode off (the default)."""
    code = (
        "import numpy as np, jax.numpy as jnp\n"
        "from designopt.kinematics.kernel import dh_model\n"
        "from designopt.kinematics.conditioning import inv_cond\n"
        "m = dh_model('modified', 'RRP', alpha=[0, 1.2, 'tw'], a=[0, 'l1', 0.5], d=[0.1, 0, 'l2'],"
        " theta=[0, 0.3, 0], variables=('l1', 'l2', 'tw'))\n"
        "J = m.jacobian(np.ones((2, 3)), np.ones((4, 3)))\n"
        "r = m.inv_cond(np.ones((2, 3)), np.ones((4, 3)), rows=(0, 1, 2), norm='2')\n"
        "s = inv_cond(jnp.ones((5, 4, 6)))\n"
        "assert J.dtype == r.dtype == s.dtype == jnp.float32, (J.dtype, r.dtype, s.dtype)\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr


# ----------------------------------------------------------------- inv_cond


def _np_ref(J, norm, normalized):
    s = np.linalg.svd(J, compute_uv=False)
    if norm == "2":
        return s[..., -1] / s[..., 0]
    m = min(J.shape[-2:])
    r = 1.0 / (np.linalg.norm(J, axis=(-2, -1)) * np.linalg.norm(np.linalg.pinv(J), axis=(-2, -1)))
    return m * r if normalized else r


@jax.jit
def _all_norms(J):
    return inv_cond(J, "2"), inv_cond(J, "fro"), inv_cond(J, "fro", True)


@jax.jit
def _both_grads(J):
    return jax.grad(lambda A: jnp.sum(inv_cond(A, "2") + inv_cond(A, "fro")))(J)


SHAPES = [(1, 4), (2, 5), (3, 3), (3, 7), (6, 3), (4, 4), (6, 6), (5, 8), (7, 4)]


def test_inv_cond_matches_numpy():
    """Random shapes against numpy's SVD and pinv; row 0 of each batch is rank-deficient
    and must give exactly 0 (with a finite gradient)."""
    rng = np.random.default_rng(0)
    for shape in SHAPES:
        J = rng.normal(size=(40,) + shape)
        m = min(shape)
        if m > 1:
            J[0] = rng.normal(size=(shape[0], m - 1)) @ rng.normal(size=(m - 1, shape[1]))
        r2, rf, rfn = _all_norms(J)
        k = 1 if m > 1 else 0
        np.testing.assert_allclose(r2[k:], _np_ref(J, "2", False)[k:], rtol=1e-8)
        np.testing.assert_allclose(rf[k:], _np_ref(J, "fro", False)[k:], rtol=1e-8)
        np.testing.assert_allclose(rfn[k:], _np_ref(J, "fro", True)[k:], rtol=1e-8)
        if m > 1:
            assert [float(r2[0]), float(rf[0]), float(rfn[0])] == [0.0, 0.0, 0.0], shape
        if shape in ((2, 5), (3, 3), (4, 4)):  # (the gradients' compile time)
            assert np.all(np.isfinite(_both_grads(jnp.asarray(J))))


def test_inv_cond_special_cases():
    """Identity (isotropic: 1), zero (0), diag(1, 1, 2) (repeated Gram eigenvalues):
    values and finite gradients."""
    B = jnp.stack([jnp.eye(3), jnp.zeros((3, 3)), jnp.diag(jnp.array([1.0, 1.0, 2.0]))])
    r2, rf, rfn = _all_norms(B)
    np.testing.assert_allclose(r2, [1.0, 0.0, 0.5], rtol=1e-12)
    np.testing.assert_allclose(rfn, [1.0, 0.0, 3 / np.sqrt(6 * 2.25)], rtol=1e-12)
    assert np.all(np.isfinite(_both_grads(B)))
    B5 = jnp.stack([jnp.eye(5), jnp.zeros((5, 5))])
    r2, rf, rfn = _all_norms(B5)
    np.testing.assert_allclose(r2, [1.0, 0.0], rtol=1e-12)
    np.testing.assert_allclose(rfn, [1.0, 0.0], rtol=1e-12)
    assert np.all(np.isfinite(_both_grads(B5)))
    # 3×3 square Frobenius (the adjugate) against numpy's cond
    A = np.random.default_rng(0).normal(size=(50, 3, 3))
    np.testing.assert_allclose(_all_norms(A)[1], 1 / np.linalg.cond(A, "fro"), rtol=1e-12)


# ------------------------------------------------ #16 item 5: DHParams as params


def test_autodiff_jacobian_accepts_a_chains_own_dhparams():
    chain = DHChain(("R", "R"), "standard")
    P = DHParams(jnp.zeros(2), jnp.array([1.0, 0.5]), jnp.zeros(2), jnp.zeros(2))
    q = jnp.ones((5, 2))
    J = jax.jit(lambda q, P: position_jacobian(lambda q, p: chain.fk(p, q), q, P))(q, P)
    assert J.shape == (5, 3, 2)
    s1, s12, c1, c12 = np.sin(1), np.sin(2), np.cos(1), np.cos(2)
    np.testing.assert_allclose(
        J[0, :2], [[-s1 - 0.5 * s12, -0.5 * s12], [c1 + 0.5 * c12, 0.5 * c12]]
    )
    # a swarm of DHParams (M, 1, n) against q (C, n)
    Ps = DHParams(
        jnp.zeros((4, 1, 2)),
        jnp.array([1.0, 0.5]) * jnp.arange(1, 5.0)[:, None, None],
        jnp.zeros((4, 1, 2)),
        jnp.zeros((4, 1, 2)),
    )
    G = jax.jit(lambda q, P: geometric_jacobian(lambda q, p: chain.fk(p, q), q, P))(q, Ps)
    assert G.shape == (4, 5, 6, 2)
    np.testing.assert_allclose(G[2, 0, :3], 3 * np.asarray(J[0]), rtol=1e-12)
    # explicit event_ndim where the default rule is ambiguous (n == batch size)
    q2 = jnp.ones((2, 2))
    J2 = jax.jit(lambda q, P: position_jacobian(lambda q, p: chain.fk(p, q), q, P, event_ndim=1))(
        q2, P
    )
    np.testing.assert_allclose(J2[1], J[0], rtol=1e-12)
