"""designopt: a vectorized JAX design-space optimizer for surgical-robot mechanisms.

Importing the package changes no global state: JAX's 64-bit mode stays as the caller set
it. The ``designopt`` command turns it on for configs with ``precision: float64``; a
script that wants float64 calls ``jax.config.update("jax_enable_x64", True)`` first.
``designopt.evaluate`` is :func:`designopt.pipeline.evaluate` (imported on first use, so
that the command line starts without JAX).
"""

from typing import Any

__version__ = "0.1.0"

__all__ = ["__version__", "evaluate"]


def __getattr__(name: str) -> Any:
    if name == "evaluate":
        from designopt.pipeline import evaluate

        return evaluate
    raise AttributeError(f"module 'designopt' has no attribute {name!r}")
