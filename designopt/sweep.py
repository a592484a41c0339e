"""Sweeps: expand a config's ``sweep`` section into members (SPEC §7, issue 5).

A key is a dotted path into the config; short forms are accepted:
``optimizer.<setting>`` → ``optimizer.settings.<setting>`` (PSO parameters such as gamma),
``study.<index key>`` → ``study.indices.<key>`` (e.g. backlash_deg), and
``design.<length>`` → ``study.fixed.<length>`` (e.g. a4). ``grid`` takes the Cartesian
product of the value lists, ``list`` zips them (equal lengths). Members that differ only
in optimizer settings share one problem and run as one vmapped batch.
"""

from __future__ import annotations

import itertools
from typing import Any

from designopt.config import RunConfig
from designopt.optim.variants import BASE
from designopt.studies.master9.indices import IndexSettings
from designopt.studies.master9.mechanism import DESIGN_KEYS

NUMERIC_PATHS = {
    "study.indices.n_samples", "study.indices.backlash_deg", "study.n_norm",
    "optimizer.n_particles", "optimizer.n_iters", "optimizer.n_runs", "seed",
}  # fmt: skip


def canonical(path: str) -> str:
    """Resolve the short forms to a full dotted path; ValueError if it names nothing."""
    parts = path.split(".")
    if len(parts) == 2 and parts[0] == "optimizer" and parts[1] in BASE:
        parts = ["optimizer", "settings", parts[1]]
    elif len(parts) == 2 and parts[0] == "study" and parts[1] in IndexSettings.__dataclass_fields__:
        parts = ["study", "indices", parts[1]]
    elif len(parts) == 2 and parts[0] == "design" and parts[1] in DESIGN_KEYS:
        parts = ["study", "fixed", parts[1]]
    full = ".".join(parts)
    ok = (
        (parts[:2] == ["optimizer", "settings"] and len(parts) == 3 and parts[2] in BASE)
        or (parts[:2] == ["study", "fixed"] and len(parts) == 3 and parts[2] in DESIGN_KEYS)
        or full in NUMERIC_PATHS
    )
    if not ok:
        raise ValueError(f"cannot vary '{path}': not a numeric key of the config")
    return full


def members(cfg: RunConfig) -> list[dict[str, float]]:
    """The list of {full path: value} overrides the sweep declares."""
    sw = cfg.sweep
    if sw is None:
        return []
    keys = [canonical(k) for k in sw.vary]
    for k in keys:
        if k.startswith("study.fixed.") and k.split(".")[-1] in cfg.study.variables:
            raise ValueError(
                f"'{k}' is a design variable of this study; vary its bounds in "
                "study.variables instead"
            )
    vals = list(sw.vary.values())
    if sw.mode == "grid":
        combos = itertools.product(*vals)
    else:
        if len({len(v) for v in vals}) != 1:
            raise ValueError("mode 'list' needs value lists of equal length")
        combos = zip(*vals, strict=True)
    return [dict(zip(keys, c, strict=True)) for c in combos]


def apply(cfg: RunConfig, overrides: dict[str, Any]) -> RunConfig:
    """A validated copy of ``cfg`` with the overrides set (and no sweep section)."""
    d = cfg.model_dump()
    d["sweep"] = None
    for path, v in overrides.items():
        node = d
        *head, last = path.split(".")
        for p in head:
            node = node.setdefault(p, {})
        if isinstance(node.get(last), int) and not isinstance(node.get(last), bool):
            if float(v) != int(v):
                raise ValueError(f"'{path}' takes whole numbers, got {v}")
            v = int(v)
        node[last] = v
    return RunConfig.model_validate(d)


def split(overrides: dict[str, Any]) -> tuple[dict[str, Any], dict[str, float]]:
    """(keys that change the problem or the run shape, vmappable optimizer settings)."""
    prefix = "optimizer.settings."
    opt = {k.removeprefix(prefix): float(v) for k, v in overrides.items() if k.startswith(prefix)}
    rest = {k: v for k, v in overrides.items() if not k.startswith(prefix)}
    return rest, opt
