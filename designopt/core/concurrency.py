"""Independent calls of compiled programs run side by side on the CPU's cores.

XLA's CPU backend runs one call of a program on one thread unless the program's loops
are large enough to split (intra-op parallelism), and it runs the calls dispatched from
one Python thread one after the other, even when they are independent. The task's IK
(a ``while_loop`` over a small batch of slots) is such a program: on a 2-core machine
one call of the planning case's block uses one core. :func:`map_calls` runs a list of
independent calls from a pool of threads (one per core the process may use), each
thread waiting for its own call's result, so that ``k`` calls take about the time of
``⌈k / cores⌉`` (docs/performance.md, "The IK's calls side by side"). The programs and their
inputs are those of the one-thread path, so the results are the same bit for bit.

:func:`in_background` compiles what a later phase needs while the present one runs (a
run's search and its final stage use two IK programs of different settings).

Where it stays one thread: ``DESIGNOPT_THREADS=1``; a backend other than the CPU; more
than one device or process (their programs' collectives must be issued in the same order
on every device); a call made from one of the pool's threads (no nesting)."""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

T = TypeVar("T")

ENV = "DESIGNOPT_THREADS"
"""Environment variable: how many calls run at once (default: the cores this process may
use, ``os.sched_getaffinity``); 1 turns the pool off."""

_local = threading.local()
_pool: list[ThreadPoolExecutor | None] = [None]
_started: set[Any] = set()
_lock = threading.Lock()


def cores() -> int:
    """The CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux
        return os.cpu_count() or 1


def threads() -> int:
    """How many calls :func:`map_calls` runs at once: ``$DESIGNOPT_THREADS`` (a whole
    number ≥ 1; anything else is ignored) or :func:`cores`; 1 where JAX runs on another
    backend than the CPU, on several devices or in several processes, and inside the
    pool's own threads."""
    if getattr(_local, "worker", False):
        return 1
    import jax

    if jax.default_backend() != "cpu" or jax.device_count() > 1 or jax.process_count() > 1:
        return 1
    raw = os.environ.get(ENV, "").strip()
    n = int(raw) if raw.isdigit() and int(raw) >= 1 else cores()
    return max(1, n)


def _worker_init() -> None:
    _local.worker = True


def _executor(n: int) -> ThreadPoolExecutor:
    with _lock:
        pool = _pool[0]
        if pool is None or pool._max_workers < n:  # noqa: SLF001  (grown, never shrunk)
            if pool is not None:
                pool.shutdown(wait=False)
            pool = ThreadPoolExecutor(n, thread_name_prefix="designopt-call",
                                      initializer=_worker_init)  # fmt: skip
            _pool[0] = pool
        return pool


def _ready(fn: Callable[[], T]) -> Callable[[], T]:
    def run() -> T:
        import jax

        return jax.block_until_ready(fn())

    return run


def _in_callers_precision(fn: Callable[[], T]) -> Callable[[], T]:
    """``fn`` to run in another thread under the calling thread's JAX precision:
    ``jax.enable_x64`` (as the API's calls use it) is a context of the thread that
    entered it, so a pool thread would otherwise trace and run the call in the process's
    default precision (float32 arrays from float64 inputs)."""
    import jax

    x64 = bool(jax.config.jax_enable_x64)

    def run() -> T:
        with jax.enable_x64(x64):
            return fn()

    return run


def map_calls(calls: Sequence[Callable[[], T]], key: Any = None) -> list[T]:
    """``[c() for c in calls]``, each result ready (``jax.block_until_ready``), the calls
    run at once on :func:`threads` threads. ``key`` (hashable) names the programs the
    calls run: the first time a key is seen the first call runs alone (it compiles or
    loads the programs; two threads would each compile them), then the rest together.
    An exception of any call is raised (the first in the calls' order)."""
    calls = [_in_callers_precision(_ready(c)) for c in calls]
    n = min(threads(), len(calls))
    if n <= 1:
        return [c() for c in calls]
    out: list[T] = []
    if key is not None and key not in _started:
        out.append(calls[0]())
        _started.add(key)
        calls = calls[1:]
        n = min(n, len(calls))
        if n <= 1:
            return out + [c() for c in calls]
    futures = [_executor(n).submit(c) for c in calls]
    return out + [f.result() for f in futures]


@contextlib.contextmanager
def in_background(fn: Callable[[], Any] | None) -> Iterator[None]:
    """Run ``fn()`` (e.g. a later phase's first call, to compile its programs) in a thread
    while the ``with`` body runs; the body's end waits for it, whether the body returns
    or raises, so no thread outlives the block. What ``fn`` raises is dropped: the phase
    that needs the programs makes its own call and reports its own errors. ``fn`` may
    ask :func:`ended` between its steps, and wait with :func:`wait`: both end its work
    early once the body has ended. ``None`` or :func:`threads` 1: nothing runs."""
    if fn is None or threads() <= 1:
        yield
        return
    done = threading.Event()
    job = _in_callers_precision(fn)

    def run() -> None:
        _local.worker, _local.done = True, done
        with contextlib.suppress(Exception):
            job()

    t = threading.Thread(target=run, name="designopt-warm", daemon=True)
    t.start()
    try:
        yield
    finally:
        done.set()
        t.join()


def ended() -> bool:
    """In a job of :func:`in_background`: whether the ``with`` body it runs beside has
    ended (returned or raised); elsewhere False."""
    done = getattr(_local, "done", None)
    return done is not None and done.is_set()


def wait(event: threading.Event, timeout: float) -> bool:
    """Wait until ``event`` is set (True), ``timeout`` s have passed or, in a job of
    :func:`in_background`, its ``with`` body has ended (False)."""
    end = time.monotonic() + timeout
    while not event.wait(min(0.05, max(end - time.monotonic(), 0.0))):
        if ended() or time.monotonic() >= end:
            return False
    return True
