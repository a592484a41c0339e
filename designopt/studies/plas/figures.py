"""Figures of a plas run: convergence of f and vel_rel along the best run; mismatch maps
over (θ2, θ3) (θ4 = 0) for the built master and the final design (velocity mismatch of a
joint-2 motion relative to the master's tip speed, eq. 29 / |v_m|, and the tip-displacement
mismatch after moving from home); the counterbalance m(θ) and I(θ) of §2.1.2."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from designopt.figures import convergence, save, style
from designopt.numerics import montecarlo as mc
from designopt.results import RunRecord
from designopt.studies.plas import mechanism as m
from designopt.studies.plas.objective import pointwise
from designopt.studies.plas.settings import INDEX_UNITS, PlasSettings

N_GRID = 81  # default map resolution: each point solves the slave's tip (dearer than 1/k)


@jax.jit
def _maps(master, slave, theta, u):
    pw = pointwise(master, slave, theta, u, 16)
    rel = jnp.where(pw["vm"] > 0, pw["dv"] / jnp.where(pw["vm"] > 0, pw["vm"], 1.0), 0.0)
    return rel, pw["dp"]


def mismatch_maps(s: PlasSettings, designs: np.ndarray, n: int = N_GRID):
    """(θ2 deg, θ3 deg, rel (M, n, n), dp (M, n, n)) over the joint box's (θ2, θ3), θ4 = 0,
    for a joint-2 rate (u = e2)."""
    dt = mc.out_dtype()
    (a0, a1), (b0, b1), _ = s.joint_ranges_deg.rows()
    g2, g3 = np.linspace(a0, a1, n), np.linspace(b0, b1, n)
    A, B = np.meshgrid(g2, g3, indexing="xy")
    theta = np.deg2rad(np.stack([A.ravel(), B.ravel(), 0 * A.ravel()], -1))
    u = np.zeros_like(theta)
    u[:, 0] = 1.0
    slave = np.array([s.slave.a2, s.slave.a3, s.slave.d5])
    rel, dp = _maps(jnp.asarray(designs, dt), jnp.asarray(slave, dt), jnp.asarray(theta, dt),
                    jnp.asarray(u, dt))  # fmt: skip
    M = designs.shape[0]
    return g2, g3, np.asarray(rel).reshape(M, n, n), np.asarray(dp).reshape(M, n, n)


def _master(s: PlasSettings, names: list[str], x: np.ndarray) -> np.ndarray:
    d = s.design() | {n: float(v) for n, v in zip(names, x, strict=True)}
    return np.array([d[k] for k in m.MASTER_KEYS])


def draw_run(rec: RunRecord, folder: Path, resolution: int = N_GRID) -> list[Path]:
    """Convergence, mismatch maps (``resolution``² points) and counterbalance of a run."""
    s: PlasSettings = rec.config.study
    names = rec.names
    x = np.asarray(list(rec.x.values()), np.float64)
    out: list[Path] = []

    br = rec.best_run
    inds = [k for k in ("f", "vel_rel", "pos_mean") if k in br]
    out += convergence(br, inds, folder, "Best run", units=INDEX_UNITS,
                       fidelity=rec.fidelity)

    designs = np.stack([np.array([m.BUILT[k] for k in m.MASTER_KEYS]), _master(s, names, x)])
    labels = ["built master (a2' = 138, d6 = 60)",
              "final: " + ", ".join(f"{n} = {v:.1f}" for n, v in zip(names, x, strict=True))]  # fmt: skip
    out += draw_maps(s, designs, labels, folder, resolution=resolution)

    out += draw_counterbalance(s, [60.0, float(designs[1, 2])], folder)
    return out


def draw_maps(s: PlasSettings, designs: np.ndarray, labels: list[str], folder: Path,
              name: str = "mismatch_map", resolution: int = N_GRID) -> list[Path]:  # fmt: skip
    g2, g3, rel, dp = mismatch_maps(s, designs, resolution)
    M = designs.shape[0]
    fig, axes = style.subplots(2, M, figsize=(4.6 * M + 0.6, 7.2), squeeze=False)
    vmax = [max(100 * rel.max(), 1e-9), max(dp.max(), 1e-9)]
    for i, (zs, lab, unit) in enumerate(((100 * rel, "|Δv| / |v_m|, joint-2 motion", "%"),
                                         (dp, "|Δp| after home → θ", "mm"))):  # fmt: skip
        ims = []
        for j in range(M):
            z = zs[j]
            ax = axes[i, j]
            ims.append(ax.pcolormesh(g2, g3, z, shading="auto", cmap="viridis", vmin=0,
                                     vmax=vmax[i], rasterized=True))  # fmt: skip
            cs = ax.contour(g2, g3, z, levels=6, colors="w", linewidths=0.5)
            ax.clabel(cs, fontsize=6, fmt="%.3g")
            ax.set_xlabel(style.label("θ2", "deg"))
            ax.set_ylabel(style.label("θ3", "deg"))
            ax.set_title(f"{labels[j]}\nmean {z.mean():.3g}, max {z.max():.3g} {unit}", fontsize=8)
        style.shared_scale(fig, ims, 0.0, vmax[i])
        fig.colorbar(ims[0], ax=list(axes[i]), label=style.label(lab, unit))
    fig.suptitle("Master-slave tip mismatch over (θ2, θ3), θ4 held at 0° (mid-range)", fontsize=10)
    return save(fig, folder, name)


def draw_counterbalance(s: PlasSettings, d6s: list[float], folder: Path) -> list[Path]:
    cb = s.counterbalance
    th = np.linspace(0.0, 45.0, 91)
    fig, axes = style.subplots(1, 2, figsize=(8.8, 3.4))
    for d6 in dict.fromkeys(d6s):
        L = cb.L_mm + cb.L_per_d6 * (d6 - m.BUILT["d6"])
        mass = np.asarray(m.counterbalance_mass(cb.M_g, L, cb.r_mm, cb.l_mm, np.deg2rad(th)))
        inertia = np.asarray(m.counterbalance_inertia(cb.M_g, L / 10, mass, cb.l_mm / 10))
        axes[0].plot(th, mass, label=f"d6 = {d6:.1f} mm (L = {L / 10:.2f} cm)")
        axes[1].plot(th, inertia / 1e3, label=f"d6 = {d6:.1f} mm")
    for ax in axes:
        ax.axvline(cb.theta_deg, color="k", lw=0.6, ls=":")
        ax.set_xlabel(style.label("tilt θ of joint 4", "deg"))
        ax.grid(alpha=0.3)
    axes[0].axhline(460, color="r", lw=0.6, ls="--", label="thesis: about 460 g at 25°")
    axes[0].set_ylabel(style.label("counterweight m", "g"))
    axes[1].set_ylabel(style.label("I = M L² + m l²", "kg·cm²"))
    axes[0].legend(fontsize=7)
    fig.suptitle("Counterbalance of joint 4 (§2.1.2, eq. 1)", fontsize=10)
    return save(fig, folder, "counterbalance")
