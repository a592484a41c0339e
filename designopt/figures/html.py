"""The interactive report: one self-contained HTML page per archive (docs/figures.md).

``page(tree)`` takes an archive as the nested dict ``designopt.archive.read`` returns and
gives one HTML document that works offline, with no server: plotly.js is embedded once
(about 4.8 MB), every plot's data follows as JSON (numeric arrays as base64 typed arrays,
exact float64), and one script draws them. ``write(tree, path)`` writes the page through
the one writer (``designopt.output``).

What a page shows, by the root attr ``kind``:

- ``run``: the best-so-far f of every run and the best run, the best run's indices over the
  iterations (± 2 SE bands where ``<index>_se`` exists; success rates clipped to [0, 1]
  with a Wilson band), the final design and its indices ± SE, the config; a replay
  (``teleop/``) its paths and tracking error;
- a ``front`` group (any kind): the Pareto front in 2-D with ± 2 SE bars, in 3-D for three
  objectives, a scatter matrix for more, hover showing each design's variables and
  indices ± SE, pairs whose order is within 2 SE (``front/ambiguous``) marked, and the
  hypervolume history when archived;
- ``scan``: curves (one varied variable) or heat maps (a two-variable grid) of f and every
  index, infeasible designs marked; otherwise f ± 2 SE per design;
- ``sweep``: the final f ± 2 SE per member and the members' convergence;
- ``bench``: per case, box plots of the final values per optimizer, the median convergence
  curves (band: interquartile range), the hypervolume when the entries carry it, and the
  statistics table;
- ``ik``: the success rate (Wilson interval) and histograms of the errors;
- ``cloud`` (an argument): a 3-D point cloud of the workspace coloured by a value.

Size: each plot keeps at most :data:`MAX_RUN_LINES` runs, :data:`MAX_LINE_POINTS` points
per curve, :data:`MAX_MARKERS` designs per scatter, :data:`MAX_CLOUD` cloud points and
:data:`MAX_CELLS` cells per heat map (evenly thinned, the last point kept; the plot's title
says so); then the whole page is thinned further until its plots hold at most
:data:`MAX_VALUES` numbers, so a page stays under about 8 MB (plotly.js included).
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
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


# ------------------------------------------------------------------------------- model


@dataclass
class Plot:
    """One plotly figure (a dict with ``data`` and ``layout``; arrays as numpy) in a div."""

    id: str
    fig: dict[str, Any]
    wide: bool = False
    note: str = ""


@dataclass
class Section:
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


def _lab(name: str, units: Mapping[str, str]) -> str:
    return esc(style.label(name, style.unit_of(name, units)))


def _every(n: int, cap: int) -> np.ndarray:
    """Indices of an even choice of at most ``cap`` of ``n`` points, first and last kept."""
    if n <= cap:
        return np.arange(n)
    idx = np.unique(np.round(np.linspace(0, n - 1, cap)).astype(int))
    return idx


def _thin_note(n: int, kept: int, what: str) -> str:
    return f" ({kept} of {n} {what} shown)" if kept < n else ""


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


# ----------------------------------------------------------------------------- sections


def _meta(tree: Mapping[str, Any]) -> str:
    at = tree.get("attrs", {})
    rows = []
    for k in ("kind", "study", "seed", "complete", "schema_version", "n_designs", "n_members",
              "wall_time_s", "compile_time_s", "run_time_s", "jax_backend"):  # fmt: skip
        if k in at:
            v = at[k]
            v = f"{float(v):.3g}" if k.endswith("_s") else _s(v)
            rows.append((k, v))
    vers = at.get("versions")
    if isinstance(vers, Mapping):
        rows.append(("versions", ", ".join(f"{k} {v}" for k, v in vers.items())))
    return _table(["attribute", "value"], rows)


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


def _hints(tree: Mapping[str, Any]) -> tuple[dict[str, str], Any]:
    """(units, the study's figures module or None) from the registry, for the study and
    config the archive names; ({}, None) for an unknown study or config."""
    import importlib

    from designopt.studies import get

    at = tree.get("attrs", {})
    try:
        st = get(_s(at.get("study", "")))
        cfg = at["config_resolved"]
        cfg = json.loads(cfg) if isinstance(cfg, str | bytes) else cfg
        units = dict(st.units(st.settings.model_validate(cfg["study"])))
    except Exception:  # noqa: BLE001 - a report of an unknown study or config still draws
        return {}, None
    home = st.figures.__module__
    for name in (home + ".figures", home.rsplit(".", 1)[0] + ".figures"):
        try:
            return units, importlib.import_module(name)
        except ImportError:
            continue
    return units, None


def _same(y0: np.ndarray, y1: np.ndarray) -> int:
    """+1 when y1 equals y0, −1 when it equals −y0, 0 otherwise."""
    if y0.shape != y1.shape or not (np.all(np.isfinite(y0)) and np.all(np.isfinite(y1))):
        return 0
    tol = 1e-9 * max(float(np.max(np.abs(y0))), 1e-300)
    if np.allclose(y0, y1, rtol=0, atol=tol):
        return 1
    return -1 if np.allclose(y0, -y1, rtol=0, atol=tol) else 0


def merged(g: Mapping[str, Any], inds: Sequence[str]) -> list[tuple[str, str]]:
    """[(index drawn, its name with every index equal to it or to its negative)], as the
    static figures draw them (``eta = eta_cone = −f``)."""
    out: list[tuple[str, list[str]]] = []
    for k in sorted(inds, key=lambda k: k == "f"):
        y = _f(g[k])
        for rep, names in out:
            s = _same(_f(g[rep]), y)
            if s:
                names.append(k if s > 0 else f"−{k}")
                break
        else:
            out.append((k, [k]))
    return [(rep, " = ".join(names)) for rep, names in out]


def _index_names(g: Mapping[str, Any], skip: Sequence[str] = ()) -> list[str]:
    out = []
    for k, v in g.items():
        if k == "attrs" or k.endswith("_se") or k in skip or isinstance(v, Mapping):
            continue
        out.append(k)
    return sorted(out, key=lambda k: (k != "f", k))


def _best_run(br: Mapping[str, Any], ids: _Ids, units: dict[str, str], rates: set[str]) -> list[Plot]:  # fmt: skip
    it = _f(br["iteration"])
    keep = _every(len(it), MAX_LINE_POINTS)
    out = []
    inds = [k for k in _index_names(br, skip=("iteration",)) if _f(br[k]).shape == it.shape]
    for j, (k, name) in enumerate(merged(br, inds)):
        y = _f(br[k])
        se = br.get(k + "_se")
        col = PALETTE[j % len(PALETTE)]
        rate = k in rates
        yy = np.clip(y, 0, 1) if rate else y
        band, what = _value_band(it[keep], yy[keep], None if se is None else _f(se)[keep], rate, col)  # fmt: skip
        line = {"type": "scatter", "mode": "lines+markers" if len(keep) < 60 else "lines",
                "x": it[keep], "y": yy[keep], "name": k, "line": {"color": col, "width": 2},
                "marker": {"size": 4}}  # fmt: skip
        if se is not None:
            line["customdata"] = _f(se)[keep]
            line["hovertemplate"] = "iteration %{x}: %{y:.6~g} ± %{customdata:.2~g} (SE)<extra></extra>"  # fmt: skip
        t = f"{name} along the best run" + (f" (band: {what})" if what else "")
        t += _thin_note(len(it), len(keep), "iterations")
        lay = _layout(esc(t), _lab("iteration", {}), _lab(k, units), showlegend=False)
        _int_ticks(lay, len(keep))
        out.append(Plot(ids("best-" + k), {"data": [*band, line], "layout": lay}))
    return out


def _final_tables(tree: Mapping[str, Any], units: dict[str, str]) -> str:
    fin, prob = tree["final"], tree.get("problem", {})
    parts = []
    x = np.atleast_1d(_f(fin["x"])) if "x" in fin else None
    if x is not None:
        names = _names(prob["names"]) if "names" in prob else [f"x{i}" for i in range(len(x))]
        lo = _f(prob["lower"]) if "lower" in prob else np.full(len(x), np.nan)
        hi = _f(prob["upper"]) if "upper" in prob else np.full(len(x), np.nan)
        rows = [(n, f"{v:.6g}", f"{a:.6g}", f"{b:.6g}", style.unit_of(n, units))
                for n, v, a, b in zip(names, x, lo, hi, strict=False)]  # fmt: skip
        parts.append("<h3>Final design</h3>"
                     + _table(["variable", "value", "lower", "upper", "unit"], rows))  # fmt: skip
    rows = []
    for k in _index_names(fin, skip=("x",)):
        v = _f(fin[k])
        if v.ndim:
            continue
        se = float(_f(fin[k + "_se"])) if k + "_se" in fin else None
        rows.append((k, _num(float(v), se), style.unit_of(k, units)))
    at = fin.get("attrs", {})
    cap = f"stage: {_s(at['stage'])}" if "stage" in at else ""
    if "n_samples_used" in at:
        cap += f"; Monte-Carlo samples: {_s(at['n_samples_used'])}"
    parts.append("<h3>Final indices (± 1 SE)</h3>" + (f"<p class='note'>{esc(cap)}</p>" if cap else "")
                 + _table(["index", "value ± SE", "unit"], rows))  # fmt: skip
    return "".join(parts)


def _config(tree: Mapping[str, Any]) -> Section | None:
    at = tree.get("attrs", {})
    if "config_yaml" not in at and "config_resolved_yaml" not in at:
        return None
    sec = Section("config", "Config")

    def pre(text: Any, what: str) -> str:
        t = _s(text)
        cut = ""
        if len(t) > MAX_TEXT:
            cut = f"<p class='note'>{esc(what)}: first {MAX_TEXT} of {len(t)} characters shown</p>"
            t = t[:MAX_TEXT]
        return f"{cut}<pre>{esc(t)}</pre>"

    if "config_yaml" in at:
        sec.items.append("<h3>As given</h3>" + pre(at["config_yaml"], "config"))
    if "config_resolved_yaml" in at:
        sec.items.append("<details><summary>Resolved (every key after defaults and overrides)"
                         "</summary>" + pre(at["config_resolved_yaml"], "resolved config")
                         + "</details>")  # fmt: skip
    return sec


def _run_sections(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str],
                  rates: set[str]) -> list[Section]:  # fmt: skip
    out = []
    opt = tree.get("optimizer", {})
    best = None
    if "best_run" in tree:
        best = int(tree["best_run"].get("attrs", {}).get("run_index", -1))
        best = best if best >= 0 else None
    if "history" in opt:
        h = _f(opt["history"])
        if best is None and "best_f" in opt:
            best = int(np.argmin(_f(opt["best_f"])))
        sec = Section("convergence", "Convergence")
        sec.items.append(_convergence(h, best, ids, "best-so-far f per iteration",
                                      style.label("best f", style.unit_of("f", units))))  # fmt: skip
        if "history_v" in opt:
            sec.items.append("<p class='note'>Constrained: each run's best-so-far design and the "
                             "best run are chosen by Deb's rules (a smaller violation first, then "
                             "f), so a run's f can rise while its violation falls.</p>")  # fmt: skip
            sec.items.append(_convergence(_f(opt["history_v"]), best, ids,
                                          "constraint violation of the best-so-far design",
                                          style.label("violation", style.DIMENSIONLESS), "violation"))  # fmt: skip
        out.append(sec)
    if "best_run" in tree:
        sec = Section("best-run", "The best run's indices")
        sec.items += _best_run(tree["best_run"], ids, units, rates)
        out.append(sec)
    if "final" in tree:
        out.append(Section("final", "Final design", [_final_tables(tree, units)]))
    if "refine" in tree and "f0" in tree["refine"]:
        r = tree["refine"]
        rows = [(int(i), f"{a:.6g}", f"{b:.6g}", f"{a - b:.3g}")
                for i, a, b in zip(np.atleast_1d(r.get("run_index", np.arange(len(np.atleast_1d(r["f0"]))))),
                                   np.atleast_1d(_f(r["f0"])), np.atleast_1d(_f(r["f"])), strict=False)]  # fmt: skip
        at = r.get("attrs", {})
        cap = ", ".join(f"{k} {_s(at[k])}" for k in ("method", "steps", "learning_rate") if k in at)
        out.append(Section("refine", "Gradient polish", [f"<p class='note'>{esc(cap)}</p>"
                           + _table(["run", "f before", "f after", "gain"], rows)]))  # fmt: skip
    if "teleop" in tree:
        out += _teleop(tree["teleop"], ids)
    ck = tree.get("checkpoint")
    if isinstance(ck, Mapping) and "history" in ck:
        sec = Section("checkpoint", "Checkpoint (incomplete run)")
        sec.items.append(_convergence(_f(ck["history"]), None, ids,
                                      f"best-so-far f, {_s(ck.get('attrs', {}).get('done', '?'))} iterations done",
                                      style.label("best f", style.DIMENSIONLESS)))  # fmt: skip
        out.append(sec)
    return out


def _teleop(t: Mapping[str, Any], ids: _Ids) -> list[Section]:
    sec = Section("teleop", "Replayed trajectory")
    if "tip" in t and "command" in t:
        tip, cmd = np.atleast_2d(_f(t["tip"])), np.atleast_2d(_f(t["command"]))
        k = _every(len(tip), MAX_LINE_POINTS)
        data = []
        for nm, p, c, dash in (("commanded", cmd, PALETTE[0], "solid"), ("achieved", tip, PALETTE[3], "dash")):  # fmt: skip
            data.append({"type": "scatter3d", "mode": "lines", "x": p[k, 0], "y": p[k, 1],
                         "z": p[k, 2], "name": nm, "line": {"color": c, "width": 4, "dash": dash}})  # fmt: skip
        scene = {a: {"title": {"text": esc(style.label(a, "mm"))}} for a in ("xaxis", "yaxis", "zaxis")}  # fmt: skip
        sec.items.append(Plot(ids("teleop-path"), {"data": data, "layout": _layout(
            "slave tip path" + _thin_note(len(tip), len(k), "samples"), scene=scene | {"aspectmode": "data"})}, wide=True))  # fmt: skip
    if "t" in t and "error" in t:
        tt, err = _f(t["t"]), _f(t["error"])
        k = _every(len(tt), MAX_LINE_POINTS)
        sec.items.append(Plot(ids("teleop-error"), {"data": [
            {"type": "scatter", "mode": "lines", "x": tt[k], "y": err[k], "name": "error",
             "line": {"color": PALETTE[3]}}],
            "layout": _layout("tracking error", esc(style.label("t", "s")),
                              esc(style.label("error", "mm")), showlegend=False)}))  # fmt: skip
    return [sec] if sec.items else []


# ----------------------------------------------------------------------------- front


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


def _front(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str]) -> list[Section]:
    fr = tree["front"]
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
    inds = [k for k in _index_names(fr, skip=("x", "f", "ambiguous", "hypervolume"))
            if _f(fr[k]).shape == (n,)]  # fmt: skip
    pairs = _pairs(fr["ambiguous"], n) if "ambiguous" in fr else np.zeros((0, 2), int)
    amb_count = np.bincount(pairs.ravel(), minlength=n) if len(pairs) else np.zeros(n, int)
    keep = _every(n, MAX_MARKERS)
    # hover: design number, variables, indices ± SE, ambiguity
    cd = [np.arange(n)[:, None].astype(float), X, amb_count[:, None].astype(float)]
    tpl = ["<b>design %{customdata[0]}</b>"]
    c = 1
    for j, v in enumerate(vnames[: X.shape[1]]):
        tpl.append(f"{esc(v)} = %{{customdata[{c + j}]:.5~g}} {esc(style.unit_of(v, units))}")
    c += X.shape[1]
    tpl.append(f"in %{{customdata[{c}]}} ambiguous pairs")
    c += 1
    for k in inds:
        se = _f(fr[k + "_se"]) if k + "_se" in fr else np.full(n, np.nan)
        cd += [_f(fr[k])[:, None], se[:, None]]
        tpl.append(f"{esc(k)} = %{{customdata[{c}]:.5~g}} ± %{{customdata[{c + 1}]:.2~g}} "
                   f"{esc(style.unit_of(k, units))}")  # fmt: skip
        c += 2
    custom = np.concatenate(cd, axis=1)[keep]
    hover = "<br>".join(tpl) + "<extra></extra>"
    amb = amb_count[keep] > 0
    colors = np.where(amb, PALETTE[1], PALETTE[0])
    symbols = ["diamond" if a else "circle" for a in amb]
    axl = [esc(style.label(f"{k} ({s})", style.unit_of(k, units))) for k, s in zip(names, senses, strict=True)]  # fmt: skip
    title = (f"Pareto front: {n} designs{_thin_note(n, len(keep), 'designs')}; bars ± 2 SE; "
             f"orange diamonds: in a pair whose order is within 2 SE ({len(pairs)} pairs)")  # fmt: skip
    sec = Section("front", "Pareto front")
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
    sec.items.append("<p class='note'>Values are the indices themselves (a <i>max</i> objective "
                     "is shown as its index, not negated). Two designs form an <i>ambiguous</i> "
                     "pair when their order in some objective is within 2 standard errors: "
                     "the Monte-Carlo noise could swap them, so neither is known to be better "
                     "there.</p>" + _table(["objective", "sense"], rows))  # fmt: skip
    hv_tree = fr if "hypervolume" in fr else tree.get("optimizer", {})
    if "hypervolume" in hv_tree:
        hv = _f(hv_tree["hypervolume"])
        ref = fr.get("attrs", {}).get("reference")
        t = "hypervolume per iteration" + (f" (reference point {np.round(_f(ref), 6).tolist()})" if ref is not None else "")  # fmt: skip
        if hv.ndim == 2:
            p = _convergence(
                hv, int(np.argmax(hv[:, -1])), ids, t, "hypervolume [-]", "hypervolume"
            )
        else:
            p = Plot(ids("hv"), {"data": [{"type": "scatter", "mode": "lines", "x": np.arange(len(hv)), "y": hv}],
                                 "layout": _layout(esc(t), _lab("iteration", {}), "hypervolume [-]")})  # fmt: skip
        sec.items.append(p)
    return [sec]


# ------------------------------------------------------------------------------- scan


def _scan(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str], mod: Any) -> list[Section]:
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
    sec = Section("scan", f"Scan over {', '.join(varied)}")
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


# ------------------------------------------------------------------------------ sweep


def _sweep(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str]) -> list[Section]:
    mem = {k: v for k, v in tree["members"].items() if k != "attrs" and isinstance(v, Mapping)}
    labels = []
    for k, m in mem.items():
        ov = m.get("attrs", {}).get("overrides", {})
        lab = ", ".join(f"{kk.split('.')[-1]}={vv}" for kk, vv in ov.items()) if isinstance(ov, Mapping) else _s(ov)  # fmt: skip
        labels.append(f"[{k}] {lab}")
    f = np.array([float(_f(m["final"]["f"])) if "final" in m else np.nan for m in mem.values()])
    se = np.array([float(_f(m["final"]["f_se"])) if "final" in m and "f_se" in m["final"] else np.nan
                   for m in mem.values()])  # fmt: skip
    sec = Section("sweep", f"Sweep: {len(mem)} members")
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


# ------------------------------------------------------------------------------ bench


def _floored(values: list[np.ndarray]) -> tuple[list[np.ndarray], float | None]:
    v = np.concatenate([np.ravel(x) for x in values]) if values else np.zeros(0)
    pos = v[v > 0]
    if (v <= 0).any() and pos.size:
        fl = float(pos.min()) / 10
        return [np.maximum(x, fl) for x in values], fl
    return values, None


def _bench(tree: Mapping[str, Any], ids: _Ids) -> list[Section]:
    out = []
    for case, g in tree["bench"].items():
        if case == "attrs" or not isinstance(g, Mapping):
            continue
        ents = {v: e for v, e in g.items() if v != "attrs" and isinstance(e, Mapping)}
        sec = Section(f"bench-{case}", f"Benchmark: {case}")
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


# --------------------------------------------------------------------------------- ik


def _ik_units(text: Any) -> dict[str, str]:
    """``"q1, q2 rad; q3 mm; pos_err mm"`` → {q1: rad, q2: rad, q3: mm, pos_err: mm}."""
    out: dict[str, str] = {}
    for part in _s(text).split(";"):
        bits = part.strip().rsplit(" ", 1)
        if len(bits) == 2:
            for nm in bits[0].split(","):
                out[nm.strip()] = bits[1].strip()
    return out


def _ik(tree: Mapping[str, Any], ids: _Ids) -> list[Section]:
    from designopt import ikreport

    ik = tree["ik"]
    ok = np.asarray(ik["success"], bool)
    n, k = len(ok), int(ok.sum())
    p = k / max(n, 1)
    lo, hi = style.wilson(np.array([p]), n)
    u = _ik_units(ik.get("attrs", {}).get("units", ""))
    sec = Section("ik", "Inverse kinematics")
    sec.items.append("<ul>" + "".join(f"<li>{esc(x)}</li>" for x in ikreport.summary_lines(ik)) + "</ul>")  # fmt: skip
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


# ------------------------------------------------------------------------------ cloud


def _cloud(cloud: Mapping[str, Any], ids: _Ids) -> Section:
    xyz = np.asarray(cloud["xyz"], np.float64).reshape(-1, 3)
    val = np.asarray(cloud["value"], np.float64).ravel()
    if len(val) != len(xyz):
        raise ValueError(f"cloud: {len(xyz)} points but {len(val)} values")
    lab, unit = _s(cloud.get("label", "value")), _s(cloud.get("unit", style.DIMENSIONLESS))
    xu = _s(cloud.get("xyz_unit", "mm"))
    n = len(xyz)
    keep = np.sort(np.random.default_rng(0).choice(n, MAX_CLOUD, replace=False)) if n > MAX_CLOUD else np.arange(n)  # fmt: skip
    fin = np.isfinite(val[keep])
    tr = {"type": "scatter3d", "mode": "markers", "x": xyz[keep, 0], "y": xyz[keep, 1],
          "z": xyz[keep, 2], "name": esc(lab),
          "marker": {"size": 2, "color": np.where(fin, val[keep], np.nan), "colorscale": "Viridis",
                     "opacity": 0.85, "colorbar": {"title": {"text": esc(style.label(lab, unit))}}},
          "hovertemplate": f"x %{{x:.4~g}}, y %{{y:.4~g}}, z %{{z:.4~g}} {esc(xu)}<br>{esc(lab)} = %{{marker.color:.4~g}} {esc(unit)}<extra></extra>"}  # fmt: skip
    scene = {a: {"title": {"text": esc(style.label(a[0], xu))}} for a in ("xaxis", "yaxis", "zaxis")}  # fmt: skip
    title = f"{lab} over the workspace: {n} points" + (
        f" ({len(keep)} shown)" if len(keep) < n else ""
    )
    lay = _layout(esc(title), scene=scene | {"aspectmode": "data"}, height=620)
    sec = Section("cloud", "Workspace")
    sec.items.append(Plot(ids("cloud"), {"data": [tr], "layout": lay}, wide=True))
    return sec


# ---------------------------------------------------------------------- contents, budget


def _contents(tree: Mapping[str, Any]) -> Section:
    rows: list[tuple[str, str, str]] = []

    def walk(g: Mapping[str, Any], pre: str) -> None:
        for k, v in g.items():
            if k == "attrs":
                continue
            if isinstance(v, Mapping):
                walk(v, f"{pre}{k}/")
            elif len(rows) < 2000:
                a = np.asarray(v)
                rows.append((pre + k, str(a.shape), str(a.dtype)))

    walk(tree, "")
    body = _table(["dataset", "shape", "dtype"], rows, "contents")
    return Section("contents", "Archive contents", [f"<details><summary>{len(rows)} datasets"
                                                    f"</summary>{body}</details>"])  # fmt: skip


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


def budget(sections: Sequence[Section], max_values: int = MAX_VALUES) -> int:
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


# ------------------------------------------------------------------------------- page


def sections(tree: Mapping[str, Any], *, cloud: Mapping[str, Any] | None = None,
             units: Mapping[str, str] | None = None) -> list[Section]:  # fmt: skip
    """The page's sections for an archive (``archive.read``'s nested dict), before the
    size budget; ``units`` ({name: unit}) adds to or overrides the study's own."""
    hint_units, mod = _hints(tree)
    u = {k: v for k, v in hint_units.items() if not k.startswith("__")} | dict(units or {})
    rates = set(getattr(mod, "RATES", ()))
    ids = _Ids()
    kind = _s(tree.get("attrs", {}).get("kind", ""))
    out: list[Section] = []
    if "front" in tree:
        out += _front(tree, ids, u)
    if kind == "run" or "optimizer" in tree or "teleop" in tree or "checkpoint" in tree:
        out += _run_sections(tree, ids, u, rates)
    if "scan" in tree:
        out += _scan(tree, ids, u, mod)
    if "members" in tree:
        out += _sweep(tree, ids, u)
    if "bench" in tree:
        out += _bench(tree, ids)
    if "ik" in tree:
        out += _ik(tree, ids)
    if cloud is not None:
        out.append(_cloud(cloud, ids))
    cfg = _config(tree)
    if cfg is not None:
        out.append(cfg)
    out.append(_contents(tree))
    return out


def _jsonable(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        if o.dtype.kind in "biuf":
            a = np.ascontiguousarray(o, np.float64)
            spec = {"dtype": "f8", "bdata": base64.b64encode(a.tobytes()).decode("ascii")}
            if a.ndim > 1:
                spec["shape"] = ", ".join(str(s) for s in a.shape)
            return spec
        return [_s(v) for v in o.ravel()]
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON: {type(o).__name__}")


def _script_json(obj: Any) -> str:
    """JSON safe inside a <script> element (no '<', '>', '&' and line separators)."""
    s = json.dumps(obj, default=_jsonable, ensure_ascii=True, allow_nan=False,
                   separators=(",", ":"))  # fmt: skip
    return s.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def _clean(o: Any) -> Any:
    """NaN/inf scalars → None (JSON null); arrays are kept (base64 keeps NaN)."""
    if isinstance(o, dict):
        return {k: _clean(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_clean(v) for v in o]
    if isinstance(o, float | np.floating) and not np.isfinite(o):
        return None
    return o


CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:0;color:#222;background:#f4f5f7}
header{background:#263238;color:#fff;padding:14px 24px}
header h1{margin:0 0 4px;font-size:20px}header p{margin:0;font-size:13px;opacity:.85}
nav{padding:8px 24px;background:#eceff1;font-size:13px;position:sticky;top:0;z-index:5;border-bottom:1px solid #d0d4d8}
nav a{margin-right:14px;color:#1565c0;text-decoration:none}
main{padding:8px 24px 40px;max-width:1500px}
section{background:#fff;border:1px solid #dde1e5;border-radius:6px;margin:16px 0;padding:8px 16px 16px}
h2{font-size:17px;margin:8px 0}h3{font-size:14px;margin:12px 0 6px}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(440px,1fr));gap:12px}
figure{margin:0;min-width:0;border:1px solid #eceff1;border-radius:4px}
figure.wide{grid-column:1/-1}figure.wide .plot{height:460px}
figcaption{font-size:12.5px;padding:6px 10px 0;color:#333}
.plot{height:360px;min-width:0}
table{border-collapse:collapse;font-size:13px;margin:6px 0}
td,th{border:1px solid #dde1e5;padding:3px 8px;text-align:left}th{background:#f0f2f4}
td{font-variant-numeric:tabular-nums}
pre{background:#f7f7f9;border:1px solid #e1e4e8;padding:8px;overflow:auto;max-height:420px;font-size:12px}
.note{color:#555;font-size:12.5px}.banner{background:#fff3cd;border:1px solid #e0c36a;padding:8px 12px;border-radius:4px}
"""

JS_DRAW = """
(function(){
  var figs = JSON.parse(document.getElementById('designopt-figures').textContent);
  var ids = Object.keys(figs), jobs = [];
  ids.forEach(function(id){
    var f = figs[id], el = document.getElementById(id);
    try {
      jobs.push(Plotly.newPlot(el, f.data, f.layout, f.config).catch(function(e){
        console.error('plot ' + id + ' failed: ' + e); el.textContent = 'plot failed: ' + e; }));
    } catch (e) { console.error('plot ' + id + ' failed: ' + e); el.textContent = 'plot failed: ' + e; }
  });
  Promise.all(jobs).then(function(){ document.body.setAttribute('data-plots-drawn', String(ids.length)); });
})();
"""


def _plotly_js() -> str:
    from plotly.offline import get_plotlyjs

    return get_plotlyjs()


def page(tree: Mapping[str, Any], *, title: str | None = None,
         cloud: Mapping[str, Any] | None = None, units: Mapping[str, str] | None = None) -> str:  # fmt: skip
    """One self-contained HTML document showing the archive ``tree`` (as
    ``designopt.archive.read`` returns it), with plotly.js embedded once; ``cloud``
    ({"xyz": (n, 3), "value": (n,), "label": str, "unit": str, optional "xyz_unit"})
    adds a 3-D point cloud; ``units`` ({name: unit}) labels axes beyond the study's own."""
    secs = sections(tree, cloud=cloud, units=units)
    n_values = budget(secs)
    at = tree.get("attrs", {})
    kind, study = _s(at.get("kind", "archive")), _s(at.get("study", ""))
    title = title or f"designopt {kind}" + (f": {study}" if study else "")
    figs: dict[str, Any] = {}
    body = []
    for s in secs:
        chunks, grid = [], []
        for it in s.items:
            if isinstance(it, Plot):
                lay = dict(it.fig["layout"])
                cap = lay.pop("title", {}).get("text", "")  # a caption wraps; a plot title
                lay["margin"] = lay.get("margin", {}) | {"t": 34}  # would run under the modebar
                if not it.wide and lay.get("showlegend") is not False and "scene" not in lay:
                    # a small plot keeps its width: the legend goes in a row above it
                    lay["legend"] = {"orientation": "h", "x": 0, "y": 1.0, "xanchor": "left",
                                     "yanchor": "bottom", "font": {"size": 10}}  # fmt: skip
                h = lay.pop("height", None)
                style_h = f' style="height:{int(h)}px"' if h else ""
                figs[it.id] = _clean({"data": it.fig["data"], "layout": lay, "config": CONFIG})
                grid.append(f'<figure class="{"wide" if it.wide else ""}"><figcaption>{cap}</figcaption>'
                            f'<div id="{esc(it.id)}" class="plot"{style_h}></div></figure>')  # fmt: skip
            else:
                if grid:
                    chunks.append(f"<div class='grid'>{''.join(grid)}</div>")
                    grid = []
                chunks.append(it)
        if grid:
            chunks.append(f"<div class='grid'>{''.join(grid)}</div>")
        body.append(f'<section id="{esc(s.id)}"><h2>{esc(s.title)}</h2>{"".join(chunks)}</section>')
    nav = "".join(f'<a href="#{esc(s.id)}">{esc(s.title)}</a>' for s in secs)
    banner = ""
    if at.get("complete") is False or (
        isinstance(at.get("complete"), np.bool_) and not at["complete"]
    ):
        banner = "<p class='banner'>This archive is a checkpoint (complete = false): a run in progress or interrupted.</p>"  # fmt: skip
    sub = f"{len(figs)} plots, {n_values} plotted numbers; offline page (plotly.js embedded)"
    return (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<meta name='generator' content='designopt'><title>{esc(title)}</title>"
        f"<style>{CSS}</style><script>{_plotly_js()}</script></head><body>"
        f"<header><h1>{esc(title)}</h1><p>{esc(sub)}</p></header><nav>{nav}</nav><main>{banner}"
        f"<section id='about'><h2>Archive</h2>{_meta(tree)}</section>{''.join(body)}</main>"
        f"<script type='application/json' id='designopt-figures'>{_script_json(figs)}</script>"
        f"<script>{JS_DRAW}</script></body></html>\n"
    )


def write(tree: Mapping[str, Any], path: str | Path, **kw: Any) -> Path:
    """Write :func:`page` of ``tree`` to ``path`` atomically through the one writer
    (``designopt.output``); ``kw`` as for :func:`page`. Returns the path."""
    from designopt import output

    text = page(tree, **kw)
    return output.write_file(path, text.encode("utf-8"), "HTML report")
