"""``designopt ik`` on the da Vinci arm (its ``Study.ik`` hook, ikcli.py, through the
generic command designopt/ikcmd.py): poses files in, archive out; bad files are one
ConfigError naming the row (the CLI prints it and exits 2)."""

import h5py
import jax.numpy as jnp
import numpy as np
import pytest

from designopt.cli.commands import build_parser
from designopt.core.errors import ConfigError
from designopt.io import archive
from designopt.studies.davinci import ikcli, paper
from designopt.studies.davinci import mechanism as m

CONFIG = "configs/davinci_ik.yaml"
X = jnp.asarray(m.table1())


def run(*argv):
    a = build_parser().parse_args(["ik", *map(str, argv)])
    return a.func(a)


def poses(n=6):
    q = np.tile(paper.to_rad(paper.TABLE2_DEG), (-(-n // 6), 1))[:n]
    return q, np.array(m.pose(X, jnp.asarray(q)))


def write_matrix_csv(path, T):
    cols = ikcli.MATRIX_COLUMNS
    lines = [",".join(cols)] + [",".join(repr(float(v)) for v in t.ravel()) for t in T]
    path.write_text("\n".join(lines) + "\n")


def to_quat(R):
    w = 0.5 * np.sqrt(np.maximum(1 + np.trace(R, axis1=1, axis2=2), 0))
    x = (R[:, 2, 1] - R[:, 1, 2]) / (4 * w)
    y = (R[:, 0, 2] - R[:, 2, 0]) / (4 * w)
    z = (R[:, 1, 0] - R[:, 0, 1]) / (4 * w)
    return np.stack([w, x, y, z], -1)


def test_matrix_csv_solves_table2_and_writes_the_archive(tmp_path, capsys):
    q, T = poses()
    f = tmp_path / "p.csv"
    write_matrix_csv(f, T)
    out = tmp_path / "ik.h5"
    assert run(CONFIG, "--poses", f, "--out", out) == 0
    a = archive.read(out)["ik"]
    assert a["q"].shape == (6, 6) and a["success"].all()
    np.testing.assert_allclose(a["q"], q, atol=1e-9)
    assert a["pos_err"].max() <= 1e-9 and a["rot_err"].max() <= 1e-9
    assert "6 solved" in capsys.readouterr().out


def test_quaternion_csv_h5_and_trajectory_agree(tmp_path):
    q, T = poses(12)
    quat = to_quat(T[:, :3, :3])
    f = tmp_path / "q.csv"
    rows = ["qw,qx,qy,qz,x,y,z"] + [
        ",".join(repr(float(v)) for v in (*qq, *t[:3, 3])) for qq, t in zip(quat, T, strict=True)
    ]
    f.write_text("\n".join(rows) + "\n")
    h = tmp_path / "p.h5"
    with h5py.File(h, "w") as fh:
        fh["poses"] = T
    assert run(CONFIG, "--poses", f, "--out", tmp_path / "a.h5", "--quiet") == 0
    assert run(CONFIG, "--poses", h, "--out", tmp_path / "b.h5", "--quiet", "--trajectory") == 0
    a, b = archive.read(tmp_path / "a.h5")["ik"], archive.read(tmp_path / "b.h5")["ik"]
    assert a["success"].all() and b["success"].all()
    np.testing.assert_allclose(a["q"], q, atol=1e-8)
    np.testing.assert_allclose(b["q"], a["q"], atol=1e-8)
    assert archive.read(tmp_path / "b.h5")["ik"]["attrs"]["mode"] == "trajectory"


@pytest.mark.parametrize(
    "edit, row, words",
    [
        ("columns", None, "header"),
        ("nan", 3, "NaN"),
        ("skew", 2, "orthonormal"),
        ("text", 4, "not a number"),
        ("short", 5, "values"),
    ],
)
def test_bad_csv_is_one_error_naming_the_row(tmp_path, edit, row, words):
    _, T = poses()
    f = tmp_path / "bad.csv"
    write_matrix_csv(f, T)
    lines = f.read_text().splitlines()
    if edit == "columns":
        lines[0] = lines[0].replace("T00", "A00")
    elif edit == "nan":
        lines[row] = lines[row].replace(lines[row].split(",")[5], "nan", 1)
    elif edit == "skew":
        v = lines[row].split(",")
        v[0] = repr(float(v[0]) * (1 + 1e-5))
        lines[row] = ",".join(v)
    elif edit == "text":
        lines[row] = "x," + lines[row].split(",", 1)[1]
    elif edit == "short":
        lines[row] = lines[row].rsplit(",", 1)[0]
    f.write_text("\n".join(lines) + "\n")
    out = tmp_path / "o.h5"
    with pytest.raises(ConfigError) as e:
        run(CONFIG, "--poses", f, "--out", out)
    msg = str(e.value)
    assert str(f) in msg and words in msg
    if row is not None:
        assert f"row {row}:" in msg
    assert not out.exists()


def test_orthonormal_within_tolerance_is_accepted_and_nonunit_quaternion_refused(tmp_path):
    _, T = poses()
    T[:, :3, :3] *= 1 + 1e-8
    f = tmp_path / "ok.csv"
    write_matrix_csv(f, T)
    assert len(ikcli.read_poses(f)) == 6
    g = tmp_path / "q.csv"
    g.write_text("x,y,z,qw,qx,qy,qz\n1,2,3,1,0,0,0\n1,2,3,0.9,0,0,0\n")
    with pytest.raises(ConfigError, match="row 2: quaternion"):
        ikcli.read_poses(g)


def test_api_refuses_nan_and_inf_with_the_pose_number():
    from designopt.app.config import load

    cfg, _ = load(CONFIG)
    _, T = poses()
    T[4, 1, 3] = np.inf
    with pytest.raises(ValueError, match="pose 5: NaN or inf"):
        ikcli.solve_poses(cfg.study, T)


def test_wrong_study_and_missing_file_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="poses file not found"):
        run(CONFIG, "--poses", tmp_path / "none.csv", "--out", tmp_path / "o.h5")
    with pytest.raises(ConfigError, match="study 'plas' has no inverse kinematics"):
        run("configs/plas.yaml", "--poses", tmp_path / "none.csv", "--out", tmp_path / "o.h5")


@pytest.mark.slow
def test_batches_padding_and_trajectory_segments_agree(tmp_path):
    """More poses than ``ik.batch``: cold batches (the last padded) and trajectory
    segments (each warm-started from the previous segment's last solution)."""
    import yaml

    from designopt.app.config import validate

    raw = yaml.safe_load(open(CONFIG))
    raw["study"]["ik"]["batch"] = 4
    cfg = validate(raw, "test")
    q, T = poses(10)
    cold = ikcli.solve_poses(cfg.study, T)
    traj = ikcli.solve_poses(cfg.study, T, trajectory=True)
    assert cold["q"].shape == (10, 6) and cold["success"].all() and traj["success"].all()
    np.testing.assert_allclose(cold["q"], q, atol=1e-8)
    np.testing.assert_allclose(traj["q"], q, atol=1e-8)
