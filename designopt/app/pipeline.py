"""What a job does, for any registered study: set-up, optimise (with checkpoints), score,
write, figures (docs/architecture.md). It only orchestrates: a ``Job`` is built
once from the validated config (``designopt.app.job``: study, precision, keys, the checked
estimate, the problem) and handed down; a run's kind is a strategy (``Single``, ``Front``,
or the study's replay); the pre-flight estimate in ``designopt.app.preflight``, scoring in
``designopt.app.scoring``, design matrices in ``designopt.app.designs``, checkpoints in
``designopt.app.checkpoint``, and results come back as the typed records of
``designopt.results``, which the archive stores (``archive.save``) and the summary text
and figures read.

Studies are reached through their registry, optimizers through ``designopt.optim``; the
typed config flows down unchanged. One root key ``key(seed)`` is split once into named
streams (``designopt.core.keys.STREAMS``), which are archived. ``out=None`` runs in memory:
nothing is claimed, checkpointed or written.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from designopt.app import checkpoint as ckpt
from designopt.app import fronts, quoted, rescoring, verdict
from designopt.app.designs import Designs, matrix, scan_designs
from designopt.app.job import Job, base_attrs, build_problem
from designopt.app.optimise import optimise
from designopt.app.preflight import Estimate
from designopt.app.records import bind
from designopt.app.reporting import draw_figures, write_html
from designopt.app.scoring import check_finite, placement, problem_group, run_groups, with_placement
from designopt.core import concurrency, devices, exported
from designopt.core.errors import ConfigError, WriteError
from designopt.core.keys import streams
from designopt.core.timing import Stopwatch
from designopt.io import archive, writer
from designopt.problems.evaluate import score
from designopt.results import FrontRecord, Record, ReplayRecord, RunRecord, ScanRecord, SweepRecord

Progress = Callable[[int | None, str], contextlib.AbstractContextManager[Callable[[int], None]]]
"""``progress(total, desc)``: a context giving ``update(n)`` for ``total`` iterations, or
marking a phase of unknown length (``total`` None: setting up, scoring, re-scoring)."""


@contextlib.contextmanager
def no_progress(total: int, desc: str) -> Iterator[Callable[[int], None]]:
    yield lambda n: None


@dataclass
class Report:
    """What a command did: the record, where it was written (None: in memory), the lines
    to print."""

    out: Path | None
    lines: list[str] = field(default_factory=list)
    record: Record | None = None

    @property
    def tree(self) -> dict[str, Any]:
        return {} if self.record is None else self.record.data()

    @property
    def attrs(self) -> dict[str, Any]:
        return {} if self.record is None else self.record.attrs


def _dry(out: Path | None, cfg: Any, est: Estimate) -> Report:
    """A dry run's report: every check passed, nothing written."""
    if out is not None:
        writer.check(out, cfg.overwrite, est.disk, make=False)
    est.warn_if_huge()
    return Report(out, [f"checks passed; nothing written; {est.lines[0]}"])


@contextlib.contextmanager
def _writing(out: Path | None, cfg: Any, est: Estimate) -> Iterator[writer.Session | None]:
    """The output session of a job writing ``out`` (claimed: lock, space, overwrite
    policy); nothing for an in-memory job."""
    if out is None:
        est.warn_if_huge()
        yield None
        return
    with writer.session() as ses:
        if ses.deadline is None:
            ses.set_deadline(cfg.max_minutes)
        writer.claim(out, cfg.overwrite, est.disk)
        est.warn_if_huge()
        yield ses


# ----------------------------------------------------------------- run strategies


def warnings(job: Job, final: dict[str, Any], targets: dict[str, Any] | None = None) -> None:
    """A final group's ``warnings`` attr, decided by :func:`designopt.app.quoted.warnings`
    (the one rule of every run kind): the study's lines on the (fresh) values, a line for
    every n/a index, the optimism lines of :func:`designopt.app.rescoring.final_groups`
    (attr ``optimism``, then dropped) and the IK coverage's (the ``warnings`` attr of the
    final design's ``targets`` group: the study's ``targets`` hook)."""
    at = final.setdefault("attrs", {})
    vals = {k: v for k, v in final.items() if k not in ("attrs", "x")}
    warn = quoted.warnings(job, vals, final.get("x"), (targets or {}).get("attrs", {}),
                           list(at.pop("optimism", [])))  # fmt: skip
    if warn:  # far from what was asked: archived, printed, shown, marked on figures
        at["warnings"] = list(warn)


class Single:
    """A single-objective run: the study's problem, its weighted f optimised, the best
    run's history and the final design scored → ``RunRecord``."""

    kind = "run"
    record = RunRecord

    def problem(self, job: Job) -> Any:
        return job.search_problem

    def ref_point(self, job: Job) -> Any:
        return None

    def groups(self, job: Job, problem: Any, res: Any) -> dict[str, Any]:
        groups = run_groups(job.cfg, problem, res, job.dtype)
        if job.cfg.final.race:  # the final stage: the race's best is the final design
            groups = raced(job, problem, res, groups)
        # the final design (and each run's best) re-scored on the fresh ``final`` stream:
        # the quoted values; the search's own stay in best_run/final
        groups = rescoring.final_groups(job, problem, res, groups)
        fr = rescoring.plan(job, "final")
        # where the final design puts the robot in the world (the study's placement)
        with_placement(groups["final"], placement(job.study, job.cfg.study,
                                                  groups["final"]["x"]), 0)  # fmt: skip
        if job.study.targets is not None:  # the final design at every target of the fresh
            # stream (a task's): their means are final/'s indices
            tg = job.study.targets(fr.cfg.study, np.asarray(groups["final"]["x"]), fr.keys,
                                   job.dtype)  # fmt: skip
            if tg is not None:
                groups["targets"] = tg
        warnings(job, groups["final"], groups.get("targets"))
        return groups

    def check(self, job: Job, groups: dict[str, Any]) -> None:
        na = tuple(job.search_problem.na_range)
        check_finite(groups["final"], job.where, "the final design", na=na)
        check_finite(groups["best_run"].get("final", {}), job.where,
                     "the final design on the search's samples", na=na)  # fmt: skip

    def lines(self, rec: Any) -> list[str]:
        return [*rec.design_lines(), rec.run_line()]

    def scoring(self, job: Job) -> str:
        """What the phase after the optimizer does (shown while it runs)."""
        n = rescoring.plan(job, "final").n
        polish = ", polishing" if job.cfg.refine else ""
        return f"scoring the best run{polish} and re-scoring the final design on {n} fresh samples"


def raced(job: Job, problem: Any, res: Any, groups: dict[str, Any]) -> dict[str, Any]:
    """A weighted or constrained run's final stage (``final.race``): its candidates
    raced on the validation stream (``designopt.app.verdict``), the archive's ``verdict``
    group, and the race's best as the final design (its values on the search's samples
    in ``final``, which ``rescoring.final_groups`` then re-scores on the fresh ``final``
    stream as every quoted number)."""
    X, _ = verdict.run_candidates(res, groups)
    x0 = np.asarray(groups["final"]["x"], np.float64)
    X = verdict.clear(job, np.concatenate([x0[None], X]))  # the search's final design first
    g = verdict.race_candidates(job, X, like=problem,
                                sources=["the search's best few designs of each run"])  # fmt: skip
    groups["verdict"] = g
    xb = verdict.best_x(g)
    if not np.array_equal(xb, x0):  # the race's best: its values on the search's samples
        fin = groups["final"]
        vals = quoted.blocked(problem, xb[None])
        groups["final"] = {k: np.asarray(v)[0] for k, v in vals.items()} | {
            "x": xb, "attrs": dict(fin.get("attrs", {})) | {"stage": "race"}}
    return groups


class Front(Single):
    """A Pareto front of the study's indices (``study.objective.pareto``): the front's
    objectives optimised, the front re-scored on fresh samples → ``FrontRecord``."""

    kind = "front"
    record = FrontRecord

    def problem(self, job: Job) -> Any:
        return fronts.objective_problem(job.search_problem, job.cfg.study.pareto)

    def ref_point(self, job: Job) -> Any:
        return fronts.reference(job.cfg)

    def groups(self, job: Job, problem: Any, res: Any) -> dict[str, Any]:
        return fronts.groups(job, problem, res)

    def check(self, job: Job, groups: dict[str, Any]) -> None:
        pass  # the re-scored front is checked by fronts.groups

    def lines(self, rec: Any) -> list[str]:
        return [*rec.summary()[1:], rec.run_line()]

    def scoring(self, job: Job) -> str:
        n = rescoring.plan(job, "front").n
        polish = "polishing each run's recommended design, " if job.cfg.refine else ""
        return f"{polish}re-scoring the front on {n} fresh samples per design"


# ------------------------------------------------------------------------------ run


def run(cfg: Any, text: str | None = None, where: str = "config", out: Path | None = None,
        resume: bool = False, progress: Progress = no_progress, resume_hint: str = "",
        dry_run: bool = False) -> Report:  # fmt: skip
    """One study run: problem, optimizer, optional polish, final scoring → RunRecord (a
    front: FrontRecord; a replay study: ReplayRecord).

    With ``out``: checkpoints go to ``<out>.partial.h5`` every ``checkpoint_every_s`` and
    when stopped (under the CLI's session a signal or the time limit stops the loop at the
    next iteration boundary, ``Interrupted``), the archive is written atomically;
    ``dry_run`` performs every check and writes nothing. ``out=None``: in memory."""
    if cfg.sweep is not None:
        raise ConfigError(f"{where}: key 'sweep': this config declares a sweep; "
                          "run it with `designopt sweep`")  # fmt: skip
    job = Job.build(cfg, where, text)
    if job.study.replay is not None:  # a front of a replay study is refused by validation
        return _replay(job, out, dry_run)
    how = Single() if cfg.study.pareto is None else Front()
    rescoring.plan(job, how.kind if how.kind == "front" else "final")  # its samples checked now
    verdict.check(job)  # the final stage's keys (final.margin names, the cap in stages)
    if dry_run:
        return _dry(out, cfg, job.estimate)
    o = cfg.optimizer
    resolved = ckpt.resume_key(cfg)
    attrs = job.attrs(how.kind) | {"resume_key": resolved}
    with _writing(out, cfg, job.estimate) as ses:
        ck, saver = None, None
        if ses is not None:
            ck = ckpt.load(archive.partial_path(out), resolved) if resume else None
            hint = resume_hint or f"designopt run CONFIG --out {out}"
            saver = ckpt.Checkpointer(out, attrs, o.n_iters, cfg.checkpoint_every_s, hint, ses, ck)
        with Stopwatch() as total:
            with Stopwatch() as setup, progress(None, "setting up"):
                problem = how.problem(job)
            with Stopwatch() as opt, progress(o.n_iters, f"{o.name} on {cfg.study.name}") as bar:
                try:
                    with concurrency.in_background(_warm(job)):
                        res = optimise(job, problem, progress=bar, checkpoint=saver, resume=ck,
                                       ref_point=how.ref_point(job))  # fmt: skip
                except KeyboardInterrupt as e:
                    if saver is None:
                        raise
                    saver.stop(e)
            if ses is not None:
                ses.set_phase("prompt")
                saver.stop_if_requested()
            with Stopwatch() as post, progress(None, how.scoring(job)):
                groups = how.groups(job, problem, res)
        attrs |= {"wall_time_s": total.wall, "compile_time_s": total.compile,
                  "run_time_s": total.run, "setup_time_s": setup.wall,
                  "optimizer_time_s": opt.wall, "post_time_s": post.wall,
                  "resumed_from": ck.done if ck else -1, "compilations": total.compilations,
                  "compilations_by_stage": {"setup": setup.compilations,
                                            "optimizer": opt.compilations,
                                            "scoring_polish": post.compilations}}  # fmt: skip
        try:
            how.check(job, groups)
        except ConfigError:
            if saver is not None:
                saver.discard()
            raise
        rec = bind(how.record(attrs, groups, cfg))
        if ses is not None:
            _write_run(out, rec, ses, saver)
    return Report(out, how.lines(rec), rec)


def _warm(job: Job) -> Callable[[], None] | None:
    """What compiles, beside the search, the programs its scoring after it runs: where the
    search scores with other settings (``optimizer.fidelity``) and the study scores in
    blocks (``Problem.staged``), the quoted problem (the study's own settings on the run
    kind's fresh stream: ``quoted.problem``, which the scoring then reuses, its
    normalisation probe included) and one block of it (the box's centre in every row) at
    the least cost that compiles its programs (``Staged.least``: the first chunk of
    targets); the block's values are dropped. None where the search's programs are the scoring's.
    It starts once the search's own block program has run (``exported.wait_ready``):
    that program's trace (which holds the GIL) and compile are what the search waits
    for, and its calls leave a core idle where one step of the search makes fewer
    independent calls than there are cores. Where the calls fill the cores (the
    planning case: two blocks of 16 designs a step on 2 cores), it starts once that
    program has been traced instead, and compiles beside its compile."""
    if job.search_cfg is None:
        return None
    st, o = job.search_problem.staged, job.cfg.optimizer
    full = st is not None and \
        -(-o.n_particles * o.n_runs // st.designs) * st.calls >= concurrency.threads()  # fmt: skip

    def warm() -> None:
        if st is not None and not exported.wait_ready(60.0, traced=full) \
                and concurrency.ended():  # fmt: skip
            return  # the search has ended (an error, Ctrl-C) before its first call
        p = quoted.problem(job, job.search_problem)
        if p.staged is None:
            return
        x = 0.5 * (np.asarray(p.lower, np.float64) + np.asarray(p.upper, np.float64))
        X = np.repeat(x[None], p.staged.designs, 0).astype(job.dtype)
        least = p.staged.least  # the least call that compiles (or loads) the programs
        p.staged.values(p.params if least is None else least(p.params), X)

    return warm


def _write_run(out: Path, rec: Record, ses: writer.Session, saver: ckpt.Checkpointer) -> None:
    """The final archive, atomically; then the checkpoint goes. A disk fault keeps (and
    names) the checkpoint."""
    with ses.writing():
        try:
            archive.save(out, rec)
        except WriteError as e:
            with contextlib.suppress(WriteError):
                saver.flush()
            raise WriteError(f"{e}; {saver.kept()}") from None
        saver.done(out)
        if ses.stop_requested():  # a stop during the final write: it is done, say so
            raise ses.interrupted()


def _replay(job: Job, out: Path | None, dry_run: bool = False) -> Report:
    """A study whose run is not an optimisation (``Study.replay``): compute, archive."""
    cfg, where = job.cfg, job.where
    if dry_run:
        return _dry(out, cfg, job.estimate)
    attrs = job.attrs("run")
    with _writing(out, cfg, job.estimate):
        with Stopwatch() as total:
            try:
                groups, lines = job.study.replay(cfg.study, job.keys, job.dtype, where)
            except ValueError as e:
                raise ConfigError(f"{where}: study: {e}") from None
        attrs |= {"wall_time_s": total.wall, "compile_time_s": total.compile,
                  "run_time_s": total.run, "compilations": total.compilations}  # fmt: skip
        rec = bind(ReplayRecord(attrs, groups, cfg))
        if out is not None:
            archive.save(out, rec)
    # the wall time and the program count: the command line's last line (cli wall_line),
    # the archive's attrs (wall_time_s, compile_time_s, compilations)
    return Report(out, list(lines), rec)


# ---------------------------------------------------------------------------- sweep


def sweep(cfg: Any, text: str | None = None, where: str = "config", out: Path | None = None,
          progress: Progress = no_progress, dry_run: bool = False) -> Report:  # fmt: skip
    """Every member of the config's ``sweep:`` section; members that differ only in
    optimizer settings run as one vmapped batch on common keys (one job per batch). No
    checkpoint: a stop writes nothing."""
    from designopt.app import sweeps as sw

    if cfg.study.pareto is not None:
        raise ConfigError(f"{where}: key 'sweep': a sweep of Pareto fronts "
                          "(study.objective.pareto) is not supported; run each front with "
                          "`designopt run`")  # fmt: skip
    if cfg.final.race:
        raise ConfigError(f"{where}: key 'final.race': the final stage races one run's "
                          "candidates; a sweep does not run it: run each member with "
                          "`designopt run`, or set final.race: false")  # fmt: skip
    groups, cfgs, members = sw.groups(cfg, where)
    jobs = {k: Job.build(c, where, text, members=len(groups[k])) for k, c in cfgs.items()}
    est = max((j.estimate for j in jobs.values()), key=lambda e: e.memory)
    est.disk = sum(j.estimate.disk for j in jobs.values())
    est.check(where)
    if dry_run:
        return _dry(out, cfg, est)
    with _writing(out, cfg, est):
        tree: dict = {"members": {}}
        rows = []
        total_it = sum(cfgs[k].optimizer.n_iters for k in groups)
        with Stopwatch() as total, progress(total_it, "sweep") as bar:
            for k, mem in groups.items():
                job = jobs[k]
                opt_sets = [sw.split(m)[1] for _, m in mem]
                res = optimise(job, job.search_problem, members=opt_sets, progress=bar)
                for j, (i, m) in enumerate(mem):
                    mres = res.member(j)
                    t = run_groups(job.cfg, job.search_problem, mres, job.dtype)
                    na = tuple(job.search_problem.na_range)
                    check_finite(t["final"], where, f"sweep member {i} {m}", na=na)
                    t = rescoring.final_groups(job, job.search_problem, mres, t)
                    check_finite(t["final"], where, f"sweep member {i} {m}", na=na)
                    warnings(job, t["final"])
                    t["attrs"] = {"overrides": m,
                                  "config_resolved_yaml": sw.resolved(cfg, m)}  # fmt: skip
                    tree["members"][f"{i:03d}"] = t
                    rows.append((i, m, t["final"]))
        tree["members"] = dict(sorted(tree["members"].items()))  # the sweep's order
        attrs = base_attrs("sweep", cfg, text, streams(cfg.seed), where) | {
            "n_members": len(members), "wall_time_s": total.wall, "compile_time_s": total.compile,
            "run_time_s": total.run, "vmapped_batches": len(groups)}  # fmt: skip
        rec = bind(SweepRecord(attrs, tree, cfg))
        if out is not None:
            archive.save(out, rec)
    lines = [f"{len(members)} members in {len(groups)} vmapped batch(es), each final design "
             "re-scored on fresh samples (final.n_samples); wall "
             f"{total.wall:.1f} s (compile {total.compile:.1f} s, run {total.run:.1f} s)"]  # fmt: skip
    subs = next(iter(jobs.values())).study.summary(cfg.study)[:3]
    for i, m, fin in sorted(rows, key=lambda r: r[0]):
        keys_txt = ", ".join(f"{k} = {v:g}" for k, v in m.items())
        vals = ", ".join(f"{s} = {float(fin[s]):.4f}" for s in subs)
        lines.append(f"  [{i:3d}] {keys_txt}:  f = {float(fin['f']):.5f}, {vals}")
        lines += [f"        warning: {w}" for w in fin.get("attrs", {}).get("warnings", [])]
    return Report(out, lines, rec)


# ------------------------------------------------------------------ evaluate / scan


def evaluate(cfg: Any, designs: Designs, where: str = "config") -> dict[str, np.ndarray]:
    """Every index of the given designs with its standard error, without optimising:
    {index: (n,), index_se: (n,), ...}, one entry per design (``designs``: a dict of
    variable → value or array, arrays broadcast; or a list of such dicts; a variable not
    given takes the middle of its box)."""
    job = Job.build(cfg, where, n_designs=1)
    X = matrix(job.problem, designs, where)
    return score(job.problem, X, batch=cfg.scan.batch if cfg.scan else 256)


def evaluate_one(cfg: Any, design: Mapping[str, float], where: str = "config"
                 ) -> tuple[dict[str, float], list[str], dict[str, str]]:  # fmt: skip
    """One design's indices (:func:`evaluate`) as floats, with the study's warnings on
    them, the lines ``run`` prints for its final design (``Study.warnings``), and the
    study's units of its variables and indices (``Study.units``). A front's config has
    no weighted f: f and its SE are left out."""
    one = compare(cfg, [design], where, replicas=0)["designs"][0]
    return one["values"], one["warnings"], one["units"]


PAIRED_REPLICAS = 8
"""Further independent sample sets (each the config's size) on which :func:`compare`
scores every design again, for the standard error of the paired differences."""
PAIRED_STREAM = 0x50414952  # "PAIR"


def check_box(problem: Any, design: Mapping[str, float], where: str) -> None:
    """ConfigError naming the first variable of ``design`` outside the study's box."""
    for n, lo, hi in zip(problem.names, problem.lower, problem.upper, strict=True):
        v = design.get(n)
        if v is not None and not float(lo) <= float(v) <= float(hi):
            txt = f"{float(v):g}" if float(f"{float(v):g}") == float(v) else repr(float(v))
            raise ConfigError(f"{where}: --design {n}={txt}: outside the design box "
                              f"[{float(lo):g}, {float(hi):g}] of variable '{n}'")  # fmt: skip


def compare(cfg: Any, designs: list[Mapping[str, float]], where: str = "config",
            replicas: int = PAIRED_REPLICAS, fresh: bool = False) -> dict[str, Any]:  # fmt: skip
    """Designs scored together, and the paired differences of every design from the
    first (``designopt eval --design … --design …``).

    All designs are scored in one call on the run's samples (common random numbers:
    the same targets, joint samples and IK seeds), so design k − design 1 is the
    difference of two estimates on the same samples. Its standard error is that of the
    paired difference: every design is scored again on ``replicas`` further independent
    sample sets of the same size (the ``samples`` stream folded with
    :data:`PAIRED_STREAM` and r), each giving one independent realisation of the paired
    difference, and the SE is the standard deviation of the ``replicas + 1``
    differences (far below √(SE₁² + SE₂²) when the samples affect both designs alike).

    Returns {"designs": [{"design": {variable: value}, "filled": [variables that took
    the middle of their box], "values": {index: value, index_se: SE, ...}, "warnings",
    "units", "placement": {name: array}, "lines": the study's lines of them}], "differences": [{"of": (k, 0), "values":
    {index: value, index_se: paired SE}}], "replicas": replicas, "n_samples": samples per
    design}. A variable outside the box: ConfigError naming it.

    Each design's values come with its ``warnings`` (``designopt.app.quoted.warnings``,
    the rule of every run kind) and, for a task, its IK coverage figure (``coverage``:
    ``ik_better``, ``ik_better_n``, ``lines``, ``warnings``; ``quoted.coverage``).

    ``fresh``: on the fresh stream a run of this config quotes its values on
    (``quoted.section``: ``final``, ``final.n_samples`` per design with the run's
    normalisation; a front's ``front``, ``front.n_samples``), scored by the function
    that scored them (``quoted.score``), so a run's final design (a front's design)
    gives the archive's ``final/`` (``front/``) values bit for bit; the replicas fold
    from it. The result's ``stream`` names the samples: ``final``, ``front`` or ``search``
    (the study's own)."""
    import jax

    job = Job.build(cfg, where, n_designs=len(designs))
    base_cfg, base_keys, stream = cfg, job.keys, "search"
    search = None
    if fresh:  # the run's normalisation: its search's (optimizer.fidelity's settings)
        fr = quoted.stream(job)
        search = job.search_problem if fr.section == "final" else None  # a front: f moot
        problem = quoted.problem(job, search)
        base_cfg, base_keys, n_used = fr.cfg, fr.keys, int(problem.n_samples_used or fr.n)
        stream = fr.section
    else:
        problem = job.problem
        n_used = int(problem.n_samples_used)
    for d in designs:
        bad = [k for k in d if k not in problem.names]
        if bad:
            raise ConfigError(f"{where}: --design {bad[0]!r}: not a design variable of this "
                              f"study; its variables: {list(problem.names)}")  # fmt: skip
        check_box(problem, d, where)
    X = matrix(problem, list(designs), where)
    front = getattr(cfg.study, "pareto", None) is not None

    def scored(prob: Any) -> dict[str, np.ndarray]:  # quoted.blocked: a run's own scoring
        res = {k: np.asarray(v, np.float64) for k, v in quoted.blocked(prob, X).items()}
        return {k: v for k, v in res.items() if not (front and k in ("f", "f_se"))}

    res = scored(problem)
    units = dict(job.study.units(cfg.study))
    placed = placement(job.study, cfg.study, X)
    out: dict[str, Any] = {"designs": [], "differences": [], "replicas": int(replicas),
                           "n_samples": n_used, "stream": stream}  # fmt: skip
    covers = quoted.coverages(job, base_cfg.study, X, base_keys)  # every design in one batch
    for i, d in enumerate(designs):
        vals = {k: float(v[i]) for k, v in res.items()}
        x = dict(zip(problem.names, X[i].tolist(), strict=True))
        pl = {k: placed[k][i] for k in placed.get("attrs", {}).get("placement", [])}
        cover = covers[i]
        warns = quoted.warnings(job, vals, X[i], cover)
        lines = list(job.study.extra_lines(cfg.study, pl)) if pl else []
        out["designs"].append({"design": x, "filled": [n for n in problem.names if n not in d],
                               "values": vals, "warnings": warns, "units": units,
                               "placement": pl, "lines": lines, "coverage": cover})  # fmt: skip
    if len(designs) < 2:
        return out
    names = [k for k in res if k + "_se" in res]
    diffs = [{k: res[k][1:] - res[k][0] for k in names}]
    root = jax.random.fold_in(base_keys["samples"], PAIRED_STREAM)
    for r in range(replicas):  # the same designs on independent sample sets
        keys = dict(base_keys) | {"samples": jax.random.fold_in(root, r)}
        prob = build_problem(base_cfg, keys, where, job.dtype)
        rep = scored(rescoring.same_normalisation(prob, search)
                     if fresh and stream == "final" else prob)  # fmt: skip
        diffs.append({k: rep[k][1:] - rep[k][0] for k in names})
    for j in range(len(designs) - 1):
        vals: dict[str, float] = {}
        for k in names:
            d = np.array([dd[k][j] for dd in diffs])
            vals[k] = float(d[0])
            ok = d[np.isfinite(d)]
            vals[k + "_se"] = float(np.std(ok, ddof=1)) if len(ok) > 1 else float("nan")
        out["differences"].append({"of": (j + 1, 0), "values": vals})
    return out


def scan(cfg: Any, text: str | None = None, where: str = "config", out: Path | None = None,
         progress: Progress = no_progress, dry_run: bool = False) -> Report:  # fmt: skip
    """Score the designs of the config's ``scan:`` section in vmapped batches → ScanRecord
    (``scan/names``, ``scan/x``, ``scan/<index>`` and ``scan/<index>_se``)."""
    if cfg.scan is None:
        raise ConfigError(f"{where}: key 'scan': missing; `designopt scan` needs one "
                          "(docs/configs.md)")  # fmt: skip
    sizes = [len(v) for v in cfg.scan.lists().values()]
    job = Job.build(cfg, where, text,
                    n_designs=math.prod(sizes) if cfg.scan.mode == "grid" else max(sizes))  # fmt: skip
    if dry_run:
        return _dry(out, cfg, job.estimate)
    with _writing(out, cfg, job.estimate):
        with Stopwatch() as total:
            problem = job.problem
            varied, X = scan_designs(cfg, problem, where)
            b = cfg.scan.batch
            plan = devices.scoring_plan(cfg.parallel, where)
            parts = []
            with progress(X.shape[0], "scan") as bar:
                for i in range(0, X.shape[0], b):
                    parts.append(score(problem, X[i : i + b], batch=b, plan=plan))
                    bar(min(b, X.shape[0] - i))
            res = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        check_finite(res, where, "scan", problem.names, X, na=tuple(problem.na_range))
        tree = {"scan": {"names": np.array(problem.names, dtype="S"), "x": X,
                         "varied": np.array(varied, dtype="S"), **res,
                         "attrs": {"mode": cfg.scan.mode, "shape": sizes}},
                "problem": problem_group(problem)}  # fmt: skip
        attrs = job.attrs("scan") | {
            "n_designs": int(X.shape[0]), "wall_time_s": total.wall,
            "compile_time_s": total.compile, "run_time_s": total.run}  # fmt: skip
        rec = bind(ScanRecord(attrs, tree, cfg))
        if out is not None:
            archive.save(out, rec)
    lines = [f"{X.shape[0]} designs over {', '.join(varied)} ({cfg.scan.mode}) in batches of "
             f"{b}; wall {total.wall:.1f} s (compile {total.compile:.1f} s, run {total.run:.1f} s)",
             *rec.best_lines()]  # fmt: skip
    return Report(out, lines, rec)


__all__ = ["Report", "build_problem", "compare", "draw_figures", "evaluate", "optimise", "run", "scan",
           "score", "sweep", "write_html"]  # fmt: skip
