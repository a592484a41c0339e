"""PSO throughput: 100 runs × 1000 iterations × 50 particles on Rastrigin, D = 30.

designopt's PTPSO (and p2) next to evosax's PSO and pyswarms' GlobalBestPSO on the same
workload, measured in this run; the peers come from the ``bench`` extra and are skipped
with a message if missing. Times are per run (total / runs), after compilation; compile
time is printed separately. ``--suite`` also times the seed's benchmark (7 variants ×
4 functions × 100 runs, unshifted) as ``designopt bench`` runs it.

Not identical algorithms: evosax draws r1, r2 once per particle (shared across
dimensions); seed 000 eq. (44) and designopt draw them per dimension (2·D numbers per
particle), which is most of a PSO step's cost on CPU. pyswarms is numpy, one run at a
time.

    python benchmarks/pso_throughput.py [--runs 100] [--iters 1000] [--suite]
"""

from __future__ import annotations

import argparse
import logging
import os
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np
from _timing import header

from designopt import optim
from designopt.problems.benchmarks import benchmark, rastrigin
from designopt.timing import Stopwatch

D, M = 30, 50
LO, HI = -5.12, 5.12


def ours(name: str, runs: int, iters: int, dtype, draws: str) -> tuple[float, float, float]:
    P = benchmark("rastrigin", D)
    with Stopwatch() as first:
        optim.run(name, P, jax.random.key(0), M, iters, runs, dtype=dtype, draws=draws)
    t0 = time.perf_counter()
    r = optim.run(name, P, jax.random.key(1), M, iters, runs, dtype=dtype, draws=draws)
    return time.perf_counter() - t0, first.compile, float(r.best_f.mean())


def evosax_pso(runs: int, iters: int) -> tuple[float, float, float] | None:
    try:
        from evosax.algorithms import PSO
    except ImportError:
        print("  evosax not installed (pip install -e '.[bench]'): skipped")
        return None
    es = PSO(population_size=M, solution=jnp.zeros(D))
    params = es.default_params

    def one(key):
        k0, k1, k2 = jax.random.split(key, 3)
        x0 = jax.random.uniform(k0, (M, D), minval=LO, maxval=HI)
        state = es.init(k1, x0, rastrigin(x0), params)

        def body(carry, k):
            st = carry
            x, st = es.ask(k, st, params)
            x = jnp.clip(x, LO, HI)
            st, _ = es.tell(k, x, rastrigin(x), st, params)
            return st, None

        state, _ = jax.lax.scan(body, state, jax.random.split(k2, iters))
        return state.best_fitness

    f = jax.jit(jax.vmap(one))
    keys = jax.random.split(jax.random.key(0), runs)
    t0 = time.perf_counter()
    jax.block_until_ready(f(keys))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    best = jax.block_until_ready(f(jax.random.split(jax.random.key(1), runs)))
    t = time.perf_counter() - t0
    return t, first - t, float(best.mean())


def pyswarms_pso(runs: int, iters: int) -> tuple[float, float] | None:
    try:
        import pyswarms as ps
    except ImportError:
        print("  pyswarms not installed (pip install -e '.[bench]'): skipped")
        return None
    logging.getLogger("pyswarms").setLevel(logging.ERROR)

    def f(x):
        return 10 * D + np.sum(x * x - 10 * np.cos(2 * np.pi * x), axis=1)

    bounds = (np.full(D, LO), np.full(D, HI))
    best = []
    here = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)  # pyswarms writes a report.log into the working directory
        try:
            t0 = time.perf_counter()
            for i in range(runs):
                np.random.seed(i)
                opt = ps.single.GlobalBestPSO(M, D, {"c1": 1.5, "c2": 1.5, "w": 0.7}, bounds=bounds)
                cost, _ = opt.optimize(f, iters=iters, verbose=False)
                best.append(cost)
            t = time.perf_counter() - t0
        finally:
            os.chdir(here)
    return t, float(np.mean(best))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--iters", type=int, default=1000)
    ap.add_argument("--pyswarms-runs", type=int, default=5, help="pyswarms runs to time")
    ap.add_argument("--suite", action="store_true", help="also time the seed's 7 × 4 suite")
    a = ap.parse_args()
    header(f"PSO throughput: {a.runs} runs × {a.iters} iterations × {M} particles, Rastrigin D={D}")
    rows = {}
    for label, name, dt, draws in [
        ("designopt PTPSO f64", "p3", jnp.float64, "uniform"),
        ("designopt PTPSO f32", "p3", jnp.float32, "uniform"),
        ("designopt PTPSO f32 splitmix", "p3", jnp.float32, "splitmix"),
        ("designopt PTPSO f64 splitmix", "p3", jnp.float64, "splitmix"),
        ("designopt p2 f32 splitmix", "p2", jnp.float32, "splitmix"),
    ]:
        t, c, fm = ours(name, a.runs, a.iters, dt, draws)
        rows[label] = t / a.runs
        print(
            f"  {label:<28} {1e3 * t / a.runs:8.2f} ms/run  (total {t:5.2f} s, compile {c:4.1f} s)  mean f {fm:7.2f}"
        )
    ev = evosax_pso(a.runs, a.iters)
    if ev is not None:
        t, c, fm = ev
        rows["evosax PSO f64"] = t / a.runs
        print(
            f"  {'evosax PSO f64':<28} {1e3 * t / a.runs:8.2f} ms/run  (total {t:5.2f} s, compile {c:4.1f} s)  mean f {fm:7.2f}"
        )
    py = pyswarms_pso(a.pyswarms_runs, a.iters)
    if py is not None:
        t, fm = py
        rows["pyswarms GlobalBestPSO"] = t / a.pyswarms_runs
        print(
            f"  {'pyswarms GlobalBestPSO':<28} {1e3 * t / a.pyswarms_runs:8.2f} ms/run  ({a.pyswarms_runs} runs timed)  mean f {fm:7.2f}"
        )
    base = rows["designopt PTPSO f32 splitmix"]
    for k, v in rows.items():
        print(f"  ratio {k:<28} / PTPSO f32 splitmix = {v / base:6.2f}")
    if a.suite:
        from designopt import benchsuite
        from designopt.config import Bench, BenchConfig

        cfg = BenchConfig(
            bench=Bench(shifted=False, draws="splitmix", n_runs=a.runs, n_iters=a.iters)
        )
        with Stopwatch() as sw:
            benchsuite.run_suite(cfg)
        print(f"  seed suite 7 variants × 4 functions × {a.runs} runs (float32, splitmix): "
              f"{sw.wall:.1f} s (compile {sw.compile:.1f} s)")  # fmt: skip


if __name__ == "__main__":
    main()
