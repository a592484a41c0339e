"""The page: its sections by archive kind, the archive-wide parts (attrs, config,
contents), the plots' JSON, the CSS and drawing script, and the writer."""

from __future__ import annotations

import base64
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from designopt.figures.hints import NONE, Hints
from designopt.figures.html.bench import _bench, _cloud, _ik
from designopt.figures.html.budget import budget
from designopt.figures.html.front import _front
from designopt.figures.html.model import CONFIG, MAX_TEXT, PageSection, Plot, _Ids, _s, _table, esc
from designopt.figures.html.robot import robot_section
from designopt.figures.html.run import _run_sections
from designopt.figures.html.scan import _scan, _sweep


def sections(tree: Mapping[str, Any], *, cloud: Mapping[str, Any] | None = None,
             units: Mapping[str, str] | None = None, hints: Hints = NONE,
             robot: Mapping[str, Any] | None = None) -> list[PageSection]:  # fmt: skip
    """The page's sections for an archive (``archive.read``'s nested dict), before the
    size budget; ``hints`` the study's (units, rates), which ``units`` ({name: unit})
    adds to or overrides; ``robot`` ({"view": View, "front": FrontView}, either
    optional; ``designopt.figures.html.robot``) adds the robot's section."""
    mod = hints
    u = dict(hints.units) | dict(units or {})
    rates = set(getattr(mod, "RATES", ()))
    ids = _Ids()
    kind = _s(tree.get("attrs", {}).get("kind", ""))
    out: list[PageSection] = []
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
    if robot and (robot.get("view") is not None or robot.get("front") is not None):
        out.append(robot_section(robot.get("view"), robot.get("front"), ids))
    if robot and robot.get("plan"):
        out.append(_plan(robot["plan"]))
    cfg = _config(tree)
    if cfg is not None:
        out.append(cfg)
    out.append(_contents(tree))
    return out


def _plan(plan: Mapping[str, Any]) -> PageSection:
    """The plan sheet (a planning run's ``plan.png``, docs/figures.md): the image, then
    its text rows (the distances, angles, indices, constraints and the final stage's
    verdict) as a list that reads without the image."""
    img = base64.b64encode(bytes(plan["png"])).decode("ascii")
    rows = "".join(f"<li>{esc(str(r))}</li>" for r in plan.get("rows", []))
    body = (f'<img class="plan" alt="{esc(str(plan.get("title", "the plan sheet")))}: the patient '
            f'from above and from the side, the incision points, the bases and the distances" '
            f'src="data:image/png;base64,{img}" style="max-width:100%;height:auto">'
            + (f"<ul>{rows}</ul>" if rows else ""))  # fmt: skip
    return PageSection("plan", "Port plan", [body])


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


def _config(tree: Mapping[str, Any]) -> PageSection | None:
    at = tree.get("attrs", {})
    if "config_yaml" not in at and "config_resolved_yaml" not in at:
        return None
    sec = PageSection("config", "Config")

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


def _contents(tree: Mapping[str, Any]) -> PageSection:
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
    return PageSection("contents", "Archive contents", [f"<details><summary>{len(rows)} datasets"
                                                    f"</summary>{body}</details>"])  # fmt: skip


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
  function dec(o){  // base64 typed arrays (as the plots' JSON holds them) to arrays
    if (o === null || typeof o !== 'object') return o;
    if (Array.isArray(o)) return o.map(dec);
    if (typeof o.bdata === 'string' && o.dtype === 'f8') {
      var b = atob(o.bdata), u = new Uint8Array(b.length);
      for (var i = 0; i < b.length; i++) u[i] = b.charCodeAt(i);
      return Array.from(new Float64Array(u.buffer));
    }
    var r = {}; Object.keys(o).forEach(function(k){ r[k] = dec(o[k]); }); return r;
  }
  function link(el, f){  // hovering or clicking a point of f.link.source restyles el
    var src = document.getElementById(f.link.source), ds = dec(f.link.designs), cur = -1;
    function show(ev){
      if (!ev || !ev.points || !ev.points.length) return;
      var c = ev.points[0].customdata, i = Array.isArray(c) ? c[0] : c;
      if (i === undefined || i === null || !ds[i] || i === cur) return;
      cur = i;
      Plotly.restyle(el, ds[i].data, f.link.traces).then(function(){
        return Plotly.relayout(el, ds[i].layout || {}); }).then(function(){
        el.setAttribute('data-design', String(i)); });
    }
    src.on('plotly_hover', show); src.on('plotly_click', show);
  }
  ids.forEach(function(id){
    var f = figs[id], el = document.getElementById(id);
    try {
      jobs.push(Plotly.newPlot(el, f.data, f.layout, f.config).then(function(){
        if (f.frames) return Plotly.addFrames(el, dec(f.frames));
      }).catch(function(e){
        console.error('plot ' + id + ' failed: ' + e); el.textContent = 'plot failed: ' + e; }));
    } catch (e) { console.error('plot ' + id + ' failed: ' + e); el.textContent = 'plot failed: ' + e; }
  });
  Promise.all(jobs).then(function(){
    ids.forEach(function(id){ if (figs[id].link) link(document.getElementById(id), figs[id]); });
    document.body.setAttribute('data-plots-drawn', String(ids.length));
  });
})();
"""


def _plotly_js() -> str:
    from plotly.offline import get_plotlyjs

    return get_plotlyjs()


def page(tree: Mapping[str, Any], *, title: str | None = None,
         cloud: Mapping[str, Any] | None = None, units: Mapping[str, str] | None = None,
         hints: Hints = NONE, robot: Mapping[str, Any] | None = None) -> str:  # fmt: skip
    """One self-contained HTML document showing the archive ``tree`` (as
    ``designopt.io.archive.read`` returns it), with plotly.js embedded once; ``cloud``
    ({"xyz": (n, 3), "value": (n,), "label": str, "unit": str, optional "xyz_unit"})
    adds a 3-D point cloud; ``hints`` the study's units and rates (``Hints``); ``units``
    ({name: unit}) labels axes beyond them; ``robot`` the robot's views (:func:`sections`)."""
    secs = sections(tree, cloud=cloud, units=units, hints=hints, robot=robot)
    at = tree.get("attrs", {})
    kind, study = _s(at.get("kind", "archive")), _s(at.get("study", ""))
    title = title or f"designopt {kind}" + (f": {study}" if study else "")
    banner = ""
    if at.get("complete") is False or (
        isinstance(at.get("complete"), np.bool_) and not at["complete"]
    ):
        banner = "<p class='banner'>This archive is a checkpoint (complete = false): a run in progress or interrupted.</p>"  # fmt: skip
    about = f"<section id='about'><h2>Archive</h2>{_meta(tree)}</section>"
    return document(secs, title, about=banner + about)


def document(secs: list[PageSection], title: str, about: str = "") -> str:
    """The HTML document of ``secs`` (thinned to the size budget first): plotly.js, the
    sections with their plots' JSON, the drawing script; ``about`` (HTML, escaped by the
    caller) before the sections."""
    n_values = budget(secs)
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
                extra = {k: it.fig[k] for k in ("frames", "link") if k in it.fig}
                figs[it.id] = _clean(
                    {"data": it.fig["data"], "layout": lay, "config": CONFIG} | extra
                )
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
    sub = f"{len(figs)} plots, {n_values} plotted numbers; offline page (plotly.js embedded)"
    return (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<meta name='generator' content='designopt'><title>{esc(title)}</title>"
        f"<style>{CSS}</style><script>{_plotly_js()}</script></head><body>"
        f"<header><h1>{esc(title)}</h1><p>{esc(sub)}</p></header><nav>{nav}</nav><main>"
        f"{about}{''.join(body)}</main>"
        f"<script type='application/json' id='designopt-figures'>{_script_json(figs)}</script>"
        f"<script>{JS_DRAW}</script></body></html>\n"
    )


def write(tree: Mapping[str, Any], path: str | Path, **kw: Any) -> Path:
    """Write :func:`page` of ``tree`` to ``path`` atomically through the one writer
    (``designopt.io.writer``); ``kw`` as for :func:`page`. Returns the path."""
    from designopt.io import writer

    text = page(tree, **kw)
    return writer.write_file(path, text.encode("utf-8"), "HTML report")
