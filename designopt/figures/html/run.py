"""The sections of a run: convergence, the best run's indices, the final design, the
gradient polish, a replayed trajectory (``teleop/``) and a checkpoint."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from designopt.figures import style
from designopt.figures.html.model import (
    MAX_LINE_POINTS,
    PALETTE,
    PageSection,
    Plot,
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
    _convergence,
    _index_names,
    _int_ticks,
    _lab,
    _layout,
    _value_band,
    merged,
)
from designopt.results.base import SEARCH_LABEL, value_text


def _run_sections(tree: Mapping[str, Any], ids: _Ids, units: dict[str, str],
                  rates: set[str]) -> list[PageSection]:  # fmt: skip
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
        sec = PageSection("convergence", "Convergence")
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
        sec = PageSection("best-run", f"The best run's indices ({SEARCH_LABEL})")
        sec.items += _best_run(tree["best_run"], ids, units, rates)
        out.append(sec)
    if "final" in tree:
        out.append(PageSection("final", "Final design", [_final_tables(tree, units)]))
    if isinstance(tree.get("runs"), Mapping) and "agree" in tree["runs"]:
        out.append(_runs(tree, units))
    if isinstance(tree.get("verdict"), Mapping) and "verdict" in tree["verdict"]:
        out.append(_verdict(tree, units))
    r = tree.get("refine")
    if isinstance(r, Mapping) and ("f0" in r or "d0" in r):
        k0, k1, what = ("f0", "f", "f") if "f0" in r else ("d0", "d", "distance to the ideal")
        n = len(np.atleast_1d(r[k0]))
        rows = [(int(i), f"{a:.6g}", f"{b:.6g}", f"{a - b:.3g}")
                for i, a, b in zip(np.atleast_1d(r.get("run_index", np.arange(n))),
                                   np.atleast_1d(_f(r[k0])), np.atleast_1d(_f(r[k1])), strict=False)]  # fmt: skip
        at = r.get("attrs", {})
        cap = ", ".join(f"{k} {_s(at[k])}" for k in ("method", "steps", "learning_rate", "step",
                                                      "first_step", "tol", "max_iterations",
                                                      "iterations", "evaluations") if k in at)  # fmt: skip
        if any(k in at for k in ("step", "first_step", "tol")):
            cap += " (steps: shares of each variable's box width)"
        if "d0" in r:
            cap += (f"; each run's recommended design, {SEARCH_LABEL}, by its distance to the "
                    "ideal point (objectives scaled to [0, 1] by the runs' non-dominated final "
                    "populations)")  # fmt: skip
        title = "Compass polish" if _s(at.get("method", "")) == "compass" else "Gradient polish"
        out.append(PageSection("refine", title, [f"<p class='note'>{esc(cap)}</p>"
                           + _table(["run", f"{what} before", f"{what} after", "gain"], rows)]))  # fmt: skip
    if "teleop" in tree:
        out += _teleop(tree["teleop"], ids)
    ck = tree.get("checkpoint")
    if isinstance(ck, Mapping) and "history" in ck:
        sec = PageSection("checkpoint", "Checkpoint (incomplete run)")
        sec.items.append(_convergence(_f(ck["history"]), None, ids,
                                      f"best-so-far f, {_s(ck.get('attrs', {}).get('done', '?'))} iterations done",
                                      style.label("best f", style.DIMENSIONLESS)))  # fmt: skip
        out.append(sec)
    return out


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


def _attr_obj(v: Any) -> Any:
    """An attr as archived: a JSON text (read back from a file) or the value itself."""
    if isinstance(v, str | bytes):
        try:
            return json.loads(v)
        except ValueError:
            return v
    return v


def placement_table(g: Mapping[str, Any], front: bool = False) -> str:
    """The study's placement of a design in the world (the group's attr ``placement``:
    e.g. the serial study's ports and bases), one row per arm (a front's group: per
    design and arm), its columns headed by the study (``placement_columns``) under each
    array's title (``placement_titles``); "" when the group has none."""
    at = g.get("attrs", {})
    names = [_s(k) for k in (_attr_obj(at.get("placement")) or [])]
    names = [k for k in names if k in g]
    if not names:
        return ""
    cols = _attr_obj(at.get("placement_columns")) or {}
    titles = _attr_obj(at.get("placement_titles")) or {}
    arrays = {}
    for k in names:
        a = _f(g[k])
        a = a if front else a[None]  # (P, A, ...)
        arrays[k] = a.reshape(a.shape[0], a.shape[1], -1)
    P, A = arrays[names[0]].shape[:2]
    head = (["design"] if front else []) + ["arm"]
    for k in names:
        c = [_s(x) for x in cols.get(k, [])] or [str(j) for j in range(arrays[k].shape[-1])]
        head += [f"{_s(titles.get(k, k))}: {h}" for h in c]
    rows = [([str(d)] if front else []) + [str(a)]
            + [f"{v:.6g}" for k in names for v in arrays[k][d, a]]
            for d in range(P) for a in range(A)]  # fmt: skip
    return _table(head, rows)


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
    srch = tree.get("best_run", {}).get("final")  # the search's values of the final design
    srch = srch if isinstance(srch, Mapping) else None

    def cell(g: Mapping[str, Any], k: str) -> str:
        if k not in g:
            return "-"
        v = float(_f(g[k]))
        if np.isnan(v):  # n/a: a ratio over too few items, with its counts
            n, of = (float(_f(g[k + s])) if k + s in g else None for s in ("_n", "_of"))
            return value_text(v, n=n, of=of)
        return _num(v, float(_f(g[k + "_se"])) if k + "_se" in g else None)

    rows = []
    for k in _index_names(fin, skip=("x",)):
        if _f(fin[k]).ndim:
            continue
        rows.append((k, cell(fin, k), *([cell(srch, k)] if srch else []), style.unit_of(k, units)))
    placed = placement_table(fin)
    if placed:  # where the design puts the robot, in numbers (e.g. the ports and bases)
        parts.append("<h3>In the world frame</h3><p class='note'>each arm's placement as the "
                     "study gives it (lengths in the chain's unit, angles in degrees)</p>"
                     + placed)  # fmt: skip
    at = fin.get("attrs", {})
    cover = tree.get("targets", {}).get("attrs", {}).get("lines", [])  # a task's IK coverage
    parts.append(notes_html(cover, at.get("warnings", [])))
    cap = f"stage: {_s(at['stage'])}" if "stage" in at else ""
    fresh = _s(at.get("samples", "")) == "fresh"
    if "n_samples_used" in at:
        cap += (f"; Monte-Carlo samples: {_s(at['n_samples_used'])} per design"
                + (" on a fresh stream the search never saw (the quoted values)" if fresh else ""))  # fmt: skip
    head = ["index", "value ± SE" + (" (fresh samples)" if fresh else "")]
    if srch:
        n = _s(srch.get("attrs", {}).get("n_samples", "?"))
        head.append(f"{SEARCH_LABEL} ({n} per design)")
        cap += ("; the search's own values of the design are biased by its choice among designs "
                "scored on the same samples")  # fmt: skip
        fid = srch.get("attrs", {}).get("fidelity")
        if fid:  # optimizer.fidelity: the search scored with other study settings
            fid = json.loads(fid) if isinstance(fid, str) else dict(fid)
            cap += ("; the search scored with optimizer.fidelity ("
                    + ", ".join(f"{k} = {v}" for k, v in fid.items()) + "), the quoted values "
                    "with the study's own settings")  # fmt: skip
    parts.append("<h3>Final indices (± 1 SE)</h3>" + (f"<p class='note'>{esc(cap)}</p>" if cap else "")
                 + _table([*head, "unit"], rows))  # fmt: skip
    return "".join(parts)


def _texts(v: Any) -> list[str]:
    """An attr holding text lines (a list, one string, or JSON of a list) as a list."""
    if v is None:
        return []
    if isinstance(v, bytes):
        v = v.decode()
    if isinstance(v, str):
        try:
            v = json.loads(v)
        except ValueError:
            return [v]
        return [str(v)] if isinstance(v, str) else [_s(w) for w in v]
    return [_s(w) for w in np.atleast_1d(np.asarray(v, dtype=object)).tolist()] if len(v) else []


def notes_html(coverage: Any, warnings: Any) -> str:
    """The IK coverage figure's lines (a task's) and the ``warning:`` lines of a scored
    design (a run's final design, a front's designs) as the page shows them: what
    ``run`` and ``show`` print, on the page too."""
    cov, warns = _texts(coverage), _texts(warnings)
    out = ""
    if cov:
        out += "<h3>IK coverage</h3>" + "".join(f"<p class='note'>{esc(c)}</p>" for c in cov)
    if warns:
        out += "<h3>Warnings</h3><ul>" + "".join(f"<li>{esc(w)}</li>" for w in warns) + "</ul>"
    return out


def _runs(tree: Mapping[str, Any], units: dict[str, str]) -> PageSection:
    """Each run's design re-scored on one common fresh stream, whether it agrees with the
    reference run, and the flat directions (``runs``)."""
    g, prob = tree["runs"], tree.get("problem", {})
    at = g.get("attrs", {})
    objs = [_s(k) for k in (_attr_obj(at.get("objectives")) or ["f"])]
    X = np.atleast_2d(_f(g["x"]))
    names = _names(prob["names"]) if "names" in prob else [f"x{i}" for i in range(X.shape[1])]
    agree = np.asarray(_f(g["agree"])).astype(bool)
    ref = int(_f(at.get("reference", 0)))
    z = float(_f(at.get("z", 2.0)))
    rows = []
    for r in range(len(X)):
        vals = [_num(float(_f(g[k])[r]), float(_f(g[k + "_se"])[r]) if k + "_se" in g else None)
                for k in objs]  # fmt: skip
        tag = "reference" if r == ref else ("agrees" if agree[r] else "differs")
        rows.append((str(r), *(f"{v:.6g}" for v in X[r]), *vals, tag))
    head = ["run", *(style.label(n, style.unit_of(n, units)) for n in names),
            *(f"{k} ± SE" for k in objs), f"within {z:g} SE of run {ref}"]  # fmt: skip
    flat = [_s(k) for k in (_attr_obj(at.get("flat")) or [])]
    share = float(_f(at.get("flat_share", 0.1)))
    verdict = (f"The {len(X)} runs agree within {z:g} SE on {', '.join(objs)}." if agree.all()
               else f"Runs {', '.join(str(r) for r in np.flatnonzero(~agree))} differ from run "
                    f"{ref} by more than {z:g} SE on {', '.join(objs)}.")  # fmt: skip
    if agree.sum() >= 2:
        verdict += (f" Flat directions (the agreeing designs differ by more than {100 * share:.0f} % "
                    f"of the box): {', '.join(flat)}." if flat else
                    f" No flat direction: the agreeing designs lie within {100 * share:.0f} % of "
                    "the box in every variable.")  # fmt: skip
    note = (f"{_s(at.get('pick', 'each run'))}, re-scored on one common fresh stream "
            f"({_s(at.get('n_samples', '?'))} samples per design); a run agrees when every "
            f"objective is within {z:g} √(SE² + SE_ref²) of the reference run's.")  # fmt: skip
    return PageSection("runs", "Runs that agree", [f"<p class='note'>{esc(note)}</p>"
                       f"<p>{esc(verdict)}</p>" + _table(head, rows)])  # fmt: skip


def _verdict(tree: Mapping[str, Any], units: dict[str, str]) -> PageSection:
    """The final stage's verdict table (``verdict``): each candidate layout raced on the
    validation stream, its objectives ± their interval, the paired difference from the
    best ± SE, each share constraint's status, the samples it used and its verdict; then
    the race's one line (one recommendation, or a tied set and how its layouts differ)."""
    g, prob = tree["verdict"], tree.get("problem", {})
    at = g.get("attrs", {})
    objs = [_s(k) for k in (_attr_obj(at.get("objectives")) or ["f"])]
    cons = [_s(k) for k in (_attr_obj(at.get("constraints")) or [])]
    X = np.atleast_2d(_f(g["x"]))
    names = _names(prob["names"]) if "names" in prob else [f"x{i}" for i in range(X.shape[1])]
    mean, half = np.atleast_2d(_f(g["mean"])), np.atleast_2d(_f(g["half"]))
    diff, dse = np.atleast_2d(_f(g["diff"])), np.atleast_2d(_f(g["diff_se"]))
    verdict = [_s(v) for v in np.atleast_1d(g["verdict"])]
    status = np.asarray(g["status"]).reshape(len(X), -1) if cons else np.zeros((len(X), 0))
    ns = np.atleast_1d(_f(g["n_samples"]))
    settled = np.asarray(g.get("settled", np.ones(len(X))), bool).reshape(-1)
    verdict = [v + ("*" if v == "equivalent" and not settled[i] else "")
               for i, v in enumerate(verdict)]  # fmt: skip
    place = [k for k in _names(at.get("placement", []) or []) if k in g and np.ndim(g[k]) == 3
             and not k.endswith("_points")]  # fmt: skip
    rows = []
    for i in range(len(X)):
        where = "; ".join(f"{k} " + " ".join("(" + ", ".join(f"{v:.3f}" for v in p) + ")"
                                            for p in np.asarray(_f(g[k]))[i]) for k in place)  # fmt: skip
        rows.append((str(i), *(f"{v:.4g}" for v in X[i]),
                     *(f"{mean[i, j]:.4f} ± {half[i, j]:.4f}" for j in range(len(objs))),
                     *(f"{diff[i, j]:+.4f} ± {dse[i, j]:.4f}" for j in range(len(objs))),
                     *(_s(status[i, c]) for c in range(len(cons))), str(int(ns[i])),
                     verdict[i], *( [where] if place else [])))  # fmt: skip
    head = ["#", *(style.label(n, style.unit_of(n, units)) for n in names),
            *(f"{k} ± interval" for k in objs), *(f"Δ {k} from the best ± SE" for k in objs),
            *cons, "samples", "verdict", *(["where it puts the robot"] if place else [])]  # fmt: skip
    margins = ", ".join(f"{k} {float(m):g}" for k, m in zip(objs, _attr_obj(at.get("margin")) or [],
                                                              strict=False))  # fmt: skip
    note = (f"The search's candidate layouts ({'; '.join(_s(x) for x in _attr_obj(at.get('sources')) or [])}), "
            f"cleared at radius {_s(at.get('radius', '?'))} and raced on the validation stream "
            f"(final.seed = {_s(at.get('seed', '?'))}, independent of the run's seed), "
            f"{_s(at.get('stage', '?'))} samples a stage up to {_s(at.get('max_samples', '?'))}: "
            "each stage is one replication, common to the candidates it scores; intervals and "
            "differences use the stage means (Student's t), decisions are Holm-corrected with "
            f"the equivalence margins {margins}; a share constraint is met / missed when its "
            "Wilson interval clears / misses its bound, else at its bound.")  # fmt: skip
    line = f"Verdict: {_s(at.get('summary', ''))} (best: #{_s(at.get('best', '?'))})."
    tie = _s(at.get("tie_note", "") or "")
    if tie:
        line += f" {tie[0].upper()}{tie[1:]}."
    if any(v.endswith("*") for v in verdict):
        line += (" * not shown equivalent within the cap: the data cannot separate it from "
                 "the best (more samples, final.max_samples, may).")
    return PageSection("verdict", "The final stage", [f"<p class='note'>{esc(note)}</p>"
                       f"<p>{esc(line)}</p>" + _table(head, rows)])  # fmt: skip


def _teleop(t: Mapping[str, Any], ids: _Ids) -> list[PageSection]:
    sec = PageSection("teleop", "Replayed trajectory")
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
