"""The one writer (docs/faults.md): every file designopt writes (archives, checkpoints,
figures, HTML pages) goes through here, with one policy.

- Who writes: only process 0 of a multi-process job (docs/scaling.md); the others call
  ``set_writer(False)``, after which ``claim`` only checks (read-only, so every process
  refuses the same outputs), and ``write_file``, ``remove`` and ``publish_figures`` write
  nothing.
- ``check``/``claim`` check an output before any heavy work: a file, not a folder; its
  folder made and writable; an existing archive refused unless ``overwrite``; free space
  against the estimate; and the lock beside it (``.<name>.lock`` holding the pid: a
  second process refuses at once, a dead holder's lock is taken over with a warning).
- ``write_file`` writes bytes atomically (a temporary file beside the target, fsync,
  rename); an ``OSError`` becomes a one-line :class:`WriteError` naming the path and the
  OS reason (exit 1), and the temporary file is removed. ``publish_figures`` draws into a
  temporary folder and moves the result into place.
- ``session(signals=True)`` (the CLI): what the command in flight has written and holds
  (temporary files, locks, folders made), and its stops: SIGINT, SIGTERM and SIGHUP
  handled alike, and the time limit (``--max-minutes``). A run in its optimisation loop
  stops at the next iteration boundary and writes its checkpoint; anywhere else a
  watcher thread stops the process at once, keeping the last checkpoint; temporary files
  and locks are removed either way.

Kept free of JAX and h5py so the CLI starts fast.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from designopt.core.errors import ConfigError, Interrupted, WriteError

# ------------------------------------------------------------ who writes, checks, lock

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


# ------------------------------------------------------------------- the session

GRACE_S = {"loop": 5.0, "prompt": 0.25}
"""How long a stop request waits for the main thread (in the optimisation loop: for the
next iteration boundary; elsewhere: for Python code to notice) before the watcher thread
stops the process itself, with the newest checkpoint written."""

EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGHUP: 143}
TIME_LIMIT = -1  # a stop request from --max-minutes (exit 143, like a scheduler's SIGTERM)


class Session:
    """What the command in flight has written, holds and is asked to do; one per process.

    ``io`` serialises writes with the signal watcher; ``temps`` and ``locks`` are removed
    at the end (and when the watcher stops the process). ``phase`` is ``"loop"`` while the
    optimiser will reach an iteration boundary soon (a stop then waits for it), else
    ``"prompt"``. ``flush`` writes the newest checkpoint not yet on disk; ``kept()``
    describes what an interruption keeps and how to resume.
    """

    def __init__(self) -> None:
        self.io = threading.RLock()
        self.cond = threading.Condition()
        self.temps: set[Path] = set()
        self.locks: list[Lock] = []
        self.made: list[Path] = []
        self.covered: set[Path] = set()
        self.phase = "prompt"
        self.busy = 0
        self.stop = threading.Event()
        self.signum: int | None = None
        self.handled = False
        self.deadline: float | None = None
        self.max_minutes: float | None = None
        self.flush: Callable[[], None] | None = None
        self.kept: Callable[[], str] = lambda: "nothing written"
        self.exit: Callable[[int], None] = os._exit
        self.t0 = time.monotonic()  # the command's start: --max-minutes counts from here
        self._wake: tuple[int, int] | None = None
        self._thread: threading.Thread | None = None
        self._saved: dict[int, object] = {}
        self._saved_fd = -1

    def covers(self, path: str | Path) -> bool:
        """Whether this command has claimed ``path`` (checked and locked it)."""
        return Path(path) in self.covered

    # -- stop requests
    def set_deadline(self, minutes: float | None) -> None:
        """Stop cleanly ``minutes`` after the command started."""
        self.max_minutes = minutes
        self.deadline = None if minutes is None else self.t0 + 60 * minutes
        self._poke()

    def stop_requested(self) -> bool:
        if (
            self.deadline is not None
            and time.monotonic() >= self.deadline
            and not self.stop.is_set()
        ):
            self.signum = TIME_LIMIT
            self.stop.set()
        return self.stop.is_set()

    @contextlib.contextmanager
    def writing(self) -> Iterator[None]:
        """Hold the writer's lock: a stop waits until the block is done."""
        with self.io:
            self.busy += 1
            try:
                yield
            finally:
                self.busy -= 1

    def _on_signal(self, signum: int, frame: object) -> None:
        """The Python-level handler (main thread): record the request. The loop meets it
        at its next iteration boundary; elsewhere the watcher thread stops the process
        (``os._exit`` after cleaning up: no interpreter shutdown amid JAX's threads)."""
        self.request(signum)

    def request(self, signum: int) -> None:
        """Ask the command to stop (a signal's number; the first request counts)."""
        with self.cond:
            if not self.stop.is_set():
                self.signum = signum
                self.stop.set()

    def set_phase(self, phase: str) -> None:
        with self.cond:
            self.phase = phase
            self.cond.notify_all()

    def code(self) -> int:
        if self.signum is None:
            return 130  # KeyboardInterrupt without a handler (library use)
        return EXIT_CODES.get(self.signum, 143)  # type: ignore[arg-type]

    def what(self) -> str:
        if self.signum == TIME_LIMIT:
            return f"stopped: the time limit (--max-minutes {self.max_minutes:g}) was reached"
        return f"interrupted ({signal.Signals(self.signum).name})" if self.signum else "interrupted"

    def interrupted(self, kept: str | None = None) -> Interrupted:
        """The main thread takes the stop over: the watcher leaves it alone."""
        with self.cond:
            self.handled = True
            self.cond.notify_all()
        return Interrupted(f"{self.what()}; {kept or self.kept()}", self.code())

    # -- signals
    def install(self) -> None:
        """Handle SIGINT, SIGTERM and SIGHUP (main thread only); start the watcher."""
        r, w = os.pipe()
        os.set_blocking(w, False)
        self._wake = (r, w)
        for s in EXIT_CODES:
            self._saved[s] = signal.signal(s, self._on_signal)
        self._saved_fd = signal.set_wakeup_fd(w)
        self._thread = threading.Thread(target=self._watch, name="designopt-signals", daemon=True)
        self._thread.start()

    def uninstall(self) -> None:
        if self._wake is None:
            return
        signal.set_wakeup_fd(self._saved_fd)
        for s, h in self._saved.items():
            signal.signal(s, h)  # type: ignore[arg-type]
        r, w = self._wake
        self._wake = None
        with self.cond:
            self.handled = True
            self.cond.notify_all()
        os.write(w, b"\0")
        if self._thread is not None:
            self._thread.join(timeout=5)
        os.close(r)
        os.close(w)

    def _poke(self) -> None:
        if self._wake is not None:
            with contextlib.suppress(OSError):
                os.write(self._wake[1], b"\xff")  # not a signal number

    def _watch(self) -> None:
        r = self._wake[0]  # type: ignore[index]
        while True:
            timeout = None
            if self.deadline is not None and not self.stop.is_set():
                timeout = max(0.0, self.deadline - time.monotonic())
            try:
                ready, _, _ = select.select([r], [], [], timeout)
                data = os.read(r, 64) if ready else b""
            except OSError:
                return
            if b"\0" in data or self._wake is None:
                return
            sigs = [b for b in data if b in (int(s) for s in EXIT_CODES)]
            if sigs:
                self.request(sigs[0])
            elif not self.stop_requested():
                continue
            end = time.monotonic() + GRACE_S["loop" if self.phase == "loop" else "prompt"]
            with self.cond:
                while not self.handled and time.monotonic() < end:
                    self.cond.wait(end - time.monotonic())
                if self.handled:
                    continue
            self._abort()

    def _abort(self) -> None:
        """Stop the process now (from the watcher thread): newest checkpoint written,
        temporary files and locks removed, one line, exit 130 or 143."""
        with self.writing():
            if self.handled:
                return
            msg = None
            if self.flush is not None:
                try:
                    self.flush()
                except WriteError as e:
                    msg = f"designopt: error: {e}"
            if msg is None:
                msg = f"designopt: {self.what()}; {self.kept()}"
            self.cleanup()
            with contextlib.suppress(Exception):
                sys.stdout.flush()
            os.write(2, (msg + "\n").encode())
            self.exit(self.code())

    def cleanup(self, failed: bool = False) -> None:
        """Remove temporary files, release locks; after a failure, remove the folders
        this command made if they are still empty."""
        for t in list(self.temps):
            _remove(t)
        self.temps.clear()
        for lk in self.locks:
            lk.release()
        self.locks.clear()
        self.covered.clear()
        if failed:
            for d in reversed(self.made):
                with contextlib.suppress(OSError):
                    d.rmdir()
        self.made.clear()


_ACTIVE: list[Session] = []


def current() -> Session | None:
    """The session of the command in flight, if any."""
    return _ACTIVE[-1] if _ACTIVE else None


@contextlib.contextmanager
def session(signals: bool = False) -> Iterator[Session]:
    """The writer's session: reuses the one in flight, else opens one (with ``signals``,
    installs the stop handling; main thread only). On exit: temporary files and locks
    removed; after an error, empty folders this command made are removed too."""
    if _ACTIVE:
        yield _ACTIVE[-1]
        return
    ses = Session()
    _ACTIVE.append(ses)
    if signals and threading.current_thread() is threading.main_thread():
        ses.install()
    failed = True
    try:
        yield ses
        failed = False
    finally:
        ses.uninstall()
        with ses.writing():
            ses.cleanup(failed)
        _ACTIVE.remove(ses)


def _remove(p: Path) -> None:
    with contextlib.suppress(OSError):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)


# ----------------------------------------------------------------------- writing

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


def discard(path: Path) -> None:
    """Remove a file or a folder of files (what was derived from a replaced archive)
    under the writer's lock; nothing there, nothing done. OSError → WriteError."""
    path = Path(path)
    if not writes() or not (path.exists() or path.is_symlink()):
        return
    with session() as ses, ses.writing():
        try:
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink(missing_ok=True)
        except OSError as e:
            raise WriteError(f"{e.filename or path}: cannot remove a stale file of the "
                             f"replaced archive: {reason(e)}") from None


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
