"""Figures of a sphere_rcm run: convergence along the best run; the index and the reach
over the (α12, α23) box with the final design, the paper's kinematic and hybrid optima
and the Raven II's as-built angles marked; 1/k over the cone's directions at the final
design and at (90°, 90°), and 1/k against the angle φ from joint axis 1 beside the
closed form sin φ of (90°, 90°).

Maps are computed by one jitted call of the study's own Problem on the whole grid (fewer
directions than the run: ``N_MAP_SAMPLES``); the cone maps by one jitted call of the
pointwise kernel."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from designopt.figures import convergence, save, style
from designopt.numerics import montecarlo as mc
from designopt.results import RunRecord
from designopt.studies.sphere import objective, paper
from designopt.studies.sphere.settings import DESIGN_KEYS, SphereSettings, units

N_GRID = 61  # points per link angle of the maps
N_MAP_SAMPLES = 1024  # directions per design of the maps (rqmc, 8 replicates)
N_CONE = 121  # grid of the cone maps (per axis of the cap's projection)

# hints for the scan figure (designopt.figures.scan)
SCAN_PANELS = {"mean 1/k": ("gci", "gci_reached")}
RATES = ("reach",)
UNDEFINED_WHEN_ZERO = {"gci_reached": "reach"}

MARKS = (  # (label, (α12, α23), marker, colour)
    ("kinematic optimum (paper)", paper.KINEMATIC_OPTIMUM, "o", "tab:cyan"),
    ("hybrid optimum (paper)", paper.HYBRID_OPTIMUM, "s", "tab:orange"),
    ("Raven II as built", paper.RAVEN_II, "D", "tab:red"),
)


def index_grid(s: SphereSettings, keys, n: int = N_GRID) -> dict[str, np.ndarray]:
    """gci, reach and f over an n-point grid of every variable (one jitted call)."""
    sm = s.model_copy(update={
        "index": s.index.model_copy(update={"n_samples": N_MAP_SAMPLES, "sampler": "rqmc",
                                            "replicates": 8, "chunk": N_MAP_SAMPLES}),
    })  # fmt: skip
    P = objective.problem(sm, keys, mc.out_dtype())
    axes = [np.linspace(*s.variables[k], n) for k in s.variables]
    mesh = np.meshgrid(*axes, indexing="ij")
    X = jnp.asarray(np.stack([g.ravel() for g in mesh], -1), mc.out_dtype())
    f, aux = jax.jit(P.fn)(P.params, X, None)
    shape = tuple(len(a) for a in axes)
    out = {k: np.asarray(aux[k]).reshape(shape) for k in ("gci", "reach")}
    return out | {"f": np.asarray(f).reshape(shape), "axes": axes}


@jax.jit
def _cone(u, a12, a23):
    per, g, ok = objective.pointwise(u, a12, a23)
    return g, ok


def cone_maps(s: SphereSettings, designs: np.ndarray, n: int = N_CONE):
    """1/k over the cone's cap, projected azimuthally about its axis (the x axis toward
    joint axis 1): the grid g (n,) in degrees from the axis, 1/k (M, n, n; NaN outside the
    cap), reached (M, n, n) and φ (n, n), the angle from joint axis 1 in degrees."""
    dt = mc.out_dtype()
    half = s.cone.half_angle_deg
    g = np.linspace(-half, half, n)
    X, Y = np.meshgrid(g, g, indexing="xy")
    t, psi = np.deg2rad(np.hypot(X, Y)), np.arctan2(Y, X)
    inside = np.hypot(X, Y) <= half
    c, e1, e2 = (
        np.asarray(v)
        for v in objective.cone_frame(jnp.asarray(np.deg2rad(s.cone.axis_angle_deg), dt))
    )
    u = (np.cos(t)[..., None] * c + (np.sin(t) * np.cos(psi))[..., None] * e1
         + (np.sin(t) * np.sin(psi))[..., None] * e2).reshape(-1, 3)  # fmt: skip
    a = np.deg2rad(designs)
    r, ok = _cone(jnp.asarray(u, dt), jnp.asarray(a[:, 0], dt), jnp.asarray(a[:, 1], dt))
    M = designs.shape[0]
    r = np.where(inside, np.asarray(r).reshape(M, n, n), np.nan)
    ok = np.asarray(ok).reshape(M, n, n) & inside
    phi = np.degrees(np.arccos(np.clip(u[:, 2], -1, 1))).reshape(n, n)
    return g, r, ok, np.where(inside, phi, np.nan)


def _mark(ax, s: SphereSettings, x: dict[str, float]) -> None:
    """The final design and the published designs inside the box, with a legend."""
    v = list(s.variables)
    (lo0, hi0), (lo1, hi1) = s.variables[v[0]], s.variables[v[1]]
    for lab, (a12, a23), mk, col in MARKS:
        p = {"alpha12": a12, "alpha23": a23}
        if lo0 <= p[v[0]] <= hi0 and lo1 <= p[v[1]] <= hi1:
            ax.plot(
                p[v[1]],
                p[v[0]],
                mk,
                ms=11 if mk == "o" else 7,
                mfc="none",
                mec=col,
                mew=1.6,
                label=lab,
            )
    ax.plot(x[v[1]], x[v[0]], "*", ms=12, color="k", mec="w", label="final design")


def draw_maps(s: SphereSettings, keys, x: dict[str, float], folder: Path) -> list[Path]:
    """The index and the reach over the design box (a heat map for two variables, curves
    for one), the final design and the published ones marked."""
    grid = index_grid(s, keys)
    v = list(s.variables)
    u = units(s)
    if len(v) == 1:
        fig, ax = style.subplots(figsize=(6.4, 3.8))
        xs = grid["axes"][0]
        ax.plot(xs, grid["gci"], label="gci = mean 1/k over the cone")
        ax.plot(xs, grid["reach"], ls="--", label="reach (share of the cone)")
        ax.axvline(x[v[0]], color="k", lw=0.8, ls=":", label=f"final: {v[0]} = {x[v[0]]:.2f}°")
        ax.set_xlabel(style.label(v[0], "deg"))
        ax.set_ylabel(style.label("gci, reach", "-"))
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fixed = ", ".join(f"{k} = {val:g}°" for k, val in s.design().items() if k not in v)
        ax.set_title(f"{fixed}; {N_MAP_SAMPLES} directions per point", fontsize=9)
        return save(fig, folder, "map")
    fig, axes = style.subplots(1, 2, figsize=(11.6, 4.9))
    ims = []
    for ax, k, title in ((axes[0], "gci", "gci = mean 1/k over the cone (unreached = 0)"),
                         (axes[1], "reach", "reach: share of the cone's directions")):  # fmt: skip
        z = grid[k]
        im = ax.pcolormesh(grid["axes"][1], grid["axes"][0], z, shading="auto", cmap="viridis",
                           vmin=0, vmax=1, rasterized=True)  # fmt: skip
        ims.append(im)
        if k == "gci":
            cs = ax.contour(grid["axes"][1], grid["axes"][0], z, levels=[0.5, 0.7, 0.8, 0.9, 0.95],
                            colors="w", linewidths=0.6)  # fmt: skip
            ax.clabel(cs, fontsize=6, fmt="%.2f")
        _mark(ax, s, x)
        ax.set_xlabel(style.label(v[1], u[v[1]]))
        ax.set_ylabel(style.label(v[0], u[v[0]]))
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
    h, lab = axes[1].get_legend_handles_labels()
    fig.legend(h, lab, loc="outside lower center", ncols=len(lab), fontsize=8)
    style.shared_scale(fig, ims, 0.0, 1.0)
    fig.colorbar(ims[0], ax=axes, label=style.label("gci, reach", "-"), shrink=0.85)
    c = s.cone
    fig.suptitle(f"Spherical RCM over its link angles: cone half-angle {c.half_angle_deg:g}°, "
                 f"axis {c.axis_angle_deg:g}° from joint axis 1 ({N_MAP_SAMPLES} directions per "
                 f"design, {N_GRID}² designs)", fontsize=10)  # fmt: skip
    return save(fig, folder, "map")


def draw_cone(s: SphereSettings, x: dict[str, float], folder: Path) -> list[Path]:
    """1/k over the cone at the final design, at (90°, 90°) and at the Raven II's angles,
    and 1/k against φ with the closed form sin φ of (90°, 90°)."""
    des = s.design() | x
    final = np.array([des[k] for k in DESIGN_KEYS])
    designs = np.stack([final, np.array(paper.KINEMATIC_OPTIMUM), np.array(paper.RAVEN_II)])
    labels = [f"final ({final[0]:.2f}°, {final[1]:.2f}°)", "kinematic optimum (90°, 90°)",
              f"Raven II as built ({paper.RAVEN_II[0]:g}°, {paper.RAVEN_II[1]:g}°)"]  # fmt: skip
    g, r, ok, phi = cone_maps(s, designs)
    fig = style.figure(figsize=(13.0, 8.6))
    ax = fig.subplot_mosaic([["a", "b", "c"], ["d", "d", "d"]])
    maps = [ax["a"], ax["b"], ax["c"]]
    ims = []
    fin = np.isfinite(phi)
    for a_, ri, oki, lab in zip(maps, r, ok, labels, strict=True):
        im = a_.pcolormesh(g, g, ri, shading="auto", cmap="viridis", rasterized=True)
        ims.append(im)
        if (~oki & fin).any():
            a_.contour(g, g, oki.astype(float), levels=[0.5], colors="r", linewidths=0.8)
        a_.set_aspect("equal")
        a_.set_xlabel(style.label("toward joint axis 1", "deg"))
        a_.set_ylabel(style.label("sideways", "deg"))
        share = 100 * oki[fin].mean()
        a_.set_title(f"{lab}\nmean 1/k {np.nanmean(np.where(oki, ri, 0.0)[fin]):.4f}, reached "
                     f"{share:.1f} % (red: edge)", fontsize=8)  # fmt: skip
    style.shared_scale(fig, ims, 0.0, 1.0)
    fig.colorbar(ims[0], ax=maps, label=style.label("1/k", "-"), shrink=0.9)
    d = ax["d"]
    for ri, oki, lab, mk in zip(r, ok, labels, (".", "x", "+"), strict=True):
        sel = fin & oki
        d.plot(phi[sel][::5], ri[sel][::5], mk, ms=3, alpha=0.5, label=lab)
    ph = np.linspace(np.nanmin(phi), np.nanmax(phi), 200)
    d.plot(ph, np.sin(np.deg2rad(ph)), "k--", lw=1.2, label="closed form at (90°, 90°): sin φ")
    d.set_xlabel(style.label("φ, the angle between joint axis 1 and the tool", "deg"))
    d.set_ylabel(style.label("1/k", "-"))
    d.grid(alpha=0.3)
    d.legend(fontsize=7, loc="lower right")
    d.set_title("1/k at the reached directions against φ: a function of φ alone", fontsize=9)
    fig.suptitle("Isotropy of the tool direction's Jacobian over the cone of tool directions, "
                 "projected about the cone's axis (angles from it)", fontsize=10)  # fmt: skip
    return save(fig, folder, "cone")


def draw_run(rec: RunRecord, folder: Path) -> list[Path]:
    """Convergence, the maps over the link angles and the 1/k maps over the cone."""
    s: SphereSettings = rec.config.study
    x = {k: float(v) for k, v in rec.x.items()}
    out: list[Path] = []
    br = rec.best_run
    out += convergence(br, [k for k in ("f", "gci", "reach") if k in br], folder, "Best run",
                       units=units(s), rates={"reach": None}, fidelity=rec.fidelity)  # fmt: skip
    out += draw_maps(s, rec.keys(), x, folder)
    out += draw_cone(s, x, folder)
    return out
