"""What every command does before its work: load the config as the command line gives
it (--seed, --overwrite, --max-minutes, devices and processes, precision, the persistent
compilation cache), the progress bar, ``--design`` values, and the command that resumes
an interrupted run. Kept free of JAX at import, so ``designopt --help`` starts fast."""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from designopt.core.errors import ConfigError


def load_args(args: argparse.Namespace):
    """The command's config: the file with the flags that override it (--seed,
    --overwrite, --max-minutes, --devices and the multi-process flags) set as dotted keys
    before the one validation (``config.load``); then JAX set up for it (devices, 64-bit
    mode for ``precision: float64``, the persistent compilation cache)."""
    from designopt.app.config import load, parse
    from designopt.core.validation import check_seed
    from designopt.io import writer

    over: dict[str, object] = parse_sets(getattr(args, "set_keys", None) or [])
    if getattr(args, "seed", None) is not None:
        over["seed"] = check_seed(args.seed, f"--seed {args.seed}")
    if getattr(args, "overwrite", False):
        over["overwrite"] = True
    if getattr(args, "max_minutes", None) is not None:
        if not (math.isfinite(args.max_minutes) and args.max_minutes > 0):
            raise ConfigError(f"--max-minutes {args.max_minutes}: give a positive number")
        over["max_minutes"] = args.max_minutes
    devices = getattr(args, "devices", None)
    if devices is not None or _multi(args):
        raw, _ = parse(args.config)
        section = raw.get("parallel") if isinstance(raw.get("parallel"), dict) else {}
        over["parallel"] = dict(section)  # the flags make a parallel section
        if devices:
            over["parallel.devices"] = devices
    if not getattr(args, "no_cache", False) and _cache_asked(args.config, over):
        use_cache()  # before validating: the study's checks compile programs too
    cfg, text = load(args.config, overrides=over)
    ses = writer.current()
    if ses is not None and cfg.max_minutes is not None:
        ses.set_deadline(cfg.max_minutes)
    parallel_flags(args, cfg)
    import jax

    if cfg.precision == "float64":  # the CLI is the program: it may switch JAX to 64-bit
        jax.config.update("jax_enable_x64", True)
    if cfg.compile_cache and not getattr(args, "no_cache", False):
        use_cache()
    return cfg, text


def _cache_asked(path: str, over: dict[str, object]) -> bool:
    """Whether the config (not yet validated) keeps the compilation cache: its
    ``compile_cache`` (or a ``--set`` of it) is true or not given. A file that cannot be
    read says no here; its validation then reports it."""
    from designopt.app.config import parse

    try:
        raw, _ = parse(path)
    except Exception:  # noqa: BLE001  (the validation names the problem)
        return False
    value = over.get("compile_cache", raw.get("compile_cache", True) if isinstance(raw, dict) else True)
    return value is True


def _multi(args: argparse.Namespace) -> bool:
    from designopt.core import devices as dev

    return dev.requested(getattr(args, "coordinator", None), getattr(args, "num_processes", None))


def parallel_flags(args: argparse.Namespace, cfg=None):
    """--devices and the multi-process flags (docs/scaling.md): JAX set up before its
    backend starts; a non-zero process of a job writes and prints nothing. ``cfg``: the
    validated config (its ``parallel`` section already holds the flags). Returns the
    parallel settings in force (None: one device, as ever)."""
    from designopt.core import devices as dev
    from designopt.io import writer

    devices = getattr(args, "devices", None)
    coord, n_proc = getattr(args, "coordinator", None), getattr(args, "num_processes", None)
    if cfg is not None:
        p = cfg.parallel
    elif devices is not None or dev.requested(coord, n_proc):
        p = dev.ParallelSettings(devices=devices or None)
    else:
        p = None
    timeout = p.timeout_s if p is not None else dev.DEFAULT_TIMEOUT_S
    dev.configure(p.devices if p is not None else devices, coord, n_proc,
                  getattr(args, "process_id", None), timeout)  # fmt: skip
    writer.set_writer(dev.is_writer())
    return p


def use_cache() -> None:
    """Keep XLA's compiled programs in :func:`cache_dir` (an unwritable folder only costs
    compile time); the mesh obstacles' distance grids are kept there too
    (``kinematics.sdf.cache_folder`` reads the same setting), so a warm command loads them."""
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
    """Where compiled programs (and mesh distance grids, ``designopt-grid-*.npz``) are kept
    between runs: ``$DESIGNOPT_CACHE_DIR``, else ``$XDG_CACHE_HOME/designopt/jax``, else
    ``~/.cache/designopt/jax``."""
    import os

    if os.environ.get("DESIGNOPT_CACHE_DIR"):
        return Path(os.environ["DESIGNOPT_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "designopt" / "jax"


ETA_AFTER_S = 60.0
"""A job whose optimizer is estimated to need longer than this prints its ETA once."""


def eta_text(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.3g} days"


SHOW_AFTER_S = 2.0
"""A phase that lasts longer than this shows that it is running (compiling, re-scoring a
front, drawing figures)."""


class Phase:
    """Shows on stderr that a phase runs, once it has lasted :data:`SHOW_AFTER_S`: on a
    terminal its name and the seconds so far, updated each second on one line (cleared
    when the phase ends); elsewhere (a log) one line. ``show=False``: nothing."""

    def __init__(self, desc: str, show: bool = True) -> None:
        import threading

        self.desc, self.show = desc, show
        self.stop = threading.Event()
        self.thread: threading.Thread | None = None
        self.shown = False

    def _run(self) -> None:
        import time

        t0 = time.perf_counter()
        tty = sys.stderr.isatty()
        if self.stop.wait(SHOW_AFTER_S):
            return
        self.shown = True
        if not tty:
            print(f"designopt: {self.desc} …", file=sys.stderr, flush=True)
            return
        while True:
            sys.stderr.write(f"\r{self.desc} … {time.perf_counter() - t0:.0f} s")
            sys.stderr.flush()
            if self.stop.wait(1.0):
                sys.stderr.write("\r\x1b[K")
                sys.stderr.flush()
                return

    def __enter__(self) -> Phase:
        if self.show:
            import threading

            self.thread = threading.Thread(target=self._run, daemon=True)
            self.thread.start()
        return self

    def close(self) -> None:
        if self.thread is not None:
            self.stop.set()
            self.thread.join()
            self.thread = None

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress(quiet: bool):
    """The command's progress (none with --quiet): ``bar(total, desc)`` for ``total``
    iterations, or for a phase of unknown length when ``total`` is None. Compiling is a
    phase of its own: until the first chunk of iterations is done the line says
    ``<desc>: compiling``; the tqdm bar starts then, so its rate and ETA count only the
    iterations. A long job prints, once, its estimated time after the first timed chunk."""

    @contextlib.contextmanager
    def bar(total: int | None, desc: str) -> Iterator[Callable[[int], None]]:
        import time

        from tqdm import tqdm

        from designopt.io import writer

        show = not quiet and writer.writes()
        if total is None:  # a phase: re-scoring a front, drawing figures
            with Phase(desc, show):
                yield lambda n: None
            return
        seen = {"n": 0, "t": None, "told": False}
        state: dict = {"bar": None}
        phase = Phase(f"{desc}: compiling", show).__enter__()

        def update(n: int) -> None:
            if state["bar"] is None:  # compiled: the bar's clock starts with the iterations
                phase.close()
                state["bar"] = tqdm(total=total, initial=n, desc=desc, unit="it",
                                    disable=not show)  # fmt: skip
            else:
                state["bar"].update(n)
            now = time.monotonic()
            if seen["t"] is not None and not seen["told"] and n > 0:
                left = (now - seen["t"]) / n * (total - seen["n"] - n)
                seen["told"] = True
                if left > ETA_AFTER_S:
                    msg = (f"designopt: {desc}: about {eta_text(left)} left "
                           f"({total - seen['n'] - n} of {total} iterations at "
                           f"{eta_text((now - seen['t']) / n)} each); --max-minutes N stops "
                           "cleanly with a checkpoint")  # fmt: skip
                    tqdm.write(msg, file=sys.stderr)
            seen["n"] += n
            seen["t"] = now

        try:
            yield update
        finally:
            phase.close()
            if state["bar"] is not None:
                state["bar"].close()

    return bar


def resume_command(args: argparse.Namespace, cfg) -> str:
    """The exact command that resumes this run: the same config, output, seed and every
    other option given (without --resume, which the caller appends)."""
    import shlex

    parts = ["designopt", "run", args.config, "--out", str(out_path(args, cfg)),
             "--seed", str(cfg.seed)]  # fmt: skip
    for flag in ("quiet", "no_figures", "no_cache", "overwrite"):
        if getattr(args, flag, False):
            parts.append("--" + flag.replace("_", "-"))
    if args.max_minutes is not None:
        parts += ["--max-minutes", f"{args.max_minutes:g}"]
    if getattr(args, "devices", None) is not None:
        parts += ["--devices", str(args.devices)]
    for item in getattr(args, "set_keys", None) or []:
        parts += ["--set", item]
    return shlex.join(parts)


DESIGN_FLAG = "--design"


def set_argument(p: argparse.ArgumentParser) -> None:
    """``--set KEY=VALUE`` (repeat): any key of the config, dotted from its top
    (``study.task.port=[0.5,0.1,-0.2]``, ``optimizer.n_iters=5``, ``study.arms.1.port=...``),
    the value read as YAML; applied through ``config.set_key`` like the file's own keys."""
    p.add_argument("--set", dest="set_keys", action="append", default=[], metavar="KEY=VALUE",
                   help="override one config key (dotted from the top, the value as YAML; "
                        "repeat), e.g. --set study.task.port=[0.5,0.1,-0.2]")  # fmt: skip


def parse_sets(items: list[str]) -> dict[str, object]:
    """--set KEY=VALUE items as {dotted key: value parsed as YAML}; ConfigError naming
    the item for a missing '=', an empty key or a value that is not YAML."""
    import yaml

    out: dict[str, object] = {}
    for item in items:
        key, eq, text = item.partition("=")
        key = key.strip()
        if not eq or not key or any(not part for part in key.split(".")):
            raise ConfigError(f"--set {item}: give KEY=VALUE with a dotted key from the "
                              "config's top, e.g. --set study.task.port=[0.5,0.1,-0.2]")  # fmt: skip
        if not text.strip():
            raise ConfigError(f"--set {item}: give a value after '=' (null: the key unset)")
        try:
            out[key] = yaml.safe_load(text)  # null: as if the file did not give the key
        except yaml.YAMLError:
            raise ConfigError(f"--set {item}: the value is not YAML (a number, a word, a "
                              "[list] or a {mapping})") from None  # fmt: skip
    return out


def design_argument(p: argparse.ArgumentParser | argparse._ArgumentGroup, help: str) -> None:
    """``--design NAME=VALUE [NAME=VALUE ...]``: one flag with several values or the flag
    repeated, all in one list (:func:`parse_design` reads it)."""
    p.add_argument(DESIGN_FLAG, action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                   help=help)  # fmt: skip


def parse_design(items: list[str]) -> dict[str, float]:
    """--design NAME=VALUE items as {name: value}: every value a usable number
    (designopt.core.validation), every name given once."""
    from designopt.core.validation import check_value

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


def out_path(args: argparse.Namespace, cfg) -> Path:
    return Path(args.out or cfg.output_path())
