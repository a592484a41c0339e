"""The configured optimizer on a study's Problem: sizes, iteration chunks (so a stop meets
an iteration boundary soon), devices (``parallel:``), the constraint method, one vmapped
batch for sweep members, a front's hypervolume reference."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from designopt.app.preflight import DESIGN_SAMPLES_PER_CHUNK
from designopt.core import devices
from designopt.problems.base import Problem

SEPARATE_UP_TO_ITERS = 5000
"""``objective_program: auto`` runs the objective as a program of its own up to this many
iterations and fused into the runner's scan beyond. Measured (docs/configs.md, "Fused or
separate"): a separate iteration costs 0.2-0.4 ms more than a fused one (three program
calls instead of a share of one chunk's), while a fused run compiles the objective into
two more programs (the first population's and the chunk's), at least 1 s each for every
shipped study on 2 CPU cores (2.5-4.6 s under load), and far more on a GPU; each of
their iterations also evaluates 40-2000 ms of Monte-Carlo samples, beside which the
0.3 ms is noise. So separate is cheaper up to some 5000 iterations, on either device."""


def separate_objective(o: Any) -> bool:
    """Whether the run evaluates the objective as a program of its own (``optim.run
    (separate=True)``) for the config's optimizer section ``o``: its
    ``objective_program``, and for ``auto`` separate up to SEPARATE_UP_TO_ITERS
    iterations (the objective compiled once, shared with the normalisation probe and the
    scoring), fused beyond (one chunked scan, no per-iteration calls)."""
    if o.objective_program != "auto":
        return o.objective_program == "separate"
    return o.n_iters <= SEPARATE_UP_TO_ITERS


def optimise(job: Any, problem: Problem, members: list[dict[str, float]] | None = None,
             progress: Callable[[int], None] | None = None,
             checkpoint: Callable[[Any], None] | None = None,
             resume: Any = None, ref_point: Any = None) -> Any:  # fmt: skip
    """The configured optimizer of ``job`` (an ``app.job.Job``) on ``problem``, from the
    job's ``optimizer`` key stream; with ``members`` (overrides of optimizer
    settings) one vmapped batch on common keys. Chunks are small (≤ 5 % of the run and
    about DESIGN_SAMPLES_PER_CHUNK of work), so a stop meets an iteration boundary soon.
    A ``parallel:`` section shards the job over devices (designopt.core.devices). The
    objective runs as a program of its own between each iteration's ask and tell
    (``optim.run(separate=True)``: one compiled objective for the whole run and its
    scoring, instead of one inside each of the runner's programs) or fused into the
    runner's scan, as :func:`separate_objective` decides."""
    from designopt import optim
    from designopt.problems import penalty

    cfg, where, key = job.cfg, job.where, job.keys["optimizer"]
    o = cfg.optimizer
    plan = devices.plan(cfg.parallel, n_runs=o.n_runs, n_particles=o.n_particles,
                         members=None if members is None else len(members), problem=problem,
                         where=where)  # fmt: skip
    if plan is not None:
        problem = plan.problem(problem)
    if o.constraints.method == "penalty":
        problem = penalty.quadratic(problem, o.constraints.weight)
    work = job.estimate.work_per_iter
    chunk = max(1, min(o.n_iters // 20, DESIGN_SAMPLES_PER_CHUNK // max(work, 1)))
    common = dict(n_particles=o.n_particles, n_iters=o.n_iters, n_runs=o.n_runs, bounds=o.bounds,
                  dtype=job.dtype, chunk_iters=chunk,
                  progress=progress, checkpoint=checkpoint, resume=resume,
                  checkpoint_at_end=checkpoint is not None,
                  separate=separate_objective(o))  # fmt: skip
    if plan is not None:
        common["plan"] = plan
    if ref_point is not None:  # a front's hypervolume reference (designopt.app.fronts)
        common["ref_point"] = ref_point
    if members is None:
        res = optim.run(o.name, problem, key, **common, **o.settings)
    else:
        res = optim.run_batch(o.name, problem, key, [o.settings | m for m in members], **common)
    if plan is not None:
        res.settings["parallel"] = plan.describe()
    return res
