"""One IK program per structure (issue #46, part 2): the task's per-target values run in
one compiled block program (``designopt.studies.serial.blocks``) that the search, the
front's re-scoring, ``eval``, the normalisation probe and the figures all call, and its
scores equal the one-program path's (``Problem.fn``, which the fused runner and
``jax.grad`` trace), whatever the chunk of targets or the block of designs: the IK's
solutions bit for bit, the values at them to 1e-12 (XLA vectorises batches of other
sizes differently: the last bits of a Jacobian, which its condition number amplifies)."""

from __future__ import annotations

import copy
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from designopt.app.config import validate
from designopt.core.keys import streams
from designopt.problems.evaluate import score
from designopt.studies.serial import blocks, objective, taskindex

jax.config.update("jax_enable_x64", True)


def _cfg(name: str, n: int, chunk: int | None = None) -> dict:
    path = Path("configs", name).resolve()
    with open(path) as f:
        cfg = yaml.safe_load(f)
    s = cfg["study"]
    s["indices"]["n_samples"] = n
    if chunk is not None:
        s["indices"]["chunk"] = chunk
    # no neighbour pass (its chunks hold whole runs of 16), and no climb (the staging, not
    # the IK, is checked)
    s["task"]["ik"] = s["task"].get("ik", {}) | {"neighbours": 0, "climb": 0}
    if isinstance(s["chain"].get("urdf"), str):
        s["chain"]["urdf"] = str(path.parent / s["chain"]["urdf"])
    return cfg


def _problem(cfg: dict):
    c = validate(copy.deepcopy(cfg), "test")
    return c, objective.problem(c.study, streams(c.seed), jnp.float64)


N = 24
"""Targets of the comparison: the size of tests/test_ports_designed.py's and
tests/test_scene_inputs.py's PUMA scenes, so that a session compiles the PUMA's one-chunk
program (2 designs, 24 targets) and its block program (chunks of 16) once for all three."""

CASES = [  # (config, designs): a port and a wall, two arms with collisions
    ("urdf_puma560_port.yaml", [[0.43, 0.43, 0.4], [0.5, 0.35, 0.3]]),
    ("two_arms_front.yaml", [[0.6, 0.45, 0.45], [0.5, 0.3, 0.55]]),
]


@pytest.mark.parametrize("name, X", CASES)
def test_the_staged_scores_equal_the_one_program_path(name, X):
    """f, every index, SE and count through the block program (2 designs: one block,
    padded; 24 targets in chunks of 16: two chunks, the last padded) equal ``fn``'s in
    one traced program (targets in one chunk of 24): the same IK solutions (joints,
    success) bit for bit, every value to 1e-12 relative."""
    X = np.asarray(X)
    _, staged = _problem(_cfg(name, N, chunk=16))
    _, whole = _problem(_cfg(name, N))
    assert taskindex.chunk(validate(_cfg(name, N, 16), "t").study) == 16
    assert taskindex.chunk(validate(_cfg(name, N), "t").study) == N
    c = validate(_cfg(name, N, 16), "t")
    Xb = np.concatenate([X, np.repeat(X[-1:], blocks.DESIGNS - len(X), 0)])
    per = blocks.assembled(c.study, [{k: np.asarray(v) for k, v in ch.items()}
                                     for ch in staged.staged.values(staged.params, Xb)],
                           blocks.DESIGNS, N, np)  # fmt: skip
    mech = blocks.program(c.study, jnp.float64)[0]
    ref_per = jax.jit(lambda p, X: taskindex.per_target(
        mech, c.study, whole.params, taskindex.design_full(p, X, jnp.float64), jnp.float64)
    )(whole.params, jnp.asarray(X))  # fmt: skip
    for k, v in ref_per.items():  # the IK's outcome bit for bit, the rest to its last bits
        if k in ("success", "converged", "q"):
            np.testing.assert_array_equal(per[k][:, : len(X)], np.asarray(v), err_msg=k)
        elif k in ("pos_err", "rot_err"):  # a converged solution's residual is a difference
            # of O(1) numbers (m, rad): its last bits are theirs (~1e-16 each), not its own
            # (a 1e-10 residual moved by 1e-16 is 1e-6 of itself; found under another XLA
            # code generator, XLA:CPU's classic fusion emitters)
            np.testing.assert_allclose(per[k][:, : len(X)], np.asarray(v), rtol=0, atol=1e-14,
                                       err_msg=k)  # fmt: skip
        else:  # XLA vectorises a (16·C)-row and a (3·N)-row batch differently, and 1/k
            # amplifies J's last bits by the condition number (3.5e-14 relative at 1/k 0.066)
            np.testing.assert_allclose(per[k][:, : len(X)], np.asarray(v), rtol=1e-12,
                                       atol=1e-16, err_msg=k)  # fmt: skip
    got = score(staged, X)
    f, aux = jax.jit(whole.fn)(whole.params, jnp.asarray(X), jax.random.key(0))
    ref = {"f": np.asarray(f)} | {k: np.asarray(v) for k, v in aux.items()}
    assert set(ref) <= set(got)
    for k in ref:  # the per-target values' last bits and the reductions' order
        np.testing.assert_allclose(got[k], ref[k], rtol=1e-12, atol=0, err_msg=k)


def test_one_block_program_serves_every_phase(tmp_path):
    """A front run of two arms (the search on 32 targets, the front's re-scoring on 96,
    then a figure's solution of a front design) compiles the IK once: one block program
    (16 targets a chunk, as ``indices.chunk`` says: the block program of the two arms'
    case above), one shape."""
    from designopt import api

    cfg = _cfg("two_arms_front.yaml", 32, chunk=16)
    cfg["optimizer"] |= {"n_particles": 8, "n_iters": 2}
    cfg["optimizer"].pop("fidelity")  # (a cheaper search IK is another program by design)
    cfg["front"] = {"n_samples": 96}
    from designopt.core import exported

    blocks._PROGRAMS.clear()
    exported._CALLS.clear()
    rec = api.run(cfg, tmp_path / "a.h5")
    assert len(blocks._PROGRAMS) == 1
    (call,) = exported._CALLS.values()  # one block signature (exported or not)
    assert call._cache_size() == 1
    x = np.asarray(rec["front"]["x"])[0]
    sol = blocks.solution(rec.config.study, x, rec.keys())  # a figure's
    assert len(exported._CALLS) == 1 and call._cache_size() == 1
    assert sol["success"].shape == (2, 32)


def test_a_warm_run_loads_the_exported_block_program(tmp_path, monkeypatch):
    """With a compilation cache folder the block program is kept as exported StableHLO
    (``core.exported``): a second process (here: the in-memory table cleared) loads it
    instead of tracing the IK again, and gives the same values bit for bit. (The PUMA's
    block program of the comparison above: XLA's compile is the cache's hit.)"""
    from designopt.core import exported

    monkeypatch.setattr(exported, "folder", lambda: tmp_path)  # the cache folder
    c, pr = _problem(_cfg("urdf_puma560_port.yaml", N, chunk=16))
    X = np.asarray([[0.43, 0.43, 0.4]] * blocks.DESIGNS)
    exported._CALLS.clear()
    first = pr.staged.values(pr.params, X)
    files = list(tmp_path.glob("designopt-export-*.bin"))
    assert len(files) == 1
    exported._CALLS.clear()
    blocks._PROGRAMS.clear()
    blocks._MEMO.clear()  # (the rows of the first call: the program runs again)

    def no_trace(*a, **k):
        raise AssertionError("traced again")

    monkeypatch.setattr(jax.export, "export", no_trace)
    again = pr.staged.values(pr.params, X)
    for a, b in zip(first, again, strict=True):
        for k in a:
            np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b[k]), err_msg=k)


def test_a_block_of_designs_computed_before_reads_their_rows(monkeypatch):
    """A block call whose designs were all computed before, on the same targets and
    params, is answered from their kept rows (``blocks._MEMO``; two arms: rows a·M + d)
    in the new call's order, bit for bit what the program gives for that block; other
    params (another sample key) run the program. (The two arms' block program of the
    comparison above.)"""
    from designopt.core import exported

    _, pr = _problem(_cfg("two_arms_front.yaml", N, chunk=16))
    a, b = np.asarray(CASES[1][1])
    ab = np.stack([a] + [b] * (blocks.DESIGNS - 1))
    ba = np.stack([b] + [a] * 3 + [b] * (blocks.DESIGNS - 4))
    blocks._MEMO.clear()
    pr.staged.values(pr.params, ab)  # computes a's and b's rows
    real = exported.compiled

    def refuse(*args, **kw):
        def ran(*a, **k):
            raise AssertionError("the program ran")

        return ran

    monkeypatch.setattr(exported, "compiled", refuse)
    kept = pr.staged.values(pr.params, ba)
    other = pr.params | {"sample_key": jax.random.key(7)}
    with pytest.raises(AssertionError, match="the program ran"):
        pr.staged.values(other, ab)
    monkeypatch.setattr(exported, "compiled", real)
    blocks._MEMO.clear()
    fresh = pr.staged.values(pr.params, ba)
    assert len(kept) == len(fresh) == 2  # two chunks of 16 targets
    for got, ref in zip(kept, fresh, strict=True):
        assert set(got) == set(ref) and "segments" in got
        for k in ref:
            np.testing.assert_array_equal(got[k], np.asarray(ref[k]), err_msg=k)


def test_the_least_call_runs_the_first_chunk_only():
    """``Staged.least`` (what the background compile calls the block program with) keeps
    the first chunk of targets: one call, whose values are the first chunk's of the
    whole call."""
    _, pr = _problem(_cfg("two_arms_front.yaml", N, chunk=16))
    X = np.repeat(np.asarray(CASES[1][1])[:1], blocks.DESIGNS, 0)
    least = pr.staged.least(pr.params)
    assert least["target_p"].shape == (16, 3) and pr.params["target_p"].shape == (N, 3)
    (one,) = pr.staged.values(least, X)
    whole = pr.staged.values(pr.params, X)
    assert len(whole) == 2
    for k in whole[0]:
        np.testing.assert_array_equal(np.asarray(one[k]), np.asarray(whole[0][k]), err_msg=k)


def test_the_elemental_emitters_give_the_same_solutions(monkeypatch):
    """``indices.emitters: elemental`` compiles the block program with XLA:CPU's classic
    emitters (``core.xlaoptions``: the option reaches ``jax.jit``), another code
    generator: the same IK outcome and the same values to the IK's own tolerance. (The
    two arms' block program of the comparison above, and its twin.)"""
    from designopt.core import xlaoptions

    assert xlaoptions.options("fusion") == {}
    assert xlaoptions.options("elemental") == {"xla_cpu_use_fusion_emitters": False}
    with pytest.raises(ValueError, match="emitters"):
        xlaoptions.options("llvm")
    X = np.repeat(np.asarray(CASES[1][1]), blocks.DESIGNS // 2, 0)
    _, fusion = _problem(_cfg("two_arms_front.yaml", N, chunk=16))
    cfg = _cfg("two_arms_front.yaml", N, chunk=16)
    cfg["study"]["indices"]["emitters"] = "elemental"
    _, elemental = _problem(cfg)
    a = fusion.staged.values(fusion.params, X)
    jit, given = jax.jit, []

    def recording(*args, **kw):  # the options the block program is jitted with
        given.append(kw.get("compiler_options"))
        return jit(*args, **kw)

    monkeypatch.setattr(jax, "jit", recording)
    b = elemental.staged.values(elemental.params, X)
    monkeypatch.setattr(jax, "jit", jit)
    assert {"xla_cpu_use_fusion_emitters": False} in given
    for ca, cb in zip(a, b, strict=True):
        assert set(ca) == set(cb)
        for k in ca:
            x, y = np.asarray(ca[k]), np.asarray(cb[k])
            if k in ("success", "converged"):
                np.testing.assert_array_equal(y, x, err_msg=k)
            else:  # the IK converges to 1e-9 (× the reach scale, rad)
                np.testing.assert_allclose(y, x, rtol=1e-9, atol=1e-9, err_msg=k)
