"""Dropping the compiled programs a test process holds (conftest's module fixture and
test_documented_commands' scenarios): they stay in the session's cache folder, so a later
test loads rather than compiles them. (A module of its own: ``conftest`` is not one name
in a session that also collects tests/faults/conftest.py.)"""

import gc

import jax


def release_compiled_programs() -> None:
    """Drop every compiled program this process holds."""
    from designopt.app import job
    from designopt.core import exported
    from designopt.problems import evaluate
    from designopt.studies.serial import blocks

    job._PROBLEMS.clear()
    evaluate._SCORERS.clear()
    blocks._PROGRAMS.clear()
    exported._CALLS.clear()
    jax.clear_caches()
    gc.collect()
