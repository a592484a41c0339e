"""The interactive HTML report (designopt.figures.html, docs/figures.md): the numbers each
plot holds against the archive, escaping, the size budget, and every archive kind's page
loaded in a real headless Chromium (plots drawn, no JavaScript error, a screenshot kept
under results/test_artifacts/)."""

from __future__ import annotations

import base64
import copy
import json
import os
import re
import select
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from designopt import results
from designopt.app import pipeline
from designopt.app.config import validate
from designopt.figures import html as H
from designopt.io import archive
from designopt.studies import get


def _hints(tree):
    """The study's hints, as ``designopt report --html`` passes them to the page."""
    from designopt.app import records, reporting

    try:
        return reporting.hints(records.bind(results.from_tree(tree)))
    except (KeyError, ValueError):
        from designopt.figures.hints import NONE

        return NONE


def sections(tree, **kw):
    return H.sections(tree, hints=_hints(tree), **kw)


def page(tree, **kw):
    return H.page(tree, hints=_hints(tree), **kw)


def write(tree, path, **kw):
    return H.write(tree, path, hints=_hints(tree), **kw)

ROOT = Path(__file__).resolve().parents[1]
ARTIFACTS = ROOT / "results" / "test_artifacts"
EVIL = "<img src=x onerror=alert(1)>"


# ------------------------------------------------------------------------------ archives


def _config(**over):
    raw = {
        "study": get("rcm").tiny,
        "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 4, "n_runs": 3},
        "precision": "float64",
        "seed": 5,
    } | over
    return validate(raw, str(ROOT / "configs" / "tiny.yaml"))


@pytest.fixture(scope="module")
def trees(tmp_path_factory) -> dict[str, dict[str, Any]]:
    """Real rcm archives (a run, a grid scan, a curve scan) and synthetic ones following the
    schema (a front, a sweep built from the run's groups, a bench, an ik), all read back
    through ``archive.read``."""
    d = tmp_path_factory.mktemp("archives")
    out: dict[str, dict[str, Any]] = {}
    t0 = time.perf_counter()
    rep = pipeline.run(_config(), "tiny", "tiny", d / "run.h5")
    out["run"] = archive.read(rep.out)
    print(f"tiny run {time.perf_counter() - t0:.1f} s")
    grid = {"a": {"from": 80, "to": 160, "num": 3}, "c": {"from": 200, "to": 300, "num": 5}}
    rep = pipeline.scan(_config(scan={"mode": "grid", "vary": grid}), "tiny", "tiny", d / "g.h5")
    out["scan_grid"] = archive.read(rep.out)
    curve = {"c": {"from": 220, "to": 290, "num": 9}}  # eq. (19) holds only mid-range
    rep = pipeline.scan(_config(scan={"vary": curve}), "tiny", "tiny", d / "c.h5")
    out["scan_curve"] = archive.read(rep.out)
    print(f"tiny run and scans {time.perf_counter() - t0:.1f} s")
    rng = np.random.default_rng(7)
    out["front2"] = _with_front(out["run"], rng, 2, 40, d / "front2.h5")
    out["front3"] = _with_front(out["run"], rng, 3, 60, d / "front3.h5")
    out["sweep"] = _sweep(out["run"], d / "sweep.h5")
    out["bench"] = _bench(rng, d / "bench.h5")
    out["ik"] = _ik(rng, d / "ik.h5")
    out["replay"] = _replay(d / "replay.h5")
    return out


def _roundtrip(tree: dict[str, Any], path: Path) -> dict[str, Any]:
    tree = copy.deepcopy(tree)
    attrs = tree.pop("attrs")
    for k in ("schema_version", "versions", "jax_backend", "jax_devices", "complete"):
        attrs.pop(k, None)
    archive.write(path, tree, attrs)
    return archive.read(path)


def _with_front(run: dict[str, Any], rng, m: int, n: int, path: Path) -> dict[str, Any]:
    """The run archive plus a ``front`` group (issue #26's schema): objectives eta (max),
    reach (max) [, eq19_margin (min)], with front/f as minimised (max objectives negated)."""
    t = copy.deepcopy(run)
    objs = ["eta", "reach", "eq19_margin"][:m]
    senses = ["max", "max", "min"][:m]
    u = np.sort(rng.uniform(0, 1, n))
    vals = {"eta": 0.3 + 0.5 * u, "reach": 1.0 - 0.6 * u**2, "eq19_margin": 40 * rng.uniform(size=n)}  # fmt: skip
    se = {k: 0.004 + 0.01 * rng.uniform(size=n) for k in vals}
    f = np.stack([-vals[k] if s == "max" else vals[k] for k, s in zip(objs, senses, strict=True)], 1)  # fmt: skip
    f_se = np.stack([se[k] for k in objs], 1)
    # ambiguous: some objective's difference within 2 SE of the difference
    diff = np.abs(f[:, None, :] - f[None, :, :])
    tol = 2 * np.sqrt(f_se[:, None, :] ** 2 + f_se[None, :, :] ** 2)
    amb = np.any(diff < tol, axis=2) & ~np.eye(n, dtype=bool)
    fr = {"x": np.stack([rng.uniform(60, 200, n), rng.uniform(200, 400, n)], 1),
          "f": f, "f_se": f_se, "ambiguous": amb,
          "hypervolume": np.maximum.accumulate(rng.uniform(0, 1, (3, 5)), axis=1),
          "attrs": {"objectives": objs, "senses": senses, "reference": [1.1] * m}}  # fmt: skip
    for k in vals:
        fr[k], fr[k + "_se"] = vals[k], se[k]
    t["front"] = fr
    return _roundtrip(t, path)


def _sweep(run: dict[str, Any], path: Path) -> dict[str, Any]:
    t = {k: v for k, v in run.items() if k == "attrs"}
    t["attrs"] = dict(t["attrs"]) | {"kind": "sweep", "n_members": 3}
    t["members"] = {}
    for i, g in enumerate((1e-7, 1e-4, 1e-2)):
        m = {k: copy.deepcopy(run[k]) for k in ("optimizer", "best_run", "final", "problem")}
        m["final"]["f"] = np.float64(run["final"]["f"]) + 0.01 * i
        m["attrs"] = {"overrides": {"optimizer.gamma": g}, "config_resolved_yaml": "x: 1"}
        t["members"][f"{i:03d}"] = m
    return _roundtrip(t, path)


def _bench(rng, path: Path) -> dict[str, Any]:
    from designopt.bench.suite import Bench, BenchConfig, statistics

    cfg = BenchConfig(bench=Bench(functions=["sphere", "rastrigin"], variants=["p1", "p3"],
                                  reference="p3"))  # fmt: skip
    results: dict[str, Any] = {}
    for case, scale in (("sphere", 1e-6), ("rastrigin_shifted", 1.0)):
        results[case] = {}
        for j, v in enumerate(("p1", "p3")):
            h = np.sort(rng.lognormal(0, 1, (8, 31)), axis=1)[:, ::-1] * np.geomspace(1, scale, 31)
            h *= 10 ** rng.uniform(-3, 0, (8, 1))  # runs spread over 3 decades
            if case == "sphere" and v == "p3":
                h[0, -5:] = 0.0  # an optimum reached exactly: drawn at a floor
            results[case][v] = {"history": h.astype(np.float32), "best_f": h[:, -1],
                                "best_x": rng.normal(size=(8, 3)),
                                "converged_at": rng.integers(3, 30, 8),
                                "hypervolume": 0.8 + 0.05 * j + 0.01 * rng.normal(size=8)}  # fmt: skip
    st = statistics(cfg, results)
    tree = {"bench": {c: {v: {k: r[k] for k in ("history", "best_f", "best_x", "converged_at", "hypervolume")}
                          | {"attrs": {"wall_s": 0.1, "compile_s": 0.05, "settings": {"name": v}}}
                          for v, r in per.items()} | {"attrs": {"stats": st[c]}}
                      for c, per in results.items()},
            "attrs": {"kind": "bench", "config_yaml": "bench: {}", "seed": 0,
                      "config_resolved": cfg.model_dump_json()}}  # fmt: skip
    return _roundtrip(tree, path)


def _ik(rng, path: Path) -> dict[str, Any]:
    n = 120
    ok = rng.uniform(size=n) < 0.85
    tree = {"ik": {"q": rng.normal(size=(n, 6)), "success": ok,
                   "iterations": rng.integers(2, 40, n),
                   "pos_err": np.where(ok, 10 ** rng.uniform(-11, -8, n), rng.uniform(0.1, 5, n)),
                   "rot_err": np.where(ok, 10 ** rng.uniform(-12, -9, n), rng.uniform(0.01, 1, n)),
                   "poses": np.tile(np.eye(4), (n, 1, 1)),
                   "attrs": {"mode": "cold", "poses_file": "poses.npy", "n": n, "arm": "psm",
                             "joint_names": [f"q{i}" for i in range(1, 7)],
                             "units": "q1, q2, q4, q5, q6 rad; q3 mm; pos_err mm; rot_err rad"}},
            "attrs": {"kind": "ik", "study": "davinci", "config_yaml": "study: {name: davinci}",
                      "seed": 0}}  # fmt: skip
    return _roundtrip(tree, path)


def _replay(path: Path) -> dict[str, Any]:
    """A trajectory replay's ``teleop`` group (rcm_teleop's layout): a square, tracked
    with a small lag."""
    t = np.linspace(0, 4, 401)
    s = np.clip(np.abs((t % 4) - 2) - 0.5, 0, 1)  # a square's corner coordinates
    cmd = np.stack([30 * s, 30 * np.roll(s, 100), np.full_like(t, -150.0)], 1)
    tip = np.roll(cmd, 2, axis=0)
    tree = {"teleop": {"t": t, "command": cmd, "tip": tip,
                       "error": np.linalg.norm(tip - cmd, axis=1),
                       "attrs": {"scale": 0.5, "dt_s": 0.01}},
            "attrs": {"kind": "run", "study": "rcm_teleop", "config_yaml": "replay"}}  # fmt: skip
    return _roundtrip(tree, path)


def _cloud(n: int = 4000, seed: int = 0) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    xyz = rng.normal(size=(n, 3)) * [60, 40, 25]
    return {
        "xyz": xyz,
        "value": 1 / (1 + np.linalg.norm(xyz / 50, axis=1)),
        "label": "1/k",
        "unit": "-",
    }


def _plots(secs: list[H.Section]) -> dict[str, H.Plot]:
    return {p.id: p for s in secs for p in s.plots()}


def _trace(plot: H.Plot, name: str) -> dict[str, Any]:
    return next(t for t in plot.fig["data"] if t.get("name") == name)


def _figs_json(text: str) -> dict[str, Any]:
    m = re.search(r"<script type='application/json' id='designopt-figures'>(.*?)</script>", text,
                  re.S)  # fmt: skip
    return json.loads(m.group(1))


def _decode(v: Any) -> np.ndarray:
    if isinstance(v, dict) and "bdata" in v:
        a = np.frombuffer(base64.b64decode(v["bdata"]), np.float64)
        return a.reshape([int(s) for s in v["shape"].split(",")]) if "shape" in v else a
    return np.asarray(v)


# ------------------------------------------------------------------- numbers in the plots


def test_run_page_holds_the_archive(trees):
    t = trees["run"]
    secs = sections(t)
    plots = _plots(secs)
    opt, br = t["optimizer"], t["best_run"]
    best = int(br["attrs"]["run_index"])
    conv = next(p for p in plots.values() if "convergence" in p.id)
    np.testing.assert_array_equal(_trace(conv, f"best run ({best})")["y"], opt["history"][best])
    q25, q50 = np.percentile(opt["history"], [25, 50], axis=0)
    np.testing.assert_allclose(_trace(conv, "median of 3 runs")["y"], q50)
    lo = next(tr for tr in conv.fig["data"] if tr.get("fill") is None and tr.get("legendgroup") == "IQR of all runs")  # fmt: skip
    np.testing.assert_allclose(lo["y"], q25)
    # the best run's eq. (19) margin (mm, no SE): its own panel, no band, unit on the axis
    m = next(p for p in plots.values() if p.id.endswith("eq19-margin"))
    assert len(m.fig["data"]) == 1 and m.fig["layout"]["yaxis"]["title"]["text"] == "eq19_margin [mm]"  # fmt: skip
    np.testing.assert_array_equal(m.fig["data"][0]["y"], br["eq19_margin"])
    # eta has a ± 2 SE band; eta, eta_cone and −f are one panel (equal values)
    e = next(p for p in plots.values() if p.id.endswith("best-eta"))
    lo, hi, line = e.fig["data"]
    np.testing.assert_allclose(hi["y"] - lo["y"], 4 * br["eta_se"], rtol=1e-12)
    assert "eta = eta_cone = −f" in e.fig["layout"]["title"]["text"]
    # reach is a rate: Wilson band inside [0, 1] around the value
    r = next(p for p in plots.values() if p.id.endswith("best-reach"))
    lo, hi, line = r.fig["data"]
    assert np.all(lo["y"] >= 0) and np.all(hi["y"] <= 1) and np.all(lo["y"] <= line["y"])
    assert "Wilson" in r.fig["layout"]["title"]["text"]
    text = page(t)
    fin = next(s for s in secs if s.id == "final").items[0]
    assert f"{float(t['final']['eta']):.6g} ± {float(t['final']['eta_se']):.2g}" in fin
    assert f"{t['final']['x'][0]:.6g}" in fin
    # one copy of plotly.js; every plot has its div and its data, which decode exactly
    from plotly.offline import get_plotlyjs

    assert text.count(get_plotlyjs()[:2000]) == 1
    figs = _figs_json(text)
    assert set(figs) == set(plots)
    for pid in figs:
        assert f'<div id="{pid}" class="plot' in text
    y = _decode(next(tr for tr in figs[conv.id]["data"] if tr.get("name") == f"best run ({best})")["y"])  # fmt: skip
    np.testing.assert_array_equal(y, opt["history"][best])
    assert "<pre>tiny</pre>" in text  # the config as given


def test_front_2d_3d_values_errors_hover_and_ambiguity(trees):
    for key, m in (("front2", 2), ("front3", 3)):
        t = trees[key]
        fr = t["front"]
        n = len(fr["f"])
        (p,) = [p for p in _plots(sections(t)).values() if p.id.split("-", 2)[2].startswith("front")]  # fmt: skip
        tr = p.fig["data"][-1]
        assert tr["type"] == ("scatter" if m == 2 else "scatter3d")
        # shown as the indices themselves (a max objective not negated), bars ± 2 SE
        np.testing.assert_array_equal(tr["x"], fr["eta"])
        np.testing.assert_array_equal(tr["y"], -fr["f"][:, 1])
        np.testing.assert_allclose(tr["error_x"]["array"], 2 * fr["f_se"][:, 0])
        if m == 3:
            np.testing.assert_array_equal(tr["z"], fr["eq19_margin"])
            np.testing.assert_allclose(tr["error_z"]["array"], 2 * fr["eq19_margin_se"])
        # marked: exactly the designs in a pair whose order is within 2 SE in some objective
        d = np.abs(fr["f"][:, None] - fr["f"][None])
        tol = 2 * np.hypot(fr["f_se"][:, None], fr["f_se"][None])
        in_pair = (np.any(d < tol, axis=2) & ~np.eye(n, dtype=bool)).any(axis=1)
        assert in_pair.any() and not in_pair.all()
        np.testing.assert_array_equal(np.asarray(tr["marker"]["symbol"]) == "diamond", in_pair)
        # hover: design number, the variables, ambiguity count, then each index and its SE
        cd = tr["customdata"]
        np.testing.assert_array_equal(cd[:, 0], np.arange(n))
        np.testing.assert_array_equal(cd[:, 1:3], fr["x"])
        hov = tr["hovertemplate"]
        assert "a = %{customdata[1]:.5~g} mm" in hov and "reach = %{customdata[" in hov
        j = hov.split("<br>").index(next(s for s in hov.split("<br>") if s.startswith("eta = ")))
        col = int(re.search(r"customdata\[(\d+)\]", hov.split("<br>")[j]).group(1))
        np.testing.assert_array_equal(cd[:, col], fr["eta"])
        np.testing.assert_array_equal(cd[:, col + 1], fr["eta_se"])
    # the pairs as a (p, 2) index array mark the same designs as the (n, n) matrix
    t = copy.deepcopy(trees["front2"])
    i, j = np.nonzero(np.triu(t["front"]["ambiguous"], 1))
    t["front"]["ambiguous"] = np.stack([i, j], 1)
    (a,) = [p for p in _plots(sections(t)).values() if p.id.endswith("front")]
    (b,) = [p for p in _plots(sections(trees["front2"])).values() if p.id.endswith("front")]
    assert a.fig["data"][-1]["marker"]["symbol"] == b.fig["data"][-1]["marker"]["symbol"]
    hv = [p for p in _plots(sections(trees["front2"])).values() if "hypervolume" in p.fig["layout"]["title"]["text"]]  # fmt: skip
    assert len(hv) == 1
    np.testing.assert_array_equal(_trace(hv[0], "median of 3 runs")["y"],
                                  np.median(trees["front2"]["front"]["hypervolume"], axis=0))  # fmt: skip


def test_scan_curves_and_maps_mark_infeasible_designs(trees):
    t = trees["scan_curve"]
    sc = t["scan"]
    plots = _plots(sections(t))
    c = sc["x"][:, 1]  # names: a, c
    o = np.argsort(c)
    p = next(p for p in plots.values() if p.id.endswith("scan-eta"))
    lo, hi, line = p.fig["data"][:3]
    np.testing.assert_array_equal(line["x"], c[o])
    np.testing.assert_array_equal(line["y"], sc["eta"][o])
    np.testing.assert_allclose(hi["y"] - lo["y"], 4 * sc["eta_se"][o], rtol=1e-12)
    assert p.fig["layout"]["xaxis"]["title"]["text"] == "c [mm]"
    bad = sc["violation"] > 0
    assert bad.any() and not bad.all()
    inf = _trace(p, "infeasible (violation > 0)")
    np.testing.assert_array_equal(np.sort(inf["x"]), np.sort(c[bad]))
    t = trees["scan_grid"]
    sc = t["scan"]
    n0, n1 = sc["attrs"]["shape"]
    maps = [p for p in _plots(sections(t)).values() if p.fig["data"][0]["type"] == "heatmap"]
    assert len(maps) >= 4
    m = next(p for p in maps if p.id.endswith("map-reach"))
    hm = m.fig["data"][0]
    np.testing.assert_array_equal(hm["z"], sc["reach"].reshape(n0, n1))
    np.testing.assert_array_equal(hm["customdata"], sc["reach_se"].reshape(n0, n1))
    np.testing.assert_array_equal(hm["x"], np.unique(sc["x"][:, 1]))
    assert (hm["zmin"], hm["zmax"]) == (0, 1)  # a rate
    bad = (sc["violation"] > 0).reshape(n0, n1)
    assert bad.any() and not bad.all()
    cross = _trace(m, "infeasible (violation > 0)")
    assert len(cross["x"]) == bad.sum()


def test_sweep_bench_and_ik_pages(trees):
    s = trees["sweep"]
    p = next(iter(_plots(sections(s)).values()))
    np.testing.assert_allclose(p.fig["data"][0]["x"], [float(m["final"]["f"]) for k, m in sorted(s["members"].items()) if k != "attrs"])  # fmt: skip
    assert p.fig["data"][0]["y"][1] == "[001] gamma=0.0001"
    b = trees["bench"]
    plots = _plots(sections(b))
    box = next(p for p in plots.values() if p.id.endswith("box-sphere"))
    y = {tr["name"]: tr["y"] for tr in box.fig["data"]}
    np.testing.assert_allclose(y["p1"], b["bench"]["sphere"]["p1"]["best_f"])
    fin = np.concatenate([b["bench"]["sphere"][v]["best_f"] for v in ("p1", "p3")])
    assert fin.min() == 0 and fin[fin > 0].max() / fin[fin > 0].min() > 100
    assert box.fig["layout"]["yaxis"]["type"] == "log"  # spans > 2 decades; 0 at a floor
    assert np.min(y["p3"]) == fin[fin > 0].min() / 10
    conv = next(p for p in plots.values() if p.id.endswith("conv-sphere"))
    assert "values ≤ 0 drawn at" in conv.fig["layout"]["title"]["text"]
    med = [tr for tr in conv.fig["data"] if tr.get("name") == "p1" and "fill" not in tr][-1]
    h = b["bench"]["sphere"]["p1"]["history"].astype(np.float64)
    np.testing.assert_allclose(med["y"], np.median(h, axis=0)[med["x"].astype(int)])
    hv = next(p for p in plots.values() if p.id.endswith("hv-rastrigin-shifted"))
    np.testing.assert_array_equal(hv.fig["data"][1]["y"], b["bench"]["rastrigin_shifted"]["p3"]["hypervolume"])  # fmt: skip
    text = page(b)
    st = b["bench"]["sphere"]["attrs"]["stats"]["rows"]["p1"]
    assert f"<td>{st['median']:.4g}</td>" in text and f"<td>{st['p_holm']:.4g}</td>" in text
    ik = trees["ik"]
    plots = _plots(sections(ik))
    rate = next(p for p in plots.values() if p.id.endswith("ik-rate")).fig["data"][0]
    ok = ik["ik"]["success"]
    n, k = len(ok), ok.sum()
    p_hat = k / n
    # Wilson score interval (z = 2): the roots of (p̂ − π)² = z² π (1 − π) / n
    roots = np.sort(np.roots([1 + 4 / n, -(2 * p_hat + 4 / n), p_hat**2]).real)
    assert rate["y"] == [p_hat]
    np.testing.assert_allclose([p_hat - rate["error_y"]["arrayminus"][0],
                                p_hat + rate["error_y"]["array"][0]], roots, atol=1e-12)  # fmt: skip
    pe = next(p for p in plots.values() if p.id.endswith("ik-pos-err"))
    solved = next(tr for tr in pe.fig["data"] if tr["name"].startswith("solved"))
    np.testing.assert_allclose(solved["x"], np.log10(ik["ik"]["pos_err"][ok]))  # 3 decades: log
    assert pe.fig["layout"]["xaxis"]["title"]["text"] == "log10 pos_err [mm]"


def test_replay_and_checkpoint_pages(trees):
    r = trees["replay"]["teleop"]
    plots = _plots(sections(trees["replay"]))
    path = next(p for p in plots.values() if p.id.endswith("teleop-path"))
    np.testing.assert_array_equal(_trace(path, "commanded")["z"], r["command"][:, 2])
    np.testing.assert_array_equal(_trace(path, "achieved")["x"], r["tip"][:, 0])
    err = next(p for p in plots.values() if p.id.endswith("teleop-error"))
    np.testing.assert_array_equal(err.fig["data"][0]["y"], r["error"])
    # a checkpoint: stated on the page, its history drawn
    h = trees["run"]["optimizer"]["history"]
    ck = {"attrs": {"kind": "run", "complete": np.False_},
          "checkpoint": {"history": h[:, :3], "attrs": {"done": 2}}}  # fmt: skip
    text = page(ck)
    assert "This archive is a checkpoint" in text and "2 iterations done" in text


def test_records_give_the_same_page(trees):
    """The lead's typed records hold the same tree (``record.to_tree()``)."""
    results = pytest.importorskip("designopt.results")
    for key in ("run", "scan_grid", "sweep", "bench", "ik", "front2"):
        t = trees[key]
        assert page(results.from_tree(t).to_tree()) == page(t), key


def test_untrusted_text_is_escaped(trees):
    t = copy.deepcopy(trees["front2"])
    t["attrs"]["config_yaml"] = f"study: </pre><script>alert(1)</script>\nname: '{EVIL}'"
    t["attrs"]["study"] = "<b>evil</b>"
    t["problem"]["names"] = np.array([EVIL.encode(), b"c"])
    t["front"]["attrs"]["objectives"] = [EVIL, "reach"]
    text = page(t, title="</title><script>alert(2)</script>", units={EVIL: "<i>mm</i>"})
    for raw in ("<script>alert", EVIL, "<b>evil</b>", "<i>mm</i>", "</title><script>"):
        assert raw not in text
    assert "&lt;/pre&gt;&lt;script&gt;alert(1)&lt;/script&gt;" in text
    assert "&lt;b&gt;evil&lt;/b&gt;" in text
    blob = re.search(r"id='designopt-figures'>(.*?)</script>", text, re.S).group(1)
    assert "<" not in blob and ">" not in blob  # JSON inside <script>: no tag can close it
    assert text.count("<script") == 3  # plotly.js, the figures' JSON, the drawing script


def test_size_budget_and_write(tmp_path):
    rng = np.random.default_rng(1)
    runs, T, n_it = 200, 20000, 20001
    h = np.minimum.accumulate(rng.lognormal(0, 1, (runs, n_it)), axis=1)
    idx = {k: np.linspace(1, 0, n_it) for k in ("f", "gci", "volume")}
    br = {"iteration": np.arange(n_it)} | idx | {k + "_se": 0.01 + 0 * v for k, v in idx.items()}
    n0 = n1 = 300
    g0, g1 = np.meshgrid(np.linspace(0, 1, n0), np.linspace(2, 3, n1), indexing="ij")
    sc = {"names": np.array([b"a", b"b"]), "varied": np.array([b"a", b"b"]),
          "x": np.stack([g0.ravel(), g1.ravel()], 1), "attrs": {"mode": "grid", "shape": [n0, n1]}}  # fmt: skip
    for k in ("f", "gci", "volume", "gcsei"):
        sc[k], sc[k + "_se"] = rng.normal(size=n0 * n1), rng.uniform(size=n0 * n1)
    tree = {"attrs": {"kind": "run", "study": "nothing-registered", "config_yaml": "x" * (H.MAX_TEXT + 5)},
            "optimizer": {"history": h, "best_f": h[:, -1]}, "best_run": br | {"attrs": {"run_index": 3}},
            "final": {"x": np.zeros(2), "f": np.float64(1.0)}, "scan": sc}  # fmt: skip
    secs = sections(tree, cloud=_cloud(200_000))
    n = H.budget(secs)
    assert n <= H.MAX_VALUES
    conv = _plots(secs)["plot-1-convergence"]
    best = _trace(conv, "best run (3)")
    assert best["x"][0] == 0 and best["x"][-1] == T  # the first and last iteration kept
    assert best["y"][-1] == h[3, -1]
    assert "of 20001 iterations" in conv.fig["layout"]["title"]["text"]
    assert "of 200 runs drawn" in conv.fig["layout"]["title"]["text"]
    t0 = time.perf_counter()
    out = write(tree, tmp_path / "big.html", cloud=_cloud(200_000))
    dt = time.perf_counter() - t0
    size = out.stat().st_size
    print(f"big page: {size / 1e6:.2f} MB, {n} numbers, built in {dt:.2f} s")
    assert size < 10e6
    text = out.read_text()
    assert f"first {H.MAX_TEXT} of {H.MAX_TEXT + 5} characters shown" in text
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # atomic: no temp left


def test_figures_pass_plotly_validation(trees):
    """Every trace and layout key is one plotly knows (its validators)."""
    import plotly.graph_objects as go

    for key, t in trees.items():
        for s in sections(t, cloud=_cloud(300) if key == "run" else None):
            for p in s.plots():
                go.Figure(p.fig)  # raises ValueError on an unknown property


# ---------------------------------------------------------------------- real Chromium

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-unsafe-swiftshader", "--disable-dev-shm-usage", "--hide-scrollbars",
         "--mute-audio", "--no-default-browser-check"]  # fmt: skip
"""--enable-unsafe-swiftshader: software WebGL for the 3-D plots under --disable-gpu."""


class Browser:
    """Headless Chromium driven over the DevTools protocol on a pipe (its fds 3 and 4:
    ``--remote-debugging-pipe``), so no websocket client is needed."""

    def __init__(self, profile: Path, log: Path) -> None:
        to_r, self._w = os.pipe()  # we write commands, Chromium reads its fd 3
        self._r, from_w = os.pipe()  # Chromium writes its fd 4, we read
        # a Python trampoline puts the pipes on fds 3 and 4 (a shell's `3<&N` fails for
        # N > 9 in dash: "Bad fd number" once a long test session holds many fds)
        hop = "import os, sys; os.dup2(int(sys.argv[1]), 3); os.dup2(int(sys.argv[2]), 4); os.execv(sys.argv[3], sys.argv[3:])"  # noqa: E501
        cmd = [sys.executable, "-c", hop, str(to_r), str(from_w), CHROMIUM, *FLAGS,
               f"--user-data-dir={profile}", "--remote-debugging-pipe", "about:blank"]  # fmt: skip
        self._log = open(log, "wb")  # noqa: SIM115 - closed in close()
        self.proc = subprocess.Popen(cmd, pass_fds=(to_r, from_w), stdin=subprocess.DEVNULL,
                                     stdout=self._log, stderr=subprocess.STDOUT)  # fmt: skip
        os.close(to_r)
        os.close(from_w)
        self._buf = b""
        self._id = 0
        self.events: list[dict[str, Any]] = []
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next(t for t in targets if t["type"] == "page")
        self.session = self.call("Target.attachToTarget", targetId=page["targetId"],
                                 flatten=True)["sessionId"]  # fmt: skip
        for m in ("Runtime.enable", "Log.enable", "Page.enable"):
            self.call(m, session=True)

    def _read(self, timeout: float) -> dict[str, Any] | None:
        while b"\0" not in self._buf:
            r, _, _ = select.select([self._r], [], [], max(0.0, timeout))
            if not r:
                return None
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the DevTools pipe")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def call(self, method: str, session: bool = False, timeout: float = 30, **params: Any) -> dict:
        self._id += 1
        msg: dict[str, Any] = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = self.session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        end = time.monotonic() + timeout
        while True:
            m = self._read(end - time.monotonic())
            if m is None:
                raise TimeoutError(method)
            if m.get("id") == self._id:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})
            self.events.append(m)

    def wait(self, method: str, timeout: float = 30) -> dict[str, Any]:
        for i, e in enumerate(self.events):
            if e.get("method") == method:
                return self.events.pop(i)
        end = time.monotonic() + timeout
        while True:
            m = self._read(end - time.monotonic())
            if m is None:
                raise TimeoutError(method)
            if m.get("method") == method:
                return m
            self.events.append(m)

    def js(self, expr: str) -> Any:
        r = self.call("Runtime.evaluate", session=True, expression=expr, returnByValue=True,
                      awaitPromise=True)  # fmt: skip
        if "exceptionDetails" in r:
            raise RuntimeError(str(r["exceptionDetails"]))
        return r["result"].get("value")

    def load(self, path: Path, width: int = 1280, timeout: float = 30) -> float:
        """Open ``path``; wait for the load event and every plot drawn; returns seconds."""
        self.events.clear()
        self.call("Emulation.setDeviceMetricsOverride", session=True, width=width, height=900,
                  deviceScaleFactor=1, mobile=False)  # fmt: skip
        t0 = time.perf_counter()
        self.call("Page.navigate", session=True, url=path.resolve().as_uri())
        self.wait("Page.loadEventFired", timeout)
        end = time.monotonic() + timeout
        while not self.js("document.body.hasAttribute('data-plots-drawn')"):
            assert time.monotonic() < end, f"{path.name}: plots not drawn in {timeout} s"
            time.sleep(0.02)
        dt = time.perf_counter() - t0
        while (m := self._read(0.1)) is not None:  # late console messages
            self.events.append(m)
        return dt

    def errors(self) -> list[str]:
        """Uncaught exceptions, console.error/assert, error log entries, dialogs."""
        out = []
        for e in self.events:
            m, p = e.get("method"), e.get("params", {})
            if m == "Runtime.exceptionThrown":
                d = p["exceptionDetails"]
                out.append(d.get("exception", {}).get("description") or d.get("text", ""))
            elif m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                out.append(" ".join(str(a.get("value", a.get("description"))) for a in p["args"]))
            elif m == "Log.entryAdded" and p["entry"]["level"] == "error":
                out.append(p["entry"]["text"])
            elif m == "Page.javascriptDialogOpening":
                out.append("dialog: " + p.get("message", ""))
        return out

    def screenshot(self, out: Path, width: int = 1280) -> None:
        h = int(self.js("Math.ceil(document.documentElement.scrollHeight)"))
        self.call("Emulation.setDeviceMetricsOverride", session=True, width=width,
                  height=min(h, 16000), deviceScaleFactor=1, mobile=False)  # fmt: skip
        self.js("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        r = self.call("Page.captureScreenshot", session=True, format="png")
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(base64.b64decode(r["data"]))

    def close(self) -> None:
        try:
            self.call("Browser.close", timeout=5)
        except (TimeoutError, RuntimeError, OSError):
            pass
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._w)
        os.close(self._r)
        self._log.close()


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    if CHROMIUM is None:
        pytest.skip("chromium is not installed (Debian: apt-get install chromium); "
                    "the page was not opened in a browser")  # fmt: skip
    d = tmp_path_factory.mktemp("chromium")
    b = Browser(d / "profile", d / "chromium.log")
    yield b
    b.close()


RENDERED = """Array.from(document.querySelectorAll('div.plot')).map(d => ({
  id: d.id, svg: d.querySelectorAll('.main-svg').length,
  container: d.querySelectorAll('.plot-container').length,
  traces: (d._fullData || []).length, gl: d.querySelectorAll('.gl-container canvas').length,
  points: d.querySelectorAll('.scatterlayer .point, .boxlayer .point').length,
  heatmaps: d.querySelectorAll('.heatmaplayer image').length,
  caption: d.parentElement.querySelector('figcaption').textContent,
  failed: d.textContent.startsWith('plot failed')}))"""

PAGES = {  # page: (tree, page kwargs)
    "run_front_cloud": ("front2", {"cloud": True}),
    "front3d": ("front3", {}),
    "scan_grid": ("scan_grid", {}),
    "scan_curve": ("scan_curve", {}),
    "sweep": ("sweep", {}),
    "bench": ("bench", {}),
    "ik": ("ik", {}),
}  # the replay's 3-D path uses the same traces as the 3-D front (checked in Python only)


@pytest.mark.parametrize("name", list(PAGES))
def test_page_renders_in_chromium(name, trees, browser, tmp_path):
    key, kw = PAGES[name]
    tree = copy.deepcopy(trees[key])
    if name == "run_front_cloud":  # hostile names must show as text, never run
        tree["problem"]["names"] = np.array([EVIL.encode(), b"c"])
    path = write(tree, tmp_path / f"{name}.html", cloud=_cloud() if kw.get("cloud") else None)
    figs = _figs_json(path.read_text())
    dt = browser.load(path)
    print(f"{name}: {path.stat().st_size / 1e6:.2f} MB, loaded and drawn in {dt:.2f} s")
    assert browser.errors() == []
    got = {r["id"]: r for r in browser.js(RENDERED)}
    assert set(got) == set(figs)
    for pid, r in got.items():
        assert not r["failed"] and r["svg"] >= 2 and r["container"] == 1, r
        assert r["caption"], r  # every plot says what it shows
        assert r["traces"] == len(figs[pid]["data"]), r
        kinds = {tr["type"] for tr in figs[pid]["data"]}
        if kinds & {"scatter3d", "splom"}:
            assert r["gl"] >= 1, r  # WebGL canvas
        if "heatmap" in kinds:
            assert r["heatmaps"] == 1, r
        if "box" in kinds or any(tr.get("mode") == "markers" and tr["type"] == "scatter"
                                 for tr in figs[pid]["data"]):  # fmt: skip
            assert r["points"] > 0, r
    if name == "run_front_cloud":
        best = int(tree["best_run"]["attrs"]["run_index"])
        secs = sections(tree, cloud=_cloud())
        pid = next(p.id for s in secs for p in s.plots()
                   if p.fig["layout"]["title"]["text"] == "best-so-far f per iteration")  # fmt: skip
        y = browser.js(f"""(() => {{ const g = document.getElementById('{pid}');
            const i = g._fullData.findIndex(t => t.name === 'best run ({best})');
            return Array.from(g._fullData[i].y); }})()""")  # fmt: skip
        assert y == tree["optimizer"]["history"][best].tolist()  # exact through the page
        # hovering design 3 of the front shows its variables and indices ± SE
        fid = next(p.id for s in secs for p in s.plots() if p.id.endswith("-front"))
        hover = browser.js(f"""(async () => {{ const g = document.getElementById('{fid}');
            Plotly.Fx.hover(g, [{{curveNumber: g._fullData.length - 1, pointNumber: 3}}]);
            await new Promise(r => setTimeout(r, 100));
            return Array.from(g.querySelectorAll('.hoverlayer text'), e => e.textContent)
                        .join(' '); }})()""")  # fmt: skip
        fr = tree["front"]
        for want in ("design 3", f"c = {fr['x'][3, 1]:.5g} mm", f"{EVIL} = {fr['x'][3, 0]:.5g}",
                     f"eta = {fr['eta'][3]:.5g} ± {fr['eta_se'][3]:.2g}"):  # fmt: skip
            assert want in hover, (want, hover)
        assert browser.js("document.querySelectorAll('img[src=\"x\"]').length") == 0
        assert EVIL in browser.js("document.getElementById('final').textContent")
    browser.screenshot(ARTIFACTS / f"html_report_{name}.png")


def test_browser_check_sees_javascript_errors(trees, browser, tmp_path):
    """The check above can fail: a page with a script error is caught."""
    text = page(trees["ik"]).replace("</body>", "<script>notDefined();</script></body>")
    p = tmp_path / "broken.html"
    p.write_text(text)
    browser.load(p)
    assert any("notDefined" in e for e in browser.errors())
