"""Fixtures of the fault-injection suite: the reference result and the children's
environment."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from faultkit import config

from designopt.cli.commands import main


@pytest.fixture(scope="session")
def reference(tmp_path_factory) -> Path:
    """The uninterrupted run of TINY (every interrupted-and-resumed run must equal it)."""
    d = tmp_path_factory.mktemp("reference")
    cfg = config(d)
    assert main(["run", str(cfg), "--quiet", "--no-figures", "--out", str(d / "ref.h5")]) == 0
    return d / "ref.h5"


@pytest.fixture(scope="session")
def child_env() -> dict[str, str]:
    """The environment of child processes: the test session's compilation cache
    (tests/conftest.py), where the in-process ``reference`` run left TINY's programs."""
    env = dict(os.environ)
    assert env.get("DESIGNOPT_CACHE_DIR"), "tests/conftest.py sets the session's cache"
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2])
    return env
