"""Batched inverse kinematics of the da Vinci patient-side arm (production solver).

A damped Newton / Levenberg-Marquardt iteration on the 6×6 system (position error in
units of a characteristic length ``L``, orientation error as a rotation vector), with:

- a fixed maximum iteration count and per-lane masks (a lane stops when it converges; a
  chunk of lanes stops when all of its lanes have);
- seeds from a database of FK samples on joint grids, nearest in pose space
  (:func:`build_database`, :func:`seed`): the arm's structure splits the pose into the
  wrist point (q1, q2, q3), the tool axis in frame 3 (q4, q5) and the jaw angle (q6), so
  three small brute-force nearest-neighbour searches replace one 6-D search that would
  need ~10¹² samples at the paper's 5° grid;
- joint limits by projection (q4, a full turn, wraps);
- among the converged solutions within limits (one per seed: the database seed and,
  when given, the previous configuration), the one closest to the previous configuration;
- per pose: success, iterations, position error (mm), orientation error (rad);
- trajectory mode: ``lax.scan`` over time, warm-started from the previous solution.

Damping follows Sugihara's rule λ = ½‖e‖² + λ₀, so every step is accepted and one FK +
Jacobian is evaluated per iteration. Everything is pure JAX on arrays; the design (α, β,
l_QH, l_IJ) is an array input.

:func:`closed_form` is the IK from the RCM geometry (used to check the solvers, not by
them): within the joint ranges the arm has one solution per reachable pose.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics.poses import check_poses  # noqa: F401 (the one pose check; re-exported)
from designopt.studies.davinci import mechanism as mech

Array = jnp.ndarray


class Options(NamedTuple):
    """Solver settings (static: they shape the compiled program)."""

    first_iter: int = 4  # LM iterations of the first pass over every lane
    continue_iter: int = 6  # then, lanes not yet converged (gathered): a short pass
    max_iter: int = 60  # iterations of each later rescue pass (failed lanes only)
    warm_iter: int = 2  # trajectory mode: iterations from the predicted solution
    tol_pos: float = 1e-10  # mm, convergence (stricter than success)
    tol_rot: float = 1e-12  # rad
    success_pos: float = 1e-9  # mm
    success_rot: float = 1e-9  # rad
    length: float = 100.0  # mm, characteristic length scaling the position rows
    damping: float = 1e-12  # λ₀
    retries: int = 1  # extra seeds for lanes that failed (next database entries)
    chunk: int = 8192  # lanes per early-exit group (measured: 1024 → 20k/s, 8192 → 50-80k/s)
    q3_weight: float = 0.01  # rad per mm in the branch distance


OPTIONS = Options()


class Grid(NamedTuple):
    """Joint-grid resolution of the seed database (deg, mm)."""

    step_deg: float = 10.0  # q1, q2
    step_q3: float = 15.0  # mm
    step_wrist_deg: float = 15.0  # q4, q5
    step_q6_deg: float = 10.0
    step_rescue_deg: float = 20.0  # joint (q4, q5, q6) grid of the rescue seeds


GRID = Grid()


class Database(NamedTuple):
    """FK samples on joint grids (all arrays; built by :func:`build_database`)."""

    qa: Array  # (NA, 2) q1, q2
    sa: Array  # (NA, 3) shaft direction (y axis of frame 2) from H
    q3: Array  # (N3,) insertion grid
    qb: Array  # (NB, 2) q4, q5
    ab: Array  # (NB, 3) tool axis in frame 3
    qc: Array  # (NC,) q6
    cs: Array  # (NC, 2) cos q6, sin q6
    qw: Array  # (NW, 3) q4, q5, q6 (coarser grid, for rescue seeds)
    rw: Array  # (NW, 9) wrist rotation in frame 3, flattened

    @property
    def size(self) -> int:
        """Number of FK samples (the three factors together span NA·N3·NB·NC poses)."""
        return sum(a.shape[0] for a in (self.qa, self.q3, self.qb, self.qc, self.qw))


def _grid(lo: float, hi: float, step: float) -> np.ndarray:
    n = max(2, int(math.ceil((hi - lo) / step - 1e-9)) + 1)
    return np.linspace(lo, hi, n)


def grid_axes(g: Grid = GRID) -> tuple[np.ndarray, ...]:
    """The per-joint grid values (rad, mm) of the database (q4 without its duplicate
    end point)."""
    lo, hi = mech.LOWER, mech.UPPER
    r = math.radians
    return (
        _grid(lo[0], hi[0], r(g.step_deg)),
        _grid(lo[1], hi[1], r(g.step_deg)),
        _grid(lo[2], hi[2], g.step_q3),
        _grid(lo[3], hi[3], r(g.step_wrist_deg))[:-1],
        _grid(lo[4], hi[4], r(g.step_wrist_deg)),
        _grid(lo[5], hi[5], r(g.step_q6_deg)),
    )


def _wrist_axis(q45: Array) -> Array:
    """Tool axis z6 = x5 in frame 3: Rx(−π/2)Rz(q4)Rx(π/2)Rz(q5)·e_x = Ry(q4)Rz(q5)·e_x."""
    c4, s4 = jnp.cos(q45[..., 0]), jnp.sin(q45[..., 0])
    c5, s5 = jnp.cos(q45[..., 1]), jnp.sin(q45[..., 1])
    return jnp.stack([c4 * c5, s5, -s4 * c5], -1)


def build_database(X: Array, g: Grid = GRID, dtype=jnp.float64) -> Database:
    """The seed database for design X (4,), factored along the chain: shaft directions
    from H over the (q1, q2) grid (FK of frame 2), the q3 grid, tool axes in frame 3
    over the (q4, q5) grid (FK of frames 3→6), jaw angles over the q6 grid."""
    ax = grid_axes(g)
    A = np.stack(np.meshgrid(ax[0], ax[1], indexing="ij"), -1).reshape(-1, 2)
    qa = jnp.asarray(A, dtype)
    R2 = _rot3(jnp.asarray(X, dtype), jnp.concatenate([qa, jnp.zeros_like(qa[:, :1])], -1))
    Bq = np.stack(np.meshgrid(ax[3], ax[4], indexing="ij"), -1).reshape(-1, 2)
    qb = jnp.asarray(Bq, dtype)
    qc = jnp.asarray(ax[5], dtype)
    r = math.radians(g.step_rescue_deg)
    lo, hi = mech.LOWER, mech.UPPER
    Wq = np.stack(np.meshgrid(_grid(lo[3], hi[3], r)[:-1], _grid(lo[4], hi[4], r),
                              _grid(lo[5], hi[5], r), indexing="ij"), -1).reshape(-1, 3)  # fmt: skip
    qw = jnp.asarray(Wq, dtype)
    c6, s6 = jnp.cos(qw[:, 2]), jnp.sin(qw[:, 2])
    z, o = jnp.zeros_like(c6), jnp.ones_like(c6)
    Rz6 = jnp.stack([jnp.stack([c6, -s6, z], -1), jnp.stack([s6, c6, z], -1),
                     jnp.stack([z, z, o], -1)], -2)  # fmt: skip
    rw = _mm(_wrist_rot(qw[:, :2]), Rz6).reshape(-1, 9)
    return Database(qa, R2[:, :, 1], jnp.asarray(ax[2], dtype), qb, _wrist_axis(qb), qc,
                    jnp.stack([jnp.cos(qc), jnp.sin(qc)], -1), qw, rw)  # fmt: skip


def _rot3(X: Array, q123: Array) -> Array:
    qfull = jnp.concatenate([q123, jnp.zeros((*q123.shape[:-1], 3), q123.dtype)], -1)
    R, _ = mech.frame_model(3).fk(X, qfull)
    return R


def _ry_half() -> np.ndarray:
    return np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def _wrist_rot(q45: Array) -> Array:
    """Ry(q4) Rz(q5) Ry(π/2): the frame-6 rotation in frame 3 at q6 = 0."""
    c4, s4 = jnp.cos(q45[..., 0]), jnp.sin(q45[..., 0])
    c5, s5 = jnp.cos(q45[..., 1]), jnp.sin(q45[..., 1])
    z = jnp.zeros_like(c4)
    o = jnp.ones_like(c4)
    Ry4 = jnp.stack([jnp.stack([c4, z, s4], -1), jnp.stack([z, o, z], -1),
                     jnp.stack([-s4, z, c4], -1)], -2)  # fmt: skip
    Rz5 = jnp.stack([jnp.stack([c5, -s5, z], -1), jnp.stack([s5, c5, z], -1),
                     jnp.stack([z, z, o], -1)], -2)  # fmt: skip
    return _mm(_mm(Ry4, Rz5), jnp.asarray(_ry_half(), c4.dtype))


def _mm(A: Array, B: Array) -> Array:
    return jnp.sum(A[..., :, :, None] * B[..., None, :, :], axis=-2)


def _mtm(A: Array, B: Array) -> Array:
    """Aᵀ B for stacks of small matrices, as a fused multiply-sum (XLA on CPU runs batched
    small ``dot_general`` slowly)."""
    return jnp.sum(A[..., :, :, None] * B[..., :, None, :], axis=-3)


def _dot3(x: Array, pts: Array) -> Array:
    """x (B, d) · pts (N, d)ᵀ as elementwise products (fused with the arg-max that reads
    it; a small-K matrix product would be materialised first)."""
    return sum(x[:, k, None] * pts[None, :, k] for k in range(x.shape[1]))


def _best(score: Array, rank: int | Array, ranks: int = 1) -> Array:
    """Index of the ``rank``-th largest score along the last axis (``rank`` an int, or a
    traced int below ``ranks``)."""
    if isinstance(rank, int) and rank == 0:
        return jnp.argmax(score, -1)
    top = jax.lax.top_k(score, rank + 1 if isinstance(rank, int) else ranks)[1]
    return top[..., rank]


def seed(X: Array, db: Database, T: Array, rank: int | Array = 0, wrist_point: bool = True,
         full_wrist: bool = False, ranks: int = 1) -> Array:  # fmt: skip
    """Joint seeds (B, 6) for target poses T (B, 4, 4), nearest FK samples factor by
    factor: the shaft direction of the (q1, q2) grid closest to the direction from H to
    the target (the ``rank``-th closest), the q3 sample closest to its distance, then the
    tool axis of the (q4, q5) grid closest to the target's in that frame 3, then the jaw
    angle of the q6 grid closest to the rest of the rotation.

    ``wrist_point``: query with the wrist point I rather than the tip J. The jaw offset
    J − I = l_IJ·y5 is perpendicular to the tool axis z6 = x5 and lies in the plane of z6
    and J − H, so I follows from the target alone; without it, poses with the shaft tip
    within a few mm of H (q3 ≲ l_IJ) get seeds tens of degrees off.
    ``full_wrist``: match the whole wrist rotation on the joint (q4, q5, q6) grid instead
    (near q5 = ±90° the tool axis hardly fixes q4, and q6's range then matters).
    ``rank`` may be traced (an int array below ``ranks``): one program for every rank.
    """
    p, a = T[:, :3, 3], T[:, :3, 2]
    d = p - mech.rcm_point(X)
    if wrist_point:  # query with the wrist point I = p − l_IJ·y5, y5 ⟂ the tool axis a
        v = d - jnp.sum(d * a, -1, keepdims=True) * a
        nv = jnp.linalg.norm(v, axis=-1, keepdims=True)
        d = d - X[3] * v / jnp.where(nv > 0, nv, 1.0)
    r = jnp.linalg.norm(d, axis=-1)
    r = jnp.where(r > 0, r, 1.0)
    q12 = db.qa[_best(_dot3(d / r[:, None], db.sa), rank, ranks)]
    q3 = db.q3[jnp.argmin(jnp.abs(r[:, None] - db.q3[None, :]), -1)]
    q123 = jnp.concatenate([q12, q3[:, None]], -1)
    W = _mtm(_rot3(X, q123), T[:, :3, :3])  # target rotation in frame 3
    if full_wrist:
        qw = db.qw[jnp.argmax(_dot3(W.reshape(-1, 9), db.rw), -1)]
        return jnp.concatenate([q123, qw], -1)
    q45 = db.qb[jnp.argmax(_dot3(W[:, :, 2], db.ab), -1)]
    G = _mtm(_wrist_rot(q45), W)  # ≈ Rz(q6)
    c, s = G[:, 0, 0] + G[:, 1, 1], G[:, 1, 0] - G[:, 0, 1]
    q6 = db.qc[jnp.argmax(c[:, None] * db.cs[None, :, 0] + s[:, None] * db.cs[None, :, 1], -1)]
    return jnp.concatenate([q123, q45, q6[:, None]], -1)


# ----------------------------------------------------------------------- errors


def _cross(a: Array, b: Array) -> Array:
    return jnp.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                      a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                      a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], -1)  # fmt: skip


def rot_vec_err(R: Array, Rt: Array) -> Array:
    """½ Σ_i r_i × rt_i: sin(θ)·axis of the rotation taking R to Rt (base frame)."""
    return 0.5 * sum(_cross(R[..., :, i], Rt[..., :, i]) for i in range(3))


def pose_errors(R: Array, p: Array, T: Array) -> tuple[Array, Array]:
    """(position error (mm), orientation error (rad)) of (R, p) against T."""
    pe = jnp.linalg.norm(T[..., :3, 3] - p, axis=-1)
    w = rot_vec_err(R, T[..., :3, :3])
    c = 0.5 * (jnp.sum(R * T[..., :3, :3], (-1, -2)) - 1.0)
    return pe, jnp.arctan2(jnp.linalg.norm(w, axis=-1), c)


# ------------------------------------------------------------------ linear algebra


def _chol_solve(A: Array, b: Array) -> Array:
    """Solve SPD systems A x = b, A (B, n, n), b (B, n), by an unrolled Cholesky on
    lane-wise arrays (no per-matrix library call)."""
    n = A.shape[-1]
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        s = A[:, j, j] - sum(L[j][k] * L[j][k] for k in range(j)) if j else A[:, j, j]
        L[j][j] = jnp.sqrt(s)
        inv = 1.0 / L[j][j]
        for i in range(j + 1, n):
            s = A[:, i, j] - sum(L[i][k] * L[j][k] for k in range(j)) if j else A[:, i, j]
            L[i][j] = s * inv
    y = [None] * n
    for i in range(n):
        y[i] = (
            (b[:, i] - sum(L[i][k] * y[k] for k in range(i))) / L[i][i] if i else b[:, i] / L[i][i]
        )
    x = [None] * n
    for i in reversed(range(n)):
        s = y[i] - sum(L[k][i] * x[k] for k in range(i + 1, n)) if i < n - 1 else y[i]
        x[i] = s / L[i][i]
    return jnp.stack(x, -1)


# ------------------------------------------------------------------------ solver


def _project(q: Array, lo: Array, hi: Array) -> Array:
    q4 = jnp.remainder(q[:, 3] + math.pi, 2 * math.pi) - math.pi
    q = q.at[:, 3].set(q4)
    return jnp.clip(q, lo, hi)


def _lm_chunk(X: Array, T: Array, q0: Array, lo: Array, hi: Array, o: Options):
    """LM on one chunk of lanes for at most ``o.max_iter`` iterations, each lane frozen
    once converged: (q, iterations per lane)."""
    L = o.length
    Rt, pt = T[:, :3, :3], T[:, :3, 3]
    B = T.shape[0]
    col = jnp.asarray([1.0, 1.0, L, 1.0, 1.0, 1.0], T.dtype)

    def residual(q):
        R, p, J = mech.ARM.fk_jacobian(X, q, char_length=L)
        J = J * col  # q3 in units of L: every column O(1)
        ep = pt - p
        ew = rot_vec_err(R, Rt)
        conv = (jnp.linalg.norm(ep, axis=-1) <= o.tol_pos) & (
            jnp.linalg.norm(ew, axis=-1) <= o.tol_rot
        )
        return jnp.concatenate([ep / L, ew], -1), J, conv

    def cond(s):
        _, it, _, active = s
        return jnp.any(active) & (it < o.max_iter)

    def body(s):
        q, it, iters, active = s
        e, J, conv = residual(q)
        active = active & ~conv
        lam = 0.5 * jnp.sum(e * e, -1) + o.damping
        A = _mtm(J, J) + lam[:, None, None] * jnp.eye(6, dtype=q.dtype)
        g = jnp.sum(J * e[:, :, None], -2)
        dq = _chol_solve(A, g) * col
        qn = _project(q + dq, lo, hi)
        ok = active & jnp.all(jnp.isfinite(qn), -1)
        q = jnp.where(ok[:, None], qn, q)
        return q, it + 1, iters + active.astype(jnp.int32), active

    init = (q0, jnp.asarray(0, jnp.int32), jnp.zeros(B, jnp.int32), jnp.ones(B, bool))
    q, _, iters, _ = jax.lax.while_loop(cond, body, init)
    return q, iters


def _chunked(fn, chunk: int, *arrays):
    """fn over lanes in chunks of ``chunk`` (padding the last chunk by repetition)."""
    n = arrays[0].shape[0]
    c = min(chunk, n)
    k = -(-n // c)
    pad = k * c - n
    if pad:
        arrays = tuple(
            jnp.concatenate([a, jnp.broadcast_to(a[-1:], (pad, *a.shape[1:]))]) for a in arrays
        )
    outs = jax.lax.map(lambda xs: fn(*xs), tuple(a.reshape(k, c, *a.shape[1:]) for a in arrays))
    return jax.tree.map(lambda o: o.reshape(k * c, *o.shape[2:])[:n], outs)


class Result(NamedTuple):
    q: Array  # (B, 6) rad, q3 mm
    success: Array  # (B,) bool
    iterations: Array  # (B,) int, LM iterations summed over the seeds tried
    pos_err: Array  # (B,) mm
    rot_err: Array  # (B,) rad


def _evaluate(X: Array, T: Array, q: Array, lo: Array, hi: Array, o: Options):
    R, p = mech.ARM.fk(X, q)
    pe, re = pose_errors(R, p, T)
    inside = jnp.all((q >= lo) & (q <= hi), -1)
    ok = (pe <= o.success_pos) & (re <= o.success_rot) & inside & jnp.all(jnp.isfinite(q), -1)
    return ok, pe, re


def _branch_dist(q: Array, q_prev: Array, o: Options) -> Array:
    w = jnp.asarray([1.0, 1.0, o.q3_weight, 1.0, 1.0, 1.0], q.dtype)
    return jnp.sum(((q - q_prev) * w) ** 2, -1)


def _pass(X, T, q0, lo, hi, o: Options, max_iter: int) -> Result:
    """One LM pass over all lanes (chunked early exit) and its evaluation."""
    oi = o._replace(max_iter=max_iter)
    q, it = _chunked(lambda Tc, qc: _lm_chunk(X, Tc, qc, lo, hi, oi), o.chunk, T, q0)
    ok, pe, re = _evaluate(X, T, q, lo, hi, o)
    return Result(q, ok, it, pe, re)


def _rescue(X, T, r: Result, start, lo, hi, o: Options, iters: int, frac: int,
            stages: int = 1) -> Result:  # fmt: skip
    """Lanes that failed start again from ``start(T_sub, q_sub, stage)`` for ``iters``
    iterations, gathered into buffers of B // ``frac`` lanes (so a batch with few
    failures costs little and one with none costs nothing). ``stages`` passes, one after
    the other, each over the lanes still failing after the last (``stage`` 0, 1, ...: a
    traced int): one loop, so the solver's step is compiled once for all of them (as
    separate loops it was compiled once per pass)."""
    B = T.shape[0]
    K = min(B, max(64, B // frac))
    oi = o._replace(max_iter=iters)

    def cond(c):
        res, todo, stage = c
        return jnp.any(todo)

    def body(c):
        res, todo, stage = c
        (idx,) = jnp.nonzero(todo, size=K, fill_value=B)
        ic = jnp.minimum(idx, B - 1)
        Tk = T[ic]
        qn, itn = _lm_chunk(X, Tk, start(Tk, res.q[ic], stage), lo, hi, oi)
        okn, pen, ren = _evaluate(X, Tk, qn, lo, hi, o)
        tgt = jnp.where(okn, idx, B)  # out of range: dropped

        def put(a, v, t=tgt):
            return a.at[t].set(v, mode="drop")

        res = Result(put(res.q, qn), put(res.success, okn),
                     res.iterations.at[idx].add(itn, mode="drop"), put(res.pos_err, pen),
                     put(res.rot_err, ren))  # fmt: skip
        todo = todo.at[idx].set(False, mode="drop")
        # this pass done: the next one over the lanes still failing
        nxt = ~jnp.any(todo) & (stage + 1 < stages)
        return res, jnp.where(nxt, ~res.success, todo), stage + nxt.astype(stage.dtype)

    out, _, _ = jax.lax.while_loop(cond, body, (r, ~r.success, jnp.asarray(0, jnp.int32)))
    return out


def solve(
    X: Array,
    db: Database,
    T: Array,
    q_prev: Array | None = None,
    o: Options = OPTIONS,
) -> Result:
    """IK of poses T (B, 4, 4) for design X (4,), cold-started from the database.

    A first pass runs ``o.first_iter`` LM iterations from the nearest database sample;
    lanes not yet solved continue for ``o.continue_iter``, then ``o.max_iter`` iterations,
    then restart from the full-wrist seed and from the next database samples
    (``o.retries``), each pass on the failed lanes only (:func:`_rescue`). With ``q_prev`` (B, 6), the previous
    configuration is a second seed and, among the converged solutions within limits, the
    one closest to q_prev is returned (joint distance with q3 scaled by ``o.q3_weight``).
    Inputs must be finite rigid transforms (:func:`check_poses`).
    """
    X = jnp.asarray(X, T.dtype)
    lo, hi = jnp.asarray(mech.LOWER, T.dtype), jnp.asarray(mech.UPPER, T.dtype)
    r = _pass(X, T, seed(X, db, T), lo, hi, o, o.first_iter)
    if q_prev is not None:
        q_prev = jnp.asarray(q_prev, T.dtype)
        r2 = _pass(X, T, _project(q_prev, lo, hi), lo, hi, o, o.first_iter)
        r2 = _rescue(X, T, r2, _keep, lo, hi, o, o.continue_iter, 16)
        r = _rescue(X, T, r, _keep, lo, hi, o, o.continue_iter, 16)
        take = r2.success & (
            ~r.success | (_branch_dist(r2.q, q_prev, o) < _branch_dist(r.q, q_prev, o))
        )
        r = jax.tree.map(
            lambda a, b: jnp.where(take.reshape(-1, *([1] * (a.ndim - 1))), b, a), r, r2
        )
    return _rescues(X, db, T, r, lo, hi, o)


def _keep(Tk: Array, qk: Array, stage: Array) -> Array:
    return qk


def _rescues(X, db, T, r: Result, lo, hi, o: Options) -> Result:
    """The rescue passes for lanes that failed: continue (few, then many iterations),
    then restart from the full-wrist seed and from the next database samples."""
    r = _rescue(X, T, r, _keep, lo, hi, o, o.continue_iter, 16)

    def start(Tk, qk, stage):  # stage 0: go on; then the database's seeds of rank 0, 1, ...
        seeded = seed(X, db, Tk, jnp.maximum(stage - 1, 0), full_wrist=True,
                      ranks=o.retries + 1)  # fmt: skip
        return jnp.where(stage == 0, qk, seeded)

    return _rescue(X, T, r, start, lo, hi, o, o.max_iter, 256, stages=o.retries + 2)


def solve_trajectory(X: Array, db: Database, T: Array, q_start: Array | None = None,
                     o: Options = OPTIONS) -> Result:  # fmt: skip
    """IK along paths T (S, P, 4, 4): S time steps of P independent paths, by a
    ``lax.scan`` over time warm-started from the previous solutions (linear predictor
    q_{k-1} + (q_{k-1} − q_{k-2}), then ``o.warm_iter`` LM iterations); the first step is
    solved by :func:`solve` (closest to ``q_start`` (P, 6) if given). Lanes whose warm
    start fails are solved from the database at that step, as :func:`solve` does."""
    X = jnp.asarray(X, T.dtype)
    lo, hi = jnp.asarray(mech.LOWER, T.dtype), jnp.asarray(mech.UPPER, T.dtype)
    first = solve(X, db, T[0], q_start, o)

    def step(carry, Tk):
        q_prev, dq = carry
        q0 = _project(q_prev + dq, lo, hi)  # linear predictor from the last two solutions
        q, it = _lm_chunk(X, Tk, q0, lo, hi, o._replace(max_iter=o.warm_iter))
        ok, pe, re = _evaluate(X, Tk, q, lo, hi, o)
        r = _rescues(X, db, Tk, Result(q, ok, it, pe, re), lo, hi, o)
        q_next = jnp.where(r.success[:, None], r.q, q_prev)
        d = q_next - q_prev
        d = d.at[:, 3].set(jnp.remainder(d[:, 3] + math.pi, 2 * math.pi) - math.pi)
        return (q_next, jnp.where(r.success[:, None], d, 0.0)), r

    q_init = jnp.where(first.success[:, None], first.q, seed(X, db, T[0]))
    _, rest = jax.lax.scan(step, (q_init, jnp.zeros_like(q_init)), T[1:])
    return jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), first, rest)


# ------------------------------------------------------------------- closed form


def closed_form(X: Array, T: Array) -> tuple[Array, Array]:
    """IK from the RCM geometry, for checking: (q (B, 6), valid (B,)).

    With d = p − H and a = z6 the tool axis, the jaw offset y5 is the unit component of
    d orthogonal to a (the sign with cos q5 ≥ 0, i.e. within the q5 range); the shaft
    tip is I = p − l_IJ·y5, q3 = |I − H|, the shaft direction gives q1, q2 and the
    orientation in frame 3 gives q4, q5, q6. ``valid``: finite, within limits and FK
    reproducing T to 1e-9 (mm, rad). Singular when d ∥ a or I = H.
    """
    X = jnp.asarray(X, T.dtype)
    H = mech.rcm_point(X)
    p, Rt = T[:, :3, 3], T[:, :3, :3]
    a = Rt[:, :, 2]
    d = p - H
    v = d - jnp.sum(d * a, -1, keepdims=True) * a
    y5 = v / jnp.linalg.norm(v, axis=-1, keepdims=True)
    I = p - X[3] * y5
    q3 = jnp.linalg.norm(I - H, axis=-1)
    s = (I - H) / q3[:, None]
    c, sn = jnp.cos(X[0] - math.pi), jnp.sin(X[0] - math.pi)
    u = jnp.stack([s[:, 0], c * s[:, 1] + sn * s[:, 2], -sn * s[:, 1] + c * s[:, 2]], -1)
    q2 = jnp.arcsin(jnp.clip(u[:, 2], -1.0, 1.0)) - (math.pi / 2 - X[1])
    q1 = jnp.arctan2(-u[:, 0], u[:, 1])
    q123 = jnp.stack([q1, q2, q3], -1)
    W = _mtm(_rot3(X, q123), Rt)
    a3 = W[:, :, 2]
    q5 = jnp.arcsin(jnp.clip(a3[:, 1], -1.0, 1.0))
    q4 = jnp.arctan2(-a3[:, 2], a3[:, 0])
    G = _mtm(_wrist_rot(jnp.stack([q4, q5], -1)), W)
    q6 = jnp.arctan2(G[:, 1, 0], G[:, 0, 0])
    q = jnp.stack([q1, q2, q3, q4, q5, q6], -1)
    lo, hi = jnp.asarray(mech.LOWER, T.dtype), jnp.asarray(mech.UPPER, T.dtype)
    ok, _, _ = _evaluate(X, T, q, lo, hi, Options())
    return q, ok
