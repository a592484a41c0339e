"""Figure of a scan archive: curves (± 2 SE bands) for one varied variable, heat maps for a
grid over two, and f against the design number otherwise.

Axes carry the study's units (``Hints.units``, from ``Study.units``). A study's ``figures`` module may declare
``SCAN_PANELS`` ({panel title: indices drawn together}), ``RATES`` (success rates: clipped
to [0, 1] with a Wilson band) and ``UNDEFINED_WHEN_ZERO`` ({index: index}: not drawn where
the other is 0, e.g. η over the reached part of a cone where nothing is reached). Curves
that are the same quantity (equal, or equal up to sign) are drawn once and named together.
Infeasible designs (``scan/violation`` > 0) are drawn as hollow grey markers or hatched
cells, named in the legend.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.collections import PatchCollection
from matplotlib.colors import LogNorm
from matplotlib.patches import Patch, Rectangle

from designopt.figures import style
from designopt.figures.canvas import save
from designopt.figures.hints import NONE, Hints
from designopt.results import ScanRecord

INFEASIBLE = {"marker": "o", "mfc": "none", "mec": "0.45", "ls": "none", "ms": 5}


def _indices(sc: Mapping[str, Any]) -> list[str]:
    """The indices drawn: f and every index of ``ScanRecord.values`` but the violation."""
    return [k for k in sc if k != "violation" and not k.endswith("_se")]


def _same(y0: np.ndarray, y1: np.ndarray) -> int:
    """+1 when y1 equals y0, −1 when it equals −y0, 0 otherwise."""
    if y0.shape != y1.shape or not (np.all(np.isfinite(y0)) and np.all(np.isfinite(y1))):
        return 0
    tol = 1e-9 * max(float(np.max(np.abs(y0))), 1e-300)
    if np.allclose(y0, y1, rtol=0, atol=tol):
        return 1
    return -1 if np.allclose(y0, -y1, rtol=0, atol=tol) else 0


def merged(sc: Mapping[str, Any], inds: list[str]) -> list[tuple[str, str]]:
    """[(index drawn, its name with every index equal to it or its negative)]; f is named
    after the index it equals (``gci = −f``)."""
    out: list[tuple[str, list[str]]] = []
    for k in sorted(inds, key=lambda k: k == "f"):
        y = np.asarray(sc[k], np.float64)
        for rep, names in out:
            s = _same(np.asarray(sc[rep], np.float64), y)
            if s:
                names.append(k if s > 0 else f"−{k}")
                break
        else:
            out.append((k, [k]))
    return [(rep, " = ".join(names)) for rep, names in out]


def _masked(sc: Mapping[str, Any], k: str, undefined: Mapping[str, str]) -> np.ndarray:
    y = np.asarray(sc[k], np.float64).copy()
    if k in undefined and undefined[k] in sc:
        y[np.asarray(sc[undefined[k]]) == 0] = np.nan
    return y


def _curves(rec: ScanRecord, folder: Path, units: dict[str, str], mod: Any) -> list[Path]:
    sc = rec.values
    var = rec.varied[0]
    study = rec.study
    x = rec.X[:, rec.names.index(var)]
    order = np.argsort(x)
    x = x[order]
    rates = set(getattr(mod, "RATES", ()))
    undefined = dict(getattr(mod, "UNDEFINED_WHEN_ZERO", {}))
    groups = dict(getattr(mod, "SCAN_PANELS", {}))
    drawn = merged(sc, _indices(sc))
    label_of = dict(drawn)
    panels: list[tuple[str, list[str]]] = []
    placed: set[str] = set()
    for title, members in groups.items():
        ks = [k for k, _ in drawn if k in members or any(m in label_of[k].split(" = ") for m in members)]  # fmt: skip
        if ks:
            panels.append((title, ks))
            placed |= set(ks)
    panels += [(label_of[k], [k]) for k, _ in drawn if k not in placed]
    bad = np.asarray(sc["violation"])[order] > 0 if "violation" in sc else None
    n = len(panels)
    cols = min(3, n)
    rows = -(-n // cols)
    fig, axes = style.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    notes = []
    for ax, (title, ks) in zip(axes.flat, panels, strict=False):
        for k in ks:
            y = _masked(sc, k, undefined)[order]
            se = np.asarray(sc[k + "_se"])[order] if k + "_se" in sc else None
            kw = {"lw": 1.2, "marker": "." if len(x) < 60 else None, "label": label_of[k]}
            if k in rates:
                line = style.rate_band(ax, x, y, se, **kw)
            else:
                line = style.band(ax, x, y, se, **kw)
            if bad is not None and bad.any():
                ax.plot(x[bad], y[bad], **INFEASIBLE, label="infeasible (violation > 0)")
            if k in undefined and np.isnan(y).any():
                notes.append(f"{k} undefined (not drawn) where {undefined[k]} = 0")
            del line
        unit = style.unit_of(ks[0], units)
        ax.set_ylabel(style.label(title if len(ks) > 1 else ks[0], unit), fontsize=9)
        ax.set_xlabel(style.label(var, style.unit_of(var, units)))
        ax.grid(alpha=0.3)
        if len(ks) > 1 or " = " in title or (bad is not None and bad.any()):
            h, lab = ax.get_legend_handles_labels()
            keep = dict(zip(lab, h, strict=True))  # one infeasible entry
            ax.legend(keep.values(), keep.keys(), fontsize=7)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    wil = "; rates: Wilson interval" if any(k in rates for _, ks in panels for k in ks) else ""
    sub = f"{study}: indices along {var} (band: ± 2 SE{wil})"
    if notes:
        sub += "\n" + "; ".join(dict.fromkeys(notes))
    fig.suptitle(sub, fontsize=10)
    return save(fig, folder, f"scan_{var}")


def _grid(rec: ScanRecord, folder: Path, units: dict[str, str], mod: Any) -> list[Path]:
    sc = rec.values
    names, varied, study = rec.names, rec.varied, rec.study
    n0, n1 = rec.shape
    X = rec.X
    i0, i1 = names.index(varied[0]), names.index(varied[1])
    g0 = X[:, i0].reshape(n0, n1)[:, 0]
    g1 = X[:, i1].reshape(n0, n1)[0, :]
    undefined = dict(getattr(mod, "UNDEFINED_WHEN_ZERO", {}))
    rates = set(getattr(mod, "RATES", ()))
    drawn = merged(sc, _indices(sc))
    first = list(units.get("__summary__", ()))
    rest = sorted((d for d in drawn if d[0] != "f"),
                  key=lambda d: first.index(d[0]) if d[0] in first else len(first))  # fmt: skip
    show = [d for d in drawn if d[0] == "f"] + rest[:2]
    bad = np.asarray(sc["violation"]).reshape(n0, n1) > 0 if "violation" in sc else None
    fig, axes = style.subplots(1, len(show), figsize=(4.6 * len(show), 3.9), squeeze=False)
    for ax, (k, lab) in zip(axes[0], show, strict=True):
        z = _masked(sc, k, undefined).reshape(n0, n1)
        fin = z[np.isfinite(z)]
        log = k not in rates and fin.size and np.all(fin > 0) and fin.max() / fin.min() > style.LOG_RATIO  # fmt: skip
        kw = {"norm": LogNorm()} if log else ({"vmin": 0, "vmax": 1} if k in rates else {})
        im = ax.pcolormesh(g1, g0, z, shading="auto", cmap="viridis", rasterized=True, **kw)
        fig.colorbar(im, ax=ax, label=style.label(lab, style.unit_of(k, units)))
        if bad is not None and bad.any():  # hatch the infeasible cells themselves
            e1, e0 = _edges(g1), _edges(g0)
            cells = [Rectangle((e1[j], e0[i]), e1[j + 1] - e1[j], e0[i + 1] - e0[i])
                     for i, j in zip(*np.nonzero(bad), strict=True)]  # fmt: skip
            ax.add_collection(PatchCollection(cells, facecolor="none", edgecolor="0.15",
                                              hatch="///", lw=0))  # fmt: skip
            ax.legend(handles=[Patch(facecolor="none", edgecolor="0.3", hatch="///",
                                     label="infeasible")], fontsize=7, loc="upper right")  # fmt: skip
        ax.set_xlabel(style.label(varied[1], style.unit_of(varied[1], units)))
        ax.set_ylabel(style.label(varied[0], style.unit_of(varied[0], units)))
        ax.set_title(lab, fontsize=9)
    fig.suptitle(f"{study}: scan over {varied[0]} × {varied[1]}", fontsize=10)
    return save(fig, folder, f"scan_{varied[0]}_{varied[1]}")


def _edges(g: np.ndarray) -> np.ndarray:
    """Cell edges around the grid points g (midpoints; half a step beyond the ends)."""
    g = np.asarray(g, np.float64)
    if g.size == 1:
        return np.array([g[0] - 0.5, g[0] + 0.5])
    mid = 0.5 * (g[1:] + g[:-1])
    return np.concatenate([[2 * g[0] - mid[0]], mid, [2 * g[-1] - mid[-1]]])


def _designs(rec: ScanRecord, folder: Path) -> list[Path]:
    sc = rec.values
    study = rec.study
    f = np.asarray(sc["f"], np.float64)
    i = np.arange(len(f))
    se = np.asarray(sc["f_se"]) if "f_se" in sc else None
    fig, ax = style.subplots(figsize=(6, 3.5))
    ax.errorbar(i, f, yerr=None if se is None else style.Z_SE * se, fmt=".", capsize=2,
                label="f ± 2 SE")  # fmt: skip
    if "violation" in sc and (np.asarray(sc["violation"]) > 0).any():
        bad = np.asarray(sc["violation"]) > 0
        ax.plot(i[bad], f[bad], **INFEASIBLE, label="infeasible (violation > 0)")
    ax.legend(fontsize=7)
    ax.set_xlabel(style.label("design number (row of scan/x)", style.DIMENSIONLESS))
    ax.set_ylabel(style.label("f", style.DIMENSIONLESS))
    ax.grid(alpha=0.3)
    ax.set_title(f"{study}: f of every scanned design", fontsize=9)
    return save(fig, folder, "scan_designs")


def draw(rec: ScanRecord, folder: Path, hints: Hints = NONE) -> list[Path]:
    """The figure of a scan record into ``folder``."""
    units, mod = dict(hints.units) | {"__summary__": tuple(hints.summary)}, hints
    varied = rec.varied
    if len(varied) == 1:
        return _curves(rec, folder, units, mod)
    if len(varied) == 2 and rec.mode == "grid":
        return _grid(rec, folder, units, mod)
    return _designs(rec, folder)
