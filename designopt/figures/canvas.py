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
import os
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

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


class _Children:
    """Figures being written by forked children: (pid, figure, png, pdf, dpi, start)."""

    def __init__(self, workers: int) -> None:
        self.workers = max(1, workers)
        self.running: list[tuple[int, plt.Figure, Path, Path, int, float]] = []

    def submit(self, fig: plt.Figure, png: Path, pdf: Path, dpi: int) -> None:
        import signal

        while len(self.running) >= self.workers:
            self._reap(self.running[0])
        # JAX (and Python ≥ 3.12) warn that a fork beside threads may deadlock a child that
        # uses them; this one uses numpy and matplotlib only, JAX is idle meanwhile, and a
        # child stuck anyway is killed after CHILD_TIMEOUT and its figure drawn here.
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
            try:
                _write(fig, png, pdf, dpi)
            finally:
                plt.close(fig)
            return
        if pid == 0:  # the child: render, write, leave without running the caller's code
            code = 1
            try:
                _child_setup(block)
                signal.pthread_sigmask(signal.SIG_SETMASK, old)
                _write(fig, png, pdf, dpi)
                code = 0
            finally:
                os._exit(code)
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
        self.running.append((pid, fig, png, pdf, dpi, time.monotonic()))

    def _reap(self, job: tuple) -> None:
        """Wait for one child; a failed, killed or stuck one (or one that cannot be waited
        for): draw its figure here, so a disk fault raises its own OSError here."""
        pid, fig, png, pdf, dpi, t0 = job
        status = None
        try:
            while status is None:
                try:
                    done, st = os.waitpid(pid, os.WNOHANG)
                except ChildProcessError:  # already reaped elsewhere (SIGCHLD ignored)
                    done, st = pid, -1
                if done:
                    status = st
                elif time.monotonic() - t0 > CHILD_TIMEOUT:
                    _kill(pid)
                    status = -1
                else:
                    time.sleep(0.005)
            if status != 0 or not (png.exists() and pdf.exists()):
                _write(fig, png, pdf, dpi)
        finally:
            if status is None:  # interrupted while waiting
                _kill(pid)
            self.running.remove(job)
            plt.close(fig)

    def finish(self) -> None:
        while self.running:
            self._reap(self.running[0])

    def kill(self) -> None:
        for pid, fig, *_ in self.running:
            _kill(pid)
            plt.close(fig)
        self.running.clear()


def _kill(pid: int) -> None:
    with contextlib.suppress(OSError):
        os.kill(pid, 9)
        os.waitpid(pid, 0)


def _child_setup(signals: set) -> None:
    """In a figure's child: default signal handlers, no wake-up pipe of the caller's, and
    (Linux) SIGKILL when the caller dies, so no child outlives it (or its output lock)."""
    import signal

    with contextlib.suppress(ValueError, OSError):
        signal.set_wakeup_fd(-1)
    for sig in signals:
        signal.signal(sig, signal.SIG_DFL)
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
