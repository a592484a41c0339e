"""How much memory a job may use: the one probe the pre-flight estimate reads."""

from __future__ import annotations

import contextlib
import os


def host_memory() -> int:
    """Bytes of host memory available to this process now (MemAvailable, else free pages)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError):
        return 1 << 62


def available_memory() -> int:
    """Memory the job can use: the accelerator's when JAX runs on one, else the host's."""
    import jax

    if jax.default_backend() != "cpu":
        with contextlib.suppress(Exception):
            return int(jax.devices()[0].memory_stats()["bytes_limit"])
    return host_memory()
