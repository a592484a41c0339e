"""Wall time split into compile time (JAX tracing, lowering, XLA compile) and the rest.

JAX reports each compilation stage through ``jax.monitoring``; one listener sums them so
that commands and benchmarks can print compile and run time separately.
"""

from __future__ import annotations

import time
from typing import Any

import jax

_STAGES = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)
_BACKEND = "/jax/core/compile/backend_compile_duration"
_total = [0.0]
_count = [0]
_registered = [False]


def _listener(name: str, secs: float, **_: Any) -> None:
    if name in _STAGES:
        _total[0] += secs
    if name == _BACKEND:
        _count[0] += 1  # one XLA compilation (or persistent-cache load) of a program


class Stopwatch:
    """``with Stopwatch() as sw: ...`` then ``sw.wall``, ``sw.compile``, ``sw.run`` and
    ``sw.compilations``: the XLA programs of the interval, each counted once per backend
    compilation, which is also the event of loading it from the persistent compilation
    cache (so a warm run counts the programs it loads)."""

    def __init__(self) -> None:
        if not _registered[0]:
            jax.monitoring.register_event_duration_secs_listener(_listener)
            _registered[0] = True
        self.wall = self.compile = 0.0
        self.compilations = 0

    def __enter__(self) -> Stopwatch:
        self._t, self._c, self._n = time.perf_counter(), _total[0], _count[0]
        return self

    def __exit__(self, *exc: Any) -> None:
        self.wall = time.perf_counter() - self._t
        self.compile = _total[0] - self._c
        self.compilations = _count[0] - self._n

    def elapsed(self) -> float:
        """Seconds since the stopwatch started (it keeps running)."""
        return time.perf_counter() - self._t

    @property
    def run(self) -> float:
        return max(self.wall - self.compile, 0.0)
