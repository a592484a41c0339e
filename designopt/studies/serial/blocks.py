"""The task's per-target values in one compiled program per structure (issue #46).

The costly part of a task index is the batched IK (``taskindex.chunk_values``): every
design solves every target. Compiled inside each caller's own program, it was compiled
once per shape: the search's swarm, the front's re-scoring (4 × the targets), the
figures' and the report's one design, ``eval``'s one design, ``scan``'s batches and the
normalisation probe, 12-15 s each for a 6-joint arm through a port. Here it is one
program of a fixed block, :data:`DESIGNS` designs × ``taskindex.chunk`` targets, with
everything else an input (the designs, the targets, each chunk's first target index,
the scene's numbers, the joint limits, the arms' bases, the IK's key), and every phase
calls it block by block from the host (``Problem.staged``: the search's objective, the
scoring, the probe; :func:`values` for the figures' solution of one design). The
reduction to indices (means, quantiles, ratio estimators, f, constraints) is a small
program of its own per target count (``problems.evaluate.staged_scores``).

The block's values equal the one-program path's (``taskindex.per_target``, which the
fused runner and ``jax.grad`` trace): a target's IK seeds hash its index in the task
(``t0``), not its place in a chunk, and no item's result depends on the other items of
its batch. The price: a block holds :data:`DESIGNS` designs, so one design's solution
(figures, ``eval``) solves as many copies of it.
"""

from __future__ import annotations

import collections
import functools
import hashlib
import json
import threading
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.core import concurrency, exported, xlaoptions
from designopt.studies.serial import taskindex
from designopt.studies.serial.mechanism import Mechanism, build
from designopt.studies.serial.settings import SerialSettings, length_unit

DESIGNS = 16
"""Designs per block: a 16-particle swarm's evaluation is one call per chunk of targets.
Each call pays the solver's tail (its hardest targets' seeds, one after another) once:
blocks of 8 designs made a 16-particle run on 1024 targets twice as slow as one program
(11.0 against 5.9 s of arithmetic); one design's solution (figures, ``eval``) costs a
block."""

NOT_READ = ("target_p", "target_R", "bounds", "lin_A", "lin_b", "idx_b")
"""``params`` entries the block program does not read (the targets come chunk by chunk;
the rest is the reduction's): left out, so a run's and its front's params reach one
program. (The front's re-scoring keeps the run's chunk: ``Cost.designs``.)"""

_PROGRAMS: dict[tuple[str, str], tuple[Mechanism, Callable]] = {}
_LOCK = threading.Lock()


def block_key(s: SerialSettings) -> str:
    """What shapes the block program, as text: ``taskindex.structure_key`` without the
    number of targets (they come in chunks, as inputs), with the chunk in effect
    (``taskindex.chunk``: given or not)."""
    d = json.loads(taskindex.structure_key(s))
    d["indices"].pop("n_samples", None)
    d["indices"]["chunk"] = taskindex.chunk(s)
    return json.dumps(d, sort_keys=True)


def program(s: SerialSettings, dtype: Any) -> tuple[Mechanism, Callable]:
    """(the chain, the jitted block program ``run(params, X, pt, Rt, t0)``): values of
    designs X (:data:`DESIGNS`, V) (the variables, config units) at one chunk of targets,
    each (A·DESIGNS, C, ...) (``taskindex.chunk_values``). One per structure and dtype."""
    ck = (block_key(s), jnp.dtype(dtype).name)
    with _LOCK:  # one jitted function per structure, whichever thread asks first
        if ck not in _PROGRAMS:
            mech = build(s)
            while len(_PROGRAMS) >= 8:
                _PROGRAMS.pop(next(iter(_PROGRAMS)))

            def run(p, X, pt, Rt, t0):
                full = taskindex.design_full(p, X, dtype)
                return taskindex.setup_values(mech, s, p, full, pt, Rt, t0, dtype)

            # XLA:CPU's code generator as the config names it (indices.emitters)
            opts = xlaoptions.options(s.indices.emitters) or None
            _PROGRAMS[ck] = (mech, jax.jit(run, compiler_options=opts))
        return _PROGRAMS[ck]


def values(s: SerialSettings, dtype: Any) -> Callable[[dict[str, Any], Any], list[dict]]:
    """``Staged.values`` of the task: ``fn(params, X)`` for X (:data:`DESIGNS`, V) gives
    the block program's values of every chunk of the targets in ``params`` (a list, one
    dict per chunk; :func:`assembled` puts them together)."""

    key = f"{block_key(s)}\n{jnp.dtype(dtype).name}"
    A = 1 if s.arms is None else len(s.arms)

    def fn(params: dict[str, Any], X: Any) -> list[dict]:
        _, run = program(s, dtype)
        p = {k: v for k, v in params.items() if k not in NOT_READ}
        pc, Rc, t0 = taskindex.chunked_targets(params, taskindex.chunk(s), dtype, np)
        Xh = np.asarray(X)
        X = jnp.asarray(X)
        args = [(p, X, pc[i], None if Rc is None else Rc[i], t0[i]) for i in range(len(t0))]
        opts = xlaoptions.options(s.indices.emitters)
        call = exported.compiled(key, run, args[0], opts)  # a warm run loads, not traces, it
        scene = _digest(key, p)
        where = [_digest(scene, pc[i], None if Rc is None else Rc[i], t0[i])
                 for i in range(len(t0))]  # fmt: skip

        def one(i: int) -> dict:  # a chunk: from the rows of earlier calls, or computed
            got = _MEMO.get(where[i], Xh, A)
            if got is None:
                got = {k: np.asarray(v) for k, v in call(*args[i]).items()}
                _MEMO.put(where[i], Xh, A, got)
            return got

        # the chunks side by side on the CPU's cores (designopt.core.concurrency)
        return concurrency.map_calls([functools.partial(one, i) for i in range(len(t0))],
                                     key=(key, exported.signature(key, args[0])))  # fmt: skip

    return fn


def least(s: SerialSettings) -> Callable[[dict[str, Any]], dict[str, Any]]:
    """``Staged.least`` of the task: params with only the first chunk of targets, so a
    call of :func:`values` made to compile the block program runs it once."""
    C = taskindex.chunk(s)

    def fn(params: dict[str, Any]) -> dict[str, Any]:
        return params | {k: params[k][:C] for k in ("target_p", "target_R") if k in params}

    return fn


def _digest(*parts: Any) -> str:
    """A digest of arrays, pytrees of them (a PRNG key: its data) and text."""
    h = hashlib.blake2b(digest_size=16)
    for leaf in jax.tree_util.tree_leaves(parts):
        if isinstance(leaf, str):
            h.update(leaf.encode())
            continue
        if jax.dtypes.issubdtype(getattr(leaf, "dtype", None), jax.dtypes.prng_key):
            leaf = jax.random.key_data(leaf)
        a = np.asarray(leaf)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


class _Rows:
    """The block program's values of recent designs, row by row: (the call's digest: the
    program, its params, the chunk of targets; the design's bytes) → that design's rows
    (A, C, ...) of every output. A design's values depend on nothing else in its block,
    so a call whose designs were all computed before, by calls on the same targets and
    params, is answered from here: within a front run, its re-scoring, its ``targets``
    group and the figures' poses ask for the same designs on the same targets. At most
    ``limit`` bytes: the oldest rows go first."""

    def __init__(self, limit: int) -> None:
        self.limit, self.size, self.lock = limit, 0, threading.Lock()
        self.data: collections.OrderedDict[tuple[str, bytes], dict[str, np.ndarray]] = \
            collections.OrderedDict()  # fmt: skip

    def get(self, where: str, X: np.ndarray, A: int) -> dict[str, np.ndarray] | None:
        with self.lock:
            got = [self.data.get((where, x.tobytes())) for x in X]
            if any(g is None for g in got):
                return None
            for x in X:
                self.data.move_to_end((where, x.tobytes()))
        M = len(X)  # rows a·M + d (arm a, design d)
        return {k: np.stack([got[d][k][a] for a in range(A) for d in range(M)])
                for k in got[0]}  # fmt: skip

    def clear(self) -> None:
        with self.lock:
            self.data.clear()
            self.size = 0

    def put(self, where: str, X: np.ndarray, A: int, out: dict[str, np.ndarray]) -> None:
        M = len(X)
        with self.lock:
            for d, x in enumerate(X):
                row = {k: v[[a * M + d for a in range(A)]] for k, v in out.items()}
                old = self.data.pop((where, x.tobytes()), None)
                self.size += sum(v.nbytes for v in row.values()) - \
                    (0 if old is None else sum(v.nbytes for v in old.values()))  # fmt: skip
                self.data[(where, x.tobytes())] = row
            while self.size > self.limit and self.data:
                _, gone = self.data.popitem(last=False)
                self.size -= sum(v.nbytes for v in gone.values())


_MEMO = _Rows(128 * 2**20)
"""The rows of recent block calls, at most 128 MiB (:class:`_Rows`)."""


def assembled(s: SerialSettings, chunks: list[dict[str, Any]], M: int, N: int, xp: Any = jnp
              ) -> dict[str, Any]:  # fmt: skip
    """:func:`values`' chunks as ``taskindex.per_target`` gives them: (A, M, N, ...)
    (``xp``: jnp in a trace, np on the host)."""
    stacked = {k: xp.stack([c[k] for c in chunks]) for k in chunks[0]}
    return taskindex.assemble(stacked, len(s.arms) if s.arms is not None else 1, M, N, xp)


def host_params(s: SerialSettings, keys: Any, dtype: Any) -> tuple[Mechanism, dict[str, Any]]:
    """(the chain, the block program's ``params`` for a run's named streams ``keys``),
    made as ``objective.problem`` makes them: the targets drawn outside the program
    (inside, XLA may fuse their arithmetic differently, and a target an ulp away can send
    the IK to another of its solutions)."""
    from designopt.studies.serial import bodies

    mech, _ = program(s, dtype)
    dt = np.dtype(jnp.dtype(dtype))
    p = {"fixed": jnp.asarray(np.asarray(mech.fixed, dt)),
         "scale": jnp.asarray(np.asarray(mech.scale, dt)),
         "q_lower": jnp.asarray(np.asarray(mech.lower, dt)),
         "q_upper": jnp.asarray(np.asarray(mech.upper, dt)),
         "sample_key": keys["samples"]} | taskindex.targets(s, keys["samples"], dtype)  # fmt: skip
    return mech, (p | bodies.base_params(s, mech, dtype) | taskindex.scene_params(s, dtype, mech)
                  | taskindex.group_params(s, dtype))  # fmt: skip


def solution(s: SerialSettings, x: Any, keys: Any, dtype: Any = jnp.float64,
             ik_key: Any = None, first: int | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """The per-target solution of one design on a run's targets, as NumPy: ``target_p``
    (N, 3) (``target_R`` (N, 3, 3) with a tool axis), ``success`` (N,) bool, ``inv_k``,
    ``manipulability``, ``joint_margin`` (0 where unreached), ``q`` (N, n), ``pos_err``,
    ``rot_err`` (with ``arms`` each (A, N, ...)). ``x`` holds the design variables in
    the config's units (a record's ``x``: a mapping or a sequence in ``s.variables``
    order), ``keys`` the run's named streams (``record.keys()``): the targets and the
    IK's seeds are those of the run, so the means of these values are the run's final
    indices (figures and the report's cloud read it). It runs the run's own compiled
    block program (:func:`program`), the design in every row of the block. ``ik_key``:
    another key for the IK's seeds (the same targets, an independent set of seeds:
    :func:`coverage`); ``first``: only the first that many targets."""

    xv = np.asarray([x[k] for k in s.variables] if hasattr(x, "keys") else x, np.float64)
    return design_of(s, solutions(s, xv[None], keys, dtype, ik_key=ik_key, first=first), 0)


def design_of(s: SerialSettings, per: dict[str, np.ndarray], i: int) -> dict[str, np.ndarray]:
    """Design i's :func:`solution` out of :func:`solutions`' arrays ``per``."""
    return {k: (v if k in ("target_p", "target_R") else v[0, i] if s.arms is None else v[:, i])
            for k, v in per.items()}  # fmt: skip


COVERAGE_STREAM = 0x434F5645  # "COVE"
COVERAGE_MIN = 64
COVERAGE_BETTER = 1e-3
COVERAGE_WARN = 0.02
"""The IK's coverage check (:func:`coverage`): at least :data:`COVERAGE_MIN` targets
solved again with an independent set of seeds (the key ``fold_in(sample key,
COVERAGE_STREAM)``); a target where that solve finds a solution better by more than
:data:`COVERAGE_BETTER` counts; a share above :data:`COVERAGE_WARN` is warned about."""


def solutions(s: SerialSettings, X: Any, keys: Any, dtype: Any = jnp.float64,
              ik_key: Any = None, first: int | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """:func:`solution` of several designs X (P, D) at once: each array (A, P, N, ...)
    (``target_p`` (N, 3)), from the block program in blocks of :data:`DESIGNS` designs
    (the last padded with its last design: one design fills its block; a design's values
    do not depend on the others of its block). ``ik_key``, ``first``: as
    :func:`solution`."""
    if jnp.dtype(dtype) == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError("the task's inverse kinematics needs float64: call "
                         "jax.config.update('jax_enable_x64', True) first")  # fmt: skip
    X = np.atleast_2d(np.asarray(X, np.float64))
    _, p = host_params(s, keys, dtype)
    if ik_key is not None:  # the IK's seeds come from the sample key (taskindex.chunk_values)
        p["sample_key"] = ik_key
    if first is not None:
        p = p | {k: p[k][:first] for k in ("target_p", "target_R") if k in p}
    dt = np.dtype(jnp.dtype(dtype))
    B, P, N = DESIGNS, len(X), p["target_p"].shape[0]
    pad = np.concatenate([X, np.repeat(X[-1:], -P % B, 0)]).astype(dt)
    run = values(s, dtype)

    def one(b: int) -> dict[str, np.ndarray]:  # one block program call per 16 designs
        chunks = [{k: np.asarray(v) for k, v in c.items()} for c in run(p, pad[b : b + B])]
        return assembled(s, chunks, B, N, np)

    parts = concurrency.map_calls([functools.partial(one, b) for b in range(0, len(pad), B)],
                                  key=("solutions", block_key(s), str(dt), N))  # fmt: skip
    out = {k: np.concatenate([q[k] for q in parts], 1)[:, :P] for k in parts[0]}
    out["success"] = out["success"] > 0.5
    return out | {k: np.asarray(p[k]) for k in ("target_p", "target_R") if k in p}


def coverage(s: SerialSettings, X: Any, keys: Any, sol: dict[str, np.ndarray],
             dtype: Any = jnp.float64) -> dict[str, Any]:  # fmt: skip
    """How often the IK's kept solution is not the best it could have kept: the run's
    first chunk of targets (at least :data:`COVERAGE_MIN`, at most the task's) solved
    again for the designs ``X`` (P, D) with an independent set of seeds, all designs in
    one batched solve (:func:`solutions`), and compared target by target (and arm by
    arm) with the run's own solutions ``sol`` (:func:`solutions`: (A, P, N, ...)) by the
    score the IK maximises (``study.task.ik.best``: 1/k, or the clearance): per design,
    the share of those targets where the second solve is better by more than
    :data:`COVERAGE_BETTER` (or reaches a target the first did not). {"ik_better": the
    shares (P,), "ik_better_n": targets compared per design (× arms)}."""
    N = int(np.asarray(sol["target_p"]).shape[0])
    K = min(N, max(COVERAGE_MIN, taskindex.chunk(s)))
    key = jax.random.fold_in(keys["samples"], COVERAGE_STREAM)
    alt = solutions(s, X, keys, dtype, ik_key=key, first=K)
    name = "clearance" if s.task.ik.best == "clearance" else "inv_k"  # type: ignore[union-attr]
    a_ok, b_ok = np.asarray(alt["success"]), np.asarray(sol["success"])[..., :K]
    a_v, b_v = np.asarray(alt[name], np.float64), np.asarray(sol[name], np.float64)[..., :K]
    better = a_ok & (~b_ok | (a_v > b_v + COVERAGE_BETTER))  # (A, P, K)
    shares = np.mean(np.moveaxis(better, 1, 0).reshape(better.shape[1], -1), -1)
    return {"ik_better": shares, "ik_better_n": float(better.shape[0] * better.shape[2])}


def coverage_lines(s: SerialSettings, cov: dict[str, float]) -> tuple[list[str], list[str]]:
    """(summary lines, ``warning:`` lines) of a coverage figure (:func:`coverage`): the
    share is always said; above :data:`COVERAGE_WARN` a warning says to raise the
    seeds (``study.task.ik.n_best``, ``n_nearest``, ``climb``)."""
    share, n = 100.0 * cov["ik_better"], int(cov["ik_better_n"])
    A = 1 if s.arms is None else len(s.arms)
    of = f"{n} targets" if A == 1 else f"{n // A} targets × {A} arms"
    score = (f"clearance higher by > {COVERAGE_BETTER:g} {length_unit(s)}"
             if s.task.ik.best == "clearance"  # type: ignore[union-attr]
             else f"1/k higher by > {COVERAGE_BETTER:g}")  # fmt: skip
    line = (f"IK coverage: a second, independent set of seeds finds a better solution "
            f"({score}) at {share:.1f} % of {of}")
    if cov["ik_better"] <= COVERAGE_WARN:
        return [line], []
    ik = s.task.ik  # type: ignore[union-attr]
    warn = (f"IK coverage: a second set of seeds finds a better solution at {share:.1f} % "
            f"of {of} (more than {100 * COVERAGE_WARN:g} %): the indices are read "
            f"at solutions that are not the best; raise study.task.ik.n_best (now "
            f"{ik.n_best}), n_nearest (now {ik.n_nearest}) or climb (now {ik.climb})")
    return [line], [warn]
