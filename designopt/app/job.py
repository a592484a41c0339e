"""A job, built once from its validated config (``Job.build``): the study (the registry's
one look-up), the precision, the named keys, the pre-flight estimate (checked), the
archive's root attrs and the study's Problem (built on first use, kept for reuse). Every
later step reads them from the job instead of looking them up again."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.app.config import resolved_yaml
from designopt.app.preflight import Estimate, estimate
from designopt.core.errors import ConfigError
from designopt.core.keys import key_data, streams
from designopt.problems.base import Problem
from designopt.studies import Study, get


def dtype_of(cfg: Any) -> np.dtype:
    """The config's precision; float64 needs JAX's x64 mode (the CLI turns it on, the
    Python API enters ``jax.enable_x64`` for its calls; a script calling the pipeline
    directly enables it itself)."""
    if cfg.precision == "float64" and not jax.config.jax_enable_x64:
        raise ConfigError(
            "key 'precision': float64 needs JAX's 64-bit mode; call "
            "jax.config.update('jax_enable_x64', True) before using designopt from Python"
        )
    return jnp.dtype(cfg.precision)


_PROBLEMS: dict[tuple, Problem] = {}
_BUILDING = threading.RLock()


def build_problem(cfg: Any, keys: Mapping[str, jax.Array], where: str = "config",
                  dtype: Any = None) -> Problem:  # fmt: skip
    """The study's Problem for this config (``dtype``: the job's, else the config's); a
    ValueError becomes a ConfigError. The last few are kept: a second run of the same study
    settings, keys and dtype in one process reuses the Problem, so its compiled programs
    too (a resume, a test, a notebook). One thread builds at a time (the final stage's
    stages are scored side by side: ``designopt.core.concurrency``)."""
    with _BUILDING:
        return _build_problem(cfg, keys, where, dtype)


def _build_problem(cfg: Any, keys: Mapping[str, jax.Array], where: str, dtype: Any) -> Problem:
    from designopt.problems import normalise

    dtype = dtype_of(cfg) if dtype is None else dtype
    o = cfg.optimizer
    # the shape of the run's objective calls (optim.run separate): the normalisation probe
    # scores in it, so the study's objective compiles once for probe, run and scoring
    shape = (o.n_runs, o.n_particles) if getattr(cfg, "parallel", None) is None else None
    key = (cfg.study.name, cfg.study.model_dump_json(), str(dtype), bool(jax.config.jax_enable_x64),
           repr(key_data(keys)), shape)  # fmt: skip
    if key in _PROBLEMS:
        return _PROBLEMS[key]
    st = get(cfg.study.name)
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


def search_config(cfg: Any, where: str = "config") -> Any:
    """``cfg`` with its ``optimizer.fidelity`` settings set (validated, the study's checks
    included), or None when it has none. A key or value the study refuses: ConfigError
    naming ``optimizer.fidelity``."""
    from designopt.app import sweeps

    fid = dict(cfg.optimizer.fidelity)
    if not fid:
        return None
    try:
        return sweeps.apply(cfg, fid, where)
    except (ValueError, ConfigError) as e:
        why = str(e).removeprefix(where + ": ")
        raise ConfigError(f"{where}: key 'optimizer.fidelity': {why}") from None


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


@dataclass
class Job:
    """One job of a validated config, built once (``Job.build``) and handed down: the
    ``study`` (its one registry look-up), ``dtype``, the named ``keys`` of ``key(seed)``,
    the checked pre-flight ``estimate``, and the study's ``problem`` (built on first use).
    ``where`` names the config in messages; ``text`` is the config file's text."""

    cfg: Any
    study: Study
    dtype: np.dtype
    keys: dict[str, jax.Array]
    estimate: Estimate
    where: str = "config"
    text: str | None = None
    search_cfg: Any = None  # cfg with optimizer.fidelity applied (None: cfg itself)
    _problem: Problem | None = field(default=None, repr=False)
    _search: Problem | None = field(default=None, repr=False)

    @classmethod
    def build(cls, cfg: Any, where: str = "config", text: str | None = None, *,
              n_designs: int = 0, members: int = 1) -> Job:  # fmt: skip
        """The job of ``cfg``: its study, precision (float64 needs JAX's 64-bit mode) and
        keys, and its pre-flight estimate for ``n_designs`` scored designs (a scan) or
        ``members`` vmapped sweep members, checked against the memory available."""
        study = get(cfg.study.name)
        dtype = dtype_of(cfg)
        est = estimate(cfg, study, n_designs=n_designs, members=members)
        est.check(where)
        return cls(cfg, study, dtype, streams(cfg.seed), est, where, text,
                   search_config(cfg, where))  # fmt: skip

    @property
    def problem(self) -> Problem:
        """The study's Problem (built once; a replay study has none: ConfigError)."""
        if self._problem is None:
            self._problem = build_problem(self.cfg, self.keys, self.where, self.dtype)
        return self._problem

    @property
    def search_problem(self) -> Problem:
        """The problem the search scores with: the study's own, or (``optimizer.fidelity``)
        the study's with those settings; the same normalisation probe stream either way."""
        if self.search_cfg is None:
            return self.problem
        if self._search is None:
            self._search = build_problem(self.search_cfg, self.keys, self.where, self.dtype)
        return self._search

    def attrs(self, kind: str) -> dict[str, Any]:
        """The root attrs of this job's archive of ``kind``."""
        return base_attrs(kind, self.cfg, self.text, self.keys, self.where)
