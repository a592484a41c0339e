"""Collision geometry (``designopt.kinematics.collision``) against brute force in NumPy.

The references sample the primitives densely: N = 2001 evenly spaced points on each
segment. Sampled points lie on the shapes, so a sampled minimum is never below the exact
one, and it exceeds it by at most half a sample spacing on each segment (distances are
1-Lipschitz in each point): 0 ≤ brute − exact ≤ (|A| + |B|) / (2 (N − 1)). The tests
check the computed distance against that window (the box's golden-section search may
exceed the exact value by its bound, 2e-10·|A|, see the module docstring).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pydantic
import pytest
import yaml

from designopt.kinematics import collision as C

N = 2001


def _pts(a, b, n=N):
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.asarray(a, float) + t * (np.asarray(b, float) - np.asarray(a, float))


def _spacing(a, b, n=N):
    return np.linalg.norm(np.subtract(b, a)) / (n - 1)


def bf_seg_seg(a0, a1, b0, b1):
    """Min over 2001 × 2001 sample pairs of the two segments."""
    P, Q = _pts(a0, a1), _pts(b0, b1)
    return min(np.sqrt(((p[:, None] - Q[None]) ** 2).sum(-1)).min() for p in np.array_split(P, 8))


def bf_box_sdf(P, c, h):
    """Exact signed distance of points P to the box [c − h, c + h], written independently
    of the module's formula: outside, the distance to the clamped point; inside, minus the
    distance to the nearest face."""
    lo, hi = np.asarray(c) - h, np.asarray(c) + h
    inside = np.all((P >= lo) & (P <= hi), -1)
    out = np.linalg.norm(P - np.clip(P, lo, hi), axis=-1)
    depth = np.minimum(P - lo, hi - P).min(-1)
    return np.where(inside, -depth, out)


def bf_seg_box(a0, a1, c, h, levels=1):
    """Min of the box SDF over segment samples; each further level resamples ±1 spacing
    about the best sample (the SDF is convex along the segment, so the minimiser is
    there), shrinking the sampling error by a factor 1000."""
    a0, a1 = np.asarray(a0, float), np.asarray(a1, float)
    lo, hi = 0.0, 1.0
    for _ in range(levels):
        s = np.linspace(lo, hi, N)
        g = bf_box_sdf(a0 + s[:, None] * (a1 - a0), c, h)
        k = int(np.argmin(g))
        step = (hi - lo) / (N - 1)
        lo, hi = max(s[k] - step, 0.0), min(s[k] + step, 1.0)
    return g[k], (hi - lo) / 2 * np.linalg.norm(a1 - a0)  # value, its sampling bound


def f64(x):
    return jnp.asarray(x, jnp.float64)


# jitted once per shape (eager calls compile every operation on its own, far slower)
seg_seg = jax.jit(C.segment_segment)
cap_cap = jax.jit(C.capsule_capsule)
cap_ball = jax.jit(C.capsule_ball)
cap_half = jax.jit(C.capsule_halfspace)
cap_box = jax.jit(C.capsule_box)
terms = jax.jit(C.clearance_terms, static_argnames=("self_pairs",))
clear = jax.jit(C.clearance, static_argnames=("self_pairs",))
arms = jax.jit(C.arms_clearance)


# --------------------------------------------------------------------------- cases

_rng = np.random.default_rng(20261126)
_X = np.array([1.0, 0, 0])
SEG_CASES = {
    **{f"random{i}": tuple(_rng.uniform(-1, 1, (4, 3))) for i in range(8)},
    "crossing": ([-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]),
    "skew": ([-1, 0, 0], [1, 0, 0], [0.3, -1, 0.5], [0.3, 1, 0.5]),
    "parallel": ([0, 0, 0], [1, 0, 0], [0.2, 0.3, 0.1], [1.4, 0.3, 0.1]),
    "antiparallel": ([0, 0, 0], [1, 0, 0], [1.4, 0.3, 0], [0.2, 0.3, 0]),
    "parallel_apart": ([0, 0, 0], [1, 0, 0], [1.5, 0.3, 0], [2.5, 0.3, 0]),
    "collinear_overlap": ([0, 0, 0], [1, 0, 0], [0.5, 0, 0], [1.5, 0, 0]),
    "collinear_apart": ([0, 0, 0], [1, 0, 0], [1.25, 0, 0], [2, 0, 0]),
    "nearly_parallel": ([0, 0, 0], [1, 0, 0], [0, 1e-3, 0.2], [1, -1e-3, 0.2]),
    "t_junction": ([0, 0, 0], [1, 0, 0], [0.5, 0, 0], [0.5, 1, 0]),
    "zero_a": ([0.3, 0.4, 0], [0.3, 0.4, 0], [-1, 0, 0], [1, 0, 0]),
    "zero_a_on_b": ([0.25, 0, 0], [0.25, 0, 0], [-1, 0, 0], [1, 0, 0]),
    "zero_both": ([0, 0, 0], [0, 0, 0], [0.3, 0.4, 0], [0.3, 0.4, 0]),
    "zero_b_beyond_end": ([0, 0, 0], [1, 0, 0], [2, 1, 0], [2, 1, 0]),
    "same": ([0, 0, 0], [1, 1, 1], [0, 0, 0], [1, 1, 1]),
}


@pytest.mark.parametrize("name", sorted(SEG_CASES))
def test_segment_segment_matches_sampling(name):
    a0, a1, b0, b1 = (np.asarray(v, float) for v in SEG_CASES[name])
    ours = float(seg_seg(f64(a0), f64(a1), f64(b0), f64(b1)))
    ref = bf_seg_seg(a0, a1, b0, b1)
    tol = (_spacing(a0, a1) + _spacing(b0, b1)) / 2
    assert -1e-12 <= ref - ours <= tol + 1e-12, (ours, ref, tol)
    # symmetric, and the same with the segments reversed
    for args in [(b0, b1, a0, a1), (a1, a0, b1, b0)]:
        assert abs(float(seg_seg(*map(f64, args))) - ours) < 1e-12


def test_segment_segment_known_values():
    s = seg_seg
    assert float(s(f64([-1, 0, 0]), f64([1, 0, 0]), f64([0, -1, 2]), f64([0, 1, 2]))) == 2.0
    d = float(s(f64([0, 0, 0]), f64([1, 0, 0]), f64([3, 4, 0]), f64([3, 4, 0])))
    assert d == pytest.approx(math.hypot(2, 4), abs=1e-15)  # from the end (1, 0, 0)
    # nearly parallel: the closest points are inside both (the 'inside' candidate)
    d = float(s(f64([0, 0, 0]), f64([1, 0, 0]), f64([0, 1e-3, 0.2]), f64([1, -1e-3, 0.2])))
    assert abs(d - 0.2) < 1e-12


@pytest.mark.parametrize("name", ["random0", "random1", "parallel", "crossing", "zero_a"])
def test_capsule_capsule_and_ball_sign(name):
    a0, a1, b0, b1 = (np.asarray(v, float) for v in SEG_CASES[name])
    ref = bf_seg_seg(a0, a1, b0, b1)
    tol = (_spacing(a0, a1) + _spacing(b0, b1)) / 2 + 1e-12
    for ra, rb in [(0.05, 0.1), (0.5, 0.7)]:
        d = float(cap_cap(f64(a0), f64(a1), ra, f64(b0), f64(b1), rb))
        exact_window = (ref - tol - ra - rb, ref - ra - rb + 1e-12)
        assert exact_window[0] <= d <= exact_window[1]
        if abs(ref - ra - rb) > tol:  # clearly apart or clearly overlapping: same sign
            assert np.sign(d) == np.sign(ref - ra - rb)
    # a ball is a zero-length capsule; sample the segment against the ball's centre
    P = _pts(a0, a1)
    refb = np.linalg.norm(P - b0, axis=-1).min() - 0.1 - 0.2
    d = float(cap_ball(f64(a0), f64(a1), 0.1, f64(b0), 0.2))
    assert -1e-12 <= refb - d <= _spacing(a0, a1) / 2 + 1e-12


def test_touching_capsules_are_at_zero():
    # the common normal of these skew lines is z; offset by ra + rb exactly
    d = cap_cap(f64([-1, 0, 0]), f64([1, 0, 0]), 0.25,
                          f64([0.2, -1, 0.75]), f64([0.2, 1, 0.75]), 0.5)  # fmt: skip
    assert abs(float(d)) < 1e-15
    d = cap_cap(f64([0, 0, 0]), f64([1, 0, 0]), 0.25, f64([2, 0, 0]), f64([3, 0, 0]), 0.75)
    assert abs(float(d)) < 1e-15
    d = cap_ball(f64([0, 0, 0]), f64([1, 0, 0]), 0.1, f64([0.5, 0.3, 0]), 0.2)
    assert abs(float(d)) < 1e-15


def test_capsule_halfspace_exact():
    n = np.array([0.0, 0.6, 0.8])
    p = np.array([0.1, -0.2, 0.3])
    for a0, a1 in _rng.uniform(-1, 1, (10, 2, 3)):
        ref = ((_pts(a0, a1) - p) @ n).min() - 0.05  # linear: the ends are sampled exactly
        d = float(cap_half(f64(a0), f64(a1), 0.05, f64(p), f64(n)))
        assert abs(d - ref) < 1e-12
    # below a table at z = 0 by 0.3 with radius 0.1: penetration 0.4
    d = cap_half(f64([0, 0, 1]), f64([0, 0, -0.3]), 0.1, f64([0, 0, 0]), f64([0, 0, 1]))
    assert abs(float(d) + 0.4) < 1e-15


BOX_C, BOX_H = np.array([0.2, -0.1, 0.3]), np.array([0.5, 0.25, 0.4])
BOX_CASES = {
    **{f"random{i}": tuple(_rng.uniform(-1.5, 1.5, (2, 3))) for i in range(8)},
    "past_edge": ([1.0, -1.0, 0.35], [1.0, 1.0, 0.25]),
    "past_vertex": ([1.2, 0.5, 0.9], [0.5, 0.5, 1.4]),
    "parallel_to_face": ([-0.5, 0.5, 0.0], [0.9, 0.5, 0.0]),
    "through": ([-1.0, 0.0, 0.3], [1.4, -0.2, 0.3]),
    "fully_inside": ([0.0, -0.1, 0.2], [0.4, 0.0, 0.5]),
    "one_end_inside": ([0.3, -0.05, 0.3], [1.5, 1.0, 1.0]),
    "zero_length_outside": ([1.0, 1.0, 1.0], [1.0, 1.0, 1.0]),
    "zero_length_inside": ([0.25, -0.1, 0.3], [0.25, -0.1, 0.3]),
    "along_the_axis_through_centre": ([0.2, -0.1, -1.0], [0.2, -0.1, 1.6]),
}


@pytest.mark.parametrize("name", sorted(BOX_CASES))
def test_capsule_box_matches_sampling(name):
    a0, a1 = (np.asarray(v, float) for v in BOX_CASES[name])
    L = np.linalg.norm(a1 - a0)
    r = 0.07
    d = float(cap_box(f64(a0), f64(a1), r, f64(BOX_C), f64(BOX_H)))
    # one level: plain dense sampling; three levels: resolution ~1e-10·L, which checks
    # the golden-section error bound 2e-10·L
    for levels, slack in [(1, 0.0), (3, 2e-10 * L)]:
        ref, tol = bf_seg_box(a0, a1, BOX_C, BOX_H, levels)
        assert -2e-10 * L - 1e-12 <= ref - r - d <= tol + slack + 1e-12, (levels, d, ref, tol)
    if abs(ref - r) > 1e-9:
        assert np.sign(d) == np.sign(ref - r)
    assert np.isclose(float(C.box_sdf(f64(a0), f64(BOX_C), f64(BOX_H))),
                      bf_box_sdf(a0[None], BOX_C, BOX_H)[0], rtol=0, atol=1e-14)  # fmt: skip


def test_capsule_box_signs():
    h = f64([0.5, 0.5, 0.5])
    inside = cap_box(f64([-0.1, 0, 0]), f64([0.1, 0, 0]), 0.05, f64([0, 0, 0]), h)
    assert float(inside) == pytest.approx(-0.55, abs=1e-12)  # centre line 0.5 deep, plus r
    apart = cap_box(f64([0.8, -1, 0]), f64([0.8, 1, 0]), 0.1, f64([0, 0, 0]), h)
    assert float(apart) == pytest.approx(0.2, abs=1e-12)


# --------------------------------------------------------------------------- gradients


def _fd(f, x, h=1e-6):
    g = np.zeros_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = h
        g.flat[i] = (float(f(f64(x + e))) - float(f(f64(x - e)))) / (2 * h)
    return g


@jax.jit
def _cc(x):
    return cap_cap(x[0:3], x[3:6], x[12], x[6:9], x[9:12], x[13])


@jax.jit
def _cb(x):
    return cap_box(x[0:3], x[3:6], x[6], x[7:10], x[10:13])


@pytest.mark.parametrize(
    "x",
    [
        # closest points inside both segments; an end against the other's inside; ends
        [-1, 0, 0, 1, 0.2, 0, 0.3, -1, 0.5, 0.1, 1, 0.7, 0.1, 0.2],
        [0, 0, 0, 1, 0, 0, 1.5, -1, 0.3, 1.6, 1, 0.2, 0.05, 0.05],
        [0, 0, 0, 1, 0.1, 0, 1.5, 0.5, 0.3, 2.5, 0.9, 0.2, 0.05, 0.05],
    ],
)
def test_capsule_capsule_gradient_matches_finite_differences(x):
    x = np.asarray(x, float)
    g = np.asarray(jax.grad(_cc)(f64(x)))
    np.testing.assert_allclose(g, _fd(_cc, x), atol=1e-7)


@pytest.mark.parametrize(
    "x",
    [
        # passing a box edge (minimum inside the segment), near a face, near a vertex
        [1.0, -1.0, 0.35, 1.05, 1.0, 0.25, 0.05, 0.2, -0.1, 0.3, 0.5, 0.25, 0.4],
        [-0.5, 0.6, 0.0, 0.9, 0.55, 0.1, 0.05, 0.2, -0.1, 0.3, 0.5, 0.25, 0.4],
        [1.2, 0.5, 0.9, 0.9, 0.6, 1.4, 0.05, 0.2, -0.1, 0.3, 0.5, 0.25, 0.4],
    ],
)
def test_capsule_box_gradient_matches_finite_differences(x):
    x = np.asarray(x, float)
    g = np.asarray(jax.grad(_cb)(f64(x)))
    np.testing.assert_allclose(g, _fd(_cb, x), atol=1e-6)


@pytest.mark.parametrize(
    "a0,a1,b0,b1",
    [
        ([0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]),  # parallel
        ([0, 0, 0], [1, 0, 0], [0.5, 0, 0], [1.5, 0, 0]),  # collinear, overlapping
        ([0.3, 0.3, 0], [0.3, 0.3, 0], [0, 0, 0], [1, 0, 0]),  # zero-length a
        ([0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]),  # zero-length, coincident
        ([-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]),  # centre lines cross
        ([0, 0, 0], [1, 1, 1], [0, 0, 0], [1, 1, 1]),  # the same segment
    ],
)
def test_gradients_have_no_nan(a0, a1, b0, b1):
    x = f64([*a0, *a1, *b0, *b1, 0.1, 0.1])
    assert np.all(np.isfinite(np.asarray(jax.grad(_cc)(x))))
    for p0, p1 in [(a0, a1), (b0, b1)]:
        y = f64([*p0, *p1, 0.1, 0, 0, 0, 0.5, 0.5, 0.5])  # through/at the box's centre
        assert np.all(np.isfinite(np.asarray(jax.grad(_cb)(y))))
        z = f64([*p0, *p1, 0.1, 0.3, 0.3, 0, 0, 0, 0])  # a box of size zero
        assert np.all(np.isfinite(np.asarray(jax.grad(_cb)(z))))


# --------------------------------------------------------------------------- an arm


def test_nonadjacent_pairs():
    assert C.nonadjacent_pairs(0) == () and C.nonadjacent_pairs(2) == ()
    assert C.nonadjacent_pairs(3) == ((0, 2),)
    assert C.nonadjacent_pairs(4) == ((0, 2), (0, 3), (1, 3))
    assert len(C.nonadjacent_pairs(7)) == 15  # C(7, 2) − 6 adjacent pairs


def _config():
    return C.Collision.model_validate(yaml.safe_load("""
        links: auto
        radius: 0.1
        self: true
        obstacles:
          - {shape: ball, center: [2, 0.5, 0], radius: 0.3}
          - {shape: capsule, a: [-1, -1, 0.5], b: [-1, 1, 0.5], radius: 0.05}
          - {shape: box, center: [3, 0, 0], size: [1, 1, 1]}
          - {shape: halfspace, point: [0, 0, -0.5], normal: [0, 0, 2]}
        margin: 0.02
    """))  # fmt: skip


# a planar 3-link arm: along x, up y, then folded back towards the first link
ARM = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0.5, 0.3, 0]], float)


def test_clearance_hand_made_arm():
    cfg = _config()
    seg = C.link_segments(f64(ARM))
    assert seg.shape == (3, 2, 3)
    r = cfg.link_radii(3)
    params = cfg.params()
    obs, own = terms(seg, r, params, C.nonadjacent_pairs(3))
    # ball: link 1 (x = 1, y in [0, 1]) is 1 from the centre: 1 − 0.1 − 0.3; capsule
    # obstacle: 1.118 − 0.15 from the base; box: 1.5 − 0.1 (x face at 2.5, from x = 1);
    # table 0.5 below: 0.5 − 0.1 — the least is the table
    assert float(obs) == pytest.approx(0.4, abs=1e-12)
    assert float(own) == pytest.approx(0.3 - 0.2, abs=1e-12)  # link 2's end 0.3 above link 0
    c = clear(seg, r, params, C.nonadjacent_pairs(3), margin=cfg.margin)
    assert float(c) == pytest.approx(0.1 - 0.02, abs=1e-12)
    # per kind: only the ball
    only_ball = C.obstacle_params([cfg.obstacles[0]])
    assert float(clear(seg, r, only_ball)) == pytest.approx(0.6, abs=1e-12)
    box = C.obstacle_params([cfg.obstacles[2]])
    assert float(clear(seg, r, box)) == pytest.approx(1.4, abs=1e-10)
    # nothing to check: +inf, with finite (zero) gradients
    assert float(clear(seg, r)) == math.inf
    g = jax.grad(lambda s: jnp.minimum(clear(s, r, C.obstacle_params([])), 1.0))(seg)
    assert np.all(np.asarray(g) == 0)


def test_clearance_batched_float32_and_jit():
    cfg = _config()
    rng = np.random.default_rng(5)
    X = f64(rng.uniform(-1, 1, (4, 3, 5, 3)))  # designs × targets × 5 joint origins
    seg = C.link_segments(X)
    assert seg.shape == (4, 3, 4, 2, 3)
    radii = f64([0.05, 0.04, 0.03, 0.02])
    pairs = C.nonadjacent_pairs(4)
    f = jax.jit(C.clearance_terms, static_argnames=("self_pairs",))
    obs, own = f(seg, radii, cfg.params(), self_pairs=pairs)
    assert obs.shape == own.shape == (4, 3)
    for i in range(4):
        for j in range(3):  # one sample at a time (one more compile, same program)
            o1, s1 = f(seg[i, j], radii, cfg.params(), self_pairs=pairs)
            assert float(o1) == pytest.approx(float(obs[i, j]), abs=1e-12)
            assert float(s1) == pytest.approx(float(own[i, j]), abs=1e-12)
    o32, s32 = f(seg.astype(jnp.float32), radii.astype(jnp.float32), cfg.params(jnp.float32),
                 self_pairs=pairs)  # fmt: skip
    assert o32.dtype == s32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(o32), np.asarray(obs), atol=2e-6)
    np.testing.assert_allclose(np.asarray(s32), np.asarray(own), atol=2e-6)
    g = jax.jit(jax.grad(lambda s: jnp.sum(clear(s, radii, cfg.params(), pairs))))(seg)
    assert np.all(np.isfinite(np.asarray(g))) and np.any(np.asarray(g) != 0)


def test_clearance_refuses_bad_pairs():
    seg = C.link_segments(f64(ARM))
    with pytest.raises(ValueError, match="self_pairs"):
        clear(seg, 0.1, None, ((0, 3),))


def test_arms_clearance():
    a = C.link_segments(f64([[0, 0, 0], [1, 0, 0], [2, 0, 0]]))
    b = C.link_segments(f64([[0, 2, 1], [1, 2, 1], [2.5, 0, 1]]))
    # every link of a against every link of b, by dense sampling
    ref = min(bf_seg_seg(*a[i], *b[j]) for i in range(2) for j in range(2))
    d = float(arms(a, f64([0.1, 0.1]), b, 0.2))
    assert -1e-12 <= ref - 0.3 - d <= 2 * 2.5 / (N - 1)
    # batched: (designs, La) against (designs, Lb)
    A = jnp.stack([a, a + 1.0])
    B = jnp.stack([b, b])
    dd = arms(A, 0.1, B, 0.2)
    assert dd.shape == (2,) and float(dd[0]) == pytest.approx(d, abs=1e-12)


# --------------------------------------------------------------------------- config


def test_config_parses_and_params():
    cfg = _config()
    assert cfg.self_ is True and cfg.links == "auto" and cfg.margin == 0.02
    assert cfg.model_dump(by_alias=True)["self"] is True
    p = cfg.params(jnp.float32)
    assert p["ball"]["c"].shape == (1, 3) and p["box"]["half"].dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(p["halfspace"]["n"]), [[0, 0, 1]])
    np.testing.assert_allclose(np.asarray(p["box"]["half"]), [[0.5, 0.5, 0.5]])
    as_dicts = C.obstacle_params([o.model_dump() for o in cfg.obstacles], jnp.float32)
    assert jax.tree.all(jax.tree.map(lambda u, v: bool(jnp.all(u == v)), p, as_dicts))
    with pytest.raises(pydantic.ValidationError, match="unknown obstacle shape"):
        C.obstacle_params([{"shape": "cone"}])
    empty = C.obstacle_params([])
    assert all(v.shape[0] == 0 for g in empty.values() for v in g.values())
    lst = C.Collision.model_validate({"radius": [0.1, 0.2], "self": False})
    assert lst.link_radii(2) == (0.1, 0.2) and lst.self_ is False
    with pytest.raises(ValueError, match="2 radii but the chain has 3 links"):
        lst.link_radii(3)
    # links: urdf takes the URDF's shapes' radii; auto needs one
    assert C.Collision.model_validate({"links": "urdf", "self": False}).radius is None
    with pytest.raises(ValueError, match="shapes give the radii"):
        C.Collision.model_validate({"links": "urdf", "radius": 0.1})
    # links: auto without a radius: the study refuses it (unless each arm gives its own)
    assert C.Collision.model_validate({"links": "auto"}).radius is None
    assert C.Collision(radius=0.1, self_=False).self_ is False  # by name from Python


def _with(**kw):
    return {"radius": 0.04, **kw}


@pytest.mark.parametrize(
    "cfg,words",
    [
        (_with(obstacles=[{"shape": "cone", "center": [0, 0, 0]}]),
         ["unknown obstacle shape", "ball, capsule, box or halfspace", "cone"]),
        (_with(radius=0), ["radius", "must be > 0, got 0"]),
        (_with(radius=-0.1), ["radius", "must be > 0, got -0.1"]),
        (_with(radius=[0.1, float("nan")]), ["radius[1]", "nan is not a finite number"]),
        (_with(radius=[0.1, "x"]), ["radius[1]", "'x' is not a number"]),
        (_with(radius=2e6), ["radius", "2e+06 is too large"]),
        (_with(radius=[]), ["radius", "at least one"]),
        (_with(obstacles=[{"shape": "ball", "center": [0, float("nan"), 0], "radius": 1}]),
         ["obstacles.0.ball.center.1", "nan is not a finite number"]),
        (_with(obstacles=[{"shape": "ball", "center": [1e9, 0, 0], "radius": 1}]),
         ["obstacles.0.ball.center.0", "1e+09 is too large"]),
        (_with(obstacles=[{"shape": "ball", "center": [0, 0, 0], "radius": 0}]),
         ["obstacles.0.ball.radius", "must be > 0"]),
        (_with(obstacles=[{"shape": "capsule", "a": [0, 0, 0], "b": [0, 0, math.inf],
                           "radius": 1}]), ["obstacles.0.capsule.b.2", "inf is not a finite"]),
        (_with(obstacles=[{"shape": "box", "center": [0, 0, 0], "size": [1, 0, 1]}]),
         ["obstacles.0.box.size.1", "must be > 0, got 0"]),
        (_with(obstacles=[{"shape": "halfspace", "point": [0, 0, 0], "normal": [0, 0, 0]}]),
         ["obstacles.0.halfspace.normal", "non-zero", "[0.0, 0.0, 0.0]"]),
        (_with(obstacles=[{"shape": "ball", "center": [0, 0, 0], "radius": 1, "r": 2}]),
         ["obstacles.0.ball.r", "Extra inputs"]),
        (_with(margin=-0.01), ["margin", "must be ≥ 0, got -0.01"]),
        (_with(margin=float("inf")), ["margin", "inf is not a finite number"]),
        (_with(**{"self": "yes"}), ["self", "valid boolean", "yes"]),
        (_with(self_collide=True), ["self_collide", "Extra inputs"]),
        (_with(links="mesh"), ["links", "'auto' or 'urdf'", "mesh"]),
    ],
)  # fmt: skip
def test_config_refuses_bad_inputs(cfg, words):
    with pytest.raises(pydantic.ValidationError) as e:
        C.Collision.model_validate(cfg)
    text = str(e.value)
    for w in words:
        assert w in text, (w, text)
