"""``designopt ik CONFIG --poses FILE`` for any study with ``Study.ik`` (designopt/cli/ik.py)
on a serial chain: the PUMA 560 (standard DH, m) solving targets made by an independent
numpy FK from random joints, every CSV format, ``--mode``, the archive and its summary;
bad files and refused requests are one line each, exit 2, nothing written. The da Vinci
arm's own tests (tests/test_davinci_ik.py) run it through the same command."""

import csv
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from designopt import results
from designopt.app import records
from designopt.cli.commands import main
from designopt.io import archive
from designopt.io import poses as target_files
from designopt.kinematics import poses

ROOT = Path(__file__).resolve().parents[1]
N = 256
LIM = np.radians([[-160, 160], [-45, 225], [-225, 45], [-110, 170], [-100, 100], [-266, 266]])
ALPHA = np.radians([90, 0, -90, 90, -90, 0])
FIXED = {"a3": 0.0203, "d3": 0.15005}


def fk(q: np.ndarray, a2: float = 0.45, d4: float = 0.45) -> np.ndarray:
    """(N, 4, 4) standard-DH FK of the PUMA 560 (Rz θ · Tz d · Tx a · Rx α), in numpy."""
    a = [0.0, a2, FIXED["a3"], 0.0, 0.0, 0.0]
    d = [0.0, 0.0, FIXED["d3"], d4, 0.0, 0.0]
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    for i in range(6):
        ct, st, ca, sa = np.cos(q[:, i]), np.sin(q[:, i]), np.cos(ALPHA[i]), np.sin(ALPHA[i])
        A = np.zeros((len(q), 4, 4))
        A[:, 0] = np.stack([ct, -st * ca, st * sa, a[i] * ct], -1)
        A[:, 1] = np.stack([st, ct * ca, -ct * sa, a[i] * st], -1)
        A[:, 2, 1:] = [sa, ca, d[i]]
        A[:, 3, 3] = 1.0
        T = T @ A
    return T


def inv_k_position(q: np.ndarray, **design: float) -> np.ndarray:
    """1/k (2-norm) of the position Jacobian by central differences of :func:`fk`."""
    h, out = 1e-6, []
    for qi in q:
        Q = qi + h * np.concatenate([np.eye(6), -np.eye(6)])
        p = fk(Q, **design)[:, :3, 3]
        s = np.linalg.svd((p[:6] - p[6:]).T / (2 * h), compute_uv=False)
        out.append(s[-1] / s[0])
    return np.array(out)


def quat(R: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions w, x, y, z of rotations R (Shepperd: from the largest of
    w², x², y², z², so no division by a small number)."""
    out = []
    for m in R:
        d = [m[0, 0] + m[1, 1] + m[2, 2], m[0, 0], m[1, 1], m[2, 2]]
        k = int(np.argmax(d))
        t = 1 + 2 * d[k] - d[0] if k else 1 + d[0]
        s = 0.5 / np.sqrt(t)
        skew = [m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]
        sym = {(1, 2): m[0, 1] + m[1, 0], (1, 3): m[0, 2] + m[2, 0], (2, 3): m[1, 2] + m[2, 1]}
        v = np.empty(4)
        v[k] = t * s
        for j in range(4):
            if j != k:
                v[j] = (skew[max(j, k) - 1] if 0 in (j, k) else sym[min(j, k), max(j, k)]) * s
        out.append(v)
    return np.array(out)


def write_csv(path: Path, head: list[str], rows: np.ndarray) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        w.writerows([[repr(float(v)) for v in r] for r in rows])
    return path


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A float64 copy of configs/puma560.yaml, N poses from random joints in the limits
    written in every format, and the pose-mode solve of the T00..T33 file."""
    d = tmp_path_factory.mktemp("ik")
    raw = yaml.safe_load((ROOT / "configs" / "puma560.yaml").read_text())
    raw["precision"] = "float64"
    raw.pop("output")
    cfg = d / "puma.yaml"
    cfg.write_text(yaml.safe_dump(raw))
    q = LIM[:, 0] + (LIM[:, 1] - LIM[:, 0]) * np.random.default_rng(7).random((N, 6))
    T = fk(q)
    p, R = T[:, :3, 3], T[:, :3, :3]
    qrows = np.c_[quat(R)[:, [1, 2, 3, 0]], p]
    files = {
        "matrix": write_csv(d / "m.csv", list(target_files.MATRIX_COLUMNS), T.reshape(N, 16)),
        "quat": write_csv(d / "q.csv", ["qx", "qy", "qz", "qw", "x", "y", "z"], qrows),
        "axis": write_csv(d / "a.csv", ["x", "y", "z", "ax", "ay", "az"], np.c_[p, R[:, :, 2]]),
        "xyz": write_csv(d / "p.csv", ["z", "y", "x"], p[:, ::-1]),
    }
    with h5py.File(d / "t.h5", "w") as f:
        f["poses"] = T
    files["h5"] = d / "t.h5"
    out = d / "m_ik.h5"
    assert main(["ik", str(cfg), "--poses", str(files["matrix"]), "--out", str(out), "--csv",
                 "--quiet"]) == 0  # fmt: skip
    return {"dir": d, "cfg": cfg, "T": T, "files": files, "out": out}


def check_solved(ik: dict, T: np.ndarray, mode: str, rate: float = 0.99, **design: float):
    """Success ≥ rate; every solved row's independent FK meets its target to 1e-9 (what
    the mode matches), within the joint limits; the archived errors agree."""
    ok = ik["success"]
    assert ok.mean() >= rate, ok.mean()
    q = ik["q"][ok]
    assert np.all((q >= LIM[:, 0] - 1e-12) & (q <= LIM[:, 1] + 1e-12))
    F = fk(q, **design)
    pe = np.linalg.norm(F[:, :3, 3] - T[ok, :3, 3], axis=-1)
    assert pe.max() <= 1e-9
    np.testing.assert_allclose(ik["pos_err"][ok], pe, atol=1e-12)
    if mode == "pose":
        assert np.abs(F[:, :3, :3] - T[ok, :3, :3]).max() <= 1e-9
    if mode == "axis":
        assert np.abs(F[:, :3, 2] - T[ok, :3, 2]).max() <= 1e-9
    if mode == "position":
        assert not ik["rot_err"].any()
    return ok


def test_pose_csv_solves_and_archives(case, capsys):
    rec = records.load(case["out"])
    assert isinstance(rec, results.IKRecord) and rec.study == "serial"
    ik = rec.ik
    ok = check_solved(ik, case["T"], "pose")
    np.testing.assert_allclose(ik["inv_k"][ok], inv_k_position(ik["q"][ok]), rtol=1e-5, atol=1e-8)
    assert rec.targets == "pose" and rec.design == pytest.approx({"a2": 0.45, "d4": 0.45})
    assert rec.joint_names == [f"q{i}" for i in range(1, 7)]
    np.testing.assert_array_equal(ik["poses"], case["T"])
    # the archive round-trips, and `show` prints its summary
    assert results.from_tree(rec.to_tree()) == rec
    archive.save(case["dir"] / "copy.h5", rec)
    assert records.load(case["dir"] / "copy.h5") == rec
    capsys.readouterr()
    assert main(["show", str(case["out"])]) == 0
    out = capsys.readouterr().out
    assert f"{N} poses: {int(ok.sum())} solved" in out and "study serial" in out
    assert "matched: pose; design: a2 = 0.45, d4 = 0.45" in out and "1/k (position block)" in out
    # --csv: the archived joints in degrees (their unit in the header), with inv_k
    rows = list(csv.DictReader(case["out"].with_name("m_ik_joints.csv").open()))
    got = np.array([[float(r[f"q{i} [deg]"]) for i in range(1, 7)] for r in rows])
    np.testing.assert_array_equal(got, np.rad2deg(ik["q"]))
    assert "pos_err [m]" in rows[0] and "rot_err [deg]" in rows[0]
    np.testing.assert_array_equal([float(r["inv_k"]) for r in rows], ik["inv_k"])


def test_quaternion_csv_and_h5_solve_the_same_poses(case, monkeypatch):
    monkeypatch.chdir(case["dir"])  # the default --out: results/serial/<stem>_ik.h5
    assert main(["ik", str(case["cfg"]), "--poses", str(case["files"]["quat"]), "--quiet"]) == 0
    a = archive.read(case["dir"] / "results" / "serial" / "q_ik.h5")["ik"]
    check_solved(a, case["T"], "pose")
    np.testing.assert_allclose(a["poses"], case["T"], atol=1e-15)
    out = case["dir"] / "h.h5"
    assert main(["ik", str(case["cfg"]), "--poses", str(case["files"]["h5"]), "--out", str(out),
                 "--quiet"]) == 0  # fmt: skip
    h = archive.read(out)["ik"]
    np.testing.assert_array_equal(h["q"], archive.read(case["out"])["ik"]["q"])  # same targets


def test_position_mode_from_poses_and_xyz_files_and_design(case):
    out = case["dir"] / "pos.h5"
    assert main(["ik", str(case["cfg"]), "--poses", str(case["files"]["matrix"]), "--mode",
                 "position", "--out", str(out), "--quiet"]) == 0  # fmt: skip
    a = archive.read(out)["ik"]
    check_solved(a, case["T"], "position")
    assert a["attrs"]["targets"] == "position"
    out = case["dir"] / "xyz.h5"
    assert main(["ik", str(case["cfg"]), "--poses", str(case["files"]["xyz"]), "--design",
                 "a2=0.5", "--out", str(out), "--quiet"]) == 0  # fmt: skip
    b = archive.read(out)["ik"]
    check_solved(b, case["T"], "position", rate=0.5, a2=0.5)  # the arm solved is a2 = 0.5
    assert b["attrs"]["design"] == pytest.approx({"a2": 0.5, "d4": 0.45})
    np.testing.assert_array_equal(b["positions"], case["T"][:, :3, 3])


def test_axis_file_and_axis_mode(case):
    out = case["dir"] / "axis.h5"
    assert main(["ik", str(case["cfg"]), "--poses", str(case["files"]["axis"]), "--out", str(out),
                 "--quiet"]) == 0  # fmt: skip
    a = archive.read(out)["ik"]
    check_solved(a, case["T"], "axis")
    assert a["attrs"]["targets"] == "axis" and set(a) >= {"positions", "axes"}
    assert a["rot_err"][a["success"]].max() <= 1e-9


def _bad(tmp_path: Path, case: dict, edit: str) -> tuple[Path, int | None, str]:
    T = case["T"][:6]
    f = tmp_path / f"{edit}.csv"
    rows = T.reshape(6, 16).copy()
    head = list(target_files.MATRIX_COLUMNS)
    if edit == "header":
        head[0] = "A00"
        return write_csv(f, head, rows), None, "header"
    if edit == "nan":
        rows[2, 3] = np.nan
        return write_csv(f, head, rows), 3, "NaN or inf"
    if edit == "skew":
        rows[1, 0] += 0.01
        return write_csv(f, head, rows), 2, "orthonormal"
    if edit == "reflection":
        rows[4, [0, 4, 8]] *= -1
        return write_csv(f, head, rows), 5, "det −1"
    if edit == "quaternion":
        return write_csv(f, list(target_files.QUAT_COLUMNS), [[0.1, 0, 0, 1, 0, 0, 0],
                                                       [0.1, 0, 0, 0.9, 0, 0, 0]]), 2, "quaternion"  # fmt: skip
    if edit == "axis":
        return write_csv(f, list(target_files.AXIS_COLUMNS), [[0.1, 0, 0, 0, 0, 1], [0.1, 0, 0, 0, 0, 1],
                                                       [0.1, 0, 0, 0, 0.5, 0]]), 3, "unit vector"  # fmt: skip
    text = write_csv(f, head, rows).read_text().splitlines()
    if edit == "text":
        text[4] = "x," + text[4].split(",", 1)[1]
        row, words = 4, "not a number"
    else:  # short
        text[2] = text[2].rsplit(",", 1)[0]
        row, words = 2, "values"
    f.write_text("\n".join(text) + "\n")
    return f, row, words


@pytest.mark.parametrize("edit", ["header", "nan", "skew", "reflection", "quaternion", "axis",
                                  "text", "short"])  # fmt: skip
def test_bad_file_is_one_line_naming_the_file_and_row(case, tmp_path, capsys, edit):
    f, row, words = _bad(tmp_path, case, edit)
    out = tmp_path / "o.h5"
    capsys.readouterr()
    assert main(["ik", str(case["cfg"]), "--poses", str(f), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
    assert str(f) in err and words in err, err
    if row is not None:
        assert f"row {row}:" in err, err
    assert not out.exists()


def _refused(capsys, argv: list[str], *needles: str) -> None:
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, (n, err)


def test_refused_requests(case, tmp_path, capsys):
    cfg, files, out = str(case["cfg"]), case["files"], str(tmp_path / "o.h5")
    _refused(capsys, ["ik", cfg, "--poses", str(files["xyz"]), "--mode", "pose", "--out", out],
             str(files["xyz"]), "--mode pose needs full poses", "positions only")  # fmt: skip
    _refused(capsys, ["ik", cfg, "--poses", str(files["axis"]), "--mode", "pose", "--out", out],
             "tool axes")  # fmt: skip
    _refused(capsys, ["ik", cfg, "--poses", str(tmp_path / "none.csv"), "--out", out],
             "poses file not found")  # fmt: skip
    _refused(capsys, ["ik", cfg, "--poses", str(files["matrix"]), "--design", "l9=1", "--out", out],
             "--design l9")  # fmt: skip
    _refused(capsys, ["ik", cfg, "--poses", str(files["matrix"]), "--trajectory", "--out", out],
             "--trajectory: an option of study 'davinci', not of study 'serial'")  # fmt: skip
    with h5py.File(tmp_path / "bad.h5", "w") as f:
        f["poses"] = np.zeros((3, 3, 3))
    _refused(capsys, ["ik", cfg, "--poses", str(tmp_path / "bad.h5"), "--out", out],
             "bad.h5", "(N, 4, 4)")  # fmt: skip
    single = tmp_path / "single.yaml"
    single.write_text(case["cfg"].read_text().replace("precision: float64", "precision: float32"))
    _refused(capsys, ["ik", str(single), "--poses", str(files["matrix"]), "--out", out],
             "key 'precision'", "float64")  # fmt: skip
    # a study without inverse kinematics; a study that solves full poses only
    _refused(capsys, ["ik", str(ROOT / "configs" / "plas.yaml"), "--poses", str(files["matrix"]),
                      "--out", out], "study 'plas' has no inverse kinematics")  # fmt: skip
    _refused(capsys, ["ik", str(ROOT / "configs" / "davinci_ik.yaml"), "--poses",
                      str(files["matrix"]), "--mode", "position", "--out", out],
             "--mode position: study 'davinci' solves pose targets")  # fmt: skip
    assert not (tmp_path / "o.h5").exists()


def test_axis_frames_and_modes_match_the_solver():
    from designopt.kinematics import ik

    assert poses.MODES == ik.MODES
    a = np.random.default_rng(0).normal(size=(50, 3))
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    a[0] = [1.0, 0.0, 0.0]
    R = poses.axis_frames(a)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", R, R), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-15)  # fmt: skip
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-15)
    np.testing.assert_array_equal(R[:, :, 2], a)
