"""Plot helpers shared by the sections: layouts, ± 2 SE and Wilson bands, the convergence
plot, and indices merged when equal (``eta = eta_cone = −f``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.html.model import (
    MAX_LINE_POINTS,
    MAX_RUN_LINES,
    PALETTE,
    Plot,
    Z,
    _every,
    _f,
    _Ids,
    _thin_note,
    esc,
)
from designopt.figures.scan import merged  # noqa: F401 (re-exported: indices equal to f drawn once, as in the static figures)


def _lab(name: str, units: Mapping[str, str]) -> str:
    return esc(style.label(name, style.unit_of(name, units)))


def _is_log(*arrays: Any) -> bool:
    v = np.concatenate([np.ravel(_f(a)) for a in arrays]) if arrays else np.zeros(0)
    v = v[np.isfinite(v)]
    return bool(v.size and np.all(v > 0) and v.max() / v.min() > style.LOG_RATIO)


def _layout(title: str, xlabel: str = "", ylabel: str = "", **kw: Any) -> dict[str, Any]:
    lay: dict[str, Any] = {
        "title": {"text": title, "font": {"size": 13}, "x": 0.02, "xanchor": "left"},
        "margin": {"l": 64, "r": 16, "t": 46, "b": 52},
        "font": {"family": "system-ui, sans-serif", "size": 11},
        "paper_bgcolor": "white",
        "plot_bgcolor": "#fafafa",
        "hovermode": "closest",
        "legend": {"font": {"size": 10}},
    }
    ax = {"gridcolor": "#e3e3e3", "zerolinecolor": "#c8c8c8", "automargin": True,
          "exponentformat": "power"}  # fmt: skip
    if xlabel or ylabel:
        lay["xaxis"] = {**ax, "title": {"text": xlabel}}
        lay["yaxis"] = {**ax, "title": {"text": ylabel}}
    lay.update(kw)
    return lay


def _band(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, color: str, name: str = "",
          legend: bool = False) -> list[dict[str, Any]]:  # fmt: skip
    """Two traces filling lo..hi (no hover)."""
    base = {"type": "scatter", "mode": "lines", "x": x, "line": {"width": 0, "color": color},
            "hoverinfo": "skip", "showlegend": False}  # fmt: skip
    return [
        base | {"y": lo, "legendgroup": name},
        base | {"y": hi, "fill": "tonexty", "fillcolor": _rgba(color, 0.22),
                "name": name, "legendgroup": name, "showlegend": legend},
    ]  # fmt: skip


def _rgba(hexcol: str, alpha: float) -> str:
    r, g, b = (int(hexcol[i : i + 2], 16) for i in (1, 3, 5))
    return f"rgba({r},{g},{b},{alpha})"


def _value_band(x: np.ndarray, y: np.ndarray, se: np.ndarray | None, rate: bool,
                color: str) -> tuple[list[dict[str, Any]], str]:  # fmt: skip
    """The ± 2 SE band (a rate: Wilson interval from the SE's implied trials), or none."""
    if se is None:
        return [], ""
    se = _f(se)
    if rate:
        n = style.trials(y, se)
        if n is not None:
            lo, hi = style.wilson(y, n)
            return _band(x, lo, hi, color, "Wilson interval"), "Wilson interval"
        lo, hi = np.clip(y - Z * se, 0, 1), np.clip(y + Z * se, 0, 1)
        return _band(x, lo, hi, color, "± 2 SE"), "± 2 SE"
    return _band(x, y - Z * se, y + Z * se, color, "± 2 SE"), "± 2 SE"


def _convergence(hist: np.ndarray, best: int | None, ids: _Ids, title: str, ylabel: str,
                 stem: str = "convergence") -> Plot:  # fmt: skip
    """Every run's best-so-far f (thin grey), the best run (bold), the median (dashed)."""
    hist = np.atleast_2d(_f(hist))
    runs, n_it = hist.shape
    it = np.arange(n_it)
    keep = _every(n_it, MAX_LINE_POINTS)
    shown = list(_every(runs, MAX_RUN_LINES))
    if best is not None and best not in shown:
        shown.append(best)
    log = _is_log(hist)
    data: list[dict[str, Any]] = []
    if runs > 1:
        q25, q50, q75 = np.percentile(hist, [25, 50, 75], axis=0)
        data += _band(it[keep], q25[keep], q75[keep], PALETTE[0], "IQR of all runs", True)
        data.append({"type": "scatter", "mode": "lines", "x": it[keep], "y": q50[keep],
                     "name": f"median of {runs} runs",
                     "line": {"color": PALETTE[0], "dash": "dash", "width": 1.5}})  # fmt: skip
    first = True
    for r in shown:
        if r == best:
            continue
        data.append({"type": "scatter", "mode": "lines", "x": it[keep], "y": hist[r, keep],
                     "name": "each run" if first else f"run {r}", "legendgroup": "runs",
                     "showlegend": first, "hovertemplate": f"run {r}: %{{y:.6~g}}<extra></extra>",
                     "line": {"color": "rgba(110,110,110,0.45)", "width": 1}})  # fmt: skip
        first = False
    if best is not None:
        data.append({"type": "scatter", "mode": "lines", "x": it[keep], "y": hist[best, keep],
                     "name": f"best run ({best})", "line": {"color": PALETTE[3], "width": 2.5}})  # fmt: skip
    note = _thin_note(runs, len(shown), "runs drawn") + _thin_note(n_it, len(keep), "iterations")
    lay = _layout(esc(title + note), _lab("iteration", {}), esc(ylabel))
    _int_ticks(lay, n_it)
    if log:
        lay["yaxis"]["type"] = "log"
    return Plot(ids(stem), {"data": data, "layout": lay}, wide=True)


def _int_ticks(lay: dict[str, Any], n: int) -> None:
    """Whole-number ticks on an iteration axis of ``n`` points."""
    lay["xaxis"]["tickformat"] = "d"
    if n <= 12:
        lay["xaxis"]["dtick"] = 1


def _index_names(g: Mapping[str, Any], skip: Sequence[str] = ()) -> list[str]:
    out = []
    for k, v in g.items():
        if k == "attrs" or k.endswith("_se") or k in skip or isinstance(v, Mapping):
            continue
        stem, _, tail = k.rpartition("_")
        if tail in ("n", "of") and stem in g:  # a ratio's counts: shown with its n/a
            continue
        out.append(k)
    return sorted(out, key=lambda k: (k != "f", k))
