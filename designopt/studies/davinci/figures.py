"""Figures of a da Vinci study run: convergence along the best run, the workspace around
the RCM point H (jaw points of the dexterity samples coloured by 1/k), and the GCI
against the wrist offset l_IJ (the other variables at their final values)."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.ticker import MaxNLocator

from designopt.figures import convergence, save, style
from designopt.numerics import montecarlo as mc
from designopt.results import RunRecord
from designopt.studies.davinci import mechanism as mech
from designopt.studies.davinci import objective
from designopt.studies.davinci.settings import TABLE1, DavinciSettings

N_LINE = 41
N_POINTS = 3000
RATES = ("coverage", "ik_success", "reach")  # success rates: clipped to [0, 1], Wilson band


def _jaw_points(s: DavinciSettings, params, x: jnp.ndarray, dt) -> tuple[jnp.ndarray, ...]:
    """The first N_POINTS dexterity samples of design x (its variables): jaw points
    relative to H, their 1/k and whether they lie in the joint ranges."""
    xf = objective.full_designs(params, x[None])[0]
    q, inside = objective.workspace_samples(s, params, xf, dt)
    q, inside = q[:N_POINTS], inside[:N_POINTS]
    _, p = mech.ARM.fk(xf, q)
    return p - mech.rcm_point(xf), objective.inv_k(s, xf, q), inside


def workspace(s: DavinciSettings, params, x: np.ndarray, folder: Path, title: str) -> list[Path]:
    """Jaw points J of the dexterity samples around H, coloured by 1/k."""
    dt = mc.out_dtype()
    # one jitted call (op by op, the samples, FK and Jacobian compiled ~100 small programs)
    pts = jax.jit(lambda P, X: _jaw_points(s, P, X, dt))
    p, c, inside = (np.asarray(a) for a in pts(params, jnp.asarray(x, dt)))
    fig = style.figure(figsize=(6.2, 5.2))
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    sc = ax.scatter(p[inside, 0], p[inside, 1], p[inside, 2], s=1, c=c[inside], cmap="viridis",
                    vmin=0, vmax=1, rasterized=True)  # fmt: skip
    if (~inside).any():
        ax.scatter(p[~inside, 0], p[~inside, 1], p[~inside, 2], s=1, c="0.7", rasterized=True)
    ax.scatter([0], [0], [0], s=40, c="red", marker="x")
    ax.text(0, 0, 0, " H", color="red")
    for a_, n in ((ax.xaxis, "x − H"), (ax.yaxis, "y − H"), (ax.zaxis, "z − H")):
        a_.set_major_locator(MaxNLocator(5))
        a_.set_label_text(style.label(n, "mm"), fontsize=9)
    ax.tick_params(labelsize=7, pad=0)
    ax.set_box_aspect(None, zoom=0.85)
    fig.colorbar(sc, ax=ax, label=style.label("1/k (Frobenius, normalised)", "-"), shrink=0.6,
                 pad=0.12, location="left")  # fmt: skip
    if (~inside).any():
        ax.scatter([], [], [], s=4, c="0.7", label="outside the cone (grey)")
        ax.legend(fontsize=7, loc="upper right")
    ax.set_title(title, fontsize=9)
    return save(fig, folder, "workspace")


def gci_line(s: DavinciSettings, params, x: np.ndarray, names: tuple[str, ...], folder: Path,
             marks: dict[str, float]) -> list[Path]:  # fmt: skip
    """GCI ± 2 SE over l_IJ (its design range, or 2-30 mm when fixed), others at x."""
    dt = mc.out_dtype()
    lo, hi = s.variables.get("l_IJ", (2.0, 30.0))
    ls = np.linspace(lo, hi, N_LINE)

    def line(P, x, ls):  # one jitted call: the design row, then l_IJ along the line
        base = objective.full_designs(P, x[None])[0]
        est = jax.vmap(lambda v: objective.dexterity(s, P, base.at[3].set(v), dt))(ls)
        return est[0], est[1], base

    g, se, base = (np.asarray(a) for a in jax.jit(line)(params, jnp.asarray(x, dt),
                                                          jnp.asarray(ls, dt)))  # fmt: skip
    fig, ax = style.subplots(figsize=(5.6, 3.8))
    style.band(ax, ls, g, se, lw=1.2, label="GCI ± 2 SE")
    for (lab, v), ls_ in zip(marks.items(), ("--", ":"), strict=False):
        ax.axvline(v, ls=ls_, lw=1.0, color="0.3", label=f"{lab}: l_IJ = {v:.3g} mm")
    ax.legend(fontsize=7, loc="best")
    ax.set_xlabel(style.label("wrist offset l_IJ", "mm"))
    ax.set_ylabel(style.label("GCI (mean 1/k over the cone)", "-"))
    beta = math.degrees(float(base[1]))
    ax.set_title(f"da Vinci arm (Applied Sciences 2019): GCI vs l_IJ at β = {beta:.2f}°",
                 fontsize=9)  # fmt: skip
    ax.grid(alpha=0.3)
    return save(fig, folder, "gci_vs_lij")


def draw_run(rec: RunRecord, folder: Path) -> list[Path]:
    """Convergence, workspace and GCI line of a run record."""
    s: DavinciSettings = rec.config.study
    params = objective.make_params(s, rec.keys(), mc.out_dtype())
    names = tuple(rec.names)
    x = np.asarray(list(rec.x.values()), np.float64)
    units = {k: "-" for k in ("f", "gci", *RATES)}
    out = convergence(rec.best_run, ["f", "gci", "ik_success"], folder,
                      "da Vinci arm: objective, GCI and IK success along the best run",
                      units=units, rates={"ik_success": s.indices.n_ik},
                      fidelity=rec.fidelity)  # fmt: skip
    desc = ", ".join(f"{n} = {v:.3g}" for n, v in zip(names, x, strict=True))
    out += workspace(s, params, x, folder, f"final design ({desc}): jaw points around H")
    marks = {"Table 1": TABLE1["l_IJ"]}
    if "l_IJ" in names:
        marks["final"] = rec.x["l_IJ"]
    out += gci_line(s, params, x, names, folder, marks)
    return out
