"""Study-A figures (seed 000 Fig. 12-15) for the initial and final design of a run.

Fig. 12: f and the sub-objectives f_k, f_l, f_p along the best run; Fig. 13: 1/k of J_v
over pairs of (q1, q2, q3), the third joint at mid-range; Fig. 14: e_max (backlash
error) over the same pairs; Fig. 15: workspace point clouds with volume and L.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt import montecarlo as mc
from designopt.figures import plt, save
from designopt.studies.master9 import indices as ind
from designopt.studies.master9 import mechanism as m

PAIRS = ((0, 1), (0, 2), (1, 2))
N_GRID = 121


def _design(x: Mapping[str, float]) -> dict[str, jnp.ndarray]:
    return {k: jnp.asarray([float(x[k])]) for k in ind.LINEAR_KEYS}


def joint_grid(pair: tuple[int, int], n: int = N_GRID) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
def _inv_cond_kernel(x, q):
    return ind.inv_cond_fro_jv(ind.jv_entries(x, ind.features(q)))[1][0]


@jax.jit
def _emax_kernel(x, q, delta):
    return ind.emax(x, ind._corner_deltas(q, delta))[0]


def inv_cond_map(x: Mapping[str, float], q: np.ndarray) -> np.ndarray:
    """Raw Frobenius 1/k of J_v (seed 000 eq. 51-53) at joint configurations q (C, 3),
    with the index kernel, jitted (one compilation for every map of the same size)."""
    dt = mc.out_dtype()
    xd = {k: v[:, None].astype(dt) for k, v in _design(x).items()}
    return np.asarray(_inv_cond_kernel(xd, jnp.asarray(q, dt)))


def emax_map(x: Mapping[str, float], q: np.ndarray, backlash_deg) -> np.ndarray:
    """Largest tip error (mm) over the backlash box (seed 000 eq. 39) at q (C, 3)."""
    dt = mc.out_dtype()
    delta = jnp.deg2rad(jnp.asarray(backlash_deg, dt))
    xd = {k: v[:, None].astype(dt) for k, v in _design(x).items()}
    return np.asarray(_emax_kernel(xd, jnp.asarray(q, dt), delta))


def _maps(fn, title: str, unit: str, designs: dict[str, Mapping[str, float]], cmap: str):
    fig, axes = plt.subplots(len(designs), 3, figsize=(11, 3.3 * len(designs)), squeeze=False)
    names = ("q1", "q2", "q3")
    for r, (label, x) in enumerate(designs.items()):
        for c, pair in enumerate(PAIRS):
            a, b, q = joint_grid(pair)
            z = fn(x, q).reshape(len(b), len(a))
            ax = axes[r, c]
            im = ax.pcolormesh(a, b, z, shading="auto", cmap=cmap, rasterized=True)
            fig.colorbar(im, ax=ax, label=unit)
            ax.set_xlabel(f"{names[pair[0]]} (deg)")
            ax.set_ylabel(f"{names[pair[1]]} (deg)")
            ax.set_title(f"{label}: mean {z.mean():.4g}", fontsize=9)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def draw(
    folder: Path,
    iters: np.ndarray,
    sub_history: Mapping[str, np.ndarray],
    designs: dict[str, Mapping[str, float]],
    backlash_deg,
    key: jax.Array,
    n_cloud: int = 6000,
) -> list[Path]:
    """Write Fig. 12-15 into ``folder``. ``designs`` maps a label ('initial', 'final', …)
    to a full design dict; ``sub_history`` holds f, f_k, f_l, f_p, volume, L per iteration."""
    out = []
    fig, axes = plt.subplots(2, 2, figsize=(9, 6))
    for ax, k, lab in zip(axes.flat, ("f", "f_k", "f_l", "f_p"),
                          ("composite f (eq. 43)", "f_k = GCSEI − GCI", "f_l = L / V^(1/3)",
                           "f_p = GPI (mm)"), strict=True):  # fmt: skip
        ax.plot(iters, sub_history[k], marker=".", lw=1)
        ax.set_xlabel("iteration")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    fig.suptitle("Best run: objective and sub-objectives (IEEE Access 2019, Fig. 12)", fontsize=10)
    fig.tight_layout()
    out += save(fig, folder, "fig12_convergence")
    fig = _maps(inv_cond_map, "Dexterity 1/k of J_v (Frobenius; IEEE Access 2019, Fig. 13)", "1/k",
                designs, "viridis")  # fmt: skip
    out += save(fig, folder, "fig13_dexterity_maps")
    fig = _maps(lambda x, q: emax_map(x, q, backlash_deg),
                f"Backlash error e_max for {tuple(backlash_deg)}° (IEEE Access 2019, Fig. 14)", "e_max (mm)",
                designs, "magma")  # fmt: skip
    out += save(fig, folder, "fig14_backlash_maps")
    fig = plt.figure(figsize=(5.2 * len(designs), 4.6))
    q3 = np.asarray(m.sample_joints(key, n_cloud, mc.out_dtype()))[:, :3]
    for i, (label, x) in enumerate(designs.items()):
        ax = fig.add_subplot(1, len(designs), i + 1, projection="3d")
        full = {**m.default_design(), **{k: float(x[k]) for k in m.DESIGN_KEYS if k in x}}
        P = np.asarray(m.position(jnp.asarray(q3), full))
        ax.scatter(
            P[:, 0], P[:, 1], P[:, 2], s=0.5, alpha=0.4, c=P[:, 2], cmap="viridis", rasterized=True
        )
        ax.set_xlabel("x (mm)", fontsize=8)
        ax.set_ylabel("y (mm)", fontsize=8)
        ax.set_zlabel("z (mm)", fontsize=8)
        L = full["a1"] + full["a3"] + full["d3"]
        vol = x.get("volume")
        vtxt = f"V = {vol:.4e} mm³, " if vol is not None else ""
        ax.set_title(f"{label}: {vtxt}L = {L:.3f} mm", fontsize=9)
        ax.tick_params(labelsize=6)
    fig.suptitle("Workspace of the position mechanism (IEEE Access 2019, Fig. 15)", fontsize=10)
    out += save(fig, folder, "fig15_workspace")
    return out


def draw_run(a: dict[str, Any], folder: Path) -> list[Path]:
    """Fig. 12-15 of a run archive (read by ``designopt.archive.read``) into ``folder``:
    the initial design of the best run (iteration 0) against the final design."""
    cfg = a["attrs"]["config_resolved"]
    names = [n.decode() for n in a["problem"]["names"]]
    fixed = a["problem"]["attrs"]["info"]["fixed"]
    br = a["best_run"]
    run = int(br["attrs"]["run_index"])
    x0 = a["optimizer"]["history_x"][run, 0]
    xf = a["final"]["x"]
    designs = {
        "initial (iteration 0)": {**fixed, **dict(zip(names, x0, strict=True)),
                                  "volume": float(br["volume"][0])},
        "final": {**fixed, **dict(zip(names, xf, strict=True)),
                  "volume": float(a["final"]["volume"])},
    }  # fmt: skip
    bl = cfg["study"]["indices"]["backlash_deg"]
    bl = bl if isinstance(bl, list) else [bl] * 3
    key = jax.random.wrap_key_data(np.asarray(a["attrs"]["keys"]["figures"], np.uint32))
    return draw(folder, br["iteration"], br, designs, bl, key)
