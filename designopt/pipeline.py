"""What a run does, for any registered study: set-up, optimise with checkpoints, score,
archive, figures; and the scoring-only paths ``evaluate`` and ``scan`` (docs/architecture.md).

The CLI parses arguments, calls these functions and prints what they return. Everything
here reaches studies through the registry (``designopt.studies``) and optimizers through
``designopt.optim``; the typed config flows down unchanged. One root key ``key(seed)`` is
split once into named streams (``designopt.studies.STREAMS``), which are archived.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from designopt import archive, finite, output, parallel
from designopt.config import ConfigError, load, validate
from designopt.errors import WriteError
from designopt.problems.base import Problem
from designopt.studies import Study, get, key_data, streams
from designopt.timing import Stopwatch

Progress = Callable[[int, str], contextlib.AbstractContextManager[Callable[[int], None]]]


@contextlib.contextmanager
def _no_progress(total: int, desc: str) -> Iterator[Callable[[int], None]]:
    yield lambda n: None


# ----------------------------------------------------------------------------- set-up


def study_of(cfg: Any) -> Study:
    return get(cfg.study.name)


def dtype_of(cfg: Any) -> np.dtype:
    """The config's precision; float64 needs JAX's x64 mode (the CLI turns it on, a script
    must call ``jax.config.update("jax_enable_x64", True)`` itself)."""
    if cfg.precision == "float64" and not jax.config.jax_enable_x64:
        raise ConfigError(
            "key 'precision': float64 needs JAX's 64-bit mode; call "
            "jax.config.update('jax_enable_x64', True) before using designopt from Python"
        )
    return jnp.dtype(cfg.precision)


def resolved_yaml(cfg: Any) -> str:
    return yaml.safe_dump(cfg.model_dump(mode="json", by_alias=True), sort_keys=False)


_PROBLEMS: dict[tuple, Problem] = {}


def build_problem(cfg: Any, keys: Mapping[str, jax.Array], where: str = "config") -> Problem:
    """The study's Problem for this config; a ValueError becomes a ConfigError. The last
    few are kept: a second run of the same study settings, keys and dtype in one process
    reuses the Problem, so its compiled programs too (a resume, a test, a notebook)."""
    dtype = dtype_of(cfg)
    key = (cfg.study.name, cfg.study.model_dump_json(), str(dtype), bool(jax.config.jax_enable_x64),
           repr(key_data(keys)))  # fmt: skip
    if key in _PROBLEMS:
        return _PROBLEMS[key]
    try:
        problem = study_of(cfg).problem(cfg.study, keys, dtype)
    except ValueError as e:
        raise ConfigError(f"{where}: study: {e}") from None
    while len(_PROBLEMS) >= 4:
        _PROBLEMS.pop(next(iter(_PROBLEMS)))
    _PROBLEMS[key] = problem
    return problem


def check_optimizer(cfg: Any, where: str) -> None:
    from designopt import optim

    o = cfg.optimizer
    for key, args in (("optimizer.name", (o.name, {})),
                      ("optimizer.settings", (o.name, dict(o.settings))),
                      ("optimizer.n_particles", (o.name, dict(o.settings), o.n_particles))):  # fmt: skip
        try:
            optim.validate(*args)
        except ValueError as e:
            raise ConfigError(f"{where}: key '{key}': {e}") from None


def check_output(path: Path, overwrite: bool = False, need_bytes: int = 0) -> None:
    """Claim the output for this command (``output.claim``): the folder made (a missing one
    is created) and proved writable, an existing archive refused unless ``overwrite``,
    enough free space, and a lock so that no second process writes there. ConfigError
    naming the output otherwise. Called after the config's own checks, so a refused
    config leaves no folder behind."""
    output.claim(path, overwrite, need_bytes)


def write_archive(path: Path, tree: dict[str, Any], attrs: dict[str, Any], **kw: Any) -> None:
    """archive.write through the one writer (``designopt.output``): atomic, the output
    claimed first if this command has not (``overwrite=True`` to replace an archive), and a
    disk fault one WriteError line (exit 1) that keeps what was there."""
    path = Path(path)
    overwrite = kw.pop("overwrite", False)
    ses = output.current()
    if ses is None or not ses.covers(path):
        check_output(path, overwrite)
    archive.write(path, tree, attrs, **kw)


# ---------------------------------------------------------------------- pre-flight

BYTES_PER_DESIGN_SAMPLE = 128
"""Peak memory per (design × Monte-Carlo sample in flight), conservative: master9 measures
80-280 B in float64 and float32 on CPU (XLA's buffers of one sample chunk)."""
BASE_BYTES = 1 << 29  # JAX, XLA and the compiled programs
DESIGN_SAMPLES_PER_S = 2e7  # master9 on 2 CPU cores: 50 × 20k samples in 27-59 ms (#14)
HUGE_WORK = 3600 * DESIGN_SAMPLES_PER_S  # an hour or more: warn before starting
DESIGN_SAMPLES_PER_CHUNK = 10_000_000
"""Work per optimizer chunk (designs × samples × iterations): ≈ 0.5 s at
DESIGN_SAMPLES_PER_S, so a stop request meets an iteration boundary promptly
(docs/faults.md)."""


def _numbers(tree: Any, key: str, path: str = "study") -> list[tuple[str, dict]]:
    """(path, the dict holding it) of every ``key`` in a settings dump."""
    out = []
    if isinstance(tree, dict):
        if isinstance(tree.get(key), (int, float)) and not isinstance(tree.get(key), bool):
            out.append((f"{path}.{key}", tree))
        for k, v in tree.items():
            out += _numbers(v, key, f"{path}.{k}")
    return out


@dataclass
class Estimate:
    """The pre-flight estimate of a job: peak memory, disk for archive + checkpoint, and
    the Monte-Carlo work per optimizer iteration (designs × samples)."""

    memory: int
    disk: int
    work_per_iter: int
    lower: str
    lines: list[str] = field(default_factory=list)
    work: float = 0.0  # design-samples of the whole job
    sample_key: str = "study.n_samples"

    def warn_if_huge(self) -> None:
        """One warning line (stderr) when the job's Monte-Carlo work means hours or more:
        the optimizer's ETA comes only after its first chunk, set-up may take long before."""
        if self.work > HUGE_WORK:
            hours = self.work / DESIGN_SAMPLES_PER_S / 3600
            print(f"designopt: warning: a huge job: about {self.work:.2g} design-samples of "
                  f"Monte-Carlo work, some {hours:.2g} h at ~{DESIGN_SAMPLES_PER_S:.0e} per "
                  f"second; lower {self.sample_key} or stop it cleanly with --max-minutes",
                  file=sys.stderr)  # fmt: skip

    def check(self, where: str) -> None:
        """ConfigError (exit 2) when the memory estimate exceeds what is available."""
        avail = available_memory()
        if self.memory > avail:
            raise ConfigError(f"{where}: key '{self.lower.split(' (')[0]}': the job needs about "
                              f"{output.human(self.memory)} of memory, {output.human(avail)} "
                              f"available; lower {self.lower}")  # fmt: skip


def available_memory() -> int:
    """Memory the job can use: the accelerator's when JAX runs on one, else the host's."""
    if jax.default_backend() != "cpu":
        with contextlib.suppress(Exception):
            return int(jax.devices()[0].memory_stats()["bytes_limit"])
    return output.available_memory()


def estimate(cfg: Any, n_designs: int = 0, members: int = 1) -> Estimate:
    """Peak memory and archive size of a run (``n_designs`` > 0: a scan of that many
    designs; ``members``: a sweep) from the config alone, before anything compiles."""
    st = cfg.study.model_dump(mode="json", by_alias=True)
    D = max(1, len(cfg.study.variables))
    samples, per_chunk, lower_chunk, sample_key = 1, 1, "study", "study.n_samples"
    for path, d in _numbers(st, "n_samples"):
        c = min(int(d["n_samples"]), int(d.get("chunk") or d["n_samples"]))
        if int(d["n_samples"]) >= samples:
            samples, sample_key = int(d["n_samples"]), path
        if c >= per_chunk:
            per_chunk = c
            lower_chunk = path.rsplit(".", 1)[0] + (".chunk" if "chunk" in d else ".n_samples")
    n_norm = max([int(d["n_norm"]) for _, d in _numbers(st, "n_norm")] + [1])
    o = cfg.optimizer
    swarm = o.n_particles * o.n_runs * members
    T = o.n_iters + 1
    if n_designs:
        batch = cfg.scan.batch if cfg.scan else 256
        flight = {"scan.batch": min(batch, n_designs), "study.n_norm": n_norm}
        host = 8 * n_designs * (D + 48)
        disk = host + (1 << 18)
    else:
        who = "optimizer.n_runs" if o.n_runs > o.n_particles else "optimizer.n_particles"
        flight = {who: swarm, "optimizer.n_iters": T, "study.n_norm": n_norm}
        host = 8 * members * (o.n_runs * T * (D + 3) * 3 + swarm * D * 8)
        disk = 2 * (8 * members * (o.n_runs * T * (D + 3) + T * 48 + swarm * D * 8) + (1 << 18))
    key, designs = max(flight.items(), key=lambda kv: kv[1])
    device = BYTES_PER_DESIGN_SAMPLE * designs * per_chunk
    memory = BASE_BYTES + device + host
    lower = key if device >= host else ("scan.vary" if n_designs else "optimizer.n_iters")
    if key == "study.n_norm":
        lower = next((p for p, _ in _numbers(st, "n_norm")), lower)
    if device >= host and per_chunk > 4096 and designs * per_chunk > 1e10:
        lower += f" (or {lower_chunk})"
    work = float(samples) * (n_norm + (n_designs or swarm * T + T))
    line = (f"pre-flight: about {output.human(memory)} of memory "
            f"({output.human(available_memory())} available), {output.human(2 * disk)} of disk")  # fmt: skip
    return Estimate(memory, 2 * disk, swarm * samples, lower, [line], work, sample_key)


def base_attrs(kind: str, cfg: Any, text: str, keys: Mapping[str, jax.Array]) -> dict[str, Any]:
    return {"kind": kind, "study": cfg.study.name, "config_yaml": text,
            "config_resolved_yaml": resolved_yaml(cfg),
            "config_resolved": cfg.model_dump_json(by_alias=True), "seed": cfg.seed,
            "keys": key_data(keys)}  # fmt: skip


# ------------------------------------------------------------------------ optimise


def optimise(cfg: Any, problem: Problem, key: jax.Array,
             members: list[dict[str, float]] | None = None,
             progress: Callable[[int], None] | None = None,
             checkpoint: Callable[[Any], None] | None = None,
             resume: Any = None, where: str = "config") -> Any:  # fmt: skip
    """The configured optimizer on ``problem``; with ``members`` (overrides of optimizer
    settings) one vmapped batch on common keys. Chunks are small (≤ 5 % of the run and
    about DESIGN_SAMPLES_PER_CHUNK of work), so a stop meets an iteration boundary soon.
    A ``parallel:`` section shards the job over devices (designopt.parallel)."""
    from designopt import optim
    from designopt.problems import penalty

    o = cfg.optimizer
    plan = parallel.plan(cfg.parallel, n_runs=o.n_runs, n_particles=o.n_particles,
                         members=None if members is None else len(members), problem=problem,
                         where=where)  # fmt: skip
    if plan is not None:
        problem = plan.problem(problem)
    if o.constraints.method == "penalty":
        problem = penalty.quadratic(problem, o.constraints.weight)
    work = estimate(cfg, members=len(members or [None])).work_per_iter
    chunk = max(1, min(o.n_iters // 20, DESIGN_SAMPLES_PER_CHUNK // max(work, 1)))
    common = dict(n_particles=o.n_particles, n_iters=o.n_iters, n_runs=o.n_runs, bounds=o.bounds,
                  dtype=dtype_of(cfg), chunk_iters=chunk,
                  progress=progress, checkpoint=checkpoint, resume=resume,
                  checkpoint_at_end=checkpoint is not None)  # fmt: skip
    if plan is not None:
        common["plan"] = plan
    if members is None:
        res = optim.run(o.name, problem, key, **common, **o.settings)
    else:
        res = optim.run_batch(o.name, problem, key, [o.settings | m for m in members], **common)
    if plan is not None:
        res.settings["parallel"] = plan.describe()
    return res


def score(problem: Problem, X: np.ndarray, batch: int | None = None,
          plan: Any = None) -> dict[str, np.ndarray]:  # fmt: skip
    """f and every index (with standard errors) of designs X (n, D), in vmapped batches of
    a fixed size (the last one padded), so one compiled program serves any n. ``plan``
    (``designopt.parallel.scoring_plan``) splits each batch's designs over its devices."""
    X = np.asarray(X, np.float64)
    n = X.shape[0]
    b = n if batch is None else max(1, min(batch, n))
    fn = _scorer(problem.fn, problem.constraints)
    params, key, host, rows = problem.params, jax.random.key(0), np.asarray, jnp.asarray
    if plan is not None:
        b = -(-b // plan.n_devices) * plan.n_devices
        params, key, host = plan.put(params), plan.put(key), plan.host
        rows = lambda x: parallel.shard_rows(plan, x)  # noqa: E731
    outs = []
    for i in range(0, n, b):
        Xi = X[i : i + b]
        pad = b - Xi.shape[0]
        if pad:
            Xi = np.concatenate([Xi, np.repeat(Xi[-1:], pad, 0)])
        f, sub = fn(params, rows(Xi), key)
        outs.append({"f": host(f)[: b - pad]} | {k: host(v)[: b - pad] for k, v in sub.items()})
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


_SCORERS: dict[Any, Any] = {}


def _scorer(fn: Callable, constraints: Callable | None = None) -> Callable:
    """fn jitted (cached per function); with constraints, ``violation`` (Σ max(g, 0), 0
    when feasible) joins the indices."""
    key = (fn, constraints)
    if key not in _SCORERS:
        if constraints is None:
            _SCORERS[key] = jax.jit(fn)
        else:
            from designopt.problems.base import violation_of

            def with_violation(params, X, k):
                f, sub = fn(params, X, k)
                return f, sub | {"violation": violation_of(constraints, params, X)}

            _SCORERS[key] = jax.jit(with_violation)
    return _SCORERS[key]


def check_finite(values: Mapping[str, Any], where: str, what: str,
                 names: Sequence[str] = (), X: np.ndarray | None = None) -> None:  # fmt: skip
    """ConfigError (exit 2, nothing written) when a result holds NaN or inf: numbers a
    config let through that the arithmetic cannot take (lengths so large their powers
    overflow in the run's precision). ``X`` (n, D): name the first design affected."""
    for k, v in values.items():
        a = np.asarray(v) if k != "attrs" else np.zeros(0)
        if a.dtype.kind != "f" or np.all(np.isfinite(a)):
            continue
        at = ""
        if X is not None and a.ndim >= 1:
            i = int(np.flatnonzero(~np.isfinite(a.reshape(len(a), -1)).all(-1))[0])
            at = " at " + ", ".join(f"{n} = {x:g}" for n, x in zip(names, X[i], strict=True))
        raise ConfigError(f"{where}: {what}: {k} is not finite{at}; the config's numbers are "
                          "outside what the arithmetic can take (e.g. lengths so large that "
                          "their powers overflow); nothing written")  # fmt: skip


def result_tree(cfg: Any, problem: Problem, res: Any) -> dict[str, Any]:
    """Archive groups of one (unbatched) run: optimizer, best_run, refine, final, problem."""
    from designopt.refine import refine

    bv = getattr(res, "best_v", None)
    # the best run by Deb's rules: least violation first, then the smallest f
    if cfg.optimizer.constraints.method != "deb":
        bv = None
    best = int(np.lexsort((res.best_f, bv))[0]) if bv is not None else int(np.argmin(res.best_f))
    sub_hist = score(problem, res.history_x[best])
    tree: dict[str, Any] = {
        "optimizer": {
            "history": res.history, "best_f": res.best_f, "best_x": res.best_x,
            "converged_at": res.converged_at, "history_x": res.history_x,
            "attrs": {"settings": res.settings},
        },
        "best_run": sub_hist | {"iteration": np.arange(res.history.shape[-1]),
                                "attrs": {"run_index": best}},
        "problem": {
            "names": np.array(problem.names, dtype="S"), "lower": problem.lower,
            "upper": problem.upper, "attrs": {"info": problem.info},
        },
    }  # fmt: skip
    deb = cfg.optimizer.constraints.method == "deb"  # a penalty run tracks no violation
    if deb and getattr(res, "history_v", None) is not None and problem.constraints is not None:
        tree["optimizer"] |= {"history_v": res.history_v, "best_v": res.best_v}
    if isinstance(problem.params, Mapping) and "bounds" in problem.params:
        tree["problem"]["norm_bounds"] = np.asarray(problem.params["bounds"])
    x_final = res.best_x[best][None]
    stage = "optimizer"
    if cfg.refine is not None:
        r = cfg.refine
        order = np.argsort(res.best_f)[: r.n_best]
        rr = refine(problem, res.best_x[order], r.steps, r.learning_rate, r.method,
                    dtype=dtype_of(cfg))  # fmt: skip
        tree["refine"] = {
            "run_index": order, "x0": rr.x0, "f0": rr.f0, "x": rr.x, "f": rr.f,
            "history": rr.history, "gain": rr.gain,
            "attrs": {"method": r.method, "steps": r.steps, "learning_rate": r.learning_rate},
        }  # fmt: skip
        i = int(np.argmin(rr.f))
        keeps_feasible = problem.constraints is None or float(
            np.asarray(problem.violation(rr.x[i : i + 1]))[0]
        ) <= float(0.0 if bv is None else bv[best])
        if rr.f[i] < res.best_f[best] and keeps_feasible:
            x_final, stage = rr.x[i][None], "refine"
    fin = {k: v[0] for k, v in score(problem, x_final).items()}
    tree["final"] = fin | {"x": x_final[0], "attrs": {"stage": stage,
                           "n_samples_used": problem.info.get("n_samples_used", 0)}}  # fmt: skip
    return tree


def _pm(name: str, v: float, se: float | None) -> str:
    if se is None:
        return f"  {name:<5} = {v:.5g}"
    rel = f"({100 * se / abs(v):.2f} %)" if v else ""
    return f"  {name:<5} = {v:.5f} ± {se:.1e} {rel}"


def summary_lines(cfg: Any, problem: Problem, tree: dict[str, Any]) -> list[str]:
    """The run summary: the best design, f, what the polish gained, the study's
    sub-objectives with ± SE."""
    st = study_of(cfg)
    units = st.units(cfg.study)
    fin = tree["final"]
    best = tree["best_run"]["attrs"]["run_index"]
    opt = tree["optimizer"]
    lines = [f"best design (run {best} of {cfg.optimizer.n_runs}; final stage: "
             f"{fin['attrs']['stage']}):"]  # fmt: skip
    lines += [f"  {n} = {v:9.4f} {units.get(n, '')}".rstrip()
              for n, v in zip(problem.names, fin["x"], strict=True)]  # fmt: skip
    lines.append(f"  f     = {float(fin['f']):.5f}   ({cfg.optimizer.name} {opt['best_f'][best]:.5f}, "
                 f"converged at iteration {opt['converged_at'][best]})")  # fmt: skip
    if "refine" in tree:
        g = tree["refine"]["gain"]
        lines.append(f"  polish ({tree['refine']['attrs']['method']}, "
                     f"{tree['refine']['attrs']['steps']} steps) gained Δf = {g.max():.2e}")  # fmt: skip
    for k in st.summary(cfg.study):
        se = fin.get(k + "_se")
        lines.append(_pm(k, float(fin[k]), None if se is None else float(se)))
    if "violation" in fin:
        v = float(fin["violation"])
        lines.append(
            f"  constraints: {'feasible' if v <= 0 else f'violated by {v:.3g} (no feasible design found)'}"
        )
    lines += st.extra_lines(cfg.study, fin)
    return lines


# ------------------------------------------------------------------------------ run


def resume_key(cfg: Any) -> str:
    """What a checkpoint must match to be resumed: the config without its control keys
    (output, overwrite, max_minutes, ...), which a resumed run may change."""
    return cfg.model_dump_json(by_alias=True, exclude=set(cfg.CONTROL_KEYS))


def load_checkpoint(partial: Path, resolved: str) -> Any:
    """The checkpoint kept in ``partial`` (ConfigError if absent, unreadable or of
    another config)."""
    import h5py

    from designopt.optim import Checkpoint

    if not partial.is_file():
        raise ConfigError(f"{partial}: no interrupted run to resume")
    try:
        with h5py.File(partial, "r") as h:
            if h.attrs.get("resume_key") != resolved:
                raise ConfigError(
                    f"{partial}: the interrupted run used a different config or seed; "
                    "run without --resume to start afresh"
                )
            c = h["checkpoint"]
            state = {k: v[()] for k, v in c["state"].items()}
            return Checkpoint(state, c["history"][()], c["history_x"][()], int(c.attrs["done"]))
    except (OSError, KeyError) as e:
        raise ConfigError(f"{partial}: not a readable checkpoint ({e})") from None


@dataclass
class Report:
    """What a command did: the archive written, the lines to print, timings."""

    out: Path
    lines: list[str] = field(default_factory=list)
    attrs: dict[str, Any] = field(default_factory=dict)
    tree: dict[str, Any] = field(default_factory=dict)


def _dry(out: Path, cfg: Any, est: Estimate) -> Report:
    """A dry run's report: every check passed, nothing written."""
    output.check(out, cfg.overwrite, est.disk, make=False)
    est.warn_if_huge()
    return Report(out, [f"checks passed; nothing written; {est.lines[0]}"])


def run(cfg: Any, text: str, where: str, out: Path, resume: bool = False,
        progress: Progress = _no_progress, resume_hint: str = "",
        dry_run: bool = False) -> Report:  # fmt: skip
    """One study run: problem, optimizer (checkpoint to ``<out>.partial.h5`` every
    ``checkpoint_every_s`` and when stopped), optional polish, final scoring, archive.

    Under the CLI's session (``output.session(signals=True)``) a signal or the time limit
    stops the loop at the next iteration boundary with the checkpoint written
    (``Interrupted``); ``dry_run`` performs every check and writes nothing."""
    if cfg.sweep is not None:
        raise ConfigError(f"{where}: key 'sweep': this config declares a sweep; "
                          "run it with `designopt sweep`")  # fmt: skip
    if study_of(cfg).replay is not None:
        return _replay(cfg, text, where, out, dry_run)
    check_optimizer(cfg, where)
    dtype_of(cfg)
    est = estimate(cfg)
    est.check(where)
    if dry_run:
        return _dry(out, cfg, est)
    o = cfg.optimizer
    partial = archive.partial_path(out)
    hint = resume_hint or f"designopt run CONFIG --out {out}"
    with output.session() as ses:
        if ses.deadline is None:
            ses.set_deadline(cfg.max_minutes)
        check_output(out, cfg.overwrite, est.disk)
        est.warn_if_huge()
        ses.covered.add(partial)
        keys = streams(cfg.seed)
        resolved = resume_key(cfg)
        ck = load_checkpoint(partial, resolved) if resume else None
        attrs = base_attrs("run", cfg, text, keys) | {"resume_key": resolved}
        kept = {"latest": ck, "written": ck.done if ck else -1, "at": time.monotonic()}

        def write_checkpoint(c: Any) -> None:
            tree = {"checkpoint": {"state": c.state, "history": c.history,
                                   "history_x": c.history_x, "attrs": {"done": c.done}}}  # fmt: skip
            try:
                write_archive(partial, tree, attrs, complete=False)
            except WriteError as e:
                raise WriteError(f"{e}; {what_is_kept(last_good=True)}") from None
            kept["written"], kept["at"] = c.done, time.monotonic()

        def flush() -> None:
            c = kept["latest"]
            if c is not None and c.done > kept["written"]:
                write_checkpoint(c)

        def what_is_kept(last_good: bool = False) -> str:
            if kept["written"] < 0 or not partial.is_file():
                return "nothing kept" if last_good else "nothing written"
            part = "the last good checkpoint" if last_good else "finished part"
            return (f"{part} ({kept['written']} of {o.n_iters} iterations) kept in "
                    f"{partial}; resume with `{hint} --resume`")  # fmt: skip

        def checkpoint(c: Any) -> None:
            kept["latest"] = c
            ses.set_phase("loop")
            if ses.stop_requested():
                with ses.writing():
                    flush()
                    raise ses.interrupted(what_is_kept())
            if time.monotonic() - kept["at"] >= cfg.checkpoint_every_s:
                write_checkpoint(c)

        ses.flush, ses.kept = flush, what_is_kept
        with Stopwatch() as total:
            with Stopwatch() as setup:
                problem = build_problem(cfg, keys, where)
            with Stopwatch() as opt, progress(o.n_iters, f"{o.name} on {cfg.study.name}") as bar:
                try:
                    res = optimise(cfg, problem, keys["optimizer"], progress=bar,
                                   checkpoint=checkpoint, resume=ck, where=where)  # fmt: skip
                except KeyboardInterrupt:
                    with ses.writing():
                        flush()
                        raise ses.interrupted(what_is_kept()) from None
            ses.set_phase("prompt")
            if ses.stop_requested():
                with ses.writing():
                    flush()
                    raise ses.interrupted(what_is_kept())
            with Stopwatch() as post:
                tree = result_tree(cfg, problem, res)
        attrs |= {"wall_time_s": total.wall, "compile_time_s": total.compile,
                  "run_time_s": total.run, "setup_time_s": setup.wall,
                  "optimizer_time_s": opt.wall, "post_time_s": post.wall,
                  "resumed_from": ck.done if ck else -1, "compilations": total.compilations,
                  "compilations_by_stage": {"setup": setup.compilations,
                                            "optimizer": opt.compilations,
                                            "scoring_polish": post.compilations}}  # fmt: skip
        try:
            check_finite(tree["final"], where, "the final design")
        except ConfigError:
            output.remove(partial)
            raise
        with ses.writing():
            try:
                write_archive(out, tree, attrs)
            except WriteError as e:
                with contextlib.suppress(WriteError):
                    flush()
                raise WriteError(f"{e}; {what_is_kept()}") from None
            output.remove(partial)
            ses.flush = None
            ses.kept = lambda: (
                f"the archive {out} is complete (`designopt report {out}` draws its figures)"
            )
            if ses.stop_requested():  # a stop during the final write: it is done, say so
                raise ses.interrupted()
    lines = summary_lines(cfg, problem, tree)
    lines.append(f"samples per design: {problem.info.get('n_samples_used', '-')}; wall "
                 f"{total.wall:.1f} s = compile {total.compile:.1f} s + run {total.run:.1f} s "
                 f"(setup {setup.wall:.1f} s, optimizer {opt.wall:.1f} s, "
                 f"scoring/polish {post.wall:.1f} s); {total.compilations} XLA compilations "
                 f"({setup.compilations} + {opt.compilations} + {post.compilations})")  # fmt: skip
    return Report(out, lines, attrs, tree)


def _replay(cfg: Any, text: str, where: str, out: Path, dry_run: bool = False) -> Report:
    """A study whose run is not an optimisation (``Study.replay``): compute, archive."""
    est = Estimate(0, 1 << 22, 0, "study", ["pre-flight: a replay, no optimizer"])
    if dry_run:
        return _dry(out, cfg, est)
    keys = streams(cfg.seed)
    attrs = base_attrs("run", cfg, text, keys)
    with output.session():
        check_output(out, cfg.overwrite, est.disk)
        est.warn_if_huge()
        with Stopwatch() as total:
            try:
                tree, lines = study_of(cfg).replay(cfg.study, keys, dtype_of(cfg), where)
            except ValueError as e:
                raise ConfigError(f"{where}: study: {e}") from None
        attrs |= {"wall_time_s": total.wall, "compile_time_s": total.compile,
                  "run_time_s": total.run, "compilations": total.compilations}  # fmt: skip
        write_archive(out, tree, attrs)
    lines = [*lines, f"wall {total.wall:.1f} s = compile {total.compile:.1f} s + run "
             f"{total.run:.1f} s; {total.compilations} XLA compilations"]  # fmt: skip
    return Report(out, lines, attrs, tree)


# ---------------------------------------------------------------------------- sweep


def sweep(cfg: Any, text: str, where: str, out: Path,
          progress: Progress = _no_progress, dry_run: bool = False) -> Report:  # fmt: skip
    """Every member of the config's ``sweep:`` section; members that differ only in
    optimizer settings run as one vmapped batch on common keys. No checkpoint: a stop
    writes nothing."""
    from pydantic import ValidationError

    from designopt import sweep as sw
    from designopt.config import error_text

    if cfg.sweep is None:
        raise ConfigError(f"{where}: key 'sweep': missing; `designopt sweep` needs one "
                          "(docs/configs.md)")  # fmt: skip
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
        raise ConfigError(f"{where}: key 'sweep.vary' → {error_text(e)}") from None
    except ValueError as e:
        raise ConfigError(f"{where}: key 'sweep.vary': {e}") from None
    ests = []
    for k, c in cfgs.items():
        check_optimizer(c, where)
        dtype_of(c)
        ests.append(estimate(c, members=len(groups[k])))
    est = max(ests, key=lambda e: e.memory)
    est.disk = sum(e.disk for e in ests)
    est.check(where)
    if dry_run:
        return _dry(out, cfg, est)
    with output.session():
        check_output(out, cfg.overwrite, est.disk)
        est.warn_if_huge()
        root_keys = streams(cfg.seed)
        tree: dict = {"members": {}}
        lines = []
        rows = []
        total_it = sum(cfgs[k].optimizer.n_iters for k in groups)
        with Stopwatch() as total, progress(total_it, "sweep") as bar:
            for k, mem in groups.items():
                c = cfgs[k]
                keys = streams(c.seed)
                problem = build_problem(c, keys, where)
                opt_sets = [sw.split(m)[1] for _, m in mem]
                res = optimise(c, problem, keys["optimizer"], members=opt_sets, progress=bar,
                               where=where)  # fmt: skip
                for j, (i, m) in enumerate(mem):
                    sets = {
                        a: (b[j] if isinstance(b, list) else b) for a, b in res.settings.items()
                    }
                    one = res._replace(**{k: (None if v is None else v[j])
                                          for k, v in res._asdict().items() if k != "settings"},
                                       settings=sets)  # fmt: skip
                    t = result_tree(c, problem, one)
                    check_finite(t["final"], where, f"sweep member {i} {m}")
                    t["attrs"] = {"overrides": m,
                                  "config_resolved_yaml": resolved_yaml(sw.apply(cfg, m))}  # fmt: skip
                    tree["members"][f"{i:03d}"] = t
                    rows.append((i, m, t["final"]))
        attrs = base_attrs("sweep", cfg, text, root_keys) | {
            "n_members": len(members), "wall_time_s": total.wall, "compile_time_s": total.compile,
            "run_time_s": total.run, "vmapped_batches": len(groups)}  # fmt: skip
        write_archive(out, tree, attrs)
    lines.append(f"{len(members)} members in {len(groups)} vmapped batch(es); wall "
                 f"{total.wall:.1f} s (compile {total.compile:.1f} s, run {total.run:.1f} s)")  # fmt: skip
    subs = study_of(cfg).summary(cfg.study)[:3]
    for i, m, fin in sorted(rows, key=lambda r: r[0]):
        keys_txt = ", ".join(f"{k} = {v:g}" for k, v in m.items())
        vals = ", ".join(f"{s} = {float(fin[s]):.4f}" for s in subs)
        lines.append(f"  [{i:3d}] {keys_txt}:  f = {float(fin['f']):.5f}, {vals}")
    return Report(out, lines, attrs, tree)


# ------------------------------------------------------------------ evaluate / scan


def _designs(cfg: Any, problem: Problem, designs: Mapping[str, Any] | Sequence[Mapping[str, Any]],
             where: str) -> np.ndarray:  # fmt: skip
    """(n, D) design matrix from {name: value or array} (or a list of such dicts); a
    variable not given takes the middle of its box."""
    rows = [designs] if isinstance(designs, Mapping) else list(designs)
    out = []
    for d in rows:
        bad = [k for k in d if k not in problem.names]
        if bad:
            raise ConfigError(f"{where}: design variable(s) {bad} not in this study's "
                              f"variables {list(problem.names)}")  # fmt: skip
        for k, v in d.items():
            bad = finite.first_bad(np.asarray(v, np.float64).ravel().tolist())
            if bad is not None:
                raise ConfigError(f"{where}: design variable '{k}': {bad[1]}")
        cols = [np.asarray(d.get(n, 0.5 * (lo + hi)), np.float64)
                for n, lo, hi in zip(problem.names, problem.lower, problem.upper, strict=True)]  # fmt: skip
        shape = np.broadcast_shapes(*[c.shape for c in cols])
        out.append(np.stack([np.broadcast_to(c, shape).reshape(-1) for c in cols], -1))
    return np.concatenate(out)


def evaluate(config: Any, designs: Mapping[str, Any] | Sequence[Mapping[str, Any]],
             where: str | None = None) -> dict[str, Any]:  # fmt: skip
    """Every index of the given design(s) with its standard error, without optimising.

    ``config`` is a config path, a parsed config dict or a validated config; ``designs``
    maps variable names to values (scalars, or arrays that broadcast: one design per
    element), or is a list of such dicts; unspecified variables take the middle of their
    box. Returns {index: value, index_se: value, ...}: floats for one design, arrays
    otherwise. float64 configs need x64 enabled (see ``dtype_of``).
    """
    if isinstance(config, (str, os.PathLike)):
        where = where or str(config)
        cfg, _ = load(config)
    elif isinstance(config, Mapping):
        where = where or "config"
        cfg = validate(dict(config), where)
    else:
        cfg, where = config, where or "config"
        finite.check_tree(cfg, where)  # a config built in Python, not through validate
    finite.check_seed(cfg.seed, f"{where}: key 'seed'")
    keys = streams(cfg.seed)
    problem = build_problem(cfg, keys, where)
    X = _designs(cfg, problem, designs, where)
    res = score(problem, X, batch=cfg.scan.batch if cfg.scan else 256)
    if X.shape[0] == 1:
        return {k: float(v[0]) for k, v in res.items()}
    return res


def scan_designs(cfg: Any, problem: Problem, where: str) -> tuple[list[str], np.ndarray]:
    """The (names varied, (n, D) designs) of the config's ``scan:`` section."""
    sc = cfg.scan
    if sc is None:
        raise ConfigError(f"{where}: key 'scan': missing; `designopt scan` needs one "
                          "(docs/configs.md)")  # fmt: skip
    lists = sc.lists()
    for k in list(lists) + list(sc.design):
        if k not in problem.names:
            sect = "vary" if k in lists else "design"
            raise ConfigError(f"{where}: key 'scan.{sect}.{k}': not a design variable of this "
                              f"study; variables: {list(problem.names)}")  # fmt: skip
    names = list(lists)
    if sc.mode == "grid":
        combos = list(itertools.product(*lists.values()))
    else:
        if len({len(v) for v in lists.values()}) != 1:
            raise ConfigError(f"{where}: key 'scan.vary': mode 'list' needs value lists of "
                              "equal length")  # fmt: skip
        combos = list(zip(*lists.values(), strict=True))
    base = {n: sc.design.get(n, 0.5 * (lo + hi))
            for n, lo, hi in zip(problem.names, problem.lower, problem.upper, strict=True)}  # fmt: skip
    X = np.array([[dict(zip(names, c, strict=True)).get(n, base[n]) for n in problem.names]
                  for c in combos], np.float64)  # fmt: skip
    return names, X


def scan(cfg: Any, text: str, where: str, out: Path,
         progress: Progress = _no_progress, dry_run: bool = False) -> Report:  # fmt: skip
    """Score the designs of the config's ``scan:`` section in vmapped batches; archive
    ``scan/names``, ``scan/x``, ``scan/<index>`` and ``scan/<index>_se``."""
    dtype_of(cfg)
    if cfg.scan is None:
        raise ConfigError(f"{where}: key 'scan': missing; `designopt scan` needs one "
                          "(docs/configs.md)")  # fmt: skip
    sizes = [len(v) for v in cfg.scan.lists().values()]
    est = estimate(cfg, n_designs=math.prod(sizes) if cfg.scan.mode == "grid" else max(sizes))
    est.check(where)
    if dry_run:
        return _dry(out, cfg, est)
    keys = streams(cfg.seed)
    with output.session():
        check_output(out, cfg.overwrite, est.disk)
        est.warn_if_huge()
        with Stopwatch() as total:
            problem = build_problem(cfg, keys, where)
            varied, X = scan_designs(cfg, problem, where)
            b = cfg.scan.batch
            plan = parallel.scoring_plan(cfg.parallel, where)
            parts = []
            with progress(X.shape[0], "scan") as bar:
                for i in range(0, X.shape[0], b):
                    parts.append(score(problem, X[i : i + b], batch=b, plan=plan))
                    bar(min(b, X.shape[0] - i))
            res = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        check_finite(res, where, "scan", problem.names, X)
        tree = {"scan": {"names": np.array(problem.names, dtype="S"), "x": X,
                         "varied": np.array(varied, dtype="S"), **res,
                         "attrs": {"mode": cfg.scan.mode, "shape": sizes}},
                "problem": {"names": np.array(problem.names, dtype="S"), "lower": problem.lower,
                            "upper": problem.upper, "attrs": {"info": problem.info}}}  # fmt: skip
        attrs = base_attrs("scan", cfg, text, keys) | {
            "n_designs": int(X.shape[0]), "wall_time_s": total.wall,
            "compile_time_s": total.compile, "run_time_s": total.run}  # fmt: skip
        write_archive(out, tree, attrs)
    lines = [f"{X.shape[0]} designs over {', '.join(varied)} ({cfg.scan.mode}) in batches of "
             f"{b}; wall {total.wall:.1f} s (compile {total.compile:.1f} s, run {total.run:.1f} s)",
             *best_lines(problem.names, X, res["f"], res.get("violation"))]  # fmt: skip
    return Report(out, lines, attrs, tree)


def best_lines(names: Sequence[str], X: np.ndarray, f: np.ndarray,
               violation: np.ndarray | None = None) -> list[str]:  # fmt: skip
    """The scored designs' summary: the lowest f; under constraints (g ≤ 0), the lowest
    f among the feasible designs, and the infeasible design with a lower f named apart."""

    def design(i: int) -> str:
        return ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, X[i], strict=True))

    f = np.asarray(f, np.float64)
    if violation is None:
        i = int(np.nanargmin(f))
        return [f"lowest f: {design(i)}: f = {f[i]:.5g}"]
    v = np.asarray(violation, np.float64)
    ok = v <= 0
    lines = [f"constraints: {int(ok.sum())} of {len(f)} designs feasible"]
    if ok.any():
        i = int(np.flatnonzero(ok)[np.nanargmin(f[ok])])
        lines.append(f"lowest f among the feasible: {design(i)}: f = {f[i]:.5g}")
        j = int(np.nanargmin(np.where(ok, np.inf, f))) if (~ok).any() else -1
        if j >= 0 and f[j] < f[i]:
            lines.append(f"  lower f only where infeasible: {design(j)}: f = {f[j]:.5g}, "
                         f"violated by {v[j]:.3g}")  # fmt: skip
    else:
        j = int(np.argmin(v))
        lines.append(f"no feasible design; least violation {v[j]:.3g} at {design(j)}: "
                     f"f = {f[j]:.5g}")  # fmt: skip
    return lines


# -------------------------------------------------------------------------- figures


def draw_figures(path: Path) -> list[Path]:
    """Draw the figures an archive supports beside it (run: the study's figures; sweep:
    final f per member; scan: a curve or heat map; bench: Fig. 10-11), through the one
    writer: drawn into a temporary folder, then moved into place (a disk fault: one
    WriteError line, the archive and any earlier figures kept)."""
    from designopt.figures import scan as scan_figs
    from designopt.figures import sweep as sweep_figs

    path = Path(path)
    a = archive.read(path)
    kind = a["attrs"].get("kind")
    folder = path.parent
    figs = folder / f"{path.stem}_figures"
    with output.session() as ses:
        if not ses.covers(path):
            check_output(path, overwrite=True)  # lock: no run may write it meanwhile
        if kind == "bench":
            from designopt import benchsuite

            return output.publish_figures(lambda d: benchsuite.draw_figures(a, d), folder,
                                          swap=False)  # fmt: skip
        if kind == "run":
            draw = get(a["attrs"]["study"]).figures
        elif kind == "sweep":
            draw = sweep_figs.draw
        elif kind == "scan":
            draw = scan_figs.draw
        else:
            raise ConfigError(f"{path}: archive kind {kind!r} has no figures")
        return output.publish_figures(lambda d: draw(a, d), figs)
