"""Helpers of the fault-injection suite (docs/faults.md): a tiny config, the CLI in-process
and as a child process, and the checks every case makes."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from designopt.cli.commands import main

TINY = """
study:
  name: serial
  chain:
    convention: standard
    joints:
      - {type: R, a: l1, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
      - {type: R, a: l2, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
  variables: {l1: [0.2, 2.0], l2: [0.2, 2.0]}
  fixed: {}
  indices: {jacobian: [vx, vy], norm: "2", normalized: false, measure: joint, n_samples: 256}
  objective: {gci: -1.0}
optimizer: {name: ptpso, n_particles: 6, n_iters: 60, n_runs: 2}
precision: float64
seed: 3
"""
RESULT_KEYS = ("optimizer/history", "optimizer/history_x", "final/x", "final/f")
STRAY = re.compile(r"\.(tmp|old|probe)-\d+$|\.lock$")


def config(folder: Path, extra: str = "checkpoint_every_s: 0\n", name: str = "c.yaml") -> Path:
    """TINY (with ``extra`` keys; by default a checkpoint at every chunk) in ``folder``."""
    p = folder / name
    p.write_text(TINY + extra)
    return p


def cli(capsys, *args: str) -> tuple[int, str, str]:
    """``designopt ARGS`` in this process: (status, stdout, stderr)."""
    capsys.readouterr()
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def one_line(err: str) -> str:
    """The single message line of a failed or stopped command (no traceback)."""
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    return lines[0]


def strays(folder: Path) -> list[str]:
    """Temporary files, probe files and locks left in ``folder`` (recursively)."""
    return sorted(str(p) for p in folder.rglob("*") if STRAY.search(p.name))


def same_result(path: Path, ref: Path) -> None:
    with h5py.File(path) as a, h5py.File(ref) as r:
        assert a.attrs["complete"]
        for k in RESULT_KEYS:
            np.testing.assert_array_equal(a[k][()], r[k][()], err_msg=k)


def resume_args(err: str) -> list[str]:
    """The resume command a stop printed, as arguments for ``main``."""
    cmd = one_line(err).split("`")[1].split()
    assert cmd[:2] == ["designopt", "run"] and cmd[-1] == "--resume"
    return cmd[1:]


def spawn(args: list[str], env: dict[str, str], **kw) -> subprocess.Popen:
    """``designopt ARGS`` as a child process (tests/faults/_child.py: it writes phase
    marks to $FAULT_MARKS)."""
    child = Path(__file__).with_name("_child.py")
    return subprocess.Popen([sys.executable, str(child), *map(str, args)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)  # fmt: skip


def copy(src: Path, dst: Path) -> bytes:
    shutil.copyfile(src, dst)
    return dst.read_bytes()
