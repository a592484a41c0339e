"""PTPSO's penalty: the p_c(ρ) curves of seed 000 Fig. 9 and a (γ, a, ρc) sweep.

Draws ``docs/img/fig9_penalty.png`` (p_c of eq. 48 over ρ for a few (a, ρc)) and runs
every (γ, a, ρc) of a grid as one vmapped batch per function (``optim.run_batch``, common
random numbers), printing mean ± std of the final value per setting; docs/optimizers.md
quotes the table.

    python benchmarks/ptpso_tuning.py [--runs 30] [--iters 1000] [--dim 30]
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _timing import header

from designopt import optim
from designopt.core.timing import Stopwatch
from designopt.figures import plt, save
from designopt.problems.benchmarks import benchmark

GAMMAS = (1e-7, 1e-5, 1e-3, 1e-1)
AS = (2.0, 10.0, 100.0)
RHO_CS = (0.5, 0.9)


def fig9(folder: Path) -> None:
    rho = np.linspace(0, 1, 201)
    fig, ax = plt.subplots(figsize=(5, 3.4))
    for a, rc in itertools.product((2.0, 10.0, 100.0), (0.5, 0.9)):
        pc = np.asarray(optim.penalty_coefficient(jnp.asarray(rho), a, rc))
        ax.plot(rho, pc, label=f"a = {a:g}, ρc = {rc:g}")
    ax.axhline(1.0, color="k", lw=0.5, ls=":")
    ax.set_xlabel("ρ (fraction of particles within γ·d_max of the best)")
    ax.set_ylabel("penalty coefficient p_c")
    ax.set_ylim(0, 5)
    ax.legend(fontsize=7)
    ax.set_title("PTPSO penalty coefficient, eq. (48) (cf. seed 000 Fig. 9)", fontsize=9)
    fig.tight_layout()
    for p in save(fig, folder, "fig9_penalty"):
        if p.suffix == ".pdf":
            p.unlink()  # the docs keep the PNG only


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--iters", type=int, default=1000)
    ap.add_argument("--dim", type=int, default=30)
    ap.add_argument("--functions", default="sphere,rastrigin,griewank,ackley")
    a = ap.parse_args()
    fig9(Path(__file__).resolve().parents[1] / "docs" / "img")
    header(f"PTPSO (γ, a, ρc) sweep: {a.runs} runs × {a.iters} it × 50 particles, D = {a.dim}")
    grid = [dict(gamma=g, a=x, rho_c=r) for g, x, r in itertools.product(GAMMAS, AS, RHO_CS)]
    members = grid + [dict(penalty=0.0)]  # the last member is p2 (no penalty)
    for fname in a.functions.split(","):
        P = benchmark(fname, a.dim)
        with Stopwatch() as sw:
            r = optim.run_batch("p3", P, jax.random.key(0), members, 50, a.iters, a.runs,
                                dtype=jnp.float32)  # fmt: skip
        print(f"\n{fname} ({len(members)} settings × {a.runs} runs in one batch: {sw.wall:.1f} s)")
        print(f"{'γ':>8}{'a':>6}{'ρc':>6}{'mean':>12}{'std':>12}{'median':>12}")
        for m, f in zip(members, r.best_f, strict=True):
            if "penalty" in m:
                print(
                    f"{'p2 (no penalty)':>20}{f.mean():>12.3e}{f.std(ddof=1):>12.3e}{np.median(f):>12.3e}"
                )
            else:
                print(f"{m['gamma']:>8.0e}{m['a']:>6g}{m['rho_c']:>6g}"
                      f"{f.mean():>12.3e}{f.std(ddof=1):>12.3e}{np.median(f):>12.3e}")  # fmt: skip


if __name__ == "__main__":
    main()
