"""The UR5 shipped in configs/robots/ur5/ and the two-UR5 scene of
configs/two_ur5_front.yaml (docs/task.md, "Two UR5s through two ports").

- the shipped files are the UR5 of the pip package example-robot-data (6.0.0) with only
  what configs/robots/ur5/README.md says changed: the same collision STLs byte for byte,
  the same joints, the mesh names pointing beside the URDF; ur5_instrument.urdf is
  ur5_robot.urdf plus the instrument;
- every mesh resolves from the URDF's own folder (no ROS_PACKAGE_PATH, no package);
- the config validates, ``eval`` of one design at 32 targets gives finite ``reach_all``
  and ``arms_ok`` (JSON), and ``view`` draws it."""

from __future__ import annotations

import hashlib
import json
import math
import sysconfig
from pathlib import Path

import pytest
from lxml import etree

import designopt
from designopt.cli.commands import main
from designopt.kinematics import meshes, urdf_collision

ROOT = Path(__file__).resolve().parents[1]
CFG = ROOT / "configs/two_ur5_front.yaml"
UR5 = ROOT / "configs/robots/ur5"
ROBOT, INSTRUMENT = UR5 / "ur5_robot.urdf", UR5 / "ur5_instrument.urdf"
ERD = (Path(sysconfig.get_paths()["purelib"])
       / "cmeel.prefix/share/example-robot-data/robots/ur_description")  # fmt: skip
STLS = ("base", "shoulder", "upperarm", "forearm", "wrist1", "wrist2", "wrist3")


def _xml(path: Path):
    return etree.parse(str(path)).getroot()


def _joints(root) -> dict[str, bytes]:
    return {j.get("name"): etree.tostring(j, with_tail=False) for j in root.findall("joint")}


def _mesh_names(root) -> list[str]:
    return [m.get("filename") for m in root.iter("mesh")]


@pytest.mark.skipif(not (ERD / "urdf/ur5_robot.urdf").is_file(),
                    reason="example-robot-data is not installed")  # fmt: skip
def test_shipped_ur5_is_example_robot_datas_with_local_meshes():
    """Same STLs byte for byte, same joints (origins, axes, limits), each link's visual
    and collision the link's own collision STL, nothing else on the links changed."""
    for name in STLS:
        ours = (UR5 / "meshes" / f"{name}.stl").read_bytes()
        theirs = (ERD / "meshes/ur5/collision" / f"{name}.stl").read_bytes()
        assert hashlib.sha256(ours).digest() == hashlib.sha256(theirs).digest(), name
    up, ours = _xml(ERD / "urdf/ur5_robot.urdf"), _xml(ROBOT)
    assert _joints(ours) == _joints(up)
    for a, b in zip(ours.findall("link"), up.findall("link"), strict=True):
        assert a.get("name") == b.get("name")
        for el in a.iter("mesh"):
            stem = Path(el.get("filename")).stem
            assert el.get("filename") == f"meshes/{stem}.stl" and stem in STLS
        for el in b.iter("mesh"):
            el.set("filename", f"meshes/{Path(el.get('filename')).stem}.stl")
        name = a.get("name")
        assert etree.tostring(a, with_tail=False) == etree.tostring(b, with_tail=False), name
    inst = _xml(INSTRUMENT)
    added = {"instrument_joint", "instrument_tip_joint"}
    assert _joints(inst) == _joints(ours) | {k: v for k, v in _joints(inst).items() if k in added}
    assert set(_joints(inst)) - set(_joints(ours)) == added


def test_every_mesh_resolves_beside_the_urdf(monkeypatch):
    """Relative mesh names: found from the URDF's folder by the drawing and by the
    collision import alike, with no ROS package path; the meshes stay small."""
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    for urdf in (ROBOT, INSTRUMENT):
        names = _mesh_names(_xml(urdf))
        assert len(names) == 14  # a visual and a collision mesh on each of 7 links
        for n in names:
            want = (UR5 / n).resolve()
            assert meshes.resolve(n, urdf).resolve() == want
            assert urdf_collision.resolve_mesh(n, urdf).resolve() == want
    assert sum(p.stat().st_size for p in (UR5 / "meshes").iterdir()) < 300_000


def test_two_ur5_config_validates_and_eval_is_finite(capsys):
    """The shipped scene loads (two arms, each through its own port) and one design
    scored at 32 targets gives finite shares; the UR5's own lengths reach the tissue box
    from b = 0.6."""
    cfg = designopt.load_config(str(CFG))
    s = cfg.study
    assert set(s.variables) == {"a2", "a3", "b"} and len(s.arms) == 2
    assert [a.port for a in s.arms] == [(-0.06, 0.0, 0.2), (0.06, 0.0, 0.2)]
    capsys.readouterr()
    argv = ["eval", str(CFG), "--design", "a2=0.425", "a3=0.39225", "b=0.6",
            "--set", "study.indices.n_samples=32", "--json"]  # fmt: skip
    assert main(argv) == 0
    res = json.loads(capsys.readouterr().out)
    for k in ("reach_all", "arms_ok", "reach_0", "reach_1"):
        assert res[k] is not None and math.isfinite(res[k]) and 0.0 <= res[k] <= 1.0, k
        assert res[f"{k}_se"] is not None and math.isfinite(res[f"{k}_se"]), k
    assert res["reach_all"] >= 0.9 and res["arms_ok"] >= 0.5, res


def test_two_ur5_view_draws(tmp_path):
    out = tmp_path / "v.png"
    assert main(["view", str(CFG), "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000
