"""Every number that enters designopt is finite and in range, or the run is refused
before any work (docs/configs.md, "Numbers that are refused").

One check for every entry point: config files (every study's section, whatever its
model), sweep and scan values, ``--design`` and ``--seed``, and the Python API's designs.
A number is refused when it is NaN, ±inf, or larger in magnitude than
:data:`MAX_MAGNITUDE`: lengths of 1e308 are finite but their squares are not, and a
float32 run overflows far sooner (a 3×3 determinant of lengths 1e7 is 1e42 > 3.4e38).
Kept import-free (no JAX, no numpy) so the CLI starts fast.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from designopt.core.errors import ConfigError

MAX_MAGNITUDE = 1e9
"""The largest magnitude a real number of a config, a design or the API may have."""

SEED_MAX = 2**32 - 1
"""Seeds are integers in [0, SEED_MAX]: JAX's default (32-bit) keys fold larger seeds
onto smaller ones (key(2**32) is key(0)), so a larger seed would repeat another run."""


def problem(v: float) -> str | None:
    """Why the real number ``v`` is refused, or None when it is fine."""
    v = float(v)
    if math.isnan(v):
        return "nan is not a finite number"
    if math.isinf(v):
        return f"{v} is not a finite number"
    if abs(v) > MAX_MAGNITUDE:
        return f"{v:g} is too large (|x| must be ≤ {MAX_MAGNITUDE:g}, or the arithmetic overflows)"
    return None


def first_bad(tree: Any, prefix: str = "") -> tuple[str, str] | None:
    """The first (dotted key, reason) of a refused real number in a nested tree of
    mappings, lists, tuples and pydantic models; None when every number is fine. Integers
    are exact and have their own per-key limits; only reals are bounded here."""
    from pydantic import BaseModel

    if isinstance(tree, BaseModel):
        tree = {
            (f.alias or k): getattr(tree, k)
            for k, f in type(tree).model_fields.items()
            if getattr(tree, k, None) is not None
        }
    if isinstance(tree, Mapping):
        items = ((f"{prefix}.{k}" if prefix else str(k), v) for k, v in tree.items())
    elif isinstance(tree, list | tuple):
        items = ((f"{prefix}.{i}" if prefix else str(i), v) for i, v in enumerate(tree))
    else:
        why = problem(tree) if isinstance(tree, float) or _np_float(tree) else None
        return None if why is None else (prefix or "(top level)", why)
    for k, v in items:
        bad = first_bad(v, k)
        if bad is not None:
            return bad
    return None


def _np_float(v: Any) -> bool:
    return type(v).__module__ == "numpy" and hasattr(v, "dtype") and v.dtype.kind == "f"


def check_tree(tree: Any, where: str, prefix: str = "") -> None:
    """ConfigError "<where>: key '<path>': <reason>" for the first refused number."""
    bad = first_bad(tree, prefix)
    if bad is not None:
        raise ConfigError(f"{where}: key '{bad[0]}': {bad[1]}")


def check_value(name: str, v: Any) -> float:
    """``v`` as a float, or ConfigError naming ``name`` when it is not a usable number."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: {v!r} is not a number") from None
    except OverflowError:
        x = math.inf
    why = problem(x)
    if why is not None:
        raise ConfigError(f"{name}: {why}")
    return x


def check_seed(v: Any, name: str = "seed") -> int:
    """``v`` as a seed in [0, SEED_MAX], or ConfigError naming ``name``."""
    if isinstance(v, bool) or not isinstance(v, int):
        raise ConfigError(f"{name}: {v!r} is not an integer; give one from 0 to {SEED_MAX}")
    if not 0 <= v <= SEED_MAX:
        raise ConfigError(f"{name}: {v} is out of range; give an integer from 0 to {SEED_MAX} "
                          "(larger seeds repeat smaller ones)")  # fmt: skip
    return v
