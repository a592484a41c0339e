"""The output policy of the one writer: an existing archive is never silently replaced
(exit 2 without --overwrite or ``overwrite: true``), a second process on the same output
refuses at once naming the holder, a dead holder's lock is taken over with a warning;
the same for every command that writes (run, sweep, scan, report)."""

from __future__ import annotations

import errno
import time

from faultkit import cli, config, copy, one_line, same_result, spawn, strays
from test_write_faults import inject

from designopt.io import archive

SCAN = "scan: {vary: {l2: [0.5, 1.0, 1.5]}, design: {l1: 1.0}}\n"


def test_existing_archive_without_and_with_overwrite(tmp_path, capsys, reference):
    cfg = config(tmp_path)
    out = tmp_path / "a.h5"
    earlier = copy(reference, out)
    for cmd in (["run", cfg], ["sweep", config(tmp_path, "sweep: {vary: {optimizer.w: [0.5]}}\n",
                                               "s.yaml")]):  # fmt: skip
        rc, _, err = cli(capsys, *cmd, "--quiet", "--no-figures", "--out", out)
        assert rc == 2
        msg = one_line(err)
        assert str(out) in msg and "--overwrite" in msg
        assert out.read_bytes() == earlier and strays(tmp_path) == []
    scan_cfg = config(tmp_path, SCAN, "scan.yaml")
    assert cli(capsys, "scan", scan_cfg, "--no-figures", "--out", out)[0] == 2
    assert out.read_bytes() == earlier
    rc, _, err = cli(capsys, "run", cfg, "--quiet", "--no-figures", "--out", out, "--overwrite")
    assert rc == 0, err
    same_result(out, reference)
    # the config key does the same
    keyed = config(tmp_path, "checkpoint_every_s: 0\noverwrite: true\n", "k.yaml")
    assert cli(capsys, "run", keyed, "--quiet", "--no-figures", "--out", out)[0] == 0
    assert strays(tmp_path) == []


def test_dry_run_writes_nothing_and_checks_the_output(tmp_path, capsys, reference):
    cfg = config(tmp_path)
    rc, out, err = cli(capsys, "run", cfg, "--dry-run", "--out", tmp_path / "new" / "a.h5")
    assert rc == 0 and "nothing written" in out and err == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]
    copy(reference, tmp_path / "a.h5")
    rc, _, err = cli(capsys, "run", cfg, "--dry-run", "--out", tmp_path / "a.h5")
    assert rc == 2 and "--overwrite" in one_line(err)


def test_two_processes_on_one_output(tmp_path, capsys, child_env):
    """A second run (here: in this process) on an output a child process is writing
    refuses at once with exit 2 and names the child's pid; the child finishes."""
    cfg = config(tmp_path)
    out = tmp_path / "a.h5"
    lock = out.with_name(".a.h5.lock")
    child = spawn(["run", cfg, "--quiet", "--no-figures", "--out", out],
                  child_env | {"FAULT_WRITE_SLEEP": "1.0"})  # fmt: skip
    t0 = time.monotonic()
    while not lock.exists():
        assert child.poll() is None and time.monotonic() - t0 < 60
        time.sleep(0.02)
    t1 = time.monotonic()
    for cmd in (["run", cfg, "--quiet", "--no-figures", "--overwrite"],
                ["scan", config(tmp_path, SCAN, "scan.yaml"), "--no-figures", "--overwrite"]):  # fmt: skip
        rc, _, err = cli(capsys, *cmd, "--out", out)
        assert rc == 2
        msg = one_line(err)
        assert f"pid {child.pid}" in msg and str(out) in msg
    assert time.monotonic() - t1 < 5  # at once, not after the child's run
    _, err = child.communicate(timeout=120)
    assert child.returncode == 0, err
    assert archive.read(out)["attrs"]["complete"]
    assert strays(tmp_path) == []
    rc, _, err = cli(capsys, "report", out)  # the lock is free again
    assert rc == 0, err


def test_a_dead_holders_lock_is_taken_over_with_a_warning(tmp_path, capsys, reference):
    out = tmp_path / "a.h5"
    lock = out.with_name(".a.h5.lock")
    lock.write_text("999999999 (designopt run c.yaml)\n")  # no such process
    rc, _, err = cli(capsys, "run", config(tmp_path), "--quiet", "--no-figures", "--out", out)
    assert rc == 0
    warning = one_line(err)
    assert "999999999" in warning and "no longer running" in warning
    same_result(out, reference)
    assert not lock.exists() and strays(tmp_path) == []


def test_every_writing_command_reports_a_disk_fault_in_one_line(tmp_path, monkeypatch, capsys):
    """scan and sweep write through the same writer: an injected ENOSPC is exit 1."""
    inject(monkeypatch, "archive", errno.ENOSPC, "write", 1)
    rc, _, err = cli(capsys, "scan", config(tmp_path, SCAN, "scan.yaml"), "--no-figures", "--quiet",
                     "--out", tmp_path / "s.h5")  # fmt: skip
    assert rc == 1 and "No space left on device" in one_line(err)
    assert not (tmp_path / "s.h5").exists() and strays(tmp_path) == []
