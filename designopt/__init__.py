"""designopt: a vectorized JAX design-space optimizer for surgical-robot mechanisms.

Importing the package changes no global state: JAX's 64-bit mode stays as the caller set
it. The ``designopt`` command turns it on for configs with ``precision: float64``; a
script that wants float64 calls ``jax.config.update("jax_enable_x64", True)`` first.
"""

from designopt.pipeline import evaluate

__version__ = "0.1.0"

__all__ = ["__version__", "evaluate"]
