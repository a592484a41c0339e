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
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
from pydantic import Field

from designopt import optim
from designopt.bench.table import format_rows, u_tests
from designopt.core.errors import ConfigError
from designopt.core.settings import Section
from designopt.core.timing import Stopwatch
from designopt.core.validation import SEED_MAX
from designopt.numerics.statistics import summary
from designopt.problems.benchmarks import benchmark

BENCH_FUNCTIONS = ("griewank", "rastrigin", "ackley", "sphere", "rosenbrock", "schwefel226")
# "acceptable" final values for the success rate (our choice, D = 30 scale)
DEFAULT_SUCCESS = {"griewank": 0.1, "rastrigin": 100.0, "ackley": 0.1, "sphere": 0.01,
                   "rosenbrock": 100.0, "schwefel226": 3000.0}  # fmt: skip


_Strict = Section  # unknown keys are errors


class Entry(_Strict):
    """One column of the comparison: a registry name, an optional label (to run the same
    optimizer twice with different settings) and its settings."""

    name: str = Field(description="The optimizer registry entry to run.")
    label: str | None = Field(
        None,
        description="The column's label (default: the name); lets one entry run twice with "
        "different settings.",
    )
    settings: dict[str, float | str] = Field(
        {},
        description="The entry's own optimizer settings {name: value}.",
    )


MO_FUNCTIONS = ("zdt1", "zdt2", "zdt3", "dtlz2", "bnh", "srn")
"""Multi-objective test problems (``designopt.problems.multi``; run by ``designopt.bench.multi``)."""


class Function(_Strict):
    """A multi-objective function with its sizes: ``{name: dtlz2, dim: 12, n_objectives: 3}``."""

    name: Literal[MO_FUNCTIONS] = Field(  # type: ignore[valid-type]
        description="A multi-objective test problem: `zdt1`, `zdt2`, `zdt3`, `dtlz2`, `bnh` or "
        "`srn`.",
    )
    dim: int | None = Field(None, ge=2, description="Its dimension D (default: the problem's own).")
    n_objectives: int | None = Field(
        None,
        ge=2,
        description="Its number of objectives (scalable problems such as dtlz2; default: the "
        "problem's own).",
    )


class Bench(_Strict):
    functions: list[Literal[BENCH_FUNCTIONS + MO_FUNCTIONS] | Function] = Field(  # type: ignore
        ["griewank", "rastrigin", "ackley", "sphere"],
        description="Test functions: single-objective names (griewank, rastrigin, ackley, sphere, "
        "rosenbrock, schwefel226) or multi-objective ones (a name or `{name, dim, "
        "n_objectives}`), the latter run by multi-objective entries only.",
    )
    hypervolume_reference: list[float] | None = Field(
        None,
        description="The multi-objective cases' hypervolume reference point (default: 1.1 per "
        "objective).",
    )
    dim: int = Field(30, ge=1, description="Dimension D of the single-objective functions.")
    shifted: bool = Field(
        True,
        description="Also run every function with its optimum moved by a seeded shift (inside 80 % "
        "of the box).",
    )
    shift_seed: int = Field(1, ge=0, le=SEED_MAX, description="Seed of the shifts.")
    variants: list[str | Entry] = Field(
        ["p1", "p2", "p3", "p4", "p5", "p6", "p7", "cmaes"],
        description="Entries of the optimizer registry to compare: a name, or `{name, label, "
        "settings}`.",
    )
    reference: str = Field(
        "p3",
        description="Label of the entry every other one is tested against (Mann-Whitney U, "
        "Holm-corrected per function).",
    )
    n_particles: int = Field(50, ge=2, description="Population size of every entry (CMA-ES: λ).")
    n_iters: int = Field(1000, ge=1, description="Iterations of every run.")
    n_runs: int = Field(100, ge=2, description="Independent runs per entry and function.")
    bounds: Literal["clip", "reflect", "reinit"] = Field(
        "clip",
        description="Bound handling: `clip`, `reflect` or `reinit`.",
    )
    success: dict[str, float] = Field(
        {},
        description="{function: value}: a final value at or below it counts as a success "
        "(defaults: griewank 0.1, rastrigin 100, ackley 0.1, sphere 0.01, ...).",
    )
    settings: dict[str, dict[str, float | str]] = Field(
        {},
        description="Per-label settings overrides, e.g. `{p3: {gamma: 1.0e-5}}`; PSO's `draws` is "
        "set here.",
    )


class BenchConfig(_Strict):
    bench: Bench = Field(Bench(), description="The benchmark suite's settings.")
    precision: Literal["float32", "float64"] = Field(
        "float32",
        description="`float32` or `float64`.",
    )
    seed: int = Field(0, ge=0, le=SEED_MAX, description="Root PRNG seed of the benchmark.")
    output: str = Field(
        "results/bench/pso_benchmark.h5",
        description="The benchmark archive's path.",
    )


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
    from designopt.bench import multi

    is_multi = {lab: optim.is_multi_objective(n) for lab, n, _ in entries(cfg)}
    have = {False: bool(cases(cfg)), True: bool(multi.cases(cfg))}
    for i, (label, _, _) in enumerate(entries(cfg)):
        if not have[is_multi[label]]:
            kind = "multi" if is_multi[label] else "single"
            raise ConfigError(f"{path}: key 'bench.variants.{i}': {label!r} is {kind}-objective "
                              f"and bench.functions has no {kind}-objective function")  # fmt: skip
    from designopt.problems.multi import MULTI_FUNCTIONS

    ref = b.hypervolume_reference
    for c, fname, _, m in multi.cases(cfg):
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
    if asked (the multi-objective cases: ``multi.cases``)."""
    b = cfg.bench
    single = [f for f in b.functions if isinstance(f, str) and f in BENCH_FUNCTIONS]
    out = [(f, f, None) for f in single]
    if b.shifted:
        out += [(f"{f}_shifted", f, b.shift_seed) for f in single]
    return out


def case_names(cfg: BenchConfig) -> list[str]:
    """Every case in the order the suite runs them: single-, then multi-objective."""
    from designopt.bench import multi

    return [c for c, _, _ in cases(cfg)] + [c for c, *_ in multi.cases(cfg)]


def run_suite(cfg: BenchConfig, progress: Callable[[int], None] | None = None,
              parallel: Any = None) -> dict[str, Any]:  # fmt: skip
    """Run every case × entry; returns {"results": {case: {label: record}}, "stats": ...}.
    ``parallel`` (a ``designopt.core.devices.ParallelSettings``) splits runs or particles over
    devices (docs/scaling.md)."""
    from designopt.core import devices as par

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
    from designopt.bench import multi

    mo = multi.run_cases(cfg, ents, key, len(cases(cfg)), progress, plan)
    return {
        "results": results | mo,
        "stats": statistics(cfg, results) | multi.statistics(cfg, mo),
    }


def statistics(cfg: BenchConfig, results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Per case: mean, std, median, best of the final values, convergence iteration,
    success (final ≤ the function's threshold) and the U test of every entry against the
    reference entry (Holm)."""
    b = cfg.bench
    out: dict[str, Any] = {}
    for case, per in results.items():
        fname = case.removesuffix("_shifted")
        thr = b.success.get(fname, DEFAULT_SUCCESS[fname])
        rows = {v: summary(rec["best_f"], rec["converged_at"], thr) for v, rec in per.items()}
        u_tests(rows, {v: rec["best_f"] for v, rec in per.items()}, b.reference)
        out[case] = {"threshold": thr, "rows": rows}
    return out


COLUMNS = (("mean", 11, ".3e"), ("std", 11, ".3e"), ("median", 11, ".3e"),
           ("best", 11, ".3e"), ("conv it", 9, ".0f", "conv_mean"), ("± std", 8, ".0f", "conv_std"),
           ("success", 9, "%", "success"))  # fmt: skip
"""The columns of a single-objective case's table: (title, width, format[, row key])."""


def format_table(case: str, st: dict[str, Any], reference: str) -> str:
    """A plain-text table for one case (what ``designopt bench`` prints)."""
    head = f"{case}  (success: final ≤ {st['threshold']:g}; U test vs {reference}, Holm)"
    return format_rows(head, st["rows"], COLUMNS)
