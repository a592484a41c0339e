"""XLA compile options chosen by name, per program.

XLA's CPU backend has two code generators for its fusions: the fusion emitters (its
default) and the classic elemental emitters (``xla_cpu_use_fusion_emitters = false``).
A program written entry by entry, as the task's block program is (every entry of a
frame, a Jacobian or a residual its own small array: about a thousand small fusions,
each compiled on its own), compiles about a third faster with the elemental ones; which
of the two runs it faster depends on the program (docs/performance.md, "XLA:CPU's code
generators"). The values agree to their last bits, not bit for bit.

:func:`options` gives the ``compiler_options`` of ``jax.jit`` for a name. The option is
given per program (``jax.jit(..., compiler_options=...)``), never to the whole process:
a wide vectorised program (a swarm's Monte-Carlo integrals in float32) runs faster with
the default. Where the backend is not the CPU, or the installed jaxlib does not know the
option (checked once, by compiling a one-line program with it), there are none.
"""

from __future__ import annotations

import threading
from typing import Any, Literal

Emitters = Literal["fusion", "elemental"]

_BY_NAME: dict[str, dict[str, Any]] = {
    "fusion": {},
    "elemental": {"xla_cpu_use_fusion_emitters": False},
}

_LOCK = threading.Lock()
_CHECKED: dict[tuple[str, str], dict[str, Any]] = {}


def options(emitters: Emitters) -> dict[str, Any]:
    """The compile options (``jax.jit(..., compiler_options=...)``) that select XLA:CPU's
    ``emitters`` on this process's default backend: ``{}`` for ``fusion``, on another
    backend, or where jaxlib refuses the option."""
    if emitters not in _BY_NAME:
        raise ValueError(f"emitters must be one of {sorted(_BY_NAME)}, got {emitters!r}")
    want = _BY_NAME[emitters]
    if not want:
        return {}
    import jax

    key = (jax.default_backend(), emitters)
    with _LOCK:
        if key not in _CHECKED:
            _CHECKED[key] = _accepted(want) if key[0] == "cpu" else {}
        return dict(_CHECKED[key])


def _accepted(opts: dict[str, Any]) -> dict[str, Any]:
    import jax
    import numpy as np

    try:
        jax.jit(lambda x: x + 1, compiler_options=opts).lower(np.float32(0)).compile()
    except Exception:  # noqa: BLE001  (an option this jaxlib does not know: none)
        return {}
    return dict(opts)
