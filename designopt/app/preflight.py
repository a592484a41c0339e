"""The pre-flight estimate of a job, from its config alone and before anything compiles:
peak memory, disk for archive and checkpoint, and the Monte-Carlo work, so that a job
that cannot fit is refused (exit 2) and a huge one warned about. Each study states its
cost per design evaluation (``Study.cost(settings) -> Cost``: samples, chunk in flight,
normalisation probes and the keys that lower them, and optionally its bytes per sample,
per design and for its own large program). The memory model and its measured constants
are below (:func:`memory`); ``benchmarks/preflight.py`` checks it against real runs."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Any

from designopt.core.errors import ConfigError
from designopt.core.memory import available_memory
from designopt.io import writer
from designopt.studies import Study
from designopt.studies.base import Cost

MiB = 1 << 20
# The memory model (issue #38 §4). The peak resident memory of a job is
#   BASE_BYTES + PROGRAM_BYTES (+ FRONT_BYTES for a Pareto front) + the study's program
#   + designs in flight × (samples per chunk × bytes per sample + bytes per design) + host,
# and XLA's compilations, not the Monte-Carlo buffers, dominate it for every shipped config.
# Measured as the peak resident set (VmHWM) of `designopt run ... --no-figures --no-cache`
# on a 2-core x86-64 CPU host (benchmarks/preflight.py prints the table; docs/faults.md).
BASE_BYTES = 250 * MiB
"""The process before a job's first program: Python with numpy, JAX and jaxlib's XLA CPU
client, h5py and designopt imported (238 MiB peak for ``run configs/master9.yaml
--dry-run``; 216 MiB for ``import designopt, jax`` and one trivial jit)."""
PROGRAM_BYTES = 180 * MiB
"""The job's ordinary compiled programs: each non-trivial XLA compilation leaves some
20-35 MiB resident (the compiler's heap, which the allocator keeps, and the executable),
and a run compiles about six (the objective, the optimizer's init/ask/tell, records,
scoring): master9 peaks 150 MiB and planar2r 230 MiB (with 22 MiB of buffers) above the
dry run."""
FRONT_BYTES = 150 * MiB
"""A Pareto front's extra programs: NSGA-II's non-dominated sorting (its init/tell
compile in 3-4 s each) and the re-scoring problem at the front's sample count
(master9_front peaks 240 MiB above master9, planar2r_front 130 MiB above planar2r)."""
BYTES_PER_DESIGN_SAMPLE = 128
"""Peak bytes per (design × Monte-Carlo sample in flight) of a study that states none
(``Cost.bytes_per_sample``, below): XLA's temporaries of one chunk, measured with
``compiled.memory_analysis()``: 5-8 B for master9 (its chunk is fused into reductions),
30-60 B for a planar serial chain, 430 B (float32) and 820 B (float64) for a 6×6 Jacobian.
A study's numbers are float64's; a float32 job's buffers count half.

A study's ``Cost`` states three more numbers (:func:`extra` reads them): ``bytes_per_sample``
(its own value of this; ``Cost``'s default is this one),
``per_design`` (bytes per design in flight beyond its samples, e.g. an IK's FK database)
and ``program`` (bytes to compile its largest program beyond an ordinary one, e.g. the
task study's batched IK: 0.45-1 GB)."""
DESIGN_SAMPLES_PER_S = 2e7  # the 9-DOF master on 2 CPU cores: 50 × 20k samples in 27-59 ms (#14)
HUGE_WORK = 3600 * DESIGN_SAMPLES_PER_S  # an hour or more: warn before starting
DESIGN_SAMPLES_PER_CHUNK = 10_000_000
"""Work per optimizer chunk (designs × samples × iterations): ≈ 0.5 s at
DESIGN_SAMPLES_PER_S, so a stop request meets an iteration boundary promptly
(docs/faults.md)."""


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
    parts: dict[str, int] = field(default_factory=dict)  # the memory's terms (:func:`memory`)

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
                              f"{writer.human(self.memory)} of memory, {writer.human(avail)} "
                              f"available; lower {self.lower}")  # fmt: skip


def extra(cost: Cost) -> tuple[int, int, int]:
    """(bytes per design-sample, bytes per design, program bytes) of a study's ``Cost``."""
    return int(cost.bytes_per_sample), int(cost.per_design), int(cost.program)


def memory(cost: Cost, designs: int, per_chunk: int, host: int = 0, front: bool = False,
           rescore: tuple[int, int] = (0, 0), itemsize: int = 8) -> dict[str, int]:  # fmt: skip
    """The peak memory's terms (bytes): ``base`` (the process), ``programs`` (the job's
    ordinary compiled programs, with FRONT_BYTES for a ``front``), ``study program`` (the
    study's own large program), ``buffers`` (``designs`` in flight × (``per_chunk``
    samples × bytes per sample + bytes per design); a front's re-scoring, ``rescore`` =
    (designs, samples per chunk), runs after the optimizer: the larger of the two) and
    ``host`` (histories and optimizer state). A study's bytes are float64's: ``itemsize``
    4 (float32) halves them."""
    bps, per_design, program = extra(cost)
    bps, per_design = bps * itemsize // 8, per_design * itemsize // 8
    run = designs * (per_chunk * bps + per_design)
    again = rescore[0] * (rescore[1] * bps + per_design)
    return {"base": BASE_BYTES, "programs": PROGRAM_BYTES + (FRONT_BYTES if front else 0),
            "study program": program, "buffers": max(run, again), "host": host}  # fmt: skip


def estimate(cfg: Any, study: Study, n_designs: int = 0, members: int = 1) -> Estimate:
    """Peak memory and archive size of a run (``n_designs`` > 0: a scan of that many
    designs; ``members``: a sweep) from the config and the study's ``cost`` hook; a study
    whose run is a replay costs a fixed small amount."""
    if study.replay is not None and not n_designs:
        return Estimate(0, 1 << 22, 0, "study", ["pre-flight: a replay, no optimizer"])
    cost = study.cost(cfg.study)
    D = max(1, len(cfg.study.variables))
    samples = max(1, int(cost.samples))
    per_chunk = max(1, min(samples, int(cost.chunk)))
    n_norm = max(1, int(cost.n_norm))
    o = cfg.optimizer
    swarm = o.n_particles * o.n_runs * members
    T = o.n_iters + 1
    front = not n_designs and getattr(cfg.study, "pareto", None) is not None
    rescore = (0, 0)
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
        if front:  # the front's designs (at most the swarm's) re-scored on more samples
            n_front = cfg.front.n_samples or 4 * samples
            rescore = (min(cfg.front.max_points, swarm), max(1, min(n_front, int(cost.chunk))))
        else:  # each run's best and the final design re-scored on fresh samples (app.rescoring)
            n_final = cfg.final.n_samples or max(4 * samples, 30)
            rescore = (o.n_runs + 1, max(1, min(n_final, int(cost.chunk))))
    key, designs = max(flight.items(), key=lambda kv: kv[1])
    itemsize = 4 if getattr(cfg, "precision", "float64") == "float32" else 8
    if cost.designs:  # a study scoring in blocks holds one block's designs at a time
        designs, rescore = min(designs, cost.designs), (min(rescore[0], cost.designs), rescore[1])
    parts = memory(cost, designs, per_chunk, host, front, rescore, itemsize)
    device = parts["buffers"]
    total = sum(parts.values())
    lower = key if device >= host else ("scan.vary" if n_designs else "optimizer.n_iters")
    if key == "study.n_norm" and cost.norm_key:
        lower = cost.norm_key
    if device >= host and per_chunk > 4096 and designs * per_chunk > 1e10:
        lower += f" (or {cost.chunk_key})"
    work = float(samples) * (n_norm + (n_designs or swarm * T + T))
    line = (f"pre-flight: about {writer.human(total)} of memory "
            f"({writer.human(available_memory())} available), {writer.human(2 * disk)} of disk")  # fmt: skip
    return Estimate(total, 2 * disk, swarm * samples, lower, [line], work, cost.samples_key,
                    parts)  # fmt: skip
