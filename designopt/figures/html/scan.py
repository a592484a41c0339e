"""The scan section (curves, heat maps or designs, infeasible ones marked) and the sweep
section (final f per member, the members' convergence)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.html.model import (
    INFEASIBLE_MARKER,
    MAX_CELLS,
    MAX_LINE_POINTS,
    MAX_MARKERS,
    PALETTE,
    PageSection,
    Plot,
    Z,
    _every,
    _f,
    _Ids,
    _names,
    _num,
    _s,
    _table,
    _thin_note,
    esc,
)
from designopt.figures.html.plots import (
    _index_names,
    _int_ticks,
    _is_log,
    _lab,
    _layout,
    _value_band,
    merged,
)


def _scan(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str], mod: Any) -> list[PageSection]:
    sc = tree["scan"]
    names = _names(sc["names"])
    varied = _names(sc["varied"])
    X = np.atleast_2d(_f(sc["x"]))
    n = len(X)
    inds = [k for k in _index_names(sc, skip=("names", "x", "varied", "violation"))
            if _f(sc[k]).shape == (n,)]  # fmt: skip
    drawn = merged(sc, inds)
    rates = set(getattr(mod, "RATES", ()))
    bad = _f(sc["violation"]) > 0 if "violation" in sc else np.zeros(n, bool)
    at = sc.get("attrs", {})
    sec = PageSection("scan", f"Scan over {', '.join(varied)}")
    sec.items.append(f"<p class='note'>{n} designs; mode {esc(at.get('mode', '?'))}; "
                     f"{int(bad.sum())} infeasible (violation &gt; 0)</p>")  # fmt: skip
    if len(varied) == 1:
        v = varied[0]
        x = X[:, names.index(v)]
        o = np.argsort(x, kind="stable")
        keep = o[_every(n, MAX_LINE_POINTS)]
        for j, (k, lab) in enumerate(drawn):
            y = _f(sc[k])
            rate = k in rates
            y = np.clip(y, 0, 1) if rate else y
            se = _f(sc[k + "_se"]) if k + "_se" in sc else None
            col = PALETTE[j % len(PALETTE)]
            band, what = _value_band(x[keep], y[keep], None if se is None else se[keep], rate, col)  # fmt: skip
            line = {"type": "scatter", "mode": "lines+markers" if len(keep) < 80 else "lines",
                    "x": x[keep], "y": y[keep], "name": lab, "line": {"color": col},
                    "marker": {"size": 5}}  # fmt: skip
            if se is not None:
                line["customdata"] = se[keep]
                line["hovertemplate"] = f"{esc(v)} = %{{x:.5~g}}: %{{y:.6~g}} ± %{{customdata:.2~g}} (SE)<extra></extra>"  # fmt: skip
            data = [*band, line]
            if bad.any():
                b = keep[bad[keep]]
                data.append({"type": "scatter", "mode": "markers", "x": x[b], "y": y[b],
                             "name": "infeasible (violation > 0)", "marker": INFEASIBLE_MARKER})  # fmt: skip
            t = f"{lab} along {v}" + (f" (band: {what})" if what else "") + _thin_note(n, len(keep), "designs")  # fmt: skip
            lay = _layout(esc(t), _lab(v, units), _lab(k, units), showlegend=bool(bad.any()))
            if not rate and _is_log(y):
                lay["yaxis"]["type"] = "log"
            sec.items.append(Plot(ids("scan-" + k), {"data": data, "layout": lay}))
    elif len(varied) == 2 and _s(at.get("mode", "")) == "grid" and "shape" in at:
        n0, n1 = (int(s) for s in at["shape"])
        i0, i1 = names.index(varied[0]), names.index(varied[1])
        g0 = X[:, i0].reshape(n0, n1)[:, 0]
        g1 = X[:, i1].reshape(n0, n1)[0, :]
        s = max(1, math.ceil(math.sqrt(n0 * n1 / MAX_CELLS)))
        r0, r1 = _every(n0, -(-n0 // s)), _every(n1, -(-n1 // s))
        badg = bad.reshape(n0, n1)[np.ix_(r0, r1)]
        for k, lab in drawn:
            z = _f(sc[k]).reshape(n0, n1)[np.ix_(r0, r1)]
            rate = k in rates
            tr: dict[str, Any] = {"type": "heatmap", "x": g1[r1], "y": g0[r0], "z": z,
                                  "colorscale": "Viridis",
                                  "colorbar": {"title": {"text": _lab(lab, units), "side": "right"}}}  # fmt: skip
            if rate:
                tr |= {"zmin": 0, "zmax": 1}
            if k + "_se" in sc:
                tr["customdata"] = _f(sc[k + "_se"]).reshape(n0, n1)[np.ix_(r0, r1)]
                tr["hovertemplate"] = (f"{esc(varied[1])} = %{{x:.5~g}}, {esc(varied[0])} = %{{y:.5~g}}"
                                       f"<br>{esc(k)} = %{{z:.6~g}} ± %{{customdata:.2~g}} (SE)<extra></extra>")  # fmt: skip
            data = [tr]
            if badg.any():
                ii, jj = np.nonzero(badg)
                data.append({"type": "scatter", "mode": "markers", "x": g1[r1][jj], "y": g0[r0][ii],
                             "name": "infeasible (violation > 0)", "hoverinfo": "skip",
                             "marker": {"symbol": "x", "size": 11, "color": "white",
                                        "line": {"width": 1, "color": "#222"}}})  # fmt: skip
            thin = _thin_note(n0 * n1, len(r0) * len(r1), "cells")
            lay = _layout(esc(f"{lab}: {varied[0]} × {varied[1]}{thin}"), _lab(varied[1], units),
                          _lab(varied[0], units), showlegend=bool(badg.any()),
                          legend={"orientation": "h", "y": -0.22, "font": {"size": 10}})  # fmt: skip
            sec.items.append(Plot(ids("map-" + k), {"data": data, "layout": lay}))
        if badg.any():
            sec.items.append("<p class='note'>White crosses: infeasible designs (violation &gt; 0).</p>")  # fmt: skip
    else:
        keep = _every(n, MAX_MARKERS)
        f = _f(sc["f"])
        se = _f(sc["f_se"]) if "f_se" in sc else None
        cd = X[keep]
        tpl = "<br>".join(f"{esc(nm)} = %{{customdata[{i}]:.5~g}} {esc(style.unit_of(nm, units))}"
                          for i, nm in enumerate(names))  # fmt: skip
        tr = {"type": "scatter", "mode": "markers", "x": keep, "y": f[keep], "name": "f ± 2 SE",
              "customdata": cd, "hovertemplate": f"design %{{x}}: f = %{{y:.6~g}}<br>{tpl}<extra></extra>",
              "marker": {"color": PALETTE[0], "size": 7}}  # fmt: skip
        if se is not None:
            tr["error_y"] = {"type": "data", "array": Z * se[keep], "visible": True}
        data = [tr]
        if bad.any():
            b = keep[bad[keep]]
            data.append({"type": "scatter", "mode": "markers", "x": b, "y": f[b],
                         "name": "infeasible (violation > 0)", "marker": INFEASIBLE_MARKER})  # fmt: skip
        lay = _layout(esc("f of every scanned design" + _thin_note(n, len(keep), "designs")),
                      _lab("design number (row of scan/x)", {}), _lab("f", units))  # fmt: skip
        sec.items.append(Plot(ids("scan-designs"), {"data": data, "layout": lay}, wide=True))
    return [sec]


def _sweep(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str]) -> list[PageSection]:
    mem = {k: v for k, v in tree["members"].items() if k != "attrs" and isinstance(v, Mapping)}
    labels = []
    for k, m in mem.items():
        ov = m.get("attrs", {}).get("overrides", {})
        lab = ", ".join(f"{kk.split('.')[-1]}={vv}" for kk, vv in ov.items()) if isinstance(ov, Mapping) else _s(ov)  # fmt: skip
        labels.append(f"[{k}] {lab}")
    f = np.array([float(_f(m["final"]["f"])) if "final" in m else np.nan for m in mem.values()])
    se = np.array([float(_f(m["final"]["f_se"])) if "final" in m and "f_se" in m["final"] else np.nan
                   for m in mem.values()])  # fmt: skip
    sec = PageSection("sweep", f"Sweep: {len(mem)} members")
    tr = {"type": "scatter", "mode": "markers", "x": f, "y": [esc(lab) for lab in labels],
          "name": "final f", "marker": {"size": 9, "color": PALETTE[0]},
          "hovertemplate": "%{y}: f = %{x:.6~g}<extra></extra>"}  # fmt: skip
    if np.isfinite(se).any():
        tr["error_x"] = {"type": "data", "array": Z * np.nan_to_num(se), "visible": True}
    lay = _layout("final f per member (bars ± 2 SE)", _lab("final f", units),
                  esc("member (category)"), height=max(320, 120 + 28 * len(mem)))  # fmt: skip
    lay["yaxis"]["autorange"] = "reversed"
    sec.items.append(Plot(ids("sweep-final"), {"data": [tr], "layout": lay}, wide=True))
    data = []
    hs = []
    for j, (lab, m) in enumerate(zip(labels, mem.values(), strict=True)):
        if "history" not in m.get("optimizer", {}):
            continue
        h = np.atleast_2d(_f(m["optimizer"]["history"]))
        hs.append(h)
        it = np.arange(h.shape[1])
        k = _every(len(it), MAX_LINE_POINTS)
        data.append({"type": "scatter", "mode": "lines", "x": it[k], "y": np.median(h, axis=0)[k],
                     "name": esc(lab), "line": {"color": PALETTE[j % len(PALETTE)]}})  # fmt: skip
    if data:
        lay = _layout("median best-so-far f over runs, per member", _lab("iteration", {}),
                      _lab("best f (median over runs)", {}))  # fmt: skip
        _int_ticks(lay, max(h.shape[1] for h in hs))
        if _is_log(*hs):
            lay["yaxis"]["type"] = "log"
        sec.items.append(Plot(ids("sweep-conv"), {"data": data, "layout": lay}, wide=True))
    rows = [(lab, _num(a, b if np.isfinite(b) else None)) for lab, a, b in zip(labels, f, se, strict=True)]  # fmt: skip
    sec.items.append(_table(["member", "final f ± SE"], rows))
    return [sec]
