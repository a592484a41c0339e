"""URDF chains (designopt.kinematics.urdf, `chain: {urdf: ...}`): FK and Jacobian against
yourdfpy's own FK and its finite differences, the DH equivalent, export round trips, the
CLI, and bad input (one line, exit 2, nothing written)."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from designopt.app.config import validate
from designopt.cli.commands import main
from designopt.core.errors import ConfigError
from designopt.kinematics import urdf as U
from designopt.studies.serial.mechanism import build

ROOT = Path(__file__).resolve().parents[1]
PUMA_URDF = ROOT / "configs" / "robots" / "puma560.urdf"
ARM_URDF = ROOT / "configs" / "robots" / "surgical_arm6.urdf"

_LIM = '<limit lower="-1.2" upper="1.1" effort="1" velocity="1"/>'

# Every feature of issue 24 in one tree: rpy origins, negative and oblique axes, a
# prismatic joint along an oblique axis, continuous, mimic (with offset), fixed joints
# (one carrying variables), a branch, and the origin `length`.
FEATURES = f"""<?xml version="1.0"?>
<robot name="features">
  <link name="world"/><link name="b"/><link name="l1"/><link name="l2"/><link name="l3"/>
  <link name="l4"/><link name="l5"/><link name="l6"/><link name="tip"/><link name="side"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="b"/>
    <origin xyz="0.01 -0.02 0.3" rpy="0.05 0.1 -0.2"/></joint>
  <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.3 -0.2 0.5"/><axis xyz="0 0 -1"/>{_LIM}</joint>
  <joint name="f1" type="fixed"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.05 0 0.4" rpy="1.5707963267948966 0 0"/></joint>
  <joint name="j2" type="continuous"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0.1 0" rpy="0 0.4 0"/><axis xyz="0 0.6 0.8"/></joint>
  <joint name="j3" type="prismatic"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.2 0 0" rpy="0 0 0.7"/><axis xyz="0.48 0.6 0.64"/>
    <limit lower="0" upper="0.3" effort="1" velocity="1"/></joint>
  <joint name="j4" type="revolute"><parent link="l4"/><child link="l5"/>
    <origin xyz="0 0 0.1"/><axis xyz="-1 0 0"/>
    <mimic joint="j1" multiplier="-0.5" offset="0.1"/>{_LIM}</joint>
  <joint name="j5" type="revolute"><parent link="l5"/><child link="l6"/>
    <origin xyz="0.02 0.15 0" rpy="0 -1.5707963267948966 0"/><axis xyz="0 1 0"/>{_LIM}</joint>
  <joint name="ft" type="fixed"><parent link="l6"/><child link="tip"/>
    <origin xyz="0.03 0.02 0.1" rpy="0.1 0.2 0.3"/></joint>
  <joint name="js" type="revolute"><parent link="l2"/><child link="side"/>
    <axis xyz="0 1 0"/>{_LIM}</joint>
</robot>
"""

BIND_NAMES = ("h", "w", "lt", "tw")
BIND = {("f1", "z"): "h", ("j5", "x"): "w", ("ft", "length"): "lt", ("j3", "yaw"): "tw"}


@pytest.fixture(scope="module")
def feat():
    rob = U.parse(FEATURES, "features.urdf")
    imp = U.import_path(rob, "world", "tip")
    binds = {k: (0.0, ((BIND_NAMES.index(v), 1.0),)) for k, v in BIND.items()}
    return imp, U.lower(imp, binds, BIND_NAMES)


def _ref_T(imp, x, q):
    """yourdfpy's base_T_tip with the design x written into the URDF."""
    text = U.export_text(FEATURES, {k: x[BIND_NAMES.index(v)] for k, v in BIND.items()}, "f")
    return U.Reference(text).fk(imp, q)


def test_import_structure(feat):
    imp, model = feat
    assert imp.chain == ("j1", "j2", "j3", "j4", "j5") and imp.active == ("j1", "j2", "j3", "j5")
    assert imp.types == ("R", "R", "P", "R")
    assert imp.lower[1] == -np.pi and imp.upper[1] == np.pi  # continuous: ±180°
    # the mimic row: q_j4 = −0.5 q_j1 + 0.1, about −x (a negative axis: sign in the row)
    row = np.asarray(model.coupling[3])
    assert abs(abs(row[0]) - 0.5) < 1e-15 and np.count_nonzero(row) == 1
    assert not model.shares_rotations  # j3.origin.yaw is a design variable


def test_fk_and_jacobian_against_yourdfpy_and_its_finite_differences(feat):
    imp, model = feat
    rng = np.random.default_rng(3)
    X = np.column_stack([rng.uniform(0.1, 0.5, 3), rng.uniform(-0.1, 0.1, 3),
                         rng.uniform(0.05, 0.2, 3), rng.uniform(-0.5, 0.5, 3)])  # fmt: skip
    lo, hi = np.asarray(imp.lower), np.asarray(imp.upper)
    Q = lo + (hi - lo) * rng.random((4, len(lo)))
    R, p, J = (np.asarray(a) for a in model.fk_jacobian(X, Q))  # (M, C, ...)
    h = 1e-6
    for m in range(len(X)):
        for c in range(len(Q)):
            T = _ref_T(imp, X[m], Q[c])
            np.testing.assert_allclose(R[m, c], T[:3, :3], atol=1e-12)
            np.testing.assert_allclose(p[m, c], T[:3, 3], atol=1e-12)
            Jfd = np.zeros((6, len(lo)))
            for k in range(len(lo)):
                e = np.zeros(len(lo))
                e[k] = h
                Tp, Tm = _ref_T(imp, X[m], Q[c] + e), _ref_T(imp, X[m], Q[c] - e)
                Jfd[:3, k] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
                W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T[:3, :3].T  # skew(ω)
                Jfd[3:, k] = (W[2, 1], W[0, 2], W[1, 0])
            np.testing.assert_allclose(J[m, c], Jfd, atol=2e-8)
            if m > 0:
                break  # one configuration per further design keeps the test fast


def test_designs_are_array_inputs_one_trace_and_a_gradient(feat):
    imp, model = feat
    traces = []

    @jax.jit
    def gci(X, q):
        traces.append(1)
        return jnp.mean(model.inv_cond(X, q, rows=(0, 1, 2), cols=(0, 1, 3)), -1)

    q = jnp.asarray(np.random.default_rng(0).uniform(-0.5, 0.5, (64, 4)))
    X1 = jnp.asarray([[0.3, 0.05, 0.1, 0.2]])
    X2 = jnp.asarray([[0.3, 0.05, 0.1, 0.2], [0.2, -0.05, 0.15, -0.1]])
    g1 = gci(X1, q)
    g2 = gci(X2, q)
    gci(X2 + 0.01, q)
    assert len(traces) == 2  # a new design is a new input, not a new trace
    np.testing.assert_allclose(g1[0], g2[0], rtol=1e-13)
    grad = jax.grad(lambda X: gci(X, q).sum())(X1)
    eps = 1e-6
    for k in range(4):
        d = jnp.zeros_like(X1).at[0, k].set(eps)
        fd = (gci(X1 + d, q).sum() - gci(X1 - d, q).sum()) / (2 * eps)
        assert abs(float(grad[0, k]) - float(fd)) < 1e-6


OFF_PATH_MASTER = f"""<robot name="m"><link name="a"/><link name="b"/><link name="c"/><link name="g"/>
  <joint name="arm" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>{_LIM}</joint>
  <joint name="grip" type="prismatic"><parent link="a"/><child link="g"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
  <joint name="finger" type="prismatic"><parent link="b"/><child link="c"/>
    <origin xyz="0.1 0 0" rpy="0 0 0.3"/><axis xyz="0 -1 0"/>
    <mimic joint="grip" multiplier="2" offset="0.01"/>
    <limit lower="0" upper="0.1" effort="1" velocity="1"/></joint>
</robot>"""


def test_a_mimic_whose_master_is_off_the_path_makes_the_master_active():
    rob = U.parse(OFF_PATH_MASTER, "m.urdf")
    imp = U.import_path(rob, None, "c")
    assert imp.chain == ("arm", "finger") and imp.active == ("arm", "grip")
    assert imp.types == ("R", "P") and imp.upper == (1.1, 0.04)
    model = U.lower(imp, {}, ())
    ref = U.Reference(OFF_PATH_MASTER)
    for q in np.random.default_rng(2).uniform([-1, 0], [1, 0.04], (4, 2)):
        R, p = (np.asarray(a) for a in model.fk(np.zeros(0), q))
        T = ref.fk(imp, q)
        np.testing.assert_allclose(R, T[:3, :3], atol=1e-12)
        np.testing.assert_allclose(p, T[:3, 3], atol=1e-12)


def test_branched_tree_needs_the_tip_and_the_root_is_the_default_base():
    rob = U.parse(FEATURES, "features.urdf")
    with pytest.raises(ConfigError, match="branches"):
        U.import_path(rob, None, None)
    imp = U.import_path(rob, None, "side")
    assert imp.base == "world" and imp.chain == ("j1", "js")


def _config(name: str, tmp_path, n_samples: int = 2048) -> dict:
    """A shipped config with small sampling, float64, its URDF path made absolute."""
    raw = yaml.safe_load((ROOT / "configs" / name).read_text())
    st = raw["study"]
    if "urdf" in st["chain"]:
        st["chain"]["urdf"] = str(ROOT / "configs" / st["chain"]["urdf"])
    st["indices"]["n_samples"] = n_samples
    st["objective"] = {"gci": -1.0}
    return raw | {"precision": "float64", "output": str(tmp_path / f"{name}.h5")}


def test_puma560_urdf_gives_the_dh_chains_gci(tmp_path):
    """configs/puma560.yaml's DH chain and configs/urdf_puma560.yaml (the PUMA 560 URDF,
    frames matched): the same FK and Jacobian, so the same GCI within its standard error
    (here: to rounding)."""
    from designopt.app import pipeline

    cu = validate(_config("urdf_puma560.yaml", tmp_path), "u")
    cd = validate(_config("puma560.yaml", tmp_path), "d")
    mu, md = build(cu.study), build(cd.study)
    assert mu.names == md.names == ("a2", "d4", "a3", "d3")
    np.testing.assert_array_equal(mu.lower, md.lower)
    np.testing.assert_allclose(mu.upper, md.upper, rtol=1e-15)
    X = np.array([[0.4318, 0.4318, 0.0203, 0.15005], [0.35, 0.55, 0.0203, 0.15005]])
    q = np.random.default_rng(1).uniform(-3, 3, (50, 6))
    Ru, pu, Ju = mu.model.fk_jacobian(X, q)
    Rd, pd, Jd = md.model.fk_jacobian(X, q)
    np.testing.assert_allclose(pu, pd, atol=1e-12)
    np.testing.assert_allclose(Ru, Rd, atol=1e-12)
    np.testing.assert_allclose(Ju, Jd, atol=1e-12)
    d = {"a2": 0.45, "d4": 0.4}
    eu = pipeline.evaluate(cu, d, where="u")
    ed = pipeline.evaluate(cd, d, where="d")
    assert abs(eu["gci"] - ed["gci"]) <= ed["gci_se"]
    assert abs(eu["gci"] - ed["gci"]) < 1e-12


def test_export_round_trip_changes_only_the_set_fields(tmp_path):
    vals = {("f1", "z"): 0.123456789012345, ("ft", "length"): 0.0777, ("j3", "yaw"): -0.3,
            ("j5", "x"): 0.011}  # fmt: skip
    text = U.export_text(FEATURES, vals, "f")
    a, b = FEATURES.splitlines(), text.splitlines()
    changed = [i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y]
    assert len(a) == len(b) and len(changed) == 4
    assert all("<origin" in b[i] for i in changed)
    rob = U.parse(text, "out")
    assert rob.joints["f1"].xyz == (0.05, 0.0, 0.123456789012345)
    assert np.isclose(np.linalg.norm(rob.joints["ft"].xyz), 0.0777, rtol=1e-15)
    # a joint without <origin> gets one
    t2 = U.export_text(FEATURES, {("js", "y"): 0.25}, "f")
    assert U.parse(t2, "o").joints["js"].xyz == (0.0, 0.25, 0.0)


# ---------------------------------------------------------------------- the CLI


def _arm_cfg(tmp_path, urdf=None, **chain):
    c = {"urdf": str(urdf or ARM_URDF), "base": "rcm_link", "tip": "jaw_tip",
         "set": {"wrist_pitch.origin.length": "l_wrist", "jaw.origin.length": "l_jaw"}} | chain  # fmt: skip
    cfg = {"study": {"name": "serial", "chain": c,
                     "variables": {"l_wrist": [0.004, 0.03], "l_jaw": [0.005, 0.03]},
                     "indices": {"jacobian": "position", "n_samples": 512},
                     "objective": {"gci": -1.0}},
           "optimizer": {"name": "ptpso", "n_particles": 6, "n_iters": 3, "n_runs": 1},
           "scan": {"vary": {"l_wrist": [0.01, 0.02], "l_jaw": [0.01, 0.02]}},
           "precision": "float64", "seed": 0, "output": str(tmp_path / "out" / "a.h5")}  # fmt: skip
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def test_eval_scan_run_chain_export(tmp_path, capsys):
    cfg = _arm_cfg(tmp_path)
    assert main(["chain", str(cfg), "--q", "10,20,0.1,30,10,-10"]) == 0
    out = capsys.readouterr().out
    assert "variable l_wrist" in out and "(OK)" in out and "outer_pitch" in out
    assert main(["eval", str(cfg), "--design", "l_wrist=0.01", "--json"]) == 0
    res = yaml.safe_load(capsys.readouterr().out)
    assert 0 < res["gci"] < 1 and res["gci_se"] > 0
    assert main(["scan", str(cfg), "--quiet", "--no-figures"]) == 0
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 0
    capsys.readouterr()
    out_urdf = tmp_path / "best.urdf"
    assert main(["export", str(tmp_path / "out" / "a.h5"), "--urdf", str(out_urdf)]) == 0
    import h5py

    with h5py.File(tmp_path / "out" / "a.h5") as h:
        x = h["final/x"][()]
    s = validate(yaml.safe_load(cfg.read_text()), "c").study
    mech = build(s)
    imp = s.chain.imported
    ref = U.Reference(out_urdf.read_text())
    q = np.asarray(imp.lower) + (np.asarray(imp.upper) - np.asarray(imp.lower)) * \
        np.random.default_rng(5).random((6, 6))  # fmt: skip
    R, p = (np.asarray(a) for a in mech.model.fk(x, q))
    for i in range(len(q)):
        T = ref.fk(imp, q[i])
        np.testing.assert_allclose(R[i], T[:3, :3], atol=1e-12)
        np.testing.assert_allclose(p[i], T[:3, 3], atol=1e-12)
    # a scan archive: the lowest f among the scanned designs
    with h5py.File(tmp_path / "out" / "a_scan.h5") as h:
        xs, fs = h["scan/x"][()], h["scan/f"][()]
    best = xs[int(np.argmin(fs))]
    assert main(["export", str(tmp_path / "out" / "a_scan.h5"), "--urdf",
                 str(tmp_path / "scan.urdf")]) == 0  # fmt: skip
    rob = U.parse((tmp_path / "scan.urdf").read_text(), "scan.urdf")
    assert np.isclose(np.linalg.norm(rob.joints["wrist_pitch"].xyz), best[0], rtol=1e-15)
    assert np.isclose(np.linalg.norm(rob.joints["jaw"].xyz), best[1], rtol=1e-15)
    # exporting again refuses to overwrite
    assert main(["export", str(tmp_path / "out" / "a.h5"), "--urdf", str(out_urdf)]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_relative_urdf_path_is_read_from_the_config_folder(tmp_path):
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "arm.urdf").write_text(ARM_URDF.read_text())
    raw = yaml.safe_load(_arm_cfg(tmp_path, urdf="robots/arm.urdf").read_text())
    from designopt.studies.serial.settings import SerialSettings

    s = SerialSettings.model_validate(raw["study"], context={"config_dir": str(tmp_path)})
    assert s.chain.urdf_path == str((tmp_path / "robots" / "arm.urdf").resolve())
    # the archived settings carry the text: validating them again needs no file
    again = SerialSettings.model_validate(s.model_dump())
    assert again.chain.urdf_text == s.chain.urdf_text


def test_cli_reads_a_relative_urdf_path_from_the_config_folder(tmp_path, capsys, monkeypatch):
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "arm.urdf").write_text(ARM_URDF.read_text())
    cfg = _arm_cfg(tmp_path, urdf="robots/arm.urdf")
    monkeypatch.chdir(ROOT)
    assert main(["chain", str(cfg)]) == 0
    assert str((tmp_path / "robots" / "arm.urdf").resolve()) in capsys.readouterr().out


def _bad_urdf(tmp_path, text):
    p = tmp_path / "bad.urdf"
    p.write_text(text)
    return p


LOOP = FEATURES.replace('<joint name="js" type="revolute"><parent link="l2"/><child link="side"/>',
                        '<joint name="js" type="revolute"><parent link="l2"/><child link="l1"/>')  # fmt: skip
STATIC = """<robot name="s"><link name="a"/><link name="b"/>
<joint name="f" type="fixed"><parent link="a"/><child link="b"/></joint></robot>"""
NAN = FEATURES.replace('xyz="0.05 0 0.4"', 'xyz="0.05 nan 0.4"')


@pytest.mark.parametrize(
    "urdf_text,chain,study,needle",
    [
        (None, {"urdf": "/nonexistent/robot.urdf"}, {}, "URDF file not found"),
        ("<robot name='x'><link name='a'></robot>", {}, {}, "malformed XML"),
        (FEATURES, {"base": "world", "tip": "nolink"}, {}, "chain.tip: no link 'nolink'"),
        (FEATURES, {"base": "nolink", "tip": "tip"}, {}, "chain.base: no link 'nolink'"),
        (FEATURES, {"base": "side", "tip": "tip"}, {}, "no path from base 'side'"),
        (FEATURES, {"tip": "tip", "set": {"nojoint.origin.x": "l_wrist", "j5.origin.z": "l_jaw"}},
         {}, "key 'study.chain.set.nojoint.origin.x': no joint 'nojoint'"),
        (FEATURES, {"tip": "tip", "set": {"j5.origin.w": "l_wrist", "j1.origin.z": "l_jaw"}},
         {}, "unknown field 'w'"),
        (FEATURES, {"tip": "tip", "set": {"j5.origin.x": "l_wrist", "j1.origin.z": "nosuch"}},
         {}, "'nosuch' is neither a design variable"),
        (FEATURES, {"tip": "tip", "set": {"j5.origin.x": "l_wrist"}}, {},
         "['l_jaw'] appear in no chain.set entry"),
        (LOOP, {"tip": "tip"}, {}, "closed loop"),
        (STATIC, {"base": "a", "tip": "b", "set": {"f.origin.x": "l_wrist", "f.origin.y": "l_jaw"}},
         {}, "no movable joint"),
        (NAN, {"tip": "tip"}, {}, "nan is not a finite number"),
        (FEATURES.replace('name="j2" type="continuous"', 'name="j2" type="floating"'),
         {"tip": "tip"}, {}, "type 'floating' is not supported"),
        (FEATURES, {"tip": "tip", "set": {"ft.origin.length": "l_wrist", "ft.origin.x": "l_jaw"}},
         {}, "cannot be set together with x, y or z"),
        (FEATURES, {"tip": "tip", "set": {"j5.origin.x": "l_wrist", "j1.origin.z": "l_jaw"},
                    "limits": {"j1": [10, float("nan")]}}, {}, "nan"),
    ],
)  # fmt: skip
def test_bad_input_one_line_exit_2_nothing_written(
    tmp_path, capsys, urdf_text, chain, study, needle
):
    if urdf_text is not None:
        chain = {"urdf": str(_bad_urdf(tmp_path, urdf_text)), "base": None, "tip": None} | chain
        if "set" not in chain:
            chain["set"] = {"j5.origin.x": "l_wrist", "j1.origin.z": "l_jaw"}
    cfg = _arm_cfg(tmp_path, **chain)
    before = sorted(tmp_path.rglob("*"))
    for cmd in (["eval", str(cfg)], ["run", str(cfg), "--quiet"], ["chain", str(cfg)]):
        assert main(cmd) == 2
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1, err
    assert sorted(tmp_path.rglob("*")) == before


@pytest.mark.parametrize(
    "extra,needle",
    [(["--q", "1,2"], "--q 1,2: expected 6 finite numbers"),
     (["--q", "a,b"], "--q a,b: expected 6 numbers"),
     (["--design", "nosuch=1"], "--design nosuch: not a design variable")],
)  # fmt: skip
def test_chain_bad_arguments(tmp_path, capsys, extra, needle):
    cfg = _arm_cfg(tmp_path)
    assert main(["chain", str(cfg), *extra]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1


def test_export_refuses_a_dh_archive_and_a_missing_archive(tmp_path, capsys):
    assert main(["export", str(tmp_path / "none.h5"), "--urdf", str(tmp_path / "o.urdf")]) == 2
    assert "archive not found" in capsys.readouterr().err
    assert not (tmp_path / "o.urdf").exists()


# --------------------------------------------------- Robotics Toolbox (bench extra)


def _rtb_robot_and_text(rtb, cls: str, monkeypatch):
    """An rtb-data URDF model and the (xacro-expanded) URDF text it was built from."""
    import importlib

    try:
        mod = importlib.import_module("roboticstoolbox.models.URDF.URDFRobot")
    except ImportError:
        mod = None
    seen: list[str] = []
    if mod is not None and hasattr(mod, "_parse_urdf"):  # Robotics Toolbox ≥ 1.5
        orig = mod._parse_urdf

        def spy(text, *a, **k):
            seen.append(text)
            return orig(text, *a, **k)

        monkeypatch.setattr(mod, "_parse_urdf", spy)
    robot = getattr(rtb.models.URDF, cls)()
    text = getattr(robot, "urdf_string", None) or (seen[-1] if seen else None)
    if not isinstance(text, str):
        pytest.skip("this Robotics Toolbox gives no access to the URDF text it read")
    return robot, text


@pytest.mark.parametrize("cls", ["LBR", "Puma560"])
def test_against_robotics_toolbox_jacob0(cls, monkeypatch):
    """The KUKA iiwa and PUMA 560 URDFs of rtb-data: our geometric Jacobian against the
    Robotics Toolbox's jacob0 on the same (xacro-expanded) URDF."""
    rtb = pytest.importorskip("roboticstoolbox", reason="the bench extra is not installed")
    robot, text = _rtb_robot_and_text(rtb, cls, monkeypatch)
    rob = U.parse(text, cls)
    leaves = [lk for lk in rob.links if lk not in {j.parent for j in rob.joints.values()}]
    imp = U.import_path(rob, None, leaves[0] if len(leaves) == 1 else robot.ee_links[0].name)
    assert robot.n == len(imp.active)
    model = U.lower(imp, {}, ())
    lo, hi = np.asarray(imp.lower), np.asarray(imp.upper)
    q = lo + (hi - lo) * np.random.default_rng(0).random((5, len(lo)))
    J = np.asarray(model.jacobian(np.zeros(0), q))
    for i in range(len(q)):
        Jr = robot.jacob0(q[i], end=imp.tip, start=imp.base)
        np.testing.assert_allclose(J[i], Jr, atol=1e-9)
