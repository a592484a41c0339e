"""Set-up of a job from its typed config: the study (through the registry), the
precision, the optimizer's settings checked, the Problem (kept for reuse), and the root
attrs every archive carries (config text, resolved config, seed, the named keys)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from designopt.core.errors import ConfigError
from designopt.core.keys import key_data
from designopt.problems.base import Problem
from designopt.studies import Study, get


def study_of(cfg: Any) -> Study:
    return get(cfg.study.name)


def dtype_of(cfg: Any) -> np.dtype:
    """The config's precision; float64 needs JAX's x64 mode (the CLI turns it on, a script
    must call ``jax.config.update("jax_enable_x64", True)`` itself)."""
    if cfg.precision == "float64" and not jax.config.jax_enable_x64:
        raise ConfigError(
            "key 'precision': float64 needs JAX's 64-bit mode; call "
            "jax.config.update('jax_enable_x64', True) before using designopt from Python"
        )
    return jnp.dtype(cfg.precision)


def resolved_yaml(cfg: Any) -> str:
    return yaml.safe_dump(cfg.model_dump(mode="json", by_alias=True), sort_keys=False)


_PROBLEMS: dict[tuple, Problem] = {}


def build_problem(cfg: Any, keys: Mapping[str, jax.Array], where: str = "config") -> Problem:
    """The study's Problem for this config; a ValueError becomes a ConfigError. The last
    few are kept: a second run of the same study settings, keys and dtype in one process
    reuses the Problem, so its compiled programs too (a resume, a test, a notebook)."""
    from designopt.problems import normalise

    dtype = dtype_of(cfg)
    o = cfg.optimizer
    # the shape of the run's objective calls (optim.run separate): the normalisation probe
    # scores in it, so the study's objective compiles once for probe, run and scoring
    shape = (o.n_runs, o.n_particles) if getattr(cfg, "parallel", None) is None else None
    key = (cfg.study.name, cfg.study.model_dump_json(), str(dtype), bool(jax.config.jax_enable_x64),
           repr(key_data(keys)), shape)  # fmt: skip
    if key in _PROBLEMS:
        return _PROBLEMS[key]
    st = study_of(cfg)
    if st.problem is None:
        raise ConfigError(f"{where}: study '{st.name}' has no design problem (its run is a "
                          "replay); use `designopt run`")  # fmt: skip
    try:
        with normalise.evaluation_shape(shape):
            problem = st.problem(cfg.study, keys, dtype)
    except ValueError as e:
        raise ConfigError(f"{where}: study: {e}") from None
    while len(_PROBLEMS) >= 4:
        _PROBLEMS.pop(next(iter(_PROBLEMS)))
    _PROBLEMS[key] = problem
    return problem


def check_optimizer(cfg: Any, where: str) -> None:
    """The optimizer's name, settings and swarm size, checked by the optimizer registry."""
    from designopt import optim

    o = cfg.optimizer
    for key, args in (("optimizer.name", (o.name, {})),
                      ("optimizer.settings", (o.name, dict(o.settings))),
                      ("optimizer.n_particles", (o.name, dict(o.settings), o.n_particles))):  # fmt: skip
        try:
            optim.validate(*args)
        except ValueError as e:
            raise ConfigError(f"{where}: key '{key}': {e}") from None


def base_attrs(kind: str, cfg: Any, text: str | None, keys: Mapping[str, jax.Array],
               where: str = "config") -> dict[str, Any]:  # fmt: skip
    """The root attrs of every archive: kind, study, the config as given (``text``; the
    resolved YAML when the config was built in Python) and resolved, the seed, the keys
    of the named streams, and the folder relative paths in the config are read from."""
    folder = Path(where).parent if Path(where).is_file() else Path.cwd()
    resolved = resolved_yaml(cfg)
    return {"kind": kind, "study": cfg.study.name, "config_yaml": resolved if text is None else text,
            "config_resolved_yaml": resolved,
            "config_resolved": cfg.model_dump_json(by_alias=True), "seed": cfg.seed,
            "keys": key_data(keys), "config_dir": str(folder.resolve())}  # fmt: skip
