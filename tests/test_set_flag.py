"""``--set KEY=VALUE`` on run, eval, scan and sweep: the same numbers as the config file
edited by hand (one override path, ``config.set_key``), list entries by index, and bad
items refused in one line naming the item."""

from __future__ import annotations

import json

import pytest
import yaml

from designopt.cli.commands import main


def _json(capsys, argv: list[str]) -> dict:
    capsys.readouterr()
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_eval_with_set_equals_the_edited_file(tmp_path, capsys):
    with open("configs/planar2r_task.yaml") as f:
        cfg = yaml.safe_load(f)
    cfg["study"]["indices"]["n_samples"] = 64
    cfg["output"] = str(tmp_path / "o.h5")
    (tmp_path / "a.yaml").write_text(yaml.safe_dump(cfg))
    cfg["study"]["task"]["region"]["center"] = [1.0, 0.2, 0.0]
    (tmp_path / "b.yaml").write_text(yaml.safe_dump(cfg))
    d = ["--design", "l1=1", "l2=0.6", "--json"]
    by_set = _json(capsys, ["eval", str(tmp_path / "a.yaml"), *d,
                            "--set", "study.task.region.center=[1.0, 0.2, 0.0]"])  # fmt: skip
    by_file = _json(capsys, ["eval", str(tmp_path / "b.yaml"), *d])
    plain = _json(capsys, ["eval", str(tmp_path / "a.yaml"), *d])
    assert by_set == by_file and by_set != plain


def test_run_with_set_and_a_list_entry(tmp_path, capsys):
    out = tmp_path / "r.h5"
    argv = ["run", "configs/planar2r.yaml", "--out", str(out), "--quiet", "--no-figures",
            "--set", "optimizer.n_iters=2", "--set", "optimizer.n_particles=4",
            "--set", "study.indices.n_samples=256"]  # fmt: skip
    assert main(argv) == 0
    from designopt.app import records

    rec = records.load(out)
    assert rec.config.optimizer.n_iters == 2 and rec.config.study.indices.n_samples == 256


@pytest.mark.parametrize("item, says", [
    ("study.task.port", "--set study.task.port: give KEY=VALUE"),
    ("=3", "--set =3: give KEY=VALUE"),
    ("seed=[1", "--set seed=[1: the value is not YAML"),
    ("study.variables.l1=[2, 1]", "key 'study.variables.l1'"),
    ("study.chain.joints.5.a=1", "'study.chain.joints.5': the list has 2 entries"),
])  # fmt: skip
def test_bad_set_items_are_one_line(tmp_path, capsys, item, says):
    capsys.readouterr()
    assert main(["eval", "configs/planar2r.yaml", "--set", item]) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_view_takes_set_as_the_other_config_commands(tmp_path, capsys):
    """--set on a study's own command that loads a config (view): an edit that is
    refused names its key, one that is taken draws."""
    capsys.readouterr()
    argv = ["view", "configs/urdf_puma560_port.yaml", "--out", str(tmp_path / "v.png")]
    assert main([*argv, "--set", "study.task.port=[0.5, 0.1]"]) == 2
    assert "key 'study.task.port'" in capsys.readouterr().err
    assert main([*argv, "--set", "study.task.port=[0.45, 0.1, -0.2]"]) == 0
    assert (tmp_path / "v.png").exists()
