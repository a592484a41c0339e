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
from typing import Any

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
        print(wall_line(rep.record.attrs, clock, figures_s, getattr(args, "config_s", 0.0)))
    return 0


def wall_line(attrs: dict, clock, figures_s: float, config_s: float = 0.0) -> str:
    """The wall time from the process's start to this line, split into parts that add up
    to it: start-up (Python, imports, and the config's ``config_s`` seconds: reading and
    validating it, the study's checks), setup, optimizer, scoring, figures and the rest
    (archive, printing). Then the compile time within it (tracing, lowering, XLA
    compiling or loading from the compilation cache) and the one count of XLA programs:
    every program compiled or loaded from the cache from the config on, the figures'
    included (``clock``: a Stopwatch started before the config was read). The exit after
    it skips interpreter teardown (``console``)."""
    if "optimizer_time_s" in attrs:
        names = {"setup": "setup", "optimizer": "optimizer", "post": "scoring"}
    else:  # a run that is not an optimisation (a study's replay): its one stage
        names = {"wall": "run"}
    a = {v: float(attrs.get(k + "_time_s", 0.0)) for k, v in names.items()}
    before = max(process_age() - clock.wall, 0.0)  # Python and imports, before the clock
    startup = before + config_s
    total = before + clock.wall
    other = total - startup - sum(a.values()) - figures_s  # archive, printing: the rest
    stages = "".join(f" + {k} {v:.1f} s" for k, v in a.items())
    return (f"wall {total:.1f} s end to end = start-up {startup:.1f} s{stages}"
            f" + figures {figures_s:.1f} s + archive and the rest {other:.1f} s; compile "
            f"{clock.compile:.1f} s summed over threads ({clock.compilations} XLA programs) = "
            "tracing, lowering and compiling each program or loading it from the compilation "
            "cache, some of it beside the run's work")


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

    clock = Stopwatch().__enter__()  # closed by _finish, after the figures
    cfg, text = _load(args)  # its compilations (the study's checks) are counted too
    args.config_s = clock.elapsed()
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


def design_groups(groups: list[list[str]]) -> list[dict[str, float]]:
    """The designs of ``eval``'s ``--design`` flags (``groups``: each flag's NAME=VALUE
    words, in order). A flag with several of them (``--design b=0.6,by=0,px=0.03`` or
    ``--design b=0.6 by=0``) is one design of its own. A flag with one joins the design
    before it when that design was built of such single flags and lacks the variable;
    else (a variable given again, or after a whole design) it starts a new design, so
    ``--design b=0.6 --design px=0.03`` stays one design and ``--design b=0.6 --design
    b=0.7`` are two."""
    designs: list[dict[str, float]] = []
    open_ = False  # the last design was built of single-variable flags
    for words in groups:
        items = [w for word in words for w in word.split(",") if w.strip()]
        d = _parse_design(items)
        if len(items) == 1 and open_ and not set(d) & set(designs[-1]):
            designs[-1] |= d
            continue
        designs.append(d)
        open_ = len(items) == 1
    return designs or [{}]


def cmd_eval(args: argparse.Namespace) -> int:
    from designopt.app import pipeline

    cfg, _ = _load(args)
    groups = getattr(args, "design_groups", None) or [[w] for w in args.design]
    designs = design_groups(groups)
    fresh = bool(getattr(args, "fresh", False))
    out = pipeline.compare(cfg, designs, where=args.config, fresh=fresh)
    if args.json:
        print(json.dumps(_eval_json(out, len(designs) == 1), allow_nan=False))
        return 0
    st = cfg.study
    box = st.variables
    units = out["designs"][0]["units"]
    if len(designs) == 1:
        _print_one(out["designs"][0], box, units)
    else:
        _print_many(out, box, units)
    if fresh:
        which = ("a front's designs (the front stream, front.n_samples" if out["stream"] == "front"
                 else "its final design (the final stream, final.n_samples")  # fmt: skip
        print(f"scored on the fresh stream a run quotes {which}: {out['n_samples']} samples "
              "per design), with the study's own settings"
              + ("" if out["stream"] == "front" else " and the run's normalisation")
              + ": the run's quoted values, bit for bit")  # fmt: skip
    front = getattr(st, "pareto", None)
    if front is not None:
        from designopt.app.config import senses

        print("a front's config: its objectives are " + ", ".join(
            f"{k} ({s})" for k, s in senses(front).items()) + " (no weighted f)")  # fmt: skip
    return 0


def _finite(v: Any) -> Any:
    """JSON-safe: NaN (n/a) and inf as null; arrays as nested lists."""
    import numpy as np

    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_finite(x) for x in v]
    if isinstance(v, np.ndarray):
        return _finite(v.tolist())
    if isinstance(v, float | np.floating):
        return float(v) if math.isfinite(v) else None
    return v


def _eval_json(out: dict[str, Any], one: bool) -> Any:
    """``eval --json``: one design as one object (its indices, ``feasible``, the study's
    placement, e.g. ``ports`` and ``bases``, ``warnings``); several as {"designs": [...],
    "differences": [{"of": [k, 1], index: value, index_se: paired SE}], ...}."""
    rows = []
    for d in out["designs"]:
        r = dict(d["values"])
        if "violation" in r:
            r["feasible"] = bool(r["violation"] <= 0)
        r |= dict(d["placement"]) | {"warnings": d["warnings"]}
        cov = d.get("coverage") or {}
        if cov:  # a task's IK coverage figure: the share and its line
            r |= {"ik_better": cov.get("ik_better"), "ik_better_n": cov.get("ik_better_n"),
                  "ik_coverage": list(cov.get("lines", []))}  # fmt: skip
        rows.append(r if one else {"design": d["design"], "middle_of_box": d["filled"]} | r)
    if one:
        return _finite(rows[0])
    diffs = [{"of": [a + 1, b + 1]} | x["values"] for x in out["differences"]
             for a, b in [x["of"]]]  # fmt: skip
    return _finite({"designs": rows, "differences": diffs, "stream": out["stream"],
                    "n_samples": out["n_samples"],
                    "paired_se": f"the standard deviation of each difference over the run's "
                                 f"samples and {out['replicas']} further independent sample "
                                 "sets, the designs scored together on each"})  # fmt: skip


def _shown(res: dict[str, float]) -> list[str]:
    counts = ("_se", "_n", "_of")  # an index's SE and a ratio's counts: printed with it
    return [k for k in res if not (k.endswith(counts) and k.rsplit("_", 1)[0] in res)]


def _unit(u: str | None) -> str:
    return "" if u in (None, "", "-") else f" {u}"


def _design_line(d: dict[str, Any], units: dict[str, str]) -> str:
    txt = ", ".join(f"{k} = {v:g}{_unit(units.get(k))}" for k, v in d["design"].items())
    if d["filled"]:
        txt += f" ({', '.join(d['filled'])}: the middle of the box, not given)"
    return txt


def _print_one(d: dict[str, Any], box: Any, units: dict[str, str]) -> None:
    from designopt.results.base import value_text

    res = d["values"]
    shown = _shown(res)
    w = max([15, *(len(k) for k in shown)])  # the names right-aligned on their "="
    for k in shown:
        txt = value_text(res[k], res.get(k + "_se"), ".6g", ".2g", res.get(k + "_n"),
                         res.get(k + "_of"))  # fmt: skip
        print(f"{k:>{w}} = {txt}" + (_unit(units.get(k)) if "n/a" not in txt else ""))
    print("design: " + _design_line(d, units))
    _tail(d)


def _tail(d: dict[str, Any], label: str = "") -> None:
    """A design's placement lines, constraints and warnings."""
    res = d["values"]
    for line in d.get("lines", []):
        print(line)
    for line in (d.get("coverage") or {}).get("lines", []):  # a task's IK coverage figure
        print(f"{label}{line}")
    if "violation" in res:
        v = res["violation"]
        print(f"{label}constraints: " + ("feasible" if v <= 0 else
                                         f"violated by {v:.3g} (an infeasible design)"))  # fmt: skip
    for w in d["warnings"]:
        print(f"{label}warning: {w}")


def _print_many(out: dict[str, Any], box: Any, units: dict[str, str]) -> None:
    """One column per design, then one per difference (design k − design 1) ± its
    paired SE."""
    from designopt.results.base import value_text

    ds, diffs = out["designs"], out["differences"]
    for i, d in enumerate(ds):
        print(f"design {i + 1}: " + _design_line(d, units))
    shown = _shown(ds[0]["values"])
    heads = [f"design {i + 1}" for i in range(len(ds))]
    heads += [f"design {a + 1} − design {b + 1}" for a, b in (x["of"] for x in diffs)]
    cells = []
    for k in shown:
        row = [value_text(d["values"][k], d["values"].get(k + "_se"), ".6g", ".2g",
                          d["values"].get(k + "_n"), d["values"].get(k + "_of"))
               for d in ds]  # fmt: skip
        for x in diffs:
            v, se = x["values"].get(k), x["values"].get(k + "_se")
            row.append("-" if v is None else value_text(v, se, "+.6g", ".2g"))
        cells.append((k + ("" if units.get(k, "-") in ("", "-") else f" [{units[k]}]"), row))
    w0 = max(len(h) for h, _ in cells)
    ws = [max(len(heads[c]), *(len(r[c]) for _, r in cells)) for c in range(len(heads))]
    print(" " * w0 + "  " + "  ".join(h.rjust(w) for h, w in zip(heads, ws, strict=True)))
    for h, r in cells:
        print(h.rjust(w0) + "  " + "  ".join(c.rjust(w) for c, w in zip(r, ws, strict=True)))
    print(f"each difference ± its paired SE: the designs scored together on the same samples "
          f"(and on {out['replicas']} further independent sample sets: the SE is the spread "
          "of the difference over them)")  # fmt: skip
    for i, d in enumerate(ds):
        if d.get("lines") or "violation" in d["values"] or d["warnings"] or d.get("coverage"):
            print(f"design {i + 1}:")
            _tail(d, "  ")


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
    if not getattr(args, "no_cache", False):
        use_cache()  # before the config is read: its mesh grids load; the figures' kernels too
    if isinstance(rec, CheckpointRecord):
        raise ConfigError(f"{p}: archive is marked incomplete (an interrupted run); "
                          "resume it with `designopt run CONFIG --resume`")  # fmt: skip
    if getattr(rec.config, "precision", None) == "float64":  # redraw as the run drew
        import jax

        jax.config.update("jax_enable_x64", True)
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
    use_cache()  # the archived config's mesh grids load from the cache folder
    out = None
    if args.csv is not None:  # checked before anything is printed
        if "targets" not in rec:
            raise ConfigError(f"{p}: --csv writes per-target values (a task study's run or "
                              "front: the archive's targets group); this archive has none, "
                              f"so there is nothing to export ({rec.kind}, study "
                              f"{rec.attrs.get('study', '-')})")  # fmt: skip
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
        groups = None
        if args is not None and DESIGN_FLAG in self._option_string_actions:
            groups = _design_groups(list(args))
            args = _design_items(list(args))
        ns, extra = super().parse_known_args(args, namespace)
        if groups is not None:  # each --design flag's words: eval's designs (design_groups)
            ns.design_groups = groups
        return ns, extra


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


def _design_groups(args: list[str]) -> list[list[str]]:
    """The NAME=VALUE words of each ``--design`` flag (``--design a=1 b=2`` or
    ``--design=a=1``), in order."""
    out: list[list[str]] = []
    i = 0
    while i < len(args):
        word = args[i]
        if word == "--":
            break
        if word.startswith(DESIGN_FLAG + "="):
            out.append([word[len(DESIGN_FLAG) + 1 :]])
        elif word == DESIGN_FLAG:
            group = []
            while i + 1 < len(args) and _item(args[i + 1]):
                i += 1
                group.append(args[i])
            out.append(group)
        i += 1
    return [g for g in out if g]


def _item(word: str) -> bool:
    return "=" in word and not word.startswith("-")


def _version() -> str:
    """The installed distribution's version (the package's metadata, as pip installed it)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("designopt")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(
        prog="designopt",
        description="Vectorized JAX design-space optimizer for surgical-robot mechanisms.",
    )
    ap.add_argument("--version", action="version", version=f"designopt {_version()}",
                    help="print the installed version and exit")  # fmt: skip
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
        "a design's variables (others: the middle of their box): several after one flag "
        "(b=0.6,by=0 or b=0.6 by=0) are one design, and each such flag one more design; "
        "single NAME=VALUE flags add to the design before them until a variable repeats. "
        "Two or more designs: one column each and design k − design 1 with its paired SE",
    )
    e.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    e.add_argument("--fresh", action="store_true",
                   help="score on the fresh sample stream a run of this config quotes its "
                        "values on, with the study's own settings: a run's final design's "
                        "(final.n_samples per design; its final/ values), a front's designs' "
                        "(front.n_samples; front/), bit for bit; not the search's samples")  # fmt: skip
    e.set_defaults(func=cmd_eval)
    st = sub.add_parser("studies", help="list the registered studies")
    st.set_defaults(func=cmd_studies)
    b = sub.add_parser(
        "bench",
        help="run the optimizer benchmark suite (the PTPSO paper, IEEE Access 2019, Fig. 10-11)",
    )
    common(b, figures=False, dry=False)
    b.set_defaults(func=cmd_bench)
    from designopt.cli import ik, reference
    from designopt.studies import STUDIES

    ik.add_parser(sub)  # one `ik` for every study with Study.ik
    reference.add_parser(sub)  # `designopt config --keys [PREFIX]`: the schema's reference
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
                   help="also write the per-target values of a task run's final design, "
                        "or of every design of a task front (a design column): per arm and "
                        "target the joints in degrees, reached, 1/k, clearance and the arm's "
                        "port and base, to PATH.csv, default <archive stem>_targets.csv "
                        "beside the archive")  # fmt: skip
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
