"""The Pareto-front section: 2-D, 3-D or a scatter matrix with ± 2 SE bars, ambiguous
pairs marked, every index of the study ± SE in the hover text (the objectives first, then
every other index), the front's designs in parallel coordinates (variables, objectives
and every other index) and the hypervolume history of the best front found so far (the
populations' own beside it)."""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.html.model import (
    MAX_MARKERS,
    PALETTE,
    PageSection,
    Plot,
    Z,
    _every,
    _f,
    _Ids,
    _names,
    _s,
    _table,
    _thin_note,
    esc,
)
from designopt.figures.html.plots import _convergence, _index_names, _lab, _layout, _rgba
from designopt.figures.html.run import notes_html, placement_table

DESIGNS_HEIGHT = 560
"""Pixels of the parallel coordinates of the front's designs."""
PARCOORDS_WIDTH = 1000
"""About the pixels the page gives the parallel coordinates' axes (a wide plot)."""
CHAR_PX = 6.2
"""About the pixels of one character of an axis name (10 px font)."""


def _plain(label: str) -> str:
    """An axis name as read: no HTML tags or entities."""
    return re.sub(r"&[#\w]+;", "x", re.sub(r"<[^>]+>", "", label))


def _pairs(amb: Any, n: int) -> np.ndarray:
    """Ambiguous pairs (p, 2) from an (n, n) boolean matrix or a (p, 2) index array."""
    a = np.asarray(amb)
    if a.ndim == 2 and a.shape == (n, n) and (a.dtype == bool or n != 2):
        i, j = np.nonzero(np.triu(a.astype(bool) | a.astype(bool).T, 1))
        return np.stack([i, j], axis=1)
    if a.ndim == 2 and a.shape[1] == 2:
        return a.astype(int)
    return np.zeros((0, 2), int)


def front_objectives(fr: Mapping[str, Any]) -> tuple[list[str], list[str]]:
    """(objective names, senses) of a front group: attrs ``objectives`` and ``senses``
    (``min``/``max``), else ``f1 … fm`` minimised."""
    at = fr.get("attrs", {})
    m = np.atleast_2d(_f(fr["f"])).shape[1]
    names = [_s(x) for x in at.get("objectives", [])] or [f"f{i + 1}" for i in range(m)]
    senses = [_s(x) for x in at.get("senses", [])] or ["min"] * m
    return names[:m], senses[:m]


def _hover(fr: Mapping[str, Any], X: np.ndarray, vnames: list[str], objs: list[str],
           vals: np.ndarray, ses: np.ndarray, others: list[str], amb_count: np.ndarray,
           units: Mapping[str, str]) -> tuple[np.ndarray, str]:  # fmt: skip
    """(customdata (n, k), hover template): the design number, its variables, its
    ambiguous pairs, the objectives ± SE, every other index ± SE (no ± where the index
    has no SE) and the rank after re-scoring."""
    n = len(vals)
    cd = [np.arange(n)[:, None].astype(float), X, amb_count[:, None].astype(float)]
    tpl = ["<b>design %{customdata[0]}</b>"]
    c = 1
    for j, v in enumerate(vnames[: X.shape[1]]):
        tpl.append(f"{esc(v)} = %{{customdata[{c + j}]:.5~g}} {esc(style.unit_of(v, units))}")
    c += X.shape[1]
    tpl.append(f"in %{{customdata[{c}]}} ambiguous pairs")
    c += 1

    def line(k: str, v: np.ndarray, se: np.ndarray | None) -> None:
        nonlocal c
        u = esc(style.unit_of(k, units))
        if se is None:
            cd.append(v[:, None])
            tpl.append(f"{esc(k)} = %{{customdata[{c}]:.5~g}} {u}")
            c += 1
        else:
            cd.extend([v[:, None], se[:, None]])
            tpl.append(f"{esc(k)} = %{{customdata[{c}]:.5~g}} ± %{{customdata[{c + 1}]:.2~g}} {u}")
            c += 2

    tpl.append("<i>objectives (± SE):</i>")
    for i, k in enumerate(objs):
        line(k, vals[:, i], ses[:, i])
    if others:
        tpl.append("<i>every other index (± SE):</i>")
    for k in others:
        line(k, _f(fr[k]), _f(fr[k + "_se"]) if k + "_se" in fr else None)
    if "rank" in fr and _f(fr["rank"]).shape == (n,):
        cd.append(_f(fr["rank"])[:, None])
        tpl.append(f"rank after re-scoring: %{{customdata[{c}]}}")
    return np.concatenate(cd, axis=1), "<br>".join(tpl) + "<extra></extra>"


def _designs(fr: Mapping[str, Any], prob: Mapping[str, Any], X: np.ndarray,
             vnames: list[str], axl: list[str], vals: np.ndarray, others: list[str],
             keep: np.ndarray, ids: _Ids, units: Mapping[str, str]) -> Plot:  # fmt: skip
    """The front's designs in parallel coordinates: each variable on its box, each
    objective and every other index on its range over the front, coloured by the first
    objective (drag along an axis to pick designs)."""
    lo = _f(prob["lower"]) if "lower" in prob else None
    hi = _f(prob["upper"]) if "upper" in prob else None
    dims = []
    for j, v in enumerate(vnames[: X.shape[1]]):
        d = {"label": _lab(v, units), "values": X[keep, j]}
        if lo is not None and hi is not None and len(lo) == X.shape[1] and hi[j] > lo[j]:
            d["range"] = [float(lo[j]), float(hi[j])]
        dims.append(d)
    dims += [{"label": axl[i], "values": vals[keep, i]} for i in range(vals.shape[1])]
    dims += [{"label": _lab(k, units), "values": _f(fr[k])[keep]} for k in others]
    for d in dims:  # short numbers on the axes and their range ends
        d["tickformat"] = ".4~g"
    # the page keeps a plot's top margin small: the axis names sit inside the plot area,
    # turned where side by side they would not fit the space between two axes
    gap = PARCOORDS_WIDTH / max(len(dims), 1)
    longest = max((len(_plain(d["label"])) for d in dims), default=0)
    turn = CHAR_PX * longest > 0.9 * gap
    rise = min(0.5, (CHAR_PX * longest * 0.6 + 30) / DESIGNS_HEIGHT) if turn else 0.16
    top = 1.0 - rise
    tr = {"type": "parcoords", "dimensions": dims, "domain": {"y": [0.0, top]},
          "labelangle": -35 if turn else 0, "labelside": "top",
          "labelfont": {"size": 10}, "rangefont": {"size": 9}, "tickfont": {"size": 9},
          "line": {"color": vals[keep, 0], "colorscale": "Viridis", "showscale": True,
                   "colorbar": {"title": {"text": axl[0], "side": "right"}, "thickness": 12,
                                "len": top, "y": 0.0, "yanchor": "bottom"}}}  # fmt: skip
    title = (f"The front's {len(keep)} designs: variables (on their box), objectives and every "
             f"other index (on their range over the front); colour: the first objective; drag "
             f"along an axis to pick designs")  # fmt: skip
    lay = _layout(esc(title), height=DESIGNS_HEIGHT)
    # the first axis' range numbers sit left of it, a turned last name runs right of it
    lay["margin"] = {"l": 70, "r": 40 + (int(CHAR_PX * longest * 0.82) if turn else 0), "b": 30}
    return Plot(ids("designs"), {"data": [tr], "layout": lay}, wide=True)


def _front(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str]) -> list[PageSection]:
    fr = tree["front"]
    own = fr.get("attrs", {}).get("units", {})  # a linear objective's unit (its variables')
    if isinstance(own, Mapping):
        units = dict(units) | {_s(k): _s(v) for k, v in own.items()}
    F = np.atleast_2d(_f(fr["f"]))
    n, m = F.shape
    Fse = np.atleast_2d(_f(fr["f_se"])) if "f_se" in fr else np.full((n, m), np.nan)
    names, senses = front_objectives(fr)
    # shown in the indices' own values: front/<name> where archived, else f with max negated
    vals = np.stack([_f(fr[k]) if k in fr and _f(fr[k]).shape == (n,) else
                     (-F[:, i] if senses[i] == "max" else F[:, i]) for i, k in enumerate(names)],
                    axis=1)  # fmt: skip
    ses = np.stack([_f(fr[k + "_se"]) if k + "_se" in fr else Fse[:, i] for i, k in enumerate(names)],
                   axis=1)  # fmt: skip
    X = np.atleast_2d(_f(fr["x"])) if "x" in fr else np.zeros((n, 0))
    prob = tree.get("problem", {})
    vnames = _names(prob["names"]) if "names" in prob else [f"x{i}" for i in range(X.shape[1])]
    skip = ("x", "f", "ambiguous", "hypervolume", "rank")
    others = [k for k in _index_names(fr, skip=skip) if _f(fr[k]).shape == (n,) and k not in names]
    pairs = _pairs(fr["ambiguous"], n) if "ambiguous" in fr else np.zeros((0, 2), int)
    amb_count = np.bincount(pairs.ravel(), minlength=n) if len(pairs) else np.zeros(n, int)
    keep = _every(n, MAX_MARKERS)
    custom, hover = _hover(fr, X, vnames, names, vals, ses, others, amb_count, units)
    custom = custom[keep]
    amb = amb_count[keep] > 0
    colors = np.where(amb, PALETTE[1], PALETTE[0])
    symbols = ["diamond" if a else "circle" for a in amb]
    axl = [esc(style.label(f"{k} ({s})", style.unit_of(k, units))) for k, s in zip(names, senses, strict=True)]  # fmt: skip
    title = (f"Pareto front: {n} designs{_thin_note(n, len(keep), 'designs')}; bars ± 2 SE; "
             f"orange diamonds: in a pair whose order is within 2 SE ({len(pairs)} pairs)")  # fmt: skip
    sec = PageSection("front", "Pareto front")
    pts: dict[str, Any] = {"mode": "markers", "customdata": custom, "hovertemplate": hover,
                           "name": "front", "marker": {"color": colors, "symbol": symbols,
                                                       "size": 8, "line": {"width": 0.5, "color": "#333"}}}  # fmt: skip
    if m == 2:
        tr = {"type": "scatter", "x": vals[keep, 0], "y": vals[keep, 1], **pts,
              "error_x": {"type": "data", "array": Z * ses[keep, 0], "visible": True,
                          "thickness": 1, "width": 0, "color": "#999"},
              "error_y": {"type": "data", "array": Z * ses[keep, 1], "visible": True,
                          "thickness": 1, "width": 0, "color": "#999"}}  # fmt: skip
        data = [tr]
        if 0 < len(pairs) <= 2000:
            px = np.full(3 * len(pairs), np.nan)
            py = px.copy()
            px[0::3], px[1::3] = vals[pairs[:, 0], 0], vals[pairs[:, 1], 0]
            py[0::3], py[1::3] = vals[pairs[:, 0], 1], vals[pairs[:, 1], 1]
            data.insert(0, {"type": "scatter", "mode": "lines", "x": px, "y": py,
                            "name": "ambiguous pair", "hoverinfo": "skip",
                            "line": {"color": _rgba(PALETTE[1], 0.5), "width": 1, "dash": "dot"}})  # fmt: skip
        lay = _layout(esc(title), axl[0], axl[1], showlegend=bool(len(pairs)))
        sec.items.append(Plot(ids("front"), {"data": data, "layout": lay}, wide=True))
    elif m == 3:
        tr = {
            "type": "scatter3d",
            "x": vals[keep, 0],
            "y": vals[keep, 1],
            "z": vals[keep, 2],
            **pts,
        }
        tr["marker"] = tr["marker"] | {"size": 4}
        for a, i in (("error_x", 0), ("error_y", 1), ("error_z", 2)):
            tr[a] = {"type": "data", "array": Z * ses[keep, i], "visible": True,
                     "thickness": 1, "width": 0, "color": "#999"}  # fmt: skip
        scene = {a: {"title": {"text": t}} for a, t in zip(("xaxis", "yaxis", "zaxis"), axl, strict=True)}  # fmt: skip
        lay = _layout(esc(title), scene=scene, height=560)
        sec.items.append(Plot(ids("front3d"), {"data": [tr], "layout": lay}, wide=True))
    else:
        dims = [{"label": axl[i], "values": vals[keep, i]} for i in range(m)]
        tr = {"type": "splom", "dimensions": dims, "customdata": custom, "hovertemplate": hover,
              "marker": {"color": colors, "size": 5}, "diagonal": {"visible": False}}  # fmt: skip
        lay = _layout(esc(title + " (pairwise projections)"), height=180 * m + 80)
        sec.items.append(Plot(ids("front-splom"), {"data": [tr], "layout": lay}, wide=True))
    rows = [(a, b) for a, b in zip(names, senses, strict=True)]
    rows += [(k, "not traded") for k in others]
    sec.items.append("<p class='note'>Values are the indices themselves (a <i>max</i> objective "
                     "is shown as its index, not negated); every other index the study computes "
                     "is in the hover text and the design plot, re-scored like the objectives. "
                     "Two designs form an <i>ambiguous</i> "
                     "pair when their order in some objective is within 2 standard errors: "
                     "the Monte-Carlo noise could swap them, so neither is known to be better "
                     "there.</p>" + _table(["index", "sense"], rows))  # fmt: skip
    if X.shape[1]:
        sec.items.append(_designs(fr, prob, X, vnames, axl, vals, others, keep, ids, units))
    at = fr.get("attrs", {})  # what a weighted run says of its final design, per design
    notes = notes_html(at.get("coverage_lines", []), at.get("warnings", []))
    if notes:
        sec.items.append(notes)
    placed = placement_table(fr, front=True)
    if placed:  # each design's placement in numbers (e.g. a planning case's ports, bases)
        sec.items.append("<p class='note'>Where each design (its row in the archive's "
                         "front/x, from 0) puts each arm in the world frame, as the study "
                         "gives it (lengths in the chain's unit, angles in degrees):</p>"
                         + placed)  # fmt: skip
    opt = tree.get("optimizer", {})
    hv_tree = fr if "hypervolume" in fr else opt
    if "hypervolume" in hv_tree:
        hv = _f(hv_tree["hypervolume"])
        ref = fr.get("attrs", {}).get("reference")
        pop = _f(opt["population_hypervolume"]) if "population_hypervolume" in opt else None
        what = ("hypervolume of the best front found so far (every design evaluated) per "
                "iteration" if pop is not None else "hypervolume per iteration")  # fmt: skip
        t = what + (f" (reference point {np.round(_f(ref), 6).tolist()})" if ref is not None else "")  # fmt: skip
        if hv.ndim == 2:
            p = _convergence(
                hv, int(np.argmax(hv[:, -1])), ids, t, "hypervolume [-]", "hypervolume"
            )
            if pop is not None and pop.shape == hv.shape:
                it = np.arange(hv.shape[1])
                p.fig["data"].append({"type": "scatter", "mode": "lines", "x": it,
                                      "y": np.median(pop, axis=0),
                                      "name": f"median of the {len(pop)} populations alone",
                                      "line": {"color": PALETTE[1], "dash": "dot", "width": 1.5}})  # fmt: skip
        else:
            p = Plot(ids("hv"), {"data": [{"type": "scatter", "mode": "lines", "x": np.arange(len(hv)), "y": hv}],
                                 "layout": _layout(esc(t), _lab("iteration", {}), "hypervolume [-]")})  # fmt: skip
        sec.items.append(p)
    return [sec]
