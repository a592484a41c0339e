"""PSO throughput: 100 runs × 1000 iterations × 50 particles on Rastrigin, D = 30.

designopt's PTPSO with its default settings (float32, x64 off, ``draws: mix32``) next to
evosax's PSO and pyswarms' GlobalBestPSO on the same work, all measured in this run; the
peers come from the ``bench`` extra and are skipped with a message if missing. Every
timing is repeated (``--repeat``) on fresh keys after a first, compiling call, and printed
as median [min–max]; compile time (first call minus a run) is printed separately. The last
line is the ratio of medians:

    ptpso/evosax = R (default settings, compile excluded), compile = T s

Not identical algorithms: evosax draws r1, r2 once per particle (shared across
dimensions); seed 000 eq. (44) and designopt draw them per dimension (2·D numbers per
particle, 3·D for PTPSO). pyswarms is numpy, one run at a time. ``--breakdown`` times the
parts of PTPSO's step (draws, objective, update) by swapping them out.

    python benchmarks/pso_throughput.py [--runs 100] [--iters 1000] [--repeat 5] [--suite]
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import tempfile
import time

import jax

jax.config.update("jax_enable_x64", False)  # the default process: float32, no x64

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _timing import header  # noqa: E402

from designopt import optim  # noqa: E402
from designopt.problems.benchmarks import benchmark, rastrigin  # noqa: E402

jax.config.update("jax_enable_x64", False)  # in case the import switched it on
D, M = 30, 50
LO, HI = -5.12, 5.12


def _timed(f, repeat: int) -> tuple[list[float], float, float]:
    """(run times, compile time, mean best f): one compiling call, then ``repeat`` runs."""
    t0 = time.perf_counter()
    f(0)
    first = time.perf_counter() - t0
    ts, fm = [], np.nan
    for i in range(repeat):
        t0 = time.perf_counter()
        fm = f(i + 1)
        ts.append(time.perf_counter() - t0)
    return ts, max(first - min(ts), 0.0), fm


def ours(
    name: str, runs: int, iters: int, repeat: int, **settings
) -> tuple[list[float], float, float]:
    P = benchmark("rastrigin", D)

    def f(seed):
        r = optim.run(name, P, jax.random.key(seed), M, iters, runs, dtype=jnp.float32, **settings)
        return float(r.best_f.mean())

    return _timed(f, repeat)


def evosax_pso(runs: int, iters: int, repeat: int) -> tuple[list[float], float, float] | None:
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

        def body(st, k):
            x, st = es.ask(k, st, params)
            x = jnp.clip(x, LO, HI)
            st, _ = es.tell(k, x, rastrigin(x), st, params)
            return st, None

        state, _ = jax.lax.scan(body, state, jax.random.split(k2, iters))
        return state.best_fitness

    g = jax.jit(jax.vmap(one))

    def f(seed):
        return float(jax.block_until_ready(g(jax.random.split(jax.random.key(seed), runs))).mean())

    return _timed(f, repeat)


def pyswarms_pso(runs: int, iters: int) -> tuple[float, float] | None:
    here = os.getcwd()
    tmp = tempfile.TemporaryDirectory()
    os.chdir(tmp.name)  # pyswarms writes a report.log into the working directory, even on import
    try:
        import pyswarms as ps
    except ImportError:
        print("  pyswarms not installed (pip install -e '.[bench]'): skipped")
        return None
    finally:
        os.chdir(here)
    logging.getLogger("pyswarms").setLevel(logging.ERROR)

    def f(x):
        return 10 * D + np.sum(x * x - 10 * np.cos(2 * np.pi * x), axis=1)

    bounds = (np.full(D, LO), np.full(D, HI))
    best = []
    with tmp:
        os.chdir(tmp.name)
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


def _row(label: str, ts: list[float], runs: int, comp: float, fm: float) -> None:
    med = statistics.median(ts)
    print(f"  {label:<34} {1e3 * med / runs:7.2f} ms/run  total {med:5.2f} s "
          f"[{min(ts):.2f}–{max(ts):.2f}]  compile {comp:4.1f} s  mean f {fm:7.2f}")  # fmt: skip


def breakdown(runs: int, iters: int, repeat: int) -> None:
    """Time PTPSO with parts of its step replaced: what each part costs."""
    from designopt.optim import draws as rng

    print("  breakdown of PTPSO's step (medians; each row swaps one part out):")
    orig = rng.uniform, rng.uniform_pair
    med = statistics.median
    try:
        ts, _, _ = ours("p3", runs, iters, repeat)
        print(f"    PTPSO, full step                       {med(ts):5.2f} s")
        rng.uniform = lambda kind, key, slot, shape, dt: jnp.full(shape, 0.5, dt)
        rng.uniform_pair = lambda kind, key, slot, shape, dt: (jnp.full(shape, 0.5, dt),) * 2
        ts2, _, _ = ours("p3", runs, iters, repeat)
        print(f"    PTPSO, draws replaced by constants     {med(ts2):5.2f} s "
              f"(the draws ≈ {med(ts) - med(ts2):.2f} s)")  # fmt: skip
    finally:
        rng.uniform, rng.uniform_pair = orig
    ts3, _, _ = ours("p2", runs, iters, repeat)
    print(f"    p2 (PTPSO without its penalty term)    {med(ts3):5.2f} s "
          f"(the penalty term ≈ {med(ts) - med(ts3):.2f} s)")  # fmt: skip
    ts4, _, _ = ours("p1", runs, iters, repeat)
    print(f"    p1 (no constriction, no penalty)       {med(ts4):5.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--iters", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=5, help="timed repeats per row")
    ap.add_argument("--pyswarms-runs", type=int, default=5, help="pyswarms runs to time")
    ap.add_argument("--suite", action="store_true", help="also time the seed's 7 × 4 suite")
    ap.add_argument("--breakdown", action="store_true", help="time the parts of PTPSO's step")
    ap.add_argument("--uniform", action="store_true", help="also time threefry draws")
    a = ap.parse_args()
    header(f"PSO throughput: {a.runs} runs × {a.iters} iterations × {M} particles, Rastrigin "
           f"D={D}, float32, x64 {'on' if jax.config.jax_enable_x64 else 'off'}")  # fmt: skip
    print(f"  medians of {a.repeat} timed runs [min–max] after a compiling call")
    ts, comp, fm = ours("ptpso", a.runs, a.iters, a.repeat)
    _row("designopt PTPSO (defaults, mix32)", ts, a.runs, comp, fm)
    t_ours = statistics.median(ts)
    if a.uniform:
        t2, c2, f2 = ours("ptpso", a.runs, a.iters, a.repeat, draws="uniform")
        _row("designopt PTPSO (draws: uniform)", t2, a.runs, c2, f2)
    t2, c2, f2 = ours("p2", a.runs, a.iters, a.repeat)
    _row("designopt p2 (defaults)", t2, a.runs, c2, f2)
    ev = evosax_pso(a.runs, a.iters, a.repeat)
    t_ev = None
    if ev is not None:
        _row("evosax PSO", *ev[:1], a.runs, ev[1], ev[2])
        t_ev = statistics.median(ev[0])
        print(f"  ratio per repeat (ours/evosax, paired by order): "
              f"{', '.join(f'{x / y:.2f}' for x, y in zip(ts, ev[0], strict=True))}")  # fmt: skip
    py = pyswarms_pso(a.pyswarms_runs, a.iters)
    if py is not None:
        t, fm = py
        per = t / a.pyswarms_runs
        print(f"  {'pyswarms GlobalBestPSO':<34} {1e3 * per:7.2f} ms/run  ({a.pyswarms_runs} runs "
              f"timed)  mean f {fm:7.2f}")  # fmt: skip
        print(f"  pyswarms/ptpso = {per / (t_ours / a.runs):.0f}× per run")
    if a.breakdown:
        breakdown(a.runs, a.iters, a.repeat)
    if a.suite:
        from designopt import benchsuite

        cfg = benchsuite.BenchConfig(
            bench=benchsuite.Bench(shifted=False, n_runs=a.runs, n_iters=a.iters)
        )
        t0 = time.perf_counter()
        benchsuite.run_suite(cfg)
        print(f"  seed suite ({len(cfg.bench.variants)} optimizers × 4 functions × {a.runs} runs, "
              f"float32, defaults): {time.perf_counter() - t0:.1f} s incl. compile")  # fmt: skip
    if t_ev is not None:
        print(f"ptpso/evosax = {t_ours / t_ev:.2f} (default settings, compile excluded), "
              f"compile = {comp:.1f} s")  # fmt: skip
    else:
        print(f"ptpso/evosax = n/a (evosax missing), compile = {comp:.1f} s")


if __name__ == "__main__":
    main()
