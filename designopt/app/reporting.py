"""What an archive shows beside it: its figures (PNG + PDF, drawn through the one writer)
and its interactive HTML page (``designopt report``, ``--html``). The study is looked up
here, through the registry, and what the figures need of it is passed to them
(``designopt.figures.hints.Hints``): the figure toolkit reaches no study."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from designopt.app import records
from designopt.core.errors import ConfigError
from designopt.figures.hints import NONE, Hints
from designopt.io import writer
from designopt.results import (
    BenchRecord,
    FrontRecord,
    Record,
    ReplayRecord,
    RunRecord,
    ScanRecord,
    SweepRecord,
)
from designopt.studies import STUDIES, Study


def figures_module(st: Study) -> Any:
    """A study's figures module (its ``RATES``, ``UNDEFINED_WHEN_ZERO``, ``SCAN_PANELS``
    hints), found beside its ``figures`` hook; None when it has none."""
    home = st.figures.__module__  # the study package itself, or a module inside it
    for name in (home + ".figures", home.rsplit(".", 1)[0] + ".figures"):
        try:
            return importlib.import_module(name)
        except ImportError:
            continue
    return None


def hints(rec: Record) -> Hints:
    """What the figures of ``rec`` may know of its study (none for an unknown study or a
    config that no longer validates: the figures still draw, with generic labels)."""
    st = STUDIES.get(rec.study)
    if st is None:
        return NONE
    try:
        s = rec.config.study
    except (LookupError, ValueError, TypeError, AttributeError, ConfigError):
        return NONE
    return Hints.of(st.units(s), tuple(st.summary(s)), figures_module(st))


def drawer(rec: Record, path: Path) -> tuple[Callable[[Any, Path], list[Path]], Path, bool]:
    """What draws a record's figures: (draw(record, folder) -> paths, the folder,
    whether the folder is replaced whole). Runs: the study's figures (``Study.figures``)
    in ``<stem>_figures``; fronts, sweeps and scans: the generic ones there too;
    benchmarks: the PTPSO paper's figures beside the archive."""
    from designopt.figures import bench, front, scan, sweep

    path = Path(path)
    figs = path.parent / f"{path.stem}_figures"
    if isinstance(rec, BenchRecord):
        return bench.draw_record, path.parent, False
    if isinstance(rec, RunRecord | ReplayRecord):
        st = STUDIES.get(rec.study)
        if st is None:
            raise ConfigError(f"{path}: study {rec.study!r} is not registered in this process; "
                              f"known: {sorted(STUDIES)}")  # fmt: skip
        return st.figures, figs, True
    if isinstance(rec, FrontRecord):  # with the study's drawings of its chosen designs
        st = STUDIES.get(rec.study)
        hook = None if st is None else st.front_figures
        return (lambda r, d: front.draw(r, d, robot=hook)), figs, True
    if isinstance(rec, SweepRecord):
        return sweep.draw, figs, True
    if isinstance(rec, ScanRecord):
        h = hints(rec)
        return (lambda r, d: scan.draw(r, d, h)), figs, True
    raise ConfigError(f"{path}: archive kind {rec.kind!r} has no figures")


def draw_figures(path: Path, record: Record | None = None) -> list[Path]:
    """Draw the figures an archive supports beside it (run: the study's figures; sweep:
    final f per member; scan: a curve or heat map; bench: Fig. 10-11), through the one
    writer: drawn into a temporary folder, then moved into place (a disk fault: one
    WriteError line, the archive and any earlier figures kept)."""
    path = Path(path)
    rec = records.load(path) if record is None else record
    with writer.session() as ses:
        if not ses.covers(path):
            writer.claim(path, overwrite=True)  # lock: no run may write it meanwhile
        draw, folder, swap = drawer(rec, path)

        def drawn(d: Path) -> list[Path]:
            from designopt.figures import canvas  # matplotlib: only when figures are drawn

            with canvas.parallel_saves():  # each figure written by a child process
                return draw(rec, d)

        return writer.publish_figures(drawn, folder, swap=swap)


def write_html(path: Path, record: Record | None = None) -> Path:
    """The interactive report of an archive: ``<stem>.html`` beside it, one self-contained
    page (``designopt.figures.html``), with the workspace of a run's final design when
    the study draws one (``Study.cloud``) and the robot in 3-D (``Study.robot``)."""
    from designopt.figures import html

    path = Path(path)
    rec = records.load(path) if record is None else record
    out = path.with_suffix(".html")
    with writer.session() as ses:
        if not ses.covers(out):
            writer.claim(out, overwrite=True)
        st = STUDIES.get(rec.study)
        has = isinstance(rec, RunRecord) and st is not None and st.cloud is not None
        cloud = st.cloud(rec) if has else None  # a run's final design has one workspace
        extra = rec.units() if isinstance(rec, FrontRecord) else None  # a front's objectives
        draws = isinstance(rec, RunRecord | FrontRecord) and st is not None and st.robot is not None
        robot = st.robot(rec) if draws else None  # the robot in 3-D (a run's, a front's)
        return html.write(rec.to_tree(), out, cloud=cloud, units=extra, hints=hints(rec),
                          robot=robot)  # fmt: skip
