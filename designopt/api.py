"""The public Python API: the same pipeline the ``designopt`` command runs, returning
typed records (``designopt.results``) instead of printing.

    import designopt
    cfg = designopt.load_config("configs/planar2r.yaml", {"optimizer.n_iters": 20})
    rec = designopt.run(cfg)                  # in memory: nothing written
    rec.x, rec.f, rec.indices["gci"]          # {variable: value}, f, (value, se)
    rec = designopt.run(cfg, out="results/m9.h5")   # the archive the CLI writes
    designopt.load("results/m9.h5") == rec    # True
    designopt.evaluate(cfg, {"l2": [0.5, 0.7]})["f"]     # one entry per design

Errors in a config or a design raise ``designopt.ConfigError`` naming the key. A float64
config runs in JAX's 64-bit mode for the extent of the call (``jax.enable_x64``, a
context: the caller's other JAX code keeps the precision it had); the arrays it returns
are numpy.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from designopt.core.errors import ConfigError
from designopt.results import Record, RunRecord, ScanRecord, SweepRecord

Config = Any
"""A validated run config (``load_config``), a config path, or a parsed config dict."""


def load_config(path: str | os.PathLike, overrides: Mapping[str, Any] | None = None) -> Any:
    """The validated config of a YAML file; ``overrides`` maps dotted keys to values
    (``{"optimizer.n_iters": 5, "study.indices.n_samples": 4096}``), set in the parsed
    YAML before validation, so they are checked exactly like the file's own keys."""
    from designopt.app.config import load

    return load(path, overrides=overrides)[0]


def _config(config: Config) -> tuple[Any, str]:
    """(validated config, where) of a path, a parsed dict or a config object. A config
    object built or changed in Python is validated again, through the same one entry as a
    file (``app.config.validate``)."""
    from designopt.app.config import validate

    if isinstance(config, str | os.PathLike):
        return load_config(config), str(config)
    if isinstance(config, Mapping):
        return validate(dict(config), "config"), "config"
    try:
        raw = config.model_dump(by_alias=True)
    except AttributeError:
        raise ConfigError(f"config: {type(config).__name__} is not a config; give a path, a "
                          "dict or designopt.load_config(...)") from None
    return validate(raw, "config"), "config"


def _precision(cfg: Any) -> contextlib.AbstractContextManager:
    """JAX's 64-bit mode for the extent of a call of a float64 config (nothing to do when
    the caller already enabled it); the caller's global setting is left as it was."""
    import jax

    if cfg.precision == "float64" and not jax.config.jax_enable_x64:
        return jax.enable_x64(True)
    return contextlib.nullcontext()


@contextlib.contextmanager
def _bar(total: int | None, desc: str) -> Iterator[Callable[[int], None]]:
    if total is None:  # a phase (setting up, scoring): no bar
        yield lambda n: None
        return
    from tqdm import tqdm

    with tqdm(total=total, desc=desc, unit="it") as t:
        yield t.update


def _progress(progress: bool) -> Any:
    from designopt.app.pipeline import no_progress

    return _bar if progress else no_progress


def run(config: Config, out: str | os.PathLike | None = None, progress: bool = False,
        overwrite: bool = False) -> RunRecord:  # fmt: skip
    """Optimise the config's study → ``RunRecord``. ``out=None``: in memory, nothing
    written; with ``out``: the archive the CLI writes (claimed, atomic; an existing one
    refused unless ``overwrite``)."""
    from designopt.app import pipeline

    cfg, where = _config(config)
    if overwrite:
        cfg = cfg.model_copy(update={"overwrite": True})  # a control key: nothing to check
    with _precision(cfg):
        rep = pipeline.run(cfg, None, where, None if out is None else Path(out),
                           progress=_progress(progress))  # fmt: skip
    return rep.record  # type: ignore[return-value]


def sweep(config: Config, out: str | os.PathLike | None = None, progress: bool = False,
          overwrite: bool = False) -> SweepRecord:  # fmt: skip
    """Every member of the config's ``sweep:`` section → ``SweepRecord``."""
    from designopt.app import pipeline

    cfg, where = _config(config)
    if overwrite:
        cfg = cfg.model_copy(update={"overwrite": True})  # a control key: nothing to check
    with _precision(cfg):
        rep = pipeline.sweep(cfg, None, where, None if out is None else Path(out),
                             progress=_progress(progress))  # fmt: skip
    return rep.record  # type: ignore[return-value]


def scan(config: Config, out: str | os.PathLike | None = None, progress: bool = False,
         overwrite: bool = False) -> ScanRecord:  # fmt: skip
    """Score the designs of the config's ``scan:`` section → ``ScanRecord``."""
    from designopt.app import pipeline

    cfg, where = _config(config)
    if overwrite:
        cfg = cfg.model_copy(update={"overwrite": True})  # a control key: nothing to check
    with _precision(cfg):
        rep = pipeline.scan(cfg, None, where, None if out is None else Path(out),
                            progress=_progress(progress))  # fmt: skip
    return rep.record  # type: ignore[return-value]


def evaluate(config: Config, designs: Any) -> dict[str, np.ndarray]:
    """Every index of the given designs with its standard error, without optimising:
    ``{"f": (n,), "gci": (n,), "gci_se": (n,), ...}``, one entry per design, always
    arrays (``float(res["f"][0])`` for one design). ``designs``: {variable: value or
    array} (arrays broadcast) or a list of such dicts; a variable not given takes the
    middle of its box."""
    from designopt.app import pipeline

    cfg, where = _config(config)
    with _precision(cfg):
        return pipeline.evaluate(cfg, designs, where)


def load(path: str | os.PathLike) -> Record:
    """The record an archive holds (run, scan, sweep, bench, IK; a checkpoint; a
    replay)."""
    from designopt.app import records

    return records.load(path)
