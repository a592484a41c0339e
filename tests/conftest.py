"""Tests are the caller: they ask for float64 explicitly (``import designopt`` no longer
changes JAX's global configuration)."""

import gc
import os
import tempfile

import jax
import pytest

jax.config.update("jax_enable_x64", True)

# CLI calls in the tests keep compiled programs in a cache of this session's own, never in
# the user's (~/.cache/designopt/jax): other processes writing there at the same time (a
# run in another terminal, another test session) must not feed this one their entries.
os.environ.setdefault("DESIGNOPT_CACHE_DIR", tempfile.mkdtemp(prefix="designopt-test-cache-"))


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Each test module's compiled programs are dropped after it: a whole suite in one
    process otherwise keeps thousands of XLA executables mapped (about three memory
    maps each) and ran into the kernel's map limit (vm.max_map_count 65530), which
    crashed XLA mid-suite."""
    yield
    from designopt.app import job
    from designopt.problems import evaluate

    job._PROBLEMS.clear()
    evaluate._SCORERS.clear()
    jax.clear_caches()
    gc.collect()
