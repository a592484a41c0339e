"""Typed records (designopt.results), the archive's load/save, and the public Python API:
round trips for every record kind, `load(run(cfg, out=p)) == run(cfg)`, overrides
validated like the file, and no generic module naming a study."""

import io
import re
import tokenize
from pathlib import Path

import numpy as np
import pytest

import designopt
from designopt import api, results
from designopt.app import records
from designopt.core.errors import ConfigError
from designopt.io import archive
from designopt.studies import STUDIES

ROOT = Path(__file__).resolve().parents[1]
PLANAR = ROOT / "configs" / "planar2r.yaml"
SMALL = {"optimizer.n_iters": 6, "optimizer.n_particles": 8, "study.indices.n_samples": 2048,
         "scan.vary.l2.num": 5}  # fmt: skip


@pytest.fixture(scope="module")
def cfg():
    return designopt.load_config(PLANAR, SMALL)


@pytest.fixture(scope="module")
def run_pair(cfg, tmp_path_factory):
    out = tmp_path_factory.mktemp("api") / "run.h5"
    return designopt.run(cfg, out=out), designopt.run(cfg), out


def test_run_in_memory_equals_the_loaded_archive(run_pair):
    written, memory, out = run_pair
    loaded = designopt.load(out)
    assert isinstance(loaded, results.RunRecord)
    assert loaded == written, loaded.differs(written)
    assert loaded == memory, loaded.differs(memory)
    assert loaded.attrs["complete"] and "complete" not in memory.attrs


def test_run_record_gives_the_design_its_indices_and_history(run_pair, cfg):
    rec = run_pair[1]
    assert list(rec.x) == ["l1", "l2"]
    for n, (lo, hi) in cfg.study.variables.items():
        assert lo <= rec.x[n] <= hi
    gci, se = rec.indices["gci"]
    assert rec.f == pytest.approx(-gci, abs=0) and 0 < se < 0.05 * gci
    assert rec.history.shape == (cfg.optimizer.n_runs, cfg.optimizer.n_iters + 1)
    assert np.all(np.diff(rec.history, axis=1) <= 0)  # best so far never worsens
    assert rec.config.optimizer.n_iters == 6
    # the same design scored by evaluate gives the same f on the search's samples (the run
    # quotes it re-scored on fresh ones: rec.f): one pipeline behind both
    ev = designopt.evaluate(cfg, rec.x)
    assert ev["f"].shape == (1,) and float(ev["f"][0]) == pytest.approx(rec.search["f"], rel=1e-12)


def test_a_changed_value_makes_records_differ(run_pair):
    rec = run_pair[1]
    tree = rec.to_tree()
    tree["final"] = dict(tree["final"]) | {"f": np.float64(rec.f + 1e-12)}
    other = results.from_tree(tree)
    assert other != rec and other.differs(rec) == "/final/f"
    tree = rec.to_tree()
    tree["attrs"] = dict(tree["attrs"]) | {"seed": rec.seed + 1}
    assert results.from_tree(tree) != rec
    # timings are measurements, not results
    tree = rec.to_tree()
    tree["attrs"] = dict(tree["attrs"]) | {"wall_time_s": 1e6}
    assert results.from_tree(tree) == rec


def _round_trip(rec, path):
    assert results.from_tree(rec.to_tree()) == rec
    archive.save(path, rec)
    back = records.load(path)
    assert type(back) is type(rec)
    assert back == rec, back.differs(rec)
    return back


def test_every_record_kind_round_trips(cfg, run_pair, tmp_path):
    _round_trip(run_pair[1], tmp_path / "run.h5")
    sc = designopt.scan(cfg)
    back = _round_trip(sc, tmp_path / "scan.h5")
    assert back.varied == ["l2"] and back.X.shape == (5, 2) and back.best_lines()
    sw = api.sweep(designopt.load_config(
        PLANAR, SMALL | {"sweep": {"vary": {"optimizer.gamma": [0.3, 0.6]}}}))  # fmt: skip
    back = _round_trip(sw, tmp_path / "sweep.h5")
    assert len(back.members) == 2
    ik = results.IKRecord(dict(run_pair[1].attrs) | {"kind": "ik"}, {"ik": {
        "q": np.arange(12.0).reshape(2, 6), "success": np.array([True, False]),
        "pos_err": np.array([1e-10, 3.0]), "rot_err": np.array([1e-12, 0.1]),
        "attrs": {"joint_names": ["a", "b", "c", "d", "e", "f"], "n": 2}}})  # fmt: skip
    back = _round_trip(ik, tmp_path / "ik.h5")
    assert back.success.tolist() == [True, False] and "1 solved" in " ".join(back.summary())
    bench = results.BenchRecord({"kind": "bench", "seed": 1}, {"bench": {"sphere": {
        "ptpso": {"history": np.ones((2, 3)), "best_f": np.zeros(2), "attrs": {"wall_s": 0.1}},
        "attrs": {"stats": {"rows": {"ptpso": {"mean": 0.0}}}}}}})  # fmt: skip
    back = _round_trip(bench, tmp_path / "bench.h5")
    assert back.stats("sphere")["rows"]["ptpso"]["mean"] == 0.0
    replay = results.ReplayRecord({"kind": "run", "study": "rcm_teleop", "seed": 0},
                                  {"teleop": {"err": np.arange(3.0), "attrs": {"summary": "ok"}}})  # fmt: skip
    assert _round_trip(replay, tmp_path / "replay.h5").summary()[-1] == "ok"


def test_a_checkpoint_is_a_record(tmp_path):
    ck = results.Record({"kind": "run", "resume_key": "k"}, {"checkpoint": {
        "state": {"x": np.ones((2, 3))}, "history": np.ones((2, 4)),
        "history_x": np.ones((2, 4, 3)), "attrs": {"done": 3}}})  # fmt: skip
    archive.save(tmp_path / "c.partial.h5", ck, complete=False)
    back = records.load(tmp_path / "c.partial.h5")
    assert isinstance(back, results.CheckpointRecord) and back.done == 3
    c = back.checkpoint()
    assert c.done == 3 and np.array_equal(c.state["x"], np.ones((2, 3)))
    assert back.summary() == ["interrupted after 3 iterations; best so far 1.00000"]
    hv = {"checkpoint": dict(ck.groups["checkpoint"], history=np.array([[0.1, 0.4], [0.2, 0.3]]))}
    front = results.from_tree({"attrs": {"kind": "front", "complete": False}, **hv})
    assert front.summary() == ["interrupted after 3 iterations; largest hypervolume so far 0.4"]


def test_load_refuses_what_is_not_an_archive(tmp_path):
    with pytest.raises(ConfigError, match="archive not found"):
        designopt.load(tmp_path / "none.h5")
    (tmp_path / "t.h5").write_text("not hdf5")
    with pytest.raises(ConfigError, match="not a readable HDF5 archive"):
        designopt.load(tmp_path / "t.h5")


def test_overrides_are_validated_like_the_file():
    c = designopt.load_config(PLANAR, {"optimizer.n_iters": 5, "seed": 7})
    assert c.optimizer.n_iters == 5 and c.seed == 7
    with pytest.raises(ConfigError, match=r"key 'optimizer.n_iters': must be ≥ 1"):
        designopt.load_config(PLANAR, {"optimizer.n_iters": 0})
    with pytest.raises(ConfigError, match="optimizer.n_itres"):
        designopt.load_config(PLANAR, {"optimizer.n_itres": 5})
    with pytest.raises(ConfigError, match="not finite|nan"):
        designopt.load_config(PLANAR, {"study.variables.l1": [0.2, float("nan")]})
    with pytest.raises(ConfigError, match="'seed' is not a section"):
        designopt.load_config(PLANAR, {"seed.x": 1})


def test_evaluate_always_returns_arrays(cfg):
    one = designopt.evaluate(cfg, {"l1": 1.0, "l2": 0.5})
    many = designopt.evaluate(cfg, {"l1": 1.0, "l2": [0.5, 0.7, 0.9]})
    assert one["gci"].shape == (1,) and many["gci"].shape == (3,)
    assert many["gci"][0] == pytest.approx(one["gci"][0], rel=1e-13)  # batch size: sum order
    with pytest.raises(ConfigError, match="l3"):
        designopt.evaluate(cfg, {"l3": 1.0})


KEPT = {tokenize.NAME, tokenize.STRING, tokenize.COMMENT, getattr(tokenize, "FSTRING_MIDDLE", -1)}


def _code_tokens(path: Path) -> list[str]:
    """Names, strings (not docstrings) and comments of a module."""
    out, prev = [], tokenize.INDENT
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
        if tok.type == tokenize.STRING and prev in (tokenize.INDENT, tokenize.NEWLINE,
                                                    tokenize.NL, tokenize.DEDENT):  # fmt: skip
            prev = tok.type  # a docstring (or a bare string statement)
            continue
        if tok.type in KEPT:
            out.append(tok.string)
        if tok.type not in (tokenize.COMMENT,):
            prev = tok.type
    return out


def test_no_generic_module_names_a_study():
    """Config, pipeline, CLI and every other module outside designopt/studies/<name>/ reach
    studies through the registry only: no study's name in their code or comments."""
    names = sorted(STUDIES)
    pat = re.compile(r"\b(" + "|".join(map(re.escape, names)) + r")\b")
    bad = []
    for p in sorted((ROOT / "designopt").rglob("*.py")):
        rel = p.relative_to(ROOT / "designopt")
        if rel.parts[0] == "studies" and len(rel.parts) > 2:
            continue  # a study's own folder
        for t in _code_tokens(p):
            if pat.search(t):
                bad.append(f"{rel}: {t[:60]}")
    assert not bad, bad


def test_report_html_writes_one_page_with_the_workspace_cloud(run_pair, capsys):
    from designopt.cli.commands import main
    from designopt.studies.serial import figures

    out = run_pair[2]
    assert main(["report", str(out), "--html", "--no-cache"]) == 0
    page = out.with_suffix(".html")
    assert capsys.readouterr().out.strip() == str(page)
    text = page.read_text()
    assert text.startswith("<!DOCTYPE html>") and "designopt run: serial" in text
    assert "1/k (2-norm)" in text  # the study's cloud hook
    rec = designopt.load(out)
    c = figures.cloud(rec, n=200)
    # independent numpy reference: the same joint samples (the figures stream), the planar
    # 2R arm's tip position and σmin/σmax of its 2×2 position Jacobian
    import jax

    rng = np.random.default_rng(np.asarray(jax.random.key_data(rec.keys()["figures"]), np.uint32))
    q = np.deg2rad(-180 + 360 * rng.uniform(size=(200, 2)))
    l1, l2 = rec.x["l1"], rec.x["l2"]
    s1, c1 = np.sin(q[:, 0]), np.cos(q[:, 0])
    s12, c12 = np.sin(q.sum(1)), np.cos(q.sum(1))
    tip = np.stack([l1 * c1 + l2 * c12, l1 * s1 + l2 * s12], -1)
    J = np.stack([np.stack([-l1 * s1 - l2 * s12, -l2 * s12], -1),
                  np.stack([l1 * c1 + l2 * c12, l2 * c12], -1)], -2)  # fmt: skip
    sv = np.linalg.svd(J, compute_uv=False)
    np.testing.assert_allclose(c["xyz"][:, :2], tip, atol=1e-12)
    np.testing.assert_allclose(c["xyz"][:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(c["value"], sv[:, 1] / sv[:, 0], rtol=1e-9, atol=1e-12)


def test_a_registered_optimizer_runs_from_a_config(cfg):
    """optim.register: a user's optimizer (here a plain random search) becomes a name a
    config can give; its run is a RunRecord like any other."""
    from typing import NamedTuple

    import jax
    import jax.numpy as jnp

    from designopt import optim
    from designopt.optim.protocol import Best, Optimizer, argbest

    class RandomSearch(Optimizer):
        class Params(NamedTuple):
            shrink: float = 0.5

        def init(self, key, params, task):
            x = jax.random.uniform(key, (self.n, task.lower.size), task.lower.dtype)
            x = task.lower + (task.upper - task.lower) * x
            f, v = task.evaluate(x, key)
            i = argbest(f, v)
            return x[i], f[i], v[i]

        def step(self, key, state, params, task):
            x0, f0, v0 = state
            w = params.shrink * (task.upper - task.lower)
            x = jnp.clip(x0 + w * jax.random.uniform(key, (self.n, x0.size), x0.dtype, -1, 1),
                         task.lower, task.upper)  # fmt: skip
            f, v = task.evaluate(x, key)
            i = argbest(f, v)
            take = (v[i] < v0) | ((v[i] == v0) & (f[i] < f0))
            return (jnp.where(take, x[i], x0), jnp.where(take, f[i], f0),
                    jnp.where(take, v[i], v0))  # fmt: skip

        def best(self, state):
            return Best(*state)

    optim.register("random_search_test", RandomSearch, source="a test's random search")
    with pytest.raises(ValueError, match="already registered"):
        optim.register("random_search_test", RandomSearch)
    c = cfg.model_copy(update={"optimizer": cfg.optimizer.model_copy(
        update={"name": "random_search_test", "settings": {"shrink": 0.3}})})  # fmt: skip
    rec = designopt.run(c)
    assert rec.config.optimizer.name == "random_search_test"
    assert rec.data()["optimizer"]["attrs"]["settings"]["shrink"] == pytest.approx(0.3)
    assert np.all(np.diff(rec.history, axis=1) <= 0) and rec.f <= rec.history[:, 0].min()
