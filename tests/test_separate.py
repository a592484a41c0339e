"""The objective as a program of its own (``optim.run(separate=True)``, protocol ask/tell):
the same search as the fused run up to float32 fusion, deterministic, resumable bit for
bit, and one compiled objective for the normalisation probe, the run and its scoring."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt import api, optim
from designopt.problems.base import evaluate_batch
from designopt.studies import STUDIES, streams


def _problem(name: str, dtype=jnp.float32):
    st = STUDIES[name]
    s = st.settings.model_validate(st.tiny | {"name": name})
    return st.problem(s, streams(0), dtype)


@pytest.mark.parametrize("opt", ["ptpso", "cmaes"])
def test_separate_matches_fused_is_deterministic_and_resumes(opt: str) -> None:
    key = streams(0)["optimizer"]
    kw = dict(n_particles=8, n_iters=6, n_runs=3, chunk_iters=2)
    pr = _problem("master9")
    cks: list = []
    a = optim.run(opt, pr, key, separate=True, checkpoint=cks.append, dtype=jnp.float32, **kw)
    b = optim.run(opt, pr, key, separate=True, dtype=jnp.float32, **kw)
    resumed = optim.run(opt, pr, key, separate=True, resume=cks[1], dtype=jnp.float32, **kw)
    assert a.eval_shape == (3, 8)
    for r in (b, resumed):
        assert np.array_equal(a.history, r.history) and np.array_equal(a.best_x, r.best_x)
    # the same search as the fused run: in float64 only the rounding of the objective's
    # fusion differs (in float32 the swarms drift apart by ~1e-4 after a few iterations)
    pr64 = _problem("master9", jnp.float64)
    fused = optim.run(opt, pr64, key, dtype=jnp.float64, **kw)
    sep = optim.run(opt, pr64, key, separate=True, dtype=jnp.float64, **kw)
    assert fused.eval_shape is None
    np.testing.assert_allclose(sep.history, fused.history, rtol=1e-10)
    np.testing.assert_allclose(sep.best_x, fused.best_x, rtol=1e-9)


def test_separate_batch_and_multi_objective() -> None:
    pr = _problem("rcm")
    key = streams(0)["optimizer"]
    kw = dict(n_particles=8, n_iters=4, n_runs=2, dtype=jnp.float32)
    members = [{"c1": 1.5}, {"c1": 2.0}]
    fused = optim.run_batch("ptpso", pr, key, members, **kw)
    sep = optim.run_batch("ptpso", pr, key, members, separate=True, **kw)
    assert sep.eval_shape == (4, 8)
    np.testing.assert_allclose(sep.history, fused.history, rtol=1e-5)
    from designopt.problems.multi import multi_benchmark

    mo = multi_benchmark("bnh")  # two objectives, constraints: Deb's domination
    f1 = optim.run("nsga2", mo, key, **kw)
    f2 = optim.run("nsga2", mo, key, separate=True, **kw)
    np.testing.assert_allclose(f2.history, f1.history, rtol=1e-5)
    np.testing.assert_allclose(f2.front.f, f1.front.f, rtol=1e-5)


def test_main_job_compiles_its_objective_once() -> None:
    """A master9 run: the probe, the swarm's every evaluation and the scoring of the best
    run call one compiled objective (one entry in evaluate_batch's cache)."""
    jax.config.update("jax_enable_x64", True)
    cfg = api.load_config("configs/master9.yaml", {
        "study.indices.n_samples": 2048, "study.indices.replicates": 2, "study.n_norm": 8,
        "optimizer.n_particles": 6, "optimizer.n_iters": 3})  # fmt: skip
    before = evaluate_batch._cache_size()
    rec = api.run(cfg)
    assert evaluate_batch._cache_size() == before + 1
    assert np.isfinite(rec.final["f"])


def test_scoring_in_the_runs_shape_equals_plain_scoring() -> None:
    from designopt.problems.evaluate import score

    pr = _problem("serial", jnp.float64)
    X = np.random.default_rng(3).uniform(pr.lower, pr.upper, (11, pr.dim))
    a = score(pr, X)
    b = score(pr, X, eval_shape=(2, 4), dtype=np.float64)  # 3 batches of 8, the last padded
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_allclose(b[k], a[k], rtol=1e-12, atol=1e-15, err_msg=k)


def test_raw_keys_and_subclasses_with_their_own_step() -> None:
    """A raw uint32 key runs separate as fused; a subclass that overrides ``step`` (its
    own algorithm) is never run through the inherited ask/tell."""
    from dataclasses import dataclass

    from designopt.optim.pso import PSO

    pr = _problem("rcm", jnp.float64)
    kw = dict(n_particles=6, n_iters=3, n_runs=2, dtype=jnp.float64)
    a = optim.run("cmaes", pr, jax.random.PRNGKey(0), **kw)
    b = optim.run("cmaes", pr, jax.random.PRNGKey(0), separate=True, **kw)
    assert b.eval_shape == (2, 6)
    np.testing.assert_allclose(b.history, a.history, rtol=1e-10)

    @dataclass(frozen=True)
    class Frozen(PSO):
        def step(self, key, state, params, task):
            return state  # never moves

    assert PSO.asks() and not Frozen.asks()


def test_objective_program_key_and_rule() -> None:
    """``optimizer.objective_program``: auto is separate up to SEPARATE_UP_TO_ITERS
    iterations and fused beyond; separate and fused are taken as given; anything else is
    refused at validation; a fused main job runs."""
    from designopt.app.optimise import SEPARATE_UP_TO_ITERS, separate_objective
    from designopt.core.errors import ConfigError

    def opt(**kw):
        over = {f"optimizer.{k}": v for k, v in kw.items()}
        return api.load_config("configs/master9.yaml", over).optimizer

    assert opt().objective_program == "auto" and separate_objective(opt())
    assert not separate_objective(opt(n_iters=SEPARATE_UP_TO_ITERS + 1))
    assert separate_objective(opt(n_iters=SEPARATE_UP_TO_ITERS + 1, objective_program="separate"))
    assert not separate_objective(opt(objective_program="fused"))
    with pytest.raises(ConfigError, match="objective_program"):
        opt(objective_program="inline")
    jax.config.update("jax_enable_x64", True)
    cfg = api.load_config("configs/master9.yaml", {
        "study.indices.n_samples": 2048, "study.indices.replicates": 2, "study.n_norm": 8,
        "optimizer.n_particles": 6, "optimizer.n_iters": 3,
        "optimizer.objective_program": "fused"})  # fmt: skip
    rec = api.run(cfg)
    assert np.isfinite(rec.final["f"])
