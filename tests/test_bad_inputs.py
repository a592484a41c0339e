"""Issue 38, "Refuse what is meaningless": every input below is refused by the CLI with
exit 2 and ONE line ``designopt: error: ...`` naming the key, file, row or element at
fault (no traceback), and nothing is written. Also: the one meaningful case kept (one
design variable bound to two URDF joint origins) and ``--design`` taking several
NAME=VALUE after one flag."""

from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from designopt.app.config import validate
from designopt.cli.commands import build_parser, main
from designopt.cli.setup import parse_design
from designopt.io import poses as target_files
from designopt.kinematics import urdf as U
from designopt.studies.serial.commands import set_values
from designopt.studies.serial.mechanism import build

ROOT = Path(__file__).resolve().parents[1]

_LIM = '<limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>'

# A 3-joint arm (yaw, two pitches) with a fixed tool joint: base → l1 → l2 → l3 → tip.
ARM = f"""<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>{_LIM}</joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>{_LIM}</joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>{_LIM}</joint>
  <joint name="tool" type="fixed"><parent link="l3"/><child link="tip"/>
    <origin xyz="0.25 0 0"/></joint>
</robot>
"""

# the same arm with a second tree beside it: the roots 'base' and 'stray'
TWO_ROOTS = ARM.replace(
    "</robot>",
    '  <link name="stray"/><link name="stray_child"/>\n'
    '  <joint name="s1" type="fixed"><parent link="stray"/><child link="stray_child"/></joint>\n'
    "</robot>",
)


def _files(tmp_path: Path) -> list[Path]:
    return sorted(tmp_path.rglob("*"))


def _refused(capsys, argv: list[str], *needles: str) -> str:
    """``main(argv)`` exits 2 with one line ``designopt: error: ...`` holding every
    needle, no traceback, nothing on stdout; the line."""
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 2
    out, err = capsys.readouterr()
    assert err.startswith("designopt: error: "), err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err and out == "", (out, err)
    for n in needles:
        assert n in err, (n, err)
    return err


def _urdf_cfg(tmp_path: Path, urdf: Path | str, **chain) -> Path:
    """A serial-study config on ``urdf`` (tip 'tip', j2's origin z the variable l)."""
    c = {"urdf": str(urdf), "tip": "tip", "set": {"j2.origin.z": "l"}} | chain
    cfg = {"study": {"name": "serial", "chain": c, "variables": {"l": [0.1, 0.5]},
                     "indices": {"jacobian": "position", "n_samples": 256},
                     "objective": {"gci": -1.0}},
           "optimizer": {"name": "ptpso", "n_particles": 4, "n_iters": 2, "n_runs": 1},
           "precision": "float64", "seed": 0, "output": str(tmp_path / "out" / "a.h5")}  # fmt: skip
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def _urdf_refused(tmp_path, capsys, cfg: Path, *needles: str) -> None:
    """eval, run and chain all refuse ``cfg`` with the needles; nothing written."""
    before = _files(tmp_path)
    for cmd in (["eval", cfg], ["run", cfg, "--quiet"], ["chain", cfg]):
        _refused(capsys, cmd, *needles)
    assert _files(tmp_path) == before


# ------------------------------------------------------------- 1. URDF with two roots


def test_urdf_with_more_than_one_root_link_is_refused_naming_the_roots(tmp_path, capsys):
    u = tmp_path / "two_roots.urdf"
    u.write_text(TWO_ROOTS)
    cfg = _urdf_cfg(tmp_path, u)  # a tip is given: the import alone would run
    _urdf_refused(tmp_path, capsys, cfg, str(u), "2 root links ('base', 'stray')", "one tree")
    # the same file without the stray tree is fine
    assert len(U.parse(ARM, "arm.urdf").links) == 5


# ----------------------------------------------------------- 2. a file that is not a URDF


@pytest.mark.parametrize(
    "text,needle",
    [
        ("<html><head><title>arm</title></head><body><p>a robot</p></body></html>",
         "not a URDF: no <robot> element (the root element is <html>)"),
        ("<!DOCTYPE html>\n<html><body>a robot<br></body></html>\n", "malformed XML"),
        ('<robot><link name="a"/></robot>', "<robot> has no name attribute"),
    ],
)  # fmt: skip
def test_a_file_that_is_not_a_urdf_is_refused(tmp_path, capsys, text, needle):
    u = tmp_path / "chain.urdf"
    u.write_text(text)
    cfg = _urdf_cfg(tmp_path, u)
    _urdf_refused(tmp_path, capsys, cfg, str(u), needle)


# ------------------------------------------------------ 3. a folder where a file is wanted


def test_a_config_path_that_is_a_folder(tmp_path, capsys):
    (tmp_path / "cfgdir").mkdir()
    before = _files(tmp_path)
    for cmd in ("eval", "run", "chain"):
        _refused(capsys, [cmd, tmp_path / "cfgdir"], str(tmp_path / "cfgdir"),
                 "is a folder, not a config file")  # fmt: skip
    assert _files(tmp_path) == before


def test_a_urdf_path_that_is_a_folder(tmp_path, capsys):
    (tmp_path / "robot.urdf").mkdir()
    cfg = _urdf_cfg(tmp_path, tmp_path / "robot.urdf")
    _urdf_refused(tmp_path, capsys, cfg, str(tmp_path / "robot.urdf"),
                  "is a folder, not a URDF file", "chain.urdf")  # fmt: skip


@pytest.fixture
def ik_case(tmp_path):
    """A float64 PUMA 560 config and a valid one-row positions file."""
    raw = yaml.safe_load((ROOT / "configs" / "puma560.yaml").read_text())
    raw["precision"] = "float64"
    raw.pop("output")
    cfg = tmp_path / "puma.yaml"
    cfg.write_text(yaml.safe_dump(raw))
    good = tmp_path / "good.csv"
    good.write_text("x,y,z\n0.3,0.1,0.2\n")
    return cfg, good


def test_an_ik_poses_path_that_is_a_folder(ik_case, tmp_path, capsys):
    cfg, _ = ik_case
    (tmp_path / "poses.csv").mkdir()
    before = _files(tmp_path)
    _refused(capsys, ["ik", cfg, "--poses", tmp_path / "poses.csv", "--out", tmp_path / "o.h5"],
             str(tmp_path / "poses.csv"), "is a folder, not a poses file", "--poses")  # fmt: skip
    assert _files(tmp_path) == before


def test_an_ik_out_that_is_a_folder(ik_case, tmp_path, capsys):
    cfg, good = ik_case
    (tmp_path / "outdir").mkdir()
    before = _files(tmp_path)
    _refused(capsys, ["ik", cfg, "--poses", good, "--out", tmp_path / "outdir"],
             f"output '{tmp_path / 'outdir'}': is a folder")  # fmt: skip
    assert _files(tmp_path) == before


# -------------------------------------------------- 4. IK targets of absurd magnitude


def test_ik_csv_target_of_absurd_magnitude_is_refused_naming_the_row(ik_case, tmp_path, capsys):
    cfg, _ = ik_case
    f = tmp_path / "far.csv"
    f.write_text("x,y,z\n0.3,0.1,0.2\n1e308,0.1,0.2\n0.3,0.1,0.2\n")
    out = tmp_path / "o.h5"
    before = _files(tmp_path)
    _refused(capsys, ["ik", cfg, "--poses", f, "--out", out],
             str(f), "row 2: x = 1e+308 is too large", "1e+09")  # fmt: skip
    f.write_text("x,y,z,ax,ay,az\n0.3,0.1,0.2,0,0,1\n0.3,-2e9,0.2,0,0,1\n")
    _refused(capsys, ["ik", cfg, "--poses", f, "--out", out], "row 2: y = -2e+09 is too large")
    assert _files(tmp_path) == before
    # the bound itself is a number like any other
    f.write_text("x,y,z\n1e9,0,0\n")
    assert target_files.read_targets(f).p[0, 0] == 1e9


def test_ik_h5_target_of_absurd_magnitude_is_refused_naming_the_row(ik_case, tmp_path, capsys):
    cfg, _ = ik_case
    T = np.broadcast_to(np.eye(4), (3, 4, 4)).copy()
    T[:, :3, 3] = 0.2
    T[2, 1, 3] = 1e308  # row 3, the pose's y
    f = tmp_path / "far.h5"
    with h5py.File(f, "w") as h:
        h["poses"] = T
    out = tmp_path / "o.h5"
    before = _files(tmp_path)
    _refused(capsys, ["ik", cfg, "--poses", f, "--out", out],
             str(f), "row 3: T13 = 1e+308 is too large")  # fmt: skip
    assert _files(tmp_path) == before


# -------------------------------------- 5. one design variable bound to two joint origins


def test_one_variable_bound_to_two_joint_origins_drives_both(tmp_path, capsys):
    """Kept: a variable named by two ``set`` keys is one number in both origins (equal
    link lengths, a symmetric design), as a DH table may name a variable in two entries.
    The kernel's FK is yourdfpy's on the URDF with the number written into both."""
    u = tmp_path / "arm.urdf"
    u.write_text(ARM)
    cfg = _urdf_cfg(tmp_path, u, set={"j2.origin.z": "l", "tool.origin.x": "l"})
    s = validate(yaml.safe_load(cfg.read_text()), str(cfg)).study
    mech = build(s)
    imp = s.chain.imported
    rng = np.random.default_rng(4)
    for ell in (0.15, 0.4):
        x = np.array([ell])
        # at q = 0 the tip is at (l, 0, 0.1 + l + 0.3): both origins moved with l
        _, p0 = (np.asarray(a) for a in mech.model.fk(x, np.zeros(3)))
        np.testing.assert_allclose(p0, [ell, 0.0, 0.4 + ell], atol=1e-15)
        text = U.export_text(ARM, set_values(s, {"l": ell}), "arm")
        rob = U.parse(text, "arm")
        assert rob.joints["j2"].xyz == (0.0, 0.0, ell) and rob.joints["tool"].xyz == (ell, 0, 0)
        ref = U.Reference(text)
        for q in rng.uniform(-1.5, 1.5, (4, 3)):
            R, p = (np.asarray(a) for a in mech.model.fk(x, q))
            T = ref.fk(imp, q)
            np.testing.assert_allclose(R, T[:3, :3], atol=1e-12)
            np.testing.assert_allclose(p, T[:3, 3], atol=1e-12)
    capsys.readouterr()
    assert main(["chain", str(cfg), "--design", "l=0.3"]) == 0
    out = capsys.readouterr().out
    assert out.count("variable l = 0.3") == 2 and "(OK)" in out, out


# ------------------------------------------------------------- 6. CLI usage errors


@pytest.mark.parametrize(
    "argv,command,message",
    [
        (["ik", "CFG", "--poses", "f.csv", "--mode", "elbow"], "ik",
         "argument --mode: invalid choice: 'elbow'"),
        (["eval"], "eval", "the following arguments are required: config"),
        (["eval", "CFG", "--bogus"], "eval", "unrecognized arguments: --bogus"),
        (["run", "CFG", "--seed", "x"], "run", "argument --seed: invalid int value: 'x'"),
        (["run", "CFG", "--devices", "0"], "run", "argument --devices: '0': give a positive"),
        (["chain", "CFG", "--design"], "chain", "argument --design: expected at least one"),
        (["nosuch"], None, "argument command: invalid choice: 'nosuch'"),
        ([], None, "the following arguments are required: command"),
    ],
)  # fmt: skip
def test_usage_errors_are_one_line(tmp_path, capsys, argv, command, message):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("study: {name: planar2r}\n")
    before = _files(tmp_path)
    argv = [str(cfg) if a == "CFG" else a for a in argv]
    err = _refused(capsys, argv, message)
    see = f"designopt {command} --help" if command else "designopt --help"
    assert err.rstrip("\n").endswith(f"; see {see}"), err
    assert "usage:" not in err
    assert _files(tmp_path) == before


def test_help_is_argparses_own(capsys):
    assert main(["ik", "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: designopt ik ") and "--poses PATH" in out
    assert out.count("\n") > 10 and "designopt: error" not in out


# ------------------------------------------------------- 7. --design NAME=VALUE ...


@pytest.mark.parametrize("command", ["eval", "ik", "chain"])
def test_design_takes_several_values_after_one_flag_or_the_flag_repeated(command):
    extra = ["--poses", "p.csv"] if command == "ik" else []
    parse = build_parser().parse_args
    forms = [
        ["c.yaml", *extra, "--design", "a2=0.4", "d4=0.45"],
        ["c.yaml", *extra, "--design", "a2=0.4", "--design", "d4=0.45"],
        ["c.yaml", "--design", "a2=0.4", *extra, "--design=d4=0.45"],
        ["--design", "a2=0.4", "d4=0.45", "c.yaml", *extra],  # CONFIG after the values
    ]
    for argv in forms:
        a = parse([command, *argv])
        assert a.config == "c.yaml" and a.design == ["a2=0.4", "d4=0.45"], (argv, a)
        assert parse_design(a.design) == {"a2": 0.4, "d4": 0.45}
    assert parse([command, "c.yaml", *extra]).design == []


def test_design_forms_agree_and_still_go_through_parse_design(tmp_path, capsys):
    cfg = str(ROOT / "configs" / "planar2r.yaml")
    outs = []
    for argv in (["eval", cfg, "--design", "l1=1", "l2=0.5", "--json"],
                 ["eval", cfg, "--design", "l1=1", "--design", "l2=0.5", "--json"],
                 ["eval", "--design", "l1=1", "l2=0.5", cfg, "--json"]):  # fmt: skip
        assert main(argv) == 0
        outs.append(capsys.readouterr().out)
    assert outs[0] == outs[1] == outs[2] and '"gci"' in outs[0]
    before = _files(tmp_path)
    _refused(capsys, ["eval", cfg, "--design", "l1=1", "l1=2"], "--design l1: given twice")
    _refused(capsys, ["eval", cfg, "--design", "l1=1", "l2=inf"], "--design l2")
    _refused(capsys, ["eval", cfg, "--design", "l1=1e308"], "--design l1", "too large")
    assert _files(tmp_path) == before
