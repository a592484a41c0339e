"""Disk faults while writing an archive, a checkpoint or a figure (ENOSPC, EIO, EACCES,
EROFS), injected into the one writer's file operations at random points, and on a real
full or read-only file system where one can be mounted: one line naming the path and the
OS reason, exit 1 (2 when refused before the run), no traceback, no temporary file, the
last good checkpoint and any earlier archive kept, and ``--resume`` gives the
uninterrupted result."""

from __future__ import annotations

import errno
import os
import random
import shutil
import subprocess
from collections import namedtuple

import pytest
from faultkit import cli, config, copy, one_line, resume_args, same_result, strays

from designopt.io import archive, writer

REASON = {errno.ENOSPC: "No space left on device", errno.EIO: "Input/output error",
          errno.EACCES: "Permission denied", errno.EROFS: "Read-only file system"}  # fmt: skip
OPS = ("open", "write", "fsync", "replace")


def inject(monkeypatch, kind: str, code: int, op: str, nth: int) -> list[str]:
    """Make the writer's ``op`` fail with ``code`` on its ``nth`` use for a ``kind`` file
    ("archive" or "checkpoint"); returns a list that records the failure."""
    fds: dict[int, str] = {}
    seen = {"n": 0}
    fired: list[str] = []

    def kind_of(path) -> str:
        return "checkpoint" if ".partial" in str(path) else "archive"

    def wrap(name, real):
        def op_(*a):
            k = kind_of(a[0]) if name in ("open", "replace") else fds.get(a[0])
            if name == op and k == kind and not fired:
                seen["n"] += 1
                if seen["n"] == nth:
                    fired.append(f"{name} #{nth}")
                    raise OSError(code, os.strerror(code), str(a[0]))
            out = real(*a)
            if name == "open":
                fds[out] = k
            return out

        return staticmethod(op_)

    for name in OPS:
        monkeypatch.setattr(writer._Ops, name, wrap(name, getattr(writer._Ops, name)))
    return fired


CASES = [("archive", errno.ENOSPC), ("archive", errno.EIO), ("checkpoint", errno.ENOSPC),
         ("checkpoint", errno.EIO), ("archive", errno.EACCES), ("checkpoint", errno.EROFS)]  # fmt: skip


@pytest.mark.parametrize("kind,code", CASES)
def test_injected_fault_while_writing(tmp_path, monkeypatch, capsys, reference, kind, code):
    rng = random.Random(f"{kind}{code}")
    op = rng.choice(OPS)
    nth = 1 if kind == "archive" else rng.randint(1, 12)
    cfg = config(tmp_path)
    out = tmp_path / "a.h5"
    earlier = copy(reference, out)
    fired = inject(monkeypatch, kind, code, op, nth)
    rc, _, err = cli(capsys, "run", cfg, "--quiet", "--no-figures", "--overwrite", "--out", out)
    assert fired, f"{op} #{nth} of the {kind} never happened"
    assert rc == 1, err
    msg = one_line(err)
    partial = archive.partial_path(out)
    assert REASON[code] in msg and str(partial if kind == "checkpoint" else out) in msg
    assert out.read_bytes() == earlier
    assert strays(tmp_path) == []
    monkeypatch.undo()
    if kind == "checkpoint" and nth == 1:
        assert not partial.exists() and "nothing kept" in msg
        return
    with archive.h5py.File(partial) as h:  # the last good checkpoint
        done = int(h["checkpoint"].attrs["done"])
    assert done == (3 * (nth - 1) if kind == "checkpoint" else 60), msg
    rc, _, err = cli(capsys, *resume_args(err))
    assert rc == 0, err
    same_result(out, reference)
    assert strays(tmp_path) == [] and not partial.exists()


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
def test_injected_fault_while_drawing_figures(tmp_path, monkeypatch, capsys, reference, code):
    """Figure writes fail from the nth on (a disk that filled up): exit 1, the archive
    complete, the earlier figures kept. The count is kept in a file, as the figures are
    written by child processes (a failed child's figure is drawn again by the caller,
    where the fault meets it too)."""
    import matplotlib.figure

    nth = random.Random(code).randint(1, 3)
    cfg = config(tmp_path)
    out = tmp_path / "a.h5"
    (tmp_path / "a_figures").mkdir()
    (tmp_path / "a_figures" / "earlier.png").write_bytes(b"earlier figure")
    real, counter = matplotlib.figure.Figure.savefig, tmp_path / "savefig-calls"

    def savefig(self, fname, *a, **kw):
        fd = os.open(counter, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
        os.write(fd, b".")
        os.close(fd)
        if counter.stat().st_size >= nth:
            raise OSError(code, os.strerror(code), str(fname))
        return real(self, fname, *a, **kw)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    rc, _, err = cli(capsys, "run", cfg, "--quiet", "--out", out)
    assert rc == 1, err
    msg = one_line(err)
    assert REASON[code] in msg and "figures" in msg and f"{out} is complete" in msg
    same_result(out, reference)
    assert [p.name for p in (tmp_path / "a_figures").iterdir()] == ["earlier.png"]
    counter.unlink()
    assert strays(tmp_path) == [] and not archive.partial_path(out).exists()


def test_unwritable_folder_is_refused_before_the_run(tmp_path, capsys):
    """EACCES through a read-only folder (root ignores permissions: skipped as root)."""
    if os.geteuid() == 0:
        pytest.skip("root ignores folder permissions")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        rc, _, err = cli(capsys, "run", config(tmp_path), "--quiet", "--out", ro / "a.h5")
        assert rc == 2
        assert "not writable" in one_line(err) and str(ro / "a.h5") in err
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)


@pytest.fixture
def small_fs(tmp_path):
    """A real 64 kB tmpfs (needs root and mount rights; skipped elsewhere)."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a file system needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)],
                       capture_output=True)  # fmt: skip
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_real_full_and_read_only_file_system(small_fs, tmp_path, monkeypatch, capsys, reference):
    cfg = config(tmp_path)
    out = small_fs / "a.h5"
    # the pre-flight estimate (archive + checkpoint) does not fit: refused before the run
    rc, _, err = cli(capsys, "run", cfg, "--quiet", "--no-figures", "--out", out)
    assert rc == 2 and "free" in one_line(err)
    assert os.listdir(small_fs) == []
    # past the estimate (as if it were wrong), the disk really fills up: exit 1, one line
    Usage = namedtuple("Usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: Usage(1 << 40, 0, 1 << 40))
    (small_fs / "pad").write_bytes(b"\0" * 40_000)
    rc, _, err = cli(capsys, "run", cfg, "--quiet", "--no-figures", "--out", out)
    assert rc == 1, err
    assert REASON[errno.ENOSPC] in one_line(err)
    assert strays(small_fs) == [] and not out.exists()
    # read-only: refused before the run
    monkeypatch.undo()
    (small_fs / "pad").unlink()
    subprocess.run(["mount", "-o", "remount,ro", str(small_fs)], check=True)
    rc, _, err = cli(capsys, "run", cfg, "--quiet", "--no-figures", "--out", out)
    assert rc == 2 and "Read-only file system" in one_line(err)
