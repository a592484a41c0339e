"""Inverse kinematics of any :class:`~designopt.kinematics.kernel.SerialModel` (DH, ET or
URDF chains): batched damped least squares, vmapped over designs × targets × seeds.

Targets come in three kinds (``mode``):

- ``position``: the tip position p (3 rows);
- ``axis``: p and the tool z axis (the roll about the tool axis is free: 5 independent
  rows; the residual z × z* has three components of rank 2);
- ``pose``: p and the full orientation R (6 rows).

Each step is Sugihara's Levenberg–Marquardt update (Sugihara, "Solvability-unconcerned
inverse kinematics by the Levenberg–Marquardt method", IEEE T-RO 2011):
Δq = (JᵀJ + (E + λ̄) I)⁻¹ Jᵀe with E = ½|e|², so the damping vanishes as the error does
(quadratic convergence near a solution) and grows far from one or near a singularity
(no blow-up). Position rows are divided by the chain's reach scale L, so that a pose
mixes metres (or mm) and radians on equal terms. Joint limits are kept by projection
(clipping) after every step. The orientation residual is ½ Σᵢ rᵢ × rᵢ* over the columns
of R (Siciliano et al., "Robotics: Modelling, Planning and Control", 2009, eq. 3.85).

Seeds: the ``n_nearest`` entries of a small FK database (``n_db`` configurations drawn
uniformly within the limits, built once per design) closest to each target, plus
``n_random`` uniform draws. Every seed is iterated ``iters`` times per round; after
each of ``rounds`` rounds, the seeds still unsolved (stalled at a limit or in a local
minimum) restart from fresh uniform draws (one compiled program, no data-dependent
exit). A revolute joint whose range spans a full turn wraps by ±2π before it is
clipped. Of the seeds that converge, the one with the largest
1/k (2-norm, position block) at its solution is kept (the designer gets the best-conditioned configuration),
otherwise the one with the smallest error. A target is solved when its position error
is ≤ ``tol_pos``·L and its orientation error ≤ ``tol_rot`` rad, within the limits;
unreachable targets are reported as failures, never as successes.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp

from designopt.kinematics.kernel import SerialModel

Mode = Literal["position", "axis", "pose"]
MODES: tuple[str, ...] = ("position", "axis", "pose")


class IKOptions(NamedTuple):
    """Solver settings (``iters``, ``n_db``, ``n_nearest``, ``n_random`` fix array shapes;
    the tolerances and damping are plain numbers)."""

    iters: int = 12  # steps per round
    rounds: int = 3  # seeds still unsolved after a round restart from a random draw
    n_db: int = 2048
    n_nearest: int = 2
    n_random: int = 2
    tol_pos: float = 1e-9  # × the reach scale L
    tol_rot: float = 1e-9  # rad
    damping: float = 1e-8  # λ̄, added to E = ½|e|² (e in units of L and rad)


DEFAULTS = IKOptions()


class IKResult(NamedTuple):
    """Per target: joints (active), success, position error (model units), orientation
    error (rad; 0 for ``position``), 1/k at the solution, and the winning seed index."""

    q: jax.Array
    success: jax.Array
    pos_err: jax.Array
    rot_err: jax.Array
    inv_k: jax.Array
    seed: jax.Array


def _rows(mode: Mode) -> tuple[int, ...]:
    return (0, 1, 2) if mode == "position" else (0, 1, 2, 3, 4, 5)


def residual(model: SerialModel, X: jax.Array, q: jax.Array, p_t: jax.Array,
             R_t: jax.Array | None, mode: Mode, L: jax.Array):  # fmt: skip
    """(e, J, p, R) of configurations q (B, n) of one design X (D,) against targets
    p_t (B, 3) and R_t (B, 3, 3) (for ``axis`` only its last column counts)."""
    R, p, J = model.fk_jacobian(X, q, rows=_rows(mode))
    e_p = (p_t - p) / L
    J_p = J[..., :3, :] / L
    if mode == "position":
        return e_p, J_p, p, R
    if mode == "axis":
        e_o = jnp.cross(R[..., :, 2], R_t[..., :, 2])
    else:
        e_o = 0.5 * sum(jnp.cross(R[..., :, i], R_t[..., :, i]) for i in range(3))
    return jnp.concatenate([e_p, e_o], -1), jnp.concatenate([J_p, J[..., 3:, :]], -2), p, R


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


def spd_solve(A: list[list[jax.Array]], b: list[jax.Array]) -> list[jax.Array]:
    """x = A⁻¹ b for a batch of small symmetric positive-definite systems given entry by
    entry (A[i][j] and b[i] arrays over the batch): Cholesky unrolled at trace time, so
    the whole solve is elementwise arithmetic over the batch (a batched LAPACK call per
    tiny matrix is far slower on a CPU)."""
    n = len(b)
    Lc: list[list[jax.Array]] = [[None] * n for _ in range(n)]  # type: ignore[list-item]
    inv_d = [None] * n
    for j in range(n):
        s = A[j][j] - sum(Lc[j][k] * Lc[j][k] for k in range(j))
        d = jnp.sqrt(s)
        inv_d[j] = 1.0 / d
        Lc[j][j] = d
        for i in range(j + 1, n):
            Lc[i][j] = (A[i][j] - sum(Lc[i][k] * Lc[j][k] for k in range(j))) * inv_d[j]
    y = [None] * n
    for i in range(n):
        y[i] = (b[i] - sum(Lc[i][k] * y[k] for k in range(i))) * inv_d[i]
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = (y[i] - sum(Lc[k][i] * x[k] for k in range(i + 1, n))) * inv_d[i]
    return x  # type: ignore[return-value]


def revolute(model: SerialModel) -> tuple[bool, ...]:
    """Per active joint: does it drive a revolute chain joint?"""
    C = model.coupling
    return tuple(any(C[i][j] != 0 and model.joint_types[i] == "R" for i in range(len(C)))
                 for j in range(model.n_active))  # fmt: skip


def project(q: jax.Array, lower: jax.Array, upper: jax.Array, wrap: jax.Array) -> jax.Array:
    """Joint limits by projection: a revolute joint whose range spans a full turn first
    moves by ±2π back into it (the same pose), then every joint is clipped."""
    two_pi = 2 * jnp.pi
    q = jnp.where(wrap & (q > upper) & (q - two_pi >= lower), q - two_pi, q)
    q = jnp.where(wrap & (q < lower) & (q + two_pi <= upper), q + two_pi, q)
    return jnp.clip(q, lower, upper)


def iterate(model: SerialModel, X: jax.Array, q: jax.Array, p_t: jax.Array,
            R_t: jax.Array | None, lower: jax.Array, upper: jax.Array, mode: Mode,
            L: jax.Array, iters: int, damping: float) -> jax.Array:  # fmt: skip
    """``iters`` damped least-squares steps from q (B, n), projected onto the limits."""
    n = q.shape[-1]
    wrap = jnp.asarray(revolute(model)) & (upper - lower >= 2 * jnp.pi)

    rev = revolute(model)

    def step(_, q):
        e, J, _, _ = residual(model, X, q, p_t, R_t, mode, L)
        k = e.shape[-1]
        ec = [e[:, r] for r in range(k)]
        # prismatic joints in units of L (so the damping weighs every joint alike)
        Jc = [[J[:, r, i] if rev[i] else J[:, r, i] * L for i in range(n)] for r in range(k)]
        lam = 0.5 * sum(x * x for x in ec) + damping
        A = [[sum(Jc[r][i] * Jc[r][j] for r in range(k)) + (lam if i == j else 0.0)
              for j in range(n)] for i in range(n)]  # fmt: skip
        g = [sum(Jc[r][i] * ec[r] for r in range(k)) for i in range(n)]
        dq = spd_solve(A, g)
        dq = jnp.stack([d if rev[i] else d * L for i, d in enumerate(dq)], -1)
        return project(q + dq, lower, upper, wrap)

    return jax.lax.fori_loop(0, iters, step, q)


def nearest(d: jax.Array, k: int) -> jax.Array:
    """Indices (T, k) of the k smallest entries of each row of d (T, n), smallest first:
    k argmin passes, each masking the previous winner (on a CPU, ``lax.top_k`` over
    rows of a few thousand is ~80× slower than this for k ≤ 4)."""
    cols = jnp.arange(d.shape[-1])
    out = []
    for _ in range(k):
        i = jnp.argmin(d, -1)
        out.append(i)
        d = jnp.where(cols == i[:, None], jnp.inf, d)
    return jnp.stack(out, -1)


def database(model: SerialModel, X: jax.Array, key: jax.Array, lower: jax.Array,
             upper: jax.Array, n: int) -> tuple[jax.Array, jax.Array, jax.Array]:  # fmt: skip
    """(q (n, nA), p (n, 3), R (n, 3, 3)): FK of n configurations uniform in the limits
    (the same draws for every design: common random numbers)."""
    u = jax.random.uniform(key, (n, lower.shape[0]), dtype=lower.dtype)
    q = lower + u * (upper - lower)
    R, p = model.fk(X, q)
    return q, p, R


def solve_design(model: SerialModel, X: jax.Array, p_t: jax.Array, R_t: jax.Array | None,
                 lower: jax.Array, upper: jax.Array, key: jax.Array, mode: Mode = "position",
                 opts: IKOptions = DEFAULTS) -> IKResult:  # fmt: skip
    """IK of T targets (p_t (T, 3), R_t (T, 3, 3) or None) for one design X (D,).
    Vmap over designs for a swarm (:func:`solve`)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if mode != "position" and R_t is None:
        raise ValueError(f"mode {mode!r} needs target orientations R_t")
    T, n = p_t.shape[0], lower.shape[0]
    # every configuration has its own joints: the per-design walk (no bases shared over a
    # swarm) is about 4× faster here than the swarm-shared one
    model = model.per_design()
    k_db, k_rand = jax.random.split(key)
    q_db, p_db, R_db = database(model, X, k_db, lower, upper, opts.n_db)
    L = jnp.maximum(jnp.max(jnp.linalg.norm(p_db - jnp.mean(p_db, 0), axis=-1)), 1e-12)
    d = jnp.sum((p_t[:, None, :] - p_db[None]) ** 2, -1) / L**2  # (T, n_db)
    if mode == "axis":
        d = d + (1.0 - jnp.einsum("ti,ki->tk", R_t[:, :, 2], R_db[:, :, 2]))
    elif mode == "pose":
        d = d + (3.0 - jnp.einsum("tij,kij->tk", R_t, R_db)) / 2
    seeds = [q_db[nearest(d, opts.n_nearest)]] if opts.n_nearest else []
    if opts.n_random:
        u = jax.random.uniform(k_rand, (T, opts.n_random, n), dtype=lower.dtype)
        seeds.append(lower + u * (upper - lower))
    q0 = jnp.concatenate(seeds, 1)  # (T, S, n)
    S = q0.shape[1]
    pt = jnp.repeat(p_t, S, axis=0)
    Rt = None if R_t is None else jnp.repeat(R_t, S, axis=0)

    def converged(q):
        R, p = model.fk(X, q)
        pe, re = errors(p, R, pt, Rt, mode)
        return (pe <= opts.tol_pos * L) & (re <= opts.tol_rot), pe, re

    def round_(r, q):
        # from the second round on, restart the seeds still unsolved (stalled at a limit
        # or in a local minimum) from fresh uniform draws
        u = jax.random.uniform(jax.random.fold_in(k_rand, r), q.shape, dtype=q.dtype)
        q = jnp.where((r == 0) | converged(q)[0][:, None], q, lower + u * (upper - lower))
        return iterate(model, X, q, pt, Rt, lower, upper, mode, L, opts.iters, opts.damping)

    q = jax.lax.fori_loop(0, opts.rounds, round_, q0.reshape(T * S, n))
    ok, pe, re = converged(q)
    ik = model.inv_cond(X, q, rows=(0, 1, 2), norm="2")  # the position block's 1/k
    pe, re, ik, ok, q = (a.reshape(T, S, *a.shape[1:]) for a in (pe, re, ik, ok, q))
    # converged seeds rank by 1/k (largest first), the others by their error after them
    score = jnp.where(ok, 2.0 + ik, -(pe / L + re))
    best = jnp.argmax(score, axis=1)

    def take(a):
        return jnp.take_along_axis(a, best.reshape((T,) + (1,) * (a.ndim - 1)), 1)[:, 0]

    return IKResult(take(q), take(ok), take(pe), take(re), take(ik), best)


def solve(model: SerialModel, X: jax.Array, p_t: jax.Array, R_t: jax.Array | None,
          lower: jax.Array, upper: jax.Array, key: jax.Array, mode: Mode = "position",
          opts: IKOptions = DEFAULTS) -> IKResult:  # fmt: skip
    """IK of the same T targets for M designs X (M, D): every field gains a leading M
    axis. The seeds' random draws are shared by the designs (common random numbers)."""
    fn = jax.vmap(lambda x: solve_design(model, x, p_t, R_t, lower, upper, key, mode, opts))
    return fn(X)
