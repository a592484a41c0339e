"""Checkpoints of a run in progress (docs/faults.md): the ``Checkpointer`` owns the
partial archive ``<out>.partial.h5``, the cadence (every ``checkpoint_every_s`` and when
stopped), and the text saying what is kept; ``load`` reads a checkpoint back for
``--resume`` after checking it belongs to the same config and seed."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from designopt.core.errors import ConfigError, WriteError
from designopt.io import archive, writer
from designopt.results import CheckpointRecord, Record


def resume_key(cfg: Any) -> str:
    """What a checkpoint must match to be resumed: the config without its control keys
    (output, overwrite, max_minutes, ...), which a resumed run may change."""
    return cfg.model_dump_json(by_alias=True, exclude=set(cfg.CONTROL_KEYS))


def load(partial: Path, resolved: str) -> Any:
    """The optimizer ``Checkpoint`` kept in ``partial`` (ConfigError if absent, unreadable
    or of another config)."""
    if not partial.is_file():
        raise ConfigError(f"{partial}: no interrupted run to resume")
    try:
        rec = archive.load(partial)
    except ConfigError as e:
        raise ConfigError(f"{partial}: not a readable checkpoint ({e})") from None
    if not isinstance(rec, CheckpointRecord):
        raise ConfigError(f"{partial}: not a readable checkpoint (a {rec.kind} archive)")
    stored = rec.attrs.get("resume_key")  # JSON: read back decoded
    if (json.loads(stored) if isinstance(stored, str) else stored) != json.loads(resolved):
        raise ConfigError(f"{partial}: the interrupted run used a different config or seed; "
                          "run without --resume to start afresh")  # fmt: skip
    try:
        return rec.checkpoint()
    except KeyError as e:
        raise ConfigError(f"{partial}: not a readable checkpoint (missing {e})") from None


class Checkpointer:
    """The optimizer's ``checkpoint`` callback for one run writing to ``out``: keeps the
    latest state, writes it to the partial archive every ``every_s`` seconds, and on a
    stop request (signal, time limit) writes it and raises ``Interrupted`` saying what is
    kept and the command that resumes (``hint`` + ``--resume``)."""

    def __init__(self, out: Path, attrs: dict[str, Any], n_iters: int, every_s: float,
                 hint: str, ses: writer.Session, resumed: Any = None) -> None:  # fmt: skip
        self.partial = archive.partial_path(out)
        self.attrs, self.n_iters, self.every_s, self.hint, self.ses = (
            attrs, n_iters, every_s, hint, ses)  # fmt: skip
        self.latest = resumed
        self.written = resumed.done if resumed is not None else -1
        self.at = time.monotonic()
        ses.covered.add(self.partial)
        ses.flush, ses.kept = self.flush, self.kept

    def write(self, c: Any) -> None:
        tree = {"checkpoint": {"state": c.state, "history": c.history,
                               "history_x": c.history_x, "attrs": {"done": c.done}}}  # fmt: skip
        rec = Record(dict(self.attrs), tree)
        try:
            archive.save(self.partial, rec, complete=False)
        except WriteError as e:
            raise WriteError(f"{e}; {self.kept(last_good=True)}") from None
        self.written, self.at = c.done, time.monotonic()

    def flush(self) -> None:
        """Write the latest state if it is newer than the last one written."""
        c = self.latest
        if c is not None and c.done > self.written:
            self.write(c)

    def kept(self, last_good: bool = False) -> str:
        """What a stop now leaves behind, and how to resume."""
        if self.written < 0 or not self.partial.is_file():
            return "nothing kept" if last_good else "nothing written"
        part = "the last good checkpoint" if last_good else "finished part"
        return (f"{part} ({self.written} of {self.n_iters} iterations) kept in "
                f"{self.partial}; resume with `{self.hint} --resume`")  # fmt: skip

    def __call__(self, c: Any) -> None:
        self.latest = c
        self.ses.set_phase("loop")
        self.stop_if_requested()
        if time.monotonic() - self.at >= self.every_s:
            self.write(c)

    def stop_if_requested(self) -> None:
        if self.ses.stop_requested():
            self.stop()

    def stop(self, cause: BaseException | None = None) -> None:
        """Write what is done and raise ``Interrupted``."""
        with self.ses.writing():
            self.flush()
            raise self.ses.interrupted(self.kept()) from cause

    def done(self, out: Path) -> None:
        """The final archive is in place: drop the partial one."""
        writer.remove(self.partial)
        self.ses.flush = None
        self.ses.kept = lambda: (
            f"the archive {out} is complete (`designopt report {out}` draws its figures)"
        )

    def discard(self) -> None:
        writer.remove(self.partial)
