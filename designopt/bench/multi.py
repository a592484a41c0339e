"""The multi-objective cases of the benchmark suite (``designopt bench``; #26): ZDT1-3,
DTLZ2 with any number of objectives, and the constrained BNH and SRN
(``designopt.problems.multi``), each run by every multi-objective entry with all runs in
one vmapped program. Per case and entry: the final hypervolume of every run against the
reference point (1.1, …, 1.1) unless ``bench.hypervolume_reference`` says otherwise, IGD+
against the sampled true front, the final fronts (runs, P, m) padded with NaN, the
hypervolume history (of the best front found so far, the optimizer's archive: never
decreasing; ``designopt.optim.runner``; the final hypervolume above is the final
population's, as pymoo reports it). Entries are compared on the hypervolume (larger is better) by
Mann-Whitney U against the reference entry with Holm's correction, as the
single-objective cases are on the final value."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt import optim
from designopt.bench.table import format_rows, u_tests
from designopt.core.timing import Stopwatch
from designopt.numerics.statistics import summary

SUCCESS_FRACTION = 0.99
"""A run succeeds when its final hypervolume reaches this fraction of the true front's."""


def case_name(spec: Any) -> str:
    """``zdt1``; ``dtlz2_m3`` / ``dtlz2_m3_d12`` when n_objectives / dim are given."""
    if isinstance(spec, str):
        return spec
    name = spec.name
    if spec.n_objectives is not None:
        name += f"_m{spec.n_objectives}"
    if spec.dim is not None:
        name += f"_d{spec.dim}"
    return name


def cases(cfg: Any) -> list[tuple[str, str, int | None, int | None]]:
    """(case, function, dim, n_objectives) of the config's multi-objective functions."""
    from designopt.problems.multi import MULTI_FUNCTIONS

    out = []
    for f in cfg.bench.functions:
        name = f if isinstance(f, str) else f.name
        if name in MULTI_FUNCTIONS:
            dim = None if isinstance(f, str) else f.dim
            m = None if isinstance(f, str) else f.n_objectives
            out.append((case_name(f), name, dim, m))
    return out


def reference_point(cfg: Any, m: int) -> np.ndarray:
    ref = cfg.bench.hypervolume_reference
    return np.full(m, 1.1) if ref is None else np.asarray(ref, np.float64)


def run_cases(cfg: Any, ents: list[tuple[str, str, dict[str, Any]]], key: jax.Array,
              offset: int, progress: Callable[[int], None] | None = None,
              plan: Any = None) -> dict[str, dict[str, Any]]:  # fmt: skip
    """Every multi-objective case × multi-objective entry: {case: {label: record}}."""
    from designopt.numerics import pareto
    from designopt.problems.multi import multi_benchmark, true_front

    b = cfg.bench
    dtype = jnp.dtype(cfg.precision)
    out: dict[str, dict[str, Any]] = {}
    for ci, (case, fname, dim, m) in enumerate(cases(cfg)):
        problem = multi_benchmark(fname, dim, m)
        m = problem.n_objectives
        ref = reference_point(cfg, m)
        truth = true_front(fname, 2000, m)
        hv_true = pareto.hypervolume(truth, ref)
        out[case] = {"attrs": {"true_hypervolume": hv_true, "reference": ref.tolist()}}
        for label, name, settings in ents:
            if not optim.is_multi_objective(name):
                continue
            with Stopwatch() as sw:
                r = optim.run(
                    name, problem, jax.random.fold_in(key, offset + ci), b.n_particles,
                    b.n_iters, b.n_runs, bounds=b.bounds, dtype=dtype,
                    chunk_iters=max(1, b.n_iters // 5), progress=progress, ref_point=ref,
                    **({"plan": plan} if plan else {}), **settings,
                )  # fmt: skip
            F = np.asarray(r.front.f, np.float64)
            keep = (np.asarray(r.front.rank) == 0) & (np.asarray(r.front.v) <= 0)
            front_f = np.where(keep[..., None], F, np.nan)
            hv = np.array([pareto.hypervolume(F[i][keep[i]], ref) for i in range(len(F))])
            igd = np.array([pareto.igd_plus(F[i][keep[i]], truth) if keep[i].any() else np.inf
                            for i in range(len(F))])  # fmt: skip
            out[case][label] = {
                "history": np.asarray(r.history, np.float32), "hypervolume": hv,
                "igd_plus": igd, "front_f": front_f, "converged_at": r.converged_at,
                "wall_s": sw.wall, "compile_s": sw.compile, "settings": r.settings,
            }  # fmt: skip
    return out


def statistics(cfg: Any, results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Per case: hypervolume mean, std, median, best (largest), IGD+ median, convergence
    generation, success (hypervolume ≥ 99 % of the true front's) and the U test of every
    entry against the reference entry (Holm)."""
    out: dict[str, Any] = {}
    for case, per in results.items():
        hv_true = per["attrs"]["true_hypervolume"]
        ents = {k: v for k, v in per.items() if k != "attrs"}
        rows = {}
        for v, rec in ents.items():
            s = summary(-rec["hypervolume"], rec["converged_at"], -SUCCESS_FRACTION * hv_true)
            rows[v] = {"mean": 0.0 - s["mean"], "std": s["std"], "median": 0.0 - s["median"],
                       "best": 0.0 - s["best"], "conv_mean": s["conv_mean"], "conv_std": s["conv_std"],
                       "success": s["success"], "igd_plus": float(np.median(rec["igd_plus"]))}  # fmt: skip
        u_tests(rows, {v: rec["hypervolume"] for v, rec in ents.items()}, cfg.bench.reference)
        out[case] = {"threshold": SUCCESS_FRACTION * hv_true, "rows": rows,
                     "higher_is_better": True, "true_hypervolume": hv_true,
                     "reference": per["attrs"]["reference"]}  # fmt: skip
    return out


COLUMNS = (("HV mean", 11, ".5f", "mean"), ("std", 10, ".1e"), ("median", 11, ".5f"),
           ("best", 11, ".5f"), ("IGD+ med", 10, ".2e", "igd_plus"),
           ("conv it", 9, ".0f", "conv_mean"), ("success", 9, "%", "success"))  # fmt: skip
"""The columns of a multi-objective case's table: (title, width, format[, row key])."""


def format_table(case: str, st: dict[str, Any], reference: str) -> str:
    """A plain-text table for one multi-objective case."""
    ref = ", ".join(f"{x:g}" for x in st["reference"])
    head = (f"{case}  (hypervolume against ({ref}), true front {st['true_hypervolume']:.5f}; "
            f"success: ≥ {100 * SUCCESS_FRACTION:g} % of it; U test vs {reference}, Holm)")
    return format_rows(head, st["rows"], COLUMNS)
