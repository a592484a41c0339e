"""Figures of a Pareto-front record (``study.objective.pareto``; docs/figures.md).

- ``front``: the re-scored front in the indices' own values (a ``max`` objective is not
  negated), ± 2 SE error bars in every objective, pairs whose order is ambiguous (within
  2 SE in some objective) joined by thin lines, designs dominated after re-scoring
  (rank > 0) and infeasible ones marked apart. Two objectives: one scatter; more: the
  pairwise projections (lower triangle), and for exactly three a 3-D scatter ``front_3d``.
- ``front_designs``: parallel coordinates of the front's designs, each variable scaled to
  its box and each objective to its range over the front, coloured by the first objective.
- ``front_indices``: every index of the study that is not an objective (the front's group
  holds them all, re-scored), one panel each against the first objective with ± 2 SE
  bars, marked as in ``front``: what the trade-off costs in what was not traded (a task
  front of GCI and length shows where the short arms stop reaching). Absent when every
  index is an objective.
- ``hypervolume``: per iteration, the hypervolume of the best front found so far (the
  non-dominated set of every design evaluated) of each run (thin) and their median
  (bold), the median of the populations' own hypervolume (dashed) and the re-scored
  front's.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D

from designopt.figures import style
from designopt.figures.canvas import plt, save
from designopt.results import FrontRecord

AMBIGUOUS = "tab:orange"
FRONT = "tab:blue"
DOMINATED = "tab:red"
INFEASIBLE = "0.45"
_SUP = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹", "0123456789")
_TO_SUP = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")
_POWER = re.compile(r"^([A-Za-zµ]+)(?:\^(\d+)|([⁰¹²³⁴⁵⁶⁷⁸⁹]+))?$")


RobotHook = Callable[[FrontRecord, Sequence[tuple[str, int]], Path], list[Path]]
"""A study's drawing of chosen designs of a front: (record, [(name, design number)],
folder) -> the figures written (the serial study's robots)."""


def draw(rec: FrontRecord, folder: Path, robot: RobotHook | None = None) -> list[Path]:
    """The figures of a front record into ``folder``; with ``robot`` (the study's hook)
    also the designs of :func:`extremes_and_knee` drawn by it, and marked on ``front``."""

    units = rec.units()
    picks = extremes_and_knee(rec) if robot is not None else []
    paths = front(rec, folder, units, picks)
    paths += designs(rec, folder, units)
    paths += indices(rec, folder, units)
    if rec.history.size:
        paths += hypervolume(rec, folder, units)
    if robot is not None:
        paths += robot(rec, picks, folder)
    return paths


def extremes_and_knee(rec: FrontRecord) -> list[tuple[str, int]]:
    """[(name, design number)] of the front's two extremes and its knee, among the
    designs of rank 0 that are feasible (every design where none is): the extremes are
    the best designs in the first and in the second objective (ties broken by the
    other); the knee is the design farthest from the line between them in the objective
    space normalised to [0, 1] per objective over those designs (each minimised: a
    ``max`` objective negated), on the side of the ideal point where any design lies
    there (a convex front), else on either side (a concave one). Repeats dropped
    (a front of one or two designs)."""
    sign = np.array([-1.0 if s == "max" else 1.0 for s in rec.objectives.values()])
    F = np.asarray(rec.F, np.float64) * sign  # minimised
    idx = np.flatnonzero(_groups(rec)[0])
    idx = idx if idx.size else np.arange(len(F))
    G = F[idx]
    span = np.ptp(G, 0)
    Z = np.where(span > 0, (G - G.min(0)) / np.where(span > 0, span, 1.0), 0.0)
    b = 1 if Z.shape[1] > 1 else 0
    i0, i1 = np.lexsort((Z[:, b], Z[:, 0]))[0], np.lexsort((Z[:, 0], Z[:, b]))[0]
    k = _knee(Z, Z[i0], Z[i1])
    obj = list(rec.objectives)
    out: dict[int, str] = {}
    for name, i in ((f"best {obj[0]}", i0), ("knee", k), (f"best {obj[b]}", i1)):
        out.setdefault(int(idx[i]), name)
    return [(name, i) for i, name in out.items()]


def _knee(Z: np.ndarray, a: np.ndarray, b: np.ndarray) -> int:
    """The row of Z farthest from the line through a and b on the side of the origin
    (the ideal point: a convex front's knee); where no row lies on that side (a concave
    front, or the origin on the line), the farthest on any side."""
    d = b - a
    dd = float(d @ d)

    def normal(v: np.ndarray) -> np.ndarray:  # the part of v normal to the line
        return v - np.outer(v @ d / dd, d).reshape(v.shape) if dd > 0 else v

    off = normal(Z - a)
    dist = np.linalg.norm(off, axis=1)
    w = normal(-a)
    n = float(np.linalg.norm(w))
    side = off @ (w / n) if n > 0 else np.zeros(len(Z))
    tol = 1e-12 * max(float(dist.max(initial=0.0)), 1.0)
    return int(np.argmax(side) if np.any(side > tol) else np.argmax(dist))


# ------------------------------------------------------------------------ helpers


def objective_label(name: str, sense: str, units: Mapping[str, str]) -> str:
    """``gci (max) [-]``: an objective's axis label, its sense and unit."""
    return style.label(f"{name} ({sense})", style.unit_of(name, units))


def unit_product(us: Sequence[str]) -> str:
    """The unit of a product of quantities with units ``us`` (a hypervolume's): the
    dimensionless ones dropped, powers of one plain unit added (``mm`` · ``mm²`` → ``mm³``),
    anything else joined with ``·``; ``mixed`` if any factor is; ``-`` if all are."""
    us = [u for u in us if u not in ("", style.DIMENSIONLESS)]
    if not us:
        return style.DIMENSIONLESS
    if "mixed" in us:
        return "mixed"
    parsed = [_POWER.match(u) for u in us]
    if not all(parsed):
        return "·".join(u if re.fullmatch(r"[\w^²³µ·]+", u) else f"({u})" for u in us)
    powers: dict[str, int] = {}
    sup = False
    for m in parsed:
        e = m.group(2) or (m.group(3) or "").translate(_SUP) or "1"
        sup |= bool(m.group(3))
        powers[m.group(1)] = powers.get(m.group(1), 0) + int(e)
    out = []
    for b, e in powers.items():
        out.append(b if e == 1 else (f"{b}{str(e).translate(_TO_SUP)}" if sup else f"{b}^{e}"))
    return "·".join(out)


def _groups(rec: FrontRecord) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks (rank 0 and feasible, rank > 0 and feasible, infeasible) over the front."""
    n = len(rec.F)
    v = rec.values.get("violation")
    bad = np.zeros(n, bool) if v is None else np.asarray(v, np.float64) > 0
    rank = rec.rank if "rank" in rec.groups["front"] else np.zeros(n, np.int64)
    return (rank == 0) & ~bad, (rank > 0) & ~bad, bad


def _bars_note(rec: FrontRecord) -> str:
    return f"bars ± 2 SE, re-scored on {rec.n_samples} fresh samples per design"


def _panel(ax: plt.Axes, F: np.ndarray, se: np.ndarray, pairs: np.ndarray,
           masks: Sequence[np.ndarray]) -> None:  # fmt: skip
    """One 2-D projection: ambiguous pairs (thin lines), ± 2 SE bars, the points."""
    if len(pairs):
        seg = np.stack([F[pairs[:, 0]], F[pairs[:, 1]]], 1)
        ax.add_collection(LineCollection(seg, colors=AMBIGUOUS, lw=0.6, alpha=0.45, zorder=1,
                                         gid="ambiguous"))  # fmt: skip
    ax.errorbar(F[:, 0], F[:, 1], xerr=style.Z_SE * se[:, 0], yerr=style.Z_SE * se[:, 1],
                fmt="none", ecolor="0.55", elinewidth=0.7, capsize=1.5, zorder=2,
                gid="se")  # fmt: skip
    on, dom, bad = masks
    kw = {"s": 16, "zorder": 3}
    ax.scatter(F[on, 0], F[on, 1], c=FRONT, gid="front:rank0", **kw)
    ax.scatter(F[dom, 0], F[dom, 1], c=DOMINATED, marker="s", gid="front:dominated", **kw)
    ax.scatter(F[bad, 0], F[bad, 1], facecolors="none", edgecolors=INFEASIBLE, s=30,
               zorder=4, gid="front:infeasible")  # fmt: skip
    ax.grid(alpha=0.3)
    for w in "xy":
        style.auto_log(ax, F[:, 0 if w == "x" else 1], axis=w)


def _handles(rec: FrontRecord, masks: Sequence[np.ndarray]) -> list:
    on, dom, bad = masks
    h = [Line2D([], [], ls="none", marker="o", color=FRONT, label=f"front (rank 0): {on.sum()}")]
    if dom.any():
        h.append(Line2D([], [], ls="none", marker="s", color=DOMINATED,
                        label=f"dominated after re-scoring: {dom.sum()}"))  # fmt: skip
    if bad.any():
        h.append(Line2D([], [], ls="none", marker="o", mfc="none", color=INFEASIBLE,
                        label=f"infeasible: {bad.sum()}"))  # fmt: skip
    h.append(Line2D([], [], color="0.55", lw=0.7, label="± 2 SE"))
    if len(rec.ambiguous):
        h.append(Line2D([], [], color=AMBIGUOUS, lw=0.8,
                        label=f"ambiguous pair (within 2 SE): {len(rec.ambiguous)}"))  # fmt: skip
    return h


def _ring(ax: plt.Axes, F: np.ndarray, picks: Sequence[tuple[str, int]]) -> list:
    """The designs drawn with their robots ringed; their legend entry (none without)."""
    if not picks:
        return []
    i = [k for _, k in picks]
    ax.scatter(F[i, 0], F[i, 1], s=110, facecolors="none", edgecolors="k", lw=1.2, zorder=5,
               gid="ringed:robots")  # fmt: skip
    what = ", ".join(f"#{k}" for _, k in picks)
    return [Line2D([], [], ls="none", marker="o", mfc="none", mec="k", ms=9,
                   label=f"extremes and knee (front_robots): {what}")]  # fmt: skip


# ------------------------------------------------------------------------ figures


def front(rec: FrontRecord, folder: Path, units: Mapping[str, str],
          picks: Sequence[tuple[str, int]] = ()) -> list[Path]:  # fmt: skip
    """``front`` (and ``front_3d`` for three objectives); ``picks`` [(name, design)]
    ringed (the designs drawn with their robots)."""
    F, se, pairs = rec.F, rec.F_se, rec.ambiguous
    obj = list(rec.objectives.items())
    m = len(obj)
    masks = _groups(rec)
    labels = [objective_label(k, s, units) for k, s in obj]
    head = f"Pareto front of {rec.study}: {len(F)} designs; {_bars_note(rec)}"
    if m == 2:
        fig, ax = style.subplots(figsize=(7.2, 4.4))
        _panel(ax, F, se, pairs, masks)
        h = _handles(rec, masks) + _ring(ax, F[:, :2], picks)
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.legend(handles=h, fontsize=7, loc="upper left",
                  bbox_to_anchor=(1.01, 1.0), borderaxespad=0)  # fmt: skip
        fig.suptitle(head, fontsize=9)
        return save(fig, folder, "front")
    k = m - 1
    fig, axes = style.subplots(k, k, figsize=(3.3 * k + 0.6, 3.0 * k + 0.5), squeeze=False)
    for r in range(k):
        for c in range(k):
            ax = axes[r, c]
            if c > r:
                ax.axis("off")
                continue
            i, j = c, r + 1  # x: objective c, y: objective r + 1
            _panel(ax, F[:, [i, j]], se[:, [i, j]], pairs, masks)
            ring = _ring(ax, F[:, [i, j]], picks)
            ax.set_xlabel(labels[i], fontsize=8)
            ax.set_ylabel(labels[j], fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, k - 1].legend(handles=_handles(rec, masks) + ring, fontsize=7, loc="upper right",
                          borderaxespad=0)  # fmt: skip
    fig.suptitle(f"{head}\n(pairwise projections)", fontsize=9)
    out = save(fig, folder, "front")
    if m == 3:
        out += _front_3d(rec, folder, labels, masks)
    return out


def _front_3d(rec: FrontRecord, folder: Path, labels: Sequence[str],
              masks: Sequence[np.ndarray]) -> list[Path]:  # fmt: skip
    F, se = rec.F, rec.F_se
    fig = style.figure(figsize=(6.8, 5.6))
    ax = fig.add_subplot(projection="3d")
    ax.errorbar(F[:, 0], F[:, 1], F[:, 2], xerr=style.Z_SE * se[:, 0],
                yerr=style.Z_SE * se[:, 1], zerr=style.Z_SE * se[:, 2], fmt="none",
                ecolor="0.6", elinewidth=0.6)  # fmt: skip
    on, dom, bad = masks
    ax.scatter(F[on, 0], F[on, 1], F[on, 2], c=FRONT, s=14, gid="front:rank0",
               depthshade=False)  # fmt: skip
    ax.scatter(F[dom, 0], F[dom, 1], F[dom, 2], c=DOMINATED, marker="s", s=14,
               gid="front:dominated", depthshade=False)  # fmt: skip
    ax.scatter(F[bad, 0], F[bad, 1], F[bad, 2], facecolors="none", edgecolors=INFEASIBLE,
               s=14, gid="front:infeasible", depthshade=False)  # fmt: skip
    ax.set_xlabel(labels[0], fontsize=8)
    ax.set_ylabel(labels[1], fontsize=8)
    ax.set_zlabel(labels[2], fontsize=8)
    ax.tick_params(labelsize=7)
    h = [x for x in _handles(rec, masks) if "ambiguous" not in x.get_label()]
    fig.legend(handles=h, fontsize=7, loc="outside lower center", ncols=len(h))
    fig.suptitle(f"Pareto front of {rec.study}: {len(F)} designs\n{_bars_note(rec)}",
                 fontsize=9)  # fmt: skip
    return save(fig, folder, "front_3d")


def parallel(rec: FrontRecord) -> tuple[np.ndarray, list[str]]:
    """The parallel coordinates (n, D + m) in [0, 1] and their axis names: each variable
    scaled to its box, each objective to its range over the front (its least value 0;
    0.5 where it is constant)."""
    X, F = rec.X, rec.F
    lo, hi = rec.lower, rec.upper
    xs = (X - lo) / np.where(hi > lo, hi - lo, 1.0)
    f0, f1 = F.min(0), F.max(0)
    fs = np.where(f1 > f0, (F - f0) / np.where(f1 > f0, f1 - f0, 1.0), 0.5)
    return np.clip(np.concatenate([xs, fs], 1), 0.0, 1.0), rec.names + list(rec.objectives)


def designs(rec: FrontRecord, folder: Path, units: Mapping[str, str]) -> list[Path]:
    """``front_designs``: parallel coordinates of the front's designs."""
    P, axis_names = parallel(rec)
    D = len(rec.names)
    obj = list(rec.objectives.items())
    F = rec.F
    ticks = []
    for a, name in enumerate(axis_names):
        if a < D:
            lo, hi = rec.lower[a], rec.upper[a]
            ticks.append(f"{style.label(name, style.unit_of(name, units))}\n"
                         f"box {lo:.3g} … {hi:.3g}")  # fmt: skip
        else:
            k, s = obj[a - D]
            lo, hi = F[:, a - D].min(), F[:, a - D].max()
            ticks.append(f"{objective_label(k, s, units)}\nfront {lo:.3g} … {hi:.3g}")
    K = len(axis_names)
    # each axis as wide as its longest label line (7 pt: about 0.06 in a character), the
    # canvas at most 16 in wide; labels that still collide are turned (``_fit_ticks``)
    chars = max(len(line) for t in ticks for line in t.split("\n"))
    per = max(1.1, 0.06 * chars + 0.25)
    fig, ax = style.subplots(figsize=(min(16.0, max(6.5, per * K + 2.2)), 4.8))
    x = np.arange(K, dtype=np.float64)
    for a in x:
        ax.axvline(a, color="0.3", lw=0.8, zorder=1)
    ax.axvspan(D - 0.5, K - 0.5, color="0.93", zorder=0, lw=0)
    on, dom, bad = _groups(rec)
    seg = np.stack([np.broadcast_to(x, P.shape), P], -1)
    lc = LineCollection(seg, array=F[:, 0], cmap="viridis", alpha=0.85, zorder=2,
                        linewidths=np.where(on, 1.1, 2.0), gid="designs",
                        linestyles=np.where(on, "solid", "dashed").tolist())  # fmt: skip
    ax.add_collection(lc)
    ax.set_xlim(-0.4, K - 0.6)
    ax.set_ylim(-0.04, 1.04)
    ax.set_xticks(x, ticks, fontsize=7)
    _fit_ticks(fig, ax)
    ax.set_xlabel("design variable (box) | objective (range over the front) (category)")
    ax.set_ylabel(style.label("scaled value", style.DIMENSIONLESS))
    k0, s0 = obj[0]
    cb = fig.colorbar(lc, ax=ax, pad=0.02)
    cb.set_label(objective_label(k0, s0, units), fontsize=8)
    note = "\ndashed: dominated or infeasible after re-scoring" if (dom | bad).any() else ""
    fig.suptitle(f"The front's {len(F)} designs of {rec.study}: 0 = the box's lower bound "
                 f"or the front's least value{note}", fontsize=9)  # fmt: skip
    return save(fig, folder, "front_designs")


def _fit_ticks(fig: Any, ax: Any) -> None:
    """Turn the x tick labels (30°, then 60°, then 90°, anchored at their axis) until no
    two of them overlap; constrained layout then keeps them on the canvas."""
    labels = ax.get_xticklabels()
    for angle in (0, 30, 60, 90):
        if angle:
            fig.set_figheight(max(fig.get_figheight(), 4.8 + 1.6 * angle / 90))
            for t in labels:
                t.set_rotation(angle)
                t.set_ha("right" if angle < 90 else "center")
                t.set_rotation_mode("anchor" if angle < 90 else "default")
        fig.canvas.draw()
        r = fig.canvas.get_renderer()
        b = [t.get_window_extent(r) for t in labels if t.get_text()]
        if all(min(p.x1, q.x1) - max(p.x0, q.x0) <= 1.0 or min(p.y1, q.y1) - max(p.y0, q.y0) <= 1.0
               for i, p in enumerate(b) for q in b[i + 1 :]):  # fmt: skip
            return


def indices(rec: FrontRecord, folder: Path, units: Mapping[str, str]) -> list[Path]:
    """``front_indices``: every other index of the study against the first objective."""
    others = rec.indices
    if not others:
        return []
    vals, F, se = rec.values, rec.F, rec.F_se
    k0, s0 = next(iter(rec.objectives.items()))
    n = len(others)
    ncols = 2 if n == 4 else min(3, n)
    nrows = -(-n // ncols)
    fig, axes = style.subplots(nrows, ncols, figsize=(max(6.4, 3.6 * ncols + 0.4),
                                                      2.7 * nrows + 1.0), squeeze=False)  # fmt: skip
    masks = _groups(rec)
    for a, k in enumerate(others):
        ax = axes[a // ncols, a % ncols]
        y = np.asarray(vals[k], np.float64)
        ys = np.asarray(vals.get(k + "_se", np.zeros(len(y))), np.float64)
        _panel(ax, np.stack([F[:, 0], y], -1), np.stack([se[:, 0], ys], -1), np.zeros((0, 2), int),
               masks)  # fmt: skip
        ax.set_ylabel(style.label(k, style.unit_of(k, units)), fontsize=8)
        ax.set_xlabel(objective_label(k0, s0, units), fontsize=8)
        ax.tick_params(labelsize=7)
    for a in range(n, nrows * ncols):
        axes[a // ncols, a % ncols].axis("off")
    h = [x for x in _handles(rec, masks) if "ambiguous" not in x.get_label()]
    fig.legend(handles=h, fontsize=7, loc="outside lower center", ncols=len(h))
    fig.suptitle(f"The front of {rec.study} ({len(F)} designs) in the study's other indices, "
                 f"against {k0}\n{_bars_note(rec)}", fontsize=9)  # fmt: skip
    return save(fig, folder, "front_indices")


def hypervolume(rec: FrontRecord, folder: Path, units: Mapping[str, str]) -> list[Path]:
    """``hypervolume``: every run's hypervolume of the best front found so far per
    iteration, their median, the populations' median and the re-scored front's."""
    H = np.atleast_2d(np.asarray(rec.history, np.float64))
    it = np.arange(H.shape[1])
    obj = list(rec.objectives)
    unit = unit_product([style.unit_of(k, units) for k in obj])
    fig, ax = style.subplots(figsize=(7.2, 4.0))
    for h in H:
        ax.plot(it, h, color="0.6", lw=0.7, alpha=0.8, gid="run")
    ax.plot(it, np.median(H, 0), color="k", lw=2.2, gid="median",
            label=f"median of {len(H)} runs")  # fmt: skip
    pop = rec.population_history
    if pop is not None:
        ax.plot(it, np.median(np.atleast_2d(pop), 0), color="tab:orange", ls=":", lw=1.4,
                gid="population", label="median of the populations alone")  # fmt: skip
    fid = dict(rec.config.optimizer.fidelity)
    ax.axhline(rec.hypervolume, color="tab:blue", ls="--", lw=1.0,
               label="front pooled over the runs, re-scored"
               + (" (the study's own settings)" if fid else ""))  # fmt: skip
    own = "each run's feasible population" if pop is None else "each run's best front so far"
    ax.plot([], [], color="0.6", lw=0.7, label=own)
    ax.set_xlabel(style.label("iteration", style.DIMENSIONLESS))
    ax.set_ylabel(style.label("hypervolume", unit))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    ref = ", ".join(f"{k} = {v:.4g}" for k, v in zip(obj, rec.reference, strict=True))
    what = "the best front found so far" if pop is not None else "the populations"
    how = ("; the search scored with " + ", ".join(f"{k} = {v}" for k, v in fid.items())
           if fid else "")  # optimizer.fidelity
    fig.suptitle(f"Hypervolume of {', '.join(obj)} ({rec.study}), {what}\nreference point: {ref}"
                 f"{how}", fontsize=9)  # fmt: skip
    return save(fig, folder, "hypervolume")
