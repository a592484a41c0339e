"""The one writer: every file designopt writes (archives, checkpoints, figures) goes
through here, with one policy (docs/faults.md).

- ``write_file`` writes bytes atomically (a temporary file beside the target, fsync,
  rename); an ``OSError`` becomes a one-line :class:`WriteError` naming the path and the
  OS reason (exit 1), and the temporary file is removed.
- ``claim`` checks an output before any heavy work: folder made and writable, a lock
  (``.<name>.lock`` holding the pid; a second process refuses at once, a dead holder's
  lock is taken over with a warning), an existing archive refused unless ``overwrite``,
  free space against the estimate.
- ``publish_figures`` draws into a temporary folder and moves the result into place.
- ``session(signals=True)`` (the CLI) handles SIGINT, SIGTERM and SIGHUP alike: a run in
  its optimisation loop stops at the next iteration boundary and writes its checkpoint;
  anywhere else (set-up, compilation, scoring) a watcher thread stops the process at once,
  keeping the last checkpoint; temporary files and locks are removed either way.

In a multi-process job (docs/scaling.md) only process 0 writes: the others call
``set_writer(False)``, after which ``claim`` only checks (read-only, so every process
refuses the same outputs), and ``write_file``, ``remove`` and ``publish_figures`` write
nothing.

This module holds the writing (``write_file``, ``remove``, ``publish_figures``); the
session and its stops live in :mod:`designopt.output_session`, who writes, the checks and
the lock in :mod:`designopt.output_policy`; every name stays importable from here.

Kept free of JAX and h5py so the CLI starts fast.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from designopt.errors import WriteError
from designopt.output_policy import (
    Lock,
    available_memory,
    check,
    claim,
    human,
    pid_alive,
    reason,
    set_writer,
    writes,
)
from designopt.output_session import (
    EXIT_CODES,
    GRACE_S,
    TIME_LIMIT,
    Session,
    _remove,
    current,
    session,
)

__all__ = [
    "EXIT_CODES",
    "GRACE_S",
    "OPS",
    "TIME_LIMIT",
    "Lock",
    "Session",
    "available_memory",
    "check",
    "claim",
    "current",
    "human",
    "pid_alive",
    "publish_figures",
    "reason",
    "remove",
    "session",
    "set_writer",
    "write_file",
    "writes",
]


class _Ops:
    """The file operations of the writer (the fault-injection tests patch these)."""

    open = staticmethod(os.open)
    write = staticmethod(os.write)
    fsync = staticmethod(os.fsync)
    close = staticmethod(os.close)
    replace = staticmethod(os.replace)
    mkdir = staticmethod(os.mkdir)


OPS = _Ops()


def write_file(path: str | Path, data: bytes, what: str = "archive") -> Path:
    """Write ``data`` to ``path`` atomically: a temporary file beside it, fsync, rename.
    WriteError (one line: path, OS reason) on any OSError; the old file, if any, is kept."""
    path = Path(path)
    if not writes():
        return path
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with session() as ses, ses.writing():
        ses.temps.add(tmp)
        try:
            fd = OPS.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                view = memoryview(data)
                while view:
                    n = OPS.write(fd, view[: 1 << 20])
                    view = view[n:]
                OPS.fsync(fd)
            finally:
                OPS.close(fd)
            OPS.replace(tmp, path)
        except OSError as e:
            raise WriteError(f"{path}: cannot write the {what}: {reason(e)}") from None
        finally:
            _remove(tmp)
            ses.temps.discard(tmp)
    return path


def remove(path: Path) -> None:
    """Remove a file (a finished run's checkpoint) under the writer's lock."""
    if not writes():
        return
    with session() as ses, ses.writing():
        path.unlink(missing_ok=True)


def publish_figures(
    draw: Callable[[Path], list[Path]], folder: Path, swap: bool = True
) -> list[Path]:
    """Draw figures into a temporary folder, then move them into ``folder``: ``swap``
    replaces the whole folder (a run's ``<stem>_figures``), else file by file (figures
    that live beside the archive). OSError → WriteError; the temporary folder removed."""
    folder = Path(folder)
    if not writes():
        return []
    tmp = folder.with_name(f".{folder.name}.tmp-{os.getpid()}")
    old = folder.with_name(f".{folder.name}.old-{os.getpid()}")
    with session() as ses:
        ses.temps |= {tmp, old}
        try:
            _remove(tmp)
            OPS.mkdir(tmp)
            drawn = [Path(p) for p in draw(tmp)]
            with ses.writing():
                if swap:
                    if folder.exists():
                        OPS.replace(folder, old)
                    OPS.replace(tmp, folder)
                else:
                    folder.mkdir(parents=True, exist_ok=True)
                    for p in drawn:
                        OPS.replace(p, folder / p.relative_to(tmp))
            return [folder / p.relative_to(tmp) for p in drawn]
        except OSError as e:
            where = e.filename or folder
            raise WriteError(f"{where}: cannot write the figures: {reason(e)}") from None
        finally:
            _remove(tmp)
            _remove(old)
            ses.temps -= {tmp, old}
