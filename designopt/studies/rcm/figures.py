"""Figures of the planar RCM studies: convergence; η(c) for each workspace (Fig. 4a of the
paper); the 1/k map over the task cone and the joint box at c = 230 mm and at the final
design (Fig. 4b); the built arm's Monte-Carlo workspace (Fig. 6); for a replay, the target
and achieved tip paths, the joints and the tracking error.

η over the reached part of the cone (``eta_reach``) is undefined where nothing is reached
and is not drawn there; reach is a rate (clipped to [0, 1], Wilson band)."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.ticker import MaxNLocator

from designopt.figures import convergence, save, style
from designopt.numerics import montecarlo as mc
from designopt.results import ReplayRecord, RunRecord
from designopt.studies.rcm import mechanism as m
from designopt.studies.rcm import objective, workspace
from designopt.studies.rcm.settings import RcmSettings, TeleopSettings, units

N_C = 81  # points of the η(c) curves
N_MAP = 121  # grid of the 1/k maps
N_CLOUD = 20_000  # points drawn of the workspace cloud (the volume uses 100 000)

# hints for the scan figure (designopt.figures.scan)
SCAN_PANELS = {"η = mean 1/k": ("eta_box", "eta_cone", "eta_reach")}
RATES = ("reach",)
UNDEFINED_WHEN_ZERO = {"eta_reach": "reach"}


def _units(s: RcmSettings) -> dict[str, str]:
    return units(s)


def eta_curves(s: RcmSettings, keys, a_val: float, cs: np.ndarray) -> dict[str, np.ndarray]:
    """η ± SE of every workspace against c at a = a_val (both measures), one jitted call."""
    out = {}
    for meas in ("cartesian", "joint"):
        sm = s.model_copy(update={
            "variables": {"a": (1.0, 1e4), "c": (1.0, 1e4)},
            "eta": s.eta.model_copy(update={"measure": meas}),
            "constraints": s.constraints.model_copy(update={"reach_min": None}),
        })  # fmt: skip
        P = objective.problem(sm, keys, mc.out_dtype())
        X = jnp.stack([jnp.full(cs.shape, a_val), jnp.asarray(cs)], -1).astype(mc.out_dtype())
        _, aux = jax.jit(P.fn)(P.params, X, None)
        for k in ("eta_box", "eta_cone", "eta_reach"):
            out[f"{k}_{meas}"] = np.asarray(aux[k])
            out[f"{k}_{meas}_se"] = np.asarray(aux[k + "_se"])
        out["reach"], out["reach_se"] = np.asarray(aux["reach"]), np.asarray(aux["reach_se"])
    return out


def draw_eta(
    s: RcmSettings, keys, a_val: float, marks: dict[str, float], folder: Path
) -> list[Path]:
    lo, hi = s.variables.get("c", (200.0, 400.0))
    cs = np.linspace(min(lo, 200.0), max(hi, 400.0), N_C)
    cur = eta_curves(s, keys, a_val, cs)
    fig, axes = style.subplots(1, 3, figsize=(13, 3.9))
    none = cur["reach"] == 0
    for ax, meas in zip(axes[:2], ("cartesian", "joint"), strict=True):
        for k, lab in (("eta_box", "joint box"), ("eta_cone", "task cone"),
                       ("eta_reach", "reachable cone")):  # fmt: skip
            y, se = cur[f"{k}_{meas}"].copy(), cur[f"{k}_{meas}_se"]
            if k == "eta_reach":
                y[none] = np.nan  # undefined where nothing is reached
            style.band(ax, cs, y, se, label=lab)
        ax.plot([230], [0.64], "k*", ms=9, label="paper: 0.64 at c = 230")
        for (name, c), ls_ in zip(marks.items(), (":", "--"), strict=False):
            ax.axvline(c, color="0.35", lw=0.9, ls=ls_, label=f"{name}: c = {c:.1f} mm")
        ax.set_xlabel(style.label("c", "mm"))
        ax.set_ylabel(style.label("η = mean 1/k", "-"))
        ax.set_title(f"{meas} measure, a = {a_val:.1f} mm", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    style.rate_band(axes[2], cs, cur["reach"], cur["reach_se"])
    if s.constraints.reach_min is not None:
        axes[2].axhline(s.constraints.reach_min, color="r", lw=0.7, ls="--",
                        label=f"reach_min {s.constraints.reach_min:g}")  # fmt: skip
        axes[2].legend(fontsize=7)
    axes[2].set_xlabel(style.label("c", "mm"))
    axes[2].set_ylabel(style.label("fraction of cone samples reached", "-"))
    axes[2].set_title(f"reach of the joint box, a = {a_val:.1f} mm", fontsize=9)
    axes[2].grid(alpha=0.3)
    note = "; η over the reachable cone not drawn where nothing is reached" if none.any() else ""
    fig.suptitle(f"η(c) (paper Fig. 4a) over stated workspaces; cone {s.cone.apex_deg:g}°, "
                 f"depth {s.cone.depth[0]:g}-{s.cone.depth[1]:g} mm (band ± 2 SE; reach: "
                 f"Wilson interval){note}", fontsize=10)  # fmt: skip
    return save(fig, folder, "eta_c")


def draw_maps(s: RcmSettings, designs: list[tuple[str, float, float]], folder: Path) -> list[Path]:
    """1/k over the joint box and over the cone's plane for designs (label, a, c)."""
    j, cone = s.joints, s.cone
    g1 = np.linspace(*j.d1, N_MAP)
    g2 = np.linspace(*j.d2, N_MAP)
    half = np.deg2rad(cone.apex_deg / 2)
    dd = np.linspace(*cone.depth, N_MAP)
    ph = np.linspace(-half, half, N_MAP)
    Dd, Ph = np.meshgrid(dd, ph, indexing="ij")
    X, Y = Dd * np.sin(Ph), -Dd * np.cos(Ph)
    fig, axes = style.subplots(2, len(designs), figsize=(4.4 * len(designs) + 0.8, 7.6),
                               squeeze=False)  # fmt: skip
    ims = []
    for i, (lab, a, c) in enumerate(designs):
        box = np.asarray(
            jax.jit(m.inv_cond)(jnp.asarray(g1)[None, :], jnp.asarray(g2)[:, None], a, c)
        )
        kc = np.asarray(m.inv_cond_r(jnp.abs(c - jnp.asarray(Dd)), c))
        q1, q2 = m.ik(jnp.asarray(X), jnp.asarray(Y), a, 0.0, c)
        reach = (np.asarray(q1) >= j.d1[0]) & (np.asarray(q1) <= j.d1[1]) & (
            np.asarray(q2) >= j.d2[0]) & (np.asarray(q2) <= j.d2[1])  # fmt: skip
        ax = axes[0, i]
        im = ax.pcolormesh(
            g1, g2, box, shading="auto", cmap="viridis", vmin=0, vmax=1, rasterized=True
        )
        ims.append(im)
        ax.contour(g1, g2, box, levels=[0.25, 0.5, 0.75, 0.95], colors="w", linewidths=0.5)
        ax.set_xlabel(style.label("d1", "mm"))
        ax.set_ylabel(style.label("d2", "mm"))
        ax.set_title(f"{lab}: joint box\nmean {box.mean():.3f}", fontsize=8)
        ax = axes[1, i]
        im = ax.pcolormesh(
            X, Y, kc, shading="auto", cmap="viridis", vmin=0, vmax=1, rasterized=True
        )
        if not reach.all():
            ax.contour(X, Y, reach.astype(float), levels=[0.5], colors="r", linewidths=0.8)
        ims.append(im)
        ax.set_aspect("equal")
        ax.set_xlabel(style.label("x − x_R", "mm"))
        ax.set_ylabel(style.label("y", "mm"))
        ax.set_title(f"{lab}: task cone (red: joint-box reach)\nreached {100 * reach.mean():.1f} % of the grid",
                     fontsize=8)  # fmt: skip
    style.shared_scale(fig, ims, 0.0, 1.0)
    fig.colorbar(ims[0], ax=axes, label=style.label("1/k", "-"), shrink=0.6)
    fig.suptitle("1/k of the planar Jacobian (paper Fig. 4b); isotropic at depth c/2; θ1 does not "
                 "change 1/k", fontsize=10)  # fmt: skip
    return save(fig, folder, "inv_k_maps")


def draw_workspace(key: jax.Array, folder: Path) -> list[Path]:
    ws = workspace.built(key, 100_000)
    P = np.asarray(ws.points)[:N_CLOUD]
    fig = style.figure(figsize=(13, 4.0))
    ax = fig.add_subplot(1, 4, 1, projection="3d")
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], s=0.3, alpha=0.3, rasterized=True)
    for a_, n in ((ax.xaxis, "x"), (ax.yaxis, "y"), (ax.zaxis, "z")):
        a_.set_major_locator(MaxNLocator(3))
        a_.set_label_text(style.label(n, "mm"), fontsize=8)
        a_.labelpad = 0
    ax.tick_params(labelsize=6, pad=0)
    ax.set_box_aspect(None, zoom=0.7)
    for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
        a2 = fig.add_subplot(1, 4, k + 2)
        a2.scatter(P[:, i], P[:, j], s=0.2, alpha=0.3, rasterized=True)
        a2.set_xlabel(style.label("xyz"[i], "mm"))
        a2.set_ylabel(style.label("xyz"[j], "mm"))
        a2.set_aspect("equal")
        a2.grid(alpha=0.3)
    fig.suptitle(f"Workspace of the built arm (paper Fig. 6), R at the origin: "
                 f"V = {float(ws.volume):.4g} ± {float(ws.volume_se):.2g} mm³ "
                 f"({N_CLOUD} of 100 000 samples drawn)", fontsize=10)  # fmt: skip
    return save(fig, folder, "workspace")


def draw_run(rec: RunRecord, folder: Path) -> list[Path]:
    """Convergence, η(c), the 1/k maps and the built arm's workspace of a run record."""
    s: RcmSettings = rec.config.study
    keys = rec.keys()
    des = s.design() | rec.x
    out: list[Path] = []
    br = rec.best_run
    out += convergence(br, [k for k in ("f", "eta", "reach") if k in br], folder, "Best run",
                       units=_units(s), rates={"reach": None}, fidelity=rec.fidelity)  # fmt: skip
    out += draw_eta(s, keys, des["a"], {"final": des["c"], "built": 250.0}, folder)
    out += draw_maps(s, [("c = 230, a = 120", 120.0, 230.0), ("built (120, 250)", 120.0, 250.0),
                         (f"final ({des['a']:.1f}, {des['c']:.1f})", des["a"], des["c"])], folder)  # fmt: skip
    out += draw_workspace(keys["figures"], folder)
    return out


def draw_teleop(rec: ReplayRecord, folder: Path) -> list[Path]:
    """Target and achieved tip paths, master and slave in (x, y), the tracking error and
    each coordinate against time; a planar path (z constant) is drawn in (x, y) and its
    constant z stated instead of a panel of z(t)."""
    s: TeleopSettings = rec.config.study
    t = rec.arrays("teleop")
    tt, cmd, tip, err = t["t"], t["command"], t["tip"], t["error"]
    clutch = np.asarray(t["clutch"], bool)
    cl = np.asarray(t["clamped"], bool)
    span = np.ptp(np.concatenate([cmd, tip]), axis=0)
    planar = span[2] <= 1e-6 * max(span[0], span[1], 1e-300)
    fig = style.figure(figsize=(13, 7))
    if planar:
        ax = fig.add_subplot(2, 3, 1)
        ax.plot(cmd[:, 0], cmd[:, 1], lw=1.2, label="target (commanded)")
        ax.plot(tip[:, 0], tip[:, 1], lw=0.8, ls="--", label="achieved")
        ax.set_aspect("equal")
        ax.set_xlabel(style.label("x", "mm"))
        ax.set_ylabel(style.label("y", "mm"))
        ax.grid(alpha=0.3)
        ax.set_title(f"slave tip path (planar: z = {cmd[0, 2]:.3g} mm throughout)", fontsize=9)
    else:
        ax = fig.add_subplot(2, 3, 1, projection="3d")
        ax.plot(*cmd.T, lw=1.2, label="target (commanded)")
        ax.plot(*tip.T, lw=0.8, ls="--", label="achieved")
        for a_, n in ((ax.xaxis, "x"), (ax.yaxis, "y"), (ax.zaxis, "z")):
            a_.set_major_locator(MaxNLocator(4))
            a_.set_label_text(style.label(n, "mm"), fontsize=8)
        ax.tick_params(labelsize=6, pad=0)
        ax.set_title("slave tip path", fontsize=9)
    ax.legend(fontsize=7)
    ax2 = fig.add_subplot(2, 3, 2)
    m_ = t["master"]
    ax2.plot(m_[:, 0], m_[:, 1], lw=0.8, color="gray", label="master")
    ax2.plot(m_[clutch, 0], m_[clutch, 1], ".", ms=1.5, color="r", label="clutch held")
    ax2.plot(cmd[:, 0] - cmd[0, 0], cmd[:, 1] - cmd[0, 1], lw=1.2, label="slave target − start")
    ax2.set_aspect("equal")
    ax2.set_xlabel(style.label("x", "mm"))
    ax2.set_ylabel(style.label("y", "mm"))
    ax2.legend(fontsize=7, loc="center right")
    ax2.set_title(f"master and slave (x, y), {s.scale:g}:1", fontsize=9)
    ax3 = fig.add_subplot(2, 3, 3)
    ax3.plot(tt, err, lw=0.8)
    ax3.set_xlabel(style.label("t", "s"))
    ax3.set_ylabel(style.label("tracking error", "mm"))
    ax3.set_title(f"max {err.max():.2f}, mean {err.mean():.2f} mm (delay {s.delay_ms:g} ms)",
                  fontsize=9)  # fmt: skip
    ax3.grid(alpha=0.3)
    for i, lab in enumerate("xy" if planar else "xyz"):
        axi = fig.add_subplot(2, 3, 4 + i)
        axi.plot(tt, cmd[:, i], lw=1.0, label="target")
        axi.plot(tt, tip[:, i], lw=0.8, ls="--", label="achieved")
        if cl.any():
            axi.plot(tt[cl], cmd[cl, i], "r.", ms=2, label="clamped")
        axi.set_xlabel(style.label("t", "s"))
        axi.set_ylabel(style.label(lab, "mm"))
        axi.legend(fontsize=7)
        axi.grid(alpha=0.3)
    if planar:  # the joints instead of a constant z(t)
        q = np.asarray(t["q"])
        axq = fig.add_subplot(2, 3, 6)
        axq.plot(tt, q[:, 1], lw=1.0, label="d1")
        axq.plot(tt, q[:, 2], lw=1.0, label="d2")
        axq.set_xlabel(style.label("t", "s"))
        axq.set_ylabel(style.label("prismatic joints d1, d2", "mm"))
        axq.legend(fontsize=7)
        axq.grid(alpha=0.3)
    fig.suptitle("Master-slave replay through the incremental mapping (paper eq. 33)", fontsize=10)
    return save(fig, folder, "teleop")
