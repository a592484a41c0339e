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
from designopt.figures import MAP_RESOLUTION, convergence, plt, save
from designopt.studies.serial.mechanism import Mechanism, build
from designopt.studies.serial.objective import measures
from designopt.studies.serial.settings import ROWS, SerialSettings


def _full(mech: Mechanism, x: np.ndarray) -> np.ndarray:
    """(M, P) kernel parameters of designs x (M, variables)."""
    x = np.atleast_2d(np.asarray(x, np.float64))
    fixed = np.broadcast_to(mech.fixed, (x.shape[0], len(mech.fixed)))
    return (np.concatenate([x, fixed], -1) * mech.scale).astype(mc.out_dtype())


def _kernel(mech: Mechanism, s: SerialSettings):
    """jit(X (M, P), q (C, n)) → (1/k (M, C), tip positions (M, C, 3)), with the index
    kernel's Jacobian rows, length scale and norm."""
    rows = s.indices.rows()
    sc = np.array([1.0 if r < 3 else s.indices.length_scale for r in rows])

    def f(X, q):
        J = mech.model.jacobian(X, q, rows=rows) * jnp.asarray(sc, X.dtype)[:, None]
        return measures(J, s.indices.norm, s.indices.normalized)[0], mech.model.fk(X, q)[1]

    return jax.jit(f)


def inv_k(mech: Mechanism, s: SerialSettings, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """1/k of the configured Jacobian rows for one design x (variables) at q (C, n)."""
    return np.asarray(_kernel(mech, s)(_full(mech, x), q.astype(mc.out_dtype()))[0][0])


def _unit(mech: Mechanism, i: int, s: SerialSettings) -> tuple[float, str]:
    return (180 / np.pi, "deg") if s.chain.joints[i].type == "R" else (1.0, "")


def draw_run(a: dict[str, Any], folder: Path, resolution: int = MAP_RESOLUTION) -> list[Path]:
    """Convergence, 1/k map (``resolution``² points) and workspace of a run archive."""
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
    n = resolution if mech.n >= 2 else 0  # the map needs two joints
    ga, gb = (
        np.linspace(lo[0], hi[0], n),
        np.linspace(lo[min(1, mech.n - 1)], hi[min(1, mech.n - 1)], n),
    )
    A, B = np.meshgrid(ga, gb, indexing="xy")
    qg = np.tile(mid, (A.size, 1))
    if n:
        qg[:, 0], qg[:, 1] = A.ravel(), B.ravel()
    rng = np.random.default_rng(np.asarray(a["attrs"]["keys"]["figures"], np.uint32))
    qc = lo + (hi - lo) * rng.uniform(size=(4000, mech.n))  # NumPy: no threefry compile
    X = _full(mech, np.stack(list(designs.values())))
    z, P = _kernel(mech, s)(X, np.concatenate([qg, qc]).astype(X.dtype))  # one XLA program
    z, P = np.asarray(z), np.asarray(P)
    if mech.n >= 2:
        fa, ua = _unit(mech, 0, s)
        fb, ub = _unit(mech, 1, s)
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        for i, (ax, lab) in enumerate(zip(axes, designs, strict=True)):
            zi = z[i, : A.size].reshape(A.shape)
            im = ax.pcolormesh(ga * fa, gb * fb, zi, shading="auto", cmap="viridis",
                               rasterized=True)  # fmt: skip
            fig.colorbar(im, ax=ax, label="1/k")
            ax.set_xlabel(f"q1 ({ua})" if ua else "q1")
            ax.set_ylabel(f"q2 ({ub})" if ub else "q2")
            ax.set_title(f"{lab}: mean {zi.mean():.4g}", fontsize=9, y=1.0)
        fig.suptitle(f"1/k ({s.indices.norm}-norm; rows {rows_txt}) over q1, q2, others at mid-range",
                     fontsize=10)  # fmt: skip
        fig.tight_layout()
        out += save(fig, folder, "dexterity_map")

    p, c = P[-1, A.size :], z[-1, A.size :]  # the final design's cloud
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
    ax.set_title("final design: tip positions of 4000 uniform joint samples", fontsize=9, y=1.0)
    fig.tight_layout()
    out += save(fig, folder, "workspace")
    return out
