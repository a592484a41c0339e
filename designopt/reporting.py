"""What an archive shows beside it: its figures (PNG + PDF, drawn through the one writer)
and its interactive HTML page (``designopt report``, ``--html``)."""

from __future__ import annotations

from pathlib import Path

from designopt import archive, output
from designopt.results import Record


def draw_figures(path: Path, record: Record | None = None) -> list[Path]:
    """Draw the figures an archive supports beside it (run: the study's figures; sweep:
    final f per member; scan: a curve or heat map; bench: Fig. 10-11), through the one
    writer: drawn into a temporary folder, then moved into place (a disk fault: one
    WriteError line, the archive and any earlier figures kept)."""
    from designopt import figures

    path = Path(path)
    rec = archive.load(path) if record is None else record
    with output.session() as ses:
        if not ses.covers(path):
            output.claim(path, overwrite=True)  # lock: no run may write it meanwhile
        draw, folder, swap = figures.drawer(rec, path)

        def drawn(d: Path) -> list[Path]:
            with figures.parallel_saves():  # each figure written by a child process
                return draw(rec, d)

        return output.publish_figures(drawn, folder, swap=swap)


def write_html(path: Path, record: Record | None = None) -> Path:
    """The interactive report of an archive: ``<stem>.html`` beside it, one self-contained
    page (``designopt.figures.html``), with the workspace of a run's final design when
    the study draws one (``Study.cloud``)."""
    from designopt.figures import html
    from designopt.studies import STUDIES

    path = Path(path)
    rec = archive.load(path) if record is None else record
    out = path.with_suffix(".html")
    with output.session() as ses:
        if not ses.covers(out):
            output.claim(out, overwrite=True)
        from designopt.results import RunRecord

        st = STUDIES.get(rec.study)
        has = isinstance(rec, RunRecord) and st is not None and st.cloud is not None
        cloud = st.cloud(rec) if has else None  # a run's final design has one workspace
        extra = rec.units() if hasattr(rec, "units") else None  # a front's own objectives
        return html.write(rec.to_tree(), out, cloud=cloud, units=extra)
