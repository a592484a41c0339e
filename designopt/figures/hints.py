"""What a figure may know of a study, passed in by the caller (the application layer looks the
study up; this package reaches none): units, the summary indices drawn first, success
rates, indices undefined where another is zero, and panels of indices drawn together."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Hints:
    """``units`` {name: unit}; ``summary`` the study's summary indices; ``RATES`` indices
    that are success rates (clipped to [0, 1], Wilson band); ``UNDEFINED_WHEN_ZERO``
    {index: index} not drawn where the other is 0; ``SCAN_PANELS`` {panel title:
    indices drawn together}. The upper-case names are those a study's ``figures`` module
    declares."""

    units: Mapping[str, str] = field(default_factory=dict)
    summary: tuple[str, ...] = ()
    RATES: tuple[str, ...] = ()  # noqa: N815
    UNDEFINED_WHEN_ZERO: Mapping[str, str] = field(default_factory=dict)  # noqa: N815
    SCAN_PANELS: Mapping[str, tuple[str, ...]] = field(default_factory=dict)  # noqa: N815

    @classmethod
    def of(cls, units: Mapping[str, str], summary: tuple[str, ...], module: Any = None) -> Hints:
        """Hints from a study's units, summary and its figures module (or None)."""
        return cls(dict(units), tuple(summary), tuple(getattr(module, "RATES", ())),
                   dict(getattr(module, "UNDEFINED_WHEN_ZERO", {})),
                   dict(getattr(module, "SCAN_PANELS", {})))  # fmt: skip


NONE = Hints()
"""No hints: the figure draws with generic labels."""
