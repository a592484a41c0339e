"""Benchmark-suite figures (one bar or curve per compared optimizer) of the haptic master
paper (IEEE Access 2019): Fig. 10 (final values, mean ± std), Fig. 11 (convergence
iteration, mean ± std) and median/IQR convergence curves."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from designopt.figures import plt, save


def _grid(n: int) -> tuple[int, int]:
    cols = min(n, 4)
    return (n + cols - 1) // cols, cols


def _bars(stats: dict[str, Any], mean: str, std: str, ylabel: str, title: str, log: bool):
    cases = list(stats)
    rows, cols = _grid(len(cases))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.8 * rows), squeeze=False)
    for ax, case in zip(axes.flat, cases, strict=False):
        r = stats[case]["rows"]
        names = list(r)
        m = np.array([r[v][mean] for v in names])
        s = np.array([r[v][std] for v in names])
        lo = np.minimum(s, m * 0.999) if log else s  # keep log-scale error bars positive
        ax.bar(names, m, yerr=[lo, s], capsize=3, color="tab:blue", alpha=0.8)
        if log and np.all(m > 0):
            ax.set_yscale("log")
        ax.set_title(case.replace("_", " "), fontsize=9, y=1.0)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.tick_params(axis="x", labelrotation=45)
    for ax in list(axes.flat)[len(cases) :]:
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def draw(folder: Path, stats: dict[str, Any], histories: dict[str, dict[str, np.ndarray]],
         n_runs: int) -> list[Path]:  # fmt: skip
    """Draw every benchmark figure into ``folder``; returns the files written."""
    out = []
    fig = _bars(stats, "mean", "std", "final best value f(x)",
                f"Final values over {n_runs} runs (mean ± std; IEEE Access 2019, Fig. 10)", log=True)  # fmt: skip
    out += save(fig, folder, "fig10_final_values")
    fig = _bars(stats, "conv_mean", "conv_std", "convergence iteration",
                f"Convergence iteration over {n_runs} runs (mean ± std; Fig. 11)", log=False)  # fmt: skip
    out += save(fig, folder, "fig11_convergence_iterations")
    cases = list(histories)
    rows, cols = _grid(len(cases))
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.8 * rows), squeeze=False)
    for ax, case in zip(axes.flat, cases, strict=False):
        for v, h in histories[case].items():
            h = np.asarray(h, np.float64)
            q25, q50, q75 = np.percentile(h, [25, 50, 75], axis=0)
            it = np.arange(h.shape[1])
            (line,) = ax.plot(it, q50, lw=1, label=v)
            ax.fill_between(it, q25, q75, color=line.get_color(), alpha=0.2, lw=0)
        if np.all(np.concatenate([np.ravel(h) for h in histories[case].values()]) > 0):
            ax.set_yscale("log")
        ax.set_title(case.replace("_", " "), fontsize=9, y=1.0)
        ax.set_xlabel("iteration", fontsize=8)
        ax.set_ylabel("best f (median, IQR)", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(cases) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    out += save(fig, folder, "convergence_curves")
    return out
