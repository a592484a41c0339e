"""Figure of a scan archive: a curve (± 2 SE band) for one varied variable, a heat map for
a grid over two, and f against the design number otherwise."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from designopt.figures import plt, save


def _indices(sc: dict[str, Any]) -> list[str]:
    skip = {"names", "x", "varied", "attrs"}
    return [k for k in sc if k not in skip and not k.endswith("_se")]


def draw(a: dict[str, Any], folder: Path) -> list[Path]:
    sc = a["scan"]
    names = [n.decode() for n in sc["names"]]
    varied = [n.decode() for n in sc["varied"]]
    X = sc["x"]
    inds = _indices(sc)
    study = a["attrs"].get("study", "")
    if len(varied) == 1:
        x = X[:, names.index(varied[0])]
        order = np.argsort(x)
        n = len(inds)
        cols = min(3, n)
        rows = -(-n // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
        for ax, k in zip(axes.flat, inds, strict=False):
            y = sc[k][order]
            ax.plot(x[order], y, lw=1.2, marker="." if len(x) < 60 else None)
            if k + "_se" in sc:
                se = sc[k + "_se"][order]
                ax.fill_between(x[order], y - 2 * se, y + 2 * se, alpha=0.25, lw=0)
            ax.set_xlabel(varied[0])
            ax.set_ylabel(k)
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[n:]:
            ax.set_visible(False)
        fig.suptitle(f"{study}: indices along {varied[0]} (band: ± 2 SE)", fontsize=10)
        fig.tight_layout()
        return save(fig, folder, f"scan_{varied[0]}")
    shape = a["scan"]["attrs"].get("shape", [])
    if len(varied) == 2 and a["scan"]["attrs"].get("mode") == "grid":
        n0, n1 = shape
        i0, i1 = names.index(varied[0]), names.index(varied[1])
        g0 = X[:, i0].reshape(n0, n1)[:, 0]
        g1 = X[:, i1].reshape(n0, n1)[0, :]
        show = ["f"] + [k for k in inds if k != "f"][:2]
        fig, axes = plt.subplots(1, len(show), figsize=(4.6 * len(show), 3.8), squeeze=False)
        for ax, k in zip(axes[0], show, strict=True):
            z = sc[k].reshape(n0, n1)
            im = ax.pcolormesh(g1, g0, z, shading="auto", cmap="viridis", rasterized=True)
            fig.colorbar(im, ax=ax, label=k)
            ax.set_xlabel(varied[1])
            ax.set_ylabel(varied[0])
            ax.set_title(k, fontsize=9, y=1.0)
        fig.suptitle(f"{study}: scan over {varied[0]} × {varied[1]}", fontsize=10)
        fig.tight_layout()
        return save(fig, folder, f"scan_{varied[0]}_{varied[1]}")
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.errorbar(np.arange(len(sc["f"])), sc["f"], yerr=2 * sc.get("f_se", 0 * sc["f"]), fmt=".")
    ax.set_xlabel("design number")
    ax.set_ylabel("f")
    fig.tight_layout()
    return save(fig, folder, "scan_designs")
