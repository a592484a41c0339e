"""The benchmark suite of seed 000 (Fig. 10-11, SPEC §3.3): optimizers × test functions.

Any registry entries side by side — the PSO family p1..p7 and CMA-ES by default — on the
seed's four functions (and their shifted copies). Every (function, entry) pair is one
``optim.run`` (all runs vmapped, iterations scanned); the PSO variants share one compiled
kernel per function (rule and penalty are array parameters) and the shifted functions
share it too (the shift is an array parameter). Statistics per function: mean, std,
median, best of the final value, mean and std of the convergence iteration, success rate,
and Mann-Whitney U of every entry against the reference (PTPSO) with Holm's correction.

``command`` is what ``designopt bench CONFIG`` runs; it writes a ``BenchRecord``, whose
figures ``designopt report`` redraws (``designopt.figures.bench.draw_record``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from designopt import optim, stats
from designopt.finite import SEED_MAX
from designopt.problems.benchmarks import benchmark
from designopt.timing import Stopwatch

BENCH_FUNCTIONS = ("griewank", "rastrigin", "ackley", "sphere", "rosenbrock", "schwefel226")
# "acceptable" final values for the success rate (our choice, D = 30 scale)
DEFAULT_SUCCESS = {"griewank": 0.1, "rastrigin": 100.0, "ackley": 0.1, "sphere": 0.01,
                   "rosenbrock": 100.0, "schwefel226": 3000.0}  # fmt: skip


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Entry(_Strict):
    """One column of the comparison: a registry name, an optional label (to run the same
    optimizer twice with different settings) and its settings."""

    name: str
    label: str | None = None
    settings: dict[str, float | str] = {}


MO_FUNCTIONS = ("zdt1", "zdt2", "zdt3", "dtlz2", "bnh", "srn")
"""Multi-objective test problems (``designopt.problems.multi``; run by ``designopt.benchmo``)."""


class Function(_Strict):
    """A multi-objective function with its sizes: ``{name: dtlz2, dim: 12, n_objectives: 3}``."""

    name: Literal[MO_FUNCTIONS]  # type: ignore[valid-type]
    dim: int | None = Field(None, ge=2)
    n_objectives: int | None = Field(None, ge=2)


class Bench(_Strict):
    functions: list[Literal[BENCH_FUNCTIONS + MO_FUNCTIONS] | Function] = [  # type: ignore[valid-type]
        "griewank", "rastrigin", "ackley", "sphere"]  # fmt: skip
    hypervolume_reference: list[float] | None = None
    """Multi-objective cases: the hypervolume's reference point (default 1.1 per objective)."""
    dim: int = Field(30, ge=1)
    shifted: bool = True  # also run every function with a seeded shift of its optimum
    shift_seed: int = Field(1, ge=0, le=SEED_MAX)
    variants: list[str | Entry] = ["p1", "p2", "p3", "p4", "p5", "p6", "p7", "cmaes"]
    reference: str = "p3"  # Mann-Whitney of every other entry against this label
    n_particles: int = Field(50, ge=2)  # population size of every entry (CMA-ES: λ)
    n_iters: int = Field(1000, ge=1)
    n_runs: int = Field(100, ge=2)
    bounds: Literal["clip", "reflect", "reinit"] = "clip"
    success: dict[str, float] = {}
    settings: dict[
        str, dict[str, float | str]
    ] = {}  # per-label overrides, e.g. {p3: {gamma: 1e-5}}


class BenchConfig(_Strict):
    bench: Bench = Bench()
    precision: Literal["float32", "float64"] = "float32"
    seed: int = Field(0, ge=0, le=SEED_MAX)
    output: str = "results/bench/pso_benchmark.h5"


def entries(cfg: BenchConfig) -> list[tuple[str, str, dict[str, Any]]]:
    """(label, registry name, settings) of every compared entry, in config order."""
    out = []
    for v in cfg.bench.variants:
        e = Entry(name=v) if isinstance(v, str) else v
        label = e.label or e.name
        out.append((label, e.name, {**e.settings, **cfg.bench.settings.get(label, {})}))
    return out


def check(cfg: BenchConfig, path: str) -> None:
    """ConfigError naming the key for an unknown optimizer, setting or label."""
    from designopt.config import ConfigError

    b = cfg.bench
    labels = []
    for i, (label, name, settings) in enumerate(entries(cfg)):
        try:
            optim.validate(name, settings, b.n_particles)
        except ValueError as e:
            raise ConfigError(f"{path}: key 'bench.variants.{i}': {e}") from None
        if label in labels:
            raise ConfigError(f"{path}: key 'bench.variants.{i}': label {label!r} used twice")
        labels.append(label)
    from designopt import benchmo

    multi = {lab: optim.is_multi_objective(n) for lab, n, _ in entries(cfg)}
    have = {False: bool(cases(cfg)), True: bool(benchmo.cases(cfg))}
    for i, (label, _, _) in enumerate(entries(cfg)):
        if not have[multi[label]]:
            kind = "multi" if multi[label] else "single"
            raise ConfigError(f"{path}: key 'bench.variants.{i}': {label!r} is {kind}-objective "
                              f"and bench.functions has no {kind}-objective function")  # fmt: skip
    from designopt.problems.multi import MULTI_FUNCTIONS

    ref = b.hypervolume_reference
    for c, fname, _, m in benchmo.cases(cfg):
        m = m or MULTI_FUNCTIONS[fname].n_objectives
        if ref is not None and len(ref) != m:
            raise ConfigError(f"{path}: key 'bench.hypervolume_reference': {len(ref)} values "
                              f"for {m} objectives (case {c})")  # fmt: skip
    if b.reference not in labels:
        raise ConfigError(f"{path}: key 'bench.reference': {b.reference!r} is not one of the "
                          f"compared entries {labels}")  # fmt: skip
    for k in b.settings:
        if k not in labels:
            raise ConfigError(
                f"{path}: key 'bench.settings.{k}': not a label of bench.variants {labels}"
            )


def cases(cfg: BenchConfig) -> list[tuple[str, str, int | None]]:
    """(case name, function, shift seed) for every single-objective function, and shifted
    if asked (the multi-objective cases: ``benchmo.cases``)."""
    b = cfg.bench
    single = [f for f in b.functions if isinstance(f, str) and f in BENCH_FUNCTIONS]
    out = [(f, f, None) for f in single]
    if b.shifted:
        out += [(f"{f}_shifted", f, b.shift_seed) for f in single]
    return out


def case_names(cfg: BenchConfig) -> list[str]:
    """Every case in the order the suite runs them: single-, then multi-objective."""
    from designopt import benchmo

    return [c for c, _, _ in cases(cfg)] + [c for c, *_ in benchmo.cases(cfg)]


def run_suite(cfg: BenchConfig, progress: Callable[[int], None] | None = None,
              parallel: Any = None) -> dict[str, Any]:  # fmt: skip
    """Run every case × entry; returns {"results": {case: {label: record}}, "stats": ...}.
    ``parallel`` (a ``designopt.parallel.ParallelSettings``) splits runs or particles over
    devices (docs/scaling.md)."""
    from designopt import parallel as par

    b = cfg.bench
    plan = par.plan(parallel, n_runs=b.n_runs, n_particles=b.n_particles, where="bench")
    dtype = jnp.dtype(cfg.precision)
    ents = entries(cfg)
    for _, name, settings in ents:
        optim.validate(name, settings, b.n_particles)
    results: dict[str, dict[str, Any]] = {}
    key = jax.random.key(cfg.seed)
    for ci, (case, fname, shift) in enumerate(cases(cfg)):
        problem = benchmark(fname, b.dim, shift)
        results[case] = {}
        for label, name, settings in ents:
            if optim.is_multi_objective(name):
                continue  # the multi-objective cases below
            with Stopwatch() as sw:
                r = optim.run(
                    name, problem, jax.random.fold_in(key, ci), b.n_particles, b.n_iters,
                    b.n_runs, bounds=b.bounds, dtype=dtype, chunk_iters=max(1, b.n_iters // 5),
                    progress=progress, **({"plan": plan} if plan else {}), **settings,
                )  # fmt: skip
            results[case][label] = {
                "history": r.history.astype(np.float32),
                "best_f": r.best_f,
                "best_x": r.best_x,
                "converged_at": r.converged_at,
                "wall_s": sw.wall,
                "compile_s": sw.compile,
                "settings": r.settings,
            }
    from designopt import benchmo

    mo = benchmo.run_cases(cfg, ents, key, len(cases(cfg)), progress, plan)
    return {
        "results": results | mo,
        "stats": statistics(cfg, results) | benchmo.statistics(cfg, mo),
    }


def statistics(cfg: BenchConfig, results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    b = cfg.bench
    out: dict[str, Any] = {}
    for case, per in results.items():
        fname = case.removesuffix("_shifted")
        thr = b.success.get(fname, DEFAULT_SUCCESS[fname])
        rows = {v: stats.summary(rec["best_f"], rec["converged_at"], thr) for v, rec in per.items()}
        others = [v for v in per if v != b.reference]
        if b.reference in per and others:
            tests = [
                stats.mann_whitney_u(per[v]["best_f"], per[b.reference]["best_f"]) for v in others
            ]
            adj = stats.holm(np.array([p for _, p in tests]))
            for v, (u, p), pa in zip(others, tests, adj, strict=True):
                rows[v] |= {"U": u, "p": p, "p_holm": float(pa)}
        out[case] = {"threshold": thr, "rows": rows}
    return out


def format_table(case: str, st: dict[str, Any], reference: str) -> str:
    """A plain-text table for one case (what ``designopt bench`` prints)."""
    w = max(8, *(len(v) + 1 for v in st["rows"]))
    head = (f"{case}  (success: final ≤ {st['threshold']:g}; U test vs {reference}, Holm)\n"
            f"{'entry':<{w}}{'mean':>11}{'std':>11}{'median':>11}{'best':>11}"
            f"{'conv it':>9}{'± std':>8}{'success':>9}{'p (Holm)':>10}")  # fmt: skip
    lines = [head]
    for v, r in st["rows"].items():
        p = f"{r['p_holm']:.1e}" if "p_holm" in r else "ref"
        lines.append(
            f"{v:<{w}}{r['mean']:>11.3e}{r['std']:>11.3e}{r['median']:>11.3e}{r['best']:>11.3e}"
            f"{r['conv_mean']:>9.0f}{r['conv_std']:>8.0f}{100 * r['success']:>8.0f}%{p:>10}"
        )
    return "\n".join(lines)


def command(config_path: str, seed: int | None, out: str | None, quiet: bool,
            overwrite: bool = False, parallel: Any = None) -> int:  # fmt: skip
    """``designopt bench CONFIG [--seed N] [--out PATH] [--quiet] [--overwrite]``: run the
    suite, print the tables, write the archive and the figures through the one writer
    (``designopt.output``). ConfigError for bad input (the CLI prints it and exits 2)
    before anything runs or is written; an existing archive needs ``overwrite``."""
    from designopt import output
    from designopt.config import load
    from designopt.finite import check_seed

    cfg, text = load(config_path, BenchConfig)
    if cfg.precision == "float64":  # the command is the program: it may switch JAX to 64-bit
        import jax

        jax.config.update("jax_enable_x64", True)
    if seed is not None:
        cfg.seed = check_seed(seed, f"--seed {seed}")
    check(cfg, config_path)
    path = Path(out or cfg.output)
    with output.session():
        output.claim(path, overwrite)
        return _command(cfg, text, path, quiet or not output.writes(), parallel)


def _command(cfg: BenchConfig, text: str, path: Path, quiet: bool, parallel: Any = None) -> int:
    """The suite, its tables, archive and figures, once the output is claimed."""
    from tqdm import tqdm

    from designopt import archive, output
    from designopt.results import BenchRecord

    b = cfg.bench
    n_ent = len(b.variants)
    mo = [optim.is_multi_objective(n) for _, n, _ in entries(cfg)]
    n_single = len(cases(cfg))
    n_multi = len(case_names(cfg)) - n_single
    total = (n_single * mo.count(False) + n_multi * mo.count(True)) * b.n_iters
    with Stopwatch() as sw, tqdm(total=total, desc="bench", unit="it", disable=quiet) as bar:
        res = run_suite(cfg, progress=bar.update, parallel=parallel)
    st = res["stats"]
    if not output.writes():  # a non-zero process of a multi-process job: process 0 reports
        return 0
    from designopt import benchmo

    for case in st:
        table = benchmo.format_table if st[case].get("higher_is_better") else format_table
        print(table(case, st[case], b.reference), end="\n\n")
    keep = ("history", "best_f", "best_x", "converged_at", "hypervolume", "igd_plus", "front_f")
    tree: dict[str, Any] = {"bench": {}}
    for case, per in res["results"].items():
        tree["bench"][case] = {
            v: {k: rec[k] for k in keep if k in rec}
            | {
                "attrs": {
                    "wall_s": rec["wall_s"],
                    "compile_s": rec["compile_s"],
                    "settings": rec["settings"],
                }
            }  # fmt: skip
            for v, rec in per.items()
            if v != "attrs"
        } | {"attrs": {"stats": st[case]}}
    attrs = {"kind": "bench", "config_yaml": text, "config_resolved": cfg.model_dump_json(),
             "seed": cfg.seed, "wall_time_s": sw.wall, "compile_time_s": sw.compile,
             "run_time_s": sw.run}  # fmt: skip
    archive.save(path, BenchRecord(attrs, tree, cfg))
    hist = {c: {v: rec["history"] for v, rec in per.items() if v != "attrs"}
            for c, per in res["results"].items()}  # fmt: skip
    from designopt.figures import bench as bench_figs

    figs = output.publish_figures(lambda d: bench_figs.draw(d, st, hist, b.n_runs), path.parent,
                                  swap=False)  # fmt: skip
    print(f"{len(res['results'])} cases × {n_ent} optimizers × {b.n_runs} runs × {b.n_iters} "
          f"iterations: wall {sw.wall:.1f} s (compile {sw.compile:.1f} s, run {sw.run:.1f} s)")  # fmt: skip
    print(f"archive: {path}")
    print(f"figures: {', '.join(p.name for p in figs if p.suffix == '.png')} in {path.parent}")
    return 0
