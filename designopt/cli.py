"""The ``designopt`` command line. User mistakes print one line and exit with status 2."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from designopt.config import ConfigError, load


class Interrupted(Exception):
    """Ctrl-C during a run; the message says what was kept."""


def _check_output(path: Path) -> None:
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"output '{path}': cannot create folder ({e.strerror})") from None
    if not os.access(parent, os.W_OK):
        raise ConfigError(f"output '{path}': folder is not writable")


def _validate_optimizer(cfg, path: str) -> None:
    from designopt.optim import make_params, resolve

    try:
        resolve(cfg.optimizer.name)
    except ValueError as e:
        raise ConfigError(f"{path}: key 'optimizer.name': {e}") from None
    try:
        make_params(cfg.optimizer.name, **cfg.optimizer.settings)
    except ValueError as e:
        raise ConfigError(f"{path}: key 'optimizer.settings': {e}") from None


def _problem(cfg, path: str):
    from designopt import study

    try:
        return study.build_problem(cfg)
    except ValueError as e:
        raise ConfigError(f"{path}: study: {e}") from None


def _load_checkpoint(partial: Path, resolved: str):
    import h5py

    from designopt.optim import Checkpoint

    if not partial.is_file():
        raise ConfigError(f"{partial}: no interrupted run to resume")
    try:
        with h5py.File(partial, "r") as h:
            if h.attrs.get("config_resolved") != resolved:
                raise ConfigError(
                    f"{partial}: the interrupted run used a different config or seed; "
                    "run without --resume to start afresh"
                )
            c = h["checkpoint"]
            state = {k: v[()] for k, v in c["state"].items()}
            return Checkpoint(state, c["history"][()], c["history_x"][()], int(c.attrs["done"]))
    except (OSError, KeyError) as e:
        raise ConfigError(f"{partial}: not a readable checkpoint ({e})") from None


def cmd_run(args: argparse.Namespace) -> int:
    cfg, text = load(args.config)
    if args.seed is not None:
        cfg.seed = args.seed
    if cfg.sweep is not None:
        raise ConfigError(f"{args.config}: key 'sweep': this config declares a sweep; "
                          "run it with `designopt sweep`")  # fmt: skip
    out = Path(args.out or cfg.output)
    _check_output(out)
    _validate_optimizer(cfg, args.config)
    from tqdm import tqdm

    from designopt import archive, study
    from designopt.timing import Stopwatch

    resolved = cfg.model_dump_json()
    partial = archive.partial_path(out)
    resume = _load_checkpoint(partial, resolved) if args.resume else None
    attrs = {"kind": "run", "study": cfg.study.name, "config_yaml": text,
             "config_resolved_yaml": study.resolved_yaml(cfg), "config_resolved": resolved,
             "seed": cfg.seed}  # fmt: skip

    def checkpoint(ck) -> None:
        tree = {"checkpoint": {"state": ck.state, "history": ck.history,
                               "history_x": ck.history_x, "attrs": {"done": ck.done}}}  # fmt: skip
        archive.write(partial, tree, attrs, complete=False)

    o = cfg.optimizer
    with Stopwatch() as total:
        with Stopwatch() as setup:
            problem = _problem(cfg, args.config)
        with Stopwatch() as opt, tqdm(total=o.n_iters, desc=f"{o.name} on {cfg.study.name}",
                                      unit="it", disable=args.quiet) as bar:  # fmt: skip
            try:
                res = study.optimise(cfg, problem, progress=bar.update, checkpoint=checkpoint,
                                     resume=resume)  # fmt: skip
            except KeyboardInterrupt:
                bar.close()
                done = partial.is_file()
                raise Interrupted(
                    f"finished part kept in {partial} (complete = False); continue with "
                    f"`designopt run {args.config} --resume`"
                    if done
                    else "no archive written"
                ) from None
        with Stopwatch() as post:
            tree = study.result_tree(cfg, problem, res)
    attrs |= {"wall_time_s": total.wall, "compile_time_s": total.compile,
              "run_time_s": total.run, "setup_time_s": setup.wall, "pso_time_s": opt.wall,
              "post_time_s": post.wall, "resumed_from": resume.done if resume else -1}  # fmt: skip
    archive.write(out, tree, attrs)
    partial.unlink(missing_ok=True)
    for line in study.summary_lines(problem, tree, o.n_runs):
        print(line)
    print(f"samples per design: {problem.info['n_samples_used']}; wall {total.wall:.1f} s = "
          f"compile {total.compile:.1f} s + run {total.run:.1f} s "
          f"(setup {setup.wall:.1f} s, PSO {opt.wall:.1f} s, scoring/polish {post.wall:.1f} s)")  # fmt: skip
    return _finish(out, args)


def _finish(out: Path, args: argparse.Namespace) -> int:
    """Print the archive path and draw the figures unless --no-figures."""
    print(f"archive: {out}")
    if not args.no_figures:
        figs = draw_figures(out)
        print(f"figures: {len(figs) // 2} (PNG + PDF) in {figs[0].parent}")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    cfg, text = load(args.config)
    if args.seed is not None:
        cfg.seed = args.seed
    if cfg.sweep is None:
        raise ConfigError(f"{args.config}: key 'sweep': missing; `designopt sweep` needs one "
                          "(docs/configs.md)")  # fmt: skip
    from designopt import sweep as sw

    try:
        members = sw.members(cfg)
        groups: dict[str, list[tuple[int, dict]]] = {}
        cfgs = {}
        for i, m in enumerate(members):
            rest, _ = sw.split(m)
            k = repr(sorted(rest.items()))
            cfgs.setdefault(k, sw.apply(cfg, rest))
            groups.setdefault(k, []).append((i, m))
    except ValidationError as e:
        err = e.errors()[0]
        raise ConfigError(f"{args.config}: key 'sweep.vary' → '{'.'.join(map(str, err['loc']))}': "
                          f"{err['msg']}") from None  # fmt: skip
    except ValueError as e:
        raise ConfigError(f"{args.config}: key 'sweep.vary': {e}") from None
    out = Path(args.out or cfg.output)
    _check_output(out)
    for c in cfgs.values():
        _validate_optimizer(c, args.config)
    from tqdm import tqdm

    from designopt import archive, study
    from designopt.timing import Stopwatch

    tree: dict = {"members": {}}
    rows = []
    total_it = sum(cfgs[k].optimizer.n_iters for k in groups)
    with Stopwatch() as total, tqdm(total=total_it, desc="sweep", unit="it",
                                    disable=args.quiet) as bar:  # fmt: skip
        for k, mem in groups.items():
            c = cfgs[k]
            problem = _problem(c, args.config)
            opt_sets = [sw.split(m)[1] for _, m in mem]
            res = study.optimise(c, problem, members=opt_sets, progress=bar.update)
            for j, (i, m) in enumerate(mem):
                sets = {a: (b[j] if isinstance(b, list) else b) for a, b in res.settings.items()}
                one = type(res)(*(v[j] for v in res[:5]), sets)
                t = study.result_tree(c, problem, one)
                member_cfg = sw.apply(cfg, m)
                t["attrs"] = {
                    "overrides": m,
                    "config_resolved_yaml": study.resolved_yaml(member_cfg),
                }
                tree["members"][f"{i:03d}"] = t
                rows.append((i, m, float(t["final"]["f"]), t["final"]))
    attrs = {"kind": "sweep", "study": cfg.study.name, "config_yaml": text,
             "config_resolved_yaml": study.resolved_yaml(cfg), "config_resolved": cfg.model_dump_json(),
             "seed": cfg.seed, "n_members": len(members), "wall_time_s": total.wall,
             "compile_time_s": total.compile, "run_time_s": total.run,
             "vmapped_batches": len(groups)}  # fmt: skip
    archive.write(out, tree, attrs)
    print(f"{len(members)} members in {len(groups)} vmapped batch(es); wall {total.wall:.1f} s "
          f"(compile {total.compile:.1f} s, run {total.run:.1f} s)")  # fmt: skip
    for i, m, f, fin in sorted(rows):
        keys = ", ".join(f"{k} = {v:g}" for k, v in m.items())
        print(f"  [{i:3d}] {keys}:  f = {f:.5f}, f_k = {float(fin['f_k']):.4f}, "
              f"f_l = {float(fin['f_l']):.4f}, f_p = {float(fin['f_p']):.4f}")  # fmt: skip
    return _finish(out, args)


def cmd_bench(args: argparse.Namespace) -> int:
    from designopt.config import BenchConfig

    cfg, text = load(args.config, BenchConfig)
    if args.seed is not None:
        cfg.seed = args.seed
    out = Path(args.out or cfg.output)
    _check_output(out)
    from designopt.optim import resolve

    for i, v in enumerate([*cfg.bench.variants, cfg.bench.reference]):
        try:
            resolve(v)
        except ValueError as e:
            where = f"bench.variants.{i}" if i < len(cfg.bench.variants) else "bench.reference"
            raise ConfigError(f"{args.config}: key '{where}': {e}") from None
    from designopt.optim import make_params

    for v, st in cfg.bench.settings.items():
        try:
            make_params(v, **st)
        except ValueError as e:
            raise ConfigError(f"{args.config}: key 'bench.settings.{v}': {e}") from None
    from tqdm import tqdm

    from designopt import archive, benchsuite
    from designopt.figures import bench as bench_figs
    from designopt.timing import Stopwatch

    b = cfg.bench
    total = len(benchsuite.cases(cfg)) * len(b.variants) * b.n_iters
    with Stopwatch() as sw, tqdm(total=total, desc="bench", unit="it", disable=args.quiet) as bar:
        res = benchsuite.run_suite(cfg, progress=bar.update)
    st = res["stats"]
    for case in st:
        print(benchsuite.format_table(case, st[case], b.reference), end="\n\n")
    tree: dict = {"bench": {}}
    for case, per in res["results"].items():
        tree["bench"][case] = {
            v: {k: rec[k] for k in ("history", "best_f", "best_x", "converged_at")}
            | {"attrs": {"wall_s": rec["wall_s"], "compile_s": rec["compile_s"], "settings": rec["settings"]}}
            for v, rec in per.items()
        } | {"attrs": {"stats": st[case]}}  # fmt: skip
    attrs = {"kind": "bench", "config_yaml": text, "config_resolved": cfg.model_dump_json(),
             "seed": cfg.seed, "wall_time_s": sw.wall, "compile_time_s": sw.compile,
             "run_time_s": sw.run}  # fmt: skip
    archive.write(out, tree, attrs)
    hist = {c: {v: rec["history"] for v, rec in per.items()} for c, per in res["results"].items()}
    figs = bench_figs.draw(out.parent, st, hist, b.n_runs)
    print(f"{len(res['results'])} cases × {len(b.variants)} variants × {b.n_runs} runs × "
          f"{b.n_iters} iterations: wall {sw.wall:.1f} s (compile {sw.compile:.1f} s, run {sw.run:.1f} s)")  # fmt: skip
    print(
        f"archive: {out}\nfigures: {', '.join(p.name for p in figs if p.suffix == '.png')} in {out.parent}"
    )
    return 0


def draw_figures(path: Path) -> list[Path]:
    """Draw the figures an archive supports (run: Fig. 12-15; bench: Fig. 10-11 and curves;
    sweep: final f per member) beside it."""
    from designopt import archive
    from designopt.figures import bench as bench_figs

    a = archive.read(path)
    kind = a["attrs"].get("kind")
    folder = path.parent
    stem = path.stem
    if kind == "bench":
        cfg = a["attrs"]["config_resolved"]
        st = {c: g["attrs"]["stats"] for c, g in a["bench"].items() if c != "attrs"}
        hist = {c: {v: g[v]["history"] for v in g if v != "attrs"} for c, g in a["bench"].items()
                if c != "attrs"}  # fmt: skip
        return bench_figs.draw(folder, st, hist, cfg["bench"]["n_runs"])
    if kind == "run":
        return _draw_run(a, folder / f"{stem}_figures")
    if kind == "sweep":
        from designopt.figures import plt, save

        mem = {k: v for k, v in a["members"].items() if k != "attrs"}
        labels = [", ".join(f"{kk.split('.')[-1]}={vv:g}" for kk, vv in m["attrs"]["overrides"].items())
                  for m in mem.values()]  # fmt: skip
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
        axes[0].bar(range(len(mem)), [float(m["final"]["f"]) for m in mem.values()])
        axes[0].set_xticks(range(len(mem)), labels, rotation=60, ha="right", fontsize=7)
        axes[0].set_ylabel("final composite f")
        for lab, m in zip(labels, mem.values(), strict=True):
            h = m["optimizer"]["history"]
            axes[1].plot(np.median(h, axis=0), label=lab, lw=1)
        axes[1].set_xlabel("iteration")
        axes[1].set_ylabel("best f (median over runs)")
        axes[1].legend(fontsize=6)
        fig.tight_layout()
        return save(fig, folder / f"{stem}_figures", "sweep_members")
    raise ConfigError(f"{path}: archive kind {kind!r} has no figures")


def _draw_run(a: dict, folder: Path) -> list[Path]:
    import jax

    from designopt.studies.master9 import figures as m9_figs

    cfg = a["attrs"]["config_resolved"]
    names = [n.decode() for n in a["problem"]["names"]]
    fixed = a["problem"]["attrs"]["info"]["fixed"]
    br = a["best_run"]
    run = int(br["attrs"]["run_index"])
    x0 = a["optimizer"]["history_x"][run, 0]
    xf = a["final"]["x"]
    designs = {
        "initial (iteration 0)": {**fixed, **dict(zip(names, x0, strict=True)),
                                  "volume": float(br["volume"][0])},
        "final": {**fixed, **dict(zip(names, xf, strict=True)),
                  "volume": float(a["final"]["volume"])},
    }  # fmt: skip
    bl = cfg["study"]["indices"]["backlash_deg"]
    bl = bl if isinstance(bl, list) else [bl] * 3
    return m9_figs.draw(folder, br["iteration"], br, designs, bl, jax.random.key(cfg["seed"]))


def cmd_report(args: argparse.Namespace) -> int:
    p = Path(args.archive)
    _readable(p)
    figs = draw_figures(p)
    for f in figs:
        print(f)
    return 0


def _readable(p: Path) -> None:
    import h5py

    if not p.is_file():
        raise ConfigError(f"{p}: archive not found")
    try:
        with h5py.File(p, "r") as h:
            if not h.attrs.get("complete", False):
                raise ConfigError(f"{p}: archive is marked incomplete (an interrupted run); "
                                  "resume it with `designopt run CONFIG --resume`")  # fmt: skip
    except OSError as e:
        raise ConfigError(f"{p}: not a readable HDF5 archive ({e})") from None


def cmd_show(args: argparse.Namespace) -> int:
    import h5py

    p = Path(args.archive)
    if not p.is_file():
        raise ConfigError(f"{p}: archive not found")
    try:
        with h5py.File(p, "r") as h:
            at = h.attrs
            kind = at.get("kind", "run")
            print(f"{p}: {kind}, study {at.get('study', '-')}, seed {at.get('seed')}, "
                  f"complete {bool(at.get('complete'))}")  # fmt: skip
            if not at.get("complete"):
                c = h["checkpoint"]
                print(f"interrupted after {c.attrs['done']} iterations; best so far "
                      f"{np.min(c['history'][()][..., -1]):.5f}")  # fmt: skip
                return 0
            print(
                f"wall time {at['wall_time_s']:.1f} s (compile {at.get('compile_time_s', 0):.1f} s)"
            )
            if kind == "run":
                names = [n.decode() for n in h["problem/names"][()]]
                fin = h["final"]
                print("final design: " + ", ".join(
                    f"{n} = {v:.3f}" for n, v in zip(names, fin["x"][()], strict=True)))  # fmt: skip
                print(f"f = {fin['f'][()]:.5f} (stage {fin.attrs['stage']}); "
                      + "; ".join(f"{k} = {fin[k][()]:.5f} ± {fin[k + '_se'][()]:.1e}"
                                  for k in ("f_k", "f_l", "f_p")))  # fmt: skip
            elif kind == "sweep":
                import json

                for k, g in h["members"].items():
                    ov = json.loads(g.attrs["overrides"])
                    print(f"  [{k}] {ov}: f = {g['final/f'][()]:.5f}")
            elif kind == "bench":
                import json

                for case, g in h["bench"].items():
                    rows = json.loads(g.attrs["stats"])["rows"]
                    best = min(rows, key=lambda v: rows[v]["mean"])
                    print(f"  {case}: best mean {best} ({rows[best]['mean']:.3e})")
    except OSError as e:
        raise ConfigError(f"{p}: not a readable HDF5 archive ({e})") from None
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="designopt",
        description="Vectorized JAX design-space optimizer for surgical-robot mechanisms.",
    )
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run one study from a YAML config")
    r.add_argument("config", help="study config (YAML), e.g. configs/master9.yaml")
    r.add_argument("--seed", type=int, default=None, help="override the config's seed")
    r.add_argument("--out", default=None, help="override the archive path")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--resume", action="store_true",
                   help="continue the interrupted run kept in <output>.partial.h5")  # fmt: skip
    r.add_argument("--no-figures", action="store_true", help="write the archive only")
    r.set_defaults(func=cmd_run)
    w = sub.add_parser("sweep", help="run every member of a config's sweep section")
    w.add_argument("config", help="config with a sweep section, e.g. configs/sweep_gamma.yaml")
    w.add_argument("--seed", type=int, default=None, help="override the config's seed")
    w.add_argument("--out", default=None, help="override the archive path")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.add_argument("--no-figures", action="store_true", help="write the archive only")
    w.set_defaults(func=cmd_sweep)
    b = sub.add_parser("bench", help="run the PSO benchmark suite (seed 000 Fig. 10-11)")
    b.add_argument("config", help="bench config (YAML), e.g. configs/pso_benchmark.yaml")
    b.add_argument("--seed", type=int, default=None, help="override the config's seed")
    b.add_argument("--out", default=None, help="override the archive path")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    b.set_defaults(func=cmd_bench)
    p = sub.add_parser("report", help="draw the figures of an archive (PNG + PDF beside it)")
    p.add_argument("archive")
    p.set_defaults(func=cmd_report)
    s = sub.add_parser("show", help="print the summary of an archive")
    s.add_argument("archive")
    s.set_defaults(func=cmd_show)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as e:
        print(f"designopt: error: {e}", file=sys.stderr)
        return 2
    except Interrupted as e:
        print(f"designopt: interrupted; {e}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("designopt: interrupted; no archive written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
