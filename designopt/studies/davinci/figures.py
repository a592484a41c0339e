"""Figures of a da Vinci study run: convergence along the best run, the workspace around
the RCM point H (jaw points of the dexterity samples coloured by 1/k), and the GCI
against the wrist offset l_IJ (the other variables at their final values)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt import montecarlo as mc
from designopt.figures import convergence, plt, save
from designopt.studies.base import archived_keys
from designopt.studies.davinci import mechanism as mech
from designopt.studies.davinci import objective
from designopt.studies.davinci.settings import TABLE1, DavinciSettings

N_LINE = 41
N_POINTS = 3000


def _full(s: DavinciSettings, params, x: np.ndarray) -> jnp.ndarray:
    return objective.full_designs(params, jnp.asarray(np.atleast_2d(x), mc.out_dtype()))[0]


def workspace(s: DavinciSettings, params, x: np.ndarray, folder: Path, title: str) -> list[Path]:
    """Jaw points J of the dexterity samples around H, coloured by 1/k."""
    dt = mc.out_dtype()
    xf = _full(s, params, x)
    q, inside = objective.workspace_samples(s, params, xf, dt)
    q, inside = q[:N_POINTS], np.asarray(inside[:N_POINTS])
    c = np.asarray(objective.inv_k(s, xf, q))
    _, p = mech.ARM.fk(xf, q)
    p = np.asarray(p) - np.asarray(mech.rcm_point(xf))
    fig = plt.figure(figsize=(5.6, 4.8))
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    sc = ax.scatter(p[inside, 0], p[inside, 1], p[inside, 2], s=1, c=c[inside], cmap="viridis",
                    vmin=0, vmax=1, rasterized=True)  # fmt: skip
    if (~inside).any():
        ax.scatter(p[~inside, 0], p[~inside, 1], p[~inside, 2], s=1, c="0.7", rasterized=True)
    ax.scatter([0], [0], [0], s=40, c="red", marker="x")
    ax.text(0, 0, 0, " H", color="red")
    ax.set_xlabel("x − H (mm)")
    ax.set_ylabel("y − H (mm)")
    ax.set_zlabel("z − H (mm)")
    fig.colorbar(sc, ax=ax, label="1/k (Frobenius, normalised)", shrink=0.7)
    ax.set_title(title, fontsize=9, y=1.0)
    return save(fig, folder, "workspace")


def gci_line(s: DavinciSettings, params, x: np.ndarray, names: tuple[str, ...], folder: Path,
             marks: dict[str, float]) -> list[Path]:  # fmt: skip
    """GCI ± 2 SE over l_IJ (its design range, or 2-30 mm when fixed), others at x."""
    dt = mc.out_dtype()
    lo, hi = s.variables.get("l_IJ", (2.0, 30.0))
    ls = np.linspace(lo, hi, N_LINE)
    base = np.asarray(_full(s, params, x))
    X = np.tile(base, (N_LINE, 1))
    X[:, 3] = ls
    est = jax.jit(jax.vmap(lambda xf: objective.dexterity(s, params, xf, dt)))(jnp.asarray(X, dt))
    g, se = np.asarray(est[0]), np.asarray(est[1])
    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    ax.plot(ls, g, lw=1.2)
    ax.fill_between(ls, g - 2 * se, g + 2 * se, alpha=0.25, lw=0)
    for lab, v in marks.items():
        ax.axvline(v, ls="--", lw=0.8, color="0.4")
        ax.text(v, ax.get_ylim()[1], f" {lab}", fontsize=8, va="top", rotation=90)
    ax.set_xlabel("wrist offset l_IJ (mm)")
    ax.set_ylabel("GCI (mean 1/k over the cone)")
    beta = math.degrees(float(base[1]))
    ax.set_title(f"da Vinci arm (Applied Sciences 2019): GCI vs l_IJ at β = {beta:.2f}°",
                 fontsize=9, y=1.0)  # fmt: skip
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save(fig, folder, "gci_vs_lij")


def draw_run(a: dict[str, Any], folder: Path) -> list[Path]:
    cfg = a["attrs"]["config_resolved"]
    s = DavinciSettings.model_validate(cfg["study"])
    params = objective.make_params(s, archived_keys(a), mc.out_dtype())
    names = tuple(s.variables)
    x = np.asarray(a["final"]["x"], np.float64)
    out = convergence(a["best_run"], ["f", "gci", "ik_success"], folder,
                      "da Vinci arm: objective, GCI and IK success along the best run")  # fmt: skip
    desc = ", ".join(f"{n} = {v:.3g}" for n, v in zip(names, x, strict=True))
    out += workspace(s, params, x, folder, f"final design ({desc}): jaw points around H")
    marks = {"Table 1": TABLE1["l_IJ"]}
    if "l_IJ" in names:
        marks["final"] = float(x[names.index("l_IJ")])
    out += gci_line(s, params, x, names, folder, marks)
    return out
