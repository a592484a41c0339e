"""Figure checks (docs/figures.md, the checker in tests/figcheck.py): the scan, sweep and
bench figures with tiny inputs, and the checker itself. Every registered study's run
figures are checked by the contract test that draws them (tests/test_studies.py).

Figures are drawn from records (``designopt.results``): the in-memory record of a command
and the record loaded back from its archive draw the same pixels."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from figcheck import assert_clean, problems

from designopt.app import pipeline, records, reporting
from designopt.app.config import validate
from designopt.figures import bench as bench_figs
from designopt.figures import canvas, style
from designopt.figures import scan as scan_figs
from designopt.figures import sweep as sweep_figs
from designopt.io import archive, writer
from designopt.numerics import statistics
from designopt.results import BenchRecord, SweepRecord
from designopt.studies import STUDIES, get

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def record():
    canvas.RECORD = []
    yield canvas.RECORD
    canvas.RECORD = None
    plt.close("all")


# ----------------------------------------------------------------- the checker itself


def test_checker_finds_missing_units_overlap_and_unshared_scales():
    fig, axes = style.subplots(1, 2, figsize=(6, 3))
    axes[0].plot([1, 2], [1, 2])
    axes[0].set_xlabel("c")  # no unit
    axes[0].set_ylabel(style.label("η", style.DIMENSIONLESS))
    axes[0].text(0.5, 1.5, "x" * 200)  # leaves the canvas
    im0 = axes[1].imshow(np.arange(4.0).reshape(2, 2))
    im1 = axes[1].imshow(np.arange(4.0).reshape(2, 2) + 5)
    axes[1].set_xlabel("a [mm]")
    axes[1].set_ylabel("b [mm]")
    fig.designopt_shared = [[im0, im1]]
    p = problems(fig)
    assert any("'c' of" in x for x in p)
    assert any("leaves the canvas" in x for x in p)
    assert any("colour limits" in x for x in p)
    style.shared_scale(fig, [im0, im1])
    assert not any("colour limits" in x for x in problems(fig))
    plt.close(fig)


def test_wilson_interval_solves_its_quadratic_and_stays_in_range():
    z = style.Z_SE
    for p, n in ((0.0, 10), (1.0, 64), (0.3, 100), (0.97, 512)):
        lo, hi = style.wilson(np.array([p]), n)
        # the Wilson bounds are the roots π of (p − π)² = z² π (1 − π) / n
        a, b, c = 1 + z**2 / n, -(2 * p + z**2 / n), p**2
        roots = np.sort(np.roots([a, b, c]).real)
        np.testing.assert_allclose([lo[0], hi[0]], roots, atol=1e-12)
        assert 0 <= lo[0] <= p <= hi[0] <= 1 and hi[0] > lo[0]
    p = np.array([0.2, 0.5])
    n = 400
    assert style.trials(p, np.sqrt(p * (1 - p) / n)) == pytest.approx(n)


def test_labels_and_log_choice():
    assert style.label("c", "mm") == "c [mm]" and style.label("η", "") == "η [-]"
    fig, ax = plt.subplots()
    assert style.auto_log(ax, np.array([1e-6, 1.0]))
    assert ax.get_yscale() == "log"
    fig, ax = plt.subplots()
    assert not style.auto_log(ax, np.array([-1.0, 1e3]))
    assert not style.auto_log(ax, np.array([1.0, 50.0]))
    plt.close("all")


def _pngs(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*.png"))}


# ------------------------------------------------------------------ every study, tiny


def _config(name: str, **over):
    raw = {
        "study": get(name).tiny,
        "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 2, "n_runs": 1},
        "precision": "float64",
        "seed": 3,
    } | over
    return validate(raw, str(ROOT / "configs" / "tiny.yaml"))


@pytest.mark.parametrize("name", sorted(n for n, st in STUDIES.items() if st.replay))
def test_replay_figures(name, tmp_path, record):
    """Studies whose run is a replay (the design studies' figures are checked by the
    contract run test in tests/test_studies.py)."""
    cfg = _config(name)
    rep = pipeline.run(cfg, "tiny", str(ROOT / "configs" / "tiny.yaml"), tmp_path / "a.h5")
    rec = records.load(rep.out)
    assert rec == rep.record
    get(name).figures(rec, tmp_path / "figs")
    assert_clean(record)
    get(name).figures(rep.record, tmp_path / "mem")  # the in-memory record: same pixels
    assert _pngs(tmp_path / "mem") == _pngs(tmp_path / "figs") != {}


def _scan(name: str, tmp_path: Path, scan: dict):
    cfg = _config(name, scan=scan)
    rep = pipeline.scan(cfg, "tiny", "tiny", tmp_path / f"{name}_{scan.get('mode', 'grid')}.h5")
    return records.load(rep.out)


def test_scan_curves_merge_equal_indices(tmp_path, record):
    a = _scan("rcm", tmp_path, {"vary": {"c": {"from": 200, "to": 400, "num": 5}}})
    scan_figs.draw(a, tmp_path / "f", reporting.hints(a))
    assert_clean(record)
    (_, fig), = record  # fmt: skip
    ys = [ax.get_ylabel() for ax in fig.axes if ax.get_visible()]
    names = [
        t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()
    ]
    assert [n for n in names if "eta_cone" in n] == ["eta = eta_cone = −f"]  # one curve
    assert not any(y.startswith(("f ", "eta_cone ")) for y in ys)
    assert sum(y.startswith("η") for y in ys) == 1  # η of every workspace in one panel


def test_scan_grid_hatches_infeasible_cells_and_designs(tmp_path, record):
    grid = {"a": {"from": 60, "to": 200, "num": 4}, "c": {"from": 200, "to": 400, "num": 3}}
    a = _scan("rcm", tmp_path, {"mode": "grid", "vary": grid})
    scan_figs.draw(a, tmp_path / "f", reporting.hints(a))
    assert (a.values["violation"] > 0).any()  # eq. (19) fails for small a, large c
    fig = record[0][1]
    texts = [
        t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()
    ]
    assert "infeasible" in texts
    a = _scan(
        "rcm", tmp_path, {"mode": "list", "vary": {"a": [80, 120, 160], "c": [220, 250, 300]}}
    )
    scan_figs.draw(a, tmp_path / "g", reporting.hints(a))
    assert_clean(record)


def test_sweep_figure(tmp_path, record):
    vary = {"optimizer.gamma": [1e-7, 1e-3], "optimizer.n_particles": [4, 6]}
    cfg = _config("rcm", sweep={"vary": vary})
    rep = pipeline.sweep(cfg, "tiny", "tiny", tmp_path / "s.h5")
    # the members run in vmapped batches (one per swarm size) and are kept in the sweep's
    # order, in memory as in the archive
    assert list(rep.record.members) == ["000", "001", "002", "003"]
    rec = records.load(rep.out)
    assert isinstance(rec, SweepRecord) and rec == rep.record
    sweep_figs.draw(rec, tmp_path / "f")
    assert_clean(record)
    (_, fig), = record  # fmt: skip
    ax = fig.axes[0]
    # one row per member in the sweep's order, at its final f, labelled by its overrides
    grid = [(g, n) for g in (1e-7, 1e-3) for n in (4, 6)]
    assert [t.get_text() for t in ax.get_yticklabels()] == [
        f"gamma={g:g}, n_particles={n}" for g, n in grid
    ]
    f = [float(rec.members[k]["final"]["f"]) for k in ("000", "001", "002", "003")]
    np.testing.assert_array_equal(ax.lines[0].get_xdata(), f)
    members = rec.member_records()
    assert list(members) == list(rep.record.member_records()) == ["000", "001", "002", "003"]
    for (k, m), (gamma, n) in zip(members.items(), grid, strict=True):
        assert list(rec.overrides()[k].values()) == [gamma, n]
        assert m.config.optimizer.settings == {"gamma": gamma}
        assert m.config.optimizer.n_particles == n and m.history.shape == (1, 3)
        assert m.config.study == rec.config.study
        assert m.study == "rcm" and m.seed == 3 and m.f == f[int(k)]
    sweep_figs.draw(rep.record, tmp_path / "mem")  # the in-memory record: same pixels
    assert _pngs(tmp_path / "mem") == _pngs(tmp_path / "f") != {}


def test_bench_figures(tmp_path, record):
    rng = np.random.default_rng(0)
    st, hist = {}, {}
    for case, scale in (("sphere", 1e-8), ("griewank_shifted", 1e-2)):
        hist[case] = {}
        rows = {}
        for v in ("p1", "p3", "cmaes"):
            h = np.sort(rng.lognormal(0, 2, (6, 30)), axis=1)[:, ::-1] * np.geomspace(1, scale, 30)
            hist[case][v] = h
            rows[v] = statistics.summary(h[:, -1], rng.integers(5, 30, 6), 1e-3)
        st[case] = {"threshold": 1e-3, "rows": rows}
    bench_figs.draw(tmp_path, st, hist, 6)
    assert_clean(record)
    curves = dict(record)["convergence_curves"]
    assert all(ax.get_yscale() == "log" for ax in curves.axes if ax.get_visible() and ax.lines)
    # the same data as a record, through its archive: the same figures (``designopt report``)
    tree = {c: {"attrs": {"stats": st[c]}} | {v: {"history": h} for v, h in hist[c].items()}
            for c in hist}  # fmt: skip
    raw = {"bench": {"functions": ["sphere", "griewank"], "n_runs": 6}}
    attrs = {"kind": "bench", "config_resolved": raw, "seed": 0}
    with writer.session():
        archive.save(tmp_path / "b.h5", BenchRecord(attrs, {"bench": tree}))
    rec = records.load(tmp_path / "b.h5")
    assert isinstance(rec, BenchRecord) and rec.n_runs == 6
    assert list(rec.cases) == ["griewank_shifted", "sphere"]  # HDF5: sorted by name
    assert rec.case_names() == ["sphere", "griewank_shifted"]  # the config's order
    assert list(rec.histories("sphere")) == ["p1", "p3", "cmaes"]
    np.testing.assert_array_equal(rec.histories("sphere")["p3"], hist["sphere"]["p3"])
    paths = bench_figs.draw_record(rec, tmp_path / "again")
    assert {p.name for p in paths} == {p.name for p in tmp_path.glob("*.p[nd][gf]")}
    assert _pngs(tmp_path / "again") == _pngs(tmp_path)
