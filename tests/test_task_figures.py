"""The serial study's task figure and task cloud (docs/figures.md, docs/task.md): a tiny
task run of the planar 2R arm whose design box cannot reach the whole disk, drawn and
read back. The figure's points are the run's targets, coloured by 1/k at the final
design's IK solution, unreached ones as crosses; the report's cloud holds the same, and
its 1/k equals the 2R closed form at the solved joints, whose forward kinematics hits
the targets; every target beyond l1 + l2 is flagged; the means are the archive's
final reach and gci."""

from __future__ import annotations

from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np
import pytest
from figcheck import assert_clean
from PIL import Image

import designopt
from designopt.figures import canvas, html
from designopt.studies.serial import blocks, drawing, report
from designopt.studies.serial import figures as serial_figs

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A short run (about 15 s on 2 cores) whose box (l1 + l2 ≤ 1.4) leaves part of the
    disk (centre 1.2, radius 0.5) out of reach."""
    jax.config.update("jax_enable_x64", True)
    cfg = designopt.load_config(ROOT / "configs/planar2r_task.yaml", {
        "study.variables": {"l1": [0.4, 0.8], "l2": [0.3, 0.6]}, "study.constraints": [],
        "study.indices.n_samples": 256, "study.task.ik.n_db": 128,
        "optimizer.n_particles": 4, "optimizer.n_iters": 2, "optimizer.n_runs": 1})  # fmt: skip
    out = tmp_path_factory.mktemp("task") / "task.h5"
    designopt.run(cfg, out=out)
    return out, designopt.load(out)


@pytest.fixture
def record():
    canvas.RECORD = []
    yield canvas.RECORD
    canvas.RECORD = None
    plt.close("all")


def _final(rec):
    """(study settings, x, keys) of the samples the record's final/ values are on (the
    fresh final stream: what the figures draw)."""
    s, keys = rec.final_stream()
    return s, rec.x, keys


def _inv_k_2r(l1: float, l2: float, q2: np.ndarray) -> np.ndarray:
    """σmin/σmax of the planar 2R position Jacobian: σ1σ2 = |det J| = l1 l2 |sin q2| and
    σ1² + σ2² = ‖J‖_F² = l1² + 2 l2² + 2 l1 l2 cos q2, so 1/k = |det J|/σmax²."""
    d = l1 * l2 * np.abs(np.sin(q2))
    f2 = l1**2 + 2 * l2**2 + 2 * l1 * l2 * np.cos(q2)
    smax2 = (f2 + np.sqrt(np.maximum(f2**2 - 4 * d**2, 0.0))) / 2
    return d / smax2


def test_cloud_is_the_final_design_at_its_ik_solutions(run):
    _, rec = run
    l1, l2 = rec.x["l1"], rec.x["l2"]
    c = serial_figs.cloud(rec)
    sol = blocks.solution(*_final(rec))
    p, ok, flag = c["xyz"], ~c["flag"], c["flag"]
    N = len(p)
    assert N == 1024 and p.shape == (N, 3) and np.all(p[:, 2] == 0)  # final.n_samples: 4 × 256
    np.testing.assert_array_equal(p, sol["target_p"])
    r = np.hypot(p[:, 0], p[:, 1])
    assert flag[r > l1 + l2 + 1e-9].all() and (r > l1 + l2).sum() > 20  # out of reach
    assert ok.sum() > N / 2
    q = sol["q"]
    fk = np.stack([l1 * np.cos(q[:, 0]) + l2 * np.cos(q.sum(1)),
                   l1 * np.sin(q[:, 0]) + l2 * np.sin(q.sum(1))], -1)  # fmt: skip
    assert np.max(np.abs(fk[ok] - p[ok, :2])) < 1e-8  # reached: the joints hit the target
    np.testing.assert_allclose(c["value"][ok], _inv_k_2r(l1, l2, q[ok, 1]), rtol=1e-9, atol=1e-12)
    assert np.isnan(c["value"][flag]).all()
    assert 1 - flag.mean() == rec.indices["reach"][0]  # the archive's final indices
    assert np.nan_to_num(c["value"]).mean() == pytest.approx(rec.indices["gci"][0], abs=1e-12)
    assert c["xyz_unit"] == "L" and c["unit"] == "-"
    # the report draws the reached targets coloured, the unreached ones as crosses
    (sec,) = [s for s in html.sections(rec.to_tree(), cloud=c) if s.id == "cloud"]
    tr, cross = sec.plots()[0].fig["data"]
    np.testing.assert_array_equal(np.c_[tr["x"], tr["y"], tr["z"]], p[ok])
    np.testing.assert_array_equal(tr["marker"]["color"], c["value"][ok])
    np.testing.assert_array_equal(np.c_[cross["x"], cross["y"], cross["z"]], p[flag])
    assert cross["marker"]["symbol"] == "cross" and cross["name"] == "unreached"


def test_task_figure_shows_targets_by_inv_k_and_unreached(run, record, tmp_path):
    out, rec = run
    paths = serial_figs.draw_run(rec, tmp_path / "figs")
    names = sorted(p.name for p in paths)
    assert names == sorted(f"{n}.{e}" for n in ("convergence", "task", "workspace")
                           for e in ("png", "pdf"))  # fmt: skip  # no joint-space map
    assert_clean(record)
    png = tmp_path / "figs" / "task.png"
    im = np.asarray(Image.open(png).convert("RGB"))
    assert png.stat().st_size > 20_000 and im.shape[0] > 400 and im.shape[1] > 400
    assert len(np.unique(im.reshape(-1, 3), axis=0)) > 100  # a colour map, not a blank
    (fig,) = [f for n, f in record if n == "task"]
    (ax,) = [a for a in fig.axes if not hasattr(a, "_colorbar")]
    dots, crosses = ax.collections
    sol = blocks.solution(*_final(rec))
    ok = sol["success"]
    p = sol["target_p"]
    got = dots.get_offsets()
    order = np.lexsort(got.T)
    want = np.lexsort(p[ok, :2].T)
    np.testing.assert_array_equal(got[order], p[ok][want, :2])  # x, y: the disk's plane
    np.testing.assert_array_equal(dots.get_array()[order], sol["inv_k"][ok][want])
    assert np.all(np.diff(dots.get_array()) <= 0)  # the least dexterous drawn last, on top
    np.testing.assert_array_equal(np.sort(crosses.get_offsets(), 0), np.sort(p[~ok, :2], 0))
    assert ax.get_xlabel() == "x [L]" and ax.get_ylabel() == "y [L]"
    title = " ".join(fig._suptitle.get_text().split())  # lines wrapped at 90 characters
    (reach, rse), (gci, gse) = rec.indices["reach"], rec.indices["gci"]
    assert f"reach {reach:.3f} ± {rse:.2g}" in title and f"gci {gci:.3f} ± {gse:.2g}" in title
    assert f"unreached (grey crosses): {(~ok).sum()}" in title and "archive" not in title
    assert not (tmp_path / "figs" / "dexterity_map.png").exists()


def test_plane_finds_the_targets_plane():
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, (200, 3))
    box_xz = u * [0.2, 0.0, 0.3] + [1, 2, 3]
    E, names = serial_figs.plane(box_xz)
    assert names == ("x", "z")
    np.testing.assert_array_equal(E, np.eye(3)[:, [0, 2]])
    n = np.array([1.0, 2.0, 2.0]) / 3  # a tilted disk: u, v span it, orthonormal
    E0 = np.linalg.svd(np.eye(3) - np.outer(n, n))[0][:, :2]
    disk = u[:, :2] @ E0.T + [0.5, 0, 0]
    E, names = serial_figs.plane(disk)
    assert names == ("u", "v")
    np.testing.assert_allclose(E.T @ E, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(E.T @ n, 0, atol=1e-12)
    assert serial_figs.plane(u) is None  # a solid region: two projections instead


def _fk_2r(l1: float, l2: float, q: np.ndarray) -> np.ndarray:
    """The planar 2R's drawn joints: base origin, joint 1, joint 2, tip (x, y)."""
    e = np.array([l1 * np.cos(q[0]), l1 * np.sin(q[0])])
    return np.array([[0, 0], [0, 0], e, e + [l2 * np.cos(q[0] + q[1]), l2 * np.sin(q[0] + q[1])]])


def test_task_figure_draws_the_arm_at_its_representative_targets(run, record, tmp_path):
    """The arm at the worst-conditioned, median and best-conditioned reached targets: its
    drawn joints are the 2R's FK at the IK solution and its tip is the target; the disk's
    outline is drawn; the legend gives each arm's 1/k."""
    _, rec = run
    serial_figs.draw_task(rec, tmp_path)
    (fig,) = [f for n, f in record if n == "task"]
    (ax,) = [a for a in fig.axes if not hasattr(a, "_colorbar")]
    sol = blocks.solution(*_final(rec))
    ok, ik = sol["success"], sol["inv_k"]
    reps = drawing.representatives(sol)
    assert [n for n, _ in reps] == ["worst-conditioned", "median", "best-conditioned"]
    (_, w), (_, m), (_, b) = reps
    assert ok[[w, m, b]].all() and ik[w] == ik[ok].min() and ik[b] == ik[ok].max()
    assert ik[m] == np.sort(ik[ok])[(ok.sum() - 1) // 2]
    for k, (_, i) in enumerate(reps):
        (line,) = [ln for ln in ax.lines if ln.get_gid() == f"arm{k}-joints"]
        want = _fk_2r(rec.x["l1"], rec.x["l2"], sol["q"][i])
        np.testing.assert_allclose(np.stack(line.get_data(), -1), want, atol=1e-12)
        assert np.abs(want[-1] - sol["target_p"][i, :2]).max() < 1e-8  # it reaches the target
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert f"best-conditioned: 1/k = {ik[b]:.3g}" in labels and "unreached" in labels
    rim = [ln for ln in ax.lines if len(ln.get_xdata()) == 49]  # the disk's outline
    assert rim and np.allclose(np.hypot(rim[0].get_xdata() - 1.2, rim[0].get_ydata()), 0.5)


def test_task_report_slider_moves_the_arm(run, tmp_path):
    """The report's robot view: one slider step per 1/k quantile of the reached targets,
    each pose the 2R's FK at that target's solution (its tip on the target); in headless
    Chromium the page draws without console errors, the 3-D view has a WebGL canvas with
    a size, and the slider's last step draws the arm at the best target."""
    from test_html_report import CHROMIUM, Browser

    from designopt.app import reporting
    from designopt.figures.html import robot as hrobot

    out, rec = run
    sol = blocks.solution(*_final(rec))
    view = report.run_view(rec)
    picks = drawing.slider_targets(sol)
    assert [p.label for p in view.poses] == [lab for lab, _ in picks] and len(picks) >= 5
    for p, (_, i) in zip(view.poses, picks, strict=True):
        want = _fk_2r(rec.x["l1"], rec.x["l2"], sol["q"][i])
        np.testing.assert_allclose(p.arms[0].points()[:, :2], want, atol=1e-12)
        np.testing.assert_allclose(p.mark, sol["target_p"][i], atol=1e-8)
    plot = hrobot.view_plot(view, html.model._Ids())
    assert len(plot.fig["frames"]) == len(picks) == len(plot.fig["layout"]["sliders"][0]["steps"])
    page = reporting.write_html(out)
    print(f"task page: {page.stat().st_size / 1e6:.2f} MB")
    assert page.stat().st_size < 10e6
    if CHROMIUM is None:
        pytest.skip("chromium is not installed; the page was not opened in a browser")
    b = Browser(tmp_path / "profile", tmp_path / "chromium.log")
    try:
        b.load(page, timeout=60)
        assert b.errors() == []
        rid = b.js("document.querySelector('div.plot[id$=\"-robot\"]').id")
        assert max(b.js(f"Array.from(document.getElementById('{rid}').querySelectorAll("
                        "'canvas')).map(c => c.width * c.height)")) > 0  # fmt: skip
        last = view.poses[-1].label
        got = b.js(f"""(async () => {{ const g = document.getElementById('{rid}');
            await Plotly.animate(g, [{last!r}], {{mode: 'immediate', frame: {{duration: 0,
                redraw: true}}, transition: {{duration: 0}}}});
            const t = g._fullData.find(t => t.name === 'final design: joints');
            return [Array.from(t.x), Array.from(t.y)]; }})()""")  # fmt: skip
        np.testing.assert_allclose(np.array(got).T, view.poses[-1].arms[0].points()[:, :2],
                                   atol=1e-12)  # fmt: skip
        assert b.errors() == []
        shots = Path("/tmp/view_shots")
        if shots.is_dir():
            b.screenshot(shots / "task_page.png")
    finally:
        b.close()
