"""Design matrices (n, D) from what a user gives: {variable: value or array} dicts for
``evaluate`` and the ``scan:`` section's grid or list; a variable not given takes the
middle of its box."""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.core import validation
from designopt.core.errors import ConfigError
from designopt.problems.base import Problem

Designs = Mapping[str, Any] | Sequence[Mapping[str, Any]]


def matrix(problem: Problem, designs: Designs, where: str) -> np.ndarray:
    """(n, D) design matrix from {name: value or array} (or a list of such dicts); arrays
    broadcast (one design per element); a variable not given takes the middle of its box."""
    rows = [designs] if isinstance(designs, Mapping) else list(designs)
    out = []
    for d in rows:
        bad = [k for k in d if k not in problem.names]
        if bad:
            raise ConfigError(f"{where}: design variable(s) {bad} not in this study's "
                              f"variables {list(problem.names)}")  # fmt: skip
        for k, v in d.items():
            bad = validation.first_bad(np.asarray(v, np.float64).ravel().tolist())
            if bad is not None:
                raise ConfigError(f"{where}: design variable '{k}': {bad[1]}")
        cols = [np.asarray(d.get(n, 0.5 * (lo + hi)), np.float64)
                for n, lo, hi in zip(problem.names, problem.lower, problem.upper, strict=True)]  # fmt: skip
        shape = np.broadcast_shapes(*[c.shape for c in cols])
        out.append(np.stack([np.broadcast_to(c, shape).reshape(-1) for c in cols], -1))
    return np.concatenate(out)


def scan_designs(cfg: Any, problem: Problem, where: str) -> tuple[list[str], np.ndarray]:
    """The (names varied, (n, D) designs) of the config's ``scan:`` section."""
    sc = cfg.scan
    if sc is None:
        raise ConfigError(f"{where}: key 'scan': missing; `designopt scan` needs one "
                          "(docs/configs.md)")  # fmt: skip
    lists = sc.lists()
    for k in list(lists) + list(sc.design):
        if k not in problem.names:
            sect = "vary" if k in lists else "design"
            raise ConfigError(f"{where}: key 'scan.{sect}.{k}': not a design variable of this "
                              f"study; variables: {list(problem.names)}")  # fmt: skip
    names = list(lists)
    if sc.mode == "grid":
        combos = list(itertools.product(*lists.values()))
    else:
        if len({len(v) for v in lists.values()}) != 1:
            raise ConfigError(f"{where}: key 'scan.vary': mode 'list' needs value lists of "
                              "equal length")  # fmt: skip
        combos = list(zip(*lists.values(), strict=True))
    base = {n: sc.design.get(n, 0.5 * (lo + hi))
            for n, lo, hi in zip(problem.names, problem.lower, problem.upper, strict=True)}  # fmt: skip
    X = np.array([[dict(zip(names, c, strict=True)).get(n, base[n]) for n in problem.names]
                  for c in combos], np.float64)  # fmt: skip
    return names, X
