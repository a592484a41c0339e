"""The benchmark sections (box plots, median convergence, hypervolume, statistics), the
inverse-kinematics section and the workspace cloud."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.html.model import (
    MAX_CLOUD,
    MAX_LINE_POINTS,
    PALETTE,
    PageSection,
    Plot,
    _every,
    _f,
    _Ids,
    _s,
    _table,
    esc,
)
from designopt.figures.html.plots import _band, _is_log, _lab, _layout


def _floored(values: list[np.ndarray]) -> tuple[list[np.ndarray], float | None]:
    v = np.concatenate([np.ravel(x) for x in values]) if values else np.zeros(0)
    pos = v[v > 0]
    if (v <= 0).any() and pos.size:
        fl = float(pos.min()) / 10
        return [np.maximum(x, fl) for x in values], fl
    return values, None


def _bench(tree: Mapping[str, Any], ids: _Ids) -> list[PageSection]:
    out = []
    for case, g in tree["bench"].items():
        if case == "attrs" or not isinstance(g, Mapping):
            continue
        ents = {v: e for v, e in g.items() if v != "attrs" and isinstance(e, Mapping)}
        sec = PageSection(f"bench-{case}", f"Benchmark: {case}")
        fin = [_f(e["best_f"]) if "best_f" in e else _f(e["history"])[:, -1] for e in ents.values()]
        shown, fl = _floored(fin)
        log = _is_log(*shown)
        data = [{"type": "box", "y": y, "name": esc(v), "boxpoints": "all", "jitter": 0.4,
                 "pointpos": 0, "marker": {"size": 3, "color": PALETTE[j % len(PALETTE)]},
                 "line": {"color": PALETTE[j % len(PALETTE)]}}
                for j, (v, y) in enumerate(zip(ents, shown, strict=True))]  # fmt: skip
        n_runs = max((len(y) for y in fin), default=0)
        t = f"{case}: final best f over {n_runs} runs"
        if fl is not None:
            t += f" (values ≤ 0 drawn at {fl:.3g})"
        lay = _layout(esc(t), esc("optimizer (category)"), _lab("final best f(x)", {}), showlegend=False)  # fmt: skip
        if log:
            lay["yaxis"]["type"] = "log"
        sec.items.append(Plot(ids(f"box-{case}"), {"data": data, "layout": lay}))
        hs = [np.atleast_2d(_f(e["history"])) for e in ents.values() if "history" in e]
        if hs:
            hsh, fl2 = _floored(hs)
            data = []
            for j, (v, h) in enumerate(zip([v for v, e in ents.items() if "history" in e], hsh, strict=True)):  # fmt: skip
                q25, q50, q75 = np.percentile(h, [25, 50, 75], axis=0)
                it = np.arange(h.shape[1])
                k = _every(len(it), MAX_LINE_POINTS // 4)
                col = PALETTE[j % len(PALETTE)]
                data += _band(it[k], q25[k], q75[k], col, esc(v))
                data.append({"type": "scatter", "mode": "lines", "x": it[k], "y": q50[k],
                             "name": esc(v), "legendgroup": esc(v), "line": {"color": col}})  # fmt: skip
            t = f"{case}: convergence (median, band IQR)"
            if fl2 is not None:
                t += f"; values ≤ 0 drawn at {fl2:.3g}"
            lay = _layout(esc(t), _lab("iteration", {}), _lab("best f (median, IQR)", {}))
            if _is_log(*hsh):
                lay["yaxis"]["type"] = "log"
            sec.items.append(Plot(ids(f"conv-{case}"), {"data": data, "layout": lay}))
        hv = {v: _f(e["hypervolume"]) for v, e in ents.items() if "hypervolume" in e}
        if hv:
            data = [{"type": "box", "y": y, "name": esc(v), "boxpoints": "all", "jitter": 0.4,
                     "pointpos": 0, "marker": {"size": 3}} for v, y in hv.items()]  # fmt: skip
            lay = _layout(esc(f"{case}: hypervolume over runs (higher is better)"),
                          esc("optimizer (category)"), "hypervolume [-]", showlegend=False)  # fmt: skip
            sec.items.append(Plot(ids(f"hv-{case}"), {"data": data, "layout": lay}))
        st = g.get("attrs", {}).get("stats")
        if isinstance(st, Mapping) and isinstance(st.get("rows"), Mapping):
            cols = ["mean", "std", "median", "best", "conv_mean", "success", "p_holm"]
            rows = []
            for v, r in st["rows"].items():
                rows.append([v] + [("ref" if c == "p_holm" else "") if c not in r else
                                   (f"{100 * r[c]:.0f} %" if c == "success" else f"{r[c]:.4g}")
                                   for c in cols])  # fmt: skip
            thr = st.get("threshold")
            cap = f"success: final ≤ {thr:g}; " if isinstance(thr, (int, float)) else ""
            sec.items.append(f"<p class='note'>{esc(cap)}Mann-Whitney U against the reference, "
                             "Holm-corrected p</p>" + _table(["entry", *cols], rows))  # fmt: skip
        out.append(sec)
    return out


def _ik_units(text: Any) -> dict[str, str]:
    """``"q1, q2 rad; q3 mm; pos_err mm"`` → {q1: rad, q2: rad, q3: mm, pos_err: mm}."""
    out: dict[str, str] = {}
    for part in _s(text).split(";"):
        bits = part.strip().rsplit(" ", 1)
        if len(bits) == 2:
            for nm in bits[0].split(","):
                out[nm.strip()] = bits[1].strip()
    return out


def _ik(tree: Mapping[str, Any], ids: _Ids) -> list[PageSection]:
    from designopt.results import ik as iktext

    ik = tree["ik"]
    ok = np.asarray(ik["success"], bool)
    n, k = len(ok), int(ok.sum())
    p = k / max(n, 1)
    lo, hi = style.wilson(np.array([p]), n)
    u = _ik_units(ik.get("attrs", {}).get("units", ""))
    sec = PageSection("ik", "Inverse kinematics")
    sec.items.append("<ul>" + "".join(f"<li>{esc(x)}</li>" for x in iktext.summary_lines(ik)) + "</ul>")  # fmt: skip
    tr = {"type": "bar", "x": ["solved"], "y": [p], "marker": {"color": PALETTE[2]},
          "error_y": {"type": "data", "symmetric": False, "array": [hi[0] - p],
                      "arrayminus": [p - lo[0]], "visible": True},
          "hovertemplate": f"{k} of {n} solved: %{{y:.4f}} (Wilson {lo[0]:.4f}…{hi[0]:.4f})<extra></extra>"}  # fmt: skip
    lay = _layout(esc(f"success rate {k}/{n} (Wilson interval, z = 2)"), esc("outcome (category)"),
                  _lab("success rate", {}), showlegend=False)  # fmt: skip
    lay["yaxis"]["range"] = [0, 1.02]
    sec.items.append(Plot(ids("ik-rate"), {"data": [tr], "layout": lay}))
    for key in ("pos_err", "rot_err", "iterations"):
        if key not in ik:
            continue
        v = _f(ik[key])
        fin = v[np.isfinite(v)]
        pos = fin[fin > 0]
        # one axis for solved and failed: log10 when the positive errors span > 2 decades
        # (an error of exactly 0 counted at a floor a decade below the least positive)
        log = key != "iterations" and pos.size > 0 and pos.max() / pos.min() > style.LOG_RATIO
        floor = float(pos.min()) / 10 if log else 0.0
        data = []
        for nm, mask, col in (("solved", ok, PALETTE[2]), ("failed", ~ok, PALETTE[3])):
            vv = v[mask & np.isfinite(v)]
            if vv.size:
                data.append({"type": "histogram", "x": np.log10(np.maximum(vv, floor)) if log else vv,
                             "name": f"{nm} ({vv.size})", "marker": {"color": col},
                             "opacity": 0.7})  # fmt: skip
        unit = u.get(key, style.DIMENSIONLESS if key == "iterations" else "")
        xl = style.label(("log10 " if log else "") + key, unit)
        t = f"{key} histogram" + (
            f" (0 counted at {floor:.2g})" if log and (fin <= 0).any() else ""
        )
        lay = _layout(esc(t), esc(xl), esc(style.label("poses", "count")),
                      barmode="overlay")  # fmt: skip
        sec.items.append(Plot(ids("ik-" + key), {"data": data, "layout": lay}))
    return [sec]


def _cloud(cloud: Mapping[str, Any], ids: _Ids) -> PageSection:
    xyz = np.asarray(cloud["xyz"], np.float64).reshape(-1, 3)
    val = np.asarray(cloud["value"], np.float64).ravel()
    if len(val) != len(xyz):
        raise ValueError(f"cloud: {len(xyz)} points but {len(val)} values")
    lab, unit = _s(cloud.get("label", "value")), _s(cloud.get("unit", style.DIMENSIONLESS))
    xu = _s(cloud.get("xyz_unit", "mm"))
    n = len(xyz)
    flag = np.zeros(n, bool) if cloud.get("flag") is None else np.asarray(cloud["flag"], bool)
    flag = flag.ravel()
    if len(flag) != n:
        raise ValueError(f"cloud: {n} points but {len(flag)} flags")
    fl_lab = _s(cloud.get("flag_label", "flagged"))
    keep = np.sort(np.random.default_rng(0).choice(n, MAX_CLOUD, replace=False)) if n > MAX_CLOUD else np.arange(n)  # fmt: skip
    where = f"x %{{x:.4~g}}, y %{{y:.4~g}}, z %{{z:.4~g}} {esc(xu)}<br>"
    k = keep[~flag[keep]]
    fin = np.isfinite(val[k])
    tr = {"type": "scatter3d", "mode": "markers", "x": xyz[k, 0], "y": xyz[k, 1],
          "z": xyz[k, 2], "name": esc(lab),
          "marker": {"size": 2, "color": np.where(fin, val[k], np.nan), "colorscale": "Viridis",
                     "opacity": 0.85, "colorbar": {"title": {"text": esc(style.label(lab, unit))}}},
          "hovertemplate": f"{where}{esc(lab)} = %{{marker.color:.4~g}} {esc(unit)}<extra></extra>"}  # fmt: skip
    data = [tr]
    kf = keep[flag[keep]]
    if kf.size:  # e.g. a task's unreached targets: grey crosses, no colour
        data.append({"type": "scatter3d", "mode": "markers", "x": xyz[kf, 0], "y": xyz[kf, 1],
                     "z": xyz[kf, 2], "name": esc(fl_lab),
                     "marker": {"size": 3, "symbol": "cross", "color": "#6b6b6b"},
                     "hovertemplate": f"{where}{esc(fl_lab)}<extra></extra>"})  # fmt: skip
    scene = {a: {"title": {"text": esc(style.label(a[0], xu))}} for a in ("xaxis", "yaxis", "zaxis")}  # fmt: skip
    title = _s(cloud.get("title", f"{lab} over the workspace"))
    title += f": {n} points" + (f" ({len(keep)} shown)" if len(keep) < n else "")
    if flag.any():
        title += f"; {fl_lab}: {int(flag.sum())} (grey crosses)"
    lay = _layout(esc(title), scene=scene | {"aspectmode": "data"}, height=620)
    if kf.size:  # two traces: the legend top left, clear of the colour bar
        lay["legend"] |= {"x": 0.0, "y": 1.0, "xanchor": "left", "yanchor": "top"}
    sec = PageSection("cloud", "Workspace")
    sec.items.append(Plot(ids("cloud"), {"data": data, "layout": lay}, wide=True))
    return sec
