"""Figure of a sweep archive: the final f of every member (± 2 SE, where the archive holds
it) and the members' convergence curves (median over runs, band: interquartile range)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from designopt.figures import style
from designopt.figures.canvas import save
from designopt.results import SweepRecord


def draw(rec: SweepRecord, folder: Path) -> list[Path]:
    """The figure of a sweep record into ``folder``."""
    mem = rec.member_records()
    labels = [", ".join(f"{kk.split('.')[-1]}={vv:g}" for kk, vv in ov.items())
              for ov in rec.overrides().values()]  # fmt: skip
    study = rec.study
    f = np.array([m.f for m in mem.values()])
    se = np.array([np.nan if m.indices["f"][1] is None else m.indices["f"][1]
                   for m in mem.values()])  # fmt: skip
    n = len(mem)
    fig, axes = style.subplots(1, 2, figsize=(11, 0.9 + max(2.8, 0.32 * n)),
                               width_ratios=[1, 1.3])  # fmt: skip
    y = np.arange(n)
    axes[0].errorbar(f, y, xerr=None if np.isnan(se).all() else style.Z_SE * se, fmt="o",
                     capsize=3, ms=4)  # fmt: skip
    axes[0].set_yticks(y, labels, fontsize=7)
    axes[0].set_ylabel("member (category)")
    axes[0].invert_yaxis()
    axes[0].set_xlabel(style.label("final objective f (± 2 SE)", style.DIMENSIONLESS))
    axes[0].grid(alpha=0.3, axis="x")
    same = np.ptp(f) <= 1e-9 * max(np.abs(f).max(), 1e-300)
    axes[0].set_title("every member reaches the same f" if same else "final f per member",
                      fontsize=9)  # fmt: skip
    ax = axes[1]
    hs = []
    for lab, m in zip(labels, mem.values(), strict=True):
        h = np.asarray(m.history, np.float64)
        it = np.arange(h.shape[1])
        q25, q50, q75 = np.percentile(h, [25, 50, 75], axis=0)
        (line,) = ax.plot(it, q50, lw=1, label=lab)
        ax.fill_between(it, q25, q75, color=line.get_color(), alpha=0.15, lw=0)
        hs.append(h)
    style.auto_log(ax, hs)
    ax.set_xlabel(style.label("iteration", style.DIMENSIONLESS))
    ax.set_ylabel(style.label("best f (median over runs; band IQR)", style.DIMENSIONLESS))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    fig.suptitle(f"Sweep of {study}: {n} members, {hs[0].shape[0]} runs each", fontsize=10)
    return save(fig, folder, "sweep_members")
