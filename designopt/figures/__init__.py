"""Figures (matplotlib, Agg backend), written as PNG and PDF beside an archive."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def save(fig: plt.Figure, folder: Path, name: str) -> list[Path]:
    """Save ``fig`` as ``folder/name.png`` and ``.pdf``, close it, return both paths."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for ext in ("png", "pdf"):
        p = folder / f"{name}.{ext}"
        fig.savefig(p, dpi=150 if ext == "png" else None, bbox_inches="tight")
        out.append(p)
    plt.close(fig)
    return out


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
