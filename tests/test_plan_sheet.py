"""The plan sheet (plan.png) of a planning run and the front's robots zoomed on the
patient (issue 67, items 4 and 5): the shipped planning case (configs/port_placement.yaml)
run tiny and single-objective, with the sizes of tests/test_planning_figures.py (so the
compiled programs are the same shapes), and a front's face over the same run (three of
its designs, their placement computed as a front archives it). The numbers printed on
the sheet are read back from its text artists and compared with the archive's; every
drawn text of plan.png and front_robots.png lies inside its figure and overlaps no
other (tests/figcheck.py, ``text_problems``)."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import jax
import numpy as np
import pytest
from figcheck import drawn_texts, text_problems

import designopt
from designopt.studies.serial import figures as serial_figs

ROOT = Path(__file__).resolve().parents[1]
PORTS = ROOT / "configs/port_placement.yaml"
N = 32  # targets, as tests/test_planning_figures.py
RUN = {"study.objective": {"arms_ok": -1.0, "gci": -1.0}, "study.indices.n_samples": N,
       "final.n_samples": N,
       "study.task.camera": {"port": [0.1, 0.0, 0.3], "band": [0.04, 0.16]},  # an endoscope
       "optimizer": {"name": "ptpso", "n_particles": 2, "n_iters": 1, "n_runs": 1}}  # fmt: skip
NUM = r"-?\d+\.\d"
VEC = re.compile(rf"\(({NUM}), ({NUM}), ({NUM})\)")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny single-objective run of the planning case and its figures (kept open)."""
    from designopt.figures import canvas

    jax.config.update("jax_enable_x64", True)
    cfg = designopt.load_config(PORTS, RUN)
    out = tmp_path_factory.mktemp("plan") / "pp.h5"
    designopt.run(cfg, out=out)
    rec = designopt.load(out)
    folder = out.parent / "figures"
    kept: list = []
    old, canvas.RECORD = canvas.RECORD, kept
    try:
        paths = serial_figs.draw_run(rec, folder)
    finally:
        canvas.RECORD = old
    yield rec, paths, dict(kept)
    import matplotlib.pyplot as plt

    for _, f in kept:
        plt.close(f)


def _front(rec, X: np.ndarray):
    """A front record's face over the run's settings (its targets, its compiled IK):
    designs X, the objectives arms_ok and gci (made-up values: one extreme, the knee,
    the other extreme), each design's ports and bases as a front archives them
    (``scoring.placement``)."""
    from designopt.studies.serial import _placement  # the study's placement hook

    placed = {k: np.asarray(v) for k, v in _placement(rec.config.study, X).items() if k != "attrs"}
    F = np.array([[0.9, 0.3], [0.7, 0.55], [0.4, 0.62]])
    return SimpleNamespace(config=rec.config, X=np.asarray(X, np.float64), F=F,
                           F_se=np.zeros_like(F), objectives={"arms_ok": "max", "gci": "max"},
                           values={"instrument_angle": np.array([55.0, 60.0, 65.0]),
                                   "instrument_angle_se": np.array([1.0, 1.5, 2.0])},
                           keys=rec.keys, units=lambda: {"instrument_angle": "deg"},
                           groups={"front": placed}, study="serial",
                           ambiguous=np.zeros((0, 2), int), n_samples=N)  # fmt: skip


X3 = np.array([[0.5, 0.0, 0.02, -0.12, 0.12], [0.55, -0.02, 0.04, -0.1, 0.11],
               [0.6, 0.02, 0.06, -0.08, 0.08]])  # fmt: skip


@pytest.fixture(scope="module")
def front(run, tmp_path_factory):
    """front_robots and the plan of the knee, drawn for three designs (kept open)."""
    from designopt.figures import canvas
    from designopt.figures import front as front_figs

    rec = run[0]
    fake = _front(rec, X3)
    picks = front_figs.extremes_and_knee(fake)
    kept: list = []
    old, canvas.RECORD = canvas.RECORD, kept
    try:
        paths = serial_figs.draw_front_robots(fake, picks, tmp_path_factory.mktemp("front"))
    finally:
        canvas.RECORD = old
    yield fake, picks, paths, dict(kept)
    import matplotlib.pyplot as plt

    for _, f in kept:
        plt.close(f)


def _gid(fig, prefix: str) -> dict[str, str]:
    return {t.get_gid(): t.get_text() for t in drawn_texts(fig)
            if str(t.get_gid()).startswith(prefix)}  # fmt: skip


def _check_numbers(fig, ports: np.ndarray) -> None:
    """The incision labels (and the table's incision column) print the ports in mm to
    0.1 mm; each dimension line prints |p_i − p_j|."""
    lab = {k: v for k, v in _gid(fig, "incision-").items() if k != "incision-camera"}
    assert len(lab) == len(ports)
    for k, p in enumerate(ports):
        m = VEC.search(lab[f"incision-{k}"])
        assert m and lab[f"incision-{k}"].endswith("mm"), lab
        np.testing.assert_allclose([float(v) for v in m.groups()], p * 1000, atol=0.05 + 1e-9)
    cells = [t.get_text() for t in drawn_texts(fig) if t.get_text().startswith("P")]
    rows = [c for c in cells if re.fullmatch(r"P\d: arm \d", c)]
    assert len(rows) == len(ports)
    dist = _gid(fig, "distance-")
    assert len(dist) == len(ports) * (len(ports) - 1) // 2
    for key, txt in dist.items():
        i, j = (int(v) for v in key.split("-")[1:])
        got = float(re.fullmatch(r"(\d+\.\d) mm", txt).group(1))
        assert got == pytest.approx(np.linalg.norm(ports[i] - ports[j]) * 1000, abs=0.05 + 1e-9)
    plan = fig.designopt_plan
    np.testing.assert_array_equal(plan.ports, ports)


def _short_title(fig) -> None:
    title = fig._suptitle.get_text()
    assert 1 <= len(title.split("\n")) <= 2, title


def test_plan_png_of_a_run_prints_the_archived_incisions(run):
    """plan.png is among a planning run's figures; its incision labels equal the
    archive's final/ports to 0.1 mm, its dimension lines the distances between them;
    the instruments' angle quoted is the archive's instrument_angle; every text lies
    inside the figure and overlaps no other; two views in equal scales."""
    rec, paths, figs = run
    assert {p.name for p in paths} >= {"plan.png", "plan.pdf"}
    assert all(p.exists() for p in paths if p.name.startswith("plan"))
    fig = figs["plan"]
    ports = np.asarray(rec.groups["final"]["ports"], np.float64)
    _check_numbers(fig, ports)
    plan = fig.designopt_plan
    a, se = rec.indices["instrument_angle"]
    texts = [t.get_text() for t in drawn_texts(fig)]
    if np.isfinite(a):
        assert plan.angle == pytest.approx((a, se))
        assert any(f"{a:.1f} ± {se:.1f} deg" in t for t in texts)
    else:  # too few tuples both arms reach: the sheet says so, with the count
        n, of = rec.indices["instrument_angle_n"][0], rec.indices["instrument_angle_of"][0]
        assert plan.angle is None
        assert any("instrument_angle): n/a" in t and f"({n:.0f} of {of:.0f})" in t for t in texts)
    views = [ax for ax in fig.axes if ax.get_title().startswith("from ")]
    assert len(views) == 2
    for ax in views:
        assert ax.get_aspect() == 1.0
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        bb = ax.get_window_extent()
        assert (x1 - x0) / bb.width == pytest.approx((y1 - y0) / bb.height, rel=1e-6)
        assert x1 - x0 < 1.0  # zoomed on the patient (the bases are 0.9-1.6 m apart)
    _short_title(fig)
    assert text_problems(fig) == []


def test_the_sheet_and_the_html_report_carry_the_final_stages_verdict(run):
    """The run raced its candidates (final.race): plan.png's rows say the race's answer
    and this layout's own verdict, read from the archive's verdict/ group; the HTML
    report has a "Port plan" section with the sheet as a PNG and the same rows."""
    from designopt.app import reporting
    from designopt.studies.serial import plansheet

    rec, _, figs = run
    g = rec.groups["verdict"]
    summary = g["attrs"]["summary"]
    summary = summary.decode() if isinstance(summary, bytes) else str(summary)
    X = np.atleast_2d(np.asarray(g["x"], np.float64))
    x = np.asarray(list(rec.x.values()), np.float64)
    j = int(np.flatnonzero(np.all(np.isclose(X, x), axis=1))[0])  # the final design raced
    mine = np.atleast_1d(g["verdict"])[j]
    mine = mine.decode() if isinstance(mine, bytes) else str(mine)
    plan, _ = plansheet.run_sheet(rec)
    assert f"final stage (the candidates raced on fresh samples): {summary}" in plan.rows[
        -2 - len(rec.warnings)]
    assert f"this layout in the final stage: {mine} (candidate #{j} of {len(X)})" in plan.rows
    texts = " ".join(t.get_text() for t in drawn_texts(figs["plan"]))
    assert "this layout in the final stage" in texts
    rec, paths, _ = run
    out = reporting.write_html(paths[0].parent.parent / "pp.h5", rec)  # the fixture's archive
    html = out.read_text()
    assert '<section id="plan"' in html or 'id="plan"' in html
    assert "Port plan" in html and 'src="data:image/png;base64,iVBOR' in html
    assert "this layout in the final stage" in html


def test_the_endoscope_is_on_the_sheet_in_the_figures_and_the_report(run):
    """``task.camera``: the archive's final/camera (its incision point and tip, as
    ``camera.pose`` places them), the sheet's C label and row, the robot figures' scope
    and the HTML report's endoscope trace; ``view_ok`` among the indices."""
    from designopt.app import reporting
    from designopt.figures import robot

    rec, paths, figs = run
    cam = np.asarray(rec.groups["final"]["camera"], np.float64).reshape(6)
    x = np.asarray(list(rec.x.values()), np.float64)
    from designopt.studies.serial.placement import camera_at

    np.testing.assert_allclose(cam, camera_at(rec.config.study, x[None])[0], atol=1e-12)
    assert 0.0 <= rec.indices["view_ok"][0] <= 1.0 and rec.indices["view_ok"][1] > 0
    fig = figs["plan"]
    m = VEC.search(_gid(fig, "incision-camera")["incision-camera"])
    np.testing.assert_allclose([float(v) for v in m.groups()], cam[:3] * 1000, atol=0.05 + 1e-9)
    texts = [t.get_text() for t in drawn_texts(fig)]
    assert "C: camera" in texts and any(t.startswith("camera C: its tip at") for t in texts)
    np.testing.assert_array_equal(fig.designopt_plan.camera, cam)
    assert any(p.name == "robot_final.png" or p.name.startswith("robot") for p in paths)
    scopes = [ln for f in figs.values() for ax in f.axes for ln in ax.get_lines()
              if ln.get_color() == robot.SCOPE]  # fmt: skip
    assert scopes, "no figure draws the endoscope"
    out = reporting.write_html(paths[0].parent.parent / "pp.h5", rec)
    assert '"name": "endoscope"' in out.read_text() or '"name":"endoscope"' in out.read_text()


def test_front_plan_is_the_knees_and_front_robots_reads(front):
    """A front's plan.png is its knee's (the design front_robots singles out), its
    numbers the knee's archived ports; front_robots has a title of at most two lines,
    its numbers in a table under the panels, each 3-D panel zoomed on the patient (its
    view holds the region, the ports and the anatomy, and is smaller than the robots'
    reach) with the anatomy drawn; no text of either leaves its figure or overlaps."""
    from designopt.figures.robot import ANATOMY

    fake, picks, paths, figs = front
    names = {p.name for p in paths}
    assert {"front_robots.png", "plan.png"} <= names
    knee = dict(picks)["knee"]
    assert knee == 1
    fig = figs["plan"]
    _check_numbers(fig, np.asarray(fake.groups["front"]["ports"])[knee])
    assert f"design {knee}" in fig._suptitle.get_text()
    assert fig.designopt_plan.angle == (60.0, 1.5)  # the knee's instrument_angle ± SE
    _short_title(fig)
    assert text_problems(fig) == []

    fr = figs["front_robots"]
    _short_title(fr)
    assert text_problems(fr) == []
    cells = [t.get_text() for t in drawn_texts(fr)]
    for name, i in picks:
        assert f"{name}: design {i}" in cells
    s = fake.config.study
    axes = [a for a in fr.axes if hasattr(a, "get_zlim")]
    assert len(axes) == len(picks)
    region_lo = np.asarray(s.task.region.center) - np.asarray(s.task.region.size) / 2
    for ax, (_, i) in zip(axes, picks, strict=True):
        lo = np.array([ax.get_xlim()[0], ax.get_ylim()[0], ax.get_zlim()[0]])
        hi = np.array([ax.get_xlim()[1], ax.get_ylim()[1], ax.get_zlim()[1]])
        ports = np.asarray(fake.groups["front"]["ports"])[i]
        assert np.all(ports >= lo) and np.all(ports <= hi)
        assert np.all(region_lo >= lo)
        assert np.max(hi - lo) < 2 * fake.X[i][0]  # smaller than the bases' distance
        from matplotlib.colors import to_rgba

        anat = [c for c in ax.collections if not hasattr(c, "_offsets3d")
                and len(c.get_facecolor()) and np.allclose(c.get_facecolor()[0][:3],
                                                           to_rgba(ANATOMY)[:3], atol=0.35)]  # fmt: skip
        assert len(anat) >= 2  # the vessel and the organ


def test_text_check_finds_overlaps_and_texts_off_the_figure():
    """The checker itself: two texts on top of each other and a text past the edge
    are named; texts that touch within a pixel pass."""
    from designopt.figures.canvas import plt

    fig = plt.figure(figsize=(4, 3), dpi=100)
    fig.text(0.1, 0.5, "alpha beta")
    fig.text(0.12, 0.5, "gamma")
    fig.text(0.95, 0.1, "far past the right edge")
    got = text_problems(fig)
    assert any("overlaps" in g and "alpha beta" in g for g in got)
    assert any("leaves the figure" in g and "far past" in g for g in got)
    plt.close(fig)
    fig = plt.figure(figsize=(4, 3), dpi=100)
    a = fig.text(0.1, 0.5, "left")
    fig.canvas.draw()
    bb = a.get_window_extent()
    fig.text((bb.x1 - 0.5) / fig.bbox.width, 0.5, "right")  # 0.5 px of overlap
    assert text_problems(fig) == []
    plt.close(fig)
