"""The page's size budget: its plots thinned evenly until they hold at most
:data:`~designopt.figures.html.model.MAX_VALUES` numbers."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.figures.html.model import MAX_VALUES, PageSection, _every

_POINTWISE = ("x", "y", "z", "customdata", "text")


def _size(tr: Mapping[str, Any]) -> int:
    n = 0
    for k, v in tr.items():
        if isinstance(v, np.ndarray):
            n += v.size
        elif isinstance(v, Mapping):
            n += _size(v)
        elif isinstance(v, list) and k == "dimensions":
            n += sum(_size(d) for d in v)
    return n


def _thin_trace(tr: dict[str, Any], s: int) -> None:
    """Keep every s-th point (heat maps: every s-th row and column) of a trace in place."""
    t = tr.get("type")
    if t == "heatmap":
        z = tr["z"]
        r0, r1 = _every(z.shape[0], -(-z.shape[0] // s)), _every(z.shape[1], -(-z.shape[1] // s))
        tr["z"] = z[np.ix_(r0, r1)]
        if isinstance(tr.get("customdata"), np.ndarray):
            tr["customdata"] = tr["customdata"][np.ix_(r0, r1)]
        tr["x"], tr["y"] = np.asarray(tr["x"])[r1], np.asarray(tr["y"])[r0]
        return
    if t not in ("scatter", "scatter3d"):
        return
    n = len(tr["x"]) if "x" in tr else 0
    keep = _every(n, -(-n // s))

    def cut(d: dict[str, Any]) -> None:
        for k, v in d.items():
            if isinstance(v, np.ndarray) and v.ndim and len(v) == n:
                d[k] = v[keep]
            elif isinstance(v, list) and len(v) == n and k in ("symbol", "text", *_POINTWISE):
                d[k] = [v[i] for i in keep]
            elif isinstance(v, dict) and k in ("marker", "error_x", "error_y", "error_z"):
                cut(v)

    cut(tr)


def budget(sections: Sequence[PageSection], max_values: int = MAX_VALUES) -> int:
    """Thin the plots of ``sections`` in place until they hold at most ``max_values``
    numbers (scatter and heat-map traces over 500 values, evenly); returns the count."""
    traces = [tr for s in sections for p in s.plots() for tr in p.fig["data"]]
    for _ in range(6):
        total = sum(_size(tr) for tr in traces)
        if total <= max_values:
            return total
        s = max(2, math.ceil(total / max_values))
        for tr in traces:
            if _size(tr) > 500:
                _thin_trace(tr, s)
    return sum(_size(tr) for tr in traces)
