"""Contract tests over the study registry: every registered study, on its ``tiny`` config."""

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import pytest
from figcheck import assert_clean

from designopt.app import pipeline, records
from designopt.app.config import validate
from designopt.app.job import Job
from designopt.figures import canvas
from designopt.studies import STUDIES, get, streams

NAMES = sorted(n for n, st in STUDIES.items() if st.replay is None)  # design studies


def config(name, tmp_path=None, **over):
    raw = {
        "study": get(name).tiny,
        "optimizer": {"name": "ptpso", "n_particles": 6, "n_iters": 4, "n_runs": 2},
        "precision": "float64",
        "seed": 3,
        "output": str((tmp_path or "results") / "a.h5") if tmp_path else None,
    } | over
    return validate(raw, "tiny")


@pytest.fixture(scope="module", params=NAMES)
def study_problem(request):
    cfg = config(request.param)
    return cfg, pipeline.build_problem(cfg, streams(cfg.seed))


def _designs(problem, n, seed=0):
    u = np.random.default_rng(seed).uniform(size=(n, problem.dim))
    return problem.lower + (problem.upper - problem.lower) * u


def test_every_study_declares_what_the_pipeline_needs():
    for name in NAMES:
        st = STUDIES[name]
        s = st.settings.model_validate(st.tiny)
        assert s.name == name
        assert set(st.summary(s)) <= set(st.indices(s))
        assert "f" in st.indices(s)


def test_swarm_row_equals_single_design(study_problem):
    cfg, P = study_problem
    X = _designs(P, 5)
    f, sub = jax.jit(P.fn)(P.params, jnp.asarray(X), jax.random.key(0))
    for i in (0, 3):
        f1, sub1 = jax.jit(P.fn)(P.params, jnp.asarray(X[i : i + 1]), jax.random.key(0))
        np.testing.assert_allclose(f1[0], f[i], rtol=1e-12, atol=1e-300)
        for k in sub:
            np.testing.assert_allclose(
                sub1[k][0], sub[k][i], rtol=1e-10, atol=1e-300
            )  # SE: sums reassociate


def test_every_index_has_a_standard_error(study_problem):
    cfg, P = study_problem
    res = pipeline.score(P, _designs(P, 2))
    st = get(cfg.study.name)
    for k in st.indices(cfg.study):
        assert k in res
    for k in st.summary(cfg.study):
        assert k + "_se" in res and np.all(res[k + "_se"] >= 0), k
    assert "f_se" in res


def test_gradients_are_finite(study_problem):
    cfg, P = study_problem
    x = jnp.asarray(_designs(P, 1, seed=1))
    # one program, as refine differentiates it (op by op, davinci's took hundreds of compiles)
    g = jax.jit(jax.grad(lambda X: P.fn(P.params, X, jax.random.key(0))[0].sum()))(x)
    assert np.all(np.isfinite(np.asarray(g))) and np.any(np.asarray(g) != 0)


BEFORE = {
    "davinci": {
        "x": [22.966670799255375, 17.706257467733643],
        "f": -1.582461029725005,
        "best_f": [-1.5824610297250052, -1.582460599452099],
    },
    "master9": {
        "x": [297.3866139883051, 266.6010130755288, 50.0],
        "f": -1.3693410225508915,
        "best_f": [-1.361047475828413, -1.3693410225509726],
    },
    "plas": {
        "x": [87.70244507199195, 79.60540902478498],
        "f": 0.01455093160333798,
        "best_f": [0.016966863020385192, 0.01455093160333798],
    },
    "rcm": {
        "x": [109.19623368963633, 252.2223143988924],
        "f": -0.5611102016462723,
        "best_f": [-0.5542628953837776, -0.5611102016462725],
    },
    "sphere_rcm": {
        "x": [89.81396244345191, 86.31629284591736],
        "f": -0.9646424272026286,
        "best_f": [-0.9646424272026286, -0.9631819996677957],
    },
    "serial": {
        "x": [0.8486084070508499, 0.05006753917671065],
        "f": -1.1649587500633616,
        "best_f": [-1.1649587500633625, -1.164727904703354],
    },
}
"""Final design, f and every run's best f of each study's tiny run (ptpso 6 × 8 × 2,
float64, seed 3) as the release before the records/pipeline redesign (#23, commit
0fb6917) computed them: the redesign must not change a number."""


@pytest.mark.parametrize("name", NAMES)
def test_run_stays_in_box_resumes_bit_exact_and_round_trips(name, tmp_path):
    cfg = config(name, tmp_path, optimizer={"name": "ptpso", "n_particles": 6, "n_iters": 8,
                                            "n_runs": 2})  # fmt: skip
    job = Job.build(cfg, "tiny")
    P = job.problem
    cks = []
    full = pipeline.optimise(job, P, checkpoint=cks.append)
    assert np.all(full.history_x >= P.lower - 1e-12) and np.all(full.history_x <= P.upper + 1e-12)
    assert cks, "chunked run gave no checkpoint"
    resumed = pipeline.optimise(job, P, resume=cks[0])
    np.testing.assert_array_equal(resumed.history, full.history)
    np.testing.assert_array_equal(resumed.history_x, full.history_x)
    # config round trip through the archive, and the record read back equals the run's
    rep = pipeline.run(cfg, "tiny", "tiny", tmp_path / "a.h5")
    rec = records.load(rep.out)
    assert rec == rep.record, rec.differs(rep.record)
    # the numbers of the release before the records/pipeline redesign (#23)
    np.testing.assert_allclose(list(rec.x.values()), BEFORE[name]["x"], rtol=1e-9, atol=1e-12)
    # f on the search's samples (best_run/final); rec.f is the fresh re-scoring's (#52)
    np.testing.assert_allclose(rec.search["f"], BEFORE[name]["f"], rtol=1e-9)
    np.testing.assert_allclose(rec.data()["optimizer"]["best_f"], BEFORE[name]["best_f"],
                               rtol=1e-9)  # fmt: skip
    back = validate(rec.attrs["config_resolved"], "archive")
    assert back == cfg and rec.config == cfg
    assert set(rec.keys()) == {"optimizer", "samples", "normalisation", "figures"}
    np.testing.assert_array_equal(rec.history, full.history)
    st = get(name)
    if st.cloud is not None:  # the interactive report's workspace cloud
        c = st.cloud(rec)
        n = len(c["value"])
        assert c["xyz"].shape == (n, 3) and n >= 1000 and c["label"] and c["unit"]
        assert np.all(np.isfinite(c["xyz"])) and np.all((c["value"] >= 0) & (c["value"] <= 1))
    canvas.RECORD = []  # every figure drawn also passes the figure checks (docs/figures.md)
    try:
        figs = get(name).figures(rec, tmp_path / "figs")
        assert figs and all(p.exists() for p in figs)
        assert_clean(canvas.RECORD)
    finally:
        canvas.RECORD = None
        plt.close("all")


@pytest.mark.parametrize("name", NAMES)
def test_eval_agrees_with_scan(name, tmp_path):
    cfg = config(name, tmp_path)
    P = pipeline.build_problem(cfg, streams(cfg.seed))
    v0, v1 = P.names[0], P.names[-1]
    lo, hi = P.lower[0], P.upper[0]
    scan = {"vary": {v0: {"from": float(lo), "to": float(hi), "num": 3}}, "batch": 2}
    cfg = config(name, tmp_path, scan=scan)
    rep = pipeline.scan(cfg, "tiny", "tiny", tmp_path / "s.h5")
    rec = records.load(rep.out)
    X, a = rec.X, rec.values
    assert X.shape == (3, P.dim)
    one = pipeline.evaluate(cfg, {v0: float(X[1, 0]), v1: float(X[1, -1])})
    assert not set(one) & set(P.names)  # indices only: {index: (1,), index_se: (1,)}
    for k, v in one.items():
        assert v.shape == (1,), k
        np.testing.assert_allclose(v[0], a[k][1], rtol=1e-10, err_msg=k)
    many = pipeline.evaluate(cfg, {v0: X[:, 0], v1: X[:, -1]})
    np.testing.assert_allclose(many["f"], a["f"], rtol=1e-12)
