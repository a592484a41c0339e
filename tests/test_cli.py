"""designopt run/show end to end, and bad input: one line, exit 2, nothing written."""

import re

import h5py
import numpy as np
import pytest

from designopt.cli.commands import main

TINY = """
study:
  name: master9
  indices: {n_samples: 2048}
  n_norm: 8
optimizer: {name: ptpso, n_particles: 8, n_iters: 4, n_runs: 2}
precision: float64
seed: 1
output: OUT
"""


def write(tmp_path, text, name="c.yaml"):
    p = tmp_path / name
    p.write_text(text.replace("OUT", str(tmp_path / "a.h5")))
    return p


def test_run_writes_archive_and_same_seed_gives_same_numbers(tmp_path, capsys):
    cfg = write(tmp_path, TINY)
    assert main(["run", str(cfg), "--quiet"]) == 0
    with h5py.File(tmp_path / "a.h5") as h:
        assert h.attrs["complete"] and "ptpso" in h.attrs["config_yaml"]
        hist = h["optimizer/history"][()]
        assert hist.shape == (2, 5) and np.all(np.diff(hist, axis=1) <= 0)
        assert h["best_run/f_k_se"][()].shape == (5,)
    assert main(["run", str(cfg), "--quiet", "--no-figures", "--out", str(tmp_path / "b.h5")]) == 0
    with h5py.File(tmp_path / "a.h5") as a, h5py.File(tmp_path / "b.h5") as b:
        np.testing.assert_array_equal(a["optimizer/history"][()], b["optimizer/history"][()])
    assert main(["show", str(tmp_path / "a.h5")]) == 0
    assert "best design" in capsys.readouterr().out


@pytest.mark.parametrize(
    "text,needle",
    [
        (TINY + "bogus: 1\n", "bogus"),
        (TINY.replace("n_particles: 8", "n_particles: many"), "optimizer.n_particles"),
        (TINY.replace("{n_samples: 2048}", "{n_samples: -5}"), "study.indices.n_samples"),
        (TINY.replace("name: ptpso", "name: p9"), "optimizer.name"),
        (TINY.replace("name: master9", "name: nosuchstudy"), "study.name"),
        (TINY.replace("n_norm: 8", "n_norm: 8\n  variables: {a1: [350, 250]}"), "variables"),
        ("study: [unclosed\n", "malformed YAML"),
    ],
)
def test_bad_config_one_line_exit_2_nothing_written(tmp_path, capsys, text, needle):
    cfg = write(tmp_path, text)
    assert main(["run", str(cfg), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert needle in err and str(cfg) in err and err.count("\n") == 1
    assert not (tmp_path / "a.h5").exists()


def test_missing_file_and_unwritable_output(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.yaml")]) == 2
    assert "not found" in capsys.readouterr().err
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    cfg = write(tmp_path, TINY.replace("output: OUT", f"output: {blocker / 'x.h5'}"))
    assert main(["run", str(cfg), "--quiet"]) == 2
    assert "cannot create folder" in capsys.readouterr().err
    assert blocker.read_text() == "not a folder"


def test_output_that_is_a_folder_or_unwritable_is_refused_before_the_run(tmp_path, capsys):
    (tmp_path / "adir").mkdir()
    cfg = write(tmp_path, TINY)
    assert main(["run", str(cfg), "--quiet", "--out", str(tmp_path / "adir")]) == 2
    err = capsys.readouterr().err
    assert "is a folder" in err and err.count("\n") == 1
    assert main(["run", str(cfg), "--quiet", "--out", "/proc/x.h5"]) == 2
    assert "not writable" in capsys.readouterr().err
    assert main(["run", str(tmp_path / "adir")]) == 2
    assert "is a folder" in capsys.readouterr().err
    # a config refused for its optimizer creates no output folder
    text = TINY.replace("name: ptpso", "name: ptspo")
    bad = write(
        tmp_path, text.replace("output: OUT", f"output: {tmp_path / 'new' / 'a.h5'}"), "b.yaml"
    )
    assert main(["run", str(bad), "--quiet"]) == 2
    assert "optimizer.name" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
    assert not list(tmp_path.glob("adir*.h5")) and not list((tmp_path / "adir").iterdir())


def test_long_jobs_print_their_eta_once_after_the_first_timed_chunk(monkeypatch, capsys):
    import time

    from designopt.cli import commands

    clock = iter([10.0, 15.0, 20.0, 25.0])  # the first chunk (compile) ends at 10 s
    monkeypatch.setattr(time, "monotonic", lambda: next(clock))
    with commands._progress(True)(100, "ptpso on master9") as update:
        for _ in range(4):
            update(1)
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "about 8 min left" in err and "--max-minutes" in err
    clock = iter([10.0, 10.1, 10.2])
    with commands._progress(True)(10, "short") as update:
        for _ in range(3):
            update(1)
    assert capsys.readouterr().err == ""


def test_bad_max_minutes_and_dry_run(tmp_path, capsys):
    cfg = write(tmp_path, TINY)
    assert main(["run", str(cfg), "--max-minutes", "-1"]) == 2
    assert "--max-minutes" in capsys.readouterr().err
    assert main(["run", str(cfg), "--max-minutes", "nan"]) == 2
    assert main(["run", str(cfg), "--dry-run"]) == 0
    assert "checks passed; nothing written" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]


def test_a_long_phase_shows_that_it_runs_and_a_short_one_does_not(monkeypatch, capsys):
    """Not a terminal (a log): one line once the phase has lasted SHOW_AFTER_S."""
    import time

    from designopt.cli import setup

    monkeypatch.setattr(setup, "SHOW_AFTER_S", 0.05)
    with setup.progress(False)(None, "re-scoring the front"):
        time.sleep(0.3)
    assert capsys.readouterr().err == "designopt: re-scoring the front …\n"
    with setup.progress(False)(None, "short"):
        pass
    with setup.progress(True)(None, "quiet"):
        time.sleep(0.3)
    assert capsys.readouterr().err == ""


def test_compiling_is_a_phase_apart_from_the_iterations(monkeypatch, capsys):
    """Until the first chunk is done the line says compiling; the bar starts after it,
    holding the first chunk's iterations, so its rate counts only iterations."""
    import time

    from designopt.cli import setup

    monkeypatch.setattr(setup, "SHOW_AFTER_S", 0.05)
    with setup.progress(False)(10, "ptpso on planar2r") as update:
        time.sleep(0.3)  # compiling
        update(4)
        update(6)
    err = capsys.readouterr().err.replace("\r", "\n")
    assert err.splitlines()[0] == "designopt: ptpso on planar2r: compiling …"
    bars = [ln for ln in err.splitlines() if ln.startswith("ptpso on planar2r:")]
    assert bars and " 4/10 " in bars[0] and "10/10" in bars[-1]


def test_a_run_prints_its_wall_time_end_to_end(tmp_path, capsys):
    cfg = write(tmp_path, TINY)
    assert main(["run", str(cfg), "--quiet"]) == 0
    out = capsys.readouterr().out.splitlines()
    last = out[-1]
    assert last.startswith("wall ") and "s end to end = start-up " in last, last
    for part in ("+ setup", "+ optimizer", "+ scoring", "+ figures", "; compile", "XLA programs"):
        assert part in last, (part, last)
    total = float(last.split()[1])
    parts = [float(x) for x in re.findall(r"(?:start-up|setup|optimizer|scoring|figures|rest) "
                                          r"([\d.]+) s", last)]  # fmt: skip
    assert len(parts) == 6 and abs(sum(parts) - total) <= 0.35  # each rounded to 0.1 s


def test_start_up_counts_from_this_process_even_when_a_shell_execs_it():
    """A shell's last command is ``exec``-ed into the shell's process, whose /proc start
    is the shell's: the start-up of ``bash -c 'pip install … && designopt run …'`` must
    not include the install (2 s of sleep stand in for it)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    code = "from designopt.cli.commands import process_age as a; print(a())"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    r = subprocess.run(["bash", "-c", f'sleep 2; exec "{sys.executable}" -c "{code}"'],
                       capture_output=True, text=True, env=env, check=True)  # fmt: skip
    assert 0.0 <= float(r.stdout) < 1.0, r.stdout
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       check=True)  # fmt: skip
    assert 0.0 <= float(r.stdout) < 1.0, r.stdout
