"""The robot drawn (issue #40; docs/figures.md, "The robot"): the joints a figure and the
report draw are the chain's forward kinematics, read back from the matplotlib and plotly
data and compared with an independent NumPy DH product (a DH chain) and with yourdfpy's
own FK (a URDF chain); a URDF's meshes are placed like yourdfpy's scene to 1e-9; the
``designopt view`` command draws DH and URDF configs and refuses bad input in one line; a
Pareto front's page draws the robot of the design under the mouse in a real browser."""

from __future__ import annotations

import io
import math
import re
import shutil
from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np
import pytest
import yourdfpy
from figcheck import assert_clean

import designopt
from designopt.cli.commands import main
from designopt.figures import canvas, robot
from designopt.figures.html import robot as hrobot
from designopt.figures.html.model import _Ids
from designopt.kinematics import meshes, urdf
from designopt.studies.serial import commands, drawing, report
from designopt.studies.serial.mechanism import build

ROOT = Path(__file__).resolve().parents[1]
MESH_URDF = ROOT / "configs/robots/mesh_arm/urdf/mesh_arm.urdf"
SHOTS = Path("/tmp/view_shots")


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


@pytest.fixture
def record():
    canvas.RECORD = []
    yield canvas.RECORD
    canvas.RECORD = None
    plt.close("all")


def _dh(al: float, a: float, d: float, th: float) -> np.ndarray:
    """The standard DH link transform Rz(θ) Tz(d) Tx(a) Rx(α), written out."""
    ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                     [0, sa, ca, d], [0, 0, 0, 1]])  # fmt: skip


def _joints_read_back(ax, k: int = 0) -> np.ndarray:
    """The joints of arm k as a figure holds them (its centre line's data)."""
    (line,) = [ln for ln in ax.lines if ln.get_gid() == f"arm{k}-joints"]
    if hasattr(line, "get_data_3d"):
        return np.stack(line.get_data_3d(), -1)
    return np.stack(line.get_data(), -1)


def test_dh_drawing_is_the_dh_product():
    """PUMA 560 (configs/puma560.yaml) at a random design and three random poses: the
    joints of the 3-D figure, of the projection and of the report's trace, the joint
    axes and the tool frame equal a product of DH matrices."""
    s = designopt.load_config(ROOT / "configs/puma560.yaml", {"precision": "float64"}).study
    mech = build(s)
    rng = np.random.default_rng(1)
    a2, d4 = rng.uniform(0.3, 0.6, 2)
    Q = mech.lower + (mech.upper - mech.lower) * rng.random((3, 6))
    arms = drawing.arms(s, mech, [[a2, d4]], Q, labels=["a", "b", "c"])[0]
    al = np.radians([90, 0, -90, 90, -90, 0])
    a, d = [0, a2, 0.0203, 0, 0, 0], [0, 0, 0.15005, d4, 0, 0]
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    robot.draw_3d(ax, robot.Scene(arms=arms), "m")
    fig2, ax2 = plt.subplots()
    E = np.linalg.qr(rng.normal(size=(3, 2)))[0]  # any plane
    robot.draw_2d(ax2, arms, E)
    for k, (arm, q) in enumerate(zip(arms, Q, strict=True)):
        T, pts, zs = np.eye(4), [np.zeros(3)], []
        for j in range(6):
            pts.append(T[:3, 3].copy())
            zs.append(T[:3, 2].copy())
            T = T @ _dh(al[j], a[j], d[j], q[j])
        pts.append(T[:3, 3])
        want = np.array(pts)
        np.testing.assert_allclose(_joints_read_back(ax, k), want, atol=1e-12)
        np.testing.assert_allclose(_joints_read_back(ax2, k), want @ E, atol=1e-12)
        tr = hrobot.arm_traces(arm, 0.02, "")[1]  # the report's centre line with its joints
        np.testing.assert_allclose(np.c_[tr["x"], tr["y"], tr["z"]], want, atol=1e-12)
        arrows = robot.axis_arrows(arm, 0.1)
        np.testing.assert_allclose(arrows[:, 0], want[1:-1], atol=1e-12)
        np.testing.assert_allclose((arrows[:, 1] - arrows[:, 0]) / 0.1, zs, atol=1e-12)
        np.testing.assert_allclose(robot.triads(arm, 1.0)[1, :, 1] - T[:3, 3], T[:3, :3].T,
                                   atol=1e-12)  # fmt: skip  # the tool frame's x, y, z
    plt.close(fig2)


def test_urdf_drawing_is_yourdfpys_fk():
    """The surgical arm's URDF (configs/urdf_arm.yaml) with a design written into the
    file: each drawn joint is where yourdfpy puts that joint's frame (parent link ∘
    origin), its axis yourdfpy's, the tip yourdfpy's tip; the original robot is the
    unchanged file's."""
    s = designopt.load_config(ROOT / "configs/urdf_arm.yaml").study
    mech = build(s)
    imp = s.chain.imported
    rng = np.random.default_rng(2)
    Q = mech.lower + (mech.upper - mech.lower) * rng.random((4, mech.n))
    design = {"l_wrist": 0.021, "l_jaw": 0.012}
    for values, make in (
        (commands.set_values(s, design),
         lambda q: drawing.arms(s, mech, [list(design.values())], q)[0][0]),
        ({}, lambda q: drawing.original_arm(s, mech, q)),
    ):  # fmt: skip
        text = urdf.export_text(s.chain.urdf_text, values, "x") if values else s.chain.urdf_text
        u = yourdfpy.URDF.load(io.BytesIO(text.encode()), build_scene_graph=True, load_meshes=False)
        for q in Q:
            arm = make(q)
            u.update_cfg(np.array([dict(zip(imp.active, q, strict=True)).get(n, 0.0)
                                   for n in u.actuated_joint_names]))  # fmt: skip
            want, axes = [np.zeros(3)], []
            for name in imp.chain:
                j = u.joint_map[name]
                T = u.get_transform(j.parent, imp.base) @ j.origin
                want.append(T[:3, 3])
                axes.append(T[:3, :3] @ (np.asarray(j.axis) / np.linalg.norm(j.axis)))
            tip = u.get_transform(imp.tip, imp.base)
            want.append(tip[:3, 3])
            np.testing.assert_allclose(arm.points(), want, atol=1e-12)
            np.testing.assert_allclose(arm.axes, axes, atol=1e-12)
            np.testing.assert_allclose(arm.tip, tip[:3, :3], atol=1e-12)


def _scene_meshes(u: yourdfpy.URDF) -> list[np.ndarray]:
    """Every geometry of yourdfpy's scene, its vertices in the root frame."""
    sc = u.scene
    out = []
    for node in sc.graph.nodes_geometry:
        T, g = sc.graph.get(node)
        out.append(np.asarray(sc.geometry[g].vertices) @ T[:3, :3].T + T[:3, 3])
    return out


def _rows(V: np.ndarray) -> np.ndarray:
    return V[np.lexsort(V.T)]


def test_meshes_are_placed_like_yourdfpys_scene():
    """configs/robots/mesh_arm (STL, OBJ and DAE meshes behind package:// and a relative
    path, a visual origin, a non-uniform scale, box/cylinder/sphere primitives, a fixed
    joint, a prismatic one), unchanged and with a design written in: every vertex where
    yourdfpy's scene puts it (1e-9); decimation keeps the budget."""
    for f in ("upper.stl", "elbow.obj", "forearm.dae"):
        if not (MESH_URDF.parents[1] / "meshes" / f).is_file():
            pytest.skip(f"mesh file {f} is not in this checkout")
    s = designopt.load_config(ROOT / "configs/urdf_mesh_arm.yaml").study
    imp = s.chain.imported
    text = MESH_URDF.read_text()
    rng = np.random.default_rng(3)
    lo, hi = np.asarray(imp.lower), np.asarray(imp.upper)
    for values in ({}, commands.set_values(s, {"l_upper": 0.41, "l_fore": 0.2})):
        t = urdf.export_text(text, values, "x") if values else text
        u = yourdfpy.URDF.load(io.StringIO(t), build_scene_graph=True, load_meshes=True,
                               mesh_dir=str(MESH_URDF.parent))  # fmt: skip
        for q in lo + (hi - lo) * rng.random((3, 3)):
            u.update_cfg(q)
            pl = meshes.placed(imp, t, MESH_URDF, values, q, max_triangles=None)
            assert not pl.missing and len(pl.meshes) == 6
            ref = _scene_meshes(u)
            assert sorted(len(V) for V in ref) == sorted(len(V) for _, V, _ in pl.meshes)
            for _, V, _ in pl.meshes:
                err = min(np.abs(_rows(V) - _rows(R)).max() for R in ref if len(R) == len(V))
                assert err < 1e-9, err
            assert pl.moved == (["forearm", "upper"] if values else [])
    arm = drawing.arms(s, build(s), [[0.4, 0.3]], lo)[0][0]  # a figure's robot: its meshes
    assert len(arm.meshes) == 6 and sum(len(F) for _, F in arm.meshes) == 1848
    small = meshes.placed(imp, text, MESH_URDF, {}, lo, max_triangles=600)
    full = meshes.placed(imp, text, MESH_URDF, {}, lo, max_triangles=None)
    assert full.triangles == small.full == 1848
    assert 600 < small.triangles <= 600 + meshes.KEEP * 6  # no mesh cut below KEEP
    for (_, Vs, Fs), (_, Vf, Ff) in zip(small.meshes, full.meshes, strict=True):
        assert 0 < len(Fs) <= max(600 * len(Ff) // 1848, meshes.KEEP, len(Ff) * (len(Ff) <= 64))
        assert Fs.min() >= 0 and Fs.max() < len(Vs)  # faces index the kept vertices
        assert np.all(Vs >= Vf.min(0) - 1e-12) and np.all(Vs <= Vf.max(0) + 1e-12)


def test_package_uris_resolve(tmp_path, monkeypatch):
    """package://PKG/rest: $ROS_PACKAGE_PATH first, then the folders above the URDF;
    relative paths from the URDF's folder; a missing file is None (drawn without it)."""
    pkg = tmp_path / "ws" / "src" / "mypkg"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    (pkg / "meshes" / "a.stl").write_text("x")
    u = pkg / "urdf" / "r.urdf"
    assert meshes.resolve("package://mypkg/meshes/a.stl", u) == pkg / "meshes" / "a.stl"
    assert meshes.resolve("../meshes/a.stl", u).resolve() == (pkg / "meshes" / "a.stl").resolve()
    assert meshes.resolve("package://mypkg/meshes/b.stl", u) is None
    other = tmp_path / "other" / "mypkg" / "meshes"
    other.mkdir(parents=True)
    (other / "a.stl").write_text("y")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "other"))
    assert meshes.resolve("package://mypkg/meshes/a.stl", u) == other / "a.stl"


def test_several_arms_with_a_colliding_pair(record, tmp_path):
    """The multi-arm hook: two arms at different base poses, one colliding, a colliding
    pair marked; each arm drawn at its base (origins moved by the base pose)."""
    s = designopt.load_config(ROOT / "configs/puma560.yaml", {"precision": "float64"}).study
    mech = build(s)
    q = drawing.home(mech)
    a = drawing.arms(s, mech, [[0.43, 0.43]], q)[0][0]
    T = np.eye(4)
    T[:3, :3] = [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]
    T[:3, 3] = [1.0, 0.0, 0.0]
    b = robot.Arm(a.origins, a.axes, a.tip, color="#2ca02c", label="arm 2", base=T,
                  colliding=True)  # fmt: skip
    a.label = "arm 1"
    pair = (a.points()[-1], b.points()[-1])
    sc = robot.Scene(arms=[a, b], collisions=[pair], title="two arms")
    fig = robot.figure([sc], "m", "two PUMAs facing each other")
    canvas.save(fig, tmp_path, "two")
    assert_clean(record)
    ax = fig.axes[0]
    np.testing.assert_allclose(_joints_read_back(ax, 1)[1:], a.origins @ T[:3, :3].T + T[:3, 3])
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "arm 2 (colliding)" in labels and "colliding pair" in labels


def _files(d: Path) -> set[Path]:
    return {p for p in d.rglob("*") if p.is_file()}


@pytest.mark.parametrize("config,extra", [
    ("puma560.yaml", ["--q", "10,20,-30,40,50,60"]),
    ("urdf_puma560_task.yaml", ["--design", "a2=0.5"]),
    ("urdf_arm.yaml", ["--design", "l_wrist=0.025", "--q", "20,30,0.1,45,30,-20"]),
    ("urdf_mesh_arm.yaml", ["--design", "l_upper=0.4", "--q", "30,40,0.05"]),
])  # fmt: skip
def test_view_command_draws_the_chain(config, extra, tmp_path, record, capsys):
    out = tmp_path / "v" / "robot.png"
    page = tmp_path / "v" / "robot.html"
    assert main(["view", str(ROOT / "configs" / config), *extra, "--out", str(out),
                 "--html", str(page)]) == 0  # fmt: skip
    printed = capsys.readouterr().out.split()
    assert printed == [str(out), str(out.with_suffix(".pdf")), str(page)]
    assert out.stat().st_size > 20_000 and out.with_suffix(".pdf").exists()
    assert_clean(record)
    [(_, fig)] = record
    urdf_chain = config.startswith("urdf")
    assert len(fig.axes) == (2 if urdf_chain else 1)  # the URDF's original beside the design
    title = fig._suptitle.get_text()
    assert ("→" in title) == urdf_chain  # the changed numbers, in m
    text = page.read_text()
    assert "Plotly.newPlot" in text and "id='robot'" in text.replace('"', "'")
    assert not re.search(r"<(script|link)[^>]+(src|href)=", text)  # offline: nothing fetched
    shutil.copy(out, SHOTS / f"view_{Path(config).stem}.png") if SHOTS.is_dir() else None


@pytest.mark.parametrize("argv,needle", [
    (["--q", "1,2"], "--q 1,2: expected 6 finite numbers"),
    (["--q", "a,b,c,d,e,f"], "--q a,b,c,d,e,f: expected 6 numbers"),
    (["--q", "0,250,0,0,0,0"], "q2 = 250 deg is outside its limits [-45, 225] deg"),
    (["--design", "a9=1"], "--design a9: not a design variable"),
    (["--design", "a2=x"], "--design a2"),
    (["--out", "OUT/robot.pdf"], "give a .png file name"),
])  # fmt: skip
def test_view_refuses_bad_input_in_one_line(argv, needle, tmp_path, capsys):
    argv = [a.replace("OUT", str(tmp_path)) for a in argv]
    before = _files(tmp_path)
    rc = main(["view", str(ROOT / "configs/puma560.yaml"), "--out", str(tmp_path / "r.png"),
               *argv])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and needle in err, err
    assert err.count("\n") == 1 and err.startswith("designopt: error: ")
    assert _files(tmp_path) == before


@pytest.fixture(scope="module")
def front(tmp_path_factory):
    """A tiny NSGA-II front of the mesh arm: 1/k against the arm's length."""
    jax.config.update("jax_enable_x64", True)
    cfg = designopt.load_config(ROOT / "configs/urdf_mesh_arm.yaml", {
        "optimizer.name": "nsga2", "optimizer.n_particles": 8, "optimizer.n_iters": 3,
        "study.indices.n_samples": 256, "front.n_samples": 256,
        "study.objective": {"pareto": {"gci": "max",
                                       "length": {"min": {"l_upper": 1, "l_fore": 1}}}}})  # fmt: skip
    out = tmp_path_factory.mktemp("front") / "front.h5"
    designopt.run(cfg, out=out)
    return out, designopt.load(out)


def test_front_view_precomputes_each_designs_robot(front):
    _, rec = front
    fv = report.front_view(rec)
    s = rec.config.study
    mech = build(s)
    n = len(rec.X)
    assert len(fv.robots) == n and len(fv.hover) == n and len(fv.reference) == 1
    np.testing.assert_array_equal(fv.y, rec.X.sum(1))  # length = l_upper + l_fore
    fplot, rplot = hrobot.front_plots(fv, _Ids())
    link = rplot.fig["link"]
    assert link["source"] == fplot.id and len(link["designs"]) == n
    k = link["traces"][1]  # the design's centre line with its joints
    for i in range(n):
        want = drawing.arms(s, mech, [rec.X[i]], drawing.home(mech))[0][0].points()
        got = np.c_[[link["designs"][i]["data"][c][1] for c in "xyz"]].T
        np.testing.assert_allclose(got, want, atol=1e-12)
    np.testing.assert_allclose(np.c_[[rplot.fig["data"][k][c] for c in "xyz"]].T,
                               drawing.arms(s, mech, [rec.X[0]], drawing.home(mech))[0][0].points())  # fmt: skip


def _names_of(fig) -> list[str]:
    return [str(t.get("name", "")) for t in fig["data"]]


def test_front_view_draws_the_original_only_where_links_are_variables(front):
    """The faint original robot (the URDF's numbers) stays beside designs that change the
    links (l_upper, l_fore here) and is left out, with its note, where every design has
    the file's links: a planning case that moves only ports and bases, made here from the
    original robot itself at other joints and on another base."""
    import dataclasses

    _, rec = front
    fv = report.front_view(rec)
    s = rec.config.study
    mech = build(s)
    (ref,) = fv.reference
    assert not hrobot.same_links(ref, fv.robots[0][0])  # the design's l_upper, l_fore
    _, rplot = hrobot.front_plots(fv, _Ids())
    assert any("original" in n for n in _names_of(rplot.fig))
    assert "original robot" in hrobot._note(fv)
    rng = np.random.default_rng(4)
    base = np.eye(4)
    base[:3, :3] = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    base[:3, 3] = [0.3, -0.2, 0.1]
    robots = []
    for i in range(len(rec.X)):
        q = mech.lower + (mech.upper - mech.lower) * rng.uniform(size=mech.n)
        (arm,) = drawing.original_arms(s, mech, rec.X[i], q, label="design")
        robots.append([dataclasses.replace(arm, base=base)])
    assert hrobot.same_links(ref, robots[0][0])
    planned = dataclasses.replace(fv, robots=robots)
    assert planned.shown_reference() == []
    fplot, rplot = hrobot.front_plots(planned, _Ids())
    assert not any("original" in n for n in _names_of(rplot.fig))
    assert "original robot" not in hrobot._note(planned)
    assert hrobot._note(planned).startswith("each design")
    page = hrobot.robot_section(front=planned)
    assert not any("original robot" in it for it in page.items if isinstance(it, str))
    # the front beside: ± 2 SE bars, the archived SEs (report.front_view passes them); none
    # without standard errors
    tr = fplot.fig["data"][0]
    nose = dataclasses.replace(planned, x_se=None, y_se=None)
    assert "error_x" not in hrobot.front_plots(nose, _Ids())[0].fig["data"][0]
    np.testing.assert_allclose(tr["error_x"]["array"], 2 * rec.F_se[:, 0], rtol=1e-12)
    np.testing.assert_allclose(tr["error_y"]["array"], 2 * rec.F_se[:, 1], rtol=1e-12)
    assert "± 2 SE" in fplot.fig["layout"]["title"]["text"]


def test_front_page_draws_the_hovered_designs_robot(front, tmp_path):
    """The report of the front in headless Chromium: no console error, the robot's WebGL
    canvas has a size, and moving the mouse onto design i draws design i's robot (its
    centre line read back from the page equals the design's FK)."""
    from test_html_report import CHROMIUM, Browser

    if CHROMIUM is None:
        pytest.skip("chromium is not installed; the page was not opened in a browser")
    from designopt.app import reporting

    path, rec = front
    page = reporting.write_html(path)
    size = page.stat().st_size
    print(f"front page: {size / 1e6:.2f} MB")
    assert size < 10e6
    s = rec.config.study
    mech = build(s)
    b = Browser(tmp_path / "profile", tmp_path / "chromium.log")
    try:
        b.load(page, timeout=60)
        assert b.errors() == []
        fid = b.js("document.querySelector('div.plot[id$=\"robot-front\"]').id")
        rid = b.js("document.querySelector('div.plot[id$=\"robot-design\"]').id")
        wh = b.js(f"Array.from(document.getElementById('{rid}').querySelectorAll('canvas'))"
                  ".map(c => c.width * c.height)")  # fmt: skip
        assert wh and max(wh) > 0
        i = len(rec.X) - 1
        xy = b.js(f"""(() => {{ const g = document.getElementById('{fid}'); g.scrollIntoView();
            const L = g._fullLayout, t = g._fullData[0], r = g.getBoundingClientRect();
            return [r.left + L._size.l + L.xaxis.l2p(t.x[{i}]),
                    r.top + L._size.t + L.yaxis.l2p(t.y[{i}])]; }})()""")  # fmt: skip
        b.call("Input.dispatchMouseEvent", session=True, type="mouseMoved", x=xy[0], y=xy[1])
        import time

        end = time.monotonic() + 10
        while b.js(f"document.getElementById('{rid}').getAttribute('data-design')") != str(i):
            assert time.monotonic() < end, "hovering the design did not draw its robot"
            time.sleep(0.05)
        got = b.js(f"""(() => {{ const g = document.getElementById('{rid}');
            const t = g._fullData.find(t => t.name === 'design: joints');
            return [Array.from(t.x), Array.from(t.y), Array.from(t.z)]; }})()""")  # fmt: skip
        want = drawing.arms(s, mech, [rec.X[i]], drawing.home(mech))[0][0].points()
        np.testing.assert_allclose(np.array(got).T, want, atol=1e-12)
        assert b.errors() == []
        if SHOTS.is_dir():
            b.screenshot(SHOTS / "front_page.png")
    finally:
        b.close()


def test_task_figure_of_a_solid_task_draws_the_arms_in_3d(record, tmp_path, monkeypatch):
    """configs/puma560_task.yaml's box task with a solution made from the forward
    kinematics (random joints; a few targets marked unreached): the task figure's 3-D
    panel draws the arm at the worst-conditioned, median and best-conditioned reached
    targets, each with its tip on its target, and passes the figure checker."""
    from types import SimpleNamespace

    from designopt.studies.serial import figures as serial_figs

    s = designopt.load_config(ROOT / "configs/puma560_task.yaml").study
    mech = build(s)
    x = np.array([0.45, 0.42])
    rng = np.random.default_rng(4)
    q = mech.lower + (mech.upper - mech.lower) * rng.random((64, 6))
    P, _, R = drawing.joint_frames(mech, drawing.full(mech, [x]), q)
    ok = np.ones(64, bool)
    ok[:5] = False
    sol = {"target_p": P[0, :, -1], "success": ok, "q": q,
           "inv_k": np.where(ok, serial_figs.inv_k(mech, s, x, q), 0.0),
           "manipulability": ok * 1.0, "joint_margin": ok * 0.5}  # fmt: skip
    monkeypatch.setattr(serial_figs, "task_solution", lambda rec: sol)
    rec = SimpleNamespace(config=SimpleNamespace(study=s), x={"a2": x[0], "d4": x[1]},
                          warnings=[], indices={})  # fmt: skip
    serial_figs.draw_task(rec, tmp_path)
    assert_clean(record)
    [(_, fig)] = record
    ax3 = next(a for a in fig.axes if hasattr(a, "get_zlim"))
    for k, (_, i) in enumerate(drawing.representatives(sol)):
        got = _joints_read_back(ax3, k)
        np.testing.assert_allclose(got[1:], P[0, i], atol=1e-12)  # the joints, then the tip
        np.testing.assert_allclose(got[-1], sol["target_p"][i], atol=1e-12)
    assert len(fig.axes) == 4  # top view, side view, colour bar, the 3-D panel
