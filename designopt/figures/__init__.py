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

from designopt.figures.canvas import DPI, MAP_RESOLUTION, parallel_saves, plt, save
from designopt.figures.convergence import convergence

__all__ = ["DPI", "MAP_RESOLUTION", "convergence", "parallel_saves", "plt", "save"]
