"""designopt: a vectorized JAX design-space optimizer for surgical-robot mechanisms.

The Python API (``designopt.api``; README "Python"): ``load_config(path, overrides)``,
``run(config, out=None) -> RunRecord``, ``scan(config, out=None) ->
ScanRecord``, ``evaluate(config, designs)`` (arrays, one entry per design) and
``load(path) -> Record``; a user's own study or optimizer registers with
``designopt.studies.register`` / ``designopt.optim.register``. They are imported on first
use, so that the command line starts without JAX.

Importing the package changes no global state: JAX's 64-bit mode stays as the caller set
it. The ``designopt`` command turns it on for configs with ``precision: float64``; a
script that wants float64 calls ``jax.config.update("jax_enable_x64", True)`` first.
"""

from typing import Any

from designopt.core.errors import ConfigError, WriteError

try:  # one source of the version: pyproject.toml, as pip installed it
    from importlib.metadata import version as _dist_version

    __version__ = _dist_version("designopt")
except Exception:  # a source tree on sys.path, not installed  # noqa: BLE001
    __version__ = "unknown"

API = ("load_config", "run", "scan", "evaluate", "load")

__all__ = ["ConfigError", "WriteError", "__version__", *API]


def __getattr__(name: str) -> Any:
    if name in API:
        from designopt import api

        return getattr(api, name)
    raise AttributeError(f"module 'designopt' has no attribute {name!r}")
