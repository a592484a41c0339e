"""PSO throughput: 100 runs × 1000 iterations × 50 particles on Rastrigin, D = 30.

designopt's PTPSO with its default settings (float32, x64 off, ``draws: mix32``) next to
evosax's PSO and pyswarms' GlobalBestPSO on the same work, all measured in this run; the
peers come from the ``bench`` extra and are skipped with a message if missing. Every
timing is repeated (``--repeat``) on fresh keys after a first, compiling call, and printed
as median [min–max]; the repeats of the rows are interleaved (A B A B …) so that every row
sees the same machine load, and the ratios are taken per repeat (paired) with their spread.
Compile time (first call minus the fastest run) is printed separately; the CPU, its vector
extensions and the load average are printed at the start and the end. The last line:

    ptpso/evosax = R [min–max] (median of per-repeat ratios, ...), compile = T s

``--formulations`` adds a row with PTPSO's step as the other backends compile it
(``designopt.optim.pso.on_cpu``): on a GPU the CPU's step with its two conditionals, on
the CPU the GPU's with selects.

Not identical algorithms: evosax draws r1, r2 once per particle (shared across
dimensions); seed 000 eq. (44) and designopt draw them per dimension (2·D numbers per
particle, 3·D for PTPSO). pyswarms is numpy, one run at a time. ``--breakdown`` times the
parts of PTPSO's step (draws, objective, update) by swapping them out.

    python benchmarks/pso_throughput.py [--runs 100] [--iters 1000] [--repeat 5] [--suite]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import statistics
import tempfile
import time
from collections.abc import Callable

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


def _compiled(f) -> tuple[Callable[[int], float], float]:
    """(f, time of its first, compiling call)."""
    t0 = time.perf_counter()
    f(0)
    return f, time.perf_counter() - t0


def interleaved(
    fns: dict[str, Callable[[int], float]],
    repeat: int,
    last: dict[str, float] | None = None,
    cpu: dict[str, list[float]] | None = None,
) -> dict[str, list[float]]:
    """Time every callable ``repeat`` times, interleaved (A B C A B C …) so that all of them
    see the same machine load; returns the wall times per name (compiling calls excluded),
    puts each callable's last value in ``last`` and its process CPU times (all threads) in
    ``cpu`` — less sensitive than wall time to other jobs on a shared machine."""
    ts: dict[str, list[float]] = {k: [] for k in fns}
    for i in range(repeat):
        for k, f in fns.items():
            t0, c0 = time.perf_counter(), time.process_time()
            y = f(i + 1)
            ts[k].append(time.perf_counter() - t0)
            if cpu is not None:
                cpu.setdefault(k, []).append(time.process_time() - c0)
            if last is not None:
                last[k] = y
    return ts


def ours(name: str, runs: int, iters: int, fresh: bool = False,
         **settings) -> Callable[[int], float]:  # fmt: skip
    """designopt's ``name`` on Rastrigin-30: seed → mean best f of ``runs`` runs.
    ``fresh``: behind a new function object, so that its first call traces and compiles
    anew (the benchmark functions are cached, and so are the programs compiled for them)."""
    P = benchmark("rastrigin", D)
    if fresh:
        base = P.fn
        P = dataclasses.replace(P, fn=lambda p, X, key: base(p, X, key))

    def f(seed):
        r = optim.run(name, P, jax.random.key(seed), M, iters, runs, dtype=jnp.float32, **settings)
        return float(r.best_f.mean())

    return f


def evosax_pso(runs: int, iters: int) -> Callable[[int], float] | None:
    try:
        from evosax.algorithms import PSO
    except ImportError:
        print("  evosax not installed (pip install -e '.[bench]'): skipped")
        return None
    except Exception as e:  # noqa: BLE001 - installed but not working with this JAX
        print(f"  evosax does not import ({type(e).__name__}: {e}): skipped")
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

    return f


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


def _row(label: str, ts: list[float], runs: int, comp: float, fm: float | None = None) -> None:
    med = statistics.median(ts)
    tail = "" if fm is None else f"  mean f {fm:7.2f}"
    print(f"  {label:<36} {1e3 * med / runs:7.2f} ms/run  total {med:5.2f} s "
          f"[{min(ts):.2f}–{max(ts):.2f}]  compile {comp:4.1f} s{tail}")  # fmt: skip


def _ratios(label: str, ts: list[float], base: list[float]) -> float:
    """Print the per-repeat ratios ts/base (paired: the same repeat round) and their spread;
    return their median."""
    r = [x / y for x, y in zip(ts, base, strict=True)]
    med = statistics.median(r)
    print(f"  {label}: median {med:.2f}  [{min(r):.2f}–{max(r):.2f}]  per repeat "
          f"{', '.join(f'{x:.2f}' for x in r)}")  # fmt: skip
    return med


def machine() -> str:
    """The CPU model and its vector extensions (Linux), and the load average now."""
    model, flags = "unknown CPU", set()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name") and model == "unknown CPU":
                model = line.split(":", 1)[1].strip()
            elif line.startswith("flags") and not flags:
                flags = set(line.split(":", 1)[1].split())
    except OSError:
        pass
    ext = "/".join(f for f in ("avx2", "avx512f") if f in flags) or "no avx2"
    load = "/".join(f"{x:.1f}" for x in os.getloadavg())
    return f"{model}, {os.cpu_count()} cores, {ext}; load average {load} (1/5/15 min)"


def breakdown(runs: int, iters: int, repeat: int, evo) -> None:
    """Time PTPSO with parts of its step replaced (interleaved with evosax): what each costs."""
    from designopt.optim import draws as rng

    print("  breakdown of PTPSO's step (each row swaps one part out; interleaved repeats):")
    fns = {"p3": _compiled(ours("p3", runs, iters))[0]}
    orig = rng.uniform, rng.uniform_pair
    try:  # compiled under the patch (a fresh problem function forces a new trace)
        rng.uniform = lambda kind, key, slot, shape, dt: jnp.full(shape, 0.5, dt)
        rng.uniform_pair = lambda kind, key, slot, shape, dt: (jnp.full(shape, 0.5, dt),) * 2
        fns["p3, draws = constants"] = _compiled(ours("p3", runs, iters, fresh=True))[0]
    finally:
        rng.uniform, rng.uniform_pair = orig
    fns["p2 (no penalty)"] = _compiled(ours("p2", runs, iters))[0]
    fns["p1 (no constriction, no penalty)"] = _compiled(ours("p1", runs, iters))[0]
    if evo is not None:
        fns["evosax"] = evo
    cpu: dict[str, list[float]] = {}
    ts = interleaved(fns, repeat, None, cpu)
    med = statistics.median
    for k, t in ts.items():
        extra = ""
        if "evosax" in ts:
            extra = (f"  ratio to evosax: wall {med(t) / med(ts['evosax']):.2f}, "
                     f"CPU {med(cpu[k]) / med(cpu['evosax']):.2f}")  # fmt: skip
        print(f"    {k:<36} {med(t):5.2f} s [{min(t):.2f}–{max(t):.2f}]  CPU {med(cpu[k]):5.2f} s"
              f"{extra}")  # fmt: skip
    full = med(cpu["p3"])
    print(f"    → in CPU time: draws ≈ {full - med(cpu['p3, draws = constants']):.2f} s, penalty "
          f"term ≈ {full - med(cpu['p2 (no penalty)']):.2f} s")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--iters", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=5, help="timed repeats per row")
    ap.add_argument("--pyswarms-runs", type=int, default=5, help="pyswarms runs to time")
    ap.add_argument("--suite", action="store_true", help="also time the seed's 7 × 4 suite")
    ap.add_argument("--breakdown", action="store_true", help="time the parts of PTPSO's step")
    ap.add_argument("--uniform", action="store_true", help="also time threefry draws")
    ap.add_argument("--formulations", action="store_true",
                    help="also time PTPSO's step as the other backends run it (pso.on_cpu: "
                         "conditionals on the CPU, selects elsewhere)")  # fmt: skip
    a = ap.parse_args()
    header(f"PSO throughput: {a.runs} runs × {a.iters} iterations × {M} particles, Rastrigin "
           f"D={D}, float32, x64 {'on' if jax.config.jax_enable_x64 else 'off'}")  # fmt: skip
    print(f"  {machine()}")
    print(f"  medians of {a.repeat} timed runs [min–max] after a compiling call; the rows' "
          f"repeats are interleaved (A B C A B C …) so that all see the same load")  # fmt: skip
    rows: dict[str, tuple[Callable[[int], float], float]] = {}
    rows["designopt PTPSO (defaults, mix32)"] = _compiled(ours("ptpso", a.runs, a.iters))
    if a.uniform:
        rows["designopt PTPSO (draws: uniform)"] = _compiled(
            ours("ptpso", a.runs, a.iters, draws="uniform")
        )
    if a.formulations:
        from designopt.optim import pso

        other = "other" if jax.default_backend() == "cpu" else "cpu"
        pso.FORCE_PLATFORM = other  # read while tracing: the compiling call only
        try:
            rows[f"designopt PTPSO, {other} step"] = _compiled(
                ours("ptpso", a.runs, a.iters, fresh=True)
            )
        finally:
            pso.FORCE_PLATFORM = None
    rows["designopt p2 (defaults)"] = _compiled(ours("p2", a.runs, a.iters))
    evo = evosax_pso(a.runs, a.iters)
    if evo is not None:
        rows["evosax PSO"] = _compiled(evo)
    fm: dict[str, float] = {}  # mean best f of the last repeat
    cpu: dict[str, list[float]] = {}
    ts = interleaved({k: f for k, (f, _) in rows.items()}, a.repeat, fm, cpu)
    comp = {k: max(c - min(ts[k]), 0.0) for k, (_, c) in rows.items()}
    for k in rows:
        _row(k, ts[k], a.runs, comp[k], fm[k])
    ptpso = "designopt PTPSO (defaults, mix32)"
    t_ours = statistics.median(ts[ptpso])
    ratio = None
    if evo is not None:
        ratio = _ratios("ptpso/evosax per repeat", ts[ptpso], ts["evosax PSO"])
        _ratios("p2/evosax per repeat", ts["designopt p2 (defaults)"], ts["evosax PSO"])
        for k in rows:
            c = cpu[k]
            print(f"  CPU time (all threads) {k:<34} {statistics.median(c):5.2f} s "
                  f"[{min(c):.2f}–{max(c):.2f}]")  # fmt: skip
        _ratios("ptpso/evosax in CPU time", cpu[ptpso], cpu["evosax PSO"])
    py = pyswarms_pso(a.pyswarms_runs, a.iters) if a.pyswarms_runs > 0 else None
    if py is not None:
        t, fmp = py
        per = t / a.pyswarms_runs
        print(f"  {'pyswarms GlobalBestPSO':<36} {1e3 * per:7.2f} ms/run  ({a.pyswarms_runs} runs "
              f"timed)  mean f {fmp:7.2f}")  # fmt: skip
        print(f"  pyswarms/ptpso = {per / (t_ours / a.runs):.0f}× per run")
    if a.breakdown:
        breakdown(a.runs, a.iters, a.repeat, evo)
    if a.suite:
        from designopt.bench import suite

        cfg = suite.BenchConfig(
            bench=suite.Bench(shifted=False, n_runs=a.runs, n_iters=a.iters)
        )
        t0 = time.perf_counter()
        suite.run_suite(cfg)
        print(f"  seed suite ({len(cfg.bench.variants)} optimizers × 4 functions × {a.runs} runs, "
              f"float32, defaults): {time.perf_counter() - t0:.1f} s incl. compile")  # fmt: skip
    print(f"  {machine()}")
    c = comp[ptpso]
    if ratio is not None:
        r = [x / y for x, y in zip(ts[ptpso], ts["evosax PSO"], strict=True)]
        print(f"ptpso/evosax = {ratio:.2f} [{min(r):.2f}–{max(r):.2f}] (median of per-repeat "
              f"ratios, default settings, compile excluded), compile = {c:.1f} s")  # fmt: skip
    else:
        print(f"ptpso/evosax = n/a (evosax missing), compile = {c:.1f} s")


if __name__ == "__main__":
    main()
