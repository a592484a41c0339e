"""``designopt`` as a child process of the fault tests, writing phase marks (seconds since
start) to the file $FAULT_MARKS: ``handlers`` (signal handling installed), ``loop`` (the
first iteration boundary: compilation is over), ``write`` (the final archive's bytes are
being written; each write then sleeps $FAULT_WRITE_SLEEP s to widen the window);
$FAULT_CHUNK_SLEEP slows each optimizer chunk."""

import os
import sys
import time

t0 = time.monotonic()
marks = os.environ.get("FAULT_MARKS")


def mark(name: str) -> None:
    if marks:
        with open(marks, "a") as f:
            f.write(f"{name} {time.monotonic() - t0:.4f}\n")


from designopt.io import writer as output  # noqa: E402

install, set_phase = output.Session.install, output.Session.set_phase


def _install(self):
    install(self)
    mark("handlers")


def _set_phase(self, phase):
    if phase == "loop" and self.phase != "loop":
        mark("loop")
    set_phase(self, phase)


open_, write_ = output.OPS.open, output.OPS.write
final_fds: set[int] = set()


def _open(path, *a):
    fd = open_(path, *a)
    if ".partial" not in str(path) and ".tmp-" in str(path):
        final_fds.add(fd)
        mark("write")
    return fd


def _write(fd, data):
    if fd in final_fds:
        time.sleep(float(os.environ.get("FAULT_WRITE_SLEEP", "0")))
    return write_(fd, data)


output.Session.install = _install
output.Session.set_phase = _set_phase
output.OPS.open = staticmethod(_open)
output.OPS.write = staticmethod(_write)

from designopt.cli import commands as cli  # noqa: E402

progress = cli._progress


def _progress(quiet):
    """The CLI's bar, each chunk slowed by $FAULT_CHUNK_SLEEP s (a longer loop)."""
    bar, pause = progress(quiet), float(os.environ.get("FAULT_CHUNK_SLEEP", "0"))

    def slowed(total, desc):
        cm = bar(total, desc)
        update = cm.__enter__()

        def step(n):
            time.sleep(pause)
            update(n)

        class Slowed:
            def __enter__(self):
                return step

            def __exit__(self, *exc):
                return cm.__exit__(*exc)

        return Slowed()

    return slowed


cli._progress = _progress
main = cli.main

rc = main(sys.argv[1:])
mark("done")
sys.exit(rc)
