"""The output policy (docs/faults.md): who writes (only process 0 of a multi-process
job), the checks of an output before any heavy work (a file, not a folder; its folder
made and writable; an existing archive refused unless ``overwrite``; free space against
the estimate), the lock beside it (``.<name>.lock``: a second process refuses at once, a
dead holder's lock is taken over with a warning) and the sweep of a killed writer's
temporary files. Use it through :mod:`designopt.output`.

Kept free of JAX and h5py so the CLI starts fast.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import sys
from pathlib import Path

from designopt.errors import ConfigError
from designopt.output_session import _remove, current

_WRITER = [True]


def set_writer(writes: bool) -> None:
    """Whether this process writes files (False: a non-zero process of a multi-process job)."""
    _WRITER[0] = bool(writes)


def writes() -> bool:
    """Whether this process writes files."""
    return _WRITER[0]


def reason(e: OSError) -> str:
    """The OS reason of an error, e.g. 'No space left on device (ENOSPC)'."""
    code = errno.errorcode.get(e.errno or 0)
    text = e.strerror or str(e) or type(e).__name__
    return f"{text} ({code})" if code else text


def human(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1000
    return f"{n:.3g} EB"  # pragma: no cover


class Lock:
    """``.<name>.lock`` beside an output: an ``flock`` held for the command's life, the
    file holding the holder's pid and command line. The kernel drops the flock when the
    holder dies, so a lock left by a killed process is taken over (with a warning)."""

    def __init__(self, path: Path) -> None:
        self.target = path
        self.path = path.with_name(f".{path.name}.lock")
        self.fd = -1

    def acquire(self) -> None:
        import fcntl

        for _ in range(10):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as e:
                raise ConfigError(f"output '{self.target}': cannot create its lock file "
                                  f"{self.path} ({reason(e)})") from None  # fmt: skip
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.pread(fd, 4096, 0).decode(errors="replace").strip() or "unknown"
                os.close(fd)
                raise ConfigError(f"output '{self.target}': in use by another designopt "
                                  f"process (pid {holder}); wait for it to end or choose "
                                  "another --out") from None  # fmt: skip
            try:  # the file may have been removed by its last holder after we opened it
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            stale = os.pread(fd, 4096, 0).decode(errors="replace").strip()
            if stale:
                print(f"designopt: warning: taking over the lock on '{self.target}' left by "
                      f"process {stale}, which is no longer running", file=sys.stderr)  # fmt: skip
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()} ({' '.join(sys.argv[:3])})\n".encode(), 0)
            self.fd = fd
            return
        raise ConfigError(f"output '{self.target}': could not take its lock {self.path}")

    def release(self) -> None:
        if self.fd < 0:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        os.close(self.fd)
        self.fd = -1


# ----------------------------------------------------------------------------- checks


def _first_existing(folder: Path) -> Path:
    p = folder
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check(path: Path, overwrite: bool = False, need_bytes: int = 0, make: bool = True) -> None:
    """The output checks of a command, without the lock: not a folder, folder creatable
    and writable, an existing archive refused unless ``overwrite``, enough free space for
    ``need_bytes``. With ``make=False`` (a dry run) nothing is created."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"output '{path}': is a folder; give a file name such as {path / 'a.h5'}")
    parent = path.parent if str(path.parent) else Path(".")
    if make:
        missing = []
        p = parent
        while not p.exists() and p != p.parent:
            missing.append(p)
            p = p.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise ConfigError(f"output '{path}': cannot create folder ({reason(e)})") from None
        ses = current()
        if ses is not None:
            ses.made += reversed(missing)
        probe = parent / f".{path.name}.probe-{os.getpid()}"
        try:
            fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            os.close(fd)
        except OSError as e:
            raise ConfigError(f"output '{path}': folder is not writable ({reason(e)})") from None
        finally:
            with contextlib.suppress(OSError):
                probe.unlink()
    else:
        base = _first_existing(parent)
        if not base.is_dir():
            raise ConfigError(f"output '{path}': cannot create folder ({base} is not a folder)")
        if not os.access(base, os.W_OK | os.X_OK):
            raise ConfigError(f"output '{path}': folder is not writable ({base})")
    if path.exists() and not overwrite:
        raise ConfigError(f"output '{path}': an archive is already there; give --overwrite "
                          "(or `overwrite: true` in the config) to replace it, or another "
                          "--out")  # fmt: skip
    if need_bytes:
        free = shutil.disk_usage(_first_existing(parent)).free
        if free < need_bytes:
            raise ConfigError(f"output '{path}': needs about {human(need_bytes)} free for the "
                              f"archive and its checkpoint; {human(free)} free there")  # fmt: skip


def claim(path: Path, overwrite: bool = False, need_bytes: int = 0) -> None:
    """Check an output (``check``) and lock it for the rest of the session (without a
    session, the checks only)."""
    path = Path(path)
    ses = current()
    if not writes():
        check(path, overwrite, need_bytes, make=False)
        if ses is not None:
            ses.covered.add(path)
        return
    if ses is None:
        check(path, overwrite, need_bytes)
        return
    if any(lk.target == path for lk in ses.locks):
        return
    check(path, overwrite=True)  # not a folder; the folder made and writable
    lk = Lock(path)
    lk.acquire()
    ses.locks.append(lk)
    ses.covered.add(path)
    _sweep_stale(path)
    check(path, overwrite=overwrite, need_bytes=need_bytes, make=False)


def pid_alive(pid: int) -> bool:
    """Whether a process with this id runs (on this machine)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _sweep_stale(path: Path) -> None:
    """Remove the temporary files of a killed writer of ``path`` (``.<stem>*.tmp-<pid>``,
    ``.old-<pid>``), which no one else may touch while we hold its lock."""
    parent = path.parent if str(path.parent) else Path(".")
    for p in parent.glob(f".{path.stem}*"):
        stem, sep, pid = p.name.rpartition("-")
        if sep and pid.isdigit() and stem.endswith((".tmp", ".old")) and not pid_alive(int(pid)):
            _remove(p)


def available_memory() -> int:
    """Bytes of memory available to this process now (MemAvailable, else free pages)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError):
        return 1 << 62
