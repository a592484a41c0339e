"""Figures of a serial-study run: convergence of f and its indices along the best run,
1/k over the first two joints (the others at mid-range) for the initial and final design,
and the final design's workspace coloured by 1/k."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt import montecarlo as mc
from designopt.figures import convergence, plt, save
from designopt.studies.serial.mechanism import Mechanism, build
from designopt.studies.serial.objective import measures
from designopt.studies.serial.settings import ROWS, SerialSettings

N_GRID = 101


def _full(mech: Mechanism, x: np.ndarray) -> jnp.ndarray:
    v = np.concatenate([np.asarray(x, np.float64), mech.fixed]) * mech.scale
    return jnp.asarray(v[None], mc.out_dtype())


def inv_k(mech: Mechanism, s: SerialSettings, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """1/k of the configured Jacobian rows for one design x (variables) at q (C, n)."""
    rows = s.indices.rows()
    J = mech.model.jacobian(_full(mech, x), jnp.asarray(q, mc.out_dtype()), rows=rows)
    sc = np.array([1.0 if r < 3 else s.indices.length_scale for r in rows])
    J = J * jnp.asarray(sc, J.dtype)[:, None]
    return np.asarray(measures(J, s.indices.norm, s.indices.normalized)[0][0])


def _unit(mech: Mechanism, i: int, s: SerialSettings) -> tuple[float, str]:
    return (180 / np.pi, "deg") if s.chain.joints[i].type == "R" else (1.0, "")


def draw_run(a: dict[str, Any], folder: Path) -> list[Path]:
    cfg = a["attrs"]["config_resolved"]
    s = SerialSettings.model_validate(cfg["study"])
    mech = build(s)
    br = a["best_run"]
    run = int(br["attrs"]["run_index"])
    designs = {
        "initial (iteration 0)": a["optimizer"]["history_x"][run, 0],
        "final": a["final"]["x"],
    }
    out = []
    out += convergence(br, ["f", *s.index_names()], folder, "Best run: objective and indices")

    rows_txt = ", ".join(ROWS[r] for r in s.indices.rows())
    lo, hi = mech.lower, mech.upper
    mid = 0.5 * (lo + hi)
    if mech.n >= 2:
        fa, ua = _unit(mech, 0, s)
        fb, ub = _unit(mech, 1, s)
        ga, gb = np.linspace(lo[0], hi[0], N_GRID), np.linspace(lo[1], hi[1], N_GRID)
        A, B = np.meshgrid(ga, gb, indexing="xy")
        q = np.tile(mid, (A.size, 1))
        q[:, 0], q[:, 1] = A.ravel(), B.ravel()
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        for ax, (lab, x) in zip(axes, designs.items(), strict=True):
            z = inv_k(mech, s, x, q).reshape(A.shape)
            im = ax.pcolormesh(ga * fa, gb * fb, z, shading="auto", cmap="viridis", rasterized=True)
            fig.colorbar(im, ax=ax, label="1/k")
            ax.set_xlabel(f"q1 ({ua})" if ua else "q1")
            ax.set_ylabel(f"q2 ({ub})" if ub else "q2")
            ax.set_title(f"{lab}: mean {z.mean():.4g}", fontsize=9)
        fig.suptitle(f"1/k ({s.indices.norm}-norm; rows {rows_txt}) over q1, q2, others at mid-range",
                     fontsize=10)  # fmt: skip
        fig.tight_layout()
        out += save(fig, folder, "dexterity_map")

    key = jax.random.wrap_key_data(np.asarray(a["attrs"]["keys"]["figures"], np.uint32))
    u = np.asarray(jax.random.uniform(key, (4000, mech.n), mc.out_dtype()))
    q = lo + (hi - lo) * u
    x = a["final"]["x"]
    _, p = mech.model.fk(_full(mech, x), jnp.asarray(q, mc.out_dtype()))
    p = np.asarray(p[0])
    c = inv_k(mech, s, x, q)
    planar = np.ptp(p[:, 2]) <= 1e-9 * max(np.ptp(p[:, :2]), 1e-300)
    fig = plt.figure(figsize=(5.2, 4.6))
    if planar:
        ax = fig.add_subplot(1, 1, 1)
        sc = ax.scatter(p[:, 0], p[:, 1], s=1, c=c, cmap="viridis", rasterized=True)
        ax.set_aspect("equal")
    else:
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        sc = ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=0.5, c=c, cmap="viridis", rasterized=True)
        ax.set_zlabel("z")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    fig.colorbar(sc, ax=ax, label="1/k", shrink=0.7)
    ax.set_title("final design: tip positions over the joint box", fontsize=9)
    out += save(fig, folder, "workspace")
    return out
