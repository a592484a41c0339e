"""Mesh obstacles (``designopt.kinematics.sdf`` and ``shape: mesh`` in
``designopt.kinematics.collision``) against independent references.

- The host's exact SDF against a brute force over every triangle (Ericson's closest
  point, every pair, in extended precision) to 1e-12, its sign against the generalised
  winding number (the solid angles of all triangles summed, van Oosterom and Strackee's
  formula), and against trimesh's ``proximity.signed_distance`` (sign flipped), whose
  own nearest points are off by up to 28 µm on this mesh (at 463 of the 64³ grid's
  points, where the brute force agrees with ours to 1e-18: its candidate search is not
  exact), hence the 5e-5 there.
- The interpolated SDF, in and outside the grid's box, and the capsule distances against
  those exact distances within the bounds the module states, and their gradients
  against central finite differences.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pydantic
import pytest
import trimesh

from designopt.app.config import validate
from designopt.core.errors import ConfigError
from designopt.kinematics import collision as C
from designopt.kinematics import sdf
from designopt.kinematics.urdf import rpy_matrix

# jitted once per shape (eager calls compile every operation on its own, far slower)
grid_sdf = jax.jit(sdf.grid_sdf)
mesh_sdf = jax.jit(sdf.mesh_sdf)
capsule_mesh = jax.jit(sdf.capsule_mesh)
terms = jax.jit(C.clearance_terms, static_argnames=("self_pairs",))

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "configs" / "data"
ORGAN = DATA / "organ.stl"


@pytest.fixture(scope="module")
def organ():
    return sdf.load_mesh(ORGAN)


@pytest.fixture(scope="module")
def grid32(organ):
    return sdf.build_grid(*organ, resolution=32)


def _pose():
    return rpy_matrix(0.4, -0.3, 1.1), np.array([0.31, -0.12, 0.2])


def _winding(v, f, P):
    """The generalised winding number of points P (n, 3): Σ Ω_T / 4π over the triangles,
    Ω from van Oosterom–Strackee; 1 inside a closed outward mesh, 0 outside."""
    T = v[f][None] - P[:, None, None, :]  # (n, m, 3, 3)
    a, b, c = T[..., 0, :], T[..., 1, :], T[..., 2, :]
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    num = np.einsum("...i,...i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("...i,...i", a, b) * lc + np.einsum("...i,...i", b, c) * la
           + np.einsum("...i,...i", c, a) * lb)  # fmt: skip
    return (2 * np.arctan2(num, den)).sum(-1) / (4 * np.pi)


def _brute_unsigned(v, f, P):
    """The distance of points P to the nearest of every triangle, by Ericson's closest
    point (Real-Time Collision Detection, 5.1.5: the Voronoi regions of the corners and
    edges, else barycentric) for every pair, in extended precision (trimesh's
    ``triangles.closest_point`` errs by up to ~2e-10 m here at points on the surface)."""
    dt = np.longdouble
    p = np.asarray(P, dt)[:, None, :]
    a, b, c = (np.asarray(v[f[:, i]], dt)[None] for i in range(3))
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c

    def dot(x, y):
        return np.sum(x * y, -1)

    d1, d2, d3, d4, d5, d6 = (
        dot(ab, ap),
        dot(ac, ap),
        dot(ab, bp),
        dot(ac, bp),
        dot(ab, cp),
        dot(ac, cp),
    )
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    den = va + vb + vc
    den = np.where(den == 0, 1, den)
    q = a + ab * (vb / den)[..., None] + ac * (vc / den)[..., None]  # inside the face

    def sel(cond, x, q):
        return np.where(cond[..., None], x, q)

    def frac(n, d):
        return (n / np.where(d == 0, 1, d))[..., None]

    bc = (d4 - d3 >= 0) & (d5 - d6 >= 0) & (va <= 0)
    q = sel(bc, b + frac(d4 - d3, (d4 - d3) + (d5 - d6)) * (c - b), q)
    q = sel((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + frac(d2, d2 - d6) * ac, q)
    q = sel((d6 >= 0) & (d5 <= d6), c, q)
    q = sel((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + frac(d1, d1 - d3) * ab, q)
    q = sel((d3 >= 0) & (d4 <= d3), b, q)
    q = sel((d1 <= 0) & (d2 <= 0), a, q)
    return np.sqrt(np.sum((p - q) ** 2, -1)).min(1).astype(float)


def _near_points(v, f, n, spread, rng):
    """n points near the surface: random vertices moved along random directions."""
    P = v[rng.integers(0, len(v), n)]
    return P + rng.normal(size=(n, 3)) * spread


# --------------------------------------------------------------------------- host SDF


def test_exact_sdf_against_brute_force_winding_number_and_trimesh(organ):
    v, f = organ
    rng = np.random.default_rng(11)
    lo, hi = v.min(0), v.max(0)
    P = np.concatenate([
        _near_points(v, f, 120, 0.002, rng),  # near the surface, both sides
        rng.uniform(lo, hi, (120, 3)),  # in the bounding box: many inside
        rng.uniform(lo - 0.05, hi + 0.05, (60, 3)),  # around it
        v[:10] + 1e-9,  # on the surface
    ])  # fmt: skip
    d = sdf.exact_sdf(v, f, P)
    np.testing.assert_allclose(np.abs(d), _brute_unsigned(v, f, P), rtol=0, atol=1e-12)
    w = _winding(v, f, P)
    assert np.all(np.isclose(w, 0, atol=1e-6) | np.isclose(w, 1, atol=1e-6))
    clear = np.abs(d) > 1e-9
    assert np.array_equal((d < 0)[clear], (w > 0.5)[clear])
    assert 50 < np.sum(d < 0) < 250  # both sides are tested
    ref = -trimesh.proximity.signed_distance(trimesh.Trimesh(v, f), P)
    np.testing.assert_allclose(d, ref, rtol=0, atol=5e-5)


def test_exact_sdf_of_a_box_and_a_concave_mesh():
    # a unit cube: exact closed form inside and outside; edges and vertices nearest
    box = trimesh.creation.box(extents=(1, 1, 1))
    v, f = np.asarray(box.vertices, float), np.asarray(box.faces)
    rng = np.random.default_rng(3)
    P = rng.uniform(-1.5, 1.5, (400, 3))
    q = np.abs(P) - 0.5
    ref = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)
    np.testing.assert_allclose(sdf.exact_sdf(v, f, P), ref, rtol=0, atol=1e-12)
    # an L-shaped (concave) prism: points in the notch are outside, near a concave edge
    xy = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2], [0, 1]], float)
    tri = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 6], [6, 3, 4], [6, 4, 5]])
    L = trimesh.creation.extrude_triangulation(xy, tri, height=1.0)
    assert L.is_volume
    v, f = np.asarray(L.vertices, float), np.asarray(L.faces)
    P = rng.uniform(-0.5, 2.5, (300, 3))
    d = sdf.exact_sdf(v, f, P)
    w = _winding(v, f, P)
    clear = np.abs(d) > 1e-9
    assert np.array_equal((d < 0)[clear], (w > 0.5)[clear])
    np.testing.assert_allclose(np.abs(d), _brute_unsigned(v, f, P), rtol=0, atol=1e-12)
    notch = np.array([[1.5, 1.5, 0.5], [1.1, 1.1, 0.5]])  # outside, nearest the notch's walls
    np.testing.assert_allclose(sdf.exact_sdf(v, f, notch), [0.5, 0.1], rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- the grid


def test_grid_covers_the_mesh_with_padding(organ, grid32):
    v, _ = organ
    g = grid32
    hi = g.origin + 31 * g.cell
    pad = sdf.PAD_CELLS * float(np.ptp(v, 0).max()) / (31 - 2 * sdf.PAD_CELLS)
    np.testing.assert_allclose(g.origin, v.min(0) - pad, rtol=0, atol=1e-15)
    np.testing.assert_allclose(hi, v.max(0) + pad, rtol=0, atol=1e-14)
    assert np.isclose(g.cell.max(), pad / sdf.PAD_CELLS)  # the longest axis: 4 cells
    # every value on the box's faces is at least the padding away from the mesh
    faces = np.concatenate([g.values[[0, -1]].ravel(), g.values[:, [0, -1]].ravel(),
                            g.values[:, :, [0, -1]].ravel()])  # fmt: skip
    assert faces.min() >= pad * (1 - 1e-12)
    g2 = sdf.build_grid(*organ, resolution=32, padding=0.03)
    np.testing.assert_allclose(g2.origin, v.min(0) - 0.03, rtol=0, atol=1e-15)


def test_interpolation_error_bound_in_the_box(organ, grid32):
    v, f = organ
    g = grid32
    rng = np.random.default_rng(5)
    lo, hi = g.origin, g.origin + 31 * g.cell
    P = np.concatenate([rng.uniform(lo, hi, (1500, 3)), _near_points(v, f, 1500, 0.004, rng)])
    P = P[np.all((P >= lo) & (P <= hi), axis=1)]
    assert len(P) > 2900
    exact = sdf.exact_sdf(v, f, P)
    got = np.asarray(grid_sdf(P, g.values, g.origin, g.cell))
    err = np.abs(got - exact)
    assert err.max() <= g.bound() + 1e-12, (err.max(), g.bound())
    assert err.max() > 0.1 * g.bound()  # the bound is not vacuous here
    # at the grid's points it is the exact value
    ijk = rng.integers(0, 32, (50, 3))
    nodes = g.origin + ijk * g.cell
    at = np.asarray(grid_sdf(nodes, g.values, g.origin, g.cell))
    np.testing.assert_allclose(at, g.values[tuple(ijk.T)], rtol=0, atol=1e-15)


def test_interpolation_bound_is_attained():
    """(√3/2)·h is the right bound: for the 1-Lipschitz f(p) = |p − c| with c at a
    cell's centre, every corner is √3 h/2 away and f(c) = 0."""
    h, n = 0.1, 8
    origin = np.zeros(3)
    ax = origin[0] + h * np.arange(n)
    X = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1)
    c = np.array([3.5, 3.5, 3.5]) * h
    vals = np.linalg.norm(X - c, axis=-1)
    got = float(grid_sdf(c, vals, origin, np.full(3, h)))
    assert got == pytest.approx(math.sqrt(3) / 2 * h, abs=1e-15)
    g = sdf.MeshGrid(vals, origin, np.full(3, h))
    assert g.bound() == pytest.approx(math.sqrt(3) / 2 * h, abs=1e-15)
    # anisotropic cells: half the diagonal
    cell = np.array([0.1, 0.2, 0.05])
    X = np.stack(np.meshgrid(*[cell[k] * np.arange(n) for k in range(3)], indexing="ij"), -1)
    c = 3.5 * cell
    got = float(grid_sdf(c, np.linalg.norm(X - c, axis=-1), origin, cell))
    assert got == pytest.approx(np.linalg.norm(cell) / 2, abs=1e-15)


def test_outside_the_box_is_an_upper_bound(organ, grid32):
    v, f = organ
    g = grid32
    lo, hi = g.origin, g.origin + 31 * g.cell
    rng = np.random.default_rng(6)
    P = rng.uniform(lo - 0.1, hi + 0.1, (3000, 3))
    P = P[np.any((P < lo) | (P > hi), axis=1)]
    exact = sdf.exact_sdf(v, f, P)
    q = np.clip(P, lo, hi)
    a, b = np.linalg.norm(P - q, axis=1), sdf.exact_sdf(v, f, q)
    got = np.asarray(grid_sdf(P, g.values, g.origin, g.cell))
    eps = g.bound() + 1e-12
    assert np.all(got >= exact - eps)  # an upper bound, to the interpolation at q
    assert np.all(got <= exact + eps + (a + b - np.sqrt(a * a + b * b)))
    assert np.all(exact >= b.min()) and b.min() >= sdf.PAD_CELLS * g.cell.max() * (1 - 1e-12)
    assert np.any(got - exact > 0.3 * (a + b - np.sqrt(a * a + b * b)) + eps)  # not exact


# --------------------------------------------------------------------------- capsules


def _stack(organ, res=32, pose=None):
    R, t = _pose() if pose is None else pose
    g = sdf.build_grid(*organ, resolution=res)
    return g, sdf.stack([g], R[None], t[None])


def _capsules(organ, n, rng, spread=0.006):
    """Capsule centre lines in the mesh frame: near the surface (crossing it or not),
    deep inside, far, crossing the box's faces, zero-length, long."""
    v, f = organ
    c = np.concatenate([_near_points(v, f, n - 40, spread, rng),
                        rng.uniform(v.min(0) - 0.06, v.max(0) + 0.06, (40, 3))])  # fmt: skip
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    L = np.where(rng.uniform(size=n) < 0.1, 0.0, rng.uniform(0.0, 0.25, n))
    s = rng.uniform(0, 1, n)
    return c - s[:, None] * L[:, None] * u, c + (1 - s)[:, None] * L[:, None] * u


def test_capsule_distance_within_the_stated_bound(organ):
    v, f = organ
    g, st = _stack(organ)
    R, t = _pose()
    rng = np.random.default_rng(7)
    a0, a1 = _capsules(organ, 160, rng)
    r = rng.uniform(0.0, 0.01, len(a0))
    args = (st["grid"], st["origin"], st["cell"], st["cells"], st["R"], st["t"])
    d = np.asarray(capsule_mesh((a0 @ R.T + t)[:, None], (a1 @ R.T + t)[:, None],
                                             r[:, None], *args))[:, 0]  # fmt: skip
    # the reference: the exact SDF at 1001 points of each centre line; the sampled minimum
    # exceeds the exact one by at most half a spacing
    s = np.linspace(0, 1, 1001)
    P = a0[:, None] + s[None, :, None] * (a1 - a0)[:, None]
    ref = sdf.exact_sdf(v, f, P.reshape(-1, 3)).reshape(len(a0), -1).min(1)
    slack = np.linalg.norm(a1 - a0, axis=1) / 2000
    eps, step = g.bound(), float(g.cell.max())
    pad = sdf.PAD_CELLS * float(g.cell.max())
    got = d + r
    assert np.all(got >= ref - slack - eps - 1e-12)  # never below the exact less ε
    near = ref < pad - slack  # the exact minimum is in the grid's box
    assert np.all(got[near] <= ref[near] + eps + step / 2 + 1e-12)
    assert near.sum() > 100 and np.sum(ref < 0) > 20  # near, and crossing into the mesh
    # measured against the bound (reported): the largest error is well inside it
    assert np.abs(got[near] - ref[near]).max() < eps + step / 2
    # float32 from float32 inputs
    args32 = [jnp.asarray(x, jnp.float32) for x in args]
    d32 = capsule_mesh(jnp.asarray((a0 @ R.T + t)[:, None], jnp.float32),
                                    jnp.asarray((a1 @ R.T + t)[:, None], jnp.float32),
                                    jnp.asarray(r[:, None], jnp.float32), *args32)  # fmt: skip
    assert d32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(d32)[:, 0], d, rtol=0, atol=2e-6)


def test_capsule_samples_and_clip(organ):
    g, st = _stack(organ)
    assert sdf.samples(32) == math.ceil(math.sqrt(3) * 31) + 1
    lo, hi = g.origin, g.origin + 31 * g.cell
    # the in-box spacing ≤ max h even along the box's diagonal
    diag = float(np.linalg.norm(hi - lo))
    assert diag / (sdf.samples(32) - 1) <= g.cell.max() * (1 + 1e-12)
    s0, s1 = sdf._clip(jnp.asarray(lo - (hi - lo)), jnp.asarray(3 * (hi - lo)),
                       jnp.asarray(lo), jnp.asarray(hi))  # fmt: skip
    assert float(s0) == pytest.approx(1 / 3) and float(s1) == pytest.approx(2 / 3)
    # a segment that misses the box is sampled at its 9 points only (s0 = s1 = 0)
    s0, s1 = sdf._clip(
        jnp.asarray(hi + 1), jnp.asarray(np.ones(3)), jnp.asarray(lo), jnp.asarray(hi)
    )
    assert float(s0) == float(s1) == 0.0
    # along x through the box's middle: parallel to four faces, inside their slabs
    c = (lo + hi) / 2
    s0, s1 = sdf._clip(jnp.asarray(c - [1, 0, 0]), jnp.asarray([2.0, 0, 0]), jnp.asarray(lo),
                       jnp.asarray(hi))  # fmt: skip
    assert float(s0) == pytest.approx((lo[0] - c[0] + 1) / 2, abs=1e-15)
    assert float(s1) == pytest.approx((hi[0] - c[0] + 1) / 2, abs=1e-15)


def _fd(f, x, h):
    g = np.zeros_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = h
        g.flat[i] = (float(f(x + e)) - float(f(x - e))) / (2 * h)
    return g


def test_gradients_match_finite_differences(organ):
    v, f = organ
    g, st = _stack(organ)
    R, t = _pose()
    args = tuple(st[k] for k in ("grid", "origin", "cell", "cells", "R", "t"))
    lo, hi = g.origin, g.origin + 31 * g.cell
    rng = np.random.default_rng(8)
    point = jax.jit(lambda p: sdf.mesh_sdf(p, *args)[0])
    gpoint = jax.jit(jax.grad(lambda p: sdf.mesh_sdf(p, *args)[0]))
    # points in the box, near the surface and outside it (world frame)
    P = np.concatenate(
        [_near_points(v, f, 6, 0.003, rng), rng.uniform(lo - 0.05, hi + 0.05, (6, 3))]
    )
    for p in P @ R.T + t:
        np.testing.assert_allclose(np.asarray(gpoint(p)), _fd(point, p, 1e-7), rtol=0, atol=1e-6)
    # capsules with both ends in the box: the clipped part is the whole line, the gradient
    # is the exact derivative of the result
    cap = jax.jit(lambda x: sdf.capsule_mesh(x[:3], x[3:6], x[6], *args)[0])
    gcap = jax.jit(jax.grad(lambda x: sdf.capsule_mesh(x[:3], x[3:6], x[6], *args)[0]))
    shrink = 0.1 * (hi - lo)
    for _ in range(6):
        e = rng.uniform(lo + shrink, hi - shrink, (2, 3)) @ R.T + t
        x = np.concatenate([e.ravel(), [0.005]])
        gx = np.asarray(gcap(x))
        np.testing.assert_allclose(gx, _fd(cap, x, 1e-7), rtol=0, atol=1e-6)
        assert gx[6] == -1.0
    # long capsules crossing the box: the gradient is that of the SDF at the best sample,
    # its parameter held fixed (the samples' parameters do not move with the ends)
    best = jax.jit(lambda x: sdf.best_sample(x[:3], x[3:6], *args)[0])
    for _ in range(6):
        c = _near_points(v, f, 1, 0.005, rng)[0]
        u = rng.normal(size=3)
        e = np.stack([c - 0.3 * u, c + 0.2 * u]) @ R.T + t
        x = np.concatenate([e.ravel(), [0.005]])
        s = float(best(x))

        def at_s(y, s=s):
            return sdf.mesh_sdf(y[:3] + s * (y[3:6] - y[:3]), *args)[0] - y[6]

        assert float(cap(x)) == pytest.approx(float(at_s(x)), abs=1e-15)
        np.testing.assert_allclose(
            np.asarray(gcap(x)), _fd(jax.jit(at_s), x, 1e-7), rtol=0, atol=1e-6
        )


def test_gradients_have_no_nan(organ):
    g, st = _stack(organ)
    args = tuple(st[k] for k in ("grid", "origin", "cell", "cells", "R", "t"))
    R, t = _pose()
    node = g.origin + np.array([5, 6, 7]) * g.cell  # exactly on a grid point
    far = np.array([5.0, 5.0, 5.0])
    cases = [(node, node), (node, node + [0.1, 0, 0]), (far, far), (far, far + 1.0),
             (g.origin, g.origin + 31 * g.cell)]  # fmt: skip
    fn = jax.jit(jax.grad(lambda a, b: jnp.sum(sdf.capsule_mesh(a, b, 0.01, *args)), (0, 1)))
    for a, b in cases:
        for gr in fn(jnp.asarray(a @ R.T + t), jnp.asarray(b @ R.T + t)):
            assert np.all(np.isfinite(np.asarray(gr)))


# --------------------------------------------------------------------------- pose


def test_pose_is_an_input_and_moves_the_mesh(organ):
    v, f = organ
    g = sdf.build_grid(v, f, resolution=32)
    rng = np.random.default_rng(9)
    traces = []

    @jax.jit
    def fn(p, st):
        traces.append(1)
        return sdf.mesh_sdf(p, st["grid"], st["origin"], st["cell"], st["cells"], st["R"], st["t"])

    for rpy, xyz in [((0, 0, 0), (0, 0, 0)), ((0.3, 0.2, -1.0), (0.5, -0.2, 0.1)),
                     ((1.2, -0.4, 2.5), (-0.3, 0.7, 0.05))]:  # fmt: skip
        R, t = rpy_matrix(*rpy), np.asarray(xyz)
        st = sdf.stack([g], R[None], t[None])
        Pm = _near_points(v, f, 300, 0.01, rng)  # in the mesh frame
        exact = sdf.exact_sdf(v @ R.T + t, f, Pm @ R.T + t)  # the posed mesh, exactly
        got = np.asarray(fn(jnp.asarray(Pm @ R.T + t)[:, None], st))[:, 0]
        assert np.abs(got - exact).max() <= g.bound() + 1e-12
    assert len(traces) == 1  # three poses, one trace


def test_meshes_of_different_resolutions_stack(organ):
    v, f = organ
    g1 = sdf.build_grid(v, f, resolution=32)
    g2 = sdf.build_grid(v * 0.5, f, resolution=40)
    R = np.stack([np.eye(3), rpy_matrix(0.1, 0.2, 0.3)])
    t = np.array([[0.0, 0, 0], [0.2, 0, 0]])
    st = sdf.stack([g1, g2], R, t)
    assert st["grid"].shape == (2, 40, 40, 40) and np.asarray(st["cells"]).tolist() == [31, 39]
    args = tuple(st[k] for k in ("grid", "origin", "cell", "cells", "R", "t"))
    rng = np.random.default_rng(10)
    P = rng.uniform(-0.1, 0.3, (500, 3))
    both = np.asarray(mesh_sdf(P[:, None], *args))
    for k, gk in enumerate((g1, g2)):  # the coarser grid in its corner reads the same
        alone = np.asarray(mesh_sdf(P, gk.values, gk.origin, gk.cell, gk.resolution - 1,
                                        R[k], t[k]))  # fmt: skip
        np.testing.assert_allclose(both[:, k], alone, rtol=0, atol=1e-15)
    # capsules: both meshes within the bound (the coarser one sampled as the finer)
    caps = [_capsules((v * sc @ R[k].T + t[k], f), 60, rng, 0.004 * sc)
            for k, sc in enumerate((1.0, 0.5))]  # fmt: skip
    a0, a1 = (np.concatenate([c[i] for c in caps]) for i in (0, 1))  # near either mesh
    d = np.asarray(capsule_mesh(a0[:, None], a1[:, None], 0.0, *args))
    s = np.linspace(0, 1, 401)
    P = (a0[:, None] + s[None, :, None] * (a1 - a0)[:, None]).reshape(-1, 3)
    slack = np.linalg.norm(a1 - a0, axis=1) / 800
    for k, (gk, scale) in enumerate(((g1, 1.0), (g2, 0.5))):
        ref = sdf.exact_sdf(v * scale @ R[k].T + t[k], f, P).reshape(len(a0), -1).min(1)
        eps, step = gk.bound(), float(gk.cell.max())
        near = ref < sdf.PAD_CELLS * step - slack
        assert near.sum() > 10
        assert np.all(d[:, k] >= ref - slack - eps - 1e-12)
        assert np.all(d[near, k] <= ref[near] + eps + step / 2 + 1e-12)


# --------------------------------------------------------------------------- config


def _cfg(tmp_path=None, **mesh):
    o = {"shape": "mesh", **({"file": "data/organ.stl"} if tmp_path is None else {}), **mesh}
    ctx = {"config_dir": str(ROOT / "configs" if tmp_path is None else tmp_path)}
    return C.Collision.model_validate({"radius": 0.01, "obstacles": [o]}, context=ctx)


def test_mesh_obstacle_config_and_clearance(organ):
    cfg = _cfg(xyz=[0.4, 0.0, 0.1], rpy=[0, 0, 90], scale=1.0, resolution=32)
    ob = cfg.obstacles[0]
    assert ob.file == str(ORGAN.resolve())  # relative to the config's folder, stored resolved
    R, t = ob.pose()
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    p = cfg.params()
    assert p["mesh"]["grid"].shape == (1, 32, 32, 32) and p["mesh"]["R"].shape == (1, 3, 3)
    # a planar arm reaching over the organ: clearance against the exact distance
    v, f = organ
    world_v = v @ R.T + t
    seg = C.link_segments(jnp.asarray([[0, 0, 0.3], [0.3, 0, 0.12], [0.5, 0.02, 0.1]]))
    obs, _ = terms(seg, 0.01, p)
    s = np.linspace(0, 1, 4001)
    pts = np.concatenate([np.asarray(seg[i, 0]) + s[:, None] * np.asarray(seg[i, 1] - seg[i, 0])
                          for i in range(2)])  # fmt: skip
    ref = sdf.exact_sdf(world_v, f, pts).min() - 0.01
    g = ob.grid()
    assert ref - 1e-4 - g.bound() <= float(obs) <= ref + g.bound() + g.cell.max() / 2
    assert float(obs) < 0  # the second link passes through the organ
    # with other obstacles: the least of the terms
    both = C.obstacle_params([ob, C.BallObstacle(shape="ball", center=(0, 0, 2), radius=0.1)])
    o2, _ = terms(seg, 0.01, both)
    assert float(o2) == pytest.approx(float(obs), abs=1e-15)
    # float32 params and segments
    o32, _ = terms(seg.astype(jnp.float32), jnp.float32(0.01), cfg.params(jnp.float32))
    assert o32.dtype == jnp.float32 and abs(float(o32) - float(obs)) < 2e-6


def test_empty_mesh_group_has_its_trailing_shapes():
    e = C.obstacle_params([])["mesh"]
    shapes = {k: tuple(a.shape) for k, a in e.items()}
    assert shapes == {"grid": (0, 64, 64, 64), "origin": (0, 3), "cell": (0, 3), "cells": (0,),
                      "R": (0, 3, 3), "t": (0, 3)}  # fmt: skip
    seg = C.link_segments(jnp.asarray([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]]))
    # an empty group adds no term (and no work): the clearance of nothing is +inf
    jaxpr = jax.make_jaxpr(lambda s: C.clearance_terms(s, 0.1, C.obstacle_params([])))(seg)
    assert "while" not in str(jaxpr) and "gather" not in str(jaxpr)
    assert float(C.clearance(seg, 0.1, C.obstacle_params([]))) == math.inf


def _bad_files(tmp_path):
    box = trimesh.creation.box(extents=(1, 1, 1))
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-1], process=False)
    open_box.export(tmp_path / "open.stl")
    (tmp_path / "junk.stl").write_bytes(b"\x00\x01 this is no mesh")
    (tmp_path / "folder.stl").mkdir()
    inverted = trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False)
    inverted.export(tmp_path / "inverted.stl")


@pytest.mark.parametrize(
    "mesh,words",
    [
        ({"file": "open.stl"}, ["obstacles.0.mesh.file", "open.stl", "not watertight"]),
        ({"file": "junk.stl"}, ["obstacles.0.mesh.file", "junk.stl", "cannot read"]),
        ({"file": "missing.stl"}, ["obstacles.0.mesh.file", "missing.stl", "no such mesh file"]),
        ({"file": "folder.stl"}, ["obstacles.0.mesh.file", "folder.stl", "is a folder"]),
        ({"file": "ok.stl", "scale": 0}, ["obstacles.0.mesh.scale", "must be > 0, got 0"]),
        ({"file": "ok.stl", "scale": -2}, ["obstacles.0.mesh.scale", "must be > 0, got -2"]),
        ({"file": "ok.stl", "resolution": 16}, ["obstacles.0.mesh.resolution", "from 32 to 128", "16"]),
        ({"file": "ok.stl", "resolution": 129}, ["obstacles.0.mesh.resolution", "129"]),
        ({"file": "ok.stl", "resolution": 64.5}, ["obstacles.0.mesh.resolution", "64.5"]),
        ({"file": "ok.stl", "resolution": "64"}, ["obstacles.0.mesh.resolution", "'64'"]),
        ({"file": "ok.stl", "resolution": True}, ["obstacles.0.mesh.resolution", "True"]),
        ({"file": "ok.stl", "padding": 0}, ["obstacles.0.mesh.padding", "must be > 0"]),
        ({"file": "ok.stl", "rpy": [0, "x", 0]}, ["obstacles.0.mesh.rpy.1"]),
        ({"file": "ok.stl", "colour": "red"}, ["obstacles.0.mesh.colour", "Extra inputs"]),
        ({}, ["obstacles.0.mesh.file", "Field required"]),
    ],
)  # fmt: skip
def test_mesh_obstacle_refuses_bad_input(tmp_path, mesh, words):
    _bad_files(tmp_path)
    (tmp_path / "ok.stl").write_bytes(ORGAN.read_bytes())
    with pytest.raises(pydantic.ValidationError) as e:
        _cfg(tmp_path, **mesh)
    text = str(e.value)
    for w in words:
        assert w in text, (w, text)


def test_bad_mesh_is_one_config_error_line(tmp_path):
    _bad_files(tmp_path)
    raw = {"radius": 0.01, "obstacles": [{"shape": "mesh", "file": "open.stl"}]}
    with pytest.raises(ConfigError) as e:
        validate(raw, str(tmp_path / "run.yaml"), C.Collision, folder=tmp_path)
    msg = str(e.value)
    assert "\n" not in msg and "key 'obstacles.0.file'" in msg and "open.stl" in msg, msg
    assert "not watertight" in msg


def test_inverted_mesh_is_reoriented(tmp_path):
    _bad_files(tmp_path)
    v, f = sdf.load_mesh(tmp_path / "inverted.stl")
    d = sdf.exact_sdf(v, f, np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    np.testing.assert_allclose(d, [-0.5, 1.5], atol=1e-12)


# --------------------------------------------------------------------------- the file


def test_shipped_organ_is_the_script_output():
    sys.path.insert(0, str(DATA))
    try:
        import make_organ
    finally:
        sys.path.remove(str(DATA))
    v, f = make_organ.organ()
    make_organ.check(v, f)
    made, shipped = make_organ.stl_bytes(v, f), ORGAN.read_bytes()
    assert len(made) == len(shipped) and made[:84] == shipped[:84]
    rec = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    a, b = (np.frombuffer(x[84:], rec)["v"] for x in (made, shipped))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-8)  # the same triangles (to an ulp)
    assert ORGAN.stat().st_size < 200_000 and len(f) <= 2000
    m = trimesh.load(ORGAN)
    assert m.is_watertight and m.is_volume


# --------------------------------------------------------------------------- a study


def test_planar_arm_reach_with_a_mesh_obstacle():
    """A planar 2R (links 0.9, 0.8, capsules of radius 0.05) over a disk of targets with
    the organ (scaled 2.5) beside it, through the study's own per-target solution: a
    target counts as reached exactly when one of its two elbow solutions keeps both link
    capsules off the mesh (the exact distance, by dense sampling of the links), except
    where that distance is within the stated bound of zero."""
    from designopt.core.keys import streams
    from designopt.studies.serial import blocks

    mesh = {"shape": "mesh", "file": "data/organ.stl", "xyz": [0.7, 0.25, 0.0],
            "rpy": [0, 0, 20], "scale": 2.5, "resolution": 48}  # fmt: skip
    disk = {"shape": "cylinder", "center": [1.1, 0.0, 0.0], "axis": [0, 0, 1], "radius": 0.5,
            "height": 0.0}  # fmt: skip
    raw = {"study": {
        "name": "serial",
        "chain": {"convention": "standard", "joints": [
            {"type": "R", "a": "l1", "limits": [-180, 180]},
            {"type": "R", "a": "l2", "limits": [-180, 180]}]},
        "variables": {"l1": [0.3, 1.5], "l2": [0.3, 1.5]},
        "task": {"region": disk, "ik": {"n_best": 2}},
        "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": 300},
        "objective": {"gci": -1.0},
        "collision": {"radius": 0.05, "obstacles": [mesh]}},
        "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 1},
        "precision": "float64", "seed": 3}  # fmt: skip
    cfg = validate(raw, "test", folder=ROOT / "configs")
    l1, l2 = 0.9, 0.8
    out = blocks.solution(cfg.study, {"l1": l1, "l2": l2}, streams(cfg.seed))
    p, got = out["target_p"], out["success"]
    ob = cfg.study.collision.obstacles[0]
    v, f = sdf.load_mesh(ob.file)
    R, t = ob.pose()
    vw = v * 2.5 @ R.T + t
    x, y = p[:, 0], p[:, 1]
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    reach = np.abs(c2) <= 1
    q2 = np.arccos(np.clip(c2, -1, 1))
    s = np.linspace(0, 1, 301)[None, :, None]
    free = []
    for sg in (1.0, -1.0):  # each elbow: the least exact distance over both links
        q1 = np.arctan2(y, x) - np.arctan2(l2 * np.sin(sg * q2), l1 + l2 * np.cos(sg * q2))
        el = np.stack([l1 * np.cos(q1), l1 * np.sin(q1), 0 * q1], -1)[:, None]
        pts = np.concatenate([s * el, el + s * (p[:, None] - el)], 1).reshape(-1, 3)
        free.append(sdf.exact_sdf(vw, f, pts).reshape(len(p), -1).min(1) - 0.05)
    best = np.maximum(*free)
    g = ob.grid()
    tol = g.bound() + g.cell.max() / 2 + 1.5 / 300  # grid, samples, the reference's spacing
    clear = np.abs(best) > tol
    oracle = reach & (best >= 0)
    assert np.array_equal(got[clear], oracle[clear])
    assert clear.mean() > 0.95
    assert np.sum(reach & (best < -tol)) >= 10  # blocked targets
    assert np.sum(reach & clear & ((free[0] >= 0) != (free[1] >= 0))) >= 100  # one elbow free
