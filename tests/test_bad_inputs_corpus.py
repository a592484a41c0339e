"""Issue 53 (part 8): bad and odd inputs as a new user writes them (body walls, ports, arms,
obstacles inside the patient, mesh files, ``--set``, ``show --csv``, the sphere study, a
design outside its box). Each is refused by the CLI in-process with exit 2 and ONE line
``designopt: error: ...`` naming the deepest key the user got wrong (or the file, flag or
value), no traceback, nothing written. Validation only: a config case goes through
``run --dry-run`` (a regression that accepts it costs a dry run, not a search).

Also the rule behind the key: of pydantic's errors, each union keeps the member the input
was meant for, and then the first error in the fields' order wins (a validator's error
caused by an earlier field's never hides its cause), checked on small models; and every
n/a index carries a ``warning:`` line (``results.base.na_warnings``; the sphere study's
``gci_reached``)."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import h5py
import numpy as np
import pytest
import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationError,
    ValidationInfo,
    field_validator,
)
from test_bad_inputs import _refused  # one line, exit 2, no traceback

from designopt.app.config import error_text, validate
from designopt.cli.commands import main
from designopt.core.errors import ConfigError
from designopt.results.base import na_indices, na_warnings

ROOT = Path(__file__).resolve().parents[1]

OPEN_STL = """solid t
facet normal 0 0 1
outer loop
vertex 0 0 0
vertex 1 0 0
vertex 0 1 0
endloop
endfacet
endsolid t
"""


def _absolute(tree: Any, folder: Path) -> Any:
    """The config with every string naming a file beside it made absolute."""
    if isinstance(tree, dict):
        return {k: _absolute(v, folder) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_absolute(v, folder) for v in tree]
    if isinstance(tree, str) and "/" in tree and (folder / tree).is_file():
        return str(folder / tree)
    return tree


def _base(name: str) -> dict:
    raw = _absolute(yaml.safe_load((ROOT / "configs" / name).read_text()), ROOT / "configs")
    raw.pop("output", None)
    return raw


PORTS = _base("port_placement.yaml")  # two UR5 arms, ports on an ellipsoid wall, meshes
SPHERE = _base("sphere_rcm.yaml")
URDF_PORT = _base("urdf_puma560_port.yaml")  # a URDF arm, its origins set by variables


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Mesh files a user may point at by mistake, and archives ``show`` may be given."""
    d = tmp_path_factory.mktemp("inputs")
    (d / "open.stl").write_text(OPEN_STL)  # one triangle: not watertight
    (d / "notes.stl").write_text("hello, not a mesh\n")
    (d / "empty.stl").write_text("")
    (d / "meshes.stl").mkdir()
    (d / "notes.h5").write_text("not HDF5\n")
    with h5py.File(d / "plain.h5", "w") as h:
        h["x"] = np.arange(3)
    return {p.name: p for p in d.iterdir()}


def _written(tmp_path: Path) -> list[Path]:
    return sorted(tmp_path.rglob("*"))


def _study(r: dict) -> dict:
    return r["study"]


def _task(r: dict) -> dict:
    return r["study"]["task"]


def _arm(k: int):
    return lambda r: r["study"]["arms"][k]


def _obstacle(k: int):
    return lambda r: r["study"]["collision"]["obstacles"][k]


def _wall(r: dict) -> dict:
    return r["study"]["task"]["body_wall"]


def _file(name: str):
    """A placeholder for a file of the ``files`` fixture, filled in by the test."""
    return f"<{name}>"


HALFSPACE = {"shape": "halfspace", "point": [0, 0, 0.2], "normal": [0, 0, 1]}

# (id, base, edit(raw), the key the message names, other words it holds)
CONFIG_CASES = [
    # -- the body wall (task.body_wall)
    ("wall-shape-unknown", PORTS, lambda r: _wall(r).update(shape="sphere"),
     "study.task.body_wall.shape", ["'sphere'", "'halfspace', 'ellipsoid', 'mesh'"]),
    ("wall-shape-missing", PORTS, lambda r: _wall(r).pop("shape"),
     "study.task.body_wall.shape", ["missing", "'ellipsoid'"]),
    ("wall-as-a-word", PORTS, lambda r: _task(r).update(body_wall="ellipsoid"),
     "study.task.body_wall", ["mapping", "shape: one of"]),
    ("wall-radii-two", PORTS, lambda r: _wall(r).update(radii=[0.2, 0.25]),
     "study.task.body_wall.radii", ["at least 3"]),
    ("wall-radius-negative", PORTS, lambda r: _wall(r).update(radii=[0.2, -0.25, 0.1]),
     "study.task.body_wall.radii.1", ["-0.25"]),
    ("wall-center-text", PORTS, lambda r: _wall(r).update(center=[0, "x", 0]),
     "study.task.body_wall.center.1", ["must be a number", "'x'"]),
    ("wall-unknown-key", PORTS, lambda r: _wall(r).update(radius=0.2),
     "study.task.body_wall.radius", ["unknown key"]),
    ("wall-zero-normal", PORTS,
     lambda r: _task(r).update(body_wall=HALFSPACE | {"normal": [0, 0, 0]}),
     "study.task.body_wall.normal", ["non-zero"]),
    ("wall-no-point", PORTS,
     lambda r: _task(r).update(body_wall={"shape": "halfspace", "normal": [0, 0, 1]}),
     "study.task.body_wall.point", ["missing"]),
    ("wall-inside", PORTS, lambda r: _task(r).update(body_wall=HALFSPACE | {"inside": True}),
     "study.task.body_wall.inside", ["not an obstacle"]),
    ("wall-mesh-file-missing", PORTS,
     lambda r: _task(r).update(body_wall={"shape": "mesh", "file": _file("nosuch.stl")}),
     "study.task.body_wall.file", ["nosuch.stl", "no such mesh file"]),
    ("wall-mesh-open", PORTS,
     lambda r: _task(r).update(body_wall={"shape": "mesh", "file": _file("open.stl")}),
     "study.task.body_wall.file", ["open.stl", "not watertight"]),
    # -- ports
    ("port-two-numbers", PORTS, lambda r: _arm(0)(r).update(port=["-px", "py0"]),
     "study.arms.0.port", ["at least 3"]),
    ("port-unknown-name", PORTS, lambda r: _arm(0)(r).update(port=["-qx", "py0", 0.3]),
     "study.arms.0.port.0", ["'qx'", "neither a design variable"]),
    ("port-a-word", PORTS, lambda r: _arm(0)(r).update(port="abc"),
     "study.arms.0.port", ["must be a list"]),
    ("port-twice", PORTS, lambda r: _task(r).update(port=[0, 0, 0.3]),
     "study.arms", ["remove task.port"]),
    ("task-port-four", PORTS,
     lambda r: [a.pop("port") for a in r["study"]["arms"]] and _task(r).update(
         port=[0, 0, 0.3, 1]), "study.task.port", ["at most 3"]),
    # -- arms
    ("arms-one", PORTS, lambda r: _study(r).update(arms=_study(r)["arms"][:1]),
     "study.arms", ["at least 2"]),
    ("arms-a-mapping", PORTS, lambda r: _study(r).update(arms={"base": {"xyz": [0, 0, 0]}}),
     "study.arms", ["must be a list"]),
    ("arm-a-list", PORTS, lambda r: _study(r)["arms"].__setitem__(0, [0, 0, 0]),
     "study.arms.0", ["mapping"]),
    ("arm-base-a-list", PORTS, lambda r: _arm(0)(r).update(base=[0, 0, 0]),
     "study.arms.0.base", ["mapping"]),
    ("arm-base-unknown-key", PORTS, lambda r: _arm(0)(r)["base"].update(xzy=[0, 0, 0]),
     "study.arms.0.base.xzy", ["unknown key"]),
    ("arm-unknown-key", PORTS, lambda r: _arm(1)(r).update(prt=[0, 0, 0]),
     "study.arms.1.prt", ["unknown key"]),
    ("arm-insertion-reversed", PORTS, lambda r: _arm(0)(r).update(insertion=[0.3, 0.1]),
     "study.arms.0.insertion", ["0 ≤ d0 < d1"]),
    ("arm-length-as-angle", PORTS, lambda r: _arm(0)(r)["base"].update(rpy=[0, 0, "b"]),
     "study.arms.0.base.rpy.2", ["'b'", "angle and as a length"]),
    # a bound the arms' names depend on: blamed on the bound, not on the arms or the chain
    ("arm-variable-bound-text", PORTS, lambda r: _study(r)["variables"].update(py1=[0, "x"]),
     "study.variables.py1.1", ["must be a number", "'x'"]),
    ("chain-set-a-list", URDF_PORT,
     lambda r: _study(r)["chain"]["set"].update({"joint3.origin.x": [0.3]}),
     "study.chain.set.joint3.origin.x", ["must be a number or text"]),
    ("arm-variable-bounds-a-word", PORTS, lambda r: _study(r)["variables"].update(b="wide"),
     "study.variables.b", ["must be a list", "'wide'"]),
    # -- obstacles inside the patient
    ("inside-not-bool", PORTS, lambda r: _obstacle(1)(r).update(inside="maybe"),
     "study.collision.obstacles.1.inside", ["true or false", "'maybe'"]),
    ("inside-radius-zero", PORTS, lambda r: _obstacle(1)(r).update(radius=0),
     "study.collision.obstacles.1.radius", ["must be > 0"]),
    ("inside-no-shape", PORTS, lambda r: _obstacle(1)(r).pop("shape"),
     "study.collision.obstacles.1.shape", ["missing", "ball, capsule, box"]),
    ("inside-shape-cone", PORTS, lambda r: _obstacle(1)(r).update(shape="cone"),
     "study.collision.obstacles.1.shape", ["'cone'", "unknown obstacle shape"]),
    # -- mesh files
    ("mesh-missing", PORTS, lambda r: _obstacle(2)(r).update(file=_file("nosuch.stl")),
     "study.collision.obstacles.2.file", ["nosuch.stl", "no such mesh file"]),
    ("mesh-a-folder", PORTS, lambda r: _obstacle(2)(r).update(file=_file("meshes.stl")),
     "study.collision.obstacles.2.file", ["meshes.stl", "folder"]),
    ("mesh-text", PORTS, lambda r: _obstacle(2)(r).update(file=_file("notes.stl")),
     "study.collision.obstacles.2.file", ["notes.stl", "cannot read"]),
    ("mesh-empty", PORTS, lambda r: _obstacle(2)(r).update(file=_file("empty.stl")),
     "study.collision.obstacles.2.file", ["empty.stl", "no triangles"]),
    ("mesh-open", PORTS, lambda r: _obstacle(2)(r).update(file=_file("open.stl")),
     "study.collision.obstacles.2.file", ["open.stl", "not watertight"]),
    ("mesh-resolution-two", PORTS, lambda r: _obstacle(2)(r).update(resolution=2),
     "study.collision.obstacles.2.resolution", ["from 32 to 128", "got 2"]),
    ("mesh-no-file", PORTS, lambda r: _obstacle(2)(r).pop("file"),
     "study.collision.obstacles.2.file", ["missing"]),
    # -- the sphere study
    ("sphere-angle-zero", SPHERE, lambda r: _study(r)["variables"].update(alpha12=[0, 150]),
     "study.variables.alpha12", ["strictly between 0 and 180"]),
    ("sphere-unknown-variable", SPHERE,
     lambda r: _study(r)["variables"].update(alpha34=[30, 60]),
     "study.variables.alpha34", ["unknown design variable", "'alpha12', 'alpha23'"]),
    ("sphere-fixed-and-variable", SPHERE, lambda r: _study(r).update(fixed={"alpha12": 90}),
     "study.fixed.alpha12", ["either variable or fixed"]),
    ("sphere-cone-a-word", SPHERE, lambda r: _study(r).update(cone="wide"),
     "study.cone", ["mapping", "'wide'"]),
    ("sphere-cone-zero", SPHERE, lambda r: _study(r)["cone"].update(half_angle_deg=0),
     "study.cone.half_angle_deg", ["must be > 0", "got 0"]),
    ("sphere-sampler", SPHERE, lambda r: _study(r)["index"].update(sampler="sobol"),
     "study.index.sampler", ["'sobol'", "'rqmc'"]),
    ("sphere-wide-cone", SPHERE, lambda r: _study(r).update(constraints={"reach_all_deg": 90}),
     "study.constraints.reach_all_deg", ["must be < 90"]),
    ("sphere-unknown-index", SPHERE, lambda r: _study(r).update(objective={"gcii": -1}),
     "study.objective.gcii", ["unknown index"]),
]  # fmt: skip


def _fill(tree: Any, files: dict[str, Path], folder: Path) -> Any:
    """``<name>`` placeholders as the fixture's files (else a missing file in ``folder``)."""
    if isinstance(tree, dict):
        return {k: _fill(v, files, folder) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_fill(v, files, folder) for v in tree]
    if isinstance(tree, str) and tree.startswith("<") and tree.endswith(">"):
        name = tree[1:-1]
        return str(files.get(name, folder / name))
    return tree


@pytest.mark.parametrize("base,edit,key,words",
                         [c[1:] for c in CONFIG_CASES], ids=[c[0] for c in CONFIG_CASES])
def test_bad_config_names_the_key(tmp_path, capsys, files, base, edit, key, words):
    raw = copy.deepcopy(base)
    edit(raw)
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(_fill(raw, files, tmp_path)))
    before = _written(tmp_path)
    err = _refused(capsys, ["run", cfg, "--dry-run", "--quiet", "--out", tmp_path / "o" / "a.h5"],
                   str(cfg), f"key '{key}':", *words)  # fmt: skip
    assert err.count("key '") == 1, err
    assert _written(tmp_path) == before


@pytest.fixture(scope="module")
def ports_cfg(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("ports") / "ports.yaml"
    p.write_text(yaml.safe_dump(PORTS))
    return p


# (id, --set values, words the line holds)
SET_CASES = [
    ("unknown-key", ["study.bogus=1"], ["key 'study.bogus': unknown key"]),
    ("text-for-a-number", ["seed=abc"], ["key 'seed': must be an integer, got 'abc'"]),
    ("float-for-a-count", ["optimizer.n_particles=1.5"],
     ["key 'optimizer.n_particles': must be a whole number, got 1.5"]),
    ("arm-past-the-list", ["study.arms.5.port=[0,0,0.3]"],
     ["override 'study.arms.5.port'", "'study.arms.5'", "2 entries"]),
    ("arm-by-name", ["study.arms.left.port=[0,0,0.3]"],
     ["override 'study.arms.left.port'", "'study.arms.left'", "not an entry number"]),
    ("into-a-number", ["seed.x=1"], ["override 'seed.x'", "'seed' is not a section"]),
    ("broken-yaml", ["study.task.insertion=[0.05,0.2"],
     ["--set study.task.insertion=[0.05,0.2", "not YAML"]),
    ("no-equals", ["seed"], ["--set seed", "KEY=VALUE"]),
    ("wall-shape", ["study.task.body_wall.shape=cube"],
     ["key 'study.task.body_wall.shape'", "'cube'"]),
    ("port-two-numbers", ["study.arms.1.port=[0.1,0.2]"], ["key 'study.arms.1.port'"]),
    ("nan", ["study.task.insertion=[0.05,.nan]"],
     ["key 'study.task.insertion.1'", "not a finite number"]),
    ("precision", ["precision=float16"], ["key 'precision'", "'float16'"]),
]  # fmt: skip


@pytest.mark.parametrize("sets,words", [c[1:] for c in SET_CASES], ids=[c[0] for c in SET_CASES])
def test_bad_set_flags(tmp_path, capsys, ports_cfg, sets, words):
    argv = ["run", ports_cfg, "--dry-run", "--quiet", "--out", tmp_path / "o" / "a.h5"]
    _refused(capsys, argv + [x for s in sets for x in ("--set", s)], *words)
    assert _written(tmp_path) == []


@pytest.mark.parametrize("name,words", [
    ("ports.yaml", ["not a readable HDF5 archive"]),  # the config instead of its archive
    ("nosuch.h5", ["archive not found"]),
    ("notes.h5", ["not a readable HDF5 archive"]),
    ("plain.h5", ["--csv", "nothing to export"]),  # an HDF5 file that is no task run
])  # fmt: skip
def test_show_csv_on_the_wrong_file(tmp_path, capsys, files, ports_cfg, name, words):
    path = ports_cfg if name == "ports.yaml" else files.get(name, tmp_path / name)
    _refused(capsys, ["show", path, "--csv"], str(path), *words)
    _refused(capsys, ["show", path, "--csv", tmp_path / "t.csv"], str(path), *words)
    assert _written(tmp_path) == []


def test_eval_outside_the_design_box(tmp_path, capsys):
    cfg = tmp_path / "sphere.yaml"
    raw = copy.deepcopy(SPHERE)
    raw["study"]["index"] = {"n_samples": 64}
    cfg.write_text(yaml.safe_dump(raw))
    for value in ("200", "10", "-45"):
        _refused(capsys, ["eval", cfg, "--design", f"alpha12={value}", "alpha23=90"], str(cfg),
                 f"--design alpha12={value}", "outside the design box [30, 150]",
                 "'alpha12'")  # fmt: skip
    _refused(capsys, ["eval", cfg, "--design", "alpha12=abc"], "--design alpha12", "'abc'")
    assert _written(tmp_path) == [cfg]


# ------------------------------------------------- the ranking rule, on small models


class _Names(BaseModel):
    """``uses`` is checked against ``names`` (a validator reading an earlier field)."""

    model_config = ConfigDict(extra="forbid")
    names: dict[str, float]
    uses: str

    @field_validator("uses")
    @classmethod
    def _known(cls, v: str, info: ValidationInfo) -> str:
        if v not in info.data.get("names", {}):
            raise ValueError(f"'{v}' is not a name (names: {sorted(info.data.get('names', {}))})")
        return v


class _Range(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    start: float = Field(alias="from")
    stop: float = Field(alias="to")
    num: int


class _Vary(BaseModel):
    v: list[float] | _Range


class _Ball(BaseModel):
    model_config = ConfigDict(extra="forbid")
    shape: Literal["ball"]
    radius: float


class _Box(BaseModel):
    model_config = ConfigDict(extra="forbid")
    shape: Literal["box"]
    size: tuple[float, float, float]


def _kind(v: Any) -> str:
    return str(v.get("shape")) if isinstance(v, dict) else ""


class _Scene(BaseModel):
    model_config = ConfigDict(extra="forbid")
    things: list[Annotated[Annotated[_Ball, Tag("ball")] | Annotated[_Box, Tag("box")],
                           Discriminator(_kind)]] = []  # fmt: skip


def _text(model: type[BaseModel], raw: dict) -> str:
    with pytest.raises(ValidationError) as e:
        model.model_validate(raw)
    return error_text(e.value, raw, model)


@pytest.mark.parametrize("model,raw,says", [
    # the cause, not the validator that failed for want of it (pydantic reports both)
    (_Names, {"names": {"a": "x"}, "uses": "a"}, "key 'names.a': must be a number, got 'x'"),
    (_Names, {"names": {"a": 1.0}, "uses": "b"}, "key 'uses': 'b' is not a name (names: ['a'])"),
    # of a union, the member the input was meant for
    (_Vary, {"v": {"from": 0, "to": 1, "num": "x"}}, "key 'v.num': must be an integer, got 'x'"),
    (_Vary, {"v": [1, "x"]}, "key 'v.1': must be a number, got 'x'"),
    (_Vary, {"v": {"from": 0, "to": 1, "nun": 3}}, "key 'v.nun': unknown key"),
    # a value no member takes: every member's shape said
    (_Vary, {"v": 5}, "key 'v': must be a list or a mapping of keys, got 5"),
    (_Vary, {"v": "wide"}, "key 'v': must be a list or a mapping of keys, got 'wide'"),
    # a tagged union names the key that picks the member
    (_Scene, {"things": [{"shape": "ball", "radius": 1}, {"size": [1, 1, 1]}]},
     "key 'things.1.shape': missing; give one of 'ball', 'box'"),
    (_Scene, {"things": [{"shape": "cone"}]}, "key 'things.0.shape': must be one of 'ball', "
                                              "'box', got 'cone'"),
    (_Scene, {"things": ["ball"]}, "key 'things.0': must be a mapping of keys with shape"),
    (_Scene, {"things": [{"shape": "box", "size": [1, 1]}]}, "key 'things.0.size': needs at "
                                                             "least 3 values"),
])  # fmt: skip
def test_the_deepest_key_at_fault(model, raw, says):
    assert _text(model, raw).startswith(says), _text(model, raw)


def test_pydantic_reports_the_consequence_too():
    """The case the rule is for: both errors are there, the cause first."""
    with pytest.raises(ValidationError) as e:
        _Names.model_validate({"names": {"a": "x"}, "uses": "a"})
    locs = [err["loc"] for err in e.value.errors()]
    assert locs == [("names", "a"), ("uses",)], locs


def test_a_study_named_wrong_is_still_named():
    for study, says in (({"name": "serail"}, "unknown study 'serail'"), ({}, "missing")):
        with pytest.raises(ConfigError) as e:
            validate({"study": {"variables": {}} | study}, "bad.yaml")
        assert f"key 'study.name': {says}" in str(e.value), e.value


# ---------------------------------------------------------- every n/a says so


def test_na_warnings_adds_a_line_for_each_na_index_no_study_line_speaks_of():
    fin = {"gci": np.float64(0.5), "gci_se": np.float64(0.01),
           "share": np.float64(math.nan), "share_se": np.float64(math.nan),
           "share_n": np.float64(3), "share_of": np.float64(128),
           "angle": math.nan, "angle_se": math.nan,
           "x": np.array([math.nan, 1.0]), "note_n": math.nan}  # fmt: skip
    assert na_indices(fin) == ["share", "angle"]
    out = na_warnings(fin)
    assert out[0].startswith("share: n/a (3 of 128): ") and out[1].startswith("angle: n/a: ")
    assert len(out) == 2
    own = ["angle: n/a (2 tuples): too few", "share_of_it: something else"]
    out = na_warnings(fin, own)
    assert out[:2] == own and len(out) == 3 and out[2].startswith("share: n/a (3 of 128)")
    assert na_warnings({"gci": 0.5, "gci_se": 0.01}, ["a line"]) == ["a line"]


def test_the_sphere_studys_na_carries_a_warning(tmp_path, capsys):
    """(30°, 30°) reaches none of the 60° cone about an axis 90° from joint axis 1 (its
    tool stays within 60° of that axis): gci_reached is n/a (0 of 64) with its line, in
    eval's print and its JSON; (90°, 90°) reaches all and says nothing."""
    import json

    from designopt.studies.sphere import STUDY

    cfg = tmp_path / "sphere.yaml"
    raw = copy.deepcopy(SPHERE)
    raw["study"]["index"] = {"n_samples": 64}
    cfg.write_text(yaml.safe_dump(raw))
    capsys.readouterr()
    assert main(["eval", str(cfg), "--design", "alpha12=30", "alpha23=30"]) == 0
    out = capsys.readouterr().out
    assert "gci_reached = n/a (0 of 64)" in out, out
    assert "warning: gci_reached: n/a (0 of 64 tool directions reached; under 30)" in out, out
    assert main(["eval", str(cfg), "--design", "alpha12=30", "alpha23=30", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["gci_reached"] is None and res["reach"] == 0
    assert [w.split(":")[0] for w in res["warnings"]] == ["gci_reached"], res["warnings"]
    assert main(["eval", str(cfg), "--design", "alpha12=90", "alpha23=90", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["reach"] == 1 and res["warnings"] == [], res
    # a run's final group (arrays, as the pipeline passes it): the same line
    s = validate(raw, str(cfg)).study
    fin = {"gci_reached": np.array(math.nan), "gci_reached_se": np.array(math.nan),
           "gci_reached_n": np.array(12.0), "gci_reached_of": np.array(4096.0),
           "gci": np.array(0.001), "gci_se": np.array(0.0)}  # fmt: skip
    assert STUDY.warnings(s, fin) == [
        "gci_reached: n/a (12 of 4096 tool directions reached; under 30): too few to say how "
        "isotropic the mechanism is where it reaches; gci counts every unreached direction as 0"
    ]
