"""The PSO benchmark suite of seed 000 (Fig. 10-11, SPEC §3.3): variants × test functions.

Every (function, variant) pair is one ``optim.run`` (all runs vmapped, iterations scanned);
all variants share one compiled kernel per function (the inertia rule and the penalty
switch are array parameters), and the shifted functions share it too (the shift is an
array parameter). Statistics per function: mean, std, median, best of the final value,
mean and std of the convergence iteration, success rate, and Mann-Whitney U of every
variant against the reference (PTPSO) with Holm's correction.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt import optim, stats
from designopt.config import DEFAULT_SUCCESS, BenchConfig
from designopt.problems.benchmarks import benchmark
from designopt.timing import Stopwatch


def cases(cfg: BenchConfig) -> list[tuple[str, str, int | None]]:
    """(case name, function, shift seed) for every function, and shifted if asked."""
    b = cfg.bench
    out = [(f, f, None) for f in b.functions]
    if b.shifted:
        out += [(f"{f}_shifted", f, b.shift_seed) for f in b.functions]
    return out


def run_suite(cfg: BenchConfig, progress: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Run every case × variant; returns {case: {variant: record}} plus statistics."""
    b = cfg.bench
    dtype = jnp.dtype(cfg.precision)
    for v in [*b.variants, b.reference]:
        optim.resolve(v)
    results: dict[str, dict[str, Any]] = {}
    key = jax.random.key(cfg.seed)
    for ci, (case, fname, shift) in enumerate(cases(cfg)):
        problem = benchmark(fname, b.dim, shift)
        results[case] = {}
        for variant in b.variants:
            with Stopwatch() as sw:
                r = optim.run(
                    variant, problem, jax.random.fold_in(key, ci), b.n_particles, b.n_iters,
                    b.n_runs, bounds=b.bounds, dtype=dtype, chunk_iters=max(1, b.n_iters // 5),
                    progress=progress, draws=b.draws, **b.settings.get(variant, {}),
                )  # fmt: skip
            results[case][variant] = {
                "history": r.history.astype(np.float32),
                "best_f": r.best_f,
                "best_x": r.best_x,
                "converged_at": r.converged_at,
                "wall_s": sw.wall,
                "compile_s": sw.compile,
                "settings": r.settings,
            }
    return {"results": results, "stats": statistics(cfg, results)}


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
    head = (f"{case}  (success: final ≤ {st['threshold']:g}; U test vs {reference}, Holm)\n"
            f"{'variant':<8}{'mean':>11}{'std':>11}{'median':>11}{'best':>11}"
            f"{'conv it':>9}{'± std':>8}{'success':>9}{'p (Holm)':>10}")  # fmt: skip
    lines = [head]
    for v, r in st["rows"].items():
        p = f"{r['p_holm']:.1e}" if "p_holm" in r else "ref"
        lines.append(
            f"{v:<8}{r['mean']:>11.3e}{r['std']:>11.3e}{r['median']:>11.3e}{r['best']:>11.3e}"
            f"{r['conv_mean']:>9.0f}{r['conv_std']:>8.0f}{100 * r['success']:>8.0f}%{p:>10}"
        )
    return "\n".join(lines)
