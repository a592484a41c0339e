"""The task indices' SEs from independent replications (issue #65, item 1): the targets
fall into R interleaved groups, each solved with its own IK database and seeds, and every
SE is the spread of the groups' values (batch means). Checked against the formulas in
NumPy, at a design that reaches nothing, and against the spread over seeds of a planar 3R
(benchmarks/se_honesty.py measures the shipped cases at 16 seeds)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import designopt
from designopt.kinematics import ik
from designopt.studies.serial import taskindex

jax.config.update("jax_enable_x64", True)

PLANAR3R = "tests/data/planar3r_task.yaml"
BOX = {"study.task.region": {"shape": "box", "center": [1.2, 0.3, 0.0], "size": [1.0, 1.0, 0.0]},
       "study.task.ik": {}, "study.indices.n_samples": 64}  # fmt: skip
DESIGN = {"l1": 1.0, "l2": 0.8, "l3": 0.5}


def _per(rng: np.random.Generator, A: int, M: int, N: int) -> dict[str, jax.Array]:
    ok = (rng.random((A, M, N)) < 0.8).astype(np.float64)
    return {"success": jnp.asarray(ok), "converged": jnp.asarray(ok),
            "inv_k": jnp.asarray(ok * rng.random((A, M, N))),
            "manipulability": jnp.asarray(ok * rng.gamma(2.0, 0.1, (A, M, N))),
            "joint_margin": jnp.asarray(ok * rng.random((A, M, N)))}  # fmt: skip


def _batch(v: np.ndarray, g: np.ndarray, G: int, x: np.ndarray | None = None) -> np.ndarray:
    """The batch-means SE of Σv/Σx (x = 1: the mean) in NumPy, one loop per group."""
    x = np.ones_like(v) if x is None else x
    Y = np.stack([v[..., g == k].sum(-1) for k in range(G) if np.any(g == k)], -1)
    X = np.stack([x[..., g == k].sum(-1) for k in range(G) if np.any(g == k)], -1)
    Gp = Y.shape[-1]
    r = Y.sum(-1) / X.sum(-1)
    return np.sqrt(((Y - r[..., None] * X) ** 2).sum(-1) / (Gp * (Gp - 1))) / (X.sum(-1) / Gp)


@pytest.mark.parametrize("N, run", [(40, 1), (37, 1), (70, 16)])
def test_se_is_the_batch_means_formula(N, run):
    """Every mean's SE is the spread of its groups (equal groups: the SD of the group
    means / √G; unequal: the ratio form), computed here from the per-target values and
    the groups (target t in (t // run) % G); the shares never below Agresti–Coull; the
    quantile's the order-statistic SE scaled by the groups' design effect on the share
    below it."""
    G = 8
    per = _per(np.random.default_rng(N), 1, 3, N)
    est = taskindex.estimates(per, grp=(G, run))
    iid = taskindex.estimates(per)
    g = (np.arange(N) // run) % G
    for k in ("gci", "manipulability", "joint_margin"):
        v = np.asarray(taskindex.values(per, k))
        np.testing.assert_allclose(est[k][0], v.mean(-1), rtol=1e-14)  # the point estimate
        want = _batch(v, g, G)
        np.testing.assert_allclose(est[k][1], want, rtol=1e-12)
        if N % G == 0 and run == 1:
            means = np.stack([v[:, g == j].mean(-1) for j in range(G)], -1)
            np.testing.assert_allclose(est[k][1], means.std(-1, ddof=1) / np.sqrt(G), rtol=1e-12)
    s = np.asarray(per["success"][0])
    ac = np.asarray(iid["reach"][1])
    np.testing.assert_allclose(est["reach"][1], np.maximum(ac, _batch(s, g, G)), rtol=1e-12)
    np.testing.assert_array_equal(est["gci_q05"][0], iid["gci_q05"][0])
    v = np.asarray(per["inv_k"][0])  # the quantile's: the order-statistic SE × the groups'
    below = (v <= np.asarray(est["gci_q05"][0])[:, None]).astype(float)  # design effect
    deff = np.maximum(_batch(below, g, G) / np.sqrt(0.05 * 0.95 / N), 1.0)
    np.testing.assert_allclose(est["gci_q05"][1], np.asarray(iid["gci_q05"][1]) * deff,
                               rtol=1e-12)  # fmt: skip


def test_ratio_and_tuples_stay_within_groups():
    """A ratio's SE is the batch-means one of Σy/Σx; the arms' tuples pair distinct
    targets of one group (each group mapped onto itself, no target onto itself)."""
    N, G = 53, 8
    rng = np.random.default_rng(1)
    x = (rng.random((2, N)) < 0.7).astype(np.float64)
    y = x * (rng.random((2, N)) < 0.6)
    lab = ik.group_of(jnp.arange(N), G)
    r, se = taskindex.ratio(jnp.asarray(y), jnp.asarray(x), 5, lab, G)
    np.testing.assert_allclose(r, y.sum(-1) / x.sum(-1), rtol=1e-14)
    g = np.arange(N) % G
    want = _batch(y, g, G, x)
    pt = (y.sum(-1) + 2) / (x.sum(-1) + 4)
    np.testing.assert_allclose(se, np.maximum(want, np.sqrt(pt * (1 - pt) / (x.sum(-1) + 4))),
                               rtol=1e-12)  # fmt: skip
    perms = [np.asarray(p) for p in taskindex.perms(jax.random.key(3), N, lab, 3)]
    np.testing.assert_array_equal(perms[0], np.arange(N))
    for p in perms[1:]:
        assert sorted(p.tolist()) == list(range(N))  # a permutation
        np.testing.assert_array_equal(g[p], g)  # of each group onto itself
        assert np.all(p != np.arange(N))  # no target paired with itself
    assert np.all(perms[1] != perms[2])  # three distinct targets per tuple


def test_a_design_that_reaches_nothing_has_finite_ses():
    """Per-target values all 0 (no target reached), two arms: every SE finite (no NaN
    but the n/a ratios), the shares' SEs positive."""
    per = {k: v * 0 for k, v in _per(np.random.default_rng(0), 2, 2, 48).items()}
    est = taskindex.estimates(per, grp=(8, 1))
    for k, (v, se) in est.items():
        assert np.all(np.isfinite(v)) and np.all(np.isfinite(se)), k
        assert np.all(np.asarray(se) >= 0), k
    for k in ("reach", "reach_0", "reach_1", "reach_all"):
        assert np.all(np.asarray(est[k][1]) > 0), k


def _eval(over: dict, seed: int, design: dict = DESIGN) -> dict[str, np.ndarray]:
    cfg = designopt.load_config(PLANAR3R, BOX | over | {"seed": seed})
    return designopt.evaluate(cfg, design)


def test_se_holds_across_seeds_and_reaching_nothing():
    """A planar 3R on a box of its plane, default IK settings, 64 targets: over 8 seeds
    the spread of every IK-read index is at most 2 × the RMS of its printed SE (it was
    1.5-1.7 × for manipulability and joint_margin at 16 seeds with one database); the
    smallest arm on a box out of its reach: reach 0 with a positive, finite SE, every other
    SE finite."""
    rows = [_eval({}, s) for s in range(8)]
    for k in ("gci", "gci_q05", "manipulability", "joint_margin"):
        v = np.array([float(r[k][0]) for r in rows])
        se = np.array([float(r[k + "_se"][0]) for r in rows])
        assert np.all(se > 0), k
        ratio = v.std(ddof=1) / np.sqrt(np.mean(se**2))
        assert ratio <= 2.0, (k, ratio)
    far = _eval({"study.task.region.center": [2.0, 0.0, 0.0]}, 0,
                {"l1": 0.5, "l2": 0.3, "l3": 0.2})  # reaches 1.0: the box lies 1.5-2.5 away
    assert float(far["reach"][0]) == 0.0
    assert 0 < float(far["reach_se"][0]) < 0.1
    for k in ("gci", "gci_q05", "manipulability", "joint_margin"):
        assert float(far[k][0]) == 0.0 and np.isfinite(float(far[k + "_se"][0])), k


def test_grouped_solve_in_chunks_gives_the_values_of_one_piece():
    """``ik.solve`` with 4 replication groups (each its own database): a task solved in
    chunks of 8 (t0 = 0, 8, …; the last padded with copies of the last target) gets the
    joints and successes of one piece, bit for bit, since a target's group is that of its
    index in the task; a design that is a copy of another (``rep``) gets its values; the
    groups' databases differ (one group's targets solved alone with G = 1 differ)."""
    import math

    from designopt.kinematics.kernel import dh_model

    pi = math.pi
    six = dh_model("standard", "RRRRRR", [pi / 2, 0, -pi / 2, pi / 2, -pi / 2, 0],
                   ["a1", "a2", "a3", 0, 0, 0], ["d1", 0, "d3", "d4", 0, "d6"], [0] * 6)  # fmt: skip
    puma = np.array([0.0, 0.4318, 0.0203, 0.0, 0.15005, 0.4318, 0.05])
    lo = np.radians([-160, -110, -135, -266, -100, -266.0])
    opts = ik.IKOptions(n_best=2, slots=64, rounds=2, n_db=512)
    X = jnp.asarray(np.stack([puma, puma * [1, 1.2, 1, 1, 1, 0.9, 1], puma]))
    rep = jnp.asarray([0, 1, 0], jnp.int32)
    N, C = 30, 8
    rng = np.random.default_rng(3)
    _, p = six.fk(jnp.asarray(puma), jnp.asarray(rng.uniform(lo, -lo, (N, 6))))
    p = np.array(p)

    @jax.jit
    def solve(p, t0, G=4):
        return ik.solve(six, X, p, None, jnp.asarray(lo), jnp.asarray(-lo), jax.random.key(5),
                        "position", opts, t0=t0, rep=rep, groups=G)  # fmt: skip

    whole = solve(jnp.asarray(p), 0)
    n_chunks = -(-N // C)
    pp = np.concatenate([p, np.repeat(p[-1:], n_chunks * C - N, 0)])
    parts = [solve(jnp.asarray(pp[c * C:(c + 1) * C]), c * C) for c in range(n_chunks)]
    q = np.concatenate([np.asarray(r.q) for r in parts], 1)[:, :N]
    ok = np.concatenate([np.asarray(r.success) for r in parts], 1)[:, :N]
    np.testing.assert_array_equal(ok, np.asarray(whole.success))
    np.testing.assert_array_equal(q, np.asarray(whole.q))
    np.testing.assert_array_equal(np.asarray(whole.q[2]), np.asarray(whole.q[0]))
    assert ok.mean() > 0.5
    one = jax.jit(lambda p: ik.solve(six, X, p, None, jnp.asarray(lo), jnp.asarray(-lo),
                                     jax.random.key(5), "position", opts, rep=rep))(
        jnp.asarray(p))  # fmt: skip
    assert not np.array_equal(np.asarray(one.q), np.asarray(whole.q))
