"""Figures written by forked children (``designopt.canvas.parallel_saves``): the same
bytes as drawn in the calling process, and a child that fails leaves its figure to the
caller (so a disk fault still raises there)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from designopt.figures import canvas

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork: Linux")


def _draw(folder: Path) -> list[Path]:
    out = []
    for i in range(3):
        fig, ax = plt.subplots(figsize=(3, 2))
        ax.plot(np.sin(np.linspace(0, 6, 50) + i))
        ax.set_title(f"panel {i}")
        out += canvas.save(fig, folder, f"f{i}")
    return out


def test_children_write_the_same_pngs(tmp_path: Path) -> None:
    seq = _draw(tmp_path / "seq")
    with canvas.parallel_saves(workers=2):
        par = _draw(tmp_path / "par")
    assert [p.name for p in par] == [p.name for p in seq]
    for a, b in zip(seq, par, strict=True):
        if a.suffix == ".png":
            assert a.read_bytes() == b.read_bytes()
        else:
            assert b.read_bytes()[:5] == b"%PDF-" and b.stat().st_size > 1000
    assert plt.get_fignums() == []


def test_a_failing_child_leaves_its_figure_to_the_caller(tmp_path: Path, monkeypatch) -> None:
    parent, real = os.getpid(), canvas._write
    calls = []

    def write(fig, png, pdf, dpi):
        if os.getpid() != parent:
            raise OSError("the child cannot write")
        calls.append(png.name)
        real(fig, png, pdf, dpi)

    monkeypatch.setattr(canvas, "_write", write)
    with canvas.parallel_saves(workers=2):
        out = _draw(tmp_path)
    assert sorted(calls) == ["f0.png", "f1.png", "f2.png"]
    assert all(p.exists() for p in out)


def test_a_disk_fault_raises_in_the_caller(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    (ro / "f0.png").mkdir()  # a folder where the PNG goes: no process can write it
    with pytest.raises(OSError), canvas.parallel_saves(workers=2):
        _draw(ro)
    assert plt.get_fignums() == []


def test_no_fork_draws_here(tmp_path: Path, monkeypatch) -> None:
    def no_fork():
        raise OSError(12, "Cannot allocate memory")

    monkeypatch.setattr(os, "fork", no_fork)
    with canvas.parallel_saves(workers=2):
        out = _draw(tmp_path)
    assert all(p.exists() for p in out) and plt.get_fignums() == []



def test_a_stuck_child_is_stopped_and_says_where(tmp_path: Path, monkeypatch, capsys) -> None:
    """A child that sleeps (a deadlock: it uses no CPU) is stopped after CHILD_IDLE
    seconds, not CHILD_TIMEOUT; its figure is drawn by the caller, and the warning
    names the child's Python frames."""
    import threading
    import time

    parent, real = os.getpid(), canvas._write

    def wait_forever_for_a_lock(fig, png, pdf, dpi):
        if os.getpid() != parent:
            threading.Event().wait()
        real(fig, png, pdf, dpi)

    monkeypatch.setattr(canvas, "_write", wait_forever_for_a_lock)
    monkeypatch.setattr(canvas, "CHILD_IDLE", 1.0)
    t0 = time.monotonic()
    with canvas.parallel_saves(workers=2):
        out = _draw(tmp_path)
    took = time.monotonic() - t0
    err = capsys.readouterr().err
    assert all(p.exists() for p in out) and plt.get_fignums() == []
    assert took < 10.0, f"{took:.1f} s"
    assert err.count("used no CPU for 1 s; stopped, and the figure drawn here") == 3, err
    assert "in wait_forever_for_a_lock" in err, err
