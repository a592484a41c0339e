"""The robot drawn for several arms, ports and obstacles (issue #45; docs/figures.md, "The
robot"): ``designopt view`` without ``--out`` (and with ``--html`` only) writes beside the
config's archive; a folder given for a file is refused with a file name of the right
kind; two arms are drawn each at its base in the world, with the patient, in the PNG and
in the 3-D page; a far-away obstacle does not widen the view and is named; the report of
a two-arm run (not a front) draws its cloud and robots; a front's designs are drawn
with every arm at a representative tuple of targets of their own IK solution (the
page's hover data and the extremes-and-knee figure); the HTML view of a single arm
through a port into a box patient shows the patient and the port."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import jax
import matplotlib.pyplot as plt
import numpy as np
import pytest
import yaml
from figcheck import assert_clean

import designopt
from designopt.cli.commands import main
from designopt.figures import canvas, robot
from designopt.figures import front as front_figs
from designopt.figures.html import robot as hrobot
from designopt.figures.html.model import _Ids
from designopt.studies.serial import drawing, report
from designopt.studies.serial import figures as serial_figs
from designopt.studies.serial.mechanism import build

ROOT = Path(__file__).resolve().parents[1]
TWO = ROOT / "configs/two_arms_front.yaml"
PORT = ROOT / "configs/urdf_puma560_port.yaml"
SHOTS = Path("/tmp/view_shots")
MIRROR = np.array([-1.0, -1.0, 1.0])
"""Arm 1 of configs/two_arms_front.yaml: yawed 180° at (b, 0, 0), arm 0 at (−b, 0, 0)."""


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


@pytest.fixture
def record():
    canvas.RECORD = []
    yield canvas.RECORD
    canvas.RECORD = None
    plt.close("all")


def _joints(ax, k: int) -> np.ndarray:
    """Arm k's base origin, joints and tip as the axes draw them."""
    (line,) = [ln for ln in ax.lines if ln.get_gid() == f"arm{k}-joints"]
    if hasattr(line, "get_data_3d"):
        return np.stack(line.get_data_3d(), -1)
    return np.stack(line.get_data(), -1)


def _arm_lines(ax) -> list[str]:
    return sorted(str(ln.get_gid()) for ln in ax.lines if str(ln.get_gid()).endswith("-joints"))


def _names(plot) -> list[str]:
    return [t.get("name", "") for t in plot.fig["data"]]


def _legend(fig) -> list[str]:
    return [t.get_text() for lg in fig.legends for t in lg.get_texts()]


# ------------------------------------------------------------------ the command


DEFAULT = "results/urdf_puma560_port/urdf_puma560_port_view.png"


@pytest.mark.parametrize("extra,png", [
    ([], DEFAULT), (["--html", "v.html"], DEFAULT), (["--out", "v.png"], "v.png"),
])  # fmt: skip
def test_view_without_out_writes_beside_the_configs_archive(extra, png, tmp_path, monkeypatch,
                                                            capsys, record):  # fmt: skip
    """``designopt view configs/urdf_puma560_port.yaml`` (and ``--html OUT.html`` alone):
    the PNG and PDF go to ``<output folder>/<stem>_view.png`` under the working folder,
    with the patient's half-space and the port drawn; a bare ``--out`` name goes to the
    working folder."""
    monkeypatch.chdir(tmp_path)
    assert main(["view", str(PORT), *extra]) == 0
    png = Path(png)
    page = ["v.html"] if "--html" in extra else []
    assert capsys.readouterr().out.split() == [str(png), str(png.with_suffix(".pdf")), *page]
    assert (tmp_path / png).stat().st_size > 20_000
    assert_clean(record)
    [(_, fig)] = record
    assert {"port", "obstacles"} <= set(_legend(fig))
    if page:
        text = (tmp_path / page[0]).read_text()
        assert '"name":"port"' in text and '"name":"obstacle 0: halfspace"' in text


@pytest.mark.parametrize("flag,name,want", [
    ("--out", "d.png", "d.png/puma560_view.png"),
    ("--html", "d.html", "d.html/puma560_view.html"),
])  # fmt: skip
def test_view_refuses_a_folder_naming_a_file_of_its_kind(flag, name, want, tmp_path, capsys):
    (tmp_path / name).mkdir()
    rc = main(["view", str(ROOT / "configs/puma560.yaml"), "--out", str(tmp_path / "r.png"),
               flag, str(tmp_path / name)])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith("designopt: error: "), err
    assert f"{flag} {tmp_path / name}: is a folder" in err and str(tmp_path / want) in err
    assert ".h5" not in err
    assert not (tmp_path / "r.png").exists()


def test_view_of_two_arms_draws_each_arm_at_its_base(tmp_path, record, capsys):
    """configs/two_arms_front.yaml at b = 0.6: arm 0's base origin at (−0.6, 0, 0), arm
    1's at (0.6, 0, 0), arm 1 the mirror image of arm 0 (yaw 180°), the patient drawn;
    the page has each arm's traces and the patient."""
    out, page = tmp_path / "two.png", tmp_path / "two.html"
    assert main(["view", str(TWO), "--design", "b=0.6", "--out", str(out),
                 "--html", str(page)]) == 0  # fmt: skip
    assert_clean(record)
    [(_, fig)] = record
    (ax,) = fig.axes
    assert _arm_lines(ax) == ["arm0-joints", "arm1-joints"]
    np.testing.assert_allclose(_joints(ax, 0)[0], [-0.6, 0, 0], atol=1e-12)
    np.testing.assert_allclose(_joints(ax, 1)[0], [0.6, 0, 0], atol=1e-12)
    np.testing.assert_allclose(_joints(ax, 1), _joints(ax, 0) * MIRROR, atol=1e-12)
    assert {"this design: arm 0", "this design: arm 1", "obstacles"} <= set(_legend(fig))
    text = page.read_text()
    for name in ("this design: arm 0: joints", "this design: arm 1: joints", "obstacle 0: box"):
        assert f'"name":"{name}"' in text
    shutil.copy(out, SHOTS / "view_two_arms.png") if SHOTS.is_dir() else None


def test_a_far_away_obstacle_does_not_widen_the_view(tmp_path, record, capsys):
    """A ball 3 km away beside configs/two_arms_front.yaml's patient: the figure's axes
    and the page's ranges stay within 2 m of the site, and both name the ball as outside
    the view."""
    cfg = yaml.safe_load(TWO.read_text())
    cfg["study"]["collision"]["obstacles"].append(
        {"shape": "ball", "center": [3000, 0, 0], "radius": 1})
    path = tmp_path / "far.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "far.png"
    assert main(["view", str(path), "--out", str(out), "--html", str(tmp_path / "far.html")]) == 0
    [(_, fig)] = record
    (ax,) = fig.axes
    for lim in (ax.get_xlim(), ax.get_ylim(), ax.get_zlim()):
        assert max(map(abs, lim)) < 2.0, lim
    note = "obstacle 1 (ball at (3000, 0, 0) m, r = 1 m) outside the view"
    assert note in fig._suptitle.get_text().replace("\n", " ")
    assert note in (tmp_path / "far.html").read_text()
    s = designopt.load_config(path).study
    mech = build(s)
    q = drawing.home(mech)
    x = np.array([0.6, 0.4, 0.4])
    from designopt.studies.serial.commands import _task_around, view_of

    plot = hrobot.view_plot(view_of(s, mech, x, q, "far", False, _task_around(s)), _Ids())
    sc = plot.fig["layout"]["scene"]
    for a in ("xaxis", "yaxis", "zaxis"):
        assert max(map(abs, sc[a]["range"])) < 2.0, sc[a]["range"]
    assert [n for n in _names(plot) if n.startswith("obstacle")] == ["obstacle 0: box"]


def test_obstacles_are_clipped_to_the_view():
    """A box is cut to the view exactly, a ball far away is left out and named, a
    half-space is the polygon where its plane cuts the view, a capsule half out is cut."""
    from designopt.kinematics.collision import BallObstacle, BoxObstacle, CapsuleObstacle, HalfSpace

    lo, hi = np.zeros(3), np.ones(3)
    box = BoxObstacle(shape="box", center=[1.0, 0.5, 0.5], size=[1.0, 2.0, 0.5])
    V, F, how = robot.clip_obstacle(box, lo, hi)
    assert how == "cut" and F.shape == (12, 3)
    np.testing.assert_allclose([V.min(0), V.max(0)], [[0.5, 0, 0.25], [1, 1, 0.75]])
    ball = BallObstacle(shape="ball", center=[3000.0, 0, 0], radius=1.0)
    assert robot.clip_obstacle(ball, lo, hi) == (None, None, "outside")
    plane = HalfSpace(shape="halfspace", point=[0, 0, 0.3], normal=[0, 0, 1])
    V, F, how = robot.clip_obstacle(plane, lo, hi)
    assert how == "" and len(V) == 4 and len(F) == 2
    np.testing.assert_allclose(V[:, 2], 0.3)
    below = HalfSpace(shape="halfspace", point=[0, 0, -5.0], normal=[0, 0, 1])
    assert robot.clip_obstacle(below, lo, hi)[2] == "outside"
    cap = CapsuleObstacle(shape="capsule", a=[0.5, 0.5, 0.5], b=[5.0, 0.5, 0.5], radius=0.1)
    V, _, how = robot.clip_obstacle(cap, lo, hi)
    assert how == "cut" and V.max() <= 1.0
    keep, notes = robot.clipped_obstacles([box, ball, plane, cap], lo, hi, "m")
    assert [k for k, *_ in keep] == [0, 2, 3]
    assert notes[1] == "obstacle 1 (ball at (3000, 0, 0) m, r = 1 m) outside the view"


# -------------------------------------------------------------- a two-arm run


@pytest.fixture(scope="module")
def two_run(tmp_path_factory):
    """A tiny single-objective run of the two arms (not a front): max reach_all."""
    jax.config.update("jax_enable_x64", True)
    cfg = designopt.load_config(TWO, {
        "study.objective": {"reach_all": -1.0}, "study.indices.n_samples": 32,
        "optimizer": {"name": "ptpso", "n_particles": 2, "n_iters": 1, "n_runs": 1}})  # fmt: skip
    out = tmp_path_factory.mktemp("two") / "two.h5"
    designopt.run(cfg, out=out)
    return out, designopt.load(out)


def test_report_html_of_a_two_arm_run(two_run, tmp_path, capsys):
    """``designopt report ARCHIVE --html`` of a two-arm run: the cloud holds one value
    per target (the arms' mean 1/k where every arm reaches it), and the robot view draws
    both arms at tuples of targets with the patient."""
    path, rec = two_run
    arch = tmp_path / "two.h5"
    arch.write_bytes(path.read_bytes())
    assert main(["report", str(arch), "--html"]) == 0
    text = (tmp_path / "two.html").read_text()
    for name in ("arm 0: joints", "arm 1: joints", "obstacle 0: box", "targets (1/k)"):
        assert f'"name":"{name}"' in text
    cl = serial_figs.cloud(rec)
    n = rec.final_stream()[0].indices.n_samples  # the fresh targets final/ is quoted on
    assert n == 4 * 32  # final.n_samples' default: 4 × the search's
    assert cl["xyz"].shape == (n, 3) and cl["value"].shape == cl["flag"].shape == (n,)
    assert "2 arms" in cl["title"]


def test_run_figures_draw_every_arm_at_its_base(two_run, tmp_path, record):
    """The workspace figure of a two-arm run draws both arms at their bases (the
    final b), with each arm's tips in the world; the task figure's 3-D panel both arms."""
    _, rec = two_run
    serial_figs.draw_run(rec, tmp_path)
    assert_clean(record)
    b = rec.x["b"]
    ws = dict(record)["workspace"]
    ax = next(a for a in ws.axes if hasattr(a, "get_zlim"))
    assert _arm_lines(ax) == ["arm0-joints", "arm1-joints"]
    np.testing.assert_allclose(_joints(ax, 0)[0], [-b, 0, 0], atol=1e-12)
    np.testing.assert_allclose(_joints(ax, 1), _joints(ax, 0) * MIRROR, atol=1e-12)
    task = dict(record)["task"]
    ax3 = next(a for a in task.axes if hasattr(a, "get_zlim"))
    assert _arm_lines(ax3) == ["arm0-joints", "arm1-joints"]


# ------------------------------------------------------------------- fronts


def _front(rec, X: np.ndarray, F: np.ndarray, senses=("max", "max")):
    """A front record's face over the run's settings (same targets, same compiled IK):
    designs X, objective values F (own values)."""
    names = ("reach_all", "arms_free")
    return SimpleNamespace(config=rec.config, X=np.asarray(X, np.float64), F=np.asarray(F),
                           F_se=np.zeros_like(F), objectives=dict(zip(names, senses, strict=True)),
                           values={}, keys=rec.keys, units=lambda: {}, groups={"front": {}},
                           study="serial", ambiguous=np.zeros((0, 2), int), n_samples=32)  # fmt: skip


X3 = np.array([[0.5, 0.35, 0.35], [0.6, 0.45, 0.45], [0.7, 0.55, 0.5]])
F3 = np.array([[1.0, 0.2], [0.9, 0.6], [0.5, 0.8]])


def test_front_view_draws_every_arm_at_a_tuple_of_targets(two_run):
    """Each design of the page's front is drawn with both arms at their bases (its own
    b), each arm's tip on its target of the design's representative tuple (not the home
    pose), the patient beside; the hover data hold every arm's traces."""
    _, rec = two_run
    fake = _front(rec, X3, F3)
    fv = report.front_view(fake)
    s = rec.config.study
    mech = build(s)
    assert len(fv.robots) == 3 and len(fv.obstacles) == 1
    for x, arms in zip(X3, fv.robots, strict=True):
        label, Q, targets = drawing.design_pose(s, mech, x, rec.keys())
        assert len(arms) == 2 and len(targets) == 2 and "tuple" in label
        assert not np.allclose(Q, drawing.home(mech))
        np.testing.assert_allclose(arms[0].points()[0], [-x[0], 0, 0], atol=1e-12)
        np.testing.assert_allclose(arms[1].points()[0], [x[0], 0, 0], atol=1e-12)
        for arm, p in zip(arms, targets, strict=True):
            np.testing.assert_allclose(arm.points()[-1], p, atol=1e-6)  # the tip on its target
    fplot, rplot = hrobot.front_plots(fv, _Ids())
    names = _names(rplot)
    assert {"design: arm 0: joints", "design: arm 1: joints", "obstacle 0: box"} <= set(names)
    link = rplot.fig["link"]
    k = names.index("design: arm 1: joints")
    j = link["traces"].index(k)
    for i, arms in enumerate(fv.robots):
        got = np.c_[[link["designs"][i]["data"][c][j] for c in "xyz"]].T
        np.testing.assert_allclose(got, arms[1].points(), atol=1e-12)


def test_extremes_and_knee():
    """On a quarter circle (both objectives minimised, convex towards the ideal point)
    the extremes are its ends and the knee its middle; with max senses the same points
    mirrored; a front of one design gives one pick."""
    t = np.linspace(0, np.pi / 2, 9)
    F = np.c_[1 - np.sin(t), 1 - np.cos(t)]
    fake = SimpleNamespace(F=F, objectives={"a": "min", "b": "min"}, values={}, groups={"front": {}})
    assert front_figs.extremes_and_knee(fake) == [("best a", 8), ("knee", 4), ("best b", 0)]
    fake.F, fake.objectives = -F, {"a": "max", "b": "max"}
    assert front_figs.extremes_and_knee(fake) == [("best a", 8), ("knee", 4), ("best b", 0)]
    fake.F = F[:1]
    assert front_figs.extremes_and_knee(fake) == [("best a", 0)]


def test_front_robots_figure(two_run, tmp_path, record):
    """``front_robots``: the extremes and the knee side by side, each with both arms at
    their bases; the front figure rings them."""
    _, rec = two_run
    fake = _front(rec, X3, F3)
    picks = front_figs.extremes_and_knee(fake)
    assert [i for _, i in picks] == [0, 1, 2]
    serial_figs.draw_front_robots(fake, picks, tmp_path)
    front_figs.front(fake, tmp_path, {}, picks)
    assert_clean(record)
    fig = dict(record)["front_robots"]
    axes = [a for a in fig.axes if hasattr(a, "get_zlim")]
    assert len(axes) == 3
    for ax, x in zip(axes, X3, strict=True):
        assert _arm_lines(ax) == ["arm0-joints", "arm1-joints"]
        np.testing.assert_allclose(_joints(ax, 0)[0], [-x[0], 0, 0], atol=1e-12)
    ring = [c for c in dict(record)["front"].axes[0].collections if c.get_gid() == "ringed:robots"]
    np.testing.assert_allclose(ring[0].get_offsets(), F3)
    if SHOTS.is_dir():
        fig.savefig(SHOTS / "front_robots.png")


# ---------------------------------------------------- one arm through a port


def test_run_page_of_a_port_task_draws_the_patient_and_the_port(monkeypatch):
    """configs/urdf_puma560_port.yaml's run page (a solution made from the forward
    kinematics): the robot view holds the patient's half-space and the port."""
    s = designopt.load_config(PORT).study
    mech = build(s)
    x = np.array([0.43, 0.43, 0.4])
    rng = np.random.default_rng(5)
    q = mech.lower + (mech.upper - mech.lower) * rng.random((16, mech.n))
    P, _, _ = drawing.joint_frames(mech, drawing.full(mech, [x]), q)
    ok = np.arange(16) > 2
    sol = {"target_p": P[0, :, -1], "success": ok, "q": q, "inv_k": np.where(ok, 0.3, 0.0)}
    monkeypatch.setattr(report.blocks, "solution", lambda *a, **k: sol)
    rec = SimpleNamespace(config=SimpleNamespace(study=s), x=dict(zip(s.variables, x, strict=True)),
                          keys=dict)  # fmt: skip
    view = report.run_view(rec)
    names = _names(hrobot.view_plot(view, _Ids()))
    assert "port" in names and "obstacle 0: halfspace" in names
