"""Tiny timing helper shared by the benchmark scripts (wall clock, best of n)."""

from __future__ import annotations

import time
from collections.abc import Callable

import jax


def best_of(fn: Callable[[], object], n: int = 5) -> float:
    """Best wall time (s) of n calls; JAX results are blocked on."""
    best = float("inf")
    for _ in range(n):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def compile_time(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t0


def header(title: str) -> None:
    dev = jax.devices()[0]
    print(f"== {title} ==  backend={jax.default_backend()} device={dev.device_kind}")
