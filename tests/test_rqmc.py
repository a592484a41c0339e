"""Randomised QMC (designopt.numerics.montecarlo): layout, bitwise accumulation, and honest SEs.

The SE tests draw many independent seeds and compare the reported SE with the observed
spread (pooled ratio within 1.5) and the z-scores against a high-accuracy reference
(spread near 1), for the ``rqmc`` and ``uniform`` samplers alike.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.numerics import montecarlo as mc

jax.config.update("jax_enable_x64", True)


def test_plan_layout_and_bad_input():
    p = mc.plan(8192, 8192, "rqmc", 16)
    assert (p.replicates, p.per_rep, p.chunk, p.n_used) == (16, 1, 512, 8192)
    p = mc.plan(10_000, 1000, "rqmc", 8)  # 1250 per replicate -> 2 chunks of 625
    assert (p.per_rep, p.chunk, p.n_used) == (2, 625, 10_000)
    assert mc.plan(100, 64, "rqmc").replicates == mc.DEFAULT_REPLICATES
    assert mc.plan(100, 64, "uniform").replicates == 1
    with pytest.raises(ValueError, match="at least 2"):
        mc.plan(100, 64, "rqmc", 1)
    with pytest.raises(ValueError, match="rqmc"):
        mc.plan(100, 64, "halton", 4)
    with pytest.raises(ValueError, match="sampler"):
        mc.check_sampling("sobol", 4, ("uniform", "rqmc"))


def test_replicates_are_shifted_halton_sets_in_the_unit_cube():
    p = mc.plan(4 * 256, 128, "rqmc", 4)
    key = jax.random.key(3)
    pts = np.stack([np.asarray(mc.chunk_points(key, k, p, 3)) for k in range(p.n_chunks)])
    assert pts.min() >= 0 and pts.max() < 1
    rep = pts.reshape(4, 256, 3)
    # each replicate: the Halton points 1..256 shifted by one vector (mod 1)
    base = np.asarray(mc.halton_points(0, 256, 3, jnp.zeros(3)))
    for r in range(4):
        d = np.mod(rep[r] - base, 1.0)
        assert np.allclose(np.mod(d - d[0] + 0.5, 1.0) - 0.5, 0.0, atol=1e-9)
    # the replicates are independent shifts, and low-discrepancy per coordinate
    assert not np.allclose(rep[0], rep[1])
    for r in range(4):
        counts = np.histogram(rep[r, :, 0], bins=16, range=(0, 1))[0]
        assert counts.max() - counts.min() <= 1


def test_to_replicate_accumulation_is_the_per_replicate_sum():
    p = mc.plan(6 * 64, 32, "rqmc", 6)
    key = jax.random.key(0)
    w = jnp.array([1.0, 2.0])

    def chunk(k):
        u = mc.chunk_points(key, k, p, 2)
        return mc.power_sums(w[:, None] * 0 + 1.0, jnp.sin(3 * u[:, 0])[None] * w[:, None])

    acc = mc.scan_chunks(lambda k: mc.to_replicate(chunk(k), k, p), mc.zero_sums((2,), p,
                         jnp.float64), p.n_chunks)  # fmt: skip
    for r in range(p.replicates):
        ks = range(r * p.per_rep, (r + 1) * p.per_rep)
        ref = chunk(ks[0])
        for k in ks[1:]:
            ref = mc.add(ref, chunk(k))
        np.testing.assert_allclose(np.asarray(acc.s1[:, r]), np.asarray(ref.s1), rtol=1e-14)
        assert float(acc.n[r]) == p.n_rep


def _ratio_case(sampler: str, replicates: int | None, n: int, n_seeds: int):
    """E[g w]/E[w] on [0,1]^3 with w = 1 + x0·x1, g = exp(x2)·cos(x0): values and SEs of
    ``n_seeds`` independent keys, and the exact value from 1-D integrals."""
    p = mc.plan(n, 4096, sampler, replicates)

    @jax.jit
    def one(key):
        def sums(k):
            u = mc.chunk_points(key, k, p, 3)
            w = 1.0 + u[:, 0] * u[:, 1]
            g = jnp.exp(u[:, 2]) * jnp.cos(u[:, 0])
            return mc.to_replicate(mc.power_sums(w, g), k, p)

        acc = mc.scan_chunks(sums, mc.zero_sums((), p, jnp.float64), p.n_chunks)
        return mc.finish(mc.mean(acc), p)

    keys = jax.random.split(jax.random.key(11), n_seeds)
    est = [one(k) for k in keys]
    v = np.array([float(e.value) for e in est])
    se = np.array([float(e.se) for e in est])
    # exact: ∫(1 + x0 x1) e^{x2} cos x0 / ∫(1 + x0 x1) = (e−1)(sin1 + (cos1 + sin1 − 1)/2) / (5/4)
    exact = (np.e - 1) * (np.sin(1) + 0.5 * (np.cos(1) + np.sin(1) - 1)) / 1.25
    return v, se, exact


@pytest.mark.parametrize("sampler,R", [("rqmc", 8), ("uniform", None), ("uniform", 8)])
def test_se_is_honest_on_a_known_ratio(sampler, R):
    v, se, exact = _ratio_case(sampler, R, 2048, 40)
    z = (v - exact) / se
    ratio = np.sqrt(np.mean(se**2)) / np.std(v - exact)
    assert 1 / 1.5 < ratio < 1.5, (ratio, z.std())
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.4
    if sampler == "rqmc":  # and far more accurate than i.i.d. points
        vu, seu, _ = _ratio_case("uniform", None, 2048, 8)
        assert np.mean(se) < 0.2 * np.mean(seu)


def test_combine_is_mean_and_sd_over_root_r():
    p = mc.Plan("rqmc", 5, 1, 8)
    x = jnp.array([[1.0, 2.0, 4.0, 3.0, 5.0], [1.0, 1.0, 1.0, 1.0, jnp.inf]])
    e = mc.combine(x, None, p)
    assert float(e.value[0]) == 3.0
    assert np.isclose(float(e.se[0]), np.std([1, 2, 4, 3, 5], ddof=1) / np.sqrt(5))
    assert np.isinf(float(e.value[1])) and np.isinf(float(e.se[1]))


def _master9_spread(sampler: str, R: int | None, n: int, n_seeds: int):
    from designopt.studies.master9 import mechanism as m
    from designopt.studies.master9.indices import swarm_indices
    from designopt.studies.master9.settings import Indices

    s = Indices(n_samples=n, chunk=8192, sampler=sampler, replicates=R)
    d = {k: jnp.asarray([v], jnp.float64) for k, v in {**m.default_design(),
                                                       **m.PAPER_FINAL}.items()}  # fmt: skip
    f = jax.jit(lambda k: swarm_indices(d, k, s))
    return [f(k) for k in jax.random.split(jax.random.key(5), n_seeds)]


def test_master9_rqmc_se_is_honest_and_smaller_than_uniform():
    from designopt.studies.master9 import mechanism as m
    from designopt.studies.master9.objective import indices

    ref = indices(m.PAPER_FINAL, n_samples=131_072, chunk=16_384, sampler="rqmc",
                  replicates=16, key=jax.random.key(77))  # fmt: skip
    ratios, zs = [], []
    for sampler, R, n in (("rqmc", 8, 4096), ("uniform", None, 4096)):
        rows = _master9_spread(sampler, R, n, 20)
        for k in ("gci", "f_k", "f_l", "gpi"):
            v = np.array([float(r[k][0]) for r in rows])
            se = np.array([float(r[k + "_se"][0]) for r in rows])
            assert ref[k + "_se"] < 0.1 * se.mean()  # the reference is far more accurate
            ratios.append(np.sqrt(np.mean(se**2)) / np.std(v - ref[k]))
            zs.append((v - ref[k]) / se)
            # the mean of the seeds agrees with the reference within 4 of its SEs (no bias)
            assert abs(v.mean() - ref[k]) < 4 * np.sqrt(
                np.mean(se**2) / len(v) + ref[k + "_se"] ** 2
            )
    pooled = np.exp(np.mean(np.log(ratios)))
    assert 1 / 1.5 < pooled < 1.5, ratios
    zsd = np.sqrt(np.mean(np.concatenate(zs) ** 2))
    assert 0.75 < zsd < 1.33, zsd


def _study_rows(study: str, section: str, upd: dict, keys: tuple[str, ...], n_seeds: int):
    """Main indices of the config's design-box centre for ``n_seeds`` sample keys
    (``study``: a config name under configs/, e.g. ``rcm`` or ``puma560``)."""
    import yaml

    from designopt.studies import STUDIES, streams

    raw = yaml.safe_load(open(f"configs/{study}.yaml"))["study"]
    st = STUDIES[raw["name"]]
    s = st.settings.model_validate({**raw, section: {**raw[section], **upd}})
    pr = st.problem(s, streams(0), jnp.float64)
    X = jnp.asarray([(np.asarray(pr.lower) + np.asarray(pr.upper)) / 2], jnp.float64)
    f = jax.jit(lambda p: pr.fn(p, X, None))
    rows = []
    for k in jax.random.split(jax.random.key(21), n_seeds):
        fv, d = f(dict(pr.params, sample_key=k))
        d = dict(d, f=fv)
        rows.append({n: (float(d[n][0]), float(d[n + "_se"][0])) for n in keys})
    return rows


@pytest.mark.parametrize(
    "study,section,keys,n,ref_n",
    [
        ("rcm", "eta", ("eta", "eta_box"), 4096, 1 << 19),
        ("plas", "mismatch", ("vel_rel", "vel_reduction", "pos_mean"), 1024, 1 << 16),
        ("planar2r", "indices", ("gci", "manipulability"), 1024, 1 << 18),  # serial
    ],
)
def test_study_se_is_honest_for_rqmc_and_uniform(study, section, keys, n, ref_n):
    big = {"n_samples": ref_n, "sampler": "rqmc", "replicates": 16}
    ref = _study_rows(study, section, big | ({"chunk": 8192} if study == "plas" else {}), keys,
                      1)[0]  # fmt: skip
    ratios, zs = [], []
    for sampler, R in (("rqmc", 8), ("uniform", 1)):
        rows = _study_rows(study, section, {"n_samples": n, "sampler": sampler,
                                            "replicates": R}, keys, 12)  # fmt: skip
        for k in keys:
            v = np.array([r[k][0] for r in rows])
            se = np.array([r[k][1] for r in rows])
            assert ref[k][1] < 0.2 * se.mean(), (k, ref[k], se.mean())
            ratios.append(np.sqrt(np.mean(se**2)) / np.std(v - ref[k][0]))
            zs.append((v - ref[k][0]) / se)
            assert abs(v.mean() - ref[k][0]) < 4 * np.sqrt(np.mean(se**2) / len(v) + ref[k][1] ** 2)
    pooled = np.exp(np.mean(np.log(ratios)))
    assert 1 / 1.5 < pooled < 1.5, ratios
    assert 0.7 < np.sqrt(np.mean(np.concatenate(zs) ** 2)) < 1.4
