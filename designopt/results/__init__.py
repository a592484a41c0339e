"""Typed results: one record class per archive kind (docs/archive.md says which record
holds what). ``from_tree`` picks the class from the tree's root attrs; the archive
(``designopt.io.archive.load`` / ``save``) stores a record's ``to_tree()``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from designopt.results.base import Record
from designopt.results.bench import BenchRecord
from designopt.results.front import FrontRecord
from designopt.results.ik import IKRecord
from designopt.results.run import CheckpointRecord, ReplayRecord, RunRecord, SweepRecord
from designopt.results.scan import ScanRecord, best_lines

KINDS: dict[str, type[Record]] = {"run": RunRecord, "scan": ScanRecord, "sweep": SweepRecord,
                                  "bench": BenchRecord, "ik": IKRecord, "front": FrontRecord}  # fmt: skip


def record_class(tree: Mapping[str, Any]) -> type[Record]:
    """The record class of an archive tree: its root attr ``kind``; an incomplete run is
    a checkpoint, a run without a ``problem`` group a replay."""
    attrs = tree.get("attrs", {})
    kind = str(attrs.get("kind", "run"))
    if "checkpoint" in tree and not attrs.get("complete", True):
        return CheckpointRecord
    if kind == "run" and "problem" not in tree:
        return ReplayRecord
    if kind not in KINDS:
        raise ValueError(f"unknown archive kind {kind!r}; known: {sorted(KINDS)}")
    return KINDS[kind]


def from_tree(tree: Mapping[str, Any], config: Any = None) -> Record:
    """The record of an archive tree (``archive.read``'s nested dict)."""
    return record_class(tree).from_tree(tree, config)


__all__ = ["KINDS", "BenchRecord", "CheckpointRecord", "FrontRecord", "IKRecord", "Record", "ReplayRecord",
           "RunRecord", "ScanRecord", "SweepRecord", "best_lines", "from_tree", "record_class"]  # fmt: skip
