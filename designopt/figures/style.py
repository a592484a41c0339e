"""The one figure style every study uses (docs/figures.md).

- Axis labels carry a unit: ``label("c", "mm")`` → ``"c [mm]"``; a dimensionless quantity
  is marked ``[-]`` (:data:`DIMENSIONLESS`), so a label without a unit is a bug the figure
  test catches. A categorical axis (optimizers, sweep members) is labelled
  ``"<what> (category)"``.
- Panels meant to be compared share one colour scale: :func:`shared_scale` sets one norm
  on all their mappables and records the group on the figure (``fig.designopt_shared``),
  where the figure test checks it.
- Monte-Carlo values get ± 2 SE bands (:func:`band`); bounded rates are clipped to [0, 1]
  with a Wilson score interval (:func:`rate_band`); log axes are chosen from the data's
  range (:func:`auto_log`).
- Figures use constrained layout (:func:`figure`, :func:`subplots`), so no label is clipped;
  a figure drawn on every run whose labels are known in advance may use :func:`grid`
  instead (margins in inches, laid out once: constrained layout measures every tick
  label again at each draw, a third of a map figure's drawing time). The figure test
  checks both for clipping and overlaps.
- Maps hold the other joints at a stated configuration: :func:`held_text` writes it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from designopt.figures.canvas import plt

DIMENSIONLESS = "-"
"""The unit of a dimensionless quantity; written ``[-]`` on an axis."""

Z_SE = 2.0
"""Bands are ± Z_SE standard errors (about 95 %); a Wilson interval uses the same z."""

LOG_RATIO = 100.0
"""An axis is logarithmic when all its values are > 0 and max/min exceeds this."""

INDEX_UNITS: dict[str, str] = {
    "f": DIMENSIONLESS,
    "violation": DIMENSIONLESS,
}
"""Units of names every study shares (a study's ``units`` overrides them)."""


def label(name: str, unit: str | None) -> str:
    """``name [unit]``; ``[-]`` for a dimensionless (``"-"`` or ``""``) unit."""
    u = unit if unit not in (None, "") else DIMENSIONLESS
    return f"{name} [{u}]"


def unit_of(name: str, units: Mapping[str, str]) -> str:
    """The unit of ``name`` from ``units`` (then :data:`INDEX_UNITS`); dimensionless
    when neither names it."""
    return units.get(name, INDEX_UNITS.get(name, DIMENSIONLESS))


def figure(**kw: Any) -> plt.Figure:
    """A figure with constrained layout."""
    return plt.figure(layout="constrained", **kw)


def grid(nrows: int, ncols: int, figsize: tuple[float, float],
         margins: tuple[float, float, float, float] = (0.75, 0.2, 0.55, 0.6),
         gaps: tuple[float, float] = (0.8, 0.8), colorbar: bool = False):  # fmt: skip
    """A figure of nrows × ncols axes on a fixed grid: ``margins`` (left, right, bottom,
    top) and ``gaps`` (between columns, between rows) in inches, so they hold for any
    figure size; ``colorbar``: a colour-bar axes in the right margin (give it ≥ 1.1 in).
    Returns (fig, axes (nrows, ncols)[, cax])."""
    W, H = figsize
    left, right, bottom, top = margins
    wg, hg = gaps
    aw = (W - left - right - (ncols - 1) * wg) / ncols
    ah = (H - bottom - top - (nrows - 1) * hg) / nrows
    fig = plt.figure(figsize=figsize)
    gs = fig.add_gridspec(nrows, ncols, left=left / W, right=1 - right / W, bottom=bottom / H,
                          top=1 - top / H, wspace=wg / aw, hspace=hg / ah)  # fmt: skip
    axes = gs.subplots(squeeze=False)
    if not colorbar:
        return fig, axes
    span = (H - bottom - top) * 0.8
    cax = fig.add_axes(((W - right + 0.3) / W, (bottom + (H - bottom - top - span) / 2) / H,
                        0.18 / W, span / H))  # fmt: skip
    return fig, axes, cax


def subplots(*args: Any, **kw: Any):
    """``plt.subplots`` with constrained layout."""
    return plt.subplots(*args, layout="constrained", **kw)


def shared_scale(fig: plt.Figure, mappables: Sequence[Any], vmin: float | None = None,
                 vmax: float | None = None, log: bool = False) -> tuple[float, float]:  # fmt: skip
    """Give ``mappables`` one colour scale (the range of all their data unless given) and
    record them as a group meant to be compared; returns (vmin, vmax)."""
    data = [np.asarray(m.get_array(), np.float64).ravel() for m in mappables]
    allv = np.concatenate([d[np.isfinite(d)] for d in data]) if data else np.zeros(1)
    lo = float(np.min(allv)) if vmin is None and allv.size else vmin
    hi = float(np.max(allv)) if vmax is None and allv.size else vmax
    lo, hi = (0.0, 1.0) if lo is None or hi is None else (lo, hi)
    if hi <= lo:
        hi = lo + max(abs(lo), 1.0) * 1e-9
    for m in mappables:
        m.set_clim(lo, hi)
    groups = getattr(fig, "designopt_shared", [])
    groups.append(list(mappables))
    fig.designopt_shared = groups
    return lo, hi


def band(ax: plt.Axes, x: np.ndarray, y: np.ndarray, se: np.ndarray | None,
         color: Any = None, **kw: Any):  # fmt: skip
    """Plot y with a ± :data:`Z_SE` SE band (none when ``se`` is None); returns the line."""
    (line,) = ax.plot(x, y, color=color, **kw)
    if se is not None:
        se = np.asarray(se, np.float64)
        ax.fill_between(x, y - Z_SE * se, y + Z_SE * se, color=line.get_color(), alpha=0.25,
                        lw=0)  # fmt: skip
    return line


def wilson(p: np.ndarray, n: float | np.ndarray, z: float = Z_SE) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval (lo, hi) of a success rate p from n trials; within [0, 1]
    and of non-zero width at p = 0 or 1."""
    p = np.clip(np.asarray(p, np.float64), 0.0, 1.0)
    n = np.maximum(np.asarray(n, np.float64), 1.0)
    d = 1 + z**2 / n
    mid = (p + z**2 / (2 * n)) / d
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / d
    return np.clip(mid - half, 0, 1), np.clip(mid + half, 0, 1)


def trials(p: np.ndarray, se: np.ndarray) -> float | None:
    """The number of trials n behind binomial rates p with standard errors se
    (n = p(1 − p)/se², the median over 0 < p < 1); None when no p is inside (0, 1)."""
    p, se = np.ravel(np.asarray(p, np.float64)), np.ravel(np.asarray(se, np.float64))
    ok = (p > 0) & (p < 1) & (se > 0)
    return float(np.median(p[ok] * (1 - p[ok]) / se[ok] ** 2)) if ok.any() else None


def rate_band(ax: plt.Axes, x: np.ndarray, p: np.ndarray, se: np.ndarray | None = None,
              n: float | None = None, **kw: Any):  # fmt: skip
    """A success rate in [0, 1]: the line clipped to [0, 1] and its Wilson interval (n
    given, or from :func:`trials`; a clipped ± 2 SE band when neither is known)."""
    p = np.clip(np.asarray(p, np.float64), 0.0, 1.0)
    (line,) = ax.plot(x, p, **kw)
    n = n if n is not None else (trials(p, se) if se is not None else None)
    if n is not None:
        lo, hi = wilson(p, n)
    elif se is not None:
        lo, hi = np.clip(p - Z_SE * se, 0, 1), np.clip(p + Z_SE * se, 0, 1)
    else:
        return line
    ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.25, lw=0)
    ax.set_ylim(min(-0.02, float(np.min(lo)) - 0.02), 1.02)
    return line


def auto_log(ax: plt.Axes, values: Iterable[np.ndarray] | np.ndarray, axis: str = "y") -> bool:
    """Make ``axis`` logarithmic when every value is > 0 and max/min > :data:`LOG_RATIO`;
    returns whether it did."""
    v = np.concatenate([np.ravel(np.asarray(a, np.float64)) for a in np.atleast_1d(values)]) \
        if not isinstance(values, np.ndarray) else np.ravel(values)  # fmt: skip
    v = v[np.isfinite(v)]
    log = bool(v.size and np.all(v > 0) and v.max() / v.min() > LOG_RATIO)
    if log:
        (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
    return log


def held_text(held: Mapping[str, str]) -> str:
    """``"held at q3 = 45 deg, q5 = -45 deg"``: where a map holds the other joints."""
    return "held at " + ", ".join(f"{k} = {v}" for k, v in held.items()) if held else ""
