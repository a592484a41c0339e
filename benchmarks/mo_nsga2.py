"""NSGA-II: designopt's (all runs one vmapped JAX program) against pymoo's, same budget.

ZDT1, ZDT2, ZDT3 (D = 30) and DTLZ2 (3 objectives, D = 12), population 100, 250
generations (the first one random: 25 000 evaluations per run, as pymoo's
``("n_gen", 250)``), 11 runs each, on this machine in this process. Both use pymoo 0.6's
NSGA-II defaults (binary tournament, SBX eta 15 prob 0.9, polynomial mutation eta 20,
per-variable rate 1/D). The hypervolume of each run's final non-dominated feasible set is
computed by the same exact routine (``designopt.numerics.pareto.hypervolume``, checked against
moocore in tests/test_pareto.py) against the reference point (1.1, …, 1.1).

Printed per problem: median [min–max] hypervolume of both, the optimum (the true front's
hypervolume, sampled densely), the Mann-Whitney p-value, the wall time of all 11 runs
for each (ours: one ``optim.run`` call after a compiling call on another key, so compile
is printed apart, median of ``--repeat`` calls; pymoo: the 11 ``minimize`` calls one after
another), the process CPU times (all threads; less sensitive to other jobs on a shared
machine) and the ratios.
Targets (issue 26): median HV ≥ pymoo's on all four; our wall ≤ 1/5 of pymoo's.

    python benchmarks/mo_nsga2.py [--runs 11] [--pop 100] [--gens 250] [--repeat 3]
                                  [--problems zdt1,zdt2,zdt3,dtlz2] [--float32]
                                  [--survival pruning|crowding]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _timing import header  # noqa: E402
from scipy.stats import mannwhitneyu  # noqa: E402

from designopt import optim  # noqa: E402
from designopt.numerics import pareto as pa  # noqa: E402
from designopt.problems.multi import multi_benchmark, true_front  # noqa: E402


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            txt = f.read()
        model = next(ln.split(":", 1)[1].strip() for ln in txt.splitlines() if "model name" in ln)
        flags = " ".join(x for x in ("avx2", "avx512f") if f" {x}" in txt)
        return f"{model} ({os.cpu_count()} cores; {flags})"
    except (OSError, StopIteration):
        return "unknown CPU"


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "?"


def _front_hv(F: np.ndarray, v: np.ndarray | None, ref: np.ndarray) -> float:
    keep = np.ones(len(F), bool) if v is None else v == 0
    F = F[keep]
    return pa.hypervolume(F[pa.non_dominated(F)], ref) if len(F) else 0.0


def ours(name: str, args, dtype) -> tuple[list[float], float, float, list[float]]:
    P = multi_benchmark(name)
    m = P.n_objectives
    ref = np.full(m, 1.1)

    def go(seed: int):
        return optim.run("nsga2", P, jax.random.key(seed), args.pop, args.gens - 1, args.runs,
                         dtype=dtype, ref_point=ref, survival=args.survival)  # fmt: skip

    t0 = time.perf_counter()
    go(10_000)  # compiles
    first = time.perf_counter() - t0
    walls, cpus = [], []
    for rep in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        r = go(rep)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    f, v = r.front.f, r.front.v
    hv = [_front_hv(f[i], v[i], ref) for i in range(args.runs)]
    if m <= 3:  # the in-loop JAX hypervolume of the last population agrees
        last = np.asarray(r.history_population)[:, -1]  # (best_f: the archive's, ≥ it)
        assert np.allclose(last, hv, rtol=1e-6, atol=1e-9), (last, hv)
    return hv, first - min(walls), statistics.median(walls), walls + cpus


def peer(name: str, args) -> tuple[list[float], float, float] | None:
    try:
        from pymoo.algorithms.moo.nsga2 import NSGA2
        from pymoo.optimize import minimize
        from pymoo.problems import get_problem
    except ImportError:
        print("  pymoo not installed (bench extra): peer skipped")
        return None
    prob = get_problem(name, n_var=12, n_obj=3) if name == "dtlz2" else get_problem(name)
    ref = np.full(prob.n_obj, 1.1)
    t0, c0 = time.perf_counter(), time.process_time()
    Fs = []
    for seed in range(args.runs):
        res = minimize(prob, NSGA2(pop_size=args.pop), ("n_gen", args.gens), seed=seed,
                       verbose=False)  # fmt: skip
        Fs.append(res.F)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    hv = [_front_hv(F, None, ref) for F in Fs]
    return hv, wall, cpu


def fmt(x: list[float]) -> str:
    return f"{statistics.median(x):.5f} [{min(x):.5f}–{max(x):.5f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=11)
    ap.add_argument("--pop", type=int, default=100)
    ap.add_argument("--gens", type=int, default=250)
    ap.add_argument("--repeat", type=int, default=3, help="timed repeats of our 11 runs")
    ap.add_argument("--problems", default="zdt1,zdt2,zdt3,dtlz2")
    ap.add_argument("--float32", action="store_true", help="our runs in float32")
    ap.add_argument("--survival", choices=("crowding", "pruning"), default="pruning",
                    help="our NSGA-II's survival (option survival; pymoo's is crowding)")  # fmt: skip
    args = ap.parse_args()
    dtype = jnp.float32 if args.float32 else jnp.float64
    header("NSGA-II: designopt vs pymoo")
    print(f"CPU: {_cpu()}; load average at start: {_load()}")
    print(f"{args.runs} runs × population {args.pop} × {args.gens} generations "
          f"({args.pop * args.gens} evaluations per run); ours in {jnp.dtype(dtype).name}, "
          f"survival {args.survival}")  # fmt: skip
    rows = []
    for name in args.problems.split(","):
        P = multi_benchmark(name)
        hv_opt = pa.hypervolume(
            true_front(name, 20000, P.n_objectives), np.full(P.n_objectives, 1.1)
        )
        hv, comp, wall, tm = ours(name, args, dtype)
        pr = peer(name, args)
        print(f"\n{name} (D = {P.dim}, m = {P.n_objectives}); optimum (dense true front) "
              f"HV = {hv_opt:.5f}")  # fmt: skip
        print(f"  ours : HV {fmt(hv)}; wall {wall:.2f} s for all {args.runs} runs "
              f"(repeats {', '.join(f'{w:.2f}' for w in tm[: args.repeat])} s; CPU "
              f"{', '.join(f'{c:.2f}' for c in tm[args.repeat :])} s), compile {comp:.2f} s")  # fmt: skip
        if pr is None:
            continue
        phv, pwall, pcpu = pr
        p = mannwhitneyu(hv, phv).pvalue
        print(f"  pymoo: HV {fmt(phv)}; wall {pwall:.2f} s for {args.runs} runs one by one "
              f"(CPU {pcpu:.2f} s)")  # fmt: skip
        cpu = statistics.median(tm[args.repeat :])
        dm = statistics.median(hv) - statistics.median(phv)
        print(f"  median HV ours − pymoo = {dm:+.5f} ({'≥' if dm >= 0 else '<'}), Mann-Whitney "
              f"p = {p:.3g}; wall pymoo/ours = {pwall / wall:.1f}× "
              f"(with our compile: {pwall / (wall + comp):.1f}×); CPU time pymoo/ours = "
              f"{pcpu / cpu:.1f}×")  # fmt: skip
        rows.append((name, dm, pwall / wall, pcpu / cpu))
    print(f"\nload average at end: {_load()}")
    for name, dm, ratio, cratio in rows:
        print(f"{name}: HV ours−pymoo {dm:+.5f}  speed-up wall {ratio:.1f}×, CPU {cratio:.1f}×")


if __name__ == "__main__":
    main()
