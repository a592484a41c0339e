"""Tests are the caller: they ask for float64 explicitly (``import designopt`` no longer
changes JAX's global configuration)."""

import jax

jax.config.update("jax_enable_x64", True)
