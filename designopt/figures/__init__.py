"""Figures (matplotlib, Agg backend), written as PNG and PDF beside an archive.

Drawing is kept cheap: each file is drawn once (the layout is the figure's own, no
``bbox_inches="tight"`` second pass), dense artists are rasterised in the PDF, PNGs are
written at ``DPI`` with fast compression, and axes titles are placed with ``y=1.0``
(otherwise matplotlib measures the tick labels at every draw to place them).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

DPI = 110  # PNG resolution (dots per inch); rasterised artists in PDFs use the same
MAP_RESOLUTION = 121  # grid points per axis of the studies' index maps


def save(fig: plt.Figure, folder: Path, name: str, dpi: int | None = None) -> list[Path]:
    """Save ``fig`` as ``folder/name.png`` and ``.pdf``, close it, return both paths."""
    folder.mkdir(parents=True, exist_ok=True)
    dpi = dpi or DPI
    png, pdf = folder / f"{name}.png", folder / f"{name}.pdf"
    fig.savefig(png, dpi=dpi, pil_kwargs={"compress_level": 1})
    fig.savefig(pdf, dpi=dpi)
    plt.close(fig)
    return [png, pdf]


def convergence(best_run: dict, indices: list[str], folder: Path, title: str) -> list[Path]:
    """One panel per index along the best run (``best_run/<index>`` of a run archive), with
    a ± 2 SE band where ``<index>_se`` exists; saved as ``convergence``."""
    fig, axes = plt.subplots(1, len(indices), figsize=(3.4 * len(indices), 3), squeeze=False)
    it = best_run["iteration"]
    for ax, k in zip(axes[0], indices, strict=True):
        y = best_run[k]
        ax.plot(it, y, marker=".", lw=1)
        if k + "_se" in best_run:
            se = best_run[k + "_se"]
            ax.fill_between(it, y - 2 * se, y + 2 * se, alpha=0.25, lw=0)
        ax.set_xlabel("iteration")
        ax.set_ylabel(k)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{title} (band: ± 2 SE)", fontsize=10)
    fig.tight_layout()
    return save(fig, folder, "convergence")
