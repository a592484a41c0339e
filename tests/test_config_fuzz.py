"""Fuzz the CLI's validation (#14): mutants of valid configs — keys deleted, types swapped,
extreme numbers, NaN, inf, odd strings, random bytes — through ``designopt run --dry-run``
(every check of a run, nothing run): no traceback, exit 0 or 2, one line on 2, nothing
written either way. Mutants aim at numbers too (NaN, ±inf, huge, negative, zero, wrong
types: #28), and every real number of every shipped config is swept deterministically."""

from __future__ import annotations

import copy
import math
import tempfile
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from designopt.app import config
from designopt.cli.commands import main
from designopt.core.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
TINY = {
    "study": {"name": "master9", "indices": {"n_samples": 2048}, "n_norm": 8},
    "optimizer": {"name": "ptpso", "n_particles": 8, "n_iters": 4, "n_runs": 2},
    "refine": {"steps": 5},
    "precision": "float64",
    "seed": 1,
}


def absolute_paths(tree, folder: Path):
    """The config with every string naming a file beside it (a URDF, a data file) made
    absolute, so that a copy written elsewhere reads the same files."""
    if isinstance(tree, dict):
        return {k: absolute_paths(v, folder) for k, v in tree.items()}
    if isinstance(tree, list):
        return [absolute_paths(v, folder) for v in tree]
    if isinstance(tree, str) and "/" in tree and (folder / tree).is_file():
        return str(folder / tree)
    return tree


def _run_configs() -> list[dict]:
    out = [TINY]
    for p in sorted((ROOT / "configs").glob("*.yaml")):
        raw = absolute_paths(yaml.safe_load(p.read_text()), p.parent)
        if isinstance(raw, dict) and "study" in raw and "sweep" not in raw:
            raw.pop("output", None)
            out.append(raw)
    return out


BASES = _run_configs()
ODD = st.sampled_from(["", " ", "\x00", "💥", "../../etc", "-1", "1e999", "nan", "NaN", "inf",
                       "~", "null", "yes", "{a: 1}", "[1, 2", "x" * 10_000, "\u202e", "%s%n"])  # fmt: skip
EXTREME = st.sampled_from([0, -1, 1, 2, 2**31, 2**63, -(2**63), 10**30, 1e-300, -1e308, 1e308,
                           math.nan, math.inf, -math.inf, 0.5, -0.0])  # fmt: skip
VALUE = st.one_of(
    EXTREME, ODD, st.booleans(), st.none(), st.lists(EXTREME, max_size=4),
    st.dictionaries(st.sampled_from(["a", "name", "n_samples", "l1"]), EXTREME, max_size=2),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(), st.text(max_size=20),
)  # fmt: skip


HOSTILE = st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1e10, 10**400, -1,
                           0, -0.0, 1e-320, "abc", "nan", "1e999", [1.0], {"a": 1}, None, True])  # fmt: skip
"""What a numeric field may be given: NaN, ±inf, huge, negative, zero, wrong types."""


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _get(tree, path):
    for k in path:
        tree = tree[k]
    return tree


def _paths(tree, prefix=()) -> list[tuple]:
    """Every key path of a nested config (dicts and lists)."""
    out = []
    items = (
        tree.items()
        if isinstance(tree, dict)
        else enumerate(tree)
        if isinstance(tree, list)
        else []
    )
    for k, v in items:
        out.append((*prefix, k))
        out += _paths(v, (*prefix, k))
    return out


@st.composite
def mutants(draw) -> bytes:
    """The bytes of a mutated config file."""
    if draw(st.integers(0, 19)) == 0:
        return draw(st.binary(max_size=300))  # random bytes
    cfg = copy.deepcopy(draw(st.sampled_from(BASES)))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(cfg)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = cfg
        for k in path[:-1]:
            parent = parent[k]
        action = draw(st.sampled_from(["delete", "value", "value", "extra", "number", "number"]))
        if action == "number":  # a number of the config (any study's) made hostile
            nums = [q for q in paths if _is_number(_get(cfg, q))]
            if nums:
                path = draw(st.sampled_from(nums))
                parent = cfg
                for k in path[:-1]:
                    parent = parent[k]
            parent[path[-1]] = copy.deepcopy(draw(HOSTILE))
        elif action == "delete":
            del parent[path[-1]]
        elif action == "value":
            parent[path[-1]] = copy.deepcopy(draw(VALUE))
        elif isinstance(parent, dict):
            parent[draw(st.sampled_from(["bogus", "Name", "n_samples", "seed"]))] = copy.deepcopy(
                draw(VALUE)
            )
    text = yaml.safe_dump(cfg, allow_unicode=True, sort_keys=False)
    if draw(st.integers(0, 9)) == 0:  # a few raw bytes inside a valid file
        i = draw(st.integers(0, len(text)))
        return text[:i].encode() + draw(st.binary(min_size=1, max_size=8)) + text[i:].encode()
    return text.encode("utf-8", "surrogatepass")


@settings(max_examples=500, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                 HealthCheck.data_too_large])  # fmt: skip
@given(data=mutants())
def test_mutated_configs_never_end_in_a_traceback(data, capsys):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        cfg = folder / "c.yaml"
        cfg.write_bytes(data)
        capsys.readouterr()
        try:
            rc = main(
                ["run", str(cfg), "--dry-run", "--quiet", "--out", str(folder / "o" / "a.h5")]
            )
        except SystemExit as e:  # argparse only; never for a config
            pytest.fail(f"SystemExit {e.code}")
        out, err = capsys.readouterr()
        event(f"exit {rc}")
        assert "Traceback" not in err + out
        assert rc in (0, 2), err
        if rc == 2:
            assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
        else:
            assert "checks passed" in out
        assert sorted(p.name for p in folder.iterdir()) == ["c.yaml"]


@pytest.mark.parametrize("base", range(len(BASES)))
def test_the_unmutated_configs_pass_the_dry_run(base, tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(BASES[base]))
    assert main(["run", str(cfg), "--dry-run", "--out", str(tmp_path / "a.h5")]) == 0, (
        capsys.readouterr().err
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]


def test_huge_jobs_are_refused_naming_the_key(tmp_path, capsys):
    """``n_particles: 100000000`` needs far more memory than any machine here: exit 2,
    one line naming the key and the estimate; the same for a run history of 10^12
    iterations."""
    for key, value, name in [("n_particles", 100_000_000, "optimizer.n_particles"),
                             ("n_iters", 10**12, "optimizer.n_iters")]:  # fmt: skip
        raw = copy.deepcopy(TINY)
        raw["optimizer"][key] = value
        cfg = tmp_path / "c.yaml"
        cfg.write_text(yaml.safe_dump(raw))
        capsys.readouterr()
        assert main(["run", str(cfg), "--quiet", "--out", str(tmp_path / "o" / "a.h5")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"key '{name}'" in err and "of memory" in err, err
        assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]


# ---------------------------------------------- every real number of every config


def _example_configs() -> list[tuple[str, dict]]:
    out = []
    for p in sorted((ROOT / "configs").glob("*.yaml")):
        raw = absolute_paths(yaml.safe_load(p.read_text()), p.parent)
        if isinstance(raw, dict) and "study" in raw:
            out.append((p.name, raw))
    return out


def _real_leaves(tree, path=()):
    items = tree.items() if isinstance(tree, dict) else enumerate(tree) if isinstance(
        tree, list) else ()  # fmt: skip
    for k, v in items:
        if isinstance(v, float) or (isinstance(v, int) and not isinstance(v, bool)):
            yield (*path, k)
        else:
            yield from _real_leaves(v, (*path, k))


def _dotted(path) -> str:
    out = ""
    for k in path:
        out += f".{k}" if out else str(k)
    return out


CONFIGS = _example_configs()


@pytest.mark.parametrize("name,raw", CONFIGS, ids=[c[0] for c in CONFIGS])
def test_every_real_number_of_every_config_refuses_nan_inf_and_huge(name, raw):
    """Each number of each shipped config (every study), set to NaN, +inf, -inf or 1e300:
    refused naming exactly that key (validation only; the CLI's path is tested above)."""
    leaves = list(_real_leaves(raw))
    assert leaves, name
    for path in leaves:
        for bad in (math.nan, math.inf, -math.inf, 1e300):
            r = copy.deepcopy(raw)
            node = r
            for k in path[:-1]:
                node = node[k]
            node[path[-1]] = bad
            with pytest.raises(ConfigError) as e:
                config.validate(r, str(ROOT / "configs" / name))
            assert f"key '{_dotted(path)}'" in str(e.value), (path, bad, str(e.value))


def test_every_config_number_through_the_cli(tmp_path, capsys):
    """One number per shipped config, through `designopt run --dry-run`: exit 2, one
    line, nothing written."""
    for _name, raw in CONFIGS:
        path = next(iter(_real_leaves(raw["study"], ("study",))), None)
        if path is None:
            continue
        r = copy.deepcopy(raw)
        r.pop("output", None)
        node = r
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = math.nan
        p = tmp_path / "c.yaml"
        p.write_text(yaml.safe_dump(r))
        cmd = "sweep" if "sweep" in r else "run"
        capsys.readouterr()
        assert main([cmd, str(p), "--dry-run", "--out", str(tmp_path / "o" / "a.h5")]) == 2
        out, err = capsys.readouterr()
        assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
        assert f"key '{_dotted(path)}'" in err and "Traceback" not in out + err, err
        assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]


@pytest.mark.parametrize("name,raw", CONFIGS, ids=[c[0] for c in CONFIGS])
def test_every_number_of_every_config_takes_odd_values_without_a_crash(name, raw):
    """Negative, zero, tiny and wrong-type values in every numeric field: the config
    validates or is refused with one ConfigError naming a key — never another exception."""
    for path in _real_leaves(raw):
        for odd in (-1, 0, -0.0, 1e-320, "abc", [1.0], None, True):
            r = copy.deepcopy(raw)
            node = r
            for k in path[:-1]:
                node = node[k]
            node[path[-1]] = odd
            try:
                config.validate(r, str(ROOT / "configs" / name))
            except ConfigError as e:
                assert "key '" in str(e) and "\n" not in str(e), (path, odd, str(e))
