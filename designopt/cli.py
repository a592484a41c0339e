"""The ``designopt`` command line: parse arguments, call ``designopt.pipeline``, print.

Exit statuses (docs/faults.md): 0 done; 1 a runtime fault (a disk full or unwritable
while writing), one line naming the path and the OS reason; 2 bad input or an output
refused before the run, one line; 130 (SIGINT) or 143 (SIGTERM, SIGHUP, --max-minutes)
interrupted, with the checkpoint kept and the command that resumes printed."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from designopt.errors import ConfigError, Interrupted, WriteError

WRITERS = ("run", "sweep", "scan", "bench", "report", "ik", "export")
"""Commands that write files: they run in the writer's session with signal handling."""


def _load(args: argparse.Namespace):
    from designopt import output
    from designopt.config import load
    from designopt.finite import check_seed

    cfg, text = load(args.config)
    if getattr(args, "seed", None) is not None:
        cfg.seed = check_seed(args.seed, f"--seed {args.seed}")
    if getattr(args, "overwrite", False):
        cfg.overwrite = True
    if getattr(args, "max_minutes", None) is not None:
        if not (math.isfinite(args.max_minutes) and args.max_minutes > 0):
            raise ConfigError(f"--max-minutes {args.max_minutes}: give a positive number")
        cfg.max_minutes = args.max_minutes
    ses = output.current()
    if ses is not None and cfg.max_minutes is not None:
        ses.set_deadline(cfg.max_minutes)
    _parallel(args, cfg)
    import jax

    if cfg.precision == "float64":  # the CLI is the program: it may switch JAX to 64-bit
        jax.config.update("jax_enable_x64", True)
    if cfg.compile_cache and not getattr(args, "no_cache", False):
        use_cache()
    return cfg, text


def _parallel(args: argparse.Namespace, cfg=None):
    """--devices and the multi-process flags (docs/scaling.md): JAX set up before its
    backend starts; a non-zero process of a job writes and prints nothing. Returns the
    parallel settings in force (None: one device, as ever)."""
    from designopt import output, parallel

    devices = getattr(args, "devices", None)
    coord, n_proc = getattr(args, "coordinator", None), getattr(args, "num_processes", None)
    multi = parallel.requested(coord, n_proc)
    p = cfg.parallel if cfg is not None else None
    if devices is not None or multi:
        p = (p or parallel.ParallelSettings()).model_copy(
            update={"devices": devices if devices else (p.devices if p else None)}
        )
        if cfg is not None:
            cfg.parallel = p
    timeout = p.timeout_s if p is not None else parallel.DEFAULT_TIMEOUT_S
    parallel.configure(p.devices if p is not None else devices, coord, n_proc,
                       getattr(args, "process_id", None), timeout)  # fmt: skip
    output.set_writer(parallel.is_writer())
    return p


def use_cache() -> None:
    """Keep XLA's compiled programs in :func:`cache_dir` (an unwritable folder only costs
    compile time)."""
    import jax

    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def cache_dir() -> Path:
    """Where compiled programs are kept between runs: ``$DESIGNOPT_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/designopt/jax``, else ``~/.cache/designopt/jax``."""
    import os

    if os.environ.get("DESIGNOPT_CACHE_DIR"):
        return Path(os.environ["DESIGNOPT_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "designopt" / "jax"


ETA_AFTER_S = 60.0
"""A job whose optimizer is estimated to need longer than this prints its ETA once."""


def _eta_text(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.3g} days"


def _progress(quiet: bool):
    """A tqdm bar (none with --quiet) that prints, once, an estimated time when the job
    is long: after the first timed chunk (the first one includes compilation)."""

    @contextlib.contextmanager
    def bar(total: int, desc: str) -> Iterator[Callable[[int], None]]:
        import time

        from tqdm import tqdm

        seen = {"n": 0, "t": None, "told": False}

        def update(n: int) -> None:
            t.update(n)
            now = time.monotonic()
            if seen["t"] is not None and not seen["told"] and n > 0:
                left = (now - seen["t"]) / n * (total - seen["n"] - n)
                seen["told"] = True
                if left > ETA_AFTER_S:
                    msg = (f"designopt: {desc}: about {_eta_text(left)} left "
                           f"({total - seen['n'] - n} of {total} iterations at "
                           f"{_eta_text((now - seen['t']) / n)} each); --max-minutes N stops "
                           "cleanly with a checkpoint")  # fmt: skip
                    t.write(msg, file=sys.stderr)
            seen["n"] += n
            seen["t"] = now

        from designopt import output

        with tqdm(total=total, desc=desc, unit="it", disable=quiet or not output.writes()) as t:
            yield update

    return bar


def _out(args: argparse.Namespace, cfg) -> Path:
    return Path(args.out or cfg.output_path())


def _finish(rep, args: argparse.Namespace) -> int:
    """Print the report's lines, the archive path and draw the figures unless --no-figures
    (a figure write fault: exit 1, the archive kept)."""
    from designopt import output, pipeline

    if not output.writes():  # a non-zero process of a multi-process job: process 0 reports
        return 0
    for line in rep.lines:
        print(line)
    if getattr(args, "dry_run", False):
        return 0
    print(f"archive: {rep.out}")
    if not getattr(args, "no_figures", False):
        ses = output.current()
        kept = f"the archive {rep.out} is complete (`designopt report {rep.out}` draws its figures)"
        if ses is not None:
            ses.kept = lambda: kept
        try:
            figs = pipeline.draw_figures(rep.out)
        except WriteError as e:
            raise WriteError(f"{e}; {kept}") from None
        print(f"figures: {len(figs) // 2} (PNG + PDF) in {figs[0].parent}")
    return 0


def resume_command(args: argparse.Namespace, cfg) -> str:
    """The exact command that resumes this run: the same config, output, seed and every
    other option given (without --resume, which the caller appends)."""
    import shlex

    parts = ["designopt", "run", args.config, "--out", str(_out(args, cfg)),
             "--seed", str(cfg.seed)]  # fmt: skip
    for flag in ("quiet", "no_figures", "no_cache", "overwrite"):
        if getattr(args, flag, False):
            parts.append("--" + flag.replace("_", "-"))
    if args.max_minutes is not None:
        parts += ["--max-minutes", f"{args.max_minutes:g}"]
    if getattr(args, "devices", None) is not None:
        parts += ["--devices", str(args.devices)]
    return shlex.join(parts)


def cmd_run(args: argparse.Namespace) -> int:
    from designopt import pipeline

    cfg, text = _load(args)
    rep = pipeline.run(cfg, text, args.config, _out(args, cfg), resume=args.resume,
                       progress=_progress(args.quiet), resume_hint=resume_command(args, cfg),
                       dry_run=args.dry_run)  # fmt: skip
    return _finish(rep, args)


def cmd_sweep(args: argparse.Namespace) -> int:
    from designopt import pipeline

    cfg, text = _load(args)
    rep = pipeline.sweep(cfg, text, args.config, _out(args, cfg), _progress(args.quiet),
                         dry_run=args.dry_run)  # fmt: skip
    return _finish(rep, args)


def cmd_scan(args: argparse.Namespace) -> int:
    from designopt import pipeline

    cfg, text = _load(args)
    out = (
        Path(args.out) if args.out else _out(args, cfg).with_name(f"{_out(args, cfg).stem}_scan.h5")
    )
    rep = pipeline.scan(cfg, text, args.config, out, _progress(args.quiet), dry_run=args.dry_run)
    return _finish(rep, args)


def _parse_design(items: list[str]) -> dict[str, float]:
    """--design NAME=VALUE items as {name: value}: every value a usable number
    (designopt.finite), every name given once."""
    from designopt.finite import check_value

    out: dict[str, float] = {}
    for it in items:
        name, sep, val = it.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ConfigError(f"--design '{it}': expected NAME=NUMBER, e.g. --design l1=0.5")
        if name in out:
            raise ConfigError(f"--design {name}: given twice ({name}={out[name]:g} and {it}); "
                              "give each variable once")  # fmt: skip
        try:
            out[name] = check_value(f"--design {name}", val)
        except ConfigError as e:
            raise ConfigError(f"{e}; expected NAME=NUMBER, e.g. --design l1=0.5") from None
    return out


def cmd_eval(args: argparse.Namespace) -> int:
    from designopt import pipeline

    cfg, _ = _load(args)
    design = _parse_design(args.design)
    res = pipeline.evaluate(cfg, design, where=args.config)
    feasible = None if "violation" not in res else bool(res["violation"] <= 0)
    if args.json:
        print(json.dumps(res | ({} if feasible is None else {"feasible": feasible})))
        return 0
    box = cfg.study.variables
    design = {k: design.get(k, 0.5 * (lo + hi)) for k, (lo, hi) in box.items()}
    for k, v in res.items():
        if k.endswith("_se"):
            continue
        se = res.get(k + "_se")
        print(f"{k:>15} = {v:.6g}" + (f" ± {se:.2g}" if se is not None else ""))
    print("design: " + ", ".join(f"{k} = {v:g}" for k, v in design.items()))
    if feasible is not None:
        print("constraints: " + ("feasible" if feasible else
                                 f"violated by {res['violation']:.3g} (an infeasible design)"))  # fmt: skip
    return 0


def cmd_studies(args: argparse.Namespace) -> int:
    from designopt.studies import STUDIES

    for name, st in STUDIES.items():
        print(f"{name}: {st.title}")
        for k, v in st.meta.items():
            print(f"  {k}: {v}")
        if st.example_config:
            print(f"  example: {st.example_config}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from designopt import benchsuite

    return benchsuite.command(args.config, args.seed, args.out, args.quiet, args.overwrite,
                              _parallel(args))  # fmt: skip


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


def cmd_ik(args: argparse.Namespace) -> int:
    from designopt.studies.davinci import ikcli

    return ikcli.cmd_ik(args, _load(args))


def cmd_chain(args: argparse.Namespace) -> int:
    from designopt.studies.serial import commands

    return commands.cmd_chain(args, _load(args))


def cmd_export(args: argparse.Namespace) -> int:
    from designopt.studies.serial import commands

    return commands.cmd_export(args)


def cmd_report(args: argparse.Namespace) -> int:
    from designopt import pipeline

    p = Path(args.archive)
    _readable(p)
    if not getattr(args, "no_cache", False):
        use_cache()  # the figure kernels compile once, then load
    for f in pipeline.draw_figures(p):
        print(f)
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    import h5py
    import numpy as np

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
            if kind == "run" and "problem" not in h:  # a replay (Study.replay)
                for g in h.values():
                    if "summary" in g.attrs:
                        print(g.attrs["summary"])
            elif kind == "run":
                names = [n.decode() for n in h["problem/names"][()]]
                fin = h["final"]
                print("final design: " + ", ".join(
                    f"{n} = {v:.4f}" for n, v in zip(names, fin["x"][()], strict=True)))  # fmt: skip
                from designopt.studies import STUDIES

                cfg = json.loads(at["config_resolved"])
                st = STUDIES.get(at.get("study", ""))
                subs = [k for k in fin if k + "_se" in fin and k != "f"][:6]
                if st is not None:
                    subs = [k for k in st.summary(st.settings.model_validate(cfg["study"]))
                            if k + "_se" in fin]  # fmt: skip
                print(f"f = {fin['f'][()]:.5f} (stage {fin.attrs['stage']}); "
                      + "; ".join(f"{k} = {fin[k][()]:.5f} ± {fin[k + '_se'][()]:.1e}"
                                  for k in subs))  # fmt: skip
            elif kind == "sweep":
                for k, g in h["members"].items():
                    ov = json.loads(g.attrs["overrides"])
                    print(f"  [{k}] {ov}: f = {g['final/f'][()]:.5f}")
            elif kind == "scan":
                from designopt.pipeline import best_lines

                sc = h["scan"]
                f = sc["f"][()]
                names = [n.decode() for n in sc["names"][()]]
                viol = sc["violation"][()] if "violation" in sc else None
                print(f"{len(f)} designs")
                for line in best_lines(names, sc["x"][()], f, viol):
                    print(line)
            elif kind == "ik":
                from designopt.ikreport import summary_lines

                g = h["ik"]
                ik = {k: v[()] for k, v in g.items()} | {"attrs": dict(g.attrs)}
                for line in summary_lines(ik):
                    print(line)
            elif kind == "bench":
                for case, g in h["bench"].items():
                    rows = json.loads(g.attrs["stats"])["rows"]
                    best = min(rows, key=lambda v: rows[v]["mean"])
                    print(f"  {case}: best mean {best} ({rows[best]['mean']:.3e})")
    except OSError as e:
        raise ConfigError(f"{p}: not a readable HDF5 archive ({e})") from None
    return 0


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: give a positive integer")
    return n


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="designopt",
        description="Vectorized JAX design-space optimizer for surgical-robot mechanisms.",
    )
    sub = ap.add_subparsers(dest="command", required=True)

    def common(p, seed=True, out=True, quiet=True, figures=True, dry=True):
        p.add_argument("config", help="config (YAML), e.g. configs/<study>.yaml")
        if seed:
            p.add_argument("--seed", type=int, default=None, help="override the config's seed")
        if out:
            p.add_argument("--out", default=None, help="override the archive path")
            p.add_argument("--overwrite", action="store_true",
                           help="replace an existing archive (else refused, exit 2)")  # fmt: skip
        if dry:
            p.add_argument("--dry-run", action="store_true",
                           help="perform every check (config, optimizer, memory and disk "
                                "estimate, output) and write nothing")  # fmt: skip
        if quiet:
            p.add_argument("--quiet", action="store_true", help="no progress bar")
        if figures:
            p.add_argument("--no-figures", action="store_true", help="write the archive only")
        p.add_argument("--no-cache", action="store_true",
                       help="do not read or write the persistent compilation cache")  # fmt: skip
        g = p.add_argument_group("devices and processes (docs/scaling.md)")
        g.add_argument("--devices", type=_positive, default=None, metavar="N",
                       help="use N devices (all processes together; on CPU, N host devices); "
                            "the axis to shard comes from the config's parallel section")  # fmt: skip
        g.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                       help="join a multi-process job (jax.distributed) at this coordinator")  # fmt: skip
        g.add_argument("--num-processes", type=_positive, default=None, metavar="N")
        g.add_argument("--process-id", type=int, default=None, metavar="I")

    r = sub.add_parser("run", help="optimise one study from a YAML config")
    common(r)
    r.add_argument("--resume", action="store_true",
                   help="continue the interrupted run kept in <output>.partial.h5")  # fmt: skip
    r.add_argument("--max-minutes", type=float, default=None, metavar="M",
                   help="stop cleanly after M minutes, keeping a checkpoint to --resume "
                        "(exit 143)")  # fmt: skip
    r.set_defaults(func=cmd_run)
    w = sub.add_parser("sweep", help="run every member of a config's sweep section")
    common(w)
    w.set_defaults(func=cmd_sweep)
    sc = sub.add_parser("scan", help="score the designs of a config's scan section (no optimiser)")
    common(sc)
    sc.set_defaults(func=cmd_scan)
    e = sub.add_parser("eval", help="print every index of one design with its standard error")
    common(e, out=False, quiet=False, figures=False, dry=False)
    e.add_argument("--design", action="append", default=[], metavar="NAME=VALUE",
                   help="a design variable's value (repeat; others: middle of their box)")  # fmt: skip
    e.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    e.set_defaults(func=cmd_eval)
    st = sub.add_parser("studies", help="list the registered studies")
    st.set_defaults(func=cmd_studies)
    b = sub.add_parser(
        "bench",
        help="run the optimizer benchmark suite (the PTPSO paper, IEEE Access 2019, Fig. 10-11)",
    )
    common(b, figures=False, dry=False)
    b.set_defaults(func=cmd_bench)
    k = sub.add_parser(
        "ik",
        help="inverse kinematics of the da Vinci arm for poses from a CSV or HDF5 file",
        description="Solve the da Vinci patient-side arm's inverse kinematics (Applied "
        "Sciences 2019) for every pose of a file: CSV with a header row and columns "
        "T00..T33 (row-major 4x4, mm) or x,y,z,qw,qx,qy,qz; or HDF5 with a dataset "
        "'poses' (N, 4, 4). Writes ik/q (q3 in mm, the others in rad), ik/success, "
        "ik/iterations, ik/pos_err (mm) and ik/rot_err (rad).",
    )
    k.add_argument(
        "config", help="config (YAML) with a davinci study, e.g. configs/davinci_ik.yaml"
    )
    k.add_argument("--poses", required=True, metavar="PATH", help="poses file (.csv or .h5)")
    k.add_argument("--out", default=None, metavar="PATH",
                   help="archive path (default results/davinci/<poses name>_ik.h5)")  # fmt: skip
    k.add_argument("--trajectory", action="store_true",
                   help="solve in row order, each pose warm-started from the previous solution")  # fmt: skip
    k.add_argument("--csv", action="store_true",
                   help="also write the joints, one row per pose, to <archive stem>_joints.csv")  # fmt: skip
    k.add_argument("--overwrite", action="store_true", help="replace an existing archive")
    k.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")
    k.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    k.set_defaults(func=cmd_ik)
    c = sub.add_parser(
        "chain",
        help="print a serial study's chain as imported (URDF or DH) and check it",
        description="Print the chain of a serial study as imported: joints, types, axes, "
        "limits, which numbers are design variables, the forward kinematics of the zero "
        "pose and of --q; for a URDF chain, cross-check the import against the URDF "
        "parser's own forward kinematics at random joint values (docs/urdf.md).",
    )
    c.add_argument("config", help="config (YAML) with a serial study, e.g. configs/urdf_arm.yaml")
    c.add_argument("--q", default=None, metavar="Q1,Q2,...",
                   help="joint values (degrees for revolute, length units for prismatic)")  # fmt: skip
    c.add_argument("--design", action="append", default=[], metavar="NAME=VALUE",
                   help="a design variable's value (repeat; others: middle of their box)")  # fmt: skip
    c.add_argument("--seed", type=int, default=None, help="seed of the random check poses")
    c.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")
    c.set_defaults(func=cmd_chain)
    x = sub.add_parser(
        "export",
        help="write the best design of a run archive back as URDF",
        description="Write the URDF of a serial study's run (or scan) archive with the best "
        "design's values in the chain's `set` fields and nothing else changed (docs/urdf.md).",
    )
    x.add_argument("archive")
    x.add_argument("--urdf", required=True, metavar="OUT.urdf", help="the URDF file to write")
    x.add_argument("--overwrite", action="store_true", help="replace an existing file")
    x.set_defaults(func=cmd_export)
    p = sub.add_parser("report", help="draw the figures of an archive (PNG + PDF beside it)")
    p.add_argument("archive")
    p.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")
    p.set_defaults(func=cmd_report)
    s = sub.add_parser("show", help="print the summary of an archive")
    s.add_argument("archive")
    s.set_defaults(func=cmd_show)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Run one command; its exit status (module docstring, docs/faults.md)."""
    args = build_parser().parse_args(argv)
    try:
        if args.command in WRITERS and not getattr(args, "dry_run", False):
            from designopt import output

            with output.session(signals=True) as ses:
                try:
                    return args.func(args)
                except KeyboardInterrupt:  # a signal outside the loop: keep what is done
                    with ses.writing():
                        if ses.flush is not None:
                            ses.flush()
                        raise ses.interrupted() from None
                except Exception as e:
                    _peer_lost(e, ses)
                    raise
        return args.func(args)
    except ConfigError as e:
        print(f"designopt: error: {e}", file=sys.stderr)
        return 2
    except WriteError as e:
        print(f"designopt: error: {e}", file=sys.stderr)
        return 1
    except Interrupted as e:
        print(f"designopt: {e}", file=sys.stderr)
        return e.code
    except KeyboardInterrupt:
        print("designopt: interrupted (SIGINT); nothing written", file=sys.stderr)
        return 130


def _peer_lost(e: BaseException, ses) -> None:
    """A process of a multi-process job died or stopped answering: the newest checkpoint
    written (process 0), one line, exit 1 at once (``jax.distributed``'s shutdown would
    wait for the lost peer). Returns when ``e`` is something else."""
    import os

    from designopt import parallel

    if "jax" not in sys.modules or (lost := parallel.peer_error(e)) is None:
        return
    kept = ""
    with contextlib.suppress(Exception), ses.writing():
        if ses.flush is not None:
            ses.flush()
        kept = "; " + ses.kept()
    ses.cleanup()
    print(f"designopt: error: {lost}{kept}", file=sys.stderr)
    with contextlib.suppress(Exception):
        sys.stdout.flush()
        sys.stderr.flush()
    os._exit(1)


if __name__ == "__main__":
    sys.exit(main())
