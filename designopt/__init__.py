"""designopt: a vectorized JAX design-space optimizer for surgical-robot mechanisms.

Importing the package enables JAX's 64-bit mode so that float64 is available where
accuracy is the point (IK, reference tests). Throughput code casts its inputs to the
precision chosen in the config (float32 or float64); nothing is silently promoted.
"""

import jax

jax.config.update("jax_enable_x64", True)

__version__ = "0.1.0"

__all__ = ["__version__"]
