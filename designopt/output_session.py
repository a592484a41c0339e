"""The writer's session (docs/faults.md): what the command in flight has written and
holds (temporary files, locks, folders made), and its stops: SIGINT, SIGTERM and SIGHUP
handled alike, and the time limit (``--max-minutes``). A run in its optimisation loop
stops at the next iteration boundary and writes its checkpoint; anywhere else a watcher
thread stops the process at once, keeping the last checkpoint. Use it through
:mod:`designopt.output`.

Kept free of JAX and h5py so the CLI starts fast.
"""

from __future__ import annotations

import contextlib
import os
import select
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from designopt.errors import Interrupted, WriteError

if TYPE_CHECKING:
    from designopt.output_policy import Lock

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
