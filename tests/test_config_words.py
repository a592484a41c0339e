"""Config errors in designopt's own words, naming the key the user wrote (no pydantic
phrasing, no union tag taken for a key)."""

from __future__ import annotations

import yaml

from designopt.cli.commands import main


def _refused(tmp_path, capsys, cfg: dict) -> str:
    cfg["output"] = str(tmp_path / "out.h5")
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(cfg))
    capsys.readouterr()
    assert main(["eval", str(p)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out.h5").exists()
    return err


def _puma() -> dict:
    with open("configs/urdf_puma560_port.yaml") as f:
        cfg = yaml.safe_load(f)
    cfg["study"]["chain"]["urdf"] = str(__import__("pathlib").Path(
        "configs/robots/puma560.urdf").resolve())  # fmt: skip
    return cfg


def test_chain_set_as_nested_yaml_is_the_dotted_form():
    from designopt.app.config import validate

    flat, nested = _puma(), _puma()
    nested["study"]["chain"]["set"] = {"joint3": {"origin": {"x": "a2"}},
                                       "joint5": {"origin": {"z": "d4"}},
                                       "tool_joint.origin.z": "l_tool"}  # fmt: skip
    a, b = validate(flat, "flat"), validate(nested, "nested")
    assert a.study.chain.bound() == b.study.chain.bound()


def test_a_bad_set_value_names_chain_set_not_the_urdf_key(tmp_path, capsys):
    cfg = _puma()
    cfg["study"]["chain"]["set"] = {"joint3": {"origin": {"x": [1, 2]}}}
    err = _refused(tmp_path, capsys, cfg)
    assert "key 'study.chain.set" in err and "chain.urdf" not in err


def test_a_unit_with_a_space_is_refused_in_plain_words(tmp_path, capsys):
    cfg = _puma()
    cfg["study"]["units"] = {"length": "m m"}
    err = _refused(tmp_path, capsys, cfg)
    assert "key 'study.units.length': must be one word" in err
    assert "String should" not in err and "pattern" not in err
