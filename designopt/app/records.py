"""Records bound to what the application layer knows: the typed config (validated once, when first
asked for) and the study's units, summary indices and own summary lines. Records
(``designopt.results``) are plain data and import no study; every record the application layer
makes or reads carries this binder, so ``record.config`` and the summaries work."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt.io import archive
from designopt.results import BenchRecord, Record


def binder(rec: Record) -> tuple[Any, dict[str, Any]]:
    """(typed config, hints) of a record: its own config when it was made with one, else
    the archived resolved config validated (a ``BenchConfig`` for a benchmark); hints from
    the study registry (``units``, ``summary``, ``extra_lines`` of the final design) or,
    for a benchmark, the suite (``case_names``)."""
    from designopt.app.config import validate

    cfg = rec._config
    if isinstance(rec, BenchRecord):
        from designopt.bench.suite import BenchConfig, case_names

        if cfg is None:
            cfg = validate(rec.raw_config(), f"archive ({rec.kind})", BenchConfig)
        return cfg, {"case_names": case_names(cfg)}
    if cfg is None:
        folder = rec.attrs.get("config_dir") or None
        # the study's checks passed when the run was made: not again (they compile
        # programs and build distance grids; ``show`` needs the typed config)
        cfg = validate(rec.raw_config(), f"archive ({rec.kind})", folder=folder, checks=False)
    hints = study_hints(cfg, rec.groups.get("final"), rec.groups.get("front"))
    fin = rec.groups.get("final")
    if isinstance(fin, dict) and str(fin.get("attrs", {}).get("samples", "")) == "fresh":
        hints["final_stream"] = lambda: _stream(cfg, rec, "final")
    if isinstance(rec.groups.get("front"), dict):
        hints["front_stream"] = lambda: _stream(cfg, rec, "front")
    return cfg, hints


def _stream(cfg: Any, rec: Record, section: str) -> tuple[Any, dict[str, Any]]:
    """(study settings, named keys) of the samples a run's ``final/`` (a front's
    ``front/``) values are on: the fresh ``section`` stream with ``<section>.n_samples``
    (``app.rescoring.stream``)."""
    from designopt.app import rescoring
    from designopt.studies import get

    fr = rescoring.stream(cfg, get(cfg.study.name), rec.keys(), section, f"archive ({rec.kind})")
    return fr.cfg.study, fr.keys


def study_hints(cfg: Any, final: Any = None, front: Any = None) -> dict[str, Any]:
    """The study's units and summary indices for ``cfg``, and its own summary lines of a
    final design (``final``: the record's ``final`` group) or, as ``design_lines``, of
    each design of a front (``front``: its ``front`` group) that archives the study's
    placement (its attr ``placement``)."""
    from designopt.studies import get

    st = get(cfg.study.name)
    out: dict[str, Any] = {"units": dict(st.units(cfg.study)),
                           "summary": tuple(st.summary(cfg.study))}  # fmt: skip
    if final is not None:
        out["extra_lines"] = list(st.extra_lines(cfg.study, final))
    placed = [] if front is None else list(front.get("attrs", {}).get("placement", []) or [])
    if placed:
        n = len(front[placed[0]])
        out["design_lines"] = [list(st.extra_lines(cfg.study, {k: front[k][i] for k in placed}))
                               for i in range(n)]  # fmt: skip
    return out


def bind(rec: Record) -> Record:
    """``rec`` with the application layer's binder attached."""
    return rec.bind(binder)


def load(path: str | Path) -> Record:
    """The record an archive holds, bound (``designopt.load``)."""
    return bind(archive.load(path))
