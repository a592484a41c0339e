"""Figures of a Pareto-front archive (designopt/figures/front.py, docs/figures.md): a real
NSGA-II front of the planar 2R arm (GCI and workspace area, both maximised; three
objectives with the manipulability), drawn and read back from the matplotlib artists:
the points are the archived front in the indices' own values, the bars are ± 2 SE, the
parallel coordinates lie in [0, 1] and match the box scaling, every other index of the
study is drawn against the first objective, the hypervolume history is that of the best
front found so far with the populations' beside it, every figure passes the shared
figure checks, and ``designopt report`` writes the PNGs."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np
import pytest
from figcheck import assert_clean
from matplotlib.collections import PathCollection
from matplotlib.container import ErrorbarContainer

import designopt
from designopt.figures import canvas
from designopt.figures import front as front_figs

ROOT = Path(__file__).resolve().parents[1]
BOX = {"l1": (0.2, 2.0), "l2": (0.2, 2.0)}  # configs/planar2r.yaml's design box


def _front(tmp: Path, pareto: dict[str, str]):
    jax.config.update("jax_enable_x64", True)
    cfg = designopt.load_config(ROOT / "configs/planar2r.yaml", {
        "optimizer.name": "nsga2", "optimizer.n_particles": 24, "optimizer.n_iters": 15,
        "study.indices.n_samples": 1024, "study.objective": {"pareto": pareto}})  # fmt: skip
    out = tmp / "front.h5"
    designopt.run(cfg, out=out)
    return out, designopt.load(out)


@pytest.fixture(scope="module")
def front2(tmp_path_factory):
    return _front(tmp_path_factory.mktemp("front2"), {"gci": "max", "volume": "max"})


@pytest.fixture(scope="module")
def front3(tmp_path_factory):
    return _front(tmp_path_factory.mktemp("front3"),
                  {"gci": "max", "volume": "max", "manipulability": "max"})  # fmt: skip


@pytest.fixture
def record():
    canvas.RECORD = []
    yield canvas.RECORD
    canvas.RECORD = None
    plt.close("all")


def _fig(record, name):
    (fig,) = [f for n, f in record if n == name]
    return fig


def _points(ax) -> np.ndarray:
    """Every front point drawn in a 2-D axes (the scatters named ``front:*``)."""
    pts = [c.get_offsets() for c in ax.collections
           if isinstance(c, PathCollection) and str(c.get_gid()).startswith("front:")]  # fmt: skip
    return np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in pts])


def _rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


def _bars(ax) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres (n, 2), x half-lengths, y half-lengths) of the axes' one error bar set."""
    (eb,) = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    assert eb.has_xerr and eb.has_yerr
    xs, ys = (np.asarray(lc.get_segments(), np.float64) for lc in eb.lines[2])
    centre = xs.mean(1)
    np.testing.assert_allclose(ys.mean(1), centre, rtol=1e-12)
    return centre, (xs[:, 1, 0] - xs[:, 0, 0]) / 2, (ys[:, 1, 1] - ys[:, 0, 1]) / 2


def test_two_objective_front_points_bars_pairs_and_labels(front2, record, tmp_path):
    _, rec = front2
    paths = front_figs.draw(rec, tmp_path)
    assert_clean(record)
    assert {p.name for p in paths} == {f"{n}.{e}" for n in ("front", "front_designs",
                                       "front_indices", "hypervolume") for e in ("png", "pdf")}  # fmt: skip
    assert all(p.stat().st_size > 0 for p in paths)
    # the front is in the indices' own values: a max objective is not negated
    F, se = rec.F, rec.F_se
    np.testing.assert_array_equal(F[:, 0], rec.values["gci"])
    np.testing.assert_array_equal(se[:, 1], rec.values["volume_se"])
    assert np.all(F > 0)
    ax = _fig(record, "front").axes[0]
    np.testing.assert_array_equal(_rows(_points(ax)), _rows(F))
    centre, hx, hy = _bars(ax)
    np.testing.assert_array_equal(centre, F)
    np.testing.assert_allclose(hx, 2 * se[:, 0], rtol=1e-9)
    np.testing.assert_allclose(hy, 2 * se[:, 1], rtol=1e-9)
    # ambiguous pairs: recomputed from F and SE (|ΔF| ≤ 2 √(se_i² + se_j²) in some objective)
    d = np.abs(F[:, None] - F[None])
    close = np.any(d <= 2 * np.sqrt(se[:, None] ** 2 + se[None] ** 2), -1)
    i, j = np.nonzero(np.triu(close, 1))
    np.testing.assert_array_equal(rec.ambiguous, np.stack([i, j], -1))
    (amb,) = [c for c in ax.collections if c.get_gid() == "ambiguous"]
    seg = np.asarray(amb.get_segments(), np.float64)
    np.testing.assert_array_equal(seg, np.stack([F[i], F[j]], 1))
    assert ax.get_xlabel() == "gci (max) [-]" and ax.get_ylabel() == "volume (max) [L^2]"
    title = _fig(record, "front")._suptitle.get_text()
    assert "± 2 SE" in title and f"{rec.n_samples} fresh samples" in title
    assert rec.n_samples == 4 * 1024  # front.n_samples defaults to 4 × the study's


def test_parallel_coordinates_scale_to_the_box_and_the_front(front2, record, tmp_path):
    _, rec = front2
    front_figs.designs(rec, tmp_path, {"l1": "L", "l2": "L", "gci": "-", "volume": "L^2"})
    assert_clean(record)
    fig = _fig(record, "front_designs")
    (lc,) = [c for c in fig.axes[0].collections if c.get_gid() == "designs"]
    seg = np.asarray(lc.get_segments(), np.float64)  # (n, D + m, 2)
    n, m = rec.F.shape
    assert seg.shape == (n, 2 + m, 2)
    np.testing.assert_array_equal(seg[..., 0], np.broadcast_to(np.arange(2.0 + m), (n, 2 + m)))
    y = seg[..., 1]
    assert np.all((y >= 0) & (y <= 1))
    lo = np.array([BOX[k][0] for k in rec.names])
    hi = np.array([BOX[k][1] for k in rec.names])
    np.testing.assert_array_equal(rec.lower, lo)
    np.testing.assert_array_equal(rec.upper, hi)
    np.testing.assert_allclose(y[:, :2], (rec.X - lo) / (hi - lo), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(y[:, 2:].min(0), 0.0, atol=1e-15)
    np.testing.assert_allclose(y[:, 2:].max(0), 1.0, rtol=1e-15)
    np.testing.assert_allclose(np.argsort(y[:, 2], kind="stable"),
                               np.argsort(rec.F[:, 0], kind="stable"))  # fmt: skip
    np.testing.assert_array_equal(np.asarray(lc.get_array()), rec.F[:, 0])
    (cb,) = [a for a in fig.axes if getattr(a, "_colorbar", None) is not None]
    assert cb.get_ylabel() == "gci (max) [-]"


def _wide(rec, k: int):
    """``rec`` with its design variables repeated ``k`` times under long names (no new
    run: the same front, more and longer axes to lay out)."""
    g = dict(rec.groups)
    pr, fr = dict(g["problem"]), dict(g["front"])
    D = len(rec.names)
    pr["names"] = np.array([f"arm{i}_joint_{j}.origin.xyz_offset" for i in range(k) for j in range(D)])
    pr["lower"], pr["upper"] = np.tile(rec.lower, k), np.tile(rec.upper, k)
    fr["x"] = np.tile(rec.X, k)
    return dataclasses.replace(rec, groups=g | {"problem": pr, "front": fr})


def test_parallel_coordinates_labels_read(front2, record, tmp_path):
    """Every text of ``front_designs`` lies inside the figure and overlaps no other (the
    figure checker's text test), with the study's two variables and with twelve long
    names, whose labels are turned to fit; the HTML twin turns its axis names too, with
    short numbers on its axes."""
    from figcheck import text_problems

    from designopt.figures.html.front import _front
    from designopt.figures.html.model import _Ids

    _, rec = front2
    units = {"gci": "-", "volume": "L^2"}
    for r, turned in ((rec, False), (_wide(rec, 6), True)):
        record.clear()
        front_figs.designs(r, tmp_path, units | {k: "L" for k in r.names})
        fig = _fig(record, "front_designs")
        assert text_problems(fig) == []
        ax = fig.axes[0]
        assert len(ax.get_xticklabels()) == len(r.names) + 2
        assert {t.get_rotation() != 0 for t in ax.get_xticklabels()} == {turned}
        assert fig.get_figwidth() <= 16.0
        (sec,) = _front(r.to_tree(), _Ids(), dict(units))
        (tr,) = [p.fig["data"][0] for p in sec.items
                 if getattr(p, "fig", None) and p.fig["data"][0]["type"] == "parcoords"]  # fmt: skip
        if turned:  # twelve long names do not fit side by side
            assert tr["labelangle"] != 0
        assert {d["tickformat"] for d in tr["dimensions"]} == {".4~g"}


def test_hypervolume_runs_median_unit_and_reference(front2, record, tmp_path):
    _, rec = front2
    front_figs.hypervolume(rec, tmp_path, {"gci": "-", "volume": "L^2"})
    assert_clean(record)
    fig = _fig(record, "hypervolume")
    ax = fig.axes[0]
    H = rec.history
    runs = [ln for ln in ax.lines if ln.get_gid() == "run"]
    assert len(runs) == H.shape[0] == 2 and H.shape[1] == 16  # 15 iterations + the start
    for ln, h in zip(runs, H, strict=True):
        np.testing.assert_array_equal(ln.get_ydata(), h)
        np.testing.assert_array_equal(ln.get_xdata(), np.arange(16))
    (med,) = [ln for ln in ax.lines if ln.get_gid() == "median"]
    np.testing.assert_array_equal(med.get_ydata(), np.median(H, 0))
    assert med.get_linewidth() > 2 * runs[0].get_linewidth()
    # the best front found so far never loses volume; the populations' own is beside it
    assert np.all(np.diff(H, axis=1) >= 0)
    pop = rec.population_history
    assert pop.shape == H.shape and np.all(H >= pop)
    (pl,) = [ln for ln in ax.lines if ln.get_gid() == "population"]
    np.testing.assert_array_equal(pl.get_ydata(), np.median(pop, 0))
    assert "best front found so far" in fig._suptitle.get_text()
    assert ax.get_ylabel() == "hypervolume [L^2]"
    title = fig._suptitle.get_text()
    assert f"gci = {rec.reference[0]:.4g}" in title
    assert f"volume = {rec.reference[1]:.4g}" in title


def test_every_other_index_against_the_first_objective(front2, front3, record, tmp_path):
    """``front_indices``: one panel per index that is not an objective (the planar arm's
    gcsei and manipulability beside gci and volume), its re-scored values ± 2 SE against
    the first objective; none when every index is an objective."""
    _, rec = front2
    others = rec.indices
    own = {k for k in rec.values if not k.endswith("_se")}
    assert set(others) == own - set(rec.objectives) and {"gcsei", "manipulability"} <= set(others)
    front_figs.indices(rec, tmp_path, rec.units())
    assert_clean(record)
    panels = [ax for ax in _fig(record, "front_indices").axes if ax.axison]
    assert len(panels) == len(others)
    for ax, k in zip(panels, others, strict=True):
        assert ax.get_ylabel().split(" [")[0] == k and ax.get_xlabel() == "gci (max) [-]"
        want = np.stack([rec.F[:, 0], rec.values[k]], -1)
        np.testing.assert_array_equal(_rows(_points(ax)), _rows(want))
        centre, hx, hy = _bars(ax)
        np.testing.assert_array_equal(centre, want)
        np.testing.assert_allclose(hx, 2 * rec.F_se[:, 0], rtol=1e-9)
        np.testing.assert_allclose(hy, 2 * rec.values[k + "_se"], rtol=1e-9)
    _, rec3 = front3  # three objectives: what is left is gcsei alone
    assert rec3.indices == ["gcsei"]
    front_figs.indices(rec3, tmp_path, rec3.units())
    assert_clean(record)
    # every index an objective: no figure
    g = {k: dict(v) if isinstance(v, dict) else v for k, v in rec.groups.items()}
    g["front"] = {k: v for k, v in g["front"].items()
                  if k.removesuffix("_se") not in others}  # fmt: skip
    alt = dataclasses.replace(rec, groups=g)
    assert alt.indices == [] and front_figs.indices(alt, tmp_path, {}) == []


def test_three_objectives_pairwise_and_3d(front3, record, tmp_path):
    _, rec = front3
    paths = front_figs.draw(rec, tmp_path)
    assert_clean(record)
    assert {p.name for p in paths} >= {"front_3d.png", "front_3d.pdf"}
    F, se = rec.F, rec.F_se
    assert F.shape[1] == 3
    panels = [ax for ax in _fig(record, "front").axes if ax.axison]
    assert len(panels) == 3  # (gci, volume), (gci, manip.), (volume, manip.)
    pairs = {(ax.get_xlabel().split()[0], ax.get_ylabel().split()[0]): ax for ax in panels}
    names = list(rec.objectives)
    assert set(pairs) == {(names[a], names[b]) for a in range(3) for b in range(a + 1, 3)}
    for (a, b), ax in pairs.items():
        i, j = names.index(a), names.index(b)
        np.testing.assert_array_equal(_rows(_points(ax)), _rows(F[:, [i, j]]))
        _, hx, hy = _bars(ax)
        np.testing.assert_allclose(hx, 2 * se[:, i], rtol=1e-9)
        np.testing.assert_allclose(hy, 2 * se[:, j], rtol=1e-9)
    ax3 = _fig(record, "front_3d").axes[0]
    pts = np.concatenate([np.stack([np.asarray(v, np.float64) for v in c._offsets3d], -1)
                          for c in ax3.collections
                          if str(c.get_gid()).startswith("front:")])  # fmt: skip
    np.testing.assert_array_equal(_rows(pts), _rows(F))
    assert ax3.get_zlabel() == "manipulability (max) [L^2]"


def test_dominated_and_infeasible_designs_are_marked(front2, record, tmp_path):
    """Designs that re-scoring ranks > 0 or finds infeasible are drawn apart (the
    record altered: the planar arm has no constraint and its front is all rank 0)."""
    _, rec = front2
    n = len(rec.F)
    g = {k: dict(v) if isinstance(v, dict) else v for k, v in rec.groups.items()}
    rank = np.zeros(n, np.int64)
    rank[[1, 4]] = 1
    viol = np.zeros(n)
    viol[[2]] = 0.5
    g["front"] = g["front"] | {"rank": rank, "violation": viol, "violation_se": np.zeros(n)}
    alt = dataclasses.replace(rec, groups=g)
    front_figs.draw(alt, tmp_path)
    assert_clean(record)
    ax = _fig(record, "front").axes[0]
    by = {c.get_gid(): np.asarray(c.get_offsets(), np.float64) for c in ax.collections
          if str(c.get_gid()).startswith("front:")}  # fmt: skip
    np.testing.assert_array_equal(by["front:dominated"], rec.F[[1, 4]])
    np.testing.assert_array_equal(by["front:infeasible"], rec.F[[2]])
    np.testing.assert_array_equal(by["front:rank0"], np.delete(rec.F, [1, 2, 4], 0))
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "dominated after re-scoring: 2" in labels and "infeasible: 1" in labels
    (lc,) = [c for c in _fig(record, "front_designs").axes[0].collections
             if c.get_gid() == "designs"]  # fmt: skip
    dashed = [ls[1] is not None for ls in lc.get_linestyles()]
    assert [i for i, d in enumerate(dashed) if d] == [1, 2, 4]


def test_unit_of_a_hypervolume():
    up = front_figs.unit_product
    assert up(["-", "L^2"]) == "L^2"
    assert up(["mm", "mm³"]) == "mm⁴"
    assert up(["L", "L^2", "-"]) == "L^3"
    assert up(["mm", "g"]) == "mm·g"
    assert up(["mm/s", "mm"]) == "(mm/s)·mm"
    assert up(["-", ""]) == "-"
    assert up(["L^2", "mixed"]) == "mixed"


def test_report_command_draws_the_front_pngs(front2, tmp_path):
    from designopt.cli.commands import main

    path, _ = front2
    arch = tmp_path / "front.h5"
    arch.write_bytes(path.read_bytes())
    assert main(["report", str(arch)]) in (0, None)
    folder = tmp_path / "front_figures"
    for name in ("front", "front_designs", "front_indices", "hypervolume"):
        for ext in ("png", "pdf"):
            assert (folder / f"{name}.{ext}").stat().st_size > 0
