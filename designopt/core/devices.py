"""Scale-out on JAX's own engine (docs/scaling.md): a device mesh over one axis of a job,
and several processes joined by ``jax.distributed`` into one job.

- **One compiled program.** :func:`plan` picks the axis to shard — ``members`` (a sweep's
  vmapped settings), ``runs``, ``particles`` (the swarm) or ``samples`` (Monte-Carlo) —
  and :class:`Plan` places the optimizer's inputs and carry with a ``NamedSharding``;
  GSPMD partitions the runner's jitted chunk. No Python loop over devices.
- **Samples.** Sample chunks are generated inside a study's ``lax.scan``, so GSPMD cannot
  split them: a study that supports it gives ``Problem.shard_samples(mesh)``, a Problem
  whose fn spreads its chunks over the mesh with ``montecarlo.scan_chunks`` (shard_map,
  the per-chunk power sums gathered and added in index order: bitwise the one-device sum).
- **Processes.** :func:`configure` (the CLI, before JAX starts its backend) joins
  ``jax.distributed`` (gloo collectives on CPU) and fixes the CPU device count. Every
  process runs the same program; only process 0 writes (``designopt.io.writer``); arrays
  come to the host at chunk boundaries with ``process_allgather``.

Kept light: JAX is imported inside the functions that need it.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field

from designopt.core.errors import ConfigError
from designopt.core.settings import Section

AXES = ("auto", "members", "runs", "particles", "samples")
MESH_AXIS = "d"
SAMPLES_AXIS = "samples"
DEFAULT_TIMEOUT_S = 60


class ParallelSettings(Section):
    """The ``parallel:`` section of a config (docs/scaling.md).

    ``devices``: how many devices the job uses (all processes together); None = every
    device JAX sees. ``axis``: what to shard, or ``auto`` (the first of members, runs,
    particles whose size divides over the devices, else samples). ``timeout_s``: how long
    a multi-process job waits for a silent peer before it gives up (exit 1).
    """

    devices: int | None = Field(
        None,
        ge=1,
        description="How many devices the job uses, all processes together (default: every device "
        "JAX sees); `--devices` overrides.",
    )
    axis: Literal["auto", "members", "runs", "particles", "samples"] = Field(
        "auto",
        description="What the device mesh splits: `members`, `runs`, `particles` or `samples`; "
        "`auto`: the first of members, runs, particles whose size divides over the "
        "devices, else samples.",
    )
    timeout_s: int = Field(
        DEFAULT_TIMEOUT_S,
        ge=5,
        le=86_400,
        description="Seconds a multi-process job waits for a silent peer before it stops (exit 1).",
    )


class PeerLost(RuntimeError):
    """A process of a multi-process job died or stopped answering (exit 1)."""


# --------------------------------------------------------------------------- processes


def requested(coordinator: str | None = None, num_processes: int | None = None) -> bool:
    """Whether this process is one of a multi-process job: the CLI's flags, or the
    variables ``jax.distributed`` reads (``JAX_COORDINATOR_ADDRESS``; a SLURM step of
    several tasks)."""
    if coordinator or (num_processes or 1) > 1:
        return True
    if os.environ.get("JAX_COORDINATOR_ADDRESS"):
        return True
    return int(os.environ.get("SLURM_NTASKS", "1") or 1) > 1 and "SLURM_JOB_ID" in os.environ


def configure(
    devices: int | None = None,
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    timeout_s: int = DEFAULT_TIMEOUT_S,
) -> None:
    """Set JAX up for this job before its backend starts (the CLI calls this).

    Joins ``jax.distributed`` when :func:`requested` (gloo collectives on CPU; a silent
    peer is declared dead after ``timeout_s``), and on CPU asks for ``devices`` devices in
    all (``devices / num_processes`` per process). ConfigError if JAX has already started
    with another device count, or the job cannot be joined.
    """
    import jax
    from jax._src import xla_bridge

    started = bool(xla_bridge._backends)
    multi = requested(coordinator, num_processes)
    if multi and not jax.distributed.is_initialized():
        if started:
            raise ConfigError("a multi-process job must be joined before JAX starts "
                              "(call designopt.core.devices.configure first)")  # fmt: skip
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        try:
            jax.distributed.initialize(
                coordinator, num_processes, process_id,
                initialization_timeout=max(timeout_s, 30),
                heartbeat_timeout_seconds=timeout_s,
                shutdown_timeout_seconds=timeout_s,
            )  # fmt: skip
        except (ValueError, TypeError, RuntimeError) as e:
            msg = " ".join(str(e).split())[:300]
            raise ConfigError(f"cannot join the multi-process job ({msg}); give --coordinator "
                              "HOST:PORT --num-processes N --process-id I, or the variables "
                              "jax.distributed reads (docs/scaling.md)") from None  # fmt: skip
    if devices is not None and devices > 1 and not started:
        n_proc = num_processes or 1
        if multi and num_processes is None:
            n_proc = jax.process_count()
        if devices % n_proc:
            raise ConfigError(f"--devices {devices}: not a multiple of the {n_proc} processes")
        jax.config.update("jax_num_cpu_devices", devices // n_proc)


def process_index() -> int:
    """This process's index in the job (0 when alone)."""
    import jax

    return jax.process_index() if jax.distributed.is_initialized() else 0


def is_writer() -> bool:
    """Whether this process writes files: process 0 of a job (or a lone process)."""
    return process_index() == 0


# ---------------------------------------------------------------------------- the plan


def _devices(n: int | None, where: str) -> list[Any]:
    import jax

    avail = jax.devices()
    if n is None:
        return avail
    if n > len(avail):
        hint = ("; on CPU give --devices on the command line (it must be set before JAX "
                "starts) or XLA_FLAGS=--xla_force_host_platform_device_count=N"
                if avail[0].platform == "cpu" else "")  # fmt: skip
        raise ConfigError(f"{where}: key 'parallel.devices': {n} devices asked, JAX sees "
                          f"{len(avail)} ({avail[0].platform}){hint}")  # fmt: skip
    if jax.process_count() > 1:  # a mesh over the first n devices must take whole processes
        per = jax.local_device_count()
        if n % per:
            raise ConfigError(f"{where}: key 'parallel.devices': {n} is not a multiple of the "
                              f"{per} devices of each process")  # fmt: skip
    return avail[:n]


def _is_key(x: Any) -> bool:
    import jax
    import jax.numpy as jnp

    return hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jax.dtypes.prng_key)


@dataclass(frozen=True, eq=False)
class Plan:
    """Where a job's arrays live: a 1-D mesh ``mesh`` and the axis it shards.

    ``pos``/``size``: the array axis (position in a leaf's shape, its length) that is
    split; leaves without it are replicated. ``axis == "samples"`` replicates every input
    and shards inside the problem's fn instead (``Problem.shard_samples``).
    """

    mesh: Any
    axis: str
    pos: int = 0
    size: int = 0

    @property
    def n_devices(self) -> int:
        return int(self.mesh.devices.size)

    def spec(self, x: Any) -> Any:
        from jax.sharding import PartitionSpec as P

        shape = getattr(x, "shape", ())
        if self.axis != "samples" and len(shape) > self.pos and shape[self.pos] == self.size:
            return P(*([None] * self.pos + [MESH_AXIS]))
        return P()

    def put(self, tree: Any) -> Any:
        """Every leaf of ``tree`` onto the mesh: split along the plan's axis where a leaf
        has it, replicated otherwise (global arrays across processes)."""
        import jax

        return jax.tree.map(self._put, tree)

    def _put(self, x: Any) -> Any:
        import jax
        from jax.sharding import NamedSharding

        sh = NamedSharding(self.mesh, self.spec(x))
        if jax.process_count() == 1:
            return jax.device_put(x, sh)
        if isinstance(x, jax.Array) and not x.is_fully_addressable:
            return x if x.sharding == sh else _reshard(sh)(x)
        if _is_key(x):
            data = np.asarray(jax.random.key_data(x))
            raw = jax.make_array_from_callback(data.shape, sh, lambda i: data[i])
            return jax.random.wrap_key_data(raw, impl=jax.random.key_impl(x))
        a = np.asarray(x)
        return jax.make_array_from_callback(a.shape, sh, lambda i: a[i])

    def host(self, x: Any) -> np.ndarray:
        """A (global) array as one numpy array on every process."""
        return to_host(x)

    def problem(self, problem: Any) -> Any:
        """The problem this plan evaluates: with samples sharded, the study's sharded
        variant (``Problem.shard_samples``); else unchanged."""
        if self.axis != "samples":
            return problem
        from jax.sharding import Mesh

        return problem.shard_samples(Mesh(self.mesh.devices, (SAMPLES_AXIS,)))

    def describe(self) -> dict[str, Any]:
        """What the archive records: axis, devices, processes."""
        import jax

        return {"axis": self.axis, "devices": self.n_devices,
                "processes": jax.process_count(),
                "platform": self.mesh.devices.flat[0].platform}  # fmt: skip


@functools.cache
def _reshard(sharding: Any) -> Callable[[Any], Any]:
    """A jitted identity onto ``sharding`` (device_put cannot move a global array)."""
    import jax

    return jax.jit(lambda x: x, out_shardings=sharding)


def to_host(x: Any) -> np.ndarray:
    """``np.asarray`` of an array, gathering it from every process when it is a global
    array of a multi-process job (``process_allgather``: every process gets it all)."""
    import jax

    if isinstance(x, jax.Array) and not x.is_fully_addressable:
        from jax.experimental import multihost_utils

        try:
            return np.asarray(multihost_utils.process_allgather(x, tiled=True))
        except Exception as e:  # noqa: BLE001 - the runtime's errors have no common type
            raise lost(e) from None
    return np.asarray(x)


def lost(e: BaseException) -> PeerLost:
    """A PeerLost naming this process and the runtime's reason."""
    msg = " ".join(str(e).split())[:240]
    return PeerLost(f"process {process_index()}: a peer process of this multi-process job "
                    f"died or stopped answering ({type(e).__name__}: {msg})")  # fmt: skip


def plan(
    settings: ParallelSettings | None,
    *,
    n_runs: int,
    n_particles: int,
    members: int | None = None,
    problem: Any = None,
    where: str = "config",
) -> Plan | None:
    """The plan of an optimisation on ``settings.devices`` devices, or None on one device
    (the default path, untouched); ``members``: the size of a sweep's vmapped batch. ``auto`` takes the first of members, runs, particles
    whose size is a multiple of the device count (no communication inside the step for
    the first two), else samples when the study supports it. ConfigError when the named
    axis cannot be split or no axis fits."""
    import jax
    from jax.sharding import Mesh

    if settings is None:
        return None
    devs = _devices(settings.devices, where)
    n = len(devs)
    if n == 1 and jax.process_count() == 1:
        return None
    batched = members is not None
    sizes = {"members": (0, members) if batched else None,
             "runs": (1 if batched else 0, n_runs),
             "particles": (2 if batched else 1, n_particles)}  # fmt: skip
    can_samples = problem is not None and getattr(problem, "shard_samples", None) is not None
    mesh = Mesh(np.array(devs), (MESH_AXIS,))
    axis = settings.axis
    if axis == "auto":
        fits = [a for a, ps in sizes.items() if ps is not None and ps[1] % n == 0]
        if fits:
            axis = fits[0]
        elif can_samples:
            axis = "samples"
        else:
            raise ConfigError(f"{where}: key 'parallel.axis': no axis of this job divides over "
                              f"{n} devices (members {members}, runs {n_runs}, particles "
                              f"{n_particles}) and the study does not shard its samples; "
                              "change parallel.devices or the sizes")  # fmt: skip
    if axis == "samples":
        if not can_samples:
            name = getattr(problem, "info", {}).get("study", "this study")
            raise ConfigError(f"{where}: key 'parallel.axis': the study {name!r} does not "
                              "support sharding its Monte-Carlo samples; shard runs, "
                              "particles or members instead")  # fmt: skip
        return Plan(mesh, "samples")
    ps = sizes[axis]
    if ps is None:
        raise ConfigError(f"{where}: key 'parallel.axis': 'members' needs a sweep "
                          "(`designopt sweep`)")  # fmt: skip
    if ps[1] % n:
        raise ConfigError(f"{where}: key 'parallel.axis': {axis} ({ps[1]}) is not a multiple "
                          f"of the {n} devices")  # fmt: skip
    return Plan(mesh, axis, ps[0], ps[1])


def scoring_plan(settings: ParallelSettings | None, where: str = "config") -> Plan | None:
    """The plan of scoring a batch of designs (``scan``, ``eval``): designs split over
    the devices (axis 0 of the batch, which the caller pads to a multiple)."""
    from jax.sharding import Mesh

    if settings is None:
        return None
    devs = _devices(settings.devices, where)
    import jax

    if len(devs) == 1 and jax.process_count() == 1:
        return None
    return Plan(Mesh(np.array(devs), (MESH_AXIS,)), "designs", 0, -1)


def shard_rows(plan_: Plan, X: Any) -> Any:
    """A batch of designs (n, D) split by rows over the plan's devices (n a multiple)."""
    return Plan(plan_.mesh, "designs", 0, int(np.shape(X)[0])).put(X)


def peer_error(e: BaseException) -> PeerLost | None:
    """``e`` as a :class:`PeerLost` when it is one, or a runtime error of JAX's
    collectives in a multi-process job; None otherwise."""
    if isinstance(e, PeerLost):
        return e
    if type(e).__name__ in ("XlaRuntimeError", "JaxRuntimeError"):
        import jax

        if jax.distributed.is_initialized() and jax.process_count() > 1:
            return lost(e)
    return None


def guard(fn: Callable[[], Any]) -> Any:
    """Run ``fn``; in a multi-process job, a runtime error of the collectives becomes a
    :class:`PeerLost` naming the process (exit 1 from the CLI)."""
    import jax

    if jax.process_count() == 1:
        return fn()
    try:
        return fn()
    except PeerLost:
        raise
    except Exception as e:  # noqa: BLE001
        if type(e).__name__ in ("XlaRuntimeError", "JaxRuntimeError"):
            raise lost(e) from None
        raise
