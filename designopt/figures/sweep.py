"""Figure of a sweep archive: final f per member and the members' convergence curves."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from designopt.figures import plt, save


def draw(a: dict[str, Any], folder: Path) -> list[Path]:
    mem = {k: v for k, v in a["members"].items() if k != "attrs"}
    labels = [", ".join(f"{kk.split('.')[-1]}={vv:g}" for kk, vv in m["attrs"]["overrides"].items())
              for m in mem.values()]  # fmt: skip
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    axes[0].bar(range(len(mem)), [float(m["final"]["f"]) for m in mem.values()])
    axes[0].set_xticks(range(len(mem)), labels, rotation=60, ha="right", fontsize=7)
    axes[0].set_ylabel("final objective f")
    for lab, m in zip(labels, mem.values(), strict=True):
        h = m["optimizer"]["history"]
        axes[1].plot(np.median(h, axis=0), label=lab, lw=1)
    axes[1].set_xlabel("iteration")
    axes[1].set_ylabel("best f (median over runs)")
    axes[1].legend(fontsize=6)
    fig.tight_layout()
    return save(fig, folder, "sweep_members")
