"""Generic batched IK (designopt.kinematics.ik) and task regions (designopt.task) against
independent references: FK round trips on random 6R chains, unreachable targets, the
planar 2R over a disk (reach = area of the disk inside the annulus, task GCI = a
quadrature in r), and the samplers' moments."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

from designopt import task as tk
from designopt.kinematics import ik
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


@pytest.fixture(scope="module")
def random_chains():
    """The PUMA 560 and two random 6R chains of the same structure (DH lengths drawn in
    [0.05, 0.5]), as three designs of one compiled solver."""
    rng = np.random.default_rng(7)
    X = np.stack([PUMA, rng.uniform(0.05, 0.5, 7), rng.uniform(0.05, 0.5, 7)])
    return jnp.asarray(X)


@pytest.mark.parametrize("mode,rate", [("position", 0.99), ("axis", 0.98), ("pose", 0.98)])
def test_fk_round_trips_on_random_chains(random_chains, mode, rate):
    """Targets made by FK from random joints within the limits are solved (success rate
    ≥ ``rate`` per chain), and every success meets the target to 1e-9."""
    opts = ik.IKOptions(iters=30, rounds=1, n_nearest=4, n_random=4, n_db=2048)
    solve = jax.jit(lambda x, p, R, k: ik.solve_design(SIX_R, x, p, R, jnp.asarray(LO6),
                                                       jnp.asarray(-LO6), k, mode, opts))  # fmt: skip
    for m, x in enumerate(random_chains):
        p, R = _fk_targets(SIX_R, x, LO6, -LO6, 128, m)
        r = solve(x, p, R, jax.random.key(m))
        ok = np.asarray(r.success)
        assert ok.mean() >= rate, (m, ok.mean())
        # the solution's own FK (an independent evaluation) meets the target
        Rq, pq = SIX_R.fk(x, r.q)
        L = float(np.max(np.linalg.norm(np.asarray(pq), axis=-1)))
        assert np.max(np.linalg.norm(np.asarray(pq - p), axis=-1)[ok]) <= 1e-9 * max(L, 1.0) * 10
        if mode == "axis":
            cosang = np.sum(np.asarray(Rq[:, :, 2] * R[:, :, 2]), -1)
            assert np.all(cosang[ok] > 1 - 1e-12)
        if mode == "pose":
            np.testing.assert_allclose(np.asarray(Rq)[ok], np.asarray(R)[ok], atol=1e-8)
        assert np.all((np.asarray(r.q) >= LO6 - 1e-12) & (np.asarray(r.q) <= -LO6 + 1e-12))


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
