"""Generic batched IK (designopt.kinematics.ik) and task regions (designopt.kinematics.task) against
independent references: FK round trips on random 6R chains (every success re-checked by
the kernel's own FK), targets that are certainly unreachable, a swarm against single
designs, the planar 2R over a disk (reach = area of the disk inside the annulus, task
GCI = a quadrature in r), and the samplers' moments."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate

from designopt.kinematics import ik
from designopt.kinematics import task as tk
from designopt.kinematics.conditioning import inv_cond
from designopt.kinematics.kernel import dh_model

PI = math.pi
SIX_R = dh_model("standard", "RRRRRR", [PI / 2, 0, -PI / 2, PI / 2, -PI / 2, 0],
                 ["a1", "a2", "a3", 0, 0, 0], ["d1", 0, "d3", "d4", 0, "d6"], [0] * 6)  # fmt: skip
PUMA = np.array([0.0, 0.4318, 0.0203, 0.0, 0.15005, 0.4318, 0.05])  # a1 a2 a3 d1 d3 d4 d6
LO6 = np.radians([-160, -110, -135, -266, -100, -266.0])
TWO_R = dh_model("standard", "RR", [0, 0], ["l1", "l2"], [0, 0], [0, 0])
LO2, HI2 = np.radians([-180.0, -180.0]), np.radians([180.0, 180.0])


def _fk_targets(model, X, lo, hi, n, seed):
    q = np.random.default_rng(seed).uniform(lo, hi, (n, len(lo)))
    R, p = model.fk(jnp.asarray(X), jnp.asarray(q))
    return p, R


# One compiled solver per mode for every 6R design and target set of 2048 targets (the
# chain's lengths and the joint limits are array inputs). ``slots`` only schedules the
# work (each target's seeds and steps do not depend on it; test_swarm_* checks this):
# 128 slots keep one phase, so one program to compile per mode.
N6 = 2048
OPTS6 = ik.IKOptions(slots=128)


@functools.cache
def _solver6(mode: str):
    return jax.jit(lambda x, p, R, lo, hi: ik.solve_design(SIX_R, x, p, R, lo, hi,
                                                           jax.random.key(3), mode, OPTS6))  # fmt: skip


def _reach(x) -> float:
    """An upper bound of the distance from the base to the tip: Σ|a| + Σ|d|."""
    return float(np.sum(np.abs(x)))


def _check_successes(x, r, p, R, lo, hi, mode):
    """Every reported success, re-checked by the kernel's own FK (XLA's sin and cos,
    numpy errors): position within 1e-9 × 2Σ (the solver's reach scale L is at most
    twice the reach bound), orientation within 1e-9 rad, joints within the limits; the
    reported position error is the true one."""
    ok = np.asarray(r.success)
    q = np.asarray(r.q)
    Rq, pq = (np.asarray(a) for a in SIX_R.fk(jnp.asarray(x), jnp.asarray(q)))
    pe = np.linalg.norm(pq - np.asarray(p), axis=-1)
    np.testing.assert_allclose(np.asarray(r.pos_err), pe, rtol=1e-9, atol=1e-15)
    assert np.all(pe[ok] <= 1e-9 * 2 * _reach(x)), pe[ok].max()
    Rt = np.asarray(R)
    if mode == "axis":
        z, zt = Rq[..., :, 2], Rt[..., :, 2]
        ang = np.arctan2(np.linalg.norm(np.cross(z, zt), axis=-1), np.sum(z * zt, -1))
        assert np.all(ang[ok] <= 1e-9), ang[ok].max()
    if mode == "pose":
        D = np.einsum("...ji,...jk->...ik", Rt, Rq)  # Rtᵀ Rq: the identity when solved
        assert np.all(np.abs(D - np.eye(3))[ok] <= 2e-9), np.abs(D - np.eye(3))[ok].max()
    assert np.all((q >= lo - 1e-15) & (q <= hi + 1e-15))


@pytest.mark.parametrize("mode", ik.MODES)
def test_fk_round_trips_on_random_6r_chains(mode):
    """Targets made by FK from random joints within the limits are solved at the default
    options: ≥ 99.9 % over the PUMA 560 and two random 6R chains of its structure (DH
    lengths drawn in [0.05, 0.5]; 3 × 2048 targets), ≥ 99.7 % on each, and every success
    checked by the kernel's own FK."""
    rng = np.random.default_rng(7)
    chains = [PUMA, rng.uniform(0.05, 0.5, 7), rng.uniform(0.05, 0.5, 7)]
    lo, hi = jnp.asarray(LO6), jnp.asarray(-LO6)
    rates = []
    for m, x in enumerate(chains):
        p, R = _fk_targets(SIX_R, x, LO6, -LO6, N6, m)
        r = _solver6(mode)(jnp.asarray(x), p, R, lo, hi)
        rates.append(float(np.mean(np.asarray(r.success))))
        _check_successes(x, r, p, R, LO6, -LO6, mode)
    assert min(rates) >= 0.997 and np.mean(rates) >= 0.999, rates


@settings(max_examples=6, deadline=None, derandomize=True)
@given(lengths=st.lists(st.floats(0.05, 0.5), min_size=7, max_size=7),
       half=st.lists(st.floats(60.0, 270.0), min_size=6, max_size=6),
       seed=st.integers(0, 2**31 - 1))  # fmt: skip
def test_random_chains_report_only_true_successes(lengths, half, seed):
    """On random 6R chains and random joint ranges: FK-made targets are nearly all
    solved, every success is true (independent FK), and targets beyond the reach bound
    Σ|a| + Σ|d| (certainly unreachable) are never successes."""
    x = np.asarray(lengths)
    lo, hi = -np.radians(half), np.radians(half)
    rng = np.random.default_rng(seed)
    p, R = _fk_targets(SIX_R, x, lo, hi, N6, seed)
    far = rng.normal(size=(256, 3))
    far *= _reach(x) * rng.uniform(1.01, 2.0, (256, 1)) / np.linalg.norm(far, axis=-1)[:, None]
    p = jnp.asarray(p).at[:256].set(far)
    r = _solver6("position")(jnp.asarray(x), p, R, jnp.asarray(lo), jnp.asarray(hi))
    ok = np.asarray(r.success)
    assert not ok[:256].any()
    assert ok[256:].mean() >= 0.995, ok[256:].mean()
    _check_successes(x, r, p, R, lo, hi, "position")


def test_swarm_rows_equal_single_designs():
    """``solve`` (designs sharing one queue, 96 slots) gives each design what
    ``solve_design`` (128 slots) gives it alone: the same success, joints and seeds
    (each target's seeds and steps do not depend on the scheduling)."""
    rng = np.random.default_rng(1)
    X = np.stack([PUMA, rng.uniform(0.05, 0.5, 7)])
    p, R = _fk_targets(SIX_R, X[1], LO6, -LO6, N6, 5)  # design 0 reaches only some
    lo, hi = jnp.asarray(LO6), jnp.asarray(-LO6)
    sw = jax.jit(lambda X: ik.solve(SIX_R, X, p, R, lo, hi, jax.random.key(3), "position",
                                    OPTS6._replace(slots=96)))(jnp.asarray(X))  # fmt: skip
    for m in range(2):
        r = _solver6("position")(jnp.asarray(X[m]), p, R, lo, hi)
        np.testing.assert_array_equal(np.asarray(sw.success[m]), np.asarray(r.success))
        np.testing.assert_array_equal(np.asarray(sw.seed[m]), np.asarray(r.seed))
        np.testing.assert_allclose(np.asarray(sw.q[m]), np.asarray(r.q), atol=1e-12)
    assert np.asarray(sw.success[1]).mean() >= 0.999
    assert 0.05 < np.asarray(sw.success[0]).mean() < 0.95


def test_n_best_keeps_the_best_conditioned_of_the_converged_seeds():
    """With ``n_best`` = 4 a target's solver goes on after its first converged seed and
    keeps the solution of highest score: every target solved alone is solved again,
    never with a worse 1/k (the first solution is among those compared), for many a
    better one (the PUMA 560's elbow and wrist branches differ in conditioning); a
    user score (here −1/k: the worst-conditioned) is honoured the same way."""
    p, R = _fk_targets(SIX_R, PUMA, LO6, -LO6, 512, 11)
    lo, hi = jnp.asarray(LO6), jnp.asarray(-LO6)

    def run(nb, score=None):
        o = OPTS6._replace(n_best=nb)
        return jax.jit(lambda x: ik.solve_design(SIX_R, x, p, R, lo, hi, jax.random.key(3),
                                                 "position", o, score))(jnp.asarray(PUMA))  # fmt: skip

    def inv_k(q):  # an independent 1/k of the position block: numpy's SVD
        J = np.asarray(SIX_R.jacobian(jnp.asarray(PUMA), jnp.asarray(q), rows=(0, 1, 2)))
        s = np.linalg.svd(J, compute_uv=False)
        return s[..., -1] / s[..., 0]

    one, four = run(1), run(4)
    worst = run(
        4,
        lambda m, t, q: (  # rows: design indices, target indices, joints (B, n)
            -inv_cond(
                jax.vmap(lambda q1: SIX_R.jacobian(jnp.asarray(PUMA), q1, rows=(0, 1, 2)))(q), "2"
            )
        ),
    )
    ok1, ok4 = np.asarray(one.success), np.asarray(four.success)
    assert ok1.mean() >= 0.999 and np.all(ok4[ok1])
    k1, k4, kw = inv_k(one.q), inv_k(four.q), inv_k(worst.q)
    np.testing.assert_allclose(np.asarray(four.inv_k), k4, atol=1e-9)
    both = ok1 & ok4
    assert np.all(k4[both] >= k1[both] - 1e-9)
    assert np.mean(k4[both] > k1[both] + 1e-3) > 0.2, np.mean(k4[both] > k1[both] + 1e-3)
    assert np.all(kw[both] <= k4[both] + 1e-9) and np.mean(kw[both] < k4[both] - 1e-3) > 0.2
    _check_successes(PUMA, four, p, R, LO6, -LO6, "position")


def test_a_failed_design_does_not_touch_the_others():
    """A NaN design in the swarm fails alone: the other designs of the same call solve
    exactly what they solve without it (the solver shares one queue and one runtime 1
    between the designs; that 1 used to come from design 0's reach scale)."""
    p, R = _fk_targets(TWO_R, [1.0, 0.6], LO2, HI2, 64, 4)
    lo, hi = jnp.asarray(LO2), jnp.asarray(HI2)
    o = ik.IKOptions(n_db=256, slots=32)
    f = jax.jit(lambda X: ik.solve(TWO_R, X, p, None, lo, hi, jax.random.key(0), "position", o))
    good = f(jnp.asarray([[1.0, 0.6], [1.0, 0.6]]))
    for X in ([[np.nan, 0.6], [1.0, 0.6]], [[1.0, 0.6], [np.nan, 0.6]]):
        r = f(jnp.asarray(X))
        bad = int(np.isnan(np.asarray(X)[:, 0]).argmax())
        assert not np.asarray(r.success[bad]).any()
        np.testing.assert_array_equal(np.asarray(r.success[1 - bad]), np.asarray(good.success[0]))
        np.testing.assert_array_equal(np.asarray(r.q[1 - bad]), np.asarray(good.q[0]))
    assert np.asarray(good.success).all()


@pytest.mark.parametrize("mode", ik.MODES)
def test_the_step_jacobian_is_the_residual_derivative_at_a_solution(mode):
    """J (e falls by J dq) against central differences of e where e = 0: the axis rows
    are ω less its roll about the tool axis, the pose rows ω."""
    q = jnp.asarray(np.random.default_rng(3).uniform(LO6, -LO6, (5, 6)))
    x = jnp.asarray(PUMA)
    Rt, pt = SIX_R.fk(x, q)
    e, J, _, _ = ik.residual(SIX_R, x, q, pt, Rt, mode, 0.9)
    h = 1e-6
    de = [(ik.residual(SIX_R, x, q.at[:, j].add(h), pt, Rt, mode, 0.9)[0]
           - ik.residual(SIX_R, x, q.at[:, j].add(-h), pt, Rt, mode, 0.9)[0]) / (2 * h)
          for j in range(6)]  # fmt: skip
    assert np.abs(np.asarray(e)).max() < 1e-15
    np.testing.assert_allclose(np.asarray(J), -np.stack(de, -1), atol=1e-8)


def test_sincos_matches_numpy():
    x = np.concatenate([np.linspace(-1000, 1000, 200_001), np.arange(-64, 65) * np.pi / 4])
    s, c = jax.jit(ik._sincos)(jnp.asarray(x))
    assert np.max(np.abs(np.asarray(s) - np.sin(x))) < 3e-16
    assert np.max(np.abs(np.asarray(c) - np.cos(x))) < 3e-16


def test_nearest_finds_an_entry_at_its_own_position():
    """A target placed on a database entry finds that entry first (distance 0 lies in
    its own Z-order window); the others come from the window in increasing distance."""
    rng = np.random.default_rng(2)
    q_db = jnp.asarray(rng.uniform(LO6, -LO6, (1000, 6)))
    R_db, p_db = SIX_R.fk(jnp.asarray(PUMA), q_db)
    L = jnp.asarray(1.0)
    index = jax.jit(ik._index, static_argnums=4)(q_db, p_db, R_db, L, "pose")
    pick = rng.choice(1000, 300, replace=False)
    nearest = jax.jit(ik._nearest, static_argnums=(4, 5, 6))
    near = np.asarray(nearest(index, p_db[pick], R_db[pick], L, "pose", 4, 32))
    np.testing.assert_array_equal(np.asarray(index[4])[near[:, 0]], np.asarray(q_db)[pick])
    f_db = np.asarray(index[3]).T[near]  # (300, 4, F)
    f_t = np.asarray(ik._features(p_db[pick], R_db[pick], L, "pose"))[:, None]
    d = np.sum((f_db - f_t) ** 2, -1)
    assert np.all(np.diff(d, axis=1) >= 0)


@jax.jit
def _solve_2r(x, p):
    """The planar 2R's position IK: one compiled program for every design and target set
    of the same size (the lengths are array inputs)."""
    return ik.solve_design(TWO_R, x, p, None, jnp.asarray(LO2), jnp.asarray(HI2),
                           jax.random.key(4), "position")  # fmt: skip


def test_unreachable_targets_are_failures():
    x = jnp.asarray([1.0, 0.5])
    far = jnp.array([[2.0, 0.0, 0.0], [0.0, 1.6, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.3]])
    r = _solve_2r(x, far)
    assert not np.any(np.asarray(r.success))  # beyond l1+l2, inside |l1−l2|, off the plane
    assert np.all(np.asarray(r.pos_err) > 1e-3)


def test_unreachable_tool_axes_are_failures():
    """The planar 2R's tool z axis is always the base z axis: reachable positions with a
    tilted axis are failures in ``axis`` mode, the untilted ones successes."""
    p = jnp.array([[1.2, 0.3, 0.0], [0.8, -0.5, 0.0], [1.0, 0.0, 0.0], [0.0, 1.1, 0.0]])
    tilt = np.radians([0.0, 1e-6, 30.0, 90.0])
    c, s, z = np.cos(tilt), np.sin(tilt), np.zeros(4)
    R = np.stack([[z + 1, z, z], [z, c, -s], [z, s, c]]).transpose(2, 0, 1)  # Rx(tilt)
    r = jax.jit(lambda p, R: ik.solve_design(TWO_R, jnp.asarray([1.0, 0.5]), p, R, jnp.asarray(LO2),
                                             jnp.asarray(HI2), jax.random.key(4), "axis"))(p, jnp.asarray(R))  # fmt: skip
    np.testing.assert_array_equal(np.asarray(r.success), [True, False, False, False])
    np.testing.assert_allclose(np.asarray(r.rot_err)[1:], tilt[1:], rtol=1e-6)


def _two_r_reference(l1: float, l2: float, radius: float) -> tuple[float, float]:
    """(reach, task GCI) of the planar 2R over the disk of ``radius`` about its base, by
    quadrature in r: reach = |disk ∩ annulus| / |disk|; 1/k (2-norm) depends on q2 only,
    cos q2 = (r² − l1² − l2²) / (2 l1 l2)."""

    def inv_k(r):
        c2 = (r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2)
        s2 = math.sqrt(max(1 - c2 * c2, 0.0))
        J = np.array([[-l1 - l2 * c2, -l2 * c2], [l2 * s2, l2 * s2]])  # rotated frame
        s = np.linalg.svd(J, compute_uv=False)
        return s[-1] / s[0]

    lo, hi = abs(l1 - l2), min(l1 + l2, radius)
    area = PI * radius**2
    reach = (PI * (hi**2 - lo**2)) / area if hi > lo else 0.0
    gci = integrate.quad(lambda r: inv_k(r) * 2 * PI * r, lo, hi, limit=200)[0] / area
    return reach, gci


@pytest.mark.parametrize("l1,l2,radius", [(1.0, 0.7, 1.5), (1.0, 0.4, 1.6), (0.8, 0.8, 1.0)])
def test_two_r_over_a_disk_matches_the_quadrature(l1, l2, radius):
    """Reach and task GCI from IK at sampled disk targets agree with the quadrature within
    4 standard errors, for designs that reach the whole disk and designs that do not."""
    region = tk.Cylinder(shape="cylinder", center=(0, 0, 0), radius=radius, height=0)
    p = tk.sample_region("cylinder", tk.region_params(region), jax.random.key(3), 4000)
    r = _solve_2r(jnp.asarray([l1, l2]), p)
    ok = np.asarray(r.success, np.float64)
    g = np.asarray(r.inv_k) * ok
    reach_ref, gci_ref = _two_r_reference(l1, l2, radius)
    n = len(ok)
    se_reach = max(math.sqrt(ok.mean() * (1 - ok.mean()) / n), 1e-12)
    se_gci = max(g.std(ddof=1) / math.sqrt(n), 1e-12)
    assert abs(ok.mean() - reach_ref) <= 4 * se_reach + 1e-12, (ok.mean(), reach_ref, se_reach)
    assert abs(g.mean() - gci_ref) <= 4 * se_gci, (g.mean(), gci_ref, se_gci)


def test_region_samplers_have_the_right_moments():
    key, n = jax.random.key(0), 200_000
    ball = tk.Ball(shape="ball", center=(1, 2, 3), radius=2.0)
    r = np.linalg.norm(np.asarray(tk.sample_region("ball", tk.region_params(ball), key, n))
                       - [1, 2, 3], axis=-1)  # fmt: skip
    assert abs(r.mean() - 0.75 * 2.0) < 4 * r.std() / math.sqrt(n)  # E r = 3R/4
    cyl = tk.Cylinder(shape="cylinder", center=(0, 0, 1), axis=(1, 0, 0), radius=1.0, height=2.0)
    c = np.asarray(tk.sample_region("cylinder", tk.region_params(cyl), key, n))
    rad = np.hypot(c[:, 1], c[:, 2] - 1)
    assert abs(rad.mean() - 2 / 3) < 4 * rad.std() / math.sqrt(n)  # E r = 2R/3 in a disk
    assert np.all(np.abs(c[:, 0]) <= 1.0) and abs(c[:, 0].mean()) < 0.01
    cone = tk.Cone(shape="cone", apex=(0, 0, 0), axis=(0, 0, -1), half_angle=30, depth=(0.05, 0.15))
    s = -np.asarray(tk.sample_region("cone", tk.region_params(cone), key, n))[:, 2]
    d0, d1 = 0.05, 0.15  # density ∝ s² on [d0, d1]: E s = 3/4 (d1⁴ − d0⁴) / (d1³ − d0³)
    assert abs(s.mean() - 0.75 * (d1**4 - d0**4) / (d1**3 - d0**3)) < 4 * s.std() / math.sqrt(n)
    pts = np.asarray(tk.sample_region("cone", tk.region_params(cone), key, n))
    ang = np.degrees(np.arctan2(np.hypot(pts[:, 0], pts[:, 1]), -pts[:, 2]))
    assert ang.max() <= 30 + 1e-9
    box = tk.Box(shape="box", center=(0, 0, 0), size=(1, 2, 0))
    b = np.asarray(tk.sample_region("box", tk.region_params(box), key, n))
    assert np.all(b[:, 2] == 0) and np.all(np.abs(b[:, 1]) <= 1)


def test_tool_axes_fill_their_cone():
    z = np.asarray(tk.sample_axes((0, 0, -1), 20.0, jax.random.key(1), 100_000))
    cos = -z[:, 2]
    assert np.all(cos >= math.cos(math.radians(20)) - 1e-12)
    assert abs(cos.mean() - (1 + math.cos(math.radians(20))) / 2) < 1e-3  # uniform on the cap
    np.testing.assert_allclose(np.linalg.norm(z, axis=-1), 1.0, atol=1e-12)


def test_the_task_schema_defaults_are_the_solvers():
    """``study.task.ik`` names every solver option, with the solver's defaults but for
    ``n_best``, ``climb`` and ``neighbours``: the task's defaults keep the index's
    definition, the best free solution (8 distinct solutions, each climbed 12 steps, a
    second pass from 4 neighbours'; issue #65), the solver alone keeps the first."""
    from designopt.studies.serial.settings import TaskIK

    schema = {k: f.default for k, f in TaskIK.model_fields.items() if k != "best"}
    assert set(schema) == set(ik.IKOptions._fields)  # (``best`` picks the score: the study's)
    assert schema | {"n_best": 1, "climb": 0, "neighbours": 0} == ik.DEFAULTS._asdict()
    assert (schema["n_best"], schema["climb"], schema["neighbours"]) == (8, 12, 4)


def test_the_task_schema_refuses_more_nearest_seeds_than_the_window():
    from pydantic import ValidationError

    from designopt.studies.serial.settings import TaskIK

    with pytest.raises(ValidationError, match=r"n_nearest \(8\) exceeds window \(4\)"):
        TaskIK(n_nearest=8, window=4)
    assert TaskIK(n_nearest=4, window=4).window == 4
