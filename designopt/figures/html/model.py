"""The page model (a :class:`Plot`, a :class:`PageSection`), the size caps and small
helpers: escaping, even thinning, tables and numbers."""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from designopt.figures import style

MAX_RUN_LINES = 30
"""Runs drawn one by one in a convergence plot (more: an even choice, plus the best run;
the median and IQR band always cover every run)."""
MAX_LINE_POINTS = 2000
"""Points per curve (iterations thinned evenly, the last one kept)."""
MAX_MARKERS = 5000
"""Designs per scatter plot (front, scan designs)."""
MAX_CLOUD = 20000
"""Points of the workspace cloud (a seeded random choice)."""
MAX_CELLS = 40000
"""Cells per heat map (both axes thinned evenly)."""
MAX_VALUES = 250_000
"""Numbers in all plots of a page together (about 2.7 MB as base64 float64)."""
MAX_TEXT = 200_000
"""Characters of config text shown (the rest cut, and the cut stated)."""
Z = style.Z_SE

PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf")  # fmt: skip
INFEASIBLE_MARKER = {"symbol": "circle-open", "color": "#6b6b6b", "size": 9,
                     "line": {"width": 1.5}}  # fmt: skip
CONFIG = {"responsive": True, "displaylogo": False}


@dataclass
class Plot:
    """One plotly figure (a dict with ``data`` and ``layout``; arrays as numpy) in a div."""

    id: str
    fig: dict[str, Any]
    wide: bool = False
    note: str = ""


@dataclass
class PageSection:
    """A titled part of the page: plots and HTML fragments (already escaped) in order."""

    id: str
    title: str
    items: list[Plot | str] = field(default_factory=list)

    def plots(self) -> list[Plot]:
        return [p for p in self.items if isinstance(p, Plot)]


def esc(x: Any) -> str:
    """HTML-escaped text of any value (bytes decoded)."""
    return html.escape(_s(x), quote=True)


def _s(x: Any) -> str:
    if isinstance(x, bytes):
        return x.decode("utf-8", "replace")
    if isinstance(x, np.ndarray) and x.ndim == 0:
        return _s(x.item())
    return str(x)


def _names(a: Any) -> list[str]:
    return [_s(v) for v in np.atleast_1d(np.asarray(a))]


def _f(a: Any) -> np.ndarray:
    return np.asarray(a, np.float64)


def _every(n: int, cap: int) -> np.ndarray:
    """Indices of an even choice of at most ``cap`` of ``n`` points, first and last kept."""
    if n <= cap:
        return np.arange(n)
    idx = np.unique(np.round(np.linspace(0, n - 1, cap)).astype(int))
    return idx


def _thin_note(n: int, kept: int, what: str) -> str:
    return f" ({kept} of {n} {what} shown)" if kept < n else ""


def _table(head: Sequence[str], rows: Sequence[Sequence[Any]], cls: str = "") -> str:
    th = "".join(f"<th>{esc(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in r) + "</tr>" for r in rows)
    c = f' class="{cls}"' if cls else ""
    return f"<table{c}><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def _num(v: float, se: float | None = None) -> str:
    if se is None or not np.isfinite(se):
        return f"{v:.6g}"
    return f"{v:.6g} ± {se:.2g}"


class _Ids:
    def __init__(self) -> None:
        self.n = 0

    def __call__(self, stem: str) -> str:
        self.n += 1
        return f"plot-{self.n}-{''.join(c if c.isalnum() else '-' for c in stem)[:40]}"
