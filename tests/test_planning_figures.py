"""Figures that fit a planning study (issue 53): the shipped planning case
(configs/port_placement.yaml: two UR5s with instruments through ports, a vessel and an
organ inside the patient), run tiny and single-objective, drawn as a surgeon would look
at it. The 3-D views open on the tuple of targets of median gap between the arms (the
gap recomputed here in NumPy from the solution's capsules) and count the colliding
tuples (the count the archive's arms_free and arms_ok imply); robot.png is one panel
when no link geometry is a variable; workspace.png plots the task's targets; the
convergence figure is a grid of at most 4 columns; the anatomy is drawn opaque and
outlined, a mesh from its triangles; ``designopt view`` draws the arms solved at the
task, each tip on its target; the HTML view's caption has no join glitches."""

from __future__ import annotations

import re
from pathlib import Path

import jax
import numpy as np
import pytest
import trimesh
from figcheck import assert_clean

import designopt
from designopt.cli.commands import main
from designopt.figures import convergence
from designopt.figures.robot import ANATOMY
from designopt.studies.serial import blocks, report, taskindex
from designopt.studies.serial import figures as serial_figs
from designopt.studies.serial.mechanism import build

ROOT = Path(__file__).resolve().parents[1]
PORTS = ROOT / "configs/port_placement.yaml"
N = 32  # targets: tuples of one target per arm
RUN = {"study.objective": {"arms_ok": -1.0, "gci": -1.0}, "study.indices.n_samples": N,
       "final.n_samples": N,  # the final design is quoted (and drawn) on N fresh tuples
       "optimizer": {"name": "ptpso", "n_particles": 2, "n_iters": 1, "n_runs": 1}}  # fmt: skip


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny single-objective run of the planning case, its record and solution."""
    jax.config.update("jax_enable_x64", True)
    cfg = designopt.load_config(PORTS, RUN)
    out = tmp_path_factory.mktemp("pp") / "pp.h5"
    designopt.run(cfg, out=out)
    rec = designopt.load(out)
    s, keys = rec.final_stream()  # the fresh samples final/ and the figures are on
    return out, rec, blocks.solution(s, rec.x, keys)


def _samples(rec):
    """The samples key of the stream the final design is quoted and drawn on."""
    return rec.final_stream()[1]["samples"]


@pytest.fixture(autouse=True, scope="module")
def _no_figure_left_open():
    """Whatever this module's tests leave open (a recorded figure, a view's) is closed
    after them: a later module in this worker counts the open figures."""
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


@pytest.fixture(scope="module")
def drawn(run, tmp_path_factory):
    """The run's figures, kept as matplotlib figures by name."""
    from designopt.figures import canvas

    _, rec, _ = run
    kept: list = []
    old = canvas.RECORD
    canvas.RECORD = kept
    try:
        serial_figs.draw_run(rec, tmp_path_factory.mktemp("figs"))
    finally:
        canvas.RECORD = old
    assert_clean(kept)  # labels with units, no text over another
    yield dict(kept)
    import matplotlib.pyplot as plt

    for _, f in kept:  # kept open for the tests (canvas.RECORD): closed after them, so no
        plt.close(f)   # later module of this worker finds them open


def _seg_dist(p0, p1, q0, q1, n: int = 400) -> float:
    """Distance between segments p0-p1 and q0-q1: exact over a dense sampling of one
    segment, each sample's exact distance to the other segment (NumPy)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    P = p0 + t * (p1 - p0)
    d = q1 - q0
    dd = float(d @ d)
    s = np.clip(((P - q0) @ d) / dd, 0.0, 1.0) if dd > 0 else np.zeros(n)
    return float(np.min(np.linalg.norm(P - (q0 + s[:, None] * d), axis=1)))


def _gaps(rec, sol):
    """(the tuples every arm reaches (N,), the least surface gap between the two arms'
    capsules per tuple, the margin), recomputed in NumPy from the solution's segments."""
    from designopt.studies.serial import bodies

    s = rec.config.study
    g = bodies.geometry(s, build(s))
    key = jax.random.fold_in(_samples(rec), 2)
    lab = taskindex.labels(N, taskindex.groups(s))
    perm = [np.asarray(p) for p in taskindex.perms(key, N, lab, 2)]
    ok = np.asarray(sol["success"], bool)
    both = ok[0][perm[0]] & ok[1][perm[1]]
    seg = [np.asarray(sol["segments"])[k][perm[k]] for k in range(2)]
    r = np.asarray(g.radii)
    gap = np.full(N, np.inf)
    for j in np.flatnonzero(both):
        gap[j] = min(_seg_dist(*seg[0][j, a], *seg[1][j, b]) - r[a] - r[b]
                     for a in range(len(r)) for b in range(len(r)))  # fmt: skip
    return both, gap, g.margin


def test_views_open_on_the_median_tuple_and_count_the_collisions(run, drawn):
    """The task figure's 3-D panel, robot.png and the report's robot view show the tuple
    of median gap (NumPy's gaps: its gap is their lower median, to the sampling's
    error); the count of colliding tuples in their titles equals NumPy's and the one the
    archive implies (arms_free_n − arms_ok · N); the tightest tuple is the next step."""
    _, rec, sol = run
    both, gap, margin = _gaps(rec, sol)
    R = int(both.sum())
    assert R >= 3, "the test needs a few tuples both arms reach"
    med = np.sort(gap[both])[(R - 1) // 2]
    colliding = int(np.sum(gap[both] < margin))
    archive = rec.indices["arms_free_n"][0] - rec.indices["arms_ok"][0] * N
    assert colliding == round(archive)
    assert R == rec.indices["arms_free_n"][0]
    task3 = next(a for a in drawn["task"].axes if hasattr(a, "get_zlim"))
    robot3 = next(a for a in drawn["robot"].axes if hasattr(a, "get_zlim"))
    for title in (task3.get_title(), robot3.get_title()):
        j = int(re.search(r"median tuple (\d+)", title).group(1))
        assert abs(gap[j] - med) < 2e-4, (title, gap[j], med)
        assert f"{colliding} of {N} tuples collide" in title, title
        tight = int(re.search(r"the tightest: tuple (\d+)", title).group(1))
        assert gap[tight] == pytest.approx(np.min(gap[both]), abs=2e-4)
    view = report.run_view(rec)
    assert view.poses[0].label.startswith(f"median tuple {j}:")
    assert f"({colliding} of {N} tuples collide" in view.poses[0].label
    if tight != j:
        assert view.poses[1].label.startswith(f"tightest tuple {tight}:")


def test_robot_png_is_one_panel_when_no_link_geometry_is_a_variable(run, drawn):
    """No ``set`` field (only bases and ports are variables): one 3-D panel, the final
    design at the median tuple, each arm's tip on its target (stars), with the ports
    and the anatomy."""
    _, rec, sol = run
    fig = drawn["robot"]
    axes3 = [a for a in fig.axes if hasattr(a, "get_zlim")]
    assert len(axes3) == 1
    (ax,) = axes3
    tips = [ln.get_data_3d() for ln in ax.get_lines() if str(ln.get_gid()).endswith("-joints")]
    assert len(tips) == 2
    j = int(re.search(r"median tuple (\d+)", ax.get_title()).group(1))
    key = jax.random.fold_in(_samples(rec), 2)
    lab = taskindex.labels(N, taskindex.groups(rec.config.study))
    p1 = int(np.asarray(taskindex.perms(key, N, lab, 2)[1])[j])
    targets = np.asarray(sol["target_p"])[[j, p1]]
    for (x, y, z), t in zip(tips, targets, strict=True):
        np.testing.assert_allclose([x[-1], y[-1], z[-1]], t, atol=1e-4)
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {"port", "anatomy (inside the patient)"} <= set(legend)


def test_workspace_of_a_port_task_plots_the_targets(run, drawn):
    """workspace.png of a port task: the scatters hold exactly the task's targets (the
    final design's, drawn from the fresh final stream), the reached ones coloured by the arms' mean
    1/k; no cloud of joint draws."""
    from designopt.studies.serial import taskindex

    _, rec, sol = run
    s, keys = rec.final_stream()
    want = np.asarray(taskindex.targets(s, keys["samples"], np.float64)["target_p"])
    ax = next(a for a in drawn["workspace"].axes if hasattr(a, "get_zlim"))
    pts = [np.column_stack(c._offsets3d) for c in ax.collections if hasattr(c, "_offsets3d")
           and len(c._offsets3d[0]) > 2]  # fmt: skip
    got = np.vstack(pts)
    assert got.shape == want.shape
    np.testing.assert_allclose(got[np.lexsort(got.T)], want[np.lexsort(want.T)], atol=1e-12)
    ok = np.all(np.asarray(sol["success"], bool), 0)
    colored = next(c for c in ax.collections if hasattr(c, "_offsets3d") and c.get_array() is not None)
    np.testing.assert_allclose(np.sort(colored.get_array()),
                               np.sort(np.mean(np.asarray(sol["inv_k"]), 0)[ok]), atol=1e-12)


def test_anatomy_stands_out_and_a_mesh_is_drawn_from_its_triangles(run, drawn):
    """The organ (configs/data/organ.stl) is drawn from every one of its triangles, in
    the anatomy's colour, opaque (alpha ≥ 0.6) and outlined; the vessel's axis is a
    line; in the report's view too (opacity ≥ 0.8)."""
    from matplotlib.colors import rgb_to_hsv, to_rgba

    from designopt.figures.html import robot as hrobot
    from designopt.figures.html.model import _Ids

    _, rec, _ = run
    organ = trimesh.load(ROOT / "configs/data/organ.stl", force="mesh")
    ax = next(a for a in drawn["workspace"].axes if hasattr(a, "get_zlim"))
    hue = rgb_to_hsv(to_rgba(ANATOMY)[:3])[0]  # shading darkens the faces, keeps their hue
    anat = [c for c in ax.collections if not hasattr(c, "_offsets3d") and len(c.get_facecolor())
            and abs(rgb_to_hsv(c.get_facecolor()[0][:3])[0] - hue) < 0.03]  # fmt: skip
    assert len(anat) == 2  # the vessel and the organ
    assert any(len(c.get_paths()) == len(organ.faces) for c in anat)
    assert all(c.get_alpha() >= 0.6 and c.get_linewidths()[0] > 0 for c in anat)
    plot = hrobot.view_plot(report.run_view(rec), _Ids())
    traces = plot.fig["data"]
    org = next(t for t in traces if "organ.stl" in t.get("name", "") and t["type"] == "mesh3d")
    assert len(org["i"]) == len(organ.faces) and org["opacity"] >= 0.8
    assert any(t["type"] == "scatter3d" and "capsule" in t.get("name", "") for t in traces)


def test_convergence_is_a_grid_of_at_most_four_columns(tmp_path):
    """17 indices: 5 rows of at most 4 panels, each panel the index's own values."""
    from designopt.figures import canvas

    it = np.arange(6)
    names = [f"i{k}" for k in range(17)]
    best = {"iteration": it} | {n: np.sin(it + k) for k, n in enumerate(names)}
    kept: list = []
    old, canvas.RECORD = canvas.RECORD, kept
    try:
        convergence(best, names, tmp_path, "t")
    finally:
        canvas.RECORD = old
    (_, fig), = kept
    import matplotlib.pyplot as plt

    plt.close(fig)  # recorded figures stay open; its axes stay readable
    axes = fig.axes
    assert len(axes) == 17
    cols = {a.get_subplotspec().colspan.start for a in axes}
    rows = {a.get_subplotspec().rowspan.start for a in axes}
    assert max(cols) <= 3 and len(rows) == 5
    for a, n in zip(axes, names, strict=True):
        np.testing.assert_allclose(a.get_lines()[0].get_ydata(), best[n])


def test_view_of_a_port_config_draws_the_arms_at_a_solved_tuple(tmp_path, capsys):
    """``designopt view`` of the planning case (no --q): the arms at the tuple of median
    gap of the config's targets, each tip on its target (the stars); the title says so
    and counts the colliding tuples; the HTML caption has no "=;" or "-;" glitch."""
    from designopt.figures import canvas

    out, page = tmp_path / "v.png", tmp_path / "v.html"
    kept: list = []
    old, canvas.RECORD = canvas.RECORD, kept
    try:
        assert main(["view", str(PORTS), "--set", f"study.indices.n_samples={N}",
                     "--design", "b=0.6", "by=0", "px=0.06", "py0=0", "py1=0",
                     "--out", str(out), "--html", str(page)]) == 0  # fmt: skip
    finally:
        canvas.RECORD = old
    (_, fig), = kept
    title = fig.texts[0].get_text() if fig.texts else fig._suptitle.get_text()
    assert "median tuple" in title and "tuples collide" in title and "home pose" not in title
    (ax,) = [a for a in fig.axes if hasattr(a, "get_zlim")]
    tips = [np.array(ln.get_data_3d())[:, -1] for ln in ax.get_lines()
            if str(ln.get_gid()).endswith("-joints")]  # fmt: skip
    stars = [np.array(c._offsets3d).ravel() for c in ax.collections
             if hasattr(c, "_offsets3d") and c.get_paths() and len(c._offsets3d[0]) == 1
             and c.get_sizes()[0] == 90]  # fmt: skip
    assert len(tips) == 2 and len(stars) == 2
    for t, st in zip(tips, stars, strict=True):
        np.testing.assert_allclose(t, st, atol=1e-4)
    html = page.read_text()
    cap = re.search(r"<figcaption>([^<]*drag to rotate)</figcaption>", html).group(1)
    assert "=;" not in cap and "-;" not in cap and "median tuple" in cap
