"""Figures of the 9-DOF haptic master (IEEE Access 2019, Fig. 12-15) for the initial and
final design of a run.

Fig. 12: f and the sub-objectives f_k, f_l, f_p (± 2 SE) along the best run; Fig. 13: 1/k
of J_v over pairs of (q1, q2, q3), the third joint held at mid-range (:data:`HELD`: the
middle of its limits, away from the box's singular edges), initial and final design on one
colour scale; Fig. 14: e_max (backlash error) over the same pairs, one colour scale;
Fig. 15: workspace point clouds with volume and L on common axes and colour limits. Every
map and cloud comes from one jitted call of the index kernels (one XLA program per run).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import numpy as np
from matplotlib.ticker import MaxNLocator

from designopt.figures import MAP_RESOLUTION, save, style
from designopt.numerics import montecarlo as mc
from designopt.studies.master9 import indices as ind
from designopt.studies.master9 import mechanism as m

PAIRS = ((0, 1), (0, 2), (1, 2))
HELD = "mid-range"
"""Where a map holds the third position joint: the middle of its limits (q1 −5°, q2 0°,
q3 0°), inside the box and away from its singular edges (1/k > 0 there)."""


def joint_grid(pair: tuple[int, int], n: int = MAP_RESOLUTION):
    """An n×n grid over two of (q1, q2, q3) within their limits, the third at mid-range.
    Returns (axis i in deg, axis j in deg, q (n·n, 3) in rad)."""
    lim = m.POSITION_LIMITS
    mid = lim.mean(axis=1)
    a = np.linspace(lim[pair[0], 0], lim[pair[0], 1], n)
    b = np.linspace(lim[pair[1], 0], lim[pair[1], 1], n)
    A, B = np.meshgrid(a, b, indexing="xy")
    q = np.tile(mid, (n * n, 1))
    q[:, pair[0]], q[:, pair[1]] = A.ravel(), B.ravel()
    return np.rad2deg(a), np.rad2deg(b), q


@jax.jit
def _kernel(x, q, delta, q_cloud):
    """Raw Frobenius 1/k of J_v (eq. 51-53) and e_max (eq. 39; backlash delta) at q (C, 3)
    for designs x {k: (M,)} → (M, C) each; tip positions (M, N, 3) of q_cloud (N, 3)."""
    xm = {k: v[:, None] for k, v in x.items()}  # (M, 1) against samples (C,)
    inv = ind.inv_cond_fro_jv(ind.jv_entries(xm, ind.features(q)))[1]
    e = ind.emax(xm, ind._corner_deltas(q, delta))
    return inv, e, m.position(q_cloud, xm)


def figure_data(designs: Mapping[str, Mapping[str, float]], backlash_deg, key_data: np.ndarray,
                n: int = MAP_RESOLUTION, n_cloud: int = 6000) -> dict[str, Any]:  # fmt: skip
    """Maps over the n×n grids of ``PAIRS`` and workspace clouds (``key_data``: the raw
    key of their joint samples) for every design, in one jitted call. Returns {"axes":
    [(deg, deg)] per pair, "designs": full design dicts, "inv_cond", "emax": (M, pairs, n,
    n), "cloud": (M, n_cloud, 3)}."""
    dt = mc.out_dtype()
    grids = [joint_grid(p, n) for p in PAIRS]
    q = np.concatenate([g[2] for g in grids])
    full = [{**m.default_design(), **{k: float(v) for k, v in x.items() if k in m.DESIGN_KEYS}}
            for x in designs.values()]  # fmt: skip
    x = {k: np.asarray([d[k] for d in full], dt) for k in m.DESIGN_KEYS}
    delta = np.deg2rad(np.asarray(backlash_deg, np.float64)).astype(dt)
    lim = m.JOINT_LIMITS[:3]  # uniform joints, drawn with NumPy (threefry compiles slowly)
    q_cloud = np.random.default_rng(np.asarray(key_data)).uniform(
        lim[:, 0], lim[:, 1], (n_cloud, 3)
    )
    inv, e, P = _kernel(x, q.astype(dt), delta, q_cloud.astype(dt))
    M = len(full)
    return {"axes": [g[:2] for g in grids], "designs": full,
            "inv_cond": np.asarray(inv).reshape(M, len(PAIRS), n, n),
            "emax": np.asarray(e).reshape(M, len(PAIRS), n, n), "cloud": np.asarray(P)}  # fmt: skip


def _extent(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float, float]:
    """imshow extent of cells centred on the uniform grid points a × b."""
    da, db = (a[-1] - a[0]) / (2 * (len(a) - 1)), (b[-1] - b[0]) / (2 * (len(b) - 1))
    return a[0] - da, a[-1] + da, b[0] - db, b[-1] + db


def _maps(z_all, axes_deg, title: str, name: str, unit: str, labels: list[str], cmap: str):
    """Rows: designs; columns: joint pairs; one colour scale over every panel."""
    # a fixed grid (style.grid): two-line titles, degree ticks, the colour bar at the right
    fig, axes, cax = style.grid(len(labels), 3, (11, 3.1 * len(labels) + 0.6),
                                margins=(0.7, 1.35, 0.5, 0.75), gaps=(0.75, 0.85),
                                colorbar=True)  # fmt: skip
    names = ("q1", "q2", "q3")
    mid = np.rad2deg(m.POSITION_LIMITS.mean(axis=1))
    ims = []
    for r, label in enumerate(labels):
        for c, pair in enumerate(PAIRS):
            a, b = axes_deg[c]
            z = z_all[r, c]
            ax = axes[r, c]
            ims.append(ax.imshow(z, origin="lower", extent=_extent(a, b), aspect="auto",
                                 interpolation="nearest", cmap=cmap, rasterized=True))  # fmt: skip
            ax.set_xlabel(style.label(names[pair[0]], "deg"))
            ax.set_ylabel(style.label(names[pair[1]], "deg"))
            held = ({0, 1, 2} - set(pair)).pop()
            ax.set_title(f"{label}: mean {z.mean():.4g}\n{names[held]} held at {mid[held]:.0f}° "
                         f"({HELD})", fontsize=8)  # fmt: skip
    style.shared_scale(fig, ims)
    fig.colorbar(ims[0], cax=cax, label=style.label(name, unit))
    fig.suptitle(title + " — one colour scale for all panels", fontsize=10)
    return fig


def draw(
    folder: Path,
    iters: np.ndarray,
    sub_history: Mapping[str, np.ndarray],
    designs: dict[str, Mapping[str, float]],
    backlash_deg,
    key_data: np.ndarray,
    n_cloud: int = 6000,
    resolution: int = MAP_RESOLUTION,
) -> list[Path]:
    """Write Fig. 12-15 into ``folder``. ``designs`` maps a label ('initial', 'final', …)
    to a full design dict; ``sub_history`` holds f, f_k, f_l, f_p, volume, L per iteration;
    the maps have ``resolution`` × ``resolution`` points."""

    def fig12() -> list[Path]:
        fig, axes = style.grid(2, 2, (9, 6), margins=(0.85, 0.2, 0.5, 0.45), gaps=(1.15, 0.65))
        for ax, k, lab, u in zip(axes.flat, ("f", "f_k", "f_l", "f_p"),
                                 ("composite f, eq. (43)", "f_k = GCSEI − GCI", "f_l = L / V^(1/3)",
                                  "f_p = GPI"), ("-", "-", "-", "mm"), strict=True):  # fmt: skip
            se = sub_history.get(k + "_se")
            style.band(ax, iters, np.asarray(sub_history[k], np.float64), se, marker=".", lw=1)
            ax.set_xlabel(style.label("iteration", style.DIMENSIONLESS))
            ax.set_ylabel(style.label(lab, u))
            ax.grid(alpha=0.3)
        fig.suptitle("Best run: objective and sub-objectives, band ± 2 SE (IEEE Access 2019, "
                     "Fig. 12)", fontsize=10)  # fmt: skip
        return save(fig, folder, "fig12_convergence")

    def fig15() -> list[Path]:
        fig = style.figure(figsize=(5.0 * len(designs) + 0.8, 4.8))
        P_all = d["cloud"]
        lo, hi = P_all.reshape(-1, 3).min(axis=0), P_all.reshape(-1, 3).max(axis=0)
        scs = []
        for i, (label, x) in enumerate(designs.items()):
            ax = fig.add_subplot(1, len(designs), i + 1, projection="3d")
            full, P = d["designs"][i], d["cloud"][i]
            scs.append(ax.scatter(P[:, 0], P[:, 1], P[:, 2], s=2, alpha=0.8, c=P[:, 2],
                                  cmap="viridis", rasterized=True, depthshade=False))  # fmt: skip
            ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
            for a in (ax.xaxis, ax.yaxis, ax.zaxis):
                a.set_major_locator(MaxNLocator(4))
            ax.set_xlabel(style.label("x", "mm"), fontsize=8, labelpad=2)
            ax.set_ylabel(style.label("y", "mm"), fontsize=8, labelpad=2)
            ax.set_zlabel(style.label("z", "mm"), fontsize=8, labelpad=2)
            L = full["a1"] + full["a3"] + full["d3"]
            vol = x.get("volume")
            vtxt = f"V = {vol:.4e} mm³, " if vol is not None else ""
            ax.set_title(f"{label}:\n{vtxt}L = {L:.3f} mm", fontsize=9)
            ax.tick_params(labelsize=6, pad=0)
        style.shared_scale(fig, scs)
        fig.colorbar(scs[0], ax=fig.axes, label=style.label("tip height z", "mm"), shrink=0.6)
        fig.suptitle(f"Workspace of the position mechanism ({n_cloud} uniform joint samples; IEEE "
                     "Access 2019, Fig. 15): common axes and colours", fontsize=10)  # fmt: skip
        return save(fig, folder, "fig15_workspace")

    d = figure_data(designs, backlash_deg, key_data, resolution, n_cloud)
    labels = list(designs)
    # the slowest figure (3-D) first: within figures.parallel_saves its child renders
    # while the others are built
    f15 = fig15()
    fig = _maps(d["inv_cond"], d["axes"], "Dexterity 1/k of J_v (Frobenius; IEEE Access 2019, "
                "Fig. 13)", "1/k", "-", labels, "viridis")  # fmt: skip
    f13 = save(fig, folder, "fig13_dexterity_maps")
    fig = _maps(d["emax"], d["axes"], f"Backlash error e_max for {tuple(backlash_deg)}° (IEEE "
                "Access 2019, Fig. 14)", "e_max", "mm", labels, "magma")  # fmt: skip
    f14 = save(fig, folder, "fig14_backlash_maps")
    return fig12() + f13 + f14 + f15


def draw_run(rec: Any, folder: Path, resolution: int = MAP_RESOLUTION) -> list[Path]:
    """Fig. 12-15 of a run (a ``RunRecord``) into ``folder``: the initial design of the
    best run (iteration 0) against the final design."""
    fixed = rec.info["fixed"]
    br = rec.best_run
    x0 = rec.history_x[rec.best_run_index, 0]
    designs = {
        "initial (iteration 0)": {**fixed, **dict(zip(rec.names, x0, strict=True)),
                                  "volume": float(br["volume"][0])},
        "final": {**fixed, **rec.x, "volume": float(rec.final["volume"])},
    }  # fmt: skip
    bl = rec.config.study.model_dump()["indices"]["backlash_deg"]
    bl = bl if isinstance(bl, list) else [bl] * 3
    key_data = np.asarray(jax.random.key_data(rec.keys()["figures"]), np.uint32)
    return draw(folder, br["iteration"], br, designs, bl, key_data, resolution=resolution)


@jax.jit
def _cloud_kernel(x, q):
    """Tip positions (N, 3) and raw Frobenius 1/k of J_v (eq. 51-53) at q (N, 3) for one
    design x {k: ()}."""
    inv = ind.inv_cond_fro_jv(ind.jv_entries(x, ind.features(q)))[1]
    return m.position(q, x), inv


def cloud(rec: Any, n: int = 8000) -> dict[str, Any]:
    """The final design's workspace for the interactive report: the tip positions of
    ``n`` uniform position-joint samples (the run's ``figures`` stream), coloured by the
    Frobenius 1/k of J_v (eq. 51-53)."""
    dt = mc.out_dtype()
    full = {**m.default_design(), **rec.info.get("fixed", {}), **rec.x}
    x = {k: np.asarray(full[k], dt) for k in m.DESIGN_KEYS}
    lim = m.JOINT_LIMITS[:3]
    key = np.asarray(jax.random.key_data(rec.keys()["figures"]), np.uint32)
    q = np.random.default_rng(key).uniform(lim[:, 0], lim[:, 1], (n, 3)).astype(dt)
    P, inv = _cloud_kernel(x, q)
    return {"xyz": np.asarray(P, np.float64), "value": np.asarray(inv, np.float64),
            "label": "1/k (Frobenius, J_v)", "unit": "-", "xyz_unit": "mm"}  # fmt: skip
