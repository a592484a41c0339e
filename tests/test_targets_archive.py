"""The final design at every target (the archive's ``targets`` group) and ``designopt
show ARCHIVE --csv``: the joints put the 2R arm's tip on each reached target (NumPy FK),
the group's means are the archived indices, and the CSV gives the joints in degrees."""

from __future__ import annotations

import csv

import numpy as np
import yaml

from designopt.app import records
from designopt.cli.commands import main


def _run(tmp_path) -> tuple[str, object]:
    with open("configs/planar2r_task.yaml") as f:
        cfg = yaml.safe_load(f)
    cfg["study"]["indices"]["n_samples"] = 64
    cfg["optimizer"] = {"name": "ptpso", "n_particles": 6, "n_iters": 2, "n_runs": 1}
    cfg["output"] = str(tmp_path / "r.h5")
    cfg.pop("scan", None)
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(p), "--no-figures", "--quiet"]) == 0
    return str(tmp_path / "r.h5"), records.load(tmp_path / "r.h5")


def test_targets_group_and_show_csv(tmp_path, capsys):
    path, rec = _run(tmp_path)
    g = rec["targets"]
    l1, l2 = rec.x["l1"], rec.x["l2"]
    q = np.asarray(g["q"], np.float64)[0]
    ok = np.asarray(g["success"], bool)[0]
    p = np.asarray(g["target_p"], np.float64)
    tip = np.stack([l1 * np.cos(q[:, 0]) + l2 * np.cos(q[:, 0] + q[:, 1]),
                    l1 * np.sin(q[:, 0]) + l2 * np.sin(q[:, 0] + q[:, 1])], -1)  # fmt: skip
    assert ok.sum() > 10
    assert np.max(np.linalg.norm(tip[ok] - p[ok, :2], axis=-1)) < 1e-6 * (l1 + l2) * 10
    fin = rec["final"]
    assert np.mean(ok) == float(fin["reach"])
    assert abs(np.mean(np.asarray(g["inv_k"])[0]) - float(fin["gci"])) < 1e-12
    capsys.readouterr()
    assert main(["show", path, "--csv"]) == 0
    out = tmp_path / "r_targets.csv"
    assert f"wrote {out}" in capsys.readouterr().out
    with out.open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["arm", "target", "x [L]", "y [L]", "z [L]", "reached", "q1 [deg]",
                       "q2 [deg]", "inv_k"]  # fmt: skip
    assert len(rows) == 1 + len(p)
    assert [int(r[1]) for r in rows[1:]] == list(range(len(p)))  # targets from 0, as arms
    assert [int(r[5]) for r in rows[1:]] == ok.astype(int).tolist()
    got = np.array([[float(r[6]), float(r[7])] for r, o in zip(rows[1:], ok, strict=True) if o])
    np.testing.assert_allclose(got, np.rad2deg(q[ok]), rtol=0, atol=1e-12)
    assert all(r[6:] == ["", "", ""] for r, o in zip(rows[1:], ok, strict=True) if not o)  # no solution


def test_show_csv_of_an_archive_without_targets_is_one_line(tmp_path, capsys):
    with open("configs/planar2r.yaml") as f:
        cfg = yaml.safe_load(f)
    cfg["optimizer"] = {"name": "ptpso", "n_particles": 4, "n_iters": 1, "n_runs": 1}
    cfg["study"]["indices"]["n_samples"] = 256
    cfg["output"] = str(tmp_path / "j.h5")
    cfg.pop("scan", None)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["run", str(tmp_path / "c.yaml"), "--no-figures", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["show", str(tmp_path / "j.h5"), "--csv"]) == 2
    err = capsys.readouterr().err
    assert "targets group" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "j_targets.csv").exists()
