"""Run any registered optimizer on any Problem: all runs as one vmap over keys, iterations as
a chunked ``lax.scan``, and (``run_batch``) a second vmap over a list of settings.

The runner sees only the protocol (protocol.py): ``init``/``step``/``best`` and opaque
state pytrees. It owns each run's PRNG key (split once per iteration, the second half is
the step's key), records the best-so-far value, design and violation after every
iteration, and hands the host a :class:`Checkpoint` between chunks, and after the last
one with ``checkpoint_at_end`` (progress bar, stops at an iteration boundary, resuming
after the loop). A checkpoint's ``state`` is a flat dict of numpy arrays named by the
state pytree's paths; resuming from it gives bit-for-bit the uninterrupted run.

A multi-objective entry (``multi_objective``, e.g. NSGA-II) runs on a problem with
``n_objectives`` > 1 through the same functions. Its per-iteration record is a
hypervolume against one reference point (given as ``ref_point``, else the componentwise
maximum of the first generation's feasible objective values over all runs): that of the
entry's archive (``archive(state) -> (Front, pruned)``: the non-dominated set of every
feasible point evaluated so far) where it keeps one, so that the history is the
convergence of the best front found so far and never decreases (an archive cut for room
can lose volume: then the larger of its and the population's hypervolume, and a running
maximum on top, a lower bound of the union's), else that of the population; the
hypervolume of each run's feasible population is recorded beside it
(``RunResult.history_population``). The result adds the final populations
(``RunResult.front``), archives (``RunResult.archive``) and the reference point
(``RunResult.ref_point``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from designopt.core import concurrency
from designopt.numerics.pareto import hypervolume_jax
from designopt.optim import registry
from designopt.optim.protocol import Front, Optimizer, Task, clean
from designopt.problems.base import Problem, evaluate_batch, scored
from designopt.problems.evaluate import staged_scores

CONVERGENCE_TOL = 1e-6


class RunResult(NamedTuple):
    """Per run (and member). For a multi-objective entry ``history`` is the hypervolume
    after each iteration against ``ref_point`` of the non-dominated set of every feasible
    point evaluated so far (the entry's archive; exact while ``archive_pruned`` is 0, a
    lower bound after; never decreasing), or of the feasible population for an entry
    without an archive (larger is better; NaN for more than 3 objectives: use
    ``designopt.numerics.pareto.hypervolume`` on ``front``), ``history_population`` the
    hypervolume of the feasible population, ``best_f`` the final hypervolume,
    ``converged_at`` the iteration after which it never grows by > tol,
    ``history_v``/``best_v`` the least violation in the population, ``history_x``/``best_x``
    empty (last axis 0), ``front`` the final populations and ``archive`` the final
    archives (empty slots: v = +inf)."""

    history: np.ndarray  # ([B,] n_runs, n_iters + 1) best-so-far value (MO: hypervolume)
    best_f: np.ndarray  # ([B,] n_runs)
    best_x: np.ndarray  # ([B,] n_runs, D)
    converged_at: np.ndarray  # ([B,] n_runs) iteration after which no improvement > tol
    history_x: np.ndarray  # ([B,] n_runs, n_iters + 1, D) best-so-far design
    settings: dict[str, Any]
    history_v: np.ndarray | None = None  # ([B,] n_runs, n_iters + 1) its constraint violation
    best_v: np.ndarray | None = None  # ([B,] n_runs) 0 = feasible
    front: Front | None = None  # MO: x ([B,] n_runs, P, D), f (…, P, m), v (…, P), rank (…, P)
    ref_point: np.ndarray | None = None  # MO: (m,) the hypervolume's reference point
    history_population: np.ndarray | None = None  # MO: ([B,] n_runs, n_iters + 1)
    archive: Front | None = None  # MO with an archive: x ([B,] n_runs, K, D), f, v, rank
    archive_pruned: np.ndarray | None = None  # ([B,] n_runs) points cut from it for room
    eval_shape: tuple[int, int] | None = None
    """(groups, rows) of the separate objective program's calls (``separate``), which
    ``designopt.problems.evaluate.score`` reuses; None when the objective ran inside the steps."""

    def member(self, j: int) -> RunResult:
        """Member ``j`` of a batched result (``run_batch``, a sweep): every array sliced on
        its leading member axis, the settings that vary per member picked."""
        sets = {a: (b[j] if isinstance(b, list) else b) for a, b in self.settings.items()}
        sliced = {k: (None if v is None else jax.tree.map(lambda a: a[j], v))
                  for k, v in self._asdict().items() if k not in ("settings", "ref_point", "eval_shape")}  # fmt: skip
        return self._replace(**sliced, settings=sets)


class Checkpoint(NamedTuple):
    """Everything needed to continue a run bit-for-bit: the optimizer state and run keys
    as a flat dict of numpy arrays (keys as raw key data), the histories so far and the
    iterations done."""

    state: dict[str, np.ndarray]
    history: np.ndarray
    history_x: np.ndarray
    done: int


def convergence_iteration(history: np.ndarray, tol: float = CONVERGENCE_TOL) -> np.ndarray:
    """SPEC §3.3: the iteration after which the best value never again improves by > tol."""
    h = np.asarray(history)
    with np.errstate(invalid="ignore"):
        gain = h[..., :-1] - h[..., 1:]
    gain = np.where(np.isfinite(gain), gain, np.inf)  # leaving +inf is an improvement
    big = gain > tol
    T = h.shape[-1] - 1
    last = T - np.argmax(big[..., ::-1], axis=-1)  # 1-based index of the last big gain
    return np.where(big.any(-1), last, 0)


def _over_runs(f, batched: bool):
    """vmap f(run_input, params) over runs, and over settings too when ``batched``."""
    runs = lambda S, p: jax.vmap(lambda s: f(s, p))(S)  # noqa: E731
    return jax.vmap(runs) if batched else runs


def _task(fn, cons, pparams, lower, upper) -> Task:
    def evaluate(X, key):
        f, _, v = scored(fn, cons, pparams, X, key)
        return clean(f).astype(X.dtype), v

    return Task(evaluate, lower, upper)


@partial(jax.jit, static_argnames=("opt", "fn", "cons", "batched"))
def _init(keys, params, pparams, lower, upper, opt, fn, cons, batched=False):
    task = _task(fn, cons, pparams, lower, upper)

    def one(key, p):
        k0, k1 = jax.random.split(key)
        return k1, opt.init(k0, p, task)

    return _over_runs(one, batched)(keys, params)


def _archive(opt: Optimizer, state) -> tuple[Front, jax.Array] | None:
    """A multi-objective entry's archive (Front, points pruned), None if it keeps none."""
    get = getattr(opt, "archive", None)
    return None if get is None else get(state)


HV_EVERY = 10
"""A multi-objective run measures its hypervolumes (the archive's and the population's)
at every HV_EVERY-th iteration and at the last one; the iterations between hold the
last value measured (the 3-objective hypervolume is O(n²) in the archive's size: every
iteration, it took over half of a DTLZ2 run). The search and its fronts are the same."""


def _hv_due(i: jax.Array | int, n_iters: jax.Array | int) -> jax.Array:
    """Whether iteration ``i`` (from 1) of ``n_iters`` measures the hypervolume."""
    return (i % HV_EVERY == 0) | (i >= n_iters)


def _track(opt: Optimizer, state, ref, due: jax.Array | bool = True) -> tuple[jax.Array, ...]:
    """What the runner keeps per iteration: the best so far (x, f, v), or for a
    multi-objective entry (an empty x, the hypervolume of the archive (else of the
    feasible population), the least violation, the feasible population's hypervolume);
    the hypervolumes NaN where ``due`` is false (:data:`HV_EVERY`; the host fills them
    with the last measured value, :func:`_fill`)."""
    if not opt.multi_objective:
        return tuple(opt.best(state))
    fr = opt.front(state)
    arch = _archive(opt, state)

    def measure(_):
        hv_pop = hypervolume_jax(fr.f, ref, fr.v == 0).astype(fr.x.dtype)
        hv = hv_pop
        if arch is not None:  # a cut archive may have lost volume the population still holds
            hv = jnp.maximum(hypervolume_jax(arch[0].f, ref, arch[0].v == 0).astype(hv.dtype),
                             hv)  # fmt: skip
        return hv, hv_pop

    if due is True:
        hv, hv_pop = measure(None)
    else:  # an unbatched predicate: a real branch, the O(n²) volume skipped
        nan = jnp.full((), jnp.nan, fr.x.dtype)
        hv, hv_pop = jax.lax.cond(due, measure, lambda _: (nan, nan), None)
    return jnp.zeros((0,), fr.x.dtype), hv, jnp.min(fr.v), hv_pop


def _fill(a: np.ndarray) -> np.ndarray:
    """NaN entries along the last axis (iterations) replaced by the last value before
    them (the hypervolumes measured every :data:`HV_EVERY` iterations); leading NaN (and
    a history of NaN: more than 3 objectives) kept."""
    a = np.asarray(a)
    idx = np.where(np.isnan(a), 0, np.arange(a.shape[-1]))
    np.maximum.accumulate(idx, axis=-1, out=idx)
    out = np.take_along_axis(a, idx, axis=-1)
    return out


def _pack(track: tuple[jax.Array, ...]) -> jax.Array:
    """One iteration's records (``_track``: x (…, D), then scalars of x's dtype) as one row
    (…, D + k): the scan writes one history buffer per iteration instead of one per
    record (a GPU launches one in-place update instead of three or four) and the host
    reads one array per chunk. :func:`_unpack` splits it; the values are only copied."""
    x, *rest = track
    if any(r.dtype != x.dtype for r in rest):  # never promote: the history keeps its dtypes
        raise TypeError(f"records of dtypes {[str(a.dtype) for a in track]}: expected one")
    return jnp.concatenate([x, *(r[..., None] for r in rest)], axis=-1)


def _unpack(rows: np.ndarray, k: int) -> list[np.ndarray]:
    """``_pack``'s rows (…, D + k) back into x (…, D) and the k scalar records."""
    D = rows.shape[-1] - k
    return [rows[..., :D], *(rows[..., D + i] for i in range(k))]


@partial(jax.jit, static_argnames=("opt", "fn", "cons", "length", "batched"))
def _advance(carry, params, pparams, lower, upper, opt, fn, cons, length, batched=False, ref=None,
             done=0, n_iters=0):  # fmt: skip
    """``length`` iterations of every run; ``done`` of ``n_iters`` before them (traced:
    where a chunk starts compiles nothing new; they time the hypervolume, ``_hv_due``)."""
    task = _task(fn, cons, pparams, lower, upper)

    def one(c, p):
        def body(c, i):
            key, state = c
            key, k = jax.random.split(key)
            state = opt.step(k, state, p, task)
            return (key, state), _pack(_track(opt, state, ref, _hv_due(i, n_iters)))

        return jax.lax.scan(body, c, done + 1 + jnp.arange(length))

    return _over_runs(one, batched)(carry, params)


def _flat(X, ek, rows: int):
    """Candidates (…runs, N, D) and their keys (…runs,) as the objective program's groups:
    X (R, rows, D) with each group padded by repeating its last row, keys (R,)."""
    N, D = X.shape[-2:]
    Xf = X.reshape((-1, N, D))
    if N < rows:
        Xf = jnp.concatenate([Xf, jnp.repeat(Xf[:, -1:], rows - N, axis=1)], axis=1)
    # the run axes flattened; a raw uint32 key (…runs, 2) keeps its last axis
    return Xf, ek.reshape((Xf.shape[0],) + ek.shape[X.ndim - 2 :])


def _unflat(a, X):
    """The objective's output a (R, rows[, m]) back to X's run axes and N candidates."""
    lead, N = X.shape[:-2], X.shape[-2]
    return a.reshape(lead + a.shape[1:])[(slice(None),) * len(lead) + (slice(0, N),)]


@partial(jax.jit, static_argnames=("opt", "batched", "rows"))
def _init_ask(keys, params, lower, upper, opt, batched=False, rows=1):
    """Separate objective: the first candidates of every run (``init`` up to evaluate)."""
    task = Task(None, lower, upper)

    def one(key, p):
        k0, k1 = jax.random.split(key)
        X, pending = opt.init_ask(k0, p, task)
        return k1, k0, X, opt.eval_key(k0), pending

    keys, k0, X, ek, pending = _over_runs(one, batched)(keys, params)
    return keys, k0, X, pending, *_flat(X, ek, rows)


@partial(jax.jit, static_argnames=("opt", "batched"))
def _init_tell(keys, k0, X, pending, f, v, params, lower, upper, opt, batched=False):
    task = Task(None, lower, upper)

    def one(run, p):
        key, k, x, pend, fr, vr = run
        return key, opt.init_tell(k, x, pend, clean(fr).astype(x.dtype), vr, p, task)

    f, v = _unflat(f, X), _unflat(v, X)
    return _over_runs(one, batched)((keys, k0, X, pending, f, v), params)


@partial(jax.jit, static_argnames=("opt", "batched", "rows"))
def _ask(carry, params, lower, upper, opt, batched=False, rows=1):
    """Separate objective: one iteration's candidates of every run (``step`` up to
    evaluate), the run keys advanced as ``_advance`` does."""
    task = Task(None, lower, upper)

    def one(c, p):
        key, state = c
        key, k = jax.random.split(key)
        X, pending = opt.ask(k, state, p, task)
        return key, k, X, opt.eval_key(k), pending

    keys, k, X, ek, pending = _over_runs(one, batched)(carry, params)
    return keys, k, X, pending, *_flat(X, ek, rows)


@partial(jax.jit, static_argnames=("opt", "batched"))
def _tell(carry, k, X, pending, f, v, params, lower, upper, opt, batched=False, ref=None,
          due=True):  # fmt: skip
    task = Task(None, lower, upper)
    due = jnp.asarray(due)

    def one(run, p):
        (key, state), kr, x, pend, fr, vr = run
        state = opt.tell(kr, state, x, pend, clean(fr).astype(x.dtype), vr, p, task)
        return (key, state), _pack(_track(opt, state, ref, due))

    f, v = _unflat(f, X), _unflat(v, X)
    return _over_runs(one, batched)((carry, k, X, pending, f, v), params)


def _template(keys, params, lower, upper, opt, batched, rows, m, dtype):
    """The first state's shapes without tracing the objective (resuming a separate run)."""
    keys1, k0, X, pending, Xf, _ = _init_ask(keys, params, lower, upper, opt=opt,
                                             batched=batched, rows=rows)  # fmt: skip
    f = jnp.zeros(Xf.shape[:2] + ((m,) if m > 1 else ()), dtype)
    v = jnp.zeros(Xf.shape[:2], dtype)
    return _init_tell(keys1, k0, X, pending, f, v, params, lower, upper, opt=opt, batched=batched)


@partial(jax.jit, static_argnames=("opt", "batched"))
def _records(carry, ref, opt, batched):
    f = lambda c, _: _track(opt, c[1], ref)  # noqa: E731
    return _over_runs(f, batched)(carry, None)


@partial(jax.jit, static_argnames=("opt", "batched"))
def _fronts(carry, opt, batched) -> Front:
    f = lambda c, _: tuple(opt.front(c[1]))  # noqa: E731
    return Front(*_over_runs(f, batched)(carry, None))


@partial(jax.jit, static_argnames=("opt", "batched"))
def _archives(carry, opt, batched) -> tuple[Front, jax.Array]:
    def f(c, _):
        fr, pruned = _archive(opt, c[1])
        return tuple(fr), pruned

    fr, pruned = _over_runs(f, batched)(carry, None)
    return Front(*fr), pruned


def first_nadir(f: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The default reference point: per objective the largest finite value among the
    feasible points of f (…, P, m) (among all points when none is feasible)."""
    f = np.asarray(f, np.float64)
    m = f.shape[-1]
    f2, v2 = f.reshape(-1, m), np.asarray(v).reshape(-1)
    ok = np.all(np.isfinite(f2), axis=1)
    pick = ok & (v2 == 0) if np.any(ok & (v2 == 0)) else ok
    if not np.any(pick):
        raise ValueError("no finite objective values in the first generation: no reference point")
    return f2[pick].max(axis=0)


def _path_name(path) -> str:
    parts = []
    for k in path:
        parts.append(str(getattr(k, "name", getattr(k, "key", getattr(k, "idx", k)))))
    return ".".join(parts)


def _is_key(x) -> bool:
    return jnp.issubdtype(x.dtype, jax.dtypes.prng_key)


def _to_numpy(carry, host: Callable[[Any], np.ndarray] = np.asarray) -> dict[str, np.ndarray]:
    leaves, _ = jax.tree_util.tree_flatten_with_path(carry)
    return {_path_name(p): host(jax.random.key_data(v) if _is_key(v) else v) for p, v in leaves}


def _from_numpy(d: dict[str, np.ndarray], template) -> Any:
    leaves, tree = jax.tree_util.tree_flatten_with_path(template)
    out = []
    for p, t in leaves:
        name = _path_name(p)
        if name not in d:
            raise ValueError(f"checkpoint lacks state entry {name!r} (another optimizer?)")
        a = jnp.asarray(d[name])
        if _is_key(t):
            a = jax.random.wrap_key_data(a)
        if a.shape != t.shape or a.dtype != t.dtype:
            raise ValueError(f"checkpoint entry {name!r} does not match this run's shape/dtype")
        out.append(a)
    return jax.tree_util.tree_unflatten(tree, out)


def _drive(name, opt, params, problem, key, n_runs, dtype, chunk_iters, progress, checkpoint,
           resume, batched, B, record, at_end=False, plan=None, ref_point=None,
           separate=False):  # fmt: skip
    n_iters = opt.n_iters
    separate = separate and opt.asks()
    rows = opt.n  # candidates per run in each call of the separate objective
    lower = jnp.asarray(problem.lower, dtype)
    upper = jnp.asarray(problem.upper, dtype)
    keys = jax.random.split(key, n_runs)
    if batched:
        keys = jnp.broadcast_to(keys, (B, n_runs))  # common random numbers across settings
    pparams = problem.params
    # a Plan (designopt.core.devices) places every input on its device mesh; None: as ever
    place = (lambda t: t) if plan is None else plan.put  # noqa: E731
    host = np.asarray if plan is None else plan.host
    if plan is not None:
        keys, params, pparams, lower, upper = plan.put((keys, params, pparams, lower, upper))
    statics = dict(opt=opt, fn=problem.fn, cons=problem.constraints, batched=batched)
    mo = opt.multi_objective
    ref = None if ref_point is None else jnp.asarray(ref_point, dtype)

    def objective(Xf, ek):  # the separate objective program: (f, v) of every group
        if problem.staged is not None and plan is None:  # the study's fixed-shape programs
            R, N, D = Xf.shape
            f, _, v = staged_scores(problem, np.asarray(Xf).reshape(R * N, D), pparams)
            return (jnp.asarray(f.reshape((R, N) + f.shape[1:])),
                    jnp.asarray(v.reshape(R, N), f.dtype))  # fmt: skip
        f, _, v = evaluate_batch(pparams, Xf, ek, fn=problem.fn, constraints=problem.constraints)
        return f, v

    def steps(keys1, k0, X, pending, Xf) -> Callable[[], None]:
        """The step programs (tell, ask, the records), compiled while the first objective
        call runs (its own compile, the IK's, takes longer): each called once on zeros of
        the objective's shapes, so the loop's first calls find them; the values are
        dropped (:func:`designopt.core.concurrency.in_background`)."""

        def warm() -> None:
            m = problem.n_objectives
            f = jnp.zeros(Xf.shape[:2] + ((m,) if m > 1 else ()), dtype)
            v = jnp.zeros(Xf.shape[:2], dtype)
            c = _init_tell(keys1, k0, X, pending, f, v, params, lower, upper, opt=opt,
                           batched=batched)  # fmt: skip
            r = ref if ref is not None or not mo else jnp.zeros((m,), dtype)
            if mo and ref is None:
                _fronts(c, opt, batched)
            _records(c, r, opt, batched)
            if concurrency.ended():
                return
            k1, k, X1, pend1, _, _ = _ask(c, params, lower, upper, opt=opt, batched=batched,
                                          rows=rows)  # fmt: skip
            jax.block_until_ready(_tell((k1, c[1]), k, X1, pend1, f, v, params, lower, upper,
                                        opt=opt, batched=batched, ref=r, due=np.bool_(True)))  # fmt: skip

        return warm

    if resume is None:
        if separate:
            keys1, k0, X, pending, Xf, ek = _init_ask(keys, params, lower, upper, opt=opt,
                                                      batched=batched, rows=rows)  # fmt: skip
            with concurrency.in_background(steps(keys1, k0, X, pending, Xf)
                                           if problem.staged is not None and plan is None
                                           else None):  # fmt: skip
                fv = objective(Xf, ek)
            carry = place(_init_tell(keys1, k0, X, pending, *fv, params, lower, upper, opt=opt,
                                     batched=batched))  # fmt: skip
        else:
            carry = place(_init(keys, params, pparams, lower, upper, **statics))
        if mo and ref is None:
            fr = _fronts(carry, opt, batched)
            ref = jnp.asarray(first_nadir(host(fr.f), host(fr.v)), dtype)
        if plan is not None and ref is not None:
            ref = plan.put(ref)
        bx, bf, bv, *bp = _records(carry, ref, opt, batched)
        hf, hx, hv = (
            [host(bf)[..., None]],
            [host(bx)[..., None, :]],
            [host(bv)[..., None]],
        )
        hp = [host(b)[..., None] for b in bp]  # MO: the population's hypervolume
        n_records = 2 + len(bp)  # f, v (MO: + the population's hypervolume) beside x
        done = 0
    else:
        template = jax.eval_shape(lambda: _template(keys, params, lower, upper, opt, batched,
                                                    rows, problem.n_objectives, dtype)
                                  if separate else _init(keys, params, pparams, lower, upper,
                                                         **statics))  # fmt: skip
        st = dict(resume.state)
        hv0 = st.pop("runner.history_v", None)
        hp0 = st.pop("runner.history_population", None)
        ref0 = st.pop("runner.ref_point", None)
        if mo:
            if ref0 is None:
                raise ValueError("checkpoint lacks the reference point (runner.ref_point)")
            if ref is not None and not np.array_equal(np.asarray(ref), np.asarray(ref0, dtype)):
                raise ValueError("ref_point differs from the checkpoint's reference point")
            ref = jnp.asarray(ref0, dtype) if plan is None else plan.put(jnp.asarray(ref0, dtype))
        carry = place(_from_numpy(st, template))
        done = resume.done
        hf, hx = [np.asarray(resume.history)], [np.asarray(resume.history_x)]
        hv = [np.zeros_like(hf[0]) if hv0 is None else np.asarray(hv0)]
        hp = [] if not mo else [np.full_like(hf[0], np.nan) if hp0 is None else np.asarray(hp0)]
        if hf[0].shape[-1] != done + 1:
            raise ValueError("checkpoint history does not match its iteration count")
        if progress is not None:
            progress(done)
        n_records = 3 if mo else 2
    chunk = n_iters if chunk_iters is None else max(1, min(chunk_iters, n_iters))
    while done < n_iters:
        length = min(chunk, n_iters - done)
        if separate:  # ask, the objective program, tell: one iteration at a time
            tracks = []  # on the device until the chunk ends: no host sync per iteration
            for j in range(length):
                keys1, k, X, pending, Xf, ek = _ask(carry, params, lower, upper, opt=opt,
                                                    batched=batched, rows=rows)  # fmt: skip
                due = np.bool_(bool(_hv_due(done + 1 + j, n_iters)))
                carry, tr = _tell((keys1, carry[1]), k, X, pending, *objective(Xf, ek), params,
                                  lower, upper, opt=opt, batched=batched, ref=ref, due=due)  # fmt: skip
                carry = place(carry)  # the same placement every iteration: one program
                tracks.append(tr)
            axis = 2 if batched else 1  # (…runs, iterations, …) as _advance's scan gives
            recs = np.stack([host(t) for t in tracks], axis=axis)
        else:
            carry, recs = _advance(
                carry, params, pparams, lower, upper, length=length, ref=ref,
                done=np.int32(done), n_iters=np.int32(n_iters), **statics
            )
            recs = host(recs)
        x, f, v, *p = _unpack(recs, n_records)
        if plan is not None:
            carry = place(carry)  # the same placement every chunk: one compiled program
        hf.append(f)
        hx.append(x)
        hv.append(v)
        hp += p
        done += length
        if progress is not None:
            progress(length)
        if checkpoint is not None and (done < n_iters or at_end):
            hf = [np.concatenate(hf, axis=-1)]
            hx = [np.concatenate(hx, axis=-2)]
            hv = [np.concatenate(hv, axis=-1)]
            state = _to_numpy(carry, host) | {"runner.history_v": hv[0]}
            if mo:
                hp = [np.concatenate(hp, axis=-1)]
                state["runner.ref_point"] = host(ref)
                state["runner.history_population"] = hp[0]
            checkpoint(Checkpoint(state, hf[0], hx[0], done))
    history = np.concatenate(hf, axis=-1)
    if mo:  # the hypervolumes between two measured iterations (HV_EVERY) hold the last
        history = _fill(history)
        hp = [_fill(np.concatenate(hp, axis=-1))]
    history_x = np.concatenate(hx, axis=-2)
    history_v = np.concatenate(hv, axis=-1)
    front = Front(*(host(a) for a in _fronts(carry, opt, batched))) if mo else None
    arch, pruned = None, None
    if mo and getattr(opt, "archive", None) is not None:
        fa, pa = _archives(carry, opt, batched)
        arch, pruned = Front(*(host(a) for a in fa)), host(pa)
        with np.errstate(invalid="ignore"):  # NaN (m > 3) stays NaN
            history = np.maximum.accumulate(history, axis=-1)  # a cut archive can lose volume
    return RunResult(
        history=history,
        best_f=history[..., -1],
        best_x=history_x[..., -1, :],
        converged_at=convergence_iteration(-history if mo else history),
        history_x=history_x,
        settings=record | ({"ref_point": tuple(host(ref).tolist())} if mo else {}),
        history_v=history_v,
        best_v=history_v[..., -1],
        front=front,
        ref_point=host(ref) if mo else None,
        history_population=np.concatenate(hp, axis=-1) if mo else None,
        archive=arch,
        archive_pruned=pruned,
        eval_shape=(int(np.prod(keys.shape[: 2 if batched else 1])), rows) if separate else None,
    )


def _prepare(name, n_particles, n_iters, n_runs, bounds, settings_list, problem=None,
             ref_point=None):  # fmt: skip
    m = None if problem is None else int(problem.n_objectives)
    for s in settings_list:
        registry.validate(name, s, n_particles, n_objectives=m)
    if ref_point is not None:
        if not registry.resolve(name).cls.multi_objective:
            raise ValueError(f"ref_point is for multi-objective optimizers, not {name!r}")
        r = np.asarray(ref_point, np.float64)
        if r.ndim != 1 or (m is not None and r.shape[0] != m):
            raise ValueError(f"ref_point has {r.size} values, the problem has {m} objectives")
        if not np.all(np.isfinite(r)):
            raise ValueError("ref_point must be finite")
    if n_iters < 1 or n_runs < 1:
        raise ValueError("n_iters must be ≥ 1 and n_runs ≥ 1")
    opts = [registry.split_settings(name, s)[1] for s in settings_list]
    if any(o != opts[0] for o in opts):
        raise ValueError("the members of a batch must share their string options (e.g. draws)")
    return registry.build(name, n_particles, n_iters, bounds, **opts[0])


def _record(name, opt, params, n_runs) -> dict[str, Any]:
    e = registry.resolve(name)
    return {"optimizer": e.name, "name": name, "source": e.source, "n_runs": n_runs,
            **opt.describe(params)}  # fmt: skip


def run(
    name: str,
    problem: Problem,
    key: jax.Array,
    n_particles: int = 50,
    n_iters: int = 1000,
    n_runs: int = 100,
    bounds: str = "clip",
    dtype: Any = jnp.float64,
    chunk_iters: int | None = None,
    progress: Callable[[int], None] | None = None,
    checkpoint: Callable[[Checkpoint], None] | None = None,
    resume: Checkpoint | None = None,
    checkpoint_at_end: bool = False,
    plan: Any = None,
    ref_point: Sequence[float] | None = None,
    separate: bool = False,
    **settings: Any,
) -> RunResult:
    """Run ``n_runs`` independent runs of optimizer ``name`` (``registry.names()``) on
    ``problem`` with population ``n_particles``.

    ``settings`` override the optimizer's numeric ``Params`` (``setting_names(name)``) or
    set its string options (e.g. PSO's ``draws``). ``checkpoint`` is called between chunks
    of ``chunk_iters`` iterations (and after the last with ``checkpoint_at_end``) with a
    :class:`Checkpoint`; passing one back as ``resume`` continues the run and gives exactly
    the uninterrupted result. ``plan`` (``designopt.core.devices.plan``) shards the runs or
    particles over a device mesh: one compiled program, the same numbers.

    A multi-objective optimizer (``nsga2``) needs a problem with ``n_objectives`` > 1 and
    a single-objective one a problem with one objective (ValueError otherwise);
    ``ref_point`` (m,) is the hypervolume's reference point (default: the componentwise
    maximum of the first generation's feasible values, over all runs).

    ``separate``: evaluate the objective as a program of its own between each iteration's
    ask and tell (protocol.py) instead of inside the chunked scan: one compiled objective
    serves the first population, every iteration and the scoring after the run
    (``RunResult.eval_shape``), at the price of three calls per iteration: for expensive
    objectives (Monte-Carlo studies), where compiling the objective dominates. Ignored
    for an optimizer without ask/tell. Deterministic and resumable as the
    fused run, though not bitwise equal to it (XLA may fuse the objective differently).
    """
    opt = _prepare(name, n_particles, n_iters, n_runs, bounds, [settings], problem, ref_point)
    e = registry.resolve(name)
    params = e.cls.make_params(dtype, e.preset, **registry.split_settings(name, settings)[0])
    return _drive(name, opt, params, problem, key, n_runs, dtype, chunk_iters, progress,
                  checkpoint, resume, False, 1, _record(name, opt, params, n_runs),
                  checkpoint_at_end, plan, ref_point, separate)  # fmt: skip


def run_batch(
    name: str,
    problem: Problem,
    key: jax.Array,
    members: Sequence[dict[str, Any]],
    n_particles: int = 50,
    n_iters: int = 1000,
    n_runs: int = 100,
    bounds: str = "clip",
    dtype: Any = jnp.float64,
    chunk_iters: int | None = None,
    progress: Callable[[int], None] | None = None,
    checkpoint: Callable[[Checkpoint], None] | None = None,
    resume: Checkpoint | None = None,
    checkpoint_at_end: bool = False,
    plan: Any = None,
    ref_point: Sequence[float] | None = None,
    separate: bool = False,
) -> RunResult:
    """Run the optimizer once per settings dict in ``members``, all as one vmapped program.

    Every member uses the same run keys (common random numbers), so member i equals
    ``run(name, ..., **members[i])`` up to floating-point reassociation. Results carry a
    leading member axis. String options must be equal across members. A
    multi-objective optimizer's members share one reference point. ``separate`` as in
    :func:`run`.
    """
    if not members:
        raise ValueError("members must hold at least one settings dict")
    members = [dict(m) for m in members]
    opt = _prepare(name, n_particles, n_iters, n_runs, bounds, members, problem, ref_point)
    e = registry.resolve(name)
    plist = [
        e.cls.make_params(dtype, e.preset, **registry.split_settings(name, m)[0]) for m in members
    ]
    params = jax.tree.map(lambda *a: jnp.stack(a), *plist)
    return _drive(name, opt, params, problem, key, n_runs, dtype, chunk_iters, progress,
                  checkpoint, resume, True, len(members), _record(name, opt, params, n_runs),
                  checkpoint_at_end, plan, ref_point, separate)  # fmt: skip
