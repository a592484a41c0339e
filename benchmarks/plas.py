"""Numbers and figures of docs/plas.md (Study D, seed 004), from the study's own code.

    .venv/bin/python benchmarks/plas.py [--run results/plas/plas.h5]
        [--scan results/plas/plas_scan.h5] [--img docs/img]

Prints the reproduction table, Table 6 side by side, the tip-error readings of Fig. 23-24,
the built master against the run's optimum (paired SE) and a few variants; writes small
PNGs (mismatch maps, scan heat map, counterbalance) to --img.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from designopt.app import config, pipeline  # noqa: E402
from designopt.io import archive  # noqa: E402
from designopt.studies.plas import figures as F  # noqa: E402
from designopt.studies.plas import mechanism as m  # noqa: E402
from designopt.studies.plas import paper as P  # noqa: E402
from designopt.studies.plas.settings import PlasSettings  # noqa: E402


def table6() -> None:
    print("\nTable 6 side by side: seed's printed eq. (28) | ours (mechanism.mapping_factors)"
          " | ratio of the kernel Jacobians' v_y / v_z entries")  # fmt: skip
    sl, ms = m.slave_row(), m.master_rows({})
    for deg in ((0, 0, 0), (30, 0, 0), (0, 30, 0), (0, 0, 30), (20, 40, -20), (30, 60, 30)):
        th = np.deg2rad(np.array([deg], float))
        seed = np.array(P.eq28_factors(*th.T)).ravel()
        ours = np.array(
            m.mapping_factors(jnp.asarray(ms[0]), jnp.asarray(sl[0]), jnp.asarray(th))
        ).ravel()
        q = m.q4(jnp.asarray(th))
        Js = np.asarray(m.SLAVE.jacobian(sl, q, rows=(1, 2), cols=(0, 1, 2)))[0, 0]
        Jm = np.asarray(m.MASTER.jacobian(ms, q, rows=(1, 2), cols=(0, 1, 2)))[0, 0]
        jr = np.array([Jm[0, 0] / Js[0, 0], Jm[0, 1] / Js[0, 1], Jm[1, 2] / Js[1, 2]])
        f = lambda v: " ".join(f"{x:.4f}" for x in v)  # noqa: E731
        print(f"| {deg} | {f(seed)} | {f(ours)} | {f(jr)} |")


def reproduction() -> None:
    print("\nReproduction (seed → ours):")
    for j, (mdeg, sdeg, travel) in P.REPRODUCE.items():
        s, pm, ps = P.single_joint_motion(j, mdeg)
        print(f"| joint {j} | {mdeg:g}° → {sdeg:g}°, {travel} mm | {s:.2f}°, master {pm:.2f} mm, "
              f"slave {ps:.2f} mm |")  # fmt: skip
    print(f"| counterbalance | about 460 g | {P.eq1_counterbalance():.1f} g |")


def readings() -> None:
    print("\nFig. 23-24 tip errors, every reading (mm):")
    r30, r60 = P.tip_error_readings(30.0), P.tip_error_readings(60.0)
    for k in r30:
        print(f"| {k} | {r30[k]:.2f} | {r60[k]:.2f} |")


def compare(run: Path | None) -> None:
    cfg, _ = config.load("configs/plas.yaml")
    designs = [{"a2p": 138.0, "d6": 60.0}]
    if run is not None and run.exists():
        a = archive.read(run)
        x = a["final"]["x"]
        designs.append({"a2p": float(x[0]), "d6": float(x[1])})
    print("\nBuilt master against the optimum (configs/plas.yaml samples):")
    keys = ("vel_rel", "vel_reduction", "vel_abs", "vel_max", "pos_mean", "pos_max",
            "k2_min", "k2_max", "k3_max", "k4", "reach", "counterweight", "inertia")  # fmt: skip
    for d in designs:
        r = pipeline.evaluate(cfg, d)
        txt = ", ".join(f"{k} = {r[k]:.5g}" + (f" ± {r[k + '_se']:.2g}" if k + "_se" in r and r[k + "_se"] else "")
                        for k in keys)  # fmt: skip
        print(f"  {d}: f = {r['f']:.5g} ± {r['f_se']:.2g}; {txt}; violation {r['violation']:.3g}")
    # a3' as a third length: the master can then be a scaled copy of the slave
    raw = cfg.model_dump(by_alias=True)
    raw["study"]["variables"] = {"a2p": [80, 240], "a3p": [0, 60], "d6": [30, 120]}
    raw["study"]["fixed"] = {}
    cfg3 = config.validate(raw, "a3p")
    for d in ({"a2p": 100.0, "a3p": 30.0, "d6": 60.0}, {"a2p": 138.0, "a3p": 0.0, "d6": 60.0}):
        r = pipeline.evaluate(cfg3, d)
        print(f"  a3' free {d}: vel_rel = {r['vel_rel']:.3g} ± {r['vel_rel_se']:.1g}, "
              f"pos_mean = {r['pos_mean']:.3g} ± {r['pos_mean_se']:.1g} mm, k4 = {r['k4']:.3g}, "
              f"violation {r['violation']:.3g}")  # fmt: skip


def images(run: Path | None, scan: Path | None, img: Path) -> None:
    import matplotlib

    matplotlib.rcParams["savefig.dpi"] = 60
    from designopt.figures import plt

    s = PlasSettings()
    img.mkdir(parents=True, exist_ok=True)
    designs = [np.array([138.0, 0.0, 60.0])]
    labels = ["built master (a2' = 138, d6 = 60)"]
    if run is not None and run.exists():
        x = archive.read(run)["final"]["x"]
        designs.append(np.array([x[0], 0.0, x[1]]))
        labels.append(f"optimum (a2' = {x[0]:.1f}, d6 = {x[1]:.1f})")
    tmp = img / "_plas_tmp"
    for p in F.draw_maps(s, np.stack(designs), labels, tmp) + F.draw_counterbalance(
        s, [60.0, float(designs[-1][2])], tmp
    ):
        if p.suffix == ".png":
            from PIL import Image

            im = Image.open(p)
            im = im.resize((im.width * 3 // 5, im.height * 3 // 5), Image.LANCZOS)
            im.convert("RGB").quantize(128).save(img / f"plas_{p.name}", optimize=True)
            p.unlink()
        else:
            p.unlink()
    tmp.rmdir()
    if scan is not None and scan.exists():
        sc = archive.read(scan)["scan"]
        n0, n1 = sc["attrs"]["shape"]
        X = sc["x"]
        g0, g1 = X[:, 0].reshape(n0, n1)[:, 0], X[:, 1].reshape(n0, n1)[0]
        fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.8))
        feas = sc["violation"].reshape(n0, n1) <= 0
        for ax, k, lab in ((axes[0], "vel_rel", "vel_rel (Σ|Δv| / Σ|v_m|)"),
                           (axes[1], "pos_mean", "pos_mean (mm)")):  # fmt: skip
            z = sc[k].reshape(n0, n1)
            im = ax.pcolormesh(g1, g0, z, shading="auto", cmap="viridis", rasterized=True)
            ax.contour(g1, g0, feas.astype(float), levels=[0.5], colors="r", linewidths=1)
            fig.colorbar(im, ax=ax, label=lab)
            ax.plot([60], [138], "w*", ms=10, label="built")
            if len(designs) > 1:
                ax.plot([designs[1][2]], [designs[1][0]], "r*", ms=10, label="optimum")
            ax.set_xlabel("d6 (mm)")
            ax.set_ylabel("a2' (mm)")
            ax.legend(fontsize=7, loc="lower right")
        fig.suptitle("Scan over (a2', d6); red line: edge of the feasible set", fontsize=10)
        fig.tight_layout()
        fig.savefig(img / "plas_scan.png", bbox_inches="tight", dpi=90)
        plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", type=Path, default=Path("results/plas/plas.h5"))
    ap.add_argument("--scan", type=Path, default=Path("results/plas/plas_scan.h5"))
    ap.add_argument("--img", type=Path, default=Path("docs/img"))
    a = ap.parse_args()
    reproduction()
    table6()
    readings()
    compare(a.run)
    images(a.run, a.scan, a.img)


if __name__ == "__main__":
    main()
