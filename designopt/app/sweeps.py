"""Sweeps: expand a config's ``sweep`` section into members (SPEC §7).

A key is a dotted path into the config. Short forms: ``optimizer.<setting>`` →
``optimizer.settings.<setting>`` (the chosen optimizer's numeric settings, e.g. gamma),
plus the study's own (``Study.sweep_aliases``, e.g. ``study.<index key>`` →
``study.indices.<key>``, ``design.<length>`` → ``study.fixed.<length>``). Any other path
must name a number of the config. ``grid`` takes the Cartesian product of the value
lists, ``list`` zips them (equal lengths). Members that differ only in optimizer settings
share one problem and run as one vmapped batch.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

from designopt.studies import get

PREFIX = "optimizer.settings."


def _numeric_paths(d: Any, prefix: str = "") -> set[str]:
    out: set[str] = set()
    if isinstance(d, dict):
        for k, v in d.items():
            out |= _numeric_paths(v, f"{prefix}{k}.")
    elif isinstance(d, (int, float)) and not isinstance(d, bool):
        out.add(prefix[:-1])
    elif isinstance(d, list) and d and all(isinstance(x, (int, float)) for x in d):
        out.add(prefix[:-1])  # a number or a list (e.g. backlash_deg) may be swept
    return out


def canonical(path: str, cfg: Any) -> str:
    """Resolve the short forms to a full dotted path; ValueError if it names nothing."""
    from designopt import optim

    settings = set(optim.setting_names(cfg.optimizer.name))
    aliases = get(cfg.study.name).sweep_aliases(cfg.study)
    parts = path.split(".")
    if len(parts) == 2 and parts[0] == "optimizer" and parts[1] in settings:
        return PREFIX + parts[1]
    if path.startswith(PREFIX) and path[len(PREFIX) :] in settings:
        return path
    if path in aliases:
        return aliases[path]
    numeric = _numeric_paths(cfg.model_dump(by_alias=True)) - {"precision"}
    if path in numeric and not path.startswith(PREFIX):
        return path
    raise ValueError(f"cannot vary '{path}': not a numeric key of the config")


def members(cfg: Any) -> list[dict[str, float]]:
    """The list of {full path: value} overrides the sweep declares."""
    sw = cfg.sweep
    if sw is None:
        return []
    keys = [canonical(k, cfg) for k in sw.vary]
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


def apply(cfg: Any, overrides: dict[str, Any], where: str = "config", checks: bool = True) -> Any:
    """The validated config of ``cfg`` with the overrides set (and no sweep section),
    through the one override path (``config.set_key``, then ``config.validate``); a whole
    number key keeps whole numbers. ``checks=False`` skips the study's own checks
    (``config.validate``): for overrides of sample counts of a config that passed them."""
    from designopt.app.config import set_key, validate

    d = cfg.model_dump(by_alias=True)
    d["sweep"] = None
    for path, v in overrides.items():
        node = d
        for p in path.split(".")[:-1]:
            node = node.get(p) if isinstance(node, dict) and isinstance(node.get(p), dict) else {}
        old = node.get(path.split(".")[-1])
        if isinstance(old, int) and not isinstance(old, bool):
            try:
                f = float(v)
            except (TypeError, ValueError):
                f = math.nan
            if not math.isfinite(f) or f != int(f) or abs(f) >= 2**63:  # "2.5", "inf", "x"
                raise ValueError(f"'{path}' takes whole numbers (of at most 63 bits), got {v}")
            v = int(f)
        set_key(d, path, v, where)
    return validate(d, where, checks=checks)


def split(overrides: dict[str, Any]) -> tuple[dict[str, Any], dict[str, float]]:
    """(keys that change the problem or the run shape, vmappable optimizer settings)."""
    opt = {k.removeprefix(PREFIX): float(v) for k, v in overrides.items() if k.startswith(PREFIX)}
    rest = {k: v for k, v in overrides.items() if not k.startswith(PREFIX)}
    return rest, opt


def groups(cfg: Any, where: str) -> tuple[dict[str, list[tuple[int, dict]]], dict[str, Any], list]:
    """The sweep's members grouped by what changes the problem or the run shape:
    ({group: [(member index, overrides)]}, {group: its config}, members). ConfigError
    naming ``sweep.vary`` for a bad key or value."""
    from designopt.core.errors import ConfigError

    if cfg.sweep is None:
        raise ConfigError(f"{where}: key 'sweep': missing; `designopt sweep` needs one "
                          "(docs/configs.md)")  # fmt: skip
    try:
        mem = members(cfg)
        out: dict[str, list[tuple[int, dict]]] = {}
        cfgs = {}
        for i, m in enumerate(mem):
            rest, _ = split(m)
            k = repr(sorted(rest.items()))
            if k not in cfgs:
                cfgs[k] = apply(cfg, rest, where)
            out.setdefault(k, []).append((i, m))
    except ConfigError as e:  # a member's config refused: name the sweep's key
        raise ConfigError(f"{where}: key 'sweep.vary' → {str(e).removeprefix(where + ': ')}") from None
    except ValueError as e:
        raise ConfigError(f"{where}: key 'sweep.vary': {e}") from None
    return out, cfgs, mem


def resolved(cfg: Any, overrides: dict[str, Any]) -> str:
    """The resolved YAML of one member's config."""
    from designopt.app.config import resolved_yaml

    return resolved_yaml(apply(cfg, overrides))
