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

WRITERS = ("run", "sweep", "scan", "bench", "report")
"""Commands that write files: they run in the writer's session with signal handling (a
study's own commands say so in ``Command.writes``)."""


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
            figs = pipeline.draw_figures(rep.out, rep.record)
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
    res = {k: float(v[0]) for k, v in pipeline.evaluate(cfg, design, where=args.config).items()}
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


def cmd_report(args: argparse.Namespace) -> int:
    from designopt import archive, pipeline
    from designopt.results import CheckpointRecord

    p = Path(args.archive)
    rec = archive.load(p)
    if isinstance(rec, CheckpointRecord):
        raise ConfigError(f"{p}: archive is marked incomplete (an interrupted run); "
                          "resume it with `designopt run CONFIG --resume`")  # fmt: skip
    if not getattr(args, "no_cache", False):
        use_cache()  # the figure kernels compile once, then load
    for f in pipeline.draw_figures(p, rec):
        print(f)
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from designopt import archive

    p = Path(args.archive)
    rec = archive.load(p)
    at = rec.attrs
    print(f"{p}: {at.get('kind', 'run')}, study {at.get('study', '-')}, seed {at.get('seed')}, "
          f"complete {bool(at.get('complete'))}")  # fmt: skip
    for line in rec.summary():
        print(line)
    return 0


class Context:
    """What a study's own command (``Study.commands``) gets from the CLI."""

    @staticmethod
    def load(args: argparse.Namespace):
        """``args.config`` loaded as every command loads it: --seed, --devices, precision
        (x64), the compilation cache."""
        return _load(args)

    @staticmethod
    def progress(quiet: bool):
        return _progress(quiet)


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
    from designopt.studies import STUDIES

    for study in STUDIES.values():
        for c in study.commands:
            q = sub.add_parser(c.name, help=c.help, description=c.description or None)
            c.arguments(q)
            q.set_defaults(func=lambda a, c=c: c.run(a, Context()), writes=c.writes)
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
        writer = args.command in WRITERS or getattr(args, "writes", False)
        if writer and not getattr(args, "dry_run", False):
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
