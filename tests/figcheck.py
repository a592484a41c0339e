"""The figure checker (docs/figures.md), shared by tests/test_figures.py and the study
contract tests: every axis and colour-bar label carries a unit in [..] or (..) ([-]:
dimensionless); no text overlaps another text, another panel or leaves the canvas
(renderer-based window extents); panels declared comparable share their colour limits.
:func:`text_problems` checks every drawn text artist of a figure (annotations, table
cells and figure texts included) against the figure's edge and against every other."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from mpl_toolkits.mplot3d import Axes3D

ROOT = Path(__file__).resolve().parents[1]
UNIT = re.compile(r"(\[[^\[\]]+\]|\([^()]+\))$")
TOL = 1.0  # px: touching boxes are not overlapping


def _unit_ok(text: str) -> bool:
    return bool(text.strip()) and bool(UNIT.search(text.strip()))


def _visible(t) -> bool:
    return t.get_visible() and bool(t.get_text().strip())


def _axes_texts(ax) -> list:
    """The frame texts of one axes: titles, axis labels, tick labels."""
    axis = [ax.xaxis, ax.yaxis] + ([ax.zaxis] if isinstance(ax, Axes3D) else [])
    out = [ax.title, ax._left_title, ax._right_title]
    for a in axis:
        if a.get_visible():  # the ticks drawn (those within the view interval); a 3-D axes'
            out.append(a.label)  # tick labels have no reliable window extent: labels only
            if not isinstance(ax, Axes3D):
                out += [t for k in a._update_ticks() for t in (k.label1, k.label2)]
    return [t for t in out if _visible(t)]


def _overlap(a, b) -> bool:
    w = min(a.x1, b.x1) - max(a.x0, b.x0)
    h = min(a.y1, b.y1) - max(a.y0, b.y0)
    return w > TOL and h > TOL


def problems(fig) -> list[str]:
    """What is wrong with ``fig`` (empty: it passes)."""
    out = []
    if not hasattr(fig.canvas, "get_renderer"):  # a closed pyplot figure: a fresh Agg canvas
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    canvas = fig.bbox
    axes = [
        ax for ax in fig.axes if ax.get_visible() and (ax.axison or getattr(ax, "_axis3don", False))
    ]
    frame = []  # (owner axes or None, text)
    for ax in axes:
        cb = getattr(ax, "_colorbar", None)
        if cb is not None:
            lab = (ax.yaxis if cb.orientation == "vertical" else ax.xaxis).label.get_text()
            if not _unit_ok(lab):
                out.append(f"colour bar label {lab!r} has no unit")
        else:
            labs = [("x", ax.get_xlabel()), ("y", ax.get_ylabel())]
            if isinstance(ax, Axes3D):
                labs.append(("z", ax.get_zlabel()))
            for w, lab in labs:
                if getattr(ax, f"{w}axis").get_visible() and not _unit_ok(lab):
                    out.append(f"{w} label {lab!r} of {ax.get_title()!r} has no unit")
        frame += [(ax, t) for t in _axes_texts(ax)]
        leg = ax.get_legend()
        if leg is not None and leg.get_visible():
            frame.append((ax, leg))
    if fig._suptitle is not None and _visible(fig._suptitle):
        frame.append((None, fig._suptitle))
    frame += [(None, leg) for leg in fig.legends]
    data = [(ax, t) for ax in axes for t in ax.texts if _visible(t)]
    boxes = [(ax, t, t.get_window_extent(r)) for ax, t in frame + data]
    for _, t, b in boxes:
        if b.x0 < canvas.x0 - TOL or b.y0 < canvas.y0 - TOL or b.x1 > canvas.x1 + TOL or \
                b.y1 > canvas.y1 + TOL:  # fmt: skip
            out.append(f"text {_name(t)} leaves the canvas")
    nf = len(frame)
    for i in range(nf):  # frame texts against frame texts and annotations
        ai, ti, bi = boxes[i]
        for _, tj, bj in boxes[i + 1 :]:
            if _overlap(bi, bj) and not _in_legend(ti, tj):
                out.append(f"text {_name(ti)} overlaps {_name(tj)}")
        if ti is fig._suptitle:
            continue
        for ax in axes:  # a frame text over another 2-D panel (a colour bar included)
            if (
                ax is not ai
                and not isinstance(ax, Axes3D)
                and _overlap(bi, ax.get_window_extent(r))
            ):
                out.append(f"text {_name(ti)} lies over another panel")
    for group in getattr(fig, "designopt_shared", []):
        lims = {tuple(np.round(m.get_clim(), 12)) for m in group}
        if len(lims) != 1:
            out.append(f"panels meant to be compared have colour limits {sorted(lims)}")
    return out


def drawn_texts(fig) -> list:
    """Every visible text artist of ``fig`` that is drawn: titles, axis labels, the tick
    labels a 2-D axes draws (those within its view interval), legends' texts, table
    cells, annotations and figure texts. A 3-D axes' tick labels are left out (matplotlib
    gives them no reliable extent), its axis labels kept; an axes drawn without its
    frame (``set_axis_off``: a table's) contributes no axis text."""
    from matplotlib.text import Text

    ticks, keep = set(), []
    for ax in fig.axes:
        is3d = isinstance(ax, Axes3D)
        on = ax.axison if not is3d else getattr(ax, "_axis3don", True)
        axis = [ax.xaxis, ax.yaxis] + ([ax.zaxis] if is3d else [])
        for a in axis:
            every = a.get_major_ticks() + a.get_minor_ticks()
            ticks |= {id(t) for k in every for t in (k.label1, k.label2)}
            ticks |= {id(a.label), id(a.offsetText)}
            if not (on and ax.get_visible() and a.get_visible()):
                continue
            keep += [a.label, a.offsetText]
            if not is3d:
                keep += [t for k in a._update_ticks() for t in (k.label1, k.label2)]
        keep += [c.get_text() for tab in ax.tables for c in tab.get_celld().values()]
    out = [t for t in fig.findobj(Text) if id(t) not in ticks] + keep
    seen, uniq = set(), []
    for t in out:
        if id(t) not in seen and _visible(t) and _shown(t):
            seen.add(id(t))
            uniq.append(t)
    return uniq


def _shown(t) -> bool:
    """Whether a text's parents (its axes, legend) are visible too."""
    ax = t.axes
    if ax is not None and not ax.get_visible():
        return False
    p = getattr(t, "_parent_legend", None)
    return p is None or p.get_visible()


def text_problems(fig, tol: float = TOL) -> list[str]:
    """Every drawn text artist (:func:`drawn_texts`) of a saved figure must lie inside
    the figure and overlap no other text artist (window extents after a draw; overlaps
    under ``tol`` px tolerated). Returns what is wrong (empty: it passes)."""
    if not hasattr(fig.canvas, "get_renderer"):
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    canvas = fig.bbox
    from matplotlib.text import Text

    texts = drawn_texts(fig)
    boxes = [Text.get_window_extent(t, r) for t in texts]  # an annotation's text, not its arrow
    out = []
    for t, b in zip(texts, boxes, strict=True):
        if b.x0 < canvas.x0 - tol or b.y0 < canvas.y0 - tol or b.x1 > canvas.x1 + tol or \
                b.y1 > canvas.y1 + tol:  # fmt: skip
            out.append(f"text {_name(t)} leaves the figure")
    for i in range(len(texts)):
        for j in range(i + 1, len(texts)):
            w = min(boxes[i].x1, boxes[j].x1) - max(boxes[i].x0, boxes[j].x0)
            h = min(boxes[i].y1, boxes[j].y1) - max(boxes[i].y0, boxes[j].y0)
            if w > tol and h > tol:
                out.append(f"text {_name(texts[i])} overlaps {_name(texts[j])}")
    return out


def _in_legend(a, b) -> bool:
    from matplotlib.legend import Legend

    return (isinstance(a, Legend) and b in a.get_texts()) or (
        isinstance(b, Legend) and a in b.get_texts()
    )


def _name(t) -> str:
    return repr(t.get_text()) if hasattr(t, "get_text") else type(t).__name__


def assert_clean(rec) -> None:
    """Every figure recorded (``designopt.canvas.RECORD``) passes :func:`problems`."""
    assert rec, "no figure was saved"
    bad = {name: p for name, fig in rec if (p := problems(fig))}
    assert not bad, "\n".join(f"{k}: {v}" for k, v in bad.items())
