"""The count of distinct IK solutions as an input (``ik.solve``'s ``n_keep``,
``taskindex.BEST_SLOTS``): a program with 8 solution slots asked for k of them gives,
bit for bit, what a program of k slots gives; settings that differ only in
``study.task.ik.n_best`` (2 to 8) share one block program (docs/task.md)."""

from __future__ import annotations

import copy
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from designopt.app.config import validate
from designopt.kinematics import ik
from designopt.studies.serial import blocks, taskindex
from tests.test_task_ik import LO6, OPTS6, PUMA, SIX_R, _fk_targets

ROOT = Path(__file__).resolve().parents[1]


def test_eight_slots_asked_for_k_solve_as_k_slots():
    """The PUMA 560 at 384 targets: a static 3-slot and 8-slot solve against the 8-slot
    program with k = 3 and k = 8 as an input (one compiled program for both): every
    field equal, joints and 1/k bit for bit."""
    p, R = _fk_targets(SIX_R, PUMA, LO6, -LO6, 384, 5)
    lo, hi = jnp.asarray(LO6), jnp.asarray(-LO6)
    x = jnp.asarray(PUMA)[None]

    def static(nb):
        o = OPTS6._replace(n_best=nb)
        return jax.jit(lambda X: ik.solve(SIX_R, X, p, R, lo, hi, jax.random.key(3), "position",
                                          o))(x)  # fmt: skip

    runtime = jax.jit(lambda X, k: ik.solve(SIX_R, X, p, R, lo, hi, jax.random.key(3),
                                            "position", OPTS6._replace(n_best=8), n_keep=k))  # fmt: skip
    for k in (3, 8):
        want, got = static(k), runtime(x, jnp.int32(k))
        for name, a, b in zip(ik.IKResult._fields, want, got, strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=f"{name}, k={k}")
    assert runtime._cache_size() == 1
    three, eight = static(3), static(8)  # and the count matters: more solutions, better 1/k
    ok = np.asarray(three.success & eight.success)
    assert np.all(np.asarray(eight.inv_k)[ok] >= np.asarray(three.inv_k)[ok] - 1e-12)
    assert np.mean(np.asarray(eight.inv_k)[ok] > np.asarray(three.inv_k)[ok] + 1e-6) > 0.05


def _settings(n_best: int):
    path = ROOT / "configs/port_placement.yaml"
    raw = yaml.safe_load(path.read_text())
    raw = copy.deepcopy(raw)
    raw["study"]["task"]["ik"]["n_best"] = n_best
    return validate(raw, str(path), checks=False).study


@pytest.mark.parametrize("a, b, shared", [(2, 8, True), (3, 5, True), (1, 2, False),
                                          (8, 16, False)])  # fmt: skip
def test_settings_that_differ_only_in_n_best_share_the_block_program(a, b, shared):
    sa, sb = _settings(a), _settings(b)
    assert (blocks.block_key(sa) == blocks.block_key(sb)) is shared
    assert (taskindex.options(sa) == taskindex.options(sb)) is shared
    pa = taskindex.scene_params(sa, jnp.float64)["ik_n_best"]
    assert int(pa) == a and pa.dtype == jnp.int32
