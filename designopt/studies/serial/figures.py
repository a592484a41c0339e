"""Figures of a serial-study run: convergence of f and its indices along the best run,
1/k over two joints for the initial and final design (one colour scale), and the final
design's workspace coloured by 1/k.

The map's joints are q2, q3 for chains of three or more joints (q1 turns the whole arm
about the base axis and leaves 1/k unchanged), else q1, q2. The other joints are held at
:func:`held`: each at its mid-range or a quarter point (mid ± range/4), whichever gives the
final design the most dexterous slice, joint by joint, so a slice never sits on a
singularity such as the PUMA 560's wrist at q5 = 0. The figure states where they are."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.ticker import MaxNLocator

from designopt import montecarlo as mc
from designopt.figures import MAP_RESOLUTION, convergence, save, style
from designopt.results import RunRecord
from designopt.studies.serial.mechanism import Mechanism, build
from designopt.studies.serial.objective import measures
from designopt.studies.serial.settings import ROWS, SerialSettings


def STUDY_UNITS(s: SerialSettings) -> dict[str, str]:  # noqa: N802
    from designopt.studies.serial import STUDY

    return STUDY.units(s)


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
    return (180 / np.pi, "deg") if _revolute(s, i) else (1.0, "L")


def _revolute(s: SerialSettings, i: int) -> bool:
    j = getattr(s.chain, "joints", None)
    return j[i].type == "R" if j is not None else True


def map_joints(n: int) -> tuple[int, int]:
    """The two joints a map is drawn over (see the module docstring)."""
    return (1, 2) if n >= 3 else (0, min(1, n - 1))


def _grid(lo, hi, pair, held, n):
    ga, gb = np.linspace(lo[pair[0]], hi[pair[0]], n), np.linspace(lo[pair[1]], hi[pair[1]], n)
    A, B = np.meshgrid(ga, gb, indexing="xy")
    q = np.tile(held, (A.size, 1))
    q[:, pair[0]], q[:, pair[1]] = A.ravel(), B.ravel()
    return ga, gb, q


def held(mech: Mechanism, s: SerialSettings, X: np.ndarray, pair: tuple[int, int],
         n: int = 15) -> np.ndarray:  # fmt: skip
    """Where the joints off the map are held (rad / length): joint by joint, the mid-range
    or quarter point (mid ± range/4) with the largest mean 1/k of design ``X`` (1, P) over
    a coarse n×n slice."""
    lo, hi = mech.lower, mech.upper
    q = 0.5 * (lo + hi)
    kern = _kernel(mech, s)
    for j in (j for j in range(mech.n) if j not in pair):
        cands = q[j] + np.array([0.0, 0.25, -0.25]) * (hi[j] - lo[j])
        qs = []
        for v in cands:
            h = q.copy()
            h[j] = v
            qs.append(_grid(lo, hi, pair, h, n)[2])
        z = np.asarray(kern(X, np.concatenate(qs).astype(X.dtype))[0][0]).reshape(len(cands), -1)
        q[j] = cands[int(np.argmax(z.mean(axis=1) - 1e-9 * np.arange(len(cands))))]
    return q


def draw_run(rec: RunRecord, folder: Path, resolution: int = MAP_RESOLUTION) -> list[Path]:
    """Convergence, 1/k map (``resolution``² points) and workspace of a run record."""
    s: SerialSettings = rec.config.study
    mech = build(s)
    br = rec.best_run
    designs = {
        "initial (iteration 0)": rec.history_x[rec.best_run_index, 0],
        "final": np.asarray(list(rec.x.values()), np.float64),
    }
    out = []
    out += convergence(br, ["f", *s.index_names()], folder, "Best run: objective and indices",
                       units=STUDY_UNITS(s))  # fmt: skip

    rows_txt = ", ".join(ROWS[r] for r in s.indices.rows())
    units = STUDY_UNITS(s)
    lo, hi = mech.lower, mech.upper
    X = _full(mech, np.stack(list(designs.values())))
    pair = map_joints(mech.n)
    n = resolution if mech.n >= 2 else 0  # the map needs two joints
    hq = held(mech, s, X[-1:], pair) if n else 0.5 * (lo + hi)
    ga, gb, qg = _grid(lo, hi, pair, hq, n)
    rng = np.random.default_rng(np.asarray(jax.random.key_data(rec.keys()["figures"]), np.uint32))
    qc = lo + (hi - lo) * rng.uniform(size=(4000, mech.n))  # NumPy: no threefry compile
    z, P = _kernel(mech, s)(X, np.concatenate([qg, qc]).astype(X.dtype))  # one XLA program
    z, P = np.asarray(z), np.asarray(P)
    m2 = ga.size * gb.size
    if mech.n >= 2:
        fa, ua = _unit(mech, pair[0], s)
        fb, ub = _unit(mech, pair[1], s)
        fig, axes = style.subplots(1, 2, figsize=(10, 4.0))
        ims = []
        for i, (ax, lab) in enumerate(zip(axes, designs, strict=True)):
            zi = z[i, :m2].reshape(gb.size, ga.size)
            ims.append(ax.pcolormesh(ga * fa, gb * fb, zi, shading="auto", cmap="viridis",
                                     rasterized=True))  # fmt: skip
            ax.set_xlabel(style.label(f"q{pair[0] + 1}", ua))
            ax.set_ylabel(style.label(f"q{pair[1] + 1}", ub))
            ax.set_title(f"{lab}: mean {zi.mean():.4g}", fontsize=9)
        style.shared_scale(fig, ims)
        fig.colorbar(ims[0], ax=list(axes), label=style.label("1/k", style.DIMENSIONLESS))
        others = [j for j in range(mech.n) if j not in pair]
        txt = style.held_text({f"q{j + 1}": f"{hq[j] * _unit(mech, j, s)[0]:.3g} "
                               f"{_unit(mech, j, s)[1]}" for j in others})  # fmt: skip
        fig.suptitle(f"1/k ({s.indices.norm}-norm; rows {rows_txt}) over q{pair[0] + 1}, "
                     f"q{pair[1] + 1}" + (f"\nother joints {txt}" if txt else
                                           "\n(q1 turns the whole arm: 1/k does not change along it)"),
                     fontsize=10)  # fmt: skip
        out += save(fig, folder, "dexterity_map")

    p, c = P[-1, m2:], z[-1, m2:]  # the final design's cloud
    planar = np.ptp(p[:, 2]) <= 1e-9 * max(np.ptp(p[:, :2]), 1e-300)
    fig = style.figure(figsize=(5.4, 4.8))
    L = units.get("__length__", "L")
    if planar:
        ax = fig.add_subplot(1, 1, 1)
        sc = ax.scatter(p[:, 0], p[:, 1], s=2, c=c, cmap="viridis", rasterized=True)
        ax.set_aspect("equal")
    else:
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        sc = ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=1, c=c, cmap="viridis", rasterized=True)
        ax.set_zlabel(style.label("z", L))
        for a_ in (ax.xaxis, ax.yaxis, ax.zaxis):
            a_.set_major_locator(MaxNLocator(5))
    ax.set_xlabel(style.label("x", L))
    ax.set_ylabel(style.label("y", L))
    fig.colorbar(sc, ax=ax, label=style.label("1/k", style.DIMENSIONLESS), shrink=0.7, pad=0.1)
    ax.set_title("final design: tip positions of 4000 uniform joint samples\n"
                 "(L: the chain's length unit)", fontsize=9)  # fmt: skip
    out += save(fig, folder, "workspace")
    return out


def cloud(rec: RunRecord, n: int = 8000) -> dict[str, Any]:
    """The final design's workspace for the interactive report: tip positions of ``n``
    uniform joint samples (the run's ``figures`` stream), coloured by 1/k."""
    s: SerialSettings = rec.config.study
    mech = build(s)
    lo, hi = mech.lower, mech.upper
    rng = np.random.default_rng(np.asarray(jax.random.key_data(rec.keys()["figures"]), np.uint32))
    q = lo + (hi - lo) * rng.uniform(size=(n, mech.n))
    X = _full(mech, np.asarray(list(rec.x.values()), np.float64))
    z, P = _kernel(mech, s)(X, q.astype(X.dtype))
    length = STUDY_UNITS(s).get("__length__", "L")
    return {"xyz": np.asarray(P[0], np.float64), "value": np.asarray(z[0], np.float64),
            "label": f"1/k ({s.indices.norm}-norm)", "unit": "-", "xyz_unit": length}  # fmt: skip
