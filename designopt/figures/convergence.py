"""The convergence figure every study draws: each index along the best run, ± 2 SE."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

COLUMNS = 4
"""At most this many panels a row: a study with many indices gets a grid, not a strip."""


def convergence(best_run: dict, indices: list[str], folder: Path, title: str,
                units: Mapping[str, str] | None = None, rates: Mapping[str, float | None] | None = None,
                fidelity: Mapping[str, object] | None = None) -> list[Path]:  # fmt: skip
    """One panel per index along the best run, in a grid of at most :data:`COLUMNS`
    columns (``best_run/<index>`` of a run archive), with
    a ± 2 SE band where ``<index>_se`` exists; ``units`` labels the axes; ``rates`` names
    the success rates (clipped to [0, 1], Wilson band; value: the number of trials, or None
    to infer it from the SE); ``fidelity``: the study settings the search scored with
    instead of the study's own (``optimizer.fidelity``, :attr:`RunRecord.fidelity`),
    named under the title, since the best run's values are the search's. Saved as
    ``convergence``."""
    from designopt.figures import style  # matplotlib: imported when a figure is drawn
    from designopt.figures.canvas import save

    units, rates = units or {}, rates or {}
    n = len(indices)
    cols = max(1, min(n, COLUMNS))
    rows = -(-n // cols)
    fig, axes = style.subplots(rows, cols, figsize=(3.4 * cols, 0.3 + 3.0 * rows), squeeze=False)
    for ax in axes.ravel()[n:]:  # the grid's last row, where it is not full
        fig.delaxes(ax)
    it = best_run["iteration"]
    for ax, k in zip(axes.ravel()[:n], indices, strict=True):
        y = np.asarray(best_run[k], np.float64)
        se = best_run.get(k + "_se")
        if k in rates:
            style.rate_band(ax, it, y, se, rates[k], marker=".", lw=1)
        else:
            style.band(ax, it, y, se, marker=".", lw=1)
        ax.set_xlabel(style.label("iteration", style.DIMENSIONLESS))
        ax.set_ylabel(style.label(k, style.unit_of(k, units)))
        ax.grid(alpha=0.3)
    head = (f"{title} (band: ± 2 SE; rates: Wilson interval)" if rates
            else f"{title} (band: ± 2 SE)")  # fmt: skip
    if fidelity:  # the search's values are at other settings than the final design's
        head += "\nthe search scored with " + ", ".join(f"{k} = {v}" for k, v in fidelity.items())
    fig.suptitle(head, fontsize=10)
    return save(fig, folder, "convergence")
