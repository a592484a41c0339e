"""Study A indices (seed 000 eq. 35-43) against independent numpy estimates and identities."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.numerics import montecarlo as mc
from designopt.studies.master9 import mechanism as m
from designopt.studies.master9 import objective as obj
from designopt.studies.master9.indices import _features, inv_cond_fro_jv, jv_entries, swarm_indices
from designopt.studies.master9.settings import Indices
from designopt.studies.master9.volume import hull_volume, voxel_volume

PUBLISHED = [(m.PAPER_INITIAL, 696.960), (m.PAPER_FINAL, 691.314)]


def numpy_indices(design, n, seed, backlash_deg=0.1):
    """Independent estimate: numpy RNG, np.linalg.cond, FK of eq. (4) at the 8 corners."""
    d = {**m.default_design(), **design}
    rng = np.random.default_rng(seed)
    lim = m.POSITION_LIMITS
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, 3))

    def P(q):
        q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2]
        w = d["a3"] * np.cos(q3) + d["a4"]
        return np.stack(
            [
                d["a1"] * np.cos(q1) + d["d3"] * np.cos(q1 + q2) + w * np.sin(q1 + q2),
                d["a1"] * np.sin(q1) + d["d3"] * np.sin(q1 + q2) - w * np.cos(q1 + q2),
                -d["a3"] * np.sin(q3),
            ],
            -1,
        )

    h = 1e-6
    J = np.stack([(P(q + h * e) - P(q - h * e)) / (2 * h) for e in np.eye(3)], -1)
    inv_k = 1.0 / np.linalg.cond(J, "fro")
    w = np.abs(np.linalg.det(J))
    dl = np.deg2rad(backlash_deg)
    corners = np.array(np.meshgrid([-dl, dl], [-dl, dl], [-dl, dl])).reshape(3, -1).T
    e = np.max([np.linalg.norm(P(q + c) - P(q), axis=-1) for c in corners], axis=0)

    def wstats(g):
        mu = np.sum(w * g) / np.sum(w)
        sd = np.sqrt(np.sum(w * (g - mu) ** 2) / np.sum(w))
        se = np.sqrt(np.sum((w * (g - mu)) ** 2)) / np.sum(w)
        return mu, sd, se

    gci, gcsei, gci_se = wstats(inv_k)
    gpi, _, gpi_se = wstats(e)
    vol = np.prod(lim[:, 1] - lim[:, 0]) * w.mean()
    return dict(gci=gci, gcsei=gcsei, gci_se=gci_se, gpi=gpi, gpi_se=gpi_se, volume=vol)


@pytest.mark.parametrize("design,L", PUBLISHED)
def test_indices_match_independent_numpy_within_4_se(design, L):
    ind = obj.indices(design, n_samples=200_000, key=jax.random.key(1))
    ref = numpy_indices(design, 200_000, seed=7)
    for k in ("gci", "gcsei", "gpi"):
        se = np.hypot(ind[f"{k}_se"], ref.get(f"{k}_se", ind[f"{k}_se"]))
        assert abs(ind[k] - ref[k]) < 4 * se, (k, ind[k], ref[k], se)
    assert ind["L"] == pytest.approx(L, abs=1e-9)  # 696.960 and 691.314 mm exactly
    assert ind["f_k"] == pytest.approx(ind["gcsei"] - ind["gci"], abs=1e-12)
    assert ind["f_l"] == pytest.approx(L / ind["volume"] ** (1 / 3), rel=1e-12)


@pytest.mark.parametrize("design,_", PUBLISHED)
def test_volume_estimators_agree(design, _):
    ind = obj.indices(design, n_samples=400_000, key=jax.random.key(2))
    vox = voxel_volume(design, h=4.0)
    assert abs(ind["volume"] - vox) / vox < 0.02
    assert hull_volume(design, n=100_000) >= vox


def test_standard_errors_shrink_like_one_over_sqrt_n_and_fixed_key_is_reproducible():
    a = obj.indices(m.PAPER_FINAL, n_samples=20_000, key=jax.random.key(3))
    b = obj.indices(m.PAPER_FINAL, n_samples=320_000, key=jax.random.key(3))
    for k in ("gci", "gcsei", "gpi", "volume"):
        ratio = b[f"{k}_se"] / a[f"{k}_se"]
        assert 0.25 * 0.85 < ratio < 0.25 * 1.15, (k, ratio)
    assert obj.indices(m.PAPER_FINAL, n_samples=20_000, key=jax.random.key(3)) == a


def test_unweighted_mean_and_std_se_match_textbook_formulas():
    g = np.random.default_rng(0).normal(2.0, 0.5, 10_000)
    ps = mc.power_sums(jnp.ones_like(g), jnp.asarray(g))
    est = mc.mean(ps)
    assert float(est.value) == pytest.approx(g.mean(), rel=1e-12)
    assert float(est.se) == pytest.approx(g.std(ddof=1) / np.sqrt(g.size), rel=1e-9)
    sd = mc.std(ps)
    assert float(sd.value) == pytest.approx(g.std(), rel=1e-12)
    # for a normal sample SE(sd) ≈ sd / sqrt(2 N)
    assert float(sd.se) == pytest.approx(g.std() / np.sqrt(2 * g.size), rel=0.05)


def test_halton_sampler_is_low_discrepancy_and_in_unit_cube():
    u = np.asarray(mc.unit_samples(jax.random.key(0), 0, 4096, 3, "halton"))
    assert u.min() >= 0 and u.max() < 1
    # each 1/8-slab of each axis holds 1/8 of the points to within 1 %
    for j in range(3):
        counts = np.histogram(u[:, j], bins=8, range=(0, 1))[0]
        assert np.all(np.abs(counts - 512) <= 6)
    ind = obj.indices(m.PAPER_FINAL, n_samples=65_536, key=jax.random.key(4), sampler="halton")
    ref = obj.indices(m.PAPER_FINAL, n_samples=400_000, key=jax.random.key(5))
    assert abs(ind["gci"] - ref["gci"]) < 4 * np.hypot(ind["gci_se"], ref["gci_se"])


def test_swarm_evaluation_equals_per_design_rows():
    P = obj.problem({"indices": {"n_samples": 8192}, "n_norm": 16})
    X = jnp.array([[285.997, 280.933, 130.03], [324.238, 317.076, 50.0], [300.0, 260.0, 90.0]])
    f, aux = P.evaluate(X)
    for i in range(3):
        fi, ai = P.evaluate(X[i : i + 1])
        np.testing.assert_allclose(fi, f[i : i + 1], rtol=1e-12)
        np.testing.assert_allclose(ai["gci"], aux["gci"][i : i + 1], rtol=1e-12)


def test_grad_of_composite_matches_central_differences():
    P = obj.problem({"indices": {"n_samples": 8192}, "n_norm": 16})
    fn = lambda x: P.fn(P.params, x[None], jax.random.key(0))[0][0]  # noqa: E731
    x0 = jnp.array([300.0, 290.0, 100.0])
    g = np.asarray(jax.grad(fn)(x0))
    h = 1e-3
    fd = np.array([(fn(x0 + h * e) - fn(x0 - h * e)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(g, fd, rtol=1e-4)


def test_singular_configuration_contributes_zero_not_nan():
    x = {k: jnp.array([[v]]) for k, v in m.default_design().items()}
    q = jnp.array([[0.1, 0.2, np.pi / 2], [0.0, 0.0, 0.0]])  # q3 = 90°: numerically singular
    _, r = inv_cond_fro_jv(jv_entries(x, _features(q)))
    assert float(r[0, 0]) < 1e-15 and float(r[0, 1]) > 0.05
    x0 = {**x, "a3": jnp.array([[0.0]])}  # a3 = 0: J33 = 0 exactly, singular everywhere
    det, r0 = inv_cond_fro_jv(jv_entries(x0, _features(q)))
    assert np.all(np.asarray(r0) == 0.0) and np.all(np.asarray(det) == 0.0)
    ind = obj.indices({**m.PAPER_FINAL, "a3": 0.0}, n_samples=4096)
    assert not any(np.isnan(v) for v in ind.values())
    assert ind["gci"] == 0.0 and ind["volume"] == 0.0 and ind["f_l"] == np.inf
    g = jax.grad(lambda a: inv_cond_fro_jv(jv_entries({**x, "a3": a}, _features(q)))[1].sum())(
        jnp.array([[0.0]])
    )
    assert np.isfinite(np.asarray(g)).all()


def test_kernel_matches_generic_closed_form_condition_number():
    from designopt.kinematics import inv_cond

    q = m.sample_joints(jax.random.key(6), 1000)[:, :3]
    d = m.default_design()
    x = {k: jnp.asarray([[d[k]]]) for k in d}
    _, r = inv_cond_fro_jv(jv_entries(x, _features(q)))
    np.testing.assert_allclose(r[0], inv_cond(m.jacobian_v_closed(q, d)), rtol=1e-12)


def test_settings_reject_bad_values():
    with pytest.raises(ValueError, match="n_samples"):
        Indices(n_samples=-5)
    with pytest.raises(ValueError, match="measure"):
        Indices(measure="polar")
    with pytest.raises(ValueError, match="replicates"):
        Indices(sampler="rqmc", replicates=1)


def test_generic_workspace_average_matches_study_kernel():
    """montecarlo.workspace_average (generic g_and_w) vs the specialised master9 kernel."""
    from designopt.kinematics import inv_cond

    d = m.default_design()

    def g_and_w(q):
        J = m.jacobian_v_closed(q, d)
        return inv_cond(J), m.det_jv(q, d)

    lo, hi = m.POSITION_LIMITS[:, 0], m.POSITION_LIMITS[:, 1]
    est, n = mc.workspace_average(g_and_w, jax.random.key(8), lo, hi, 100_000, chunk=25_000)
    ref = obj.indices(d, n_samples=100_000, key=jax.random.key(9))
    assert n == 100_000
    assert abs(float(est.value) - ref["gci"]) < 4 * np.hypot(float(est.se), ref["gci_se"])
    joint, _ = mc.workspace_average(g_and_w, jax.random.key(8), lo, hi, 100_000, measure="joint")
    assert abs(float(joint.value) - float(est.value)) > 4 * float(est.se)  # the measures differ


def test_problem_carries_its_bounds_and_samples_typed():
    """Problem.norm_bounds is the Halton probe's (3, 2) min/max of (f_k, f_l, f_p) (the same
    numbers as params["bounds"] and the archived info), recomputed here by scoring the
    Halton designs with swarm_indices; n_samples_used is the plan's count."""
    from designopt.studies import streams

    keys = streams(3)
    P = obj.problem({"indices": {"n_samples": 4096, "chunk": 1024}, "n_norm": 8}, keys)
    s = Indices(n_samples=4096, chunk=1024)
    Xn = mc.box_samples(keys["normalisation"], P.lower, P.upper, 8, "halton", jnp.float64)
    d = {k: jnp.full((8,), v) for k, v in m.default_design().items()}
    d |= {n: Xn[:, i] for i, n in enumerate(P.names)}
    ind = swarm_indices(d, keys["samples"], s)
    ref = np.array([[np.min(ind[k]), np.max(ind[k])] for k in ("f_k", "f_l", "f_p")])
    np.testing.assert_allclose(P.norm_bounds, ref, rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(P.params["bounds"]), P.norm_bounds)
    assert [P.info["norm_bounds"][k] for k in ("f_k", "f_l", "f_p")] == P.norm_bounds.tolist()
    assert P.n_samples_used == P.info["n_samples_used"] == 4096
    assert P.names == ("a1", "a3", "d3") and P.lower.tolist() == [250, 250, 50]


def test_weighted_sum_and_flat_bounds():
    """normalise.weighted_sum against the formula in numpy; a flat index gets max = min + 1."""
    from designopt.problems import normalise

    rng = np.random.default_rng(5)
    x = [rng.normal(size=7) for _ in range(3)]
    se = [rng.uniform(0, 1, 7) for _ in range(3)]
    b = np.sort(rng.normal(size=(3, 2)), 1)
    w = [4.0, -2.0, 0.5]
    f, f_se = normalise.weighted_sum(x, jnp.asarray(b), w, se)
    span = b[:, 1] - b[:, 0]
    np.testing.assert_allclose(f, sum(w[i] * (x[i] - b[i, 0]) / span[i] for i in range(3)))
    np.testing.assert_allclose(f_se, sum(abs(w[i]) * se[i] / span[i] for i in range(3)))

    def fn(params, X, key):  # index "c" is flat over the box
        return X[:, 0], {"a": X[:, 0] + X[:, 1], "c": jnp.zeros(X.shape[0])}

    from designopt.studies import streams

    lo, hi = np.array([0.0, 1.0]), np.array([2.0, 3.0])
    bb = normalise.probe_bounds(fn, None, ("a", "c"), lo, hi, 16, streams(0), jnp.float64)
    Xn = np.asarray(mc.box_samples(streams(0)["normalisation"], lo, hi, 16, "halton"))
    np.testing.assert_array_equal(bb, [[Xn.sum(1).min(), Xn.sum(1).max()], [0.0, 1.0]])


def test_cost_names_the_config_keys_it_reads():
    """Study.cost: each *_key resolves, in the settings dump, to the number it reports
    (chunk: the smaller of chunk and n_samples, as a chunk never exceeds the samples)."""
    from designopt.studies import STUDIES
    from designopt.studies.master9.settings import Master9Settings

    for idx, n_norm in (({"n_samples": 5000, "chunk": 9000}, 7), ({}, 64)):
        s = Master9Settings.model_validate({"name": "master9", "indices": idx, "n_norm": n_norm})
        c = STUDIES["master9"].cost(s)
        dump = {"study": s.model_dump()}

        def at(key, dump=dump):
            for part in key.split("."):
                dump = dump[part]
            return dump

        assert c.samples == at(c.samples_key) == s.indices.n_samples
        assert c.chunk == min(at(c.chunk_key), c.samples)
        assert c.n_norm == at(c.norm_key) == n_norm
