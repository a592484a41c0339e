"""Incision points and bases in numbers (issue 53) on the shipped planning case
(configs/port_placement.yaml at tiny sizes): `eval --json`, the run's summary, `show`,
the archive (final/ and front/), the CSV of a run and of a front (every design's
targets, a design column). The ports are checked against an independent closest point
on the ellipsoid wall (scipy, from the design's own numbers), the bases against the
config's xyz/rpy, the projection distance against both, the per-target values of each
front design against the front's re-scored indices."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import h5py
import jax
import numpy as np
import pytest
from scipy.optimize import minimize

from designopt.cli.commands import main

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parents[1]
CFG = str(ROOT / "configs/port_placement.yaml")
TINY = ["--set", "study.indices.n_samples=32", "--set", "front.n_samples=32",
        "--set", "optimizer.n_particles=4", "--set", "optimizer.n_iters=2"]  # fmt: skip
CENTRE, RADII, PORT_Z = np.array([0.0, 0.0, 0.06]), np.array([0.20, 0.25, 0.12]), 0.30
NAMES = ("b", "by", "px", "py0", "py1")


def _closest(p: np.ndarray) -> np.ndarray:
    """The wall's closest point to p: a constrained minimisation from 12 starts."""
    best = None
    for th in np.linspace(0.2, 2.9, 4):
        for ph in np.linspace(-2.5, 2.5, 3):
            x0 = CENTRE + RADII * np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph),
                                            np.cos(th)])  # fmt: skip
            r = minimize(lambda x: np.sum((x - p) ** 2), x0, method="SLSQP",
                         constraints=[{"type": "eq",
                                       "fun": lambda x: np.sum(((x - CENTRE) / RADII) ** 2) - 1}],
                         options={"ftol": 1e-15, "maxiter": 500})  # fmt: skip
            if best is None or r.fun < best.fun:
                best = r
    return best.x


def _expected(x: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points before projection (2, 3), ports (2, 3), bases (2, 6)) from the config's
    arms: ports [-px, py0, 0.30] and [px, py1, 0.30], bases [-b, by, 0] rpy 0 and
    [b, by, 0] rpy (0, 0, 180)."""
    pts = np.array([[-x["px"], x["py0"], PORT_Z], [x["px"], x["py1"], PORT_Z]])
    bases = np.array([[-x["b"], x["by"], 0, 0, 0, 0], [x["b"], x["by"], 0, 0, 0, 180.0]])
    return pts, np.array([_closest(p) for p in pts]), bases


def _printed_ports(text: str) -> list[np.ndarray]:
    return [np.array([float(v) for v in m.split(",")])
            for m in re.findall(r"port \(([^)]*)\) m", text)]  # fmt: skip


def test_eval_json_and_text_give_the_incision_points_and_bases(capsys):
    x = {"b": 0.6, "by": 0.05, "px": 0.1, "py0": -0.09, "py1": 0.04}
    args = ["eval", CFG, *TINY[:2], "--design", ",".join(f"{k}={v}" for k, v in x.items())]
    assert main([*args, "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    pts, ports, bases = _expected(x)
    np.testing.assert_allclose(js["ports"], ports, atol=2e-6)
    np.testing.assert_allclose(js["port_points"], pts, atol=1e-15)
    np.testing.assert_allclose(js["bases"], bases, atol=1e-15)
    np.testing.assert_allclose(js["port_shift"], np.linalg.norm(ports - pts, axis=1), atol=2e-6)
    assert np.all(np.asarray(js["port_shift"]) > 0.05)  # the projection moved them (cm)
    assert main(args) == 0
    out = capsys.readouterr().out
    shown = _printed_ports(out)
    np.testing.assert_allclose(shown[:2], ports, atol=6e-5)  # 4 decimals in the text
    assert "incision point" in out and "rpy (0.00, 0.00, 180.00) deg" in out
    assert re.search(r"clearance = \S+ ± \S+ m\b", out), out  # the index with its unit


@pytest.fixture(scope="module")
def front(tmp_path_factory):
    d = tmp_path_factory.mktemp("front")
    out = d / "pp.h5"
    assert main(["run", CFG, *TINY, "--out", str(out), "--quiet", "--no-figures"]) == 0
    return out


def test_a_front_archives_every_designs_ports_bases_and_targets(front, capsys):
    capsys.readouterr()
    with h5py.File(front) as h:
        X = h["front/x"][()]
        ports, bases, shift = h["front/ports"][()], h["front/bases"][()], h["front/port_shift"][()]
        ok, tp = h["targets/success"][()], h["targets/target_p"][()]
        reach = [h[f"front/reach_{k}"][()] for k in (0, 1)]
        n_samples = int(h["front"].attrs["n_samples"])
    P = len(X)
    assert ports.shape == (P, 2, 3) and bases.shape == (P, 2, 6) and shift.shape == (P, 2)
    assert ok.shape == (P, 2, n_samples) and tp.shape == (n_samples, 3)
    for i in range(P):
        x = dict(zip(NAMES, X[i], strict=True))
        pts, want, b = _expected(x)
        np.testing.assert_allclose(ports[i], want, atol=2e-6)
        np.testing.assert_allclose(bases[i], b, atol=1e-15)
        np.testing.assert_allclose(shift[i], np.linalg.norm(want - pts, axis=1), atol=2e-6)
        for k in (0, 1):  # the re-scoring's targets: their share reached is reach_k
            np.testing.assert_allclose(ok[i, k].mean(), reach[k][i], rtol=0, atol=1e-12)
    # show prints each shown design's ports
    assert main(["show", str(front)]) == 0
    text = capsys.readouterr().out
    assert "where the shown designs put the robot" in text
    np.testing.assert_allclose(_printed_ports(text)[:2], ports[0], atol=6e-5)


def test_a_fronts_csv_has_every_design_with_its_ports_and_bases(front, tmp_path, capsys):
    out = tmp_path / "f.csv"
    assert main(["show", str(front), "--csv", str(out)]) == 0
    capsys.readouterr()
    rows = list(csv.DictReader(out.open()))
    with h5py.File(front) as h:
        ports, bases, ok = h["front/ports"][()], h["front/bases"][()], h["targets/success"][()]
    P, A, N = ok.shape
    assert len(rows) == P * A * N and list(rows[0])[:3] == ["design", "arm", "target"]
    for r in rows[:: max(1, len(rows) // 17)]:
        d, a, t = int(r["design"]), int(r["arm"]), int(r["target"])
        got = [float(r[f"port_{c} [m]"]) for c in "xyz"]
        np.testing.assert_array_equal(got, ports[d, a])
        base = [float(r[f"base_{c} [m]"]) for c in "xyz"]
        base += [float(r[f"base_{c} [deg]"]) for c in ("roll", "pitch", "yaw")]
        np.testing.assert_array_equal(base, bases[d, a])
        assert int(r["reached"]) == int(ok[d, a, t])


def test_a_single_objective_run_prints_and_archives_its_ports(tmp_path, capsys):
    out = tmp_path / "one.h5"
    rc = main(["run", CFG, *TINY, "--set", "study.objective={gci: -1.0}", "--set",
               "optimizer.name=ptpso", "--set", "optimizer.n_iters=1", "--out", str(out),
               "--quiet", "--no-figures"])  # fmt: skip
    text = capsys.readouterr().out
    assert rc == 0, text
    with h5py.File(out) as h:
        x = dict(zip(NAMES, h["final/x"][()], strict=True))
        ports, bases = h["final/ports"][()], h["final/bases"][()]
        av = h["targets/arm_values"][()]
    pts, want, b = _expected(x)
    np.testing.assert_allclose(ports, want, atol=2e-6)
    np.testing.assert_allclose(bases, b, atol=1e-15)
    np.testing.assert_array_equal(av, np.concatenate([ports, bases], -1))
    np.testing.assert_allclose(_printed_ports(text)[:2], want, atol=6e-5)
    assert re.search(r"clearance = \S+ ± \S+ m", text), text
    assert main(["show", str(out), "--csv", str(tmp_path / "one.csv")]) == 0
    shown = capsys.readouterr().out
    np.testing.assert_allclose(_printed_ports(shown)[:2], want, atol=6e-5)
    rows = list(csv.DictReader((tmp_path / "one.csv").open()))
    assert "design" not in rows[0] and float(rows[0]["port_x [m]"]) == ports[0, 0]
    # the HTML report's table of the final design, read back from the file
    import html

    from designopt.app import records
    from designopt.figures.html.run import placement_table

    page = html.unescape(placement_table(records.load(out).groups["final"]))
    assert page.count("<tr>") == 3 and "base pose: x [m]" in page
    assert f"{ports[1, 2]:.6g}" in page and f"{bases[1, 0]:.6g}" in page


def test_csv_of_an_archive_without_targets_is_one_line(tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    text = (ROOT / "configs/planar2r.yaml").read_text()
    cfg.write_text(text.replace("output: results/planar2r/planar2r.h5",
                                f"output: {tmp_path / 'p.h5'}"))  # fmt: skip
    assert main(["run", str(cfg), "--set", "study.indices.n_samples=200", "--set",
                 "optimizer.n_iters=1", "--set", "optimizer.n_particles=4", "--quiet",
                 "--no-figures"]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["show", str(tmp_path / "p.h5"), "--csv"]) == 2
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "nothing to export" in err and "Traceback" not in err
    assert not list(tmp_path.glob("*.csv"))


def test_the_html_report_tables_the_ports_and_bases(front):
    """The report's table (figures.html.run.placement_table) of an archive read back:
    one row per design and arm, the study's headings, the archived numbers."""
    import html

    from designopt.app import records
    from designopt.figures.html.run import placement_table

    rec = records.load(front)
    fr = rec.groups["front"]
    page = html.unescape(placement_table(fr, front=True))
    ports, bases = np.asarray(fr["ports"]), np.asarray(fr["bases"])
    rows = page.split("<tr>")[2:]  # after the heading row
    assert len(rows) == ports.shape[0] * ports.shape[1]
    assert "port: the incision point on the body wall: x [m]" in page
    assert "base pose: yaw [deg]" in page
    cells = [c.split("</td>")[0] for c in rows[1].split("<td>")[1:]]
    assert cells[:2] == ["0", "1"]  # design 0, arm 1
    assert [float(c) for c in cells[2:5]] == pytest.approx(ports[0, 1], abs=1e-6)
    assert [float(c) for c in cells[-6:]] == pytest.approx(bases[0, 1], abs=1e-6)
