"""Figures (matplotlib, Agg backend), written as PNG and PDF beside an archive.

Drawing is kept cheap: each file is drawn once (the layout is the figure's own, no
``bbox_inches="tight"`` second pass), dense artists are rasterised in the PDF, PNGs are
written at ``DPI`` with fast compression, and axes titles are placed with ``y=1.0``
(otherwise matplotlib measures the tick labels at every draw to place them).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

DPI = 110  # PNG resolution (dots per inch); rasterised artists in PDFs use the same
MAP_RESOLUTION = 121  # grid points per axis of the studies' index maps
RECORD: list[tuple[str, plt.Figure]] | None = None
"""When a list (the figure test sets it), :func:`save` appends (name, figure) and leaves
the figure open, so its axes can be walked after drawing."""


def save(fig: plt.Figure, folder: Path, name: str, dpi: int | None = None) -> list[Path]:
    """Save ``fig`` as ``folder/name.png`` and ``.pdf``, close it, return both paths."""
    folder.mkdir(parents=True, exist_ok=True)
    dpi = dpi or DPI
    png, pdf = folder / f"{name}.png", folder / f"{name}.pdf"
    fig.savefig(png, dpi=dpi, pil_kwargs={"compress_level": 1})
    # the PNG's draw placed every axes: keep those positions for the PDF rather than
    # solving the constrained layout again (a third of the PDF's drawing time)
    fig.set_layout_engine("none")
    fig.savefig(pdf, dpi=dpi)
    if RECORD is not None:
        RECORD.append((name, fig))
    plt.close(fig)
    return [png, pdf]


def convergence(best_run: dict, indices: list[str], folder: Path, title: str,
                units: Mapping[str, str] | None = None, rates: Mapping[str, float | None] | None = None
                ) -> list[Path]:  # fmt: skip
    """One panel per index along the best run (``best_run/<index>`` of a run archive), with
    a ± 2 SE band where ``<index>_se`` exists; ``units`` labels the axes; ``rates`` names
    the success rates (clipped to [0, 1], Wilson band; value: the number of trials, or None
    to infer it from the SE). Saved as ``convergence``."""
    from designopt.figures import style

    units, rates = units or {}, rates or {}
    n = len(indices)
    fig, axes = style.subplots(1, n, figsize=(3.4 * n, 3), squeeze=False)
    it = best_run["iteration"]
    for ax, k in zip(axes[0], indices, strict=True):
        y = np.asarray(best_run[k], np.float64)
        se = best_run.get(k + "_se")
        if k in rates:
            style.rate_band(ax, it, y, se, rates[k], marker=".", lw=1)
        else:
            style.band(ax, it, y, se, marker=".", lw=1)
        ax.set_xlabel(style.label("iteration", style.DIMENSIONLESS))
        ax.set_ylabel(style.label(k, style.unit_of(k, units)))
        ax.grid(alpha=0.3)
    fig.suptitle(f"{title} (band: ± 2 SE; rates: Wilson interval)" if rates
                 else f"{title} (band: ± 2 SE)", fontsize=10)  # fmt: skip
    return save(fig, folder, "convergence")


def drawer(record, path: Path):
    """What draws a record's figures: (draw(record, folder) -> paths, the folder,
    whether the folder is replaced whole). Runs: the study's figures (``Study.figures``)
    in ``<stem>_figures``; sweeps and scans: the generic ones there too; benchmarks: the
    PTPSO paper's figures beside the archive."""
    from designopt.errors import ConfigError
    from designopt.results import (
        BenchRecord,
        FrontRecord,
        ReplayRecord,
        RunRecord,
        ScanRecord,
        SweepRecord,
    )

    path = Path(path)
    figs = path.parent / f"{path.stem}_figures"
    if isinstance(record, BenchRecord):
        from designopt.figures import bench

        return bench.draw_record, path.parent, False
    if isinstance(record, RunRecord | ReplayRecord):
        from designopt.studies import get

        return get(record.study).figures, figs, True
    if isinstance(record, FrontRecord):
        from designopt.figures import front

        return front.draw, figs, True
    if isinstance(record, SweepRecord):
        from designopt.figures import sweep

        return sweep.draw, figs, True
    if isinstance(record, ScanRecord):
        from designopt.figures import scan

        return scan.draw, figs, True
    raise ConfigError(f"{path}: archive kind {record.kind!r} has no figures")
