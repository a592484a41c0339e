"""``designopt bench CONFIG``: the optimizer suite of ``designopt.bench`` run as a job:
the config loaded, the output claimed, the tables printed, the archive (a
``BenchRecord``) and the figures written through the one writer."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from designopt import optim
from designopt.app.records import bind
from designopt.bench import multi
from designopt.bench.suite import (
    BenchConfig,
    case_names,
    cases,
    check,
    entries,
    format_table,
    run_suite,
)
from designopt.core.timing import Stopwatch
from designopt.figures import bench as bench_figs
from designopt.io import archive, writer
from designopt.results import BenchRecord


def command(config_path: str, seed: int | None, out: str | None, quiet: bool,
            overwrite: bool = False, parallel: Any = None) -> int:  # fmt: skip
    """``designopt bench CONFIG [--seed N] [--out PATH] [--quiet] [--overwrite]``: run the
    suite, print the tables, write the archive and the figures through the one writer
    (``designopt.io.writer``). ConfigError for bad input (the CLI prints it and exits 2)
    before anything runs or is written; an existing archive needs ``overwrite``."""
    from designopt.app.config import load
    from designopt.core.validation import check_seed
    from designopt.io import writer

    cfg, text = load(config_path, BenchConfig)
    if cfg.precision == "float64":  # the command is the program: it may switch JAX to 64-bit
        import jax

        jax.config.update("jax_enable_x64", True)
    if seed is not None:
        cfg.seed = check_seed(seed, f"--seed {seed}")
    check(cfg, config_path)
    path = Path(out or cfg.output)
    with writer.session():
        writer.claim(path, overwrite)
        return _command(cfg, text, path, quiet or not writer.writes(), parallel)


def _command(cfg: BenchConfig, text: str, path: Path, quiet: bool, parallel: Any = None) -> int:
    """The suite, its tables, archive and figures, once the output is claimed."""
    from tqdm import tqdm

    b = cfg.bench
    n_ent = len(b.variants)
    mo = [optim.is_multi_objective(n) for _, n, _ in entries(cfg)]
    n_single = len(cases(cfg))
    n_multi = len(case_names(cfg)) - n_single
    total = (n_single * mo.count(False) + n_multi * mo.count(True)) * b.n_iters
    with Stopwatch() as sw, tqdm(total=total, desc="bench", unit="it", disable=quiet) as bar:
        res = run_suite(cfg, progress=bar.update, parallel=parallel)
    st = res["stats"]
    if not writer.writes():  # a non-zero process of a multi-process job: process 0 reports
        return 0
    for case in st:
        table = multi.format_table if st[case].get("higher_is_better") else format_table
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
    archive.save(path, bind(BenchRecord(attrs, tree, cfg)))
    hist = {c: {v: rec["history"] for v, rec in per.items() if v != "attrs"}
            for c, per in res["results"].items()}  # fmt: skip
    figs = writer.publish_figures(lambda d: bench_figs.draw(d, st, hist, b.n_runs), path.parent,
                                  swap=False)  # fmt: skip
    print(f"{len(res['results'])} cases × {n_ent} optimizers × {b.n_runs} runs × {b.n_iters} "
          f"iterations: wall {sw.wall:.1f} s (compile {sw.compile:.1f} s, run {sw.run:.1f} s)")  # fmt: skip
    print(f"archive: {path}")
    print(f"figures: {', '.join(p.name for p in figs if p.suffix == '.png')} in {path.parent}")
    return 0
