"""Benchmark-suite figures (one bar or curve per compared optimizer) of the haptic master
paper (IEEE Access 2019): Fig. 10 (final values: median and interquartile range with every
run as a dot, the paper's mean ± std being in the printed tables), Fig. 11 (convergence
iteration, mean ± std) and median/IQR convergence curves. Value axes are logarithmic when
the data span more than two decades (values ≤ 0, e.g. an optimum reached exactly, are drawn
at a floor a decade below the smallest positive value, as stated in the title)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.canvas import save
from designopt.results import BenchRecord


def _grid(n: int) -> tuple[int, int]:
    cols = min(n, 4)
    return (n + cols - 1) // cols, cols


def _floor(values: list[np.ndarray]) -> float | None:
    """A log-axis floor for values ≤ 0: a decade below the smallest positive value (None
    when every value is positive or none is)."""
    v = np.concatenate([np.ravel(x) for x in values])
    pos = v[v > 0]
    return float(pos.min()) / 10 if (v <= 0).any() and pos.size else None


def _final(stats: dict[str, Any], histories: dict[str, dict[str, np.ndarray]], n_runs: int):
    cases = list(stats)
    rows, cols = _grid(len(cases))
    fig, axes = style.subplots(rows, cols, figsize=(3.3 * cols, 2.9 * rows + 0.4),
                               squeeze=False)  # fmt: skip
    floors = []
    for ax, case in zip(axes.flat, cases, strict=False):
        names = list(stats[case]["rows"])
        fin = [np.asarray(histories[case][v], np.float64)[:, -1] for v in names]
        fl = _floor(fin)
        if fl is not None:
            fin = [np.maximum(f, fl) for f in fin]
            floors.append(case)
        x = np.arange(len(names))
        q25, q50, q75 = (np.array([np.percentile(f, q) for f in fin]) for q in (25, 50, 75))
        hv = bool(stats[case].get("higher_is_better"))
        if hv:  # hypervolumes differ in the third decimal: a dash, and an axis zoomed to them
            ax.plot(x, q50, "_", ms=18, mew=2, color="tab:blue", label="median")
        else:
            ax.bar(x, q50, color="tab:blue", alpha=0.5, label="median")
        ax.errorbar(x, q50, yerr=[q50 - q25, q75 - q50], fmt="none", ecolor="k", capsize=3,
                    lw=1, label="IQR")  # fmt: skip
        for i, f in enumerate(fin):
            jit = np.random.default_rng(i).uniform(-0.25, 0.25, f.size)
            ax.plot(i + jit, f, ".", ms=2, color="0.25", alpha=0.6)
        if hv:
            ax.margins(x=0.15, y=0.15)
        else:
            style.auto_log(ax, fin)
        ax.set_xticks(x, names, rotation=45, fontsize=7)
        ax.set_xlabel("optimizer (category)", fontsize=8)
        ax.set_title(case.replace("_", " "), fontsize=9)
        what = "final hypervolume" if stats[case].get("higher_is_better") else "final best f(x)"
        ax.set_ylabel(style.label(what, style.DIMENSIONLESS), fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(cases) :]:
        ax.set_visible(False)
    note = (
        f"; values ≤ 0 drawn at 1/10 of the least positive ({', '.join(floors)})" if floors else ""
    )
    dash = (
        " or dash: hypervolume axes zoomed, not from 0"
        if any(stats[c].get("higher_is_better") for c in cases)
        else ""
    )
    fig.suptitle(f"Final values over {n_runs} runs: median (bar{dash}), IQR (whisker), runs (dots); "
                 f"IEEE Access 2019, Fig. 10{note}", fontsize=9)  # fmt: skip
    return fig


def _bars(stats: dict[str, Any], mean: str, std: str, ylabel: str, title: str):
    cases = list(stats)
    rows, cols = _grid(len(cases))
    fig, axes = style.subplots(rows, cols, figsize=(3.3 * cols, 2.9 * rows), squeeze=False)
    for ax, case in zip(axes.flat, cases, strict=False):
        r = stats[case]["rows"]
        names = list(r)
        m = np.array([r[v][mean] for v in names])
        s = np.array([r[v][std] for v in names])
        ax.bar(names, m, yerr=[np.minimum(s, m), s], capsize=3, color="tab:blue", alpha=0.8)
        ax.set_title(case.replace("_", " "), fontsize=9)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.tick_params(axis="x", labelrotation=45)
        ax.set_xlabel("optimizer (category)", fontsize=8)
    for ax in list(axes.flat)[len(cases) :]:
        ax.set_visible(False)
    fig.suptitle(title, fontsize=10)
    return fig


def draw(folder: Path, stats: dict[str, Any], histories: dict[str, dict[str, np.ndarray]],
         n_runs: int) -> list[Path]:  # fmt: skip
    """Draw every benchmark figure into ``folder``; returns the files written."""
    out = save(_final(stats, histories, n_runs), folder, "fig10_final_values")
    fig = _bars(stats, "conv_mean", "conv_std", style.label("convergence iteration", "-"),
                f"Convergence iteration over {n_runs} runs (mean ± std, clipped at 0; Fig. 11)")  # fmt: skip
    out += save(fig, folder, "fig11_convergence_iterations")
    cases = list(histories)
    rows, cols = _grid(len(cases))
    fig, axes = style.subplots(rows, cols, figsize=(3.4 * cols, 2.8 * rows + 0.6),
                               squeeze=False)  # fmt: skip
    floors = []
    for ax, case in zip(axes.flat, cases, strict=False):
        hs = [np.asarray(h, np.float64) for h in histories[case].values()]
        fl = _floor(hs)
        if fl is not None:
            hs = [np.maximum(h, fl) for h in hs]
            floors.append(case)
        for v, h in zip(histories[case], hs, strict=True):
            q25, q50, q75 = np.percentile(h, [25, 50, 75], axis=0)
            it = np.arange(h.shape[1])
            (line,) = ax.plot(it, q50, lw=1, label=v)
            ax.fill_between(it, q25, q75, color=line.get_color(), alpha=0.2, lw=0)
        style.auto_log(ax, hs)
        ax.set_title(case.replace("_", " "), fontsize=9)
        ax.set_xlabel(style.label("iteration", "-"), fontsize=8)
        what = "hypervolume" if stats[case].get("higher_is_better") else "best f"
        ax.set_ylabel(style.label(f"{what} (median, IQR)", "-"), fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(cases) :]:
        ax.set_visible(False)
    h, lab = axes.flat[0].get_legend_handles_labels()
    fig.legend(h, lab, fontsize=7, ncol=min(len(lab), 8), loc="outside lower center")
    note = (
        f"; values ≤ 0 drawn at 1/10 of the least positive ({', '.join(floors)})" if floors else ""
    )
    fig.suptitle(f"Convergence over {n_runs} runs (median, band IQR){note}", fontsize=9)
    out += save(fig, folder, "convergence_curves")
    return out


def draw_record(rec: BenchRecord, folder: Path) -> list[Path]:
    """Draw a benchmark record's figures into ``folder`` (``designopt report``)."""
    cases = rec.case_names()  # the order the suite ran them, as drawn after the run
    stats = {c: rec.stats(c) for c in cases}
    histories = {c: rec.histories(c) for c in cases}
    return draw(Path(folder), stats, histories, rec.n_runs)
