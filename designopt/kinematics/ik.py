"""Inverse kinematics of any :class:`~designopt.kinematics.kernel.SerialModel` (DH, ET or
URDF chains): batched damped least squares over designs × targets, in one jitted program
of fixed shapes.

Targets come in three kinds (``mode``):

- ``position``: the tip position p (3 rows);
- ``axis``: p and the tool z axis (the roll about the tool axis is free: 5 independent
  rows; the residual z × z* has three components of rank 2);
- ``pose``: p and the full orientation R (6 rows).

Step. Sugihara's Levenberg–Marquardt update (Sugihara, "Solvability-unconcerned inverse
kinematics by the Levenberg–Marquardt method", IEEE T-RO 2011):
Δq = (JᵀJ + λ I)⁻¹ Jᵀe with λ = ``damping_e``·E + ``damping``, E = ½|e|², so the damping
vanishes as the error does (quadratic convergence) and grows far from a solution or near a
singularity. With fewer rows than joints the same step is solved in the row space,
Δq = Jᵀ(JJᵀ + λ I)⁻¹ e (3×3 for ``position``). Position rows are divided by the chain's
reach scale L, so a pose mixes lengths and radians on equal terms; prismatic joints count
in units of L. The damping floor is tiny (1e-16) and E weighs 0.1, not Sugihara's 1:
near a singular solution (a target at the rim of the workspace, e.g. a PUMA 560 with the
elbow almost straight, where σ_min(J) falls like the square of the distance to the fold)
a larger damping only crawls. Joint limits: a joint on a limit whose descent direction
(Jᵀe) points out of the range is fixed for the step (its column dropped), then every
joint is projected back into its range (a revolute joint whose range spans a full turn
first wraps by ±2π). The orientation residual is ½ Σᵢ rᵢ × rᵢ* over the columns of R
(Siciliano et al., "Robotics: Modelling, Planning and Control", 2009, eq. 3.85).

Seeds, tried one after the other for each target until one converges (or, with
``n_best`` > 1, until that many have; the solution of highest score is kept, by default
the 2-norm 1/k of the position Jacobian, so the designer gets the best-conditioned
configuration among those found): the ``n_nearest``
entries of an FK database (``n_db`` configurations uniform within the limits, the same
draws for every design) nearest to the target, then ``n_random × rounds`` database
entries picked by a hash of (target, attempt), i.e. uniform draws. A seed is dropped
after ``iters`` steps, or earlier when a block of ``block`` steps did not bring its
least error below ``stall`` × its least error before. The nearest entries are found
without a T × n_db distance matrix: the database is sorted by the Z-order (Morton) code
of its tip positions; each target finds its own code by binary search and ranks the
``window`` entries around it by position and orientation distance.

Scheduling. Every (design, target) pair is an item of one queue (a ring buffer of
(item, seed) pairs); a fixed number of slots hold the items in flight. A ``while_loop``
runs ``block`` steps on every slot (a converged configuration is frozen), then a slot
whose item converged or ran out of seeds is freed, one whose seed was dropped puts the
item back at the end of the queue with its next seed, and free slots take the queue's
next pairs. The steps run on the busy slots only, a chunk of B/8 slots at a time (all
B when B/8 < 32): once the queue is empty the busy slots move to the front (in their order)
and only the chunks that hold them run, so the hard tail does not keep a large batch
running, and the step is compiled once, for one chunk (earlier the busy slots moved to
batches 8× and 64× smaller, each with its own copy of the step: 4096 → 512 → 64).
Designs share the queue: a design
with many unreachable targets costs its own work, not every design's.

Arithmetic. The step is evaluated entry by entry (structure of arrays: every entry of e,
J, R, p is one array over the slots; the chain's structural zeros folded at trace time),
the 6×6 (or 3×3) solve an unrolled Cholesky. The sines and cosines of the joints are
loop-carried and computed by a shared range reduction and fdlibm's polynomials; e and J
pass through a division by a runtime 1: XLA counts sin, cos and products as cheap and
would otherwise copy the chain into every consumer (measured on a 6R pose step: 4× the
operations and 12× the sines and cosines).

A target is solved when its position error is ≤ ``tol_pos``·L and its orientation error
≤ ``tol_rot`` rad, within the limits, checked afresh at the end on the returned joints
(with XLA's own sin and cos); unreachable targets are reported as failures, never as
successes. The n_best solution slots are checked in a loop (one copy of the check and
the score in the program) and the result's fields are materialised once.

Neighbours (``neighbours`` > 0). The best solution moves continuously with the target: a
second pass seeds every target with the kept solutions of its nearest reached
neighbours (among its run of 16 targets), so a branch that one target's seeds found
serves the targets around it; the better of the two passes' solutions is kept.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp

from designopt.kinematics import _fold as F
from designopt.kinematics import kernel as K
from designopt.kinematics.conditioning import inv_cond
from designopt.kinematics.kernel import SerialModel

Mode = Literal["position", "axis", "pose"]
MODES: tuple[str, ...] = ("position", "axis", "pose")


class IKOptions(NamedTuple):
    """Solver settings. Seeds per target: ``n_nearest`` + ``n_random`` × ``rounds``, at
    most ``iters`` steps each, stopping once ``n_best`` of them have converged (the best
    of those by the score is kept). All but the tolerances and the damping fix array
    shapes or loop bounds."""

    iters: int = 48  # LM steps per seed at most (rounded up to a multiple of block)
    rounds: int = 8  # random seeds: n_random × rounds after the nearest ones
    n_db: int = 4096  # FK database per design
    n_nearest: int = 4  # nearest database entries tried first
    n_random: int = 6
    tol_pos: float = 1e-9  # × the reach scale L
    tol_rot: float = 1e-9  # rad
    damping: float = 1e-16  # λ̄: λ = damping_e·E + λ̄ (e in units of L and rad)
    damping_e: float = 0.1  # the weight of E = ½|e|² in λ
    stall: float = 0.5  # drop a seed whose least E fell less than this factor in a block
    window: int = 32  # database entries ranked per target (Z-order neighbours)
    block: int = 4  # steps between checks (convergence, seed change, refill)
    slots: int = 0  # items in flight (0: min(M·T, clip(M·T/4, 1024, 4096)))
    n_best: int = 1  # distinct converged seeds compared per target (1: the first found)
    climb: int = 0  # null-space ascent steps of the score from each kept solution (0: none)
    neighbours: int = 0  # a second pass from the kept solutions of this many neighbours


DEFAULTS = IKOptions()


class IKResult(NamedTuple):
    """Per target: joints (active), success, position error (model units), orientation
    error (rad; 0 for ``position``), 1/k (2-norm, position block) at the joints, and the
    seed they come from (0 = the nearest database entry; for a failure, the seed that
    came closest; a neighbour pass's seed r, the r-th nearest neighbour's solution, is
    counted after the first pass's seeds). With an ``accept`` predicate, ``success``
    also asks that it accepts the joints, and ``converged`` says whether they are within tolerance and limits alone."""

    q: jax.Array
    success: jax.Array
    pos_err: jax.Array
    rot_err: jax.Array
    inv_k: jax.Array
    seed: jax.Array
    converged: jax.Array  # within tolerance and limits, accepted or not (= success without
    #                       an ``accept`` predicate)
    tries: jax.Array | None = None  # seeds tried (int32; the profile of a solve)
    refused: jax.Array | None = None  # converged seeds ``accept`` refused (int32)


# ------------------------------------------------------------ entry-wise kinematics

Scalar = F.Scalar

# Cody–Waite split of π/2 and the minimax polynomials of sin and cos on [−π/4, π/4]
# (Sun Microsystems' fdlibm, k_sin.c and k_cos.c, 1993)
_PIO2 = (1.57079632673412561417e00, 6.07710050630396597660e-11, 2.02226624871116645580e-21)
_SIN = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
        2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)  # fmt: skip
_COS = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
        -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)  # fmt: skip


def _sincos(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(sin x, cos x) to a few 1e-16 (absolute) for joint angles |x| ≤ 10³: one shared
    range reduction and two polynomials, plain vectorisable arithmetic (XLA's sin and
    cos cost about ten times as much on a CPU)."""
    k = jnp.round(x * (2 / math.pi))
    r = ((x - k * _PIO2[0]) - k * _PIO2[1]) - k * _PIO2[2]
    z = r * r
    ps, pc = _SIN[5], _COS[5]
    for a, b in zip(_SIN[4::-1], _COS[4::-1], strict=True):
        ps, pc = ps * z + a, pc * z + b
    s = r + r * z * ps
    c = (1.0 - 0.5 * z) + z * z * pc
    n = k.astype(jnp.int32) & 3
    odd = (n & 1) == 1
    s, c = jnp.where(odd, c, s), jnp.where(odd, s, c)
    return jnp.where(n >= 2, -s, s), jnp.where((n == 1) | (n == 2), -c, c)


def _lincomb(key, cols) -> Scalar:
    return F.total(F.mul(c, cols[j]) for j, c in enumerate(key) if c != 0.0)


class _Chain:
    """A chain evaluated entry by entry for items that each have their own design and
    joints: the frame kernel's walk (``kernel._Walk``: its folding and its Jacobian
    columns) with per-item design columns and the sines and cosines supplied."""

    def __init__(self, model: SerialModel) -> None:
        self.model = model.per_design()
        self.n, self.D = model.n_active, len(model.variables)
        w = self._walk([jnp.ones(1)] * self.D, [jnp.zeros(1)] * self.n, {}, {})
        self.keys_q = tuple(w.trig_q)  # joint combinations whose sin and cos it needs
        self.keys_x = tuple(w.trig_x)  # design combinations (angles that are variables)
        self.rev = revolute(model)

    def _walk(self, xc, qc, trig_q, trig_x) -> K._Walk:
        dtype = jnp.result_type(*qc)
        w = K._Walk(self.model, jnp.zeros((1, self.D), dtype), jnp.zeros((1, self.n), dtype))
        w.xcol, w.qcol = list(xc), list(qc)
        w.trig_q.update(trig_q)
        w.trig_x.update(trig_x)
        for s in self.model.steps:
            w.step(s)
        return w

    def trig_q(self, qc, exact: bool = False, one=None) -> dict:
        """cos and sin of every joint combination (:func:`_sincos`, or XLA's); with
        ``one`` each passes through a division (computed once, not in every consumer)."""
        out = {}
        for key in self.keys_q:
            a = _lincomb(key, qc)
            s, c = (jnp.sin(a), jnp.cos(a)) if exact else _sincos(a)
            out[key] = (c, s) if one is None else (c / one, s / one)
        return out

    def trig_x(self, xc) -> dict:
        out = {}
        for key in self.keys_x:
            a = F.total(F.mul(s, xc[k]) for k, s in key)
            out[key] = (jnp.cos(a), jnp.sin(a))
        return out

    def fk(self, xc, qc, trig_q, trig_x, rows: tuple[int, ...] | None = None):
        """(R 3×3, p 3, J rows×n or None) entry by entry: Python floats (structural
        values) or (B,) arrays."""
        B = qc[0].shape[0]
        w = self._walk(xc, qc, trig_q, trig_x)
        R = [[_flat(x, B) for x in row] for row in w.rot_entries()]
        p = [_flat(w.contract(e), B) for e in w.pos_lins()]
        J = None
        if rows is not None:
            E = w.jacobian_entries(rows, tuple(range(self.n)), None)
            J = [[_flat(w.contract(e), B) for e in row] for row in E]
        return R, p, J


def _flat(x: Scalar, B: int) -> Scalar:
    """A kernel entry as a (B,) array (Python constants stay constants)."""
    if F.is_const(x):
        return x
    return jnp.reshape(x, (-1,)) if jnp.size(x) == B else jnp.broadcast_to(jnp.ravel(x), (B,))


def _cross(a, b):
    return [F.mul_sub(a[1], b[2], a[2], b[1]), F.mul_sub(a[2], b[0], a[0], b[2]),
            F.mul_sub(a[0], b[1], a[1], b[0])]  # fmt: skip


def _dot(a, b) -> Scalar:
    return F.total(F.mul(x, y) for x, y in zip(a, b, strict=True))


def _residual(R, p, J, pt, Rt, mode: Mode, invL):
    """(e, J, c): the residual and its Jacobian (position rows in units of L; e falls
    by J dq for a step dq) and the cosine test of the orientation (z·z* for ``axis``,
    tr(RᵀR*) − 1 for ``pose``: > 0 tells a small angle from one near π, where the
    sine-sized residual is small too). The orientation rows are the residual's
    derivative at the solution: ω for ``pose``; for ``axis`` ω less its roll about the
    tool axis, (I − z zᵀ) ω (with ω itself a step would also hold the roll, which the
    residual leaves free: a 2R or 5R arm could not follow; measured on 6R arms, these
    rows also converge more often than ω or the exact derivative −z* × (ω × z), whose
    gain vanishes at 90°)."""
    e = [F.mul(F.sub(pt[i], p[i]), invL) for i in range(3)]
    c = None
    if mode == "axis":
        z, zt = [R[i][2] for i in range(3)], [Rt[i][2] for i in range(3)]
        e += _cross(z, zt)
        c = _dot(z, zt)
        if J is not None:  # ω_j less its roll about the tool axis: (I − z zᵀ) ω_j
            cols = []
            for j in range(len(J[0])):
                w = [J[3][j], J[4][j], J[5][j]]
                wz = _dot(w, z)
                cols.append([F.sub(w[r], F.mul(wz, z[r])) for r in range(3)])
            J = [*J[:3], *([col[r] for col in cols] for r in range(3))]
    elif mode == "pose":
        acc: list[Scalar] = [0.0, 0.0, 0.0]
        for j in range(3):
            cj = _cross([R[i][j] for i in range(3)], [Rt[i][j] for i in range(3)])
            acc = [F.add(acc[i], cj[i]) for i in range(3)]
        e += [F.mul(0.5, a) for a in acc]
        c = F.sub(F.total(F.mul(R[i][j], Rt[i][j]) for i in range(3) for j in range(3)), 1.0)
    if J is not None:
        J = [[F.mul(x, invL) for x in J[r]] if r < 3 else list(J[r]) for r in range(len(J))]
    return e, J, c


def _chol_solve(A: list[list[Scalar]], b: list[Scalar]) -> list[Scalar]:
    """x = A⁻¹ b for a batch of small symmetric positive-definite systems given entry by
    entry: Cholesky unrolled at trace time, elementwise over the batch (a batched LAPACK
    call per tiny matrix is far slower on a CPU). The factor entries divide by the pivots
    (rather than multiply by reciprocals), which also keeps XLA from recomputing each
    of them in every later one."""
    n = len(b)
    Lc: list[list[Scalar]] = [[0.0] * n for _ in range(n)]
    d: list[Scalar] = [1.0] * n
    for j in range(n):
        s = F.sub(A[j][j], F.total(F.mul(Lc[j][k], Lc[j][k]) for k in range(j)))
        d[j] = jnp.sqrt(jnp.maximum(s, 1e-32))  # a pivot lost to rounding stays positive
        for i in range(j + 1, n):
            s = F.sub(A[i][j], F.total(F.mul(Lc[i][k], Lc[j][k]) for k in range(j)))
            Lc[i][j] = 0.0 if F.is_const(s) and s == 0.0 else s / d[j]
    y: list[Scalar] = [0.0] * n
    for i in range(n):
        y[i] = F.sub(b[i], F.total(F.mul(Lc[i][k], y[k]) for k in range(i))) / d[i]
    x: list[Scalar] = [0.0] * n
    for i in reversed(range(n)):
        x[i] = F.sub(y[i], F.total(F.mul(Lc[k][i], x[k]) for k in range(i + 1, n))) / d[i]
    return x


def _lm_step(e, J, rev: tuple[bool, ...], L, lam, qc, lower, upper) -> list[Scalar]:
    """Sugihara's step with damping λ, in joint space (k ≥ n rows) or row space (k < n).
    A joint on a limit that the descent direction Jᵀe pushes further out is fixed."""
    k, n = len(e), len(J[0])
    Jc = [[J[r][i] if rev[i] else F.mul(J[r][i], L) for i in range(n)] for r in range(k)]
    g = [_dot([Jc[r][i] for r in range(k)], e) for i in range(n)]
    out = [((qc[i] <= lower[i]) & (g[i] < 0)) | ((qc[i] >= upper[i]) & (g[i] > 0))
           for i in range(n)]  # fmt: skip
    Jc = [[jnp.where(out[i], 0.0, Jc[r][i]) if not F.is_const(Jc[r][i]) else Jc[r][i]
           for i in range(n)] for r in range(k)]  # fmt: skip
    if k < n:
        A = [[F.add(_dot(Jc[i], Jc[j]), lam if i == j else 0.0) for j in range(k)]
             for i in range(k)]  # fmt: skip
        y = _chol_solve(A, e)
        dq = [F.total(F.mul(Jc[r][i], y[r]) for r in range(k)) for i in range(n)]
    else:
        cols = [[Jc[r][i] for r in range(k)] for i in range(n)]
        A = [[F.add(_dot(cols[i], cols[j]), lam if i == j else 0.0) for j in range(n)]
             for i in range(n)]  # fmt: skip
        dq = _chol_solve(A, [jnp.where(out[i], 0.0, g[i]) for i in range(n)])
    return [d if rev[i] else F.mul(d, L) for i, d in enumerate(dq)]


def _project(qc: list, lower, upper, rev: tuple[bool, ...]) -> list:
    """Joint limits by projection, joint by joint: a revolute joint whose range spans a
    full turn first moves by ±2π back into it (the same pose), then every joint is
    clipped."""
    two_pi = 2 * math.pi
    out = []
    for i, x in enumerate(qc):
        lo, hi = lower[i], upper[i]
        if rev[i]:
            full = hi - lo >= two_pi
            x = jnp.where(full & (x > hi) & (x - two_pi >= lo), x - two_pi, x)
            x = jnp.where(full & (x < lo) & (x + two_pi <= hi), x + two_pi, x)
        out.append(jnp.clip(x, lo, hi))
    return out


def _one(x: jax.Array) -> jax.Array:
    """A 1 computed from data: dividing by it is exact and keeps XLA from fusing (and
    thereby recomputing) the dividend into each of its consumers."""
    return jnp.where(jnp.isnan(jnp.ravel(x)[0]), 2.0, 1.0).astype(x.dtype)


def _keep(x: Scalar, one: jax.Array) -> Scalar:
    return x if F.is_const(x) else x / one


# ----------------------------------------------------------------- public helpers


def _rows(mode: Mode) -> tuple[int, ...]:
    return (0, 1, 2) if mode == "position" else (0, 1, 2, 3, 4, 5)


def residual(model: SerialModel, X: jax.Array, q: jax.Array, p_t: jax.Array,
             R_t: jax.Array | None, mode: Mode, L: jax.Array):  # fmt: skip
    """(e, J, p, R) of configurations q (B, n) of one design X (D,) against targets
    p_t (B, 3) and R_t (B, 3, 3) (for ``axis`` only its last column counts), as arrays:
    the residual and Jacobian the solver steps with, computed by the solver's own
    entry-wise code (:class:`_Chain`, :func:`_residual`), XLA's sin and cos."""
    ch = _Chain(model)
    B, dtype = q.shape[0], q.dtype
    X = jnp.asarray(X, dtype)
    xc = [jnp.broadcast_to(X[k], (B,)) for k in range(ch.D)]
    qc = [q[:, i] for i in range(ch.n)]
    R, p, J = ch.fk(xc, qc, ch.trig_q(qc, exact=True), ch.trig_x(xc), _rows(mode))
    pt = [p_t[:, i] for i in range(3)]
    Rt = None if R_t is None else [[R_t[:, r, c] for c in range(3)] for r in range(3)]
    e, J, _ = _residual(R, p, J, pt, Rt, mode, 1.0 / L)

    def arr(x):
        return jnp.broadcast_to(jnp.asarray(x, dtype), (B,))

    def mat(rows):
        return jnp.stack([jnp.stack([arr(x) for x in row], -1) for row in rows], -2)

    return jnp.stack([arr(x) for x in e], -1), mat(J), jnp.stack([arr(x) for x in p], -1), mat(R)


def errors(p: jax.Array, R: jax.Array, p_t: jax.Array, R_t: jax.Array | None,
           mode: Mode) -> tuple[jax.Array, jax.Array]:  # fmt: skip
    """Position error |p* − p| and orientation error (rad): the angle between the tool
    axes (``axis``) or of R*ᵀR (``pose``); 0 for ``position``."""
    pos = jnp.linalg.norm(p_t - p, axis=-1)
    if mode == "position":
        return pos, jnp.zeros_like(pos)
    if mode == "axis":
        z, zt = R[..., :, 2], R_t[..., :, 2]
        return pos, jnp.arctan2(jnp.linalg.norm(jnp.cross(z, zt), axis=-1), jnp.sum(z * zt, -1))
    Rr = jnp.einsum("...ji,...jk->...ik", R_t, R)
    tr = Rr[..., 0, 0] + Rr[..., 1, 1] + Rr[..., 2, 2]
    w = jnp.stack([Rr[..., 2, 1] - Rr[..., 1, 2], Rr[..., 0, 2] - Rr[..., 2, 0],
                   Rr[..., 1, 0] - Rr[..., 0, 1]], -1)  # fmt: skip
    return pos, jnp.arctan2(jnp.linalg.norm(w, axis=-1), tr - 1.0)


def revolute(model: SerialModel) -> tuple[bool, ...]:
    """Per active joint: does it drive a revolute chain joint?"""
    C = model.coupling
    return tuple(any(C[i][j] != 0 and model.joint_types[i] == "R" for i in range(len(C)))
                 for j in range(model.n_active))  # fmt: skip


# -------------------------------------------------------------------------- seeds


def _spread3(x: jax.Array) -> jax.Array:
    """The low 10 bits of x moved to every third bit (uint32)."""
    x = x.astype(jnp.uint32) & 0x3FF
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    return (x | (x << 2)) & 0x09249249


def _morton(p: jax.Array, lo: jax.Array, scale: jax.Array) -> jax.Array:
    """Z-order code of positions p (..., 3) on a 1024³ grid."""
    g = jnp.clip(jnp.floor((p - lo) * scale), 0, 1023).astype(jnp.int32)
    return _spread3(g[..., 0]) | (_spread3(g[..., 1]) << 1) | (_spread3(g[..., 2]) << 2)


def _features(p: jax.Array, R: jax.Array | None, L: jax.Array, mode: Mode) -> jax.Array:
    """(..., F) points whose squared distance is |Δp|²/L² (+ (1 − z·z*) for ``axis``,
    + (3 − tr RᵀR*)/2 for ``pose``)."""
    f = [p / L]
    if mode == "axis":
        f.append(R[..., :, 2] / math.sqrt(2.0))
    elif mode == "pose":
        f.append(R.reshape(R.shape[:-2] + (9,)) / 2.0)
    return jnp.concatenate(f, -1)


def _index(q_db: jax.Array, p_db: jax.Array, R_db: jax.Array, L: jax.Array, mode: Mode):
    """One design's database sorted by the Z-order code of its positions: (lo, scale,
    codes (N,), features (F, N), joints (N, n)). The sort carries the features and joints
    along, which also materialises them (a gather from them would otherwise recompute
    the FK for every gathered element)."""
    lo = jnp.min(p_db, 0)
    scale = 1023.0 / jnp.maximum(jnp.max(jnp.max(p_db, 0) - lo), jnp.finfo(p_db.dtype).tiny)
    f = _features(p_db, R_db, L, mode)
    ops = jax.lax.sort((_morton(p_db, lo, scale), *f.T, *q_db.T), num_keys=1)
    nf = f.shape[1]
    return lo, scale, ops[0], jnp.stack(ops[1 : 1 + nf]), jnp.stack(ops[1 + nf :], -1)


_CHUNK = 8192  # targets per nearest-entry search (bounds the T × window intermediates)


def _joint_gap(a: jax.Array, b: jax.Array, rev: tuple[bool, ...], L: jax.Array) -> jax.Array:
    """The largest joint difference of configurations a and b (..., n): revolute joints
    by their angle apart (wrapped to [0, π]), prismatic ones in units of the reach L
    (a scalar or (...,))."""
    d = a - b
    r = jnp.asarray(rev)
    d = jnp.where(r, jnp.abs(jnp.remainder(d + math.pi, 2 * math.pi) - math.pi),
                  jnp.abs(d) / jnp.asarray(L)[..., None])
    return jnp.max(d, -1)


def _nearest(index, p_t: jax.Array, R_t: jax.Array | None, L: jax.Array, mode: Mode,
             k: int, window: int, rev: tuple[bool, ...] = ()) -> jax.Array:  # fmt: skip
    """(T, k) indices into one design's sorted database (:func:`_index`) of k entries
    near each target among the ``window`` entries around its own Z-order code (binary
    search): the nearest by :func:`_features` distance first, then, of the 2k nearest,
    each next the one farthest in joint space from those already picked (greedy
    farthest-point, :func:`_joint_gap`), so that the seeds start on different branches of
    the arm (shoulder, elbow, wrist sides) rather than on one. ``rev``: the joints'
    kinds (empty: the k nearest, in order)."""
    lo, scale, code, f_db, q_db = index
    n = code.shape[0]
    W = min(window, n)
    T = p_t.shape[0]
    C = min(T, _CHUNK)
    pad = -T % C
    f_t = _features(p_t, R_t, L, mode)
    code_t = _morton(p_t, lo, scale)
    f_t = jnp.concatenate([f_t, jnp.repeat(f_t[-1:], pad, 0)]).reshape(-1, C, f_t.shape[1])
    code_t = jnp.concatenate([code_t, jnp.repeat(code_t[-1:], pad)]).reshape(-1, C)

    def chunk(args):
        ct, ft = args
        i = jnp.searchsorted(code, ct)
        cand = jnp.clip(i - W // 2, 0, n - W)[:, None] + jnp.arange(W)  # (C, W)
        d = sum((f_db[j][cand] - ft[:, j, None]) ** 2 for j in range(f_db.shape[0]))
        picks = []
        P = min(k if not rev else 2 * k, W)  # the pool the spread seeds come from
        for _ in range(P):
            j = jnp.argmin(d, 1)
            picks.append(j)
            d = jnp.where(jnp.arange(W) == j[:, None], jnp.inf, d)
        pool = jnp.take_along_axis(cand, jnp.stack(picks, 1), 1).astype(jnp.int32)  # (C, P)
        if not rev or k <= 1:
            return pool[:, :k]
        qp = q_db[pool]  # (C, P, n)
        chosen = [jnp.zeros((C,), jnp.int32)]
        gap = _joint_gap(qp, qp[:, :1], rev, L)  # (C, P)
        for _ in range(min(k, P) - 1):
            j = jnp.argmax(gap, 1).astype(jnp.int32)
            chosen.append(j)
            qj = jnp.take_along_axis(qp, j[:, None, None], 1)
            gap = jnp.minimum(gap, _joint_gap(qp, qj, rev, L))
        return jnp.take_along_axis(pool, jnp.stack(chosen, 1), 1)

    return jax.lax.map(chunk, (code_t, f_t)).reshape(-1, min(k, W))[:T]


def _fk_arrays(ch: _Chain, X: jax.Array, q: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(R (M, N, 3, 3), p (M, N, 3)) of joints q (N, n) for every design X (M, D)."""
    M, N = X.shape[0], q.shape[0]
    one = _one(q)
    qc = [jnp.tile(q[:, i] / one, M) for i in range(ch.n)]
    xc = [jnp.repeat(X[:, k], N) for k in range(ch.D)]
    R, p, _ = ch.fk(xc, qc, ch.trig_q(qc, one=one), ch.trig_x(xc))
    R = [[jnp.broadcast_to(jnp.asarray(x, q.dtype), (M * N,)) / one for x in row] for row in R]
    p = [jnp.broadcast_to(jnp.asarray(x, q.dtype), (M * N,)) / one for x in p]
    Ra = jnp.stack([jnp.stack(row, -1) for row in R], -2).reshape(M, N, 3, 3)
    return Ra, jnp.stack(p, -1).reshape(M, N, 3)


# ------------------------------------------------------------------------- solver


def _phases(B: int) -> tuple[int, ...]:
    """B, B/8, B/64, … (not below 32): the solver's slots, then the slots per chunk of
    steps (``B/8``). (Once the successive batches' slot counts, each compiled apart.)"""
    out = [B]
    while out[-1] // 8 >= 32:
        out.append(out[-1] // 8)
    return tuple(out)


def _materialised(r: IKResult) -> IKResult:
    """The fields computed once (XLA would otherwise fuse the final check, FK and
    condition number included, into each consumer of each field: a copy per use)."""
    return IKResult(*jax.lax.optimization_barrier(tuple(r)))


def _check(mode: Mode, R_t, opts: IKOptions) -> None:
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if mode != "position" and R_t is None:
        raise ValueError(f"mode {mode!r} needs target orientations R_t")
    if min(opts.iters, opts.block, opts.n_db, opts.window, opts.n_best) < 1:
        raise ValueError("IKOptions: iters, block, n_db, window and n_best must be ≥ 1")
    if opts.climb < 0:
        raise ValueError("IKOptions: climb must be ≥ 0")
    if not 0 <= opts.neighbours < NEIGHBOUR_GROUP:
        raise ValueError(f"IKOptions: neighbours must be in [0, {NEIGHBOUR_GROUP - 1}]")


def solve(model: SerialModel, X: jax.Array, p_t: jax.Array, R_t: jax.Array | None,
          lower: jax.Array, upper: jax.Array, key: jax.Array, mode: Mode = "position",
          opts: IKOptions = DEFAULTS,
          score: Callable[[jax.Array], jax.Array] | None = None,
          accept: Callable[[jax.Array, jax.Array, jax.Array], jax.Array] | None = None,
          t0: jax.Array | int = 0, rep: jax.Array | None = None,
          hopeless: jax.Array | None = None, n_keep: jax.Array | None = None,
          groups: int = 1, run: int = 1) -> IKResult:  # fmt: skip
    """IK of the same T targets (p_t (T, 3), R_t (T, 3, 3) or None) for M designs
    X (M, D), or of each design's own T targets (p_t (M, T, 3), R_t (M, T, 3, 3)): every
    field has leading axes (M, T). The database draws and the seeds' hashes are shared
    by the designs (common random numbers); the designs' targets share one queue of
    slots. With ``opts.n_best`` > 1 a target's solver goes on after a seed converged,
    until ``n_best`` distinct solutions have (or its seeds run out), and keeps the
    solution of highest ``score(m, t, q)`` (rows: design indices (B,), target indices
    (B,), joints (B, n) → (B,); default the 2-norm 1/k of the position Jacobian,
    :attr:`IKResult.inv_k`), each first climbed along its self-motion when
    ``opts.climb`` > 0 (:func:`_climb`). ``accept(m, t, q)`` (design indices (B,), target indices
    (B,), joints (B, n) → bool (B,)), e.g. "collision-free": a converged seed it refuses
    is dropped like one that failed and the target goes on with its next seed; only
    accepted solutions count as successes (and towards ``n_best``). ``t0`` (an array
    input): the index of the first target in the task's whole list; a target's random
    seeds hash its index there, so a task solved in chunks of any size gets the seeds it
    gets in one piece. ``rep`` (M,) int (an array input): each design's representative,
    a design whose targets and chain are the same (``rep[m] ≤ m``, ``rep[rep[m]] ==
    rep[m]``, e.g. :func:`representatives`): only representatives' items enter the
    queue, and every other design's fields are copied from its representative's. Items
    are independent and their seeds hash (target, attempt), not the design, so the copy
    is what solving it again would give; a block of copies (a padded block, a swarm
    that met at one point) costs one design's work. ``hopeless`` (M, T) bool (an array
    input): items that no solution can serve (``accept`` refuses every one, or the caller
    rejects every one: a target out of an instrument's insertion range, its shaft through
    the anatomy): they get one seed, not all of them, and their joints are that seed's
    end (a failure's joints either way). ``n_keep`` (an int array input, 1 ≤ ``n_keep``
    ≤ ``opts.n_best``): the distinct solutions a target's solver looks for, when fewer
    than the ``opts.n_best`` solution slots the program holds, so that one compiled
    program serves every count up to it (its slots beyond ``n_keep`` stay unused; the
    result is the one ``opts.n_best = n_keep`` gives). ``opts.neighbours`` = k > 0: a
    second pass over the items (a loop over the same program), each seeded with the kept
    joints of its k nearest reached targets of the same design among its run of
    :data:`NEIGHBOUR_GROUP` (:func:`_neighbour_seeds`); its solution replaces the first
    pass's where it scores higher. A task solved in chunks that are multiples of the run
    (``t0`` too) gets the values of one piece. ``groups`` = G > 1 (static): the task's
    targets fall into G interleaved groups, target ``t0 + t`` in group
    ``((t0 + t) // run) % G`` (runs of ``run`` targets: :data:`NEIGHBOUR_GROUP` with
    ``neighbours``, so that a neighbour is always of the target's own group), and each
    group draws its own database (``opts.n_db`` entries, from the key's database draw
    at index g), which its targets' nearest and random seeds come from: the groups are
    independent replications of the whole solve, whose spread is the standard error of
    an index read at the solutions (:func:`group_of`; G = 1: one database, as before)."""
    _check(mode, R_t, opts)
    X = jnp.asarray(X)
    per_design = p_t.ndim == 3
    M, T, n = X.shape[0], p_t.shape[-2], lower.shape[0]
    I = M * T  # noqa: E741  (items: design-major)
    dtype = p_t.dtype
    ch = _Chain(model)
    rev = ch.rev
    k_db, k_hash = jax.random.split(key)

    G = max(int(groups), 1)
    t_base = jnp.asarray(t0).astype(jnp.uint32)  # the chunk's first target in the task
    # each target's group (T,): its database (all 0 with one group)
    grp = group_of(jnp.arange(T, dtype=jnp.int32) + jnp.asarray(t0, jnp.int32), G, run)
    # the databases: one set of joints per group, FK per design, each sorted by Z order
    if G == 1:
        u = jax.random.uniform(k_db, (opts.n_db, n), dtype=dtype)
    else:
        u = jax.random.uniform(k_db, (G, opts.n_db, n), dtype=dtype).reshape(-1, n)
    q_db = lower + u * (upper - lower)  # (G·n_db, n)
    one = _one(q_db)  # from data every design shares: a NaN design must not touch the others
    qg = q_db.reshape(G, opts.n_db, n)
    n_near = min(opts.n_nearest, opts.n_db, opts.window)
    # a design's databases and its targets' nearest entries are made for representatives
    # only (a block of copies, eval's one design, pays for one; the rest copy theirs)
    if G > 1:  # the targets by group: each group's in task order, where it starts, its size
        g_order = jnp.argsort(grp, stable=True)
        g_count = jnp.sum(grp[None, :] == jnp.arange(G)[:, None], 1)
        g_start = jnp.cumsum(g_count) - g_count
        g_place = jnp.zeros((T,), jnp.int32).at[g_order].set(jnp.arange(T, dtype=jnp.int32)) \
            - g_start[grp]  # each target's place among its group's  # fmt: skip
        r_ = max(int(run), 1)
        K_g = min(T, (T // (r_ * G) + 2) * r_)  # a group's most targets in T consecutive ones
    is_rep = (jnp.ones((M,), bool) if rep is None
              else jnp.asarray(rep, jnp.int32) == jnp.arange(M, dtype=jnp.int32))  # fmt: skip

    def database(m):
        """Design m's reach L, its G sorted databases (:func:`_index`, each (G, ...)) and
        its targets' nearest entries in their own group's database (T, k)."""
        R_m, p_m = _fk_arrays(ch, X[m][None], q_db)  # (1, G·n_db, ...)
        L_m = jnp.maximum(jnp.max(jnp.linalg.norm(p_m[0] - jnp.mean(p_m[0], 0), axis=-1)),
                          1e-12)  # fmt: skip
        idx = jax.vmap(lambda q, p, R: _index(q, p, R, L_m, mode))(
            qg, p_m.reshape(G, opts.n_db, 3), R_m.reshape(G, opts.n_db, 3, 3))  # fmt: skip
        if not n_near:
            return L_m, idx, jnp.zeros((T, 1), jnp.int32)
        pt_m = p_t[m] if per_design else p_t
        Rt_m = None if R_t is None else R_t[m] if per_design else R_t
        if G == 1:
            return L_m, idx, _nearest(jax.tree_util.tree_map(lambda a: a[0], idx), pt_m, Rt_m,
                                      L_m, mode, n_near, opts.window, rev)  # fmt: skip
        # each group's own targets (K places, the last repeated) in its own database
        sel = jnp.minimum(g_start[:, None] + jnp.arange(K_g)[None, :],
                          g_start[:, None] + jnp.maximum(g_count[:, None], 1) - 1)  # (G, K)
        tg = g_order[sel]  # (G, K) target indices
        nr = jax.lax.map(lambda a: _nearest(a[0], pt_m[a[1]], None if Rt_m is None else
                                            Rt_m[a[1]], L_m, mode, n_near, opts.window, rev),
                         (idx, tg))  # (G, K, k)  # fmt: skip
        return L_m, idx, nr[grp, g_place]

    blank = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype),
                                   jax.eval_shape(database, jnp.int32(0)))  # fmt: skip
    L, index, near = jax.lax.map(
        lambda m: jax.lax.cond(is_rep[m], database, lambda m: blank, m),
        jnp.arange(M, dtype=jnp.int32))  # fmt: skip
    if rep is not None:
        L, index, near = jax.tree_util.tree_map(lambda a: a[jnp.asarray(rep, jnp.int32)],
                                                (L, index, near))  # fmt: skip
    q_sorted = index[4]  # (M, G, n_db, n)
    attempts = max(n_near + opts.n_random * opts.rounds, 1)
    K_nb = opts.neighbours  # seeds of the neighbour pass (0: no such pass)
    salt = jax.random.bits(k_hash, (), jnp.uint32)
    xT = X.T  # (D, M)
    # (3, T) or, per design, (3, M·T) by item; R: row 3i + j holds R[i, j]
    ptT = p_t.reshape(-1, 3).T
    RtT = None if R_t is None else R_t.reshape(-1, 9).T
    tcol = (lambda i, t: jnp.minimum(i, I - 1)) if per_design else (lambda i, t: t)  # noqa: E731
    cols = () if mode == "position" else (2,) if mode == "axis" else (0, 1, 2)
    tol_p2, tol_r2 = (0.5 * opts.tol_pos) ** 2, (0.5 * opts.tol_rot) ** 2
    rows = _rows(mode)
    iters = -(-opts.iters // opts.block) * opts.block

    def split(i):
        ic = jnp.minimum(i, I - 1)
        return ic // T, ic % T

    def seed(i, a):
        """Joints (n, B) of seed a of items i: a nearest entry, then hashed ones."""
        m, t = split(i)
        a_near = near[m, t, jnp.minimum(a, near.shape[2] - 1)]
        h = ((t.astype(jnp.uint32) + t_base) * jnp.uint32(2654435761)
             ^ (a.astype(jnp.uint32) + salt) * jnp.uint32(2246822519))  # fmt: skip
        h = h ^ (h >> 15)
        a_rand = (h % jnp.uint32(opts.n_db)).astype(jnp.int32)
        q = q_sorted[m, grp[t], jnp.where(a < n_near, a_near, a_rand)].T
        if not K_nb:
            return q
        # a neighbour pass: seed a is the kept joints of the item's a-th nearest neighbour
        given = ctx["S"][m, t, jnp.clip(a, 0, K_nb - 1)].T
        return jnp.where(ctx["pass"] > 0, given, q)

    def block(i, qc):
        """``opts.block`` steps from qc (frozen where converged) for items i. Returns
        (qc, converged, the least E = ½|e|² met); ``accept`` is asked in the round, of
        the converged seeds that are no duplicate."""
        m, t = split(i)
        xc = [xT[k, m] for k in range(ch.D)]
        tx = ch.trig_x(xc)
        Lm = L[m]
        tc = tcol(i, t)
        pt = [ptT[j, tc] for j in range(3)]
        Rt = None
        if RtT is not None:
            Rt = [[RtT[3 * r + c, tc] if c in cols else 0.0 for c in range(3)] for r in range(3)]

        def body(_, c):
            qc, tq, conv, Em = c
            R, p, J = ch.fk(xc, qc, tq, tx, rows)
            e, J, cz = _residual(R, p, J, pt, Rt, mode, 1.0 / Lm)
            e = [_keep(x, one) for x in e]
            J = [[_keep(x, one) for x in r] for r in J]
            ok = _dot(e[:3], e[:3]) <= tol_p2
            if mode != "position":
                ok = ok & (_dot(e[3:], e[3:]) <= tol_r2) & (cz > 0)
            E = 0.5 * _dot(e, e)
            dq = _lm_step(e, J, rev, Lm, opts.damping_e * E + opts.damping, qc, lower, upper)
            new = _project([x + d for x, d in zip(qc, dq, strict=True)], lower, upper, rev)
            qc = [jnp.where(ok, a, b) for a, b in zip(qc, new, strict=True)]
            return qc, ch.trig_q(qc), ok, jnp.minimum(Em, E)

        z = jnp.zeros_like(qc[0])
        c0 = (qc, ch.trig_q(qc), z > 0, z + jnp.inf)
        qc, _, ok, Em = jax.lax.fori_loop(0, opts.block, body, c0)
        return qc, ok, Em

    nb = opts.n_best  # solution slots (the program's shapes)
    # distinct solutions sought: the slots, or the runtime count n_keep (loop bounds)
    nk = nb if n_keep is None or nb == 1 else jnp.clip(jnp.asarray(n_keep, jnp.int32), 1, nb)
    B0 = opts.slots if opts.slots > 0 else max(1024, min(4096, I // 4))
    B = min(I, B0)
    C = _phases(B)[1] if len(_phases(B)) > 1 else B  # slots per block call
    Bp = -(-B // C) * C  # slots, a multiple of C (the extra ones never busy)

    def blocks(i, q):
        """:func:`block` on the busy slots (a prefix, :func:`compact`), C at a time: the
        step's program is compiled once, for C slots, and the hard tail (few busy
        slots) runs few of them."""
        busy = jnp.sum(i < I, dtype=jnp.int32)

        def chunk(k, c):
            q, ok, Em = c
            o = (k * C).astype(jnp.int32)
            qk = [jax.lax.dynamic_slice(q[j], (o,), (C,)) for j in range(n)]
            qc, okk, Emk = block(jax.lax.dynamic_slice(i, (o,), (C,)), qk)
            return (jax.lax.dynamic_update_slice(q, jnp.stack(qc), (jnp.int32(0), o)),
                    jax.lax.dynamic_update_slice(ok, okk, (o,)),
                    jax.lax.dynamic_update_slice(Em, Emk, (o,)))  # fmt: skip

        c0 = (q, jnp.zeros(i.shape, bool), jnp.full(i.shape, jnp.inf, dtype))
        q, ok, Em = jax.lax.fori_loop(0, (busy + C - 1) // C, chunk, c0)
        return list(q), ok, Em

    def compact(s):
        """The busy slots moved to the front, in their order (a slot's place changes no
        item's result). While the queue holds pairs every slot is busy: nothing moves."""
        busy = s[0] < I
        nb_ = jnp.sum(busy, dtype=jnp.int32)
        to = jnp.where(busy, jnp.cumsum(busy, dtype=jnp.int32) - 1,
                       nb_ + jnp.cumsum(~busy, dtype=jnp.int32) - 1)  # fmt: skip
        return (*(jnp.zeros_like(x).at[to].set(x, unique_indices=True) for x in s[:4]),
                jnp.zeros_like(s[4]).at[:, to].set(s[4], unique_indices=True), *s[5:])  # fmt: skip

    def inv_k_rows(m, t, q):  # the default score: the 2-norm 1/k of the position Jacobian
        xr = [xT[k, m] for k in range(ch.D)]
        qc = [q[:, j] for j in range(n)]
        _, _, J = ch.fk(xr, qc, ch.trig_q(qc, exact=True), ch.trig_x(xr), (0, 1, 2))
        B = q.shape[0]
        return inv_cond(jnp.stack([jnp.stack([jnp.broadcast_to(jnp.asarray(x, dtype), (B,))
                                              for x in row], -1) for row in J], -2), "2")  # fmt: skip

    score_rows = inv_k_rows if score is None else score

    def round_(s):
        i, a, it, Eb, q, head, tail, qi, qa, q_out, a_out, E_out, nc, n_try, n_ref, sc_out = s
        active = i < I
        ic = jnp.minimum(i, I - 1)
        qc, ok, Em = blocks(i, q)
        q = jnp.stack(qc)
        it = it + opts.block
        n_conv = nc[ic]
        m_, t_ = split(i)
        qT = q.T
        dup = jnp.zeros_like(ok)
        sc_new = jnp.zeros(ok.shape, dtype)
        if nb > 1:  # a solution the item has already found (the same joints, or the same
            # score: a self-motion the score is flat along, a symmetric branch) is no new
            # one: the item goes on with its next seed (n_best counts distinct solutions)
            sc_new = on_rows(lambda r: score_rows(m_[r], t_[r], qT[r]), ok,
                             max(C // 4, 1))  # fmt: skip

            def same(c, dup):
                qs = jax.lax.dynamic_slice_in_dim(q_out, c * I, I, 1)[:, ic]  # (n, B)
                ss = sc_out[c * I + ic]
                near_ = (_joint_gap(qT, qs.T, rev, L[ic // T]) <= DUPLICATE) | (
                    jnp.abs(sc_new - ss) <= DUPLICATE_SCORE * jnp.maximum(1.0, jnp.abs(ss)))
                return dup | ((c < n_conv) & near_)

            dup = ok & jax.lax.fori_loop(0, nk, same, dup)
            ok = ok & ~dup
        refused = jnp.zeros_like(ok)
        if accept is not None:  # asked of the converged slots that bring a new solution
            # only (a collision check costs several LM blocks; a duplicate's joints are
            # those of a solution the item holds, accepted already)
            acc = on_rows(lambda r: accept(m_[r], t_[r], qT[r]), ok, max(C // 4, 1))
            refused = ok & ~acc
            ok = ok & acc
        # a seed is dropped when it used its steps or its least error stopped falling, or
        # converged to joints ``accept`` refuses
        stalled = ~(Em < opts.stall * Eb)
        Eb = jnp.minimum(Eb, Em)
        give_up = ~ok & ~dup & ((it >= iters) | stalled | refused)
        last = a + 1 >= (attempts if not K_nb else jnp.where(ctx["pass"] > 0, K_nb, attempts))
        if hopeless is not None:  # one seed only: no solution can be kept
            last = last | one_seed[ic]
        # converged joints go to the item's next solution slot (of n_best); a dropped
        # seed's joints go to slot 0 when the item has none and they beat its best so far
        better = Em < E_out[ic]
        idx = jnp.where(active & ok, n_conv * I + i,
                        jnp.where(active & give_up & better, i, nb * I))  # fmt: skip
        q_out = q_out.at[:, idx].set(q, mode="drop")
        a_out = a_out.at[idx].set(a, mode="drop")
        sc_out = sc_out.at[jnp.where(active & ok, idx, nb * I)].set(sc_new, mode="drop")
        E_out = E_out.at[jnp.where(idx < nb * I, i, I)].set(jnp.where(ok, -1.0, Em), mode="drop")
        nc = nc.at[jnp.where(active & ok, i, I)].add(1, mode="drop")
        n_try = n_try.at[jnp.where(active, i, I)].max(a + 1, mode="drop")
        n_ref = n_ref.at[jnp.where(active & refused, i, I)].add(1, mode="drop")
        more = (ok & (n_conv + 1 < nk)) | dup  # n_best asks for another (new) solution
        retry = active & (give_up | more) & ~last
        free = active & (ok | give_up | dup)
        # an item whose seed was dropped goes to the back of the queue with its next seed
        at = jnp.where(retry, (tail + jnp.cumsum(retry, dtype=jnp.int32) - 1) % I, I)
        qi, qa = qi.at[at].set(i, mode="drop"), qa.at[at].set(a + 1, mode="drop")
        tail = tail + jnp.sum(retry, dtype=jnp.int32)
        # free slots take the queue's next (item, seed)
        pos = head + jnp.cumsum(free, dtype=jnp.int32) - 1
        take = free & (pos < tail)
        i = jnp.where(take, qi[pos % I], jnp.where(free, I, i))
        a = jnp.where(take, qa[pos % I], a)
        head = jnp.minimum(head + jnp.sum(free, dtype=jnp.int32), tail)
        it = jnp.where(free, 0, it)
        Eb = jnp.where(free, jnp.inf, Eb)
        q = jnp.where(take[None], seed(i, a), q)
        return i, a, it, Eb, q, head, tail, qi, qa, q_out, a_out, E_out, nc, n_try, n_ref, sc_out

    def copied(r: IKResult) -> IKResult:  # every design's fields from its representative's
        return r if rep is None else IKResult(*(x[jnp.asarray(rep, jnp.int32)] for x in r))

    one_seed = None if hopeless is None else jnp.broadcast_to(hopeless, (M, T)).reshape(I)
    solved = (jnp.ones((I,), bool) if rep is None else
              jnp.repeat(jnp.asarray(rep, jnp.int32) == jnp.arange(M, dtype=jnp.int32), T))  # fmt: skip
    ctx: dict = {"pass": 0, "S": None}  # the pass being traced (:func:`attempt`), read by seed

    def attempt(pass_, S, has=None):
        """One pass of the queue over the items (pass 0: the database seeds; a
        neighbour pass: the seeds ``S`` (M, T, K, n), for the items with a reached
        neighbour, ``has`` (M, T)) and the pick of each item's best solution: (its
        fields, its score (−inf where none is accepted))."""
        ctx["pass"], ctx["S"] = pass_, S
        # the queue: the representatives' items, in order (all of them without ``rep``);
        # a neighbour pass leaves out the hopeless ones
        if rep is None and not K_nb:
            order, n_items = jnp.arange(I, dtype=jnp.int32), jnp.asarray(I, jnp.int32)
        else:
            queued = solved
            if K_nb:
                out = ~has.reshape(I) if one_seed is None else ~has.reshape(I) | one_seed
                queued = solved & ~((pass_ > 0) & out)
            order = jnp.argsort(~queued, stable=True).astype(jnp.int32)
            n_items = jnp.sum(queued, dtype=jnp.int32)
        k0 = jnp.arange(Bp, dtype=jnp.int32)
        i = jnp.where(k0 < jnp.minimum(B, n_items), order[jnp.minimum(k0, I - 1)], I)
        a = jnp.zeros_like(i)
        s = (i, a, a, jnp.full(i.shape, jnp.inf, dtype), seed(i, a),
             jnp.minimum(jnp.asarray(B, jnp.int32), n_items), n_items,
             order, jnp.zeros((I,), jnp.int32),
             jnp.zeros((n, nb * I), dtype), jnp.zeros((nb * I,), jnp.int32),
             jnp.full((I,), jnp.inf, dtype), jnp.zeros((I,), jnp.int32),
             jnp.zeros((I,), jnp.int32), jnp.zeros((I,), jnp.int32),
             jnp.zeros((nb * I if nb > 1 else 1,), dtype))  # fmt: skip

        s = jax.lax.while_loop(lambda s: jnp.any(s[0] < I), lambda s: round_(compact(s)), s)
        q_out, a_out, n_conv = s[9], s[10], s[12].reshape(M, T)
        tries, refusals = s[13].reshape(M, T), s[14].reshape(M, T)

        # the returned joints, checked afresh with XLA's sin and cos; of several converged
        # solutions, the one of highest score, each first climbed along its self-motion
        xc = [jnp.repeat(X[:, k], T) for k in range(ch.D)]
        tx = ch.trig_x(xc)
        n_conv_f = s[12]

        def arr(x):
            return jnp.broadcast_to(jnp.asarray(x, dtype), (I,))

        def climb(r, q0):
            """Rows r (items, (k,)) from their converged joints q0 (k, n) up the score along
            the null space of the target's rows (:func:`_climb`): the climbed joints where
            they are converged, within the limits, accepted and better; else q0."""
            m, t = split(r)
            xr = [xT[k, m] for k in range(ch.D)]
            tc = tcol(r, t)
            pt = [ptT[j, tc] for j in range(3)]
            Rt = None
            if RtT is not None:
                Rt = [[RtT[3 * a + b, tc] if b in cols else 0.0 for b in range(3)] for a in range(3)]
            return _climb(ch, xr, pt, Rt, L[m], mode, rev, lower, upper, opts,
                          lambda q: score_rows(m, t, q),
                          None if accept is None else (lambda q: accept(m, t, q)), q0)  # fmt: skip

        def result(c):
            """The solutions of slot c (of n_best), climbed, checked afresh, and scored."""
            qc = [jax.lax.dynamic_slice_in_dim(q_out[j], c * I, I) for j in range(n)]
            climbed = None
            if opts.climb > 0:  # a representative's converged (and accepted) solutions
                climbed = (c < n_conv_f) & solved
                qf = jnp.stack(qc, -1)
                qn = on_rows(lambda r: climb(r, qf[r]), climbed, min(I, CLIMB_ROWS))
                qf = jnp.where(climbed[:, None], qn, qf)
                qc = [qf[:, j] for j in range(n)]
            R, p, J = ch.fk(xc, qc, ch.trig_q(qc, exact=True, one=one), tx, (0, 1, 2))
            Ra = jnp.stack([jnp.stack([arr(x) for x in row], -1) for row in R], -2)
            pa = jnp.stack([arr(x) for x in p], -1).reshape(M, T, 3)
            Ja = jnp.stack([jnp.stack([arr(x) for x in row], -1) for row in J], -2)
            pe, re = errors(pa, Ra.reshape(M, T, 3, 3), p_t if per_design else p_t[None],
                            None if R_t is None else R_t if per_design else R_t[None], mode)  # fmt: skip
            q = jnp.stack(qc, -1).reshape(M, T, n)
            inside = jnp.all((q >= lower) & (q <= upper), -1)
            conv = (pe <= opts.tol_pos * L[:, None]) & (re <= opts.tol_rot) & inside
            ok = conv
            if accept is not None:  # (a climbed row's joints were accepted by the climb)
                qf, cf = q.reshape(I, n), conv.reshape(I)
                need = cf if climbed is None else cf & ~climbed
                acc = on_rows(lambda r: accept(r // T, r % T, qf[r]), need, min(I, CHECK_ROWS))
                ok = conv & (acc if climbed is None else acc | climbed).reshape(M, T)
            ik_ = inv_cond(Ja.reshape(M, T, 3, n), "2")
            a_c = jax.lax.dynamic_slice_in_dim(a_out, c * I, I).reshape(M, T)
            return IKResult(q, ok, pe, re, ik_, a_c, conv, tries, refusals)

        if nb == 1 and not K_nb:
            return result(0), None

        def pick(c, carry):
            """Slot c's solutions replace the best so far where they score higher (slot 0's
            always: a target's solution when none converged is there)."""
            best, sc_best = carry
            r = result(c)
            ok = r.success & ((c == 0) | (c < n_conv))
            if score is None:
                val = r.inv_k
            else:
                qf = r.q.reshape(I, n)
                val = on_rows(lambda rr: score(rr // T, rr % T, qf[rr]), ok.reshape(I),
                              min(I, CHECK_ROWS)).reshape(M, T)  # fmt: skip
            sc = jnp.where(ok, jnp.nan_to_num(val, nan=-jnp.inf), -jnp.inf)
            take = jax.lax.optimization_barrier((c == 0) | (sc > sc_best))
            best = IKResult(*(jnp.where(take.reshape(take.shape + (1,) * (x.ndim - 2)), y, x)
                              for x, y in zip(best, r, strict=True)))  # fmt: skip
            return best, jnp.where(take, sc, sc_best)

        z = jnp.zeros((M, T), dtype)
        best0 = IKResult(jnp.zeros((M, T, n), dtype), z > 0, z, z, z, jnp.zeros((M, T), jnp.int32),
                         z > 0, tries, refusals)
        return jax.lax.fori_loop(0, nk, pick, (best0, jnp.full((M, T), -jnp.inf, dtype)))

    if not K_nb:
        return _materialised(copied(attempt(0, None)[0]))

    def passes(k, carry):
        """Pass k (0: the database seeds, 1: the neighbours' solutions): its solutions
        replace the best so far where they score higher."""
        best, sc = carry
        S, has = _neighbour_seeds(p_t, best.q, best.success, t0, K_nb)
        b, sc_k = attempt(k, S, has)
        take = jax.lax.optimization_barrier((k == 0) | (sc_k > sc))
        tried = (b.tries + best.tries, b.refused + best.refused)
        b = b._replace(seed=b.seed + jnp.where(k > 0, attempts, 0))  # after pass 0's
        best = IKResult(*(jnp.where(take.reshape(take.shape + (1,) * (x.ndim - 2)), y, x)
                          for x, y in zip(best[:7], b[:7], strict=True)), *tried)  # fmt: skip
        return best, jnp.where(take, sc_k, sc)

    zi = jnp.zeros((M, T), jnp.int32)
    zf = zi.astype(dtype)
    best0 = IKResult(jnp.zeros((M, T, n), dtype), zi > 0, zf, zf, zf, zi, zi > 0, zi, zi)
    best, _ = jax.lax.fori_loop(0, 2, passes, (best0, jnp.full((M, T), -jnp.inf, dtype)))
    return _materialised(copied(best))


def group_of(t: jax.Array, groups: int, run: int = 1) -> jax.Array:
    """The replication group of task targets ``t`` (int): ``(t // run) % groups``
    (:func:`solve`'s ``groups``): interleaved runs of ``run`` targets."""
    t = jnp.asarray(t, jnp.int32)
    return (t // max(int(run), 1)) % max(int(groups), 1)


NEIGHBOUR_GROUP = 16
"""Targets per neighbourhood of the neighbour pass (``IKOptions.neighbours``): a target's
neighbours are found among the targets of its group, the task's targets ``t0 + t`` cut
into runs of this many from the first, so a task solved in chunks that are multiples of
it (or in one piece) gets the values of one piece."""


def _neighbour_seeds(p_t: jax.Array, q: jax.Array, ok: jax.Array, t0: jax.Array | int,
                     k: int) -> tuple[jax.Array, jax.Array]:
    """The seeds of the neighbour pass (M, T, k, n): for each target of each design, the
    kept joints ``q`` (M, T, n) of its k nearest reached (``ok`` (M, T)) targets of its
    group (:data:`NEIGHBOUR_GROUP`; targets ``p_t`` (T, 3) or (M, T, 3), ``t0`` the first
    one's index in the task; the distance between tip positions: targets that differ in
    their tool axes alone are at one point). Of targets at one point only the first
    counts (a padded chunk's copies of its last target are none); a target with fewer
    than k such neighbours gets its own joints in the free places. Also (M, T): whether
    a target has any."""
    M, T, n = q.shape
    G = NEIGHBOUR_GROUP
    P = jnp.broadcast_to(p_t, (M, T, 3))
    t = jnp.arange(T, dtype=jnp.int32)
    # the groups: positions in the task t0 + t, cut at multiples of G (t0 % G of the first
    # group lie before this chunk)
    off = jnp.asarray(t0, jnp.int32) % G
    Tg = -(-(T + G - 1) // G) * G  # room for the offset
    slot = t + off  # each target's place in the padded run of groups
    pad = lambda x, fill: jnp.full((M, Tg, *x.shape[2:]), fill, x.dtype).at[:, slot].set(x)  # noqa: E731
    Pg = pad(P, jnp.nan).reshape(M, Tg // G, G, 3)
    okg = pad(ok, False).reshape(M, Tg // G, G)
    d2 = jnp.sum((Pg[:, :, :, None] - Pg[:, :, None]) ** 2, -1)  # (M, g, G, G)
    same = jnp.all(Pg[:, :, :, None] == Pg[:, :, None], -1)
    lower = jnp.arange(G)[:, None] > jnp.arange(G)[None, :]  # [u, w]: w before u
    first = ~jnp.any(same & lower, -1)  # (M, g, G): no earlier target at its point
    cand = okg[:, :, None, :] & first[:, :, None, :] & ~same
    d2 = jnp.where(cand, d2, jnp.inf)
    neg, idx = jax.lax.top_k(-d2, min(k, G - 1))  # (M, g, G, k)
    got = jnp.isfinite(neg)
    idx = idx.reshape(M, Tg, -1)[:, slot]  # (M, T, k): places in the padded run
    got = got.reshape(M, Tg, -1)[:, slot]
    at = ((slot // G) * G)[None, :, None] + idx  # (M, T, k): the neighbours' places
    kk = idx.shape[-1]
    S = jnp.take_along_axis(pad(q, 0.0), at.reshape(M, T * kk)[..., None], axis=1)
    S = S.reshape(M, T, kk, n)
    S = jnp.where(got[..., None], S, q[:, :, None])
    if kk < k:
        S = jnp.concatenate([S, jnp.repeat(q[:, :, None], k - kk, 2)], 2)
    return S, jnp.any(got, -1)


CLIMB_ROWS = 256
"""Rows per call of the null-space climb (:func:`_climb`) after the solve."""
CLIMB_STEP = 1.0
"""The climb's first step length factor α (joints move α × the projected gradient)."""
CLIMB_MAX = 0.25
"""The climb's largest joint move per step (rad; prismatic joints in units of the reach):
:data:`CLIMB_CORRECT` LM corrections bring a move of this size back onto the target."""
CLIMB_CORRECT = 3
"""LM steps that bring a climb step back onto the target: from a step of CLIMB_MAX, the
error falls quadratically (measured on the UR5 with a tilted instrument: 3.5e-3, 3e-5,
1e-9, 2e-16 × the reach), so three reach :data:`CLIMB_NEAR` with room to spare."""
CLIMB_NEAR = 1e-6
"""A climb step stands when its corrected joints are this close to the target (× the
reach; rad): the last steps polish to the solver's tolerance."""
CLIMB_DAMPING = 1e-9
"""The damping floor of the climb's LM corrections (the solver's own is 1e-16). Along the
self-motion the task rows' JᵀJ has a zero pivot: with the solver's floor, the rounding of
Jᵀe along it (≈ 1e-16 |e|) was divided by ≈ 1e-16 and moved the joints along the
self-motion by far more than the error being corrected, so the corrections oscillated
around 1e-7 instead of converging, and about half the climb's steps were refused
(measured on the UR5 with a tilted instrument, 2026-11-29). With 1e-9 the null-space
move is ≤ 1e-7 |e| and the corrections converge quadratically (3.5e-3, 3e-5, 1e-9,
2e-16); a direction is slowed only where σ(J) < 3e-5 (a solution at a singularity,
where the climb's step then does not stand and the converged joints are kept)."""
CLIMB_FLAT = 1e-7
"""The climb stops at a row whose projected gradient (the largest joint component, per
unit of score) is below this: the score is flat along the self-motion there (a straight
instrument's roll about its own axis; the forward differences' noise is about 1e-8)."""
CLIMB_SMALLEST = 1e-6
"""... or whose step factor α has shrunk below this (steps that did not stand)."""
NULL_EPS = 1e-12
"""The regularisation of J Jᵀ in the null-space projector (the task rows of an ``axis``
target have rank 5 of 6: J Jᵀ is singular, and the regularised solve stays exact there,
since the singular direction's components of Jg and Jᵀ vanish together)."""


def _climb(ch: _Chain, xr: list, pt: list, Rt: list | None, L: jax.Array, mode: Mode,
           rev: tuple[bool, ...], lower: jax.Array, upper: jax.Array, opts: IKOptions,
           score: Callable[[jax.Array], jax.Array],
           accept: Callable[[jax.Array], jax.Array] | None, q0: jax.Array) -> jax.Array:  # fmt: skip
    """Projected gradient ascent of ``score`` (joints (k, n) → (k,)) over a target's
    solution set, from converged joints q0 (k, n) (design columns ``xr``, targets
    ``pt``, ``Rt`` entry by entry, reach L (k,)). Where the chain keeps free directions
    at the target (a seventh joint, the roll about a tool axis, the roll through a
    port), a step moves along the score's gradient projected onto the null space of the
    target's rows (in the LM step's joint units; N = I − Jᵀ(JJᵀ + εI)⁻¹J), then
    :data:`CLIMB_CORRECT` Levenberg–Marquardt steps bring it back onto the target; it stands when
    it is back (:data:`CLIMB_NEAR`), scores higher and ``accept`` takes it (the best free
    solution often lies where the arm meets an obstacle), and the step length follows
    Barzilai and Borwein (a secant along the projected gradient: in one free direction
    Newton's step), shrinking 4× after a step that does not stand. ``opts.climb`` steps,
    then LM steps to the solver's tolerance. The climbed joints are kept where they are
    within the tolerance and the limits, score higher than q0 and ``accept`` takes them;
    elsewhere q0 (converged and accepted already) is returned unchanged. Without free
    directions the projected gradient is 0 and nothing moves."""
    n = len(rev)
    dtype = q0.dtype
    B = q0.shape[0]
    invL = 1.0 / L
    rows = _rows(mode)

    def b(x):
        return jnp.broadcast_to(jnp.asarray(x, dtype), (B,))

    tx = ch.trig_x(xr)

    def resid(qc):
        R, p, J = ch.fk(xr, qc, ch.trig_q(qc, exact=True), tx, rows)
        return _residual(R, p, J, pt, Rt, mode, invL)

    def near(e, cz, tol_p, tol_r):
        ok = _dot(e[:3], e[:3]) <= tol_p**2
        if mode != "position":
            ok = ok & (_dot(e[3:], e[3:]) <= tol_r**2) & (cz > 0)
        return jnp.broadcast_to(ok, (B,))

    def lm(qc, freeze=None):
        e, J, cz = resid(qc)
        E = 0.5 * _dot(e, e)
        lam = opts.damping_e * E + max(opts.damping, CLIMB_DAMPING)
        dq = _lm_step(e, J, rev, L, lam, qc, lower, upper)
        new = _project([x + d for x, d in zip(qc, dq, strict=True)], lower, upper, rev)
        if freeze is None:
            return new
        done = near(e, cz, 0.5 * opts.tol_pos, 0.5 * opts.tol_rot)
        return [jnp.where(done, a, c) for a, c in zip(qc, new, strict=True)]

    h_fd = math.sqrt(float(jnp.finfo(dtype).eps))

    def value_grad(qa):
        """The score and its gradient by forward differences, one joint at a time in a
        loop: one copy of the score in the program (its reverse-mode derivative, through
        the condition number's eigen- or singular values, compiled several times longer)."""
        def col(j, S):  # j = 0: the score at qa; j ≥ 1: qa with joint j − 1 moved by h_fd
            e = (jnp.arange(1, n + 1) == j).astype(dtype)
            return S.at[j].set(score(qa + h_fd * e))

        S = jax.lax.fori_loop(0, n + 1, col, jnp.zeros((n + 1, B), dtype))
        v = S[0]
        g = ((S[1:] - v) / h_fd).T
        return jnp.nan_to_num(v, nan=-jnp.inf), jnp.nan_to_num(g, nan=0.0, posinf=0.0,
                                                                neginf=0.0)  # fmt: skip

    def direction(qc, g):
        """(the projected gradient in joint units (k, n), whether qc is on the target)."""
        e, J, cz = resid(qc)
        k = len(J)
        Jc = [[J[r][i] if rev[i] else F.mul(J[r][i], L) for i in range(n)] for r in range(k)]
        gu = [g[:, i] if rev[i] else g[:, i] * L for i in range(n)]
        Jg = [_dot(Jc[r], gu) for r in range(k)]
        A = [[F.add(_dot(Jc[i], Jc[j]), NULL_EPS if i == j else 0.0) for j in range(k)]
             for i in range(k)]  # fmt: skip
        y = _chol_solve(A, Jg)
        du = [F.sub(gu[i], F.total(F.mul(Jc[r][i], y[r]) for r in range(k))) for i in range(n)]
        d = jnp.stack([b(du[i]) if rev[i] else b(du[i]) * L for i in range(n)], -1)
        return d, near(e, cz, CLIMB_NEAR, CLIMB_NEAR)

    def step(i, c):
        """Step i: a trial along the projected gradient, corrected and scored (step 0
        scores q0 itself: one copy of the score's gradient in the program). A trial that
        is better and on the target but collides bounds the free stretch ahead: the next
        trials bisect towards that edge (``rem``: the joint move to it) instead of
        shrinking 4×, since the best free solution often lies on it."""
        qa, s, d, al, s0, rem = c
        nd = jnp.maximum(jnp.max(jnp.abs(d), -1), jnp.finfo(dtype).tiny)
        h = jnp.where(i == 0, 0.0, jnp.minimum(jnp.minimum(al, CLIMB_MAX / nd), 0.5 * rem / nd))
        qt = _project([qa[:, j] + h * d[:, j] for j in range(n)], lower, upper, rev)
        qt = jax.lax.fori_loop(0, jnp.where(i == 0, 0, CLIMB_CORRECT), lambda _, q: lm(q), qt)
        qta = jnp.stack(qt, -1)
        st, gt = value_grad(qta)
        dt, on = direction(qt, gt)
        up = on & (st > s)
        hit = jnp.zeros_like(up)
        if accept is not None:  # a step into a collision does not stand: the best free
            free = accept(qta)  # solution often lies on the edge of a collision
            hit = (i > 0) & up & ~free
            up = up & free
        up = (i == 0) | up
        dq, dd = qta - qa, dt - d
        curv = -jnp.sum(dq * dd, -1)
        bb = jnp.where(curv > 0, jnp.sum(dq * dq, -1) / jnp.where(curv > 0, curv, 1.0), 2 * al)
        al = jnp.where(i == 0, al, jnp.where(up, jnp.clip(bb, 1e-6, 1e3),
                                             jnp.where(hit, al, al / 4)))  # fmt: skip
        move = h * nd
        # the edge bounds the way ahead only: a step that turns the direction frees it
        ahead = jnp.sum(dt * d, -1) > 0.5 * jnp.linalg.norm(dt, axis=-1) * jnp.linalg.norm(d, axis=-1)
        rem = jnp.where(hit, move, jnp.where(up & (i > 0), jnp.where(ahead, rem - move, jnp.inf),
                                             rem))  # fmt: skip
        return (jnp.where(up[:, None], qta, qa), jnp.where(up, st, s),
                jnp.where(up[:, None], dt, d), al, jnp.where(i == 0, st, s0), rem)  # fmt: skip

    z = jnp.zeros((B,), dtype)
    c0 = (q0, z - jnp.inf, jnp.zeros_like(q0), z + CLIMB_STEP, z, z + jnp.inf)

    def live(i, c):  # a row stops where the projected gradient vanishes (a self-motion
        # the score does not see, or none) or its step has shrunk to nothing
        _, _, d, al, _, _ = c
        return (i == 0) | ((jnp.max(jnp.abs(d), -1) > CLIMB_FLAT) & (al > CLIMB_SMALLEST))

    def going(ic):
        i, c = ic
        return (i <= opts.climb) & jnp.any(live(i, c))

    def body(ic):  # a stopped row stays as it is, however long the others climb: its
        i, c = ic  # result does not depend on the rows beside it
        on = live(i, c)
        new = step(i, c)
        return i + 1, tuple(jnp.where(on.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)
                            for a, b in zip(new, c, strict=True))

    _, (qa, s, _, _, s0, _) = jax.lax.while_loop(going, body, (jnp.int32(0), c0))
    qc = jax.lax.fori_loop(0, 2 * CLIMB_CORRECT, lambda _, q: lm(q, freeze=True), [qa[:, j] for j in range(n)])
    qa = jnp.stack(qc, -1)
    R, p, _ = ch.fk(xr, qc, ch.trig_q(qc, exact=True), tx, None)
    e, _, cz = _residual(R, p, None, pt, Rt, mode, invL)
    inside = jnp.all((qa >= lower) & (qa <= upper), -1)
    keep = near(e, cz, 0.5 * opts.tol_pos, 0.5 * opts.tol_rot) & inside & (s > s0)
    keep = keep & (score(qa) > s0)
    if accept is not None:
        keep = keep & accept(qa)
    return jnp.where(keep[:, None], qa, q0)


CHECK_ROWS = 256
"""Rows per call of an ``accept`` check after the solve (:func:`on_rows`)."""
DUPLICATE = 1e-6
"""Two converged solutions of a target are one when no joint differs by more than this
(rad; prismatic joints in units of the reach): seeds converge to 1e-9."""
DUPLICATE_SCORE = 1e-7
"""... or when their scores agree to this (relative above 1): the same point of a
self-motion the score does not see (a straight instrument's roll about its own axis
leaves the position Jacobian as it is), or a branch symmetric to one found (a wrist
flipped). Either way it adds nothing to the choice of the best."""


def on_rows(fn: Callable[[jax.Array], jax.Array], mask: jax.Array, k: int) -> jax.Array:
    """``fn`` (row indices (k,) int32 → (k, ...) values) asked of the rows where ``mask``
    (R,) holds, k rows at a time (a loop of ⌈Σmask / k⌉ calls), its values there and
    zeros (False) elsewhere: a costly per-row check (a collision test) paid for the rows
    that need it, not for all R. Each row's value is what ``fn`` gives it in any batch
    (no row's value reads another's)."""
    R = mask.shape[0]
    k = max(1, min(k, R))
    n_groups = -(-R // k)
    idx = jnp.nonzero(mask, size=n_groups * k, fill_value=R)[0].astype(jnp.int32)
    out0 = jax.eval_shape(fn, jnp.zeros((k,), jnp.int32))
    out = jnp.zeros((R + 1, *out0.shape[1:]), out0.dtype)

    def body(g, out):
        r = jax.lax.dynamic_slice(idx, (g * k,), (k,))
        return out.at[r].set(fn(jnp.minimum(r, R - 1)), mode="drop")

    used = (jnp.sum(mask, dtype=jnp.int32) + k - 1) // k
    return jax.lax.fori_loop(0, used, body, out)[:R]


def representatives(X: jax.Array) -> jax.Array:
    """(M,) int32: for each row of X (M, D), the first row equal to it (a row holding a
    NaN is its own): :func:`solve`'s ``rep`` for designs that share their targets."""
    X = jnp.asarray(X)
    same = jnp.all(X[:, None, :] == X[None, :, :], -1)  # (M, M); NaN ≠ NaN
    M = X.shape[0]
    first = jnp.argmax(same, axis=1).astype(jnp.int32)
    return jnp.where(jnp.any(same, axis=1), first, jnp.arange(M, dtype=jnp.int32))


def solve_design(model: SerialModel, X: jax.Array, p_t: jax.Array, R_t: jax.Array | None,
                 lower: jax.Array, upper: jax.Array, key: jax.Array, mode: Mode = "position",
                 opts: IKOptions = DEFAULTS,
                 score: Callable[[jax.Array], jax.Array] | None = None) -> IKResult:  # fmt: skip
    """IK of T targets (p_t (T, 3), R_t (T, 3, 3) or None) for one design X (D,)
    (:func:`solve` with M = 1; ``score(m, t, q)`` as :func:`solve`'s: rows' design and
    target indices (B,) and joints (B, n) to (B,))."""
    r = solve(model, jnp.asarray(X)[None], p_t, R_t, lower, upper, key, mode, opts, score)
    return IKResult(*(x[0] for x in r))
