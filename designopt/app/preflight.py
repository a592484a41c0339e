"""The pre-flight estimate of a job, from its config alone and before anything compiles:
peak memory, disk for archive and checkpoint, and the Monte-Carlo work, so that a job
that cannot fit is refused (exit 2) and a huge one warned about. Each study states its
cost per design evaluation (``Study.cost(settings) -> Cost``: samples, chunk in flight,
normalisation probes and the keys that lower them)."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Any

from designopt.core.errors import ConfigError
from designopt.core.memory import available_memory
from designopt.io import writer
from designopt.studies import Study

BYTES_PER_DESIGN_SAMPLE = 128
"""Peak memory per (design × Monte-Carlo sample in flight), conservative: the 9-DOF master study measures
80-280 B in float64 and float32 on CPU (XLA's buffers of one sample chunk)."""
BASE_BYTES = 1 << 29  # JAX, XLA and the compiled programs
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
    if key == "study.n_norm" and cost.norm_key:
        lower = cost.norm_key
    if device >= host and per_chunk > 4096 and designs * per_chunk > 1e10:
        lower += f" (or {cost.chunk_key})"
    work = float(samples) * (n_norm + (n_designs or swarm * T + T))
    line = (f"pre-flight: about {writer.human(memory)} of memory "
            f"({writer.human(available_memory())} available), {writer.human(2 * disk)} of disk")  # fmt: skip
    return Estimate(memory, 2 * disk, swarm * samples, lower, [line], work, cost.samples_key)
