"""Tests are the caller: they ask for float64 explicitly (``import designopt`` no longer
changes JAX's global configuration)."""

import os
import tempfile

import jax

jax.config.update("jax_enable_x64", True)

# CLI calls in the tests keep compiled programs in a cache of this session's own, never in
# the user's (~/.cache/designopt/jax): other processes writing there at the same time (a
# run in another terminal, another test session) must not feed this one their entries.
os.environ.setdefault("DESIGNOPT_CACHE_DIR", tempfile.mkdtemp(prefix="designopt-test-cache-"))
