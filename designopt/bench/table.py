"""What both benchmark suites share: the rank tests of every entry against the reference
entry (Mann-Whitney U, Holm-corrected) and the plain-text table they print."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from designopt.numerics.statistics import holm, mann_whitney_u


def u_tests(rows: dict[str, dict[str, Any]], samples: Mapping[str, Any], reference: str) -> None:
    """Add ``U``, ``p`` and ``p_holm`` (the U test of each entry's ``samples`` against the
    reference entry's, Holm over the entries) to every row but the reference's."""
    others = [v for v in samples if v != reference]
    if reference not in samples or not others:
        return
    tests = [mann_whitney_u(samples[v], samples[reference]) for v in others]
    adj = holm(np.array([p for _, p in tests]))
    for v, (u, p), pa in zip(others, tests, adj, strict=True):
        rows[v] |= {"U": u, "p": p, "p_holm": float(pa)}


def format_rows(head: str, rows: Mapping[str, Mapping[str, Any]],
                columns: Sequence[tuple]) -> str:  # fmt: skip
    """``head``, a header row and one row per entry: each column ``(title, width, format)``
    or ``(title, width, format, row key)`` (the key defaults to the title; format ``%``
    prints a fraction as a whole percentage), then the Holm-corrected p-value (``ref`` for
    the reference entry)."""
    w = max(8, *(len(v) + 1 for v in rows))
    title = f"{'entry':<{w}}" + "".join(f"{c[0]:>{c[1]}}" for c in columns) + f"{'p (Holm)':>10}"
    lines = [head, title]
    for v, r in rows.items():
        cells = []
        for c in columns:
            x = r[c[3] if len(c) > 3 else c[0]]
            cells.append(f"{100 * x:>{c[1] - 1}.0f}%" if c[2] == "%" else f"{x:>{c[1]}{c[2]}}")
        p = f"{r['p_holm']:.1e}" if "p_holm" in r else "ref"
        lines.append(f"{v:<{w}}" + "".join(cells) + f"{p:>10}")
    return "\n".join(lines)
