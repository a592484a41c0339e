"""Figures (matplotlib, Agg backend), written as PNG and PDF beside an archive; fed
plain arrays and records, with whatever a study knows (units, hints) passed in as
arguments: this package reaches no study (docs/figures.md).

- ``canvas``: the backend, ``save`` (PNG + PDF, one draw each) and ``parallel_saves``
  (each figure written by a forked child while the next is built);
- ``style``: labels, units, bands, the grid of panels;
- ``convergence``: the best run's indices;
- ``scan``, ``sweep``, ``front``, ``bench``: the generic figures of those archives;
- ``html``: the offline interactive report.
"""

from __future__ import annotations

import importlib
from typing import Any

from designopt.figures.convergence import convergence

_CANVAS = ("DPI", "MAP_RESOLUTION", "parallel_saves", "plt", "save")
"""The backend's names, imported from ``canvas`` when first used: importing a
light submodule (``designopt.figures.hints``, read by ``eval`` and ``show``) does not
import matplotlib (about 0.2 s of a warm command's start-up)."""


def __getattr__(name: str) -> Any:
    if name in _CANVAS:
        value = getattr(importlib.import_module("designopt.figures.canvas"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'designopt.figures' has no attribute {name!r}")


__all__ = ["DPI", "MAP_RESOLUTION", "convergence", "parallel_saves", "plt", "save"]
