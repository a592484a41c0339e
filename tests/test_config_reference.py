"""The config-key reference (designopt.app.reference, `designopt config --keys`): every
field of every config model is described, the reference lists exactly the keys the
models accept (walked here independently of the generator) and every key of every
shipped config, and an unknown prefix is one clear error. No JAX compile."""

from __future__ import annotations

import argparse
import types
import typing
from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel

from designopt.app import reference
from designopt.app.config import RunConfigBase, run_config_model
from designopt.bench.suite import BenchConfig
from designopt.core.errors import ConfigError
from designopt.studies import STUDIES

CONFIGS = sorted(Path(__file__).resolve().parents[1].joinpath("configs").glob("*.yaml"))


def _models(tp: typing.Any) -> list[type[BaseModel]]:
    """The models a field's type holds, at any depth (unions, lists, mappings)."""
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        return [tp]
    return [m for a in typing.get_args(tp) for m in _models(a)]


def _every_model() -> list[type[BaseModel]]:
    seen: list[type[BaseModel]] = []

    def walk(m: type[BaseModel]) -> None:
        if m in seen:
            return
        seen.append(m)
        for f in m.model_fields.values():
            for sub in _models(f.annotation):
                walk(sub)

    walk(run_config_model())
    walk(BenchConfig)
    return seen


def test_every_field_is_described():
    models = _every_model()
    assert len(models) > 40  # the run config, every study's sections, task, collision, bench
    bare = [f"{m.__module__}.{m.__qualname__}.{name}" for m in models
            for name, f in m.model_fields.items() if not (f.description or "").strip()]  # fmt: skip
    assert not bare, f"fields without a description: {bare}"


def _paths(model: type[BaseModel], prefix: str) -> set[str]:
    """Every dotted key of ``model`` (this test's own walk: a list of sections adds
    ``[]``, a mapping of sections ``.*``, a union each member's keys)."""
    out: set[str] = set()
    for name, f in model.model_fields.items():
        extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
        key = prefix + str(extra.get("config_key") or f.alias or name)
        out.add(key)
        tp = f.annotation
        suffix = ""
        while True:  # strip Optional / Annotated / list / dict down to the sections
            origin, args = typing.get_origin(tp), typing.get_args(tp)
            if origin is typing.Annotated:
                tp = args[0]
            elif origin in (typing.Union, types.UnionType):
                inner = [a for a in args if _models(a)]
                if len(inner) != 1:
                    break
                tp = inner[0]
            elif origin is list and _models(args[0]):
                suffix, tp = suffix + "[]", args[0]
            elif origin is dict and _models(args[1]):
                suffix, tp = suffix + ".*", args[1]
            else:
                break
        for sub in _models(tp):
            out |= _paths(sub, key + suffix + ".")
    return out


def test_reference_lists_exactly_the_models_keys():
    got = {(e.config, e.study, e.key) for e in reference.keys()}
    want = {("run", None, k) for k in _paths(RunConfigBase, "")} | {("run", None, "study")}
    for name, study in STUDIES.items():
        want |= {("run", name, k) for k in _paths(study.settings, "study.")}
    want |= {("bench", None, k) for k in _paths(BenchConfig, "")}
    assert got == want
    assert ("run", "serial", "study.task.ik.n_best") in got
    assert ("run", "serial", "study.task.region.half_angle") in got  # a variant's key
    assert ("run", "serial", "study.arms[].port") in got
    assert ("run", None, "scan.vary.*.from") in got  # the alias, not the field's name
    assert ("run", "serial", "study.collision.self") in got


def _yaml_keys(node: typing.Any, prefix: str = "") -> list[str]:
    """Every key path of a parsed YAML document (a list entry as ``[]``)."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            key = f"{prefix}{k}"
            out += [key, *_yaml_keys(v, key + ".")]
    elif isinstance(node, list):
        for v in node:
            out += _yaml_keys(v, prefix.removesuffix(".") + "[].")
    return out


def _covered(path: str, known: dict[str, reference.KeyDoc]) -> bool:
    """Whether the reference lists a config's key: the key itself, with names of one's
    choice as ``*``; a key below a free-form mapping (``study.fixed.a4``,
    ``optimizer.settings.gamma``) is its mapping's."""
    cur = ""
    for part in path.split("."):
        head, brackets = part.split("[]", 1)[0], "[]" * part.count("[]")
        nxt = f"{cur}.{head}" if cur else head
        if nxt in known or nxt + "[]" in known or any(k.startswith(nxt + ".") for k in known):
            cur = nxt + brackets  # (a section that only holds listed keys: objective.pareto)
        elif f"{cur}.*" in known:
            cur = f"{cur}.*" + brackets
        elif cur in known and known[cur].type.startswith("mapping"):
            return True
        else:
            return False
    return True


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_key_of_a_shipped_config_is_listed(path):
    raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    if "bench" in raw:
        entries = [e for e in reference.keys() if e.config == "bench"]
    else:
        name = raw["study"]["name"]
        entries = [e for e in reference.keys()
                   if e.config == "run" and e.study in (None, name)]  # fmt: skip
    known = {e.key: e for e in entries}
    missing = [k for k in _yaml_keys(raw) if not _covered(k, known)]
    assert not missing, f"{path.name}: keys the reference does not list: {missing}"


def test_an_unknown_key_is_not_covered():
    """The check above can fail: a misspelt key is not listed."""
    known = {e.key: e for e in reference.keys() if e.study in (None, "serial")}
    assert _covered("study.task.ik.n_best", known)
    assert _covered("study.fixed.l1", known)  # a free-form mapping's own names
    assert not _covered("study.task.ik.n_bets", known)
    assert not _covered("optimizer.n_particle", known)


def test_text_of_a_section():
    out = reference.text("optimizer", width=100)
    assert "optimizer.n_particles" in out
    desc = run_config_model().model_fields["optimizer"].annotation.model_fields["n_particles"]
    assert " ".join(desc.description.split()) in " ".join(out.split())
    assert "≥ 2" in out and "default 50" in out
    heads = [line for line in out.splitlines() if line and not line.startswith(" ")]
    assert heads and all(h.startswith("optimizer") for h in heads)  # only keys under it
    assert max(len(line) for line in out.splitlines()) <= 100


def test_prefixes():
    ik = reference.keys("study.task.ik")
    assert {e.study for e in ik} == {"serial"}
    assert all(e.key.startswith("study.task.ik") for e in ik)
    assert any(e.key == "study.task.ik.n_best" and e.range == "≥ 1; ≤ 64" for e in ik)
    assert {e.study for e in reference.keys("plas")} == {"plas"}
    assert [e.key for e in reference.keys("seed") if e.config == "run"] == ["seed"]
    assert reference.keys("study.arms.port") == reference.keys("study.arms[].port")
    region = reference.keys("study.task.region")
    assert {e.table for e in region} >= {"study.task.region (shape: box)",
                                         "study.task.region (points)"}  # fmt: skip
    pareto = reference.keys("study.objective.pareto")  # spelled as a config spells it
    assert {e.study for e in pareto} == set(STUDIES)


def test_unknown_prefix():
    with pytest.raises(ConfigError, match=r"'optimiser'.*optimizer"):
        reference.keys("optimiser")
    with pytest.raises(ConfigError, match="study.task.ik.n_bets"):
        reference.text("study.task.ik.n_bets")


def test_markdown():
    md = reference.markdown()
    assert "generated from the schema at build time" in md
    assert "| key | type | default | range | description |" in md
    assert "| `optimizer.n_particles` | int | `50` | ≥ 2 |" in md
    for name in STUDIES:
        assert f"## Study `{name}`" in md
    assert "## Benchmark configs" in md
    rows = [line for line in md.splitlines() if line.startswith("| `")]
    assert len(rows) == len(reference.keys())


def test_cli(capsys):
    from designopt.cli import reference as cli

    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="command")
    cli.add_parser(sub)
    args = ap.parse_args(["config", "--keys", "refine"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "refine.method" in out and "optimizer." not in out
    args = ap.parse_args(["config", "--keys"])
    assert args.func(args) == 0
    assert "study.task.ik.n_best" in capsys.readouterr().out
    args = ap.parse_args(["config", "--markdown"])
    assert args.func(args) == 0
    assert capsys.readouterr().out.startswith("# Config key reference")
    with pytest.raises(ConfigError, match="nosuch"):
        args = ap.parse_args(["config", "--keys", "nosuch"])
        args.func(args)
