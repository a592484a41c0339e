"""The ``designopt`` command line: parse arguments, call ``designopt.app.pipeline``, print.

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
import time
from pathlib import Path

from designopt.cli.setup import DESIGN_FLAG, design_argument, set_argument, use_cache
from designopt.cli.setup import load_args as _load
from designopt.cli.setup import out_path as _out
from designopt.cli.setup import parallel_flags as _parallel
from designopt.cli.setup import parse_design as _parse_design
from designopt.cli.setup import progress as _progress
from designopt.cli.setup import resume_command as _resume_command
from designopt.core.errors import ConfigError, Interrupted, WriteError

_IMPORTED = time.perf_counter()

WRITERS = ("run", "sweep", "scan", "bench", "report")
"""Commands that write files: they run in the writer's session with signal handling (a
study's own commands say so in ``Command.writes``)."""


def _finish(rep, args: argparse.Namespace, clock=None) -> int:
    """Print the report's lines, the archive path and draw the figures unless --no-figures
    (a figure write fault: exit 1, the archive kept); with ``clock`` (a run's Stopwatch,
    started after the config was loaded) the wall time end to end, split by stage."""
    from designopt.app import pipeline
    from designopt.io import writer

    if not writer.writes():  # a non-zero process of a multi-process job: process 0 reports
        return 0
    for line in rep.lines:
        print(line)
    if getattr(args, "dry_run", False):
        return 0
    print(f"archive: {rep.out}")
    figures_s = 0.0
    if not getattr(args, "no_figures", False):
        import time

        ses = writer.current()
        kept = f"the archive {rep.out} is complete (`designopt report {rep.out}` draws its figures)"
        if ses is not None:
            ses.kept = lambda: kept
        t0 = time.perf_counter()
        try:
            with _progress(args.quiet)(None, "drawing figures"):
                figs = pipeline.draw_figures(rep.out, rep.record)
        except WriteError as e:
            raise WriteError(f"{e}; {kept}") from None
        figures_s = time.perf_counter() - t0
        print(f"figures: {len(figs) // 2} (PNG + PDF) in {figs[0].parent}")
    if clock is not None and rep.record is not None:
        clock.__exit__(None, None, None)
        print(wall_line(rep.record.attrs, clock, figures_s))
    return 0


def wall_line(attrs: dict, clock, figures_s: float) -> str:
    """The wall time from the process's start to this line, split into start-up (Python,
    imports, the config), setup, optimizer, scoring, figures and the rest (archive,
    printing), with the compile time of it all and the XLA programs compiled. The exit
    after it skips interpreter teardown (``console``)."""
    startup = max(process_age() - clock.wall, 0.0)
    a = {k: float(attrs.get(k + "_time_s", 0.0)) for k in ("setup", "optimizer", "post")}
    total = startup + clock.wall
    other = max(clock.wall - sum(a.values()) - figures_s, 0.0)
    return (f"wall {total:.1f} s end to end = start-up {startup:.1f} s + setup "
            f"{a['setup']:.1f} s + optimizer {a['optimizer']:.1f} s + scoring {a['post']:.1f} s"
            f" + figures {figures_s:.1f} s + archive and the rest {other:.1f} s; compile "
            f"{clock.compile:.1f} s of it ({clock.compilations} XLA programs)")


EXEC_GAP_S = 1.0
"""Python's own start before it imports the CLI takes some 0.04 s: a process whose /proc
age exceeds its time since that import by more than this was started by a shell that
``exec``-ed it (``bash -c 'pip install … && designopt run …'``, the last command of a
subshell), and /proc dates it from the shell's fork."""


def process_age() -> float:
    """Seconds since this process started (Linux: /proc; elsewhere, or when the process
    was ``exec``-ed from an older one, since designopt's CLI was imported)."""
    import os
    import time

    imported = time.perf_counter() - _IMPORTED
    try:
        with open("/proc/self/stat") as f:
            start = int(f.read().rsplit(")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
        with open("/proc/uptime") as f:
            age = max(float(f.read().split()[0]) - start, 0.0)
    except (OSError, ValueError, IndexError):
        return imported
    return age if age - imported <= EXEC_GAP_S else imported


def cmd_run(args: argparse.Namespace) -> int:
    from designopt.app import pipeline
    from designopt.core.timing import Stopwatch

    cfg, text = _load(args)
    clock = Stopwatch().__enter__()  # closed by _finish, after the figures
    rep = pipeline.run(cfg, text, args.config, _out(args, cfg), resume=args.resume,
                       progress=_progress(args.quiet), resume_hint=_resume_command(args, cfg),
                       dry_run=args.dry_run)  # fmt: skip
    return _finish(rep, args, None if args.dry_run else clock)


def cmd_sweep(args: argparse.Namespace) -> int:
    from designopt.app import pipeline

    cfg, text = _load(args)
    rep = pipeline.sweep(cfg, text, args.config, _out(args, cfg), _progress(args.quiet),
                         dry_run=args.dry_run)  # fmt: skip
    return _finish(rep, args)


def cmd_scan(args: argparse.Namespace) -> int:
    from designopt.app import pipeline

    cfg, text = _load(args)
    out = (
        Path(args.out) if args.out else _out(args, cfg).with_name(f"{_out(args, cfg).stem}_scan.h5")
    )
    rep = pipeline.scan(cfg, text, args.config, out, _progress(args.quiet), dry_run=args.dry_run)
    return _finish(rep, args)


def cmd_eval(args: argparse.Namespace) -> int:
    from designopt.app import pipeline
    from designopt.results.base import value_text

    cfg, _ = _load(args)
    design = _parse_design(args.design)
    res, warns, units = pipeline.evaluate_one(cfg, design, where=args.config)
    feasible = None if "violation" not in res else bool(res["violation"] <= 0)
    if args.json:  # valid JSON always: a value that is n/a (NaN) is null
        out = {k: (v if math.isfinite(v) else None) for k, v in res.items()}
        out |= ({} if feasible is None else {"feasible": feasible}) | {"warnings": warns}
        print(json.dumps(out, allow_nan=False))
        return 0
    box = cfg.study.variables
    design = {k: design.get(k, 0.5 * (lo + hi)) for k, (lo, hi) in box.items()}
    counts = ("_se", "_n", "_of")  # an index's SE and a ratio's counts: printed with it
    shown = [k for k in res if not (k.endswith(counts) and k.rsplit("_", 1)[0] in res)]
    w = max([15, *(len(k) for k in shown)])  # the names right-aligned on their "="
    for k, v in res.items():
        if k not in shown:
            continue
        txt = value_text(v, res.get(k + "_se"), ".6g", ".2g", res.get(k + "_n"),
                         res.get(k + "_of"))  # fmt: skip
        u = units.get(k, "")
        print(f"{k:>{w}} = {txt}" + (f" {u}" if u not in ("", "-") and "n/a" not in txt else ""))
    print("design: " + ", ".join(f"{k} = {v:g}" + (f" {units[k]}" if units.get(k, "-") != "-" else "")
                                 for k, v in design.items()))  # fmt: skip
    front = getattr(cfg.study, "pareto", None)
    if front is not None:
        from designopt.app.config import senses

        print("a front's config: its objectives are " + ", ".join(
            f"{k} ({s})" for k, s in senses(front).items()) + " (no weighted f)")  # fmt: skip
    if feasible is not None:
        print("constraints: " + ("feasible" if feasible else
                                 f"violated by {res['violation']:.3g} (an infeasible design)"))  # fmt: skip
    for w in warns:
        print(f"warning: {w}")
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
    from designopt.app import bench

    return bench.command(args.config, args.seed, args.out, args.quiet, args.overwrite,
                         _parallel(args))  # fmt: skip


def cmd_report(args: argparse.Namespace) -> int:
    from designopt.app import pipeline, records
    from designopt.results import CheckpointRecord

    p = Path(args.archive)
    rec = records.load(p)
    if isinstance(rec, CheckpointRecord):
        raise ConfigError(f"{p}: archive is marked incomplete (an interrupted run); "
                          "resume it with `designopt run CONFIG --resume`")  # fmt: skip
    if getattr(rec.config, "precision", None) == "float64":  # redraw as the run drew
        import jax

        jax.config.update("jax_enable_x64", True)
    if not getattr(args, "no_cache", False):
        use_cache()  # the figure kernels compile once, then load
    if getattr(args, "html", False):
        print(pipeline.write_html(p, rec))
        return 0
    for f in pipeline.draw_figures(p, rec):
        print(f)
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from designopt.app import records

    p = Path(args.archive)
    rec = records.load(p)
    out = None
    if args.csv is not None:  # checked before anything is printed
        if "targets" not in rec:
            raise ConfigError(f"{p}: --csv writes the final design at every target of a task "
                              "run (the archive's targets group); this archive has none")  # fmt: skip
        out = Path(args.csv) if args.csv else p.with_name(f"{p.stem}_targets.csv")
        if out.suffix.lower() != ".csv" or out.is_dir():
            raise ConfigError(f"--csv {args.csv}: give a .csv file name")
    at = rec.attrs
    print(f"{p}: {at.get('kind', 'run')}, study {at.get('study', '-')}, seed {at.get('seed')}, "
          f"complete {bool(at.get('complete'))}")  # fmt: skip
    for line in rec.summary():
        print(line)
    if out is not None:
        from designopt.io import writer
        from designopt.results.run import targets_csv_text

        writer.write_file(out, targets_csv_text(rec["targets"]).encode(), "targets CSV")
        print(f"wrote {out}")
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
        """The progress bar (none with ``--quiet``)."""
        return _progress(quiet)

    @staticmethod
    def design(items: list[str]) -> dict[str, float]:
        """``--design NAME=VALUE`` items as {name: value}, each a usable number."""
        return _parse_design(items)

    @staticmethod
    def load_record(path: str | Path):
        """The record an archive holds, bound to its config (``designopt.load``)."""
        from designopt.app import records

        return records.load(path)


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: give a positive integer")
    return n


class Parser(argparse.ArgumentParser):
    """argparse with a usage error as one line, ``designopt: error: <argparse's message>;
    see <prog> --help``, exit 2 (argparse prints the usage block first); ``--help`` as
    argparse prints it. Every subparser is one too (``parser_class``). ``--design a=1 b=2``
    (one flag, several NAME=VALUE) stops at the first word without '=', so a CONFIG after
    it is still the positional."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"designopt: error: {message}; see {self.prog} --help\n")

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
        ns, extra = self.parse_known_args(args, namespace)
        if extra:
            cmd = getattr(ns, "command", None)
            prog = f"{self.prog} {cmd}" if cmd else self.prog
            self.exit(2, f"designopt: error: unrecognized arguments: {' '.join(extra)}; "
                         f"see {prog} --help\n")  # fmt: skip
        return ns

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        if args is not None and DESIGN_FLAG in self._option_string_actions:
            args = _design_items(list(args))
        return super().parse_known_args(args, namespace)


def _design_items(args: list[str]) -> list[str]:
    """``--design a=1 b=2`` as ``--design=a=1 --design=b=2``: the values of one flag are
    the words with '=' after it (not an option), so a positional after them stays one."""
    out: list[str] = []
    i = 0
    while i < len(args):
        word = args[i]
        if word == "--":
            return out + args[i:]
        if word == DESIGN_FLAG and i + 1 < len(args) and _item(args[i + 1]):
            i += 1
            while i < len(args) and _item(args[i]):
                out.append(f"{DESIGN_FLAG}={args[i]}")
                i += 1
            continue
        out.append(word)
        i += 1
    return out


def _item(word: str) -> bool:
    return "=" in word and not word.startswith("-")


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(
        prog="designopt",
        description="Vectorized JAX design-space optimizer for surgical-robot mechanisms.",
    )
    sub = ap.add_subparsers(dest="command", required=True, parser_class=Parser)

    def common(p, seed=True, out=True, quiet=True, figures=True, dry=True):
        p.add_argument("config", help="config (YAML), e.g. configs/<study>.yaml")
        set_argument(p)
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
    design_argument(
        e,
        "design variables' values, one or several after one flag or the flag "
        "repeated (others: middle of their box)",
    )
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
    from designopt.cli import ik
    from designopt.studies import STUDIES

    ik.add_parser(sub)  # one `ik` for every study with Study.ik
    for study in STUDIES.values():
        for c in study.commands:
            q = sub.add_parser(c.name, help=c.help, description=c.description or None)
            c.arguments(q)
            if any(a.dest == "config" for a in q._actions):  # loads a config: --set too
                set_argument(q)
            q.set_defaults(func=lambda a, c=c: c.run(a, Context()), writes=c.writes)
    p = sub.add_parser("report", help="draw the figures of an archive (PNG + PDF beside it)")
    p.add_argument("archive")
    p.add_argument("--html", action="store_true",
                   help="write one self-contained interactive page <archive stem>.html beside "
                        "it instead (offline, no server; docs/figures.md)")  # fmt: skip
    p.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")
    p.set_defaults(func=cmd_report)
    s = sub.add_parser("show", help="print the summary of an archive")
    s.add_argument("archive")
    s.add_argument("--csv", nargs="?", const="", default=None, metavar="PATH.csv",
                   help="also write the final design at every target of a task run (joints "
                        "in degrees, reached, 1/k, clearance; per arm) to PATH.csv, default "
                        "<archive stem>_targets.csv beside the archive")  # fmt: skip
    s.set_defaults(func=cmd_show)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Run one command; its exit status (module docstring, docs/faults.md). A usage error
    is one line and 2, ``--help`` 0 (both returned, not raised)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # argparse: --help, or a usage error (Parser.error)
        return e.code if isinstance(e.code, int) else 2
    try:
        writes = args.command in WRITERS or getattr(args, "writes", False)
        if writes and not getattr(args, "dry_run", False):
            from designopt.io import writer

            with writer.session(signals=True) as ses:
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
    except BrokenPipeError:  # the reader went away (`designopt show A | head`): stop quietly
        import os

        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, as a shell reports a process killed by it


def _peer_lost(e: BaseException, ses) -> None:
    """A process of a multi-process job died or stopped answering: the newest checkpoint
    written (process 0), one line, exit 1 at once (``jax.distributed``'s shutdown would
    wait for the lost peer). Returns when ``e`` is something else."""
    import os

    from designopt.core import devices

    if "jax" not in sys.modules or (lost := devices.peer_error(e)) is None:
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


def console() -> None:
    """The ``designopt`` command: :func:`main`, then a prompt exit. Everything is written
    and closed when main returns; interpreter teardown (freeing JAX's and matplotlib's
    modules and XLA's client, 0.3-0.8 s after a run on 2 cores) is skipped. A process of a
    multi-process job exits normally (``jax.distributed``'s shutdown meets its peers)."""
    rc = main()
    jax = sys.modules.get("jax")
    if jax is not None and jax.distributed.is_initialized():
        sys.exit(rc)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    import os

    os._exit(int(rc or 0))


if __name__ == "__main__":
    console()
