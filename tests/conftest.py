"""Tests are the caller: they ask for float64 explicitly (``import designopt`` no longer
changes JAX's global configuration)."""

import os
import shutil
import tempfile

import jax
import pytest
from compiled import release_compiled_programs

from designopt.cli.setup import use_cache

jax.config.update("jax_enable_x64", True)

# CLI calls in the tests keep compiled programs in a cache of this session's own, never in
# the user's (~/.cache/designopt/jax): other processes writing there at the same time (a
# run in another terminal, another test session) must not feed this one their entries.
# pytest-xdist's workers inherit the controller's variable: they share the folder, and
# so do the child processes the tests start (they get os.environ): a program compiles
# once per session. Only the process that made the folder removes it, at the session's end.
_OWN_CACHE = "" if os.environ.get("DESIGNOPT_CACHE_DIR") else tempfile.mkdtemp(
    prefix="designopt-test-cache-")  # fmt: skip
if _OWN_CACHE:
    os.environ["DESIGNOPT_CACHE_DIR"] = _OWN_CACHE

# The whole session keeps its compiled programs there from the first test on, as the CLI
# does for its runs (designopt.cli.setup.use_cache): a program that another test module
# (or a worker, or a child process given this folder) compiled already is loaded, not
# compiled again, after _release_compiled_programs dropped it from memory. Loaded
# programs are XLA's own serialized executables: the same numbers. (Without this, the
# first in-process CLI call switched the cache on for the rest of the session anyway.)
use_cache()


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Each test module's compiled programs are dropped after it: a whole suite in one
    process otherwise keeps thousands of XLA executables mapped (about three memory
    maps each) and ran into the kernel's map limit (vm.max_map_count 65530), which
    crashed XLA mid-suite."""
    yield
    release_compiled_programs()


def pytest_sessionfinish(session: pytest.Session) -> None:
    """The session's cache folder goes when the session ends (in the process that made
    it: xdist's controller, after its workers; a folder given in $DESIGNOPT_CACHE_DIR
    stays)."""
    if _OWN_CACHE and not hasattr(session.config, "workerinput"):
        shutil.rmtree(_OWN_CACHE, ignore_errors=True)
