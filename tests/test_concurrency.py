"""Independent calls of compiled programs side by side (designopt.core.concurrency): the
same results as one after the other, bit for bit, in the calls' order; errors raised;
no nesting; ``DESIGNOPT_THREADS=1`` turns it off; a background job is waited for."""

from __future__ import annotations

import threading
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.core import concurrency


def test_map_calls_keeps_the_order_and_runs_the_calls_at_once(monkeypatch):
    monkeypatch.setenv(concurrency.ENV, "2")
    names: list[str] = []
    barrier = threading.Barrier(2, timeout=10)  # both calls must be running at once

    def call(i: int):
        names.append(threading.current_thread().name)
        barrier.wait()
        return jnp.arange(3) + i

    out = concurrency.map_calls([lambda i=i: call(i) for i in range(2)])
    assert [np.asarray(o).tolist() for o in out] == [[0, 1, 2], [1, 2, 3]]
    assert all(n.startswith("designopt-call") for n in names)


def test_the_first_call_of_a_new_key_runs_alone(monkeypatch):
    monkeypatch.setenv(concurrency.ENV, "2")
    running, most = [0], [0]
    lock = threading.Lock()

    def call(i: int) -> int:
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        time.sleep(0.05 if i == 0 else 0.2)
        with lock:
            running[0] -= 1
        return i

    key = ("test", object())
    assert concurrency.map_calls([lambda i=i: call(i) for i in range(3)], key=key) == [0, 1, 2]
    assert most[0] == 2  # the first alone, then the two others together
    most[0] = 0
    assert concurrency.map_calls([lambda i=i: call(i) for i in range(2)], key=key) == [0, 1]
    assert most[0] == 2  # a key seen before: all at once


def test_an_error_is_raised_and_one_thread_is_one_after_the_other(monkeypatch):
    monkeypatch.setenv(concurrency.ENV, "2")

    def bad():
        raise ValueError("the second call")

    with pytest.raises(ValueError, match="the second call"):
        concurrency.map_calls([lambda: 1, bad, lambda: 3])
    monkeypatch.setenv(concurrency.ENV, "1")
    assert concurrency.threads() == 1
    names = []
    concurrency.map_calls([lambda: names.append(threading.current_thread().name)] * 2)
    assert names == [threading.main_thread().name] * 2


def test_calls_made_inside_a_call_run_in_its_thread(monkeypatch):
    monkeypatch.setenv(concurrency.ENV, "2")

    def outer(i: int) -> list[str]:
        inner = concurrency.map_calls([lambda: threading.current_thread().name] * 2)
        return [threading.current_thread().name, *inner]

    for got in concurrency.map_calls([lambda i=i: outer(i) for i in range(2)]):
        assert len(set(got)) == 1  # nested: one after the other in the worker itself


def test_in_background_waits_for_its_job_and_drops_its_error(monkeypatch):
    monkeypatch.setenv(concurrency.ENV, "2")
    done = []

    def job():
        time.sleep(0.2)
        done.append(True)
        raise RuntimeError("dropped: the phase that needs it reports its own")

    with concurrency.in_background(job):
        assert not done
    assert done == [True]
    with pytest.raises(KeyError), concurrency.in_background(lambda: done.append(False)):
        raise KeyError("the body's error")
    assert done == [True, False]  # waited for, the body's error raised
    monkeypatch.setenv(concurrency.ENV, "1")
    with concurrency.in_background(lambda: done.append("no")):
        pass
    assert done == [True, False]  # one thread: nothing runs in the background


def test_a_waiting_background_job_ends_with_the_body(monkeypatch):
    """A job that waits for an event (``concurrency.wait``, as the study's background
    compile waits for the search's first program) returns False at once when the body
    ends before the event (an error, Ctrl-C): the body's end is not held up; set in
    time, the wait returns True."""
    monkeypatch.setenv(concurrency.ENV, "2")
    event, seen = threading.Event(), []

    def job():
        seen.append(concurrency.wait(event, 60.0))
        seen.append(concurrency.ended())

    t0 = time.monotonic()
    with pytest.raises(KeyError), concurrency.in_background(job):
        raise KeyError("the body fails before the event")
    assert seen == [False, True] and time.monotonic() - t0 < 5.0
    seen.clear()
    with concurrency.in_background(job):
        event.set()
        time.sleep(0.1)
    assert seen[0] is True
    assert not concurrency.ended()  # outside a background job
    assert concurrency.wait(event, 0.0)
    assert not concurrency.wait(threading.Event(), 0.05)  # the timeout


def test_exported_wait_ready_once_the_first_program_is_traced_or_has_run(monkeypatch, tmp_path):
    """``exported.wait_ready`` returns once the first program from ``exported.compiled``
    has run; with ``traced``, once it has been traced and its call has begun: the call
    of an exported program (which compiles it, freeing the GIL) already sees that, not
    the run; a program traced by its own call (no cache folder) gives both when the call
    returns. The call's value is the program's."""
    from designopt.core import exported

    fn = jax.jit(lambda x: x * 2.0)
    seen = []
    real_jit = jax.jit

    def recording_jit(f, **kw):  # the loaded module's jit: its call records the waits
        inner = real_jit(f, **kw)

        def call(*a):
            seen.append((exported.wait_ready(0.0, traced=True), exported.wait_ready(0.0)))
            return inner(*a)

        return call

    for where in (tmp_path, None):
        monkeypatch.setattr(exported, "_READY", threading.Event())
        monkeypatch.setattr(exported, "_TRACED", threading.Event())
        monkeypatch.setattr(exported, "_CALLS", {})
        monkeypatch.setattr(exported, "folder", lambda w=where: w)
        with monkeypatch.context() as m:
            m.setattr(jax, "jit", recording_jit)
            call = exported.compiled(f"test-ready-{where is None}", fn, (jnp.ones(3),))
        assert not exported.wait_ready(0.0, traced=True)
        np.testing.assert_array_equal(np.asarray(call(jnp.ones(3))), [2.0, 2.0, 2.0])
        assert seen == ([(True, False)] if where is not None else [])
        assert exported.wait_ready(0.0) and exported.wait_ready(0.0, traced=True)
        seen.clear()
    assert list(tmp_path.glob("designopt-export-*.bin"))  # the first one was exported


def test_the_first_call_of_a_reduction_runs_alone_among_its_kind():
    """Two reductions of one code (two problems of a study, e.g. a race's two stages
    drawn side by side) called at once for the first time at the same shapes: the
    second waits until the first has returned (then compiles or loads its own), so
    their traces do not overlap; the values are each its own."""
    from designopt.problems import evaluate

    spans: list[tuple[float, float]] = []

    def make(scale: float):
        def reduce(params, X, k, values):
            t0 = time.perf_counter()
            time.sleep(0.3)  # at trace time
            spans.append((t0, time.perf_counter()))
            return scale * jnp.sum(X, -1), {"v": values * scale}

        return reduce

    a, b = (evaluate._reducer(make(s), None) for s in (1.0, 2.0))
    X = jnp.ones((3, 2)) * 0.123  # shapes no other test of the session uses
    out: dict[int, object] = {}
    threads = [threading.Thread(target=lambda i=i, r=r: out.__setitem__(i, r({}, X, None, X)))
               for i, r in enumerate((a, b))]  # fmt: skip
    for th in threads:
        th.start()
    for th in threads:
        th.join(30)
    assert len(spans) == 2
    (s0, e0), (s1, e1) = sorted(spans)
    assert s1 >= e0  # one after the other
    np.testing.assert_allclose(np.asarray(out[1][0]), 2 * np.asarray(out[0][0]))
    np.testing.assert_array_equal(np.asarray(out[1][2]), 0.0)  # no constraints: no violation


def test_the_task_blocks_side_by_side_equal_one_after_the_other(monkeypatch):
    """The PUMA port case of tests/test_staged.py (its block program, 24 targets in
    chunks of 16): 20 designs (two blocks) solved with two threads and with one give the
    same joints and values bit for bit."""
    from test_staged import N, _cfg

    from designopt.app.config import validate
    from designopt.core.keys import streams
    from designopt.studies.serial import blocks

    jax.config.update("jax_enable_x64", True)
    c = validate(_cfg("urdf_puma560_port.yaml", N, chunk=16), "t")
    rng = np.random.default_rng(3)
    X = np.array([[0.43, 0.43, 0.4]]) + rng.uniform(-0.05, 0.05, (20, 3))
    got = {}
    for n in ("1", "2"):
        monkeypatch.setenv(concurrency.ENV, n)
        got[n] = blocks.solutions(c.study, X, streams(c.seed), jnp.float64)
    assert set(got["1"]) == set(got["2"])
    for k in got["1"]:
        np.testing.assert_array_equal(got["1"][k], got["2"][k], err_msg=k)
    assert got["1"]["success"].any()


def test_the_calls_and_a_background_job_run_in_the_callers_precision(monkeypatch):
    """``jax.enable_x64`` (the API's calls run under it) holds in the thread that entered
    it: the pool's threads and a background job run in the caller's precision, not the
    process's (float32 arrays from float64 inputs gave an API ``evaluate`` of a task in
    several chunks wrong values)."""
    monkeypatch.setenv(concurrency.ENV, "2")
    before = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    try:
        seen: list = []
        with jax.enable_x64(True):
            out = concurrency.map_calls([lambda: jnp.zeros(2)] * 3)
            with concurrency.in_background(lambda: seen.append(jnp.zeros(2).dtype)):
                pass
        assert [o.dtype for o in out] == [jnp.float64] * 3
        assert seen == [jnp.float64]
        out = concurrency.map_calls([lambda: jnp.zeros(2)] * 3)  # and back: the process's
        assert [o.dtype for o in out] == [jnp.float32] * 3
    finally:
        jax.config.update("jax_enable_x64", before)
