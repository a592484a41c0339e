"""PSO's step as a GPU runs it (``pso.on_cpu``'s other formulation: every inertia rule and
both penalty branches computed and selected, no conditional in the loop), checked on the
CPU since CI has no GPU: the same search as the CPU's step up to rounding, and no
conditional in the compiled scan. The CPU's own step is untouched by it (its results are
pinned by the other tests)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt import optim
from designopt.optim import pso, registry, runner
from designopt.problems.benchmarks import benchmark


def _fresh(P):
    """P behind a new function object: its programs are traced and compiled anew (the
    formulation is read while tracing; a benchmark's function and programs are cached)."""
    base = P.fn
    return dataclasses.replace(P, fn=lambda p, X, key: base(p, X, key))


def _run(monkeypatch, form: str, *args, batch=None, **kw):
    """A run traced with the given formulation."""
    monkeypatch.setattr(pso, "FORCE_PLATFORM", form)
    P = _fresh(benchmark("rastrigin", 5, shift=1))
    key = jax.random.key(5)
    if batch is not None:
        return optim.run_batch(args[0], P, key, batch, 12, 15, 3, dtype=jnp.float64, **kw)
    return optim.run(args[0], P, key, 12, 15, 3, dtype=jnp.float64, **kw)


@pytest.mark.parametrize("variant", ["p1", "p3", "p4", "p5", "p6", "p7"])
def test_gpu_step_is_the_cpu_step_up_to_rounding(monkeypatch, variant: str) -> None:
    jax.config.update("jax_enable_x64", True)
    a = _run(monkeypatch, "cpu", variant, bounds="reflect")
    b = _run(monkeypatch, "other", variant, bounds="reflect")
    np.testing.assert_allclose(b.history, a.history, rtol=1e-9)
    np.testing.assert_allclose(b.history_x, a.history_x, rtol=1e-9, atol=1e-12)


def test_gpu_step_with_batched_penalty_and_separate(monkeypatch) -> None:
    jax.config.update("jax_enable_x64", True)
    members = [{"penalty": 0.0}, {"penalty": 1.0, "c1": 1.7}]
    a = _run(monkeypatch, "cpu", "p3", batch=members)
    b = _run(monkeypatch, "other", "p3", batch=members)
    np.testing.assert_allclose(b.history, a.history, rtol=1e-9)
    c = _run(monkeypatch, "cpu", "p6", separate=True)
    d = _run(monkeypatch, "other", "p6", separate=True)
    np.testing.assert_allclose(d.history, c.history, rtol=1e-9)


def test_gpu_step_has_no_conditional(monkeypatch) -> None:
    P = benchmark("sphere", 4)
    opt = registry.build("ptpso", 6, 5, "clip")
    e = registry.resolve("ptpso")
    params = e.cls.make_params(jnp.float32, e.preset)
    lo, hi = jnp.asarray(P.lower, jnp.float32), jnp.asarray(P.upper, jnp.float32)
    st = dict(opt=opt, fn=P.fn, cons=P.constraints)
    texts = {}
    for form in ("cpu", "other"):
        monkeypatch.setattr(pso, "FORCE_PLATFORM", form)
        fresh = dict(st, fn=_fresh(P).fn)  # a fresh trace per formulation
        carry = runner._init(jax.random.split(jax.random.key(0), 2), params, P.params, lo, hi,
                             **fresh)  # fmt: skip
        texts[form] = runner._advance.lower(carry, params, P.params, lo, hi, length=5,
                                            **fresh).compile().as_text()  # fmt: skip
    assert "conditional(" in texts["cpu"]  # the rule's switch and the penalty's cond
    assert "conditional(" not in texts["other"]
