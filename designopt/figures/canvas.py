"""The canvas every figure is drawn on (matplotlib, Agg backend) and how it is written:
PNG and PDF beside an archive.

Drawing is kept cheap: each file is drawn once (the layout is the figure's own, no
``bbox_inches="tight"`` second pass), dense artists are rasterised in the PDF, PNGs are
written at ``DPI`` with fast compression, and axes titles are placed with ``y=1.0``
(otherwise matplotlib measures the tick labels at every draw to place them). Within
:func:`parallel_saves` (every figure the CLI draws) each figure is rendered in a forked
child process while the caller builds the next one, one child per CPU core.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import os
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

DPI = 110  # PNG resolution (dots per inch); rasterised artists in PDFs use the same
MAP_RESOLUTION = 121  # grid points per axis of the studies' index maps
RECORD: list[tuple[str, plt.Figure]] | None = None
"""When a list (the figure test sets it), :func:`save` appends (name, figure) and leaves
the figure open, so its axes can be walked after drawing."""


CHILD_TIMEOUT = 60.0
"""Seconds a figure's child process may take before it is killed and the figure drawn in
the calling process instead."""

CHILD_IDLE = 5.0
"""Seconds a figure's child may use no CPU at all, while the caller waits for it, before it
counts as stuck (a drawing child computes all the time; a deadlocked one sleeps)."""


@dataclasses.dataclass
class _Child:
    pid: int
    fig: plt.Figure
    png: Path
    pdf: Path
    dpi: int
    start: float
    stacks: IO[bytes]  # where the child writes its Python stack when asked (SIGUSR1)


class _Children:
    """Figures being written by forked children."""

    def __init__(self, workers: int) -> None:
        self.workers = max(1, workers)
        self.running: list[_Child] = []

    def submit(self, fig: plt.Figure, png: Path, pdf: Path, dpi: int) -> None:
        import signal

        while len(self.running) >= self.workers:
            self._reap(self.running[0])
        # JAX (and Python ≥ 3.12) warn that a fork beside threads may deadlock a child that
        # uses them (a lock another thread held at the fork); this one uses numpy and
        # matplotlib only (artists hold numpy data: matplotlib converts at creation). A
        # child stuck anyway is stopped (CHILD_IDLE, CHILD_TIMEOUT), its figure drawn
        # here, and a warning shows where it was stuck.
        stacks = tempfile.TemporaryFile()
        # Signals are blocked across the fork, so none runs the caller's code in the child.
        block = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
        old = signal.pthread_sigmask(signal.SIG_BLOCK, block)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                warnings.filterwarnings("ignore", r"os\.fork\(\) was called", RuntimeWarning)
                pid = os.fork()
        except OSError:  # no fork (memory, process limit): draw it here
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
            stacks.close()
            try:
                _write(fig, png, pdf, dpi)
            finally:
                plt.close(fig)
            return
        if pid == 0:  # the child: render, write, leave without running the caller's code
            code = 1
            try:
                _child_setup(block, stacks)
                signal.pthread_sigmask(signal.SIG_SETMASK, old)
                _write(fig, png, pdf, dpi)
                code = 0
            finally:
                os._exit(code)
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
        self.running.append(_Child(pid, fig, png, pdf, dpi, time.monotonic(), stacks))

    def _reap(self, job: _Child) -> None:
        """Wait for one child; a failed, killed or stuck one (or one that cannot be waited
        for): draw its figure here, so a disk fault raises its own OSError here."""
        status = None
        cpu, idle_since = None, time.monotonic()
        try:
            while status is None:
                try:
                    done, st = os.waitpid(job.pid, os.WNOHANG)
                except ChildProcessError:  # already reaped elsewhere (SIGCHLD ignored)
                    done, st = job.pid, -1
                now = time.monotonic()
                used = _cpu_ticks(job.pid)
                if used is None or used != cpu:
                    cpu, idle_since = used, now
                if done:
                    status = st
                elif now - job.start > CHILD_TIMEOUT or now - idle_since > CHILD_IDLE:
                    why = (f"used no CPU for {CHILD_IDLE:g} s" if now - job.start <= CHILD_TIMEOUT
                           else f"did not finish within {CHILD_TIMEOUT:g} s")  # fmt: skip
                    stack = _stack(job)
                    _kill(job.pid)
                    status = -1
                    print(f"warning: {job.png.name}: its drawing process {why}; stopped, and "
                          f"the figure drawn here{stack}", file=sys.stderr)
                else:
                    time.sleep(0.005)
            if status != 0 or not (job.png.exists() and job.pdf.exists()):
                _write(job.fig, job.png, job.pdf, job.dpi)
        finally:
            if status is None:  # interrupted while waiting
                _kill(job.pid)
            self.running.remove(job)
            job.stacks.close()
            plt.close(job.fig)

    def finish(self) -> None:
        while self.running:
            self._reap(self.running[0])

    def kill(self) -> None:
        for job in self.running:
            _kill(job.pid)
            job.stacks.close()
            plt.close(job.fig)
        self.running.clear()


def _cpu_ticks(pid: int) -> int | None:
    """The CPU time (user + system, clock ticks) process ``pid`` has used (None where
    /proc cannot say)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        return int(fields[11]) + int(fields[12])  # utime, stime (fields 14 and 15)
    except (OSError, IndexError, ValueError):
        return None


def _stack(job: _Child) -> str:
    """The stuck child's Python stack (faulthandler's, on SIGUSR1), innermost frames
    first, as lines to append to the warning ("" when it cannot be had)."""
    import signal

    try:
        os.kill(job.pid, signal.SIGUSR1)
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            job.stacks.seek(0)
            text = job.stacks.read().decode(errors="replace")
            if "File" in text and text.endswith("\n"):
                break
            time.sleep(0.02)
    except OSError:
        return ""
    frames = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("File")]
    return "".join(f"\n  {f}" for f in frames[:8])


def _kill(pid: int) -> None:
    with contextlib.suppress(OSError):
        os.kill(pid, 9)
        os.waitpid(pid, 0)


def _child_setup(signals: set, stacks: IO[bytes]) -> None:
    """In a figure's child: default signal handlers, no wake-up pipe of the caller's, its
    Python stack written to ``stacks`` on SIGUSR1 (what the caller reports when the
    child is stuck), and (Linux) SIGKILL when the caller dies, so no child outlives it
    (or its output lock)."""
    import faulthandler
    import signal

    with contextlib.suppress(ValueError, OSError):
        signal.set_wakeup_fd(-1)
    for sig in signals:
        signal.signal(sig, signal.SIG_DFL)
    with contextlib.suppress(Exception):
        faulthandler.register(signal.SIGUSR1, file=stacks, all_threads=True)
    with contextlib.suppress(Exception):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if os.getppid() == 1:  # the caller died before prctl
            os._exit(1)


_CHILDREN: contextvars.ContextVar[_Children | None] = contextvars.ContextVar(
    "designopt_figure_children", default=None
)


@contextlib.contextmanager
def parallel_saves(workers: int | None = None) -> Iterator[None]:
    """Within: :func:`save` hands each figure to a forked child process that writes its
    PNG and PDF, up to ``workers`` (default: the CPU cores available) at a time, while
    the caller goes on building the next figure; leaving waits for all of them. A child
    that fails or takes longer than :data:`CHILD_TIMEOUT` is replaced by drawing the
    figure here. Sequential where there is no ``os.fork`` (not Linux) or one core, and
    while :data:`RECORD` is set."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
    n = n if workers is None else workers
    if not hasattr(os, "fork") or not sys.platform.startswith("linux") or n < 2:
        yield
        return
    import matplotlib.backends.backend_pdf  # noqa: F401 (imported once, not in each child)

    kids = _Children(n)
    token = _CHILDREN.set(kids)
    try:
        yield
        kids.finish()
    finally:
        kids.kill()
        _CHILDREN.reset(token)


def _write(fig: plt.Figure, png: Path, pdf: Path, dpi: int) -> None:
    fig.savefig(png, dpi=dpi, pil_kwargs={"compress_level": 1})
    # the PNG's draw placed every axes: keep those positions for the PDF rather than
    # solving the constrained layout again (a third of the PDF's drawing time)
    fig.set_layout_engine("none")
    fig.savefig(pdf, dpi=dpi)


def save(fig: plt.Figure, folder: Path, name: str, dpi: int | None = None) -> list[Path]:
    """Save ``fig`` as ``folder/name.png`` and ``.pdf``, close it, return both paths
    (within :func:`parallel_saves`: written by a child process by the time it ends)."""
    folder.mkdir(parents=True, exist_ok=True)
    dpi = dpi or DPI
    png, pdf = folder / f"{name}.png", folder / f"{name}.pdf"
    kids = _CHILDREN.get()
    if kids is not None and RECORD is None:
        try:
            kids.submit(fig, png, pdf, dpi)  # may first finish an earlier figure (and fail)
        except BaseException:
            plt.close(fig)
            raise
        return [png, pdf]
    try:
        _write(fig, png, pdf, dpi)
    finally:
        if RECORD is not None:
            RECORD.append((name, fig))
        else:
            plt.close(fig)
    return [png, pdf]
