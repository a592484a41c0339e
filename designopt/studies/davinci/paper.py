"""The da Vinci patient-side arm IK paper's method (Applied Sciences 2019), in JAX, as
the reference the production solver (``ik.py``) is compared with.

The paper reduces the six pose equations to one equation in q1 (seed 002 eq. 4-22) and
solves it by scanning q1 over its range with step h, refined when no root is found
(§3.2, §4.3), and Newton's iteration (eq. 24). Its elimination runs on complex
exponentials x_j = e^{i q_j} (eq. 5-9) with constants c1..c60 and C'1..C'13 that the
paper does not print, so we eliminate the same unknowns in the same order with the
arm's geometry instead (H the RCM point, d = p − H, a the tool axis z6, s the shaft):

- eq. (10)-(14) → q2(q1): the shaft must lie in the plane of a and d, s·(a × d) = 0,
  which is linear in (cos q2, sin q2): two roots q2 and q2 + π (the paper's x2 = ±√f1);
- eq. (17)-(21) → q4, q5, q6 from the orientation in frame 3 (q5 in [−90°, 90°]),
  hence the jaw offset direction y5;
- eq. (15)-(16) → q3 = (d − l_IJ y5)·s, the shaft tip I = p − l_IJ y5 projected on
  the shaft;
- eq. (22) → F(q1) = d·a − q3 (s·a) = (I − H − q3 s)·a, zero exactly when the pose is
  reached (I − H − q3 s lies in the plane of s and a and is orthogonal to s; F is free
  of poles, unlike the form q3 = d·a / s·a, which blows up at q5 = 0).

The two expressions of eq. (23) are the two q2 roots; both are scanned and the solution
closest to the previous configuration X_s is kept (eq. 23's rule). Brackets come from the
scan at step h (θ0 = −90°, h0 = 20° by default, halved up to ``levels`` times while no
valid root is found); each is finished by Newton's iteration (eq. 24) with F' from
forward-mode autodiff, kept inside its bracket by bisection (the paper caps Newton at
50 iterations; so do we). Everything is static-shaped and ``vmap``-able over poses.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from designopt.studies.davinci import ik
from designopt.studies.davinci import mechanism as mech

TABLE2_DEG = np.array(
    [
        [10.0, -125.0, 100.0, 100.0, -14.0, 18.0],
        [15.4, -116.5, 101.3, 86.4, 13.7, -15.9],
        [-50.24, -60.76, 126.94, 101.38, -15.94, 24.79],
        [48.369, -80.597, 125.468, -80.594, -68.592, 15.238],
        [-56.54835, -53.89576, 168.8532, -96.35847, -50.26843, 50.46851],
        [43.365874952, -125.6874598, 136.84521597, 75.31254896, 25.98457268, -42.587941523],
    ]
)
"""Table 2's six input joint sets (θ1, θ2 in deg, l_IH in mm, θ3, θ4, θ5 in deg) =
(q1, q2, q3, q4, q5, q6)."""
TABLE2_STEP_DEG = np.array([20.0, 20.0, 10.0, 20.0, 20.0, 20.0])
"""The step h Table 2 reports for each set."""
TABLE2_TIME_S = np.array([0.421, 0.406, 0.484, 0.390, 0.437, 0.437])
"""Table 2's solve times on the paper's PC (Table 3: 0.016 s each on the controller)."""


def to_rad(q_deg: np.ndarray) -> np.ndarray:
    """Table units (deg, q3 in mm) → solver units (rad, q3 in mm)."""
    q = np.radians(np.asarray(q_deg, np.float64))
    q[..., 2] = np.asarray(q_deg)[..., 2]
    return q


def to_deg(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, np.float64)
    out = np.degrees(q)
    out[..., 2] = q[..., 2]
    return out


class Reduced(NamedTuple):
    F: jnp.ndarray  # eq. (22) residual (mm)
    q: jnp.ndarray  # (6,) the other joints eliminated from q1


def _pre(X: jnp.ndarray, q1: jnp.ndarray) -> jnp.ndarray:
    """Rotation of the frame before Rz(q2): Rx(α − π) Rz(q1) Rx(π/2 − β) Ry(π/2)."""

    def rx(t):
        c, s = jnp.cos(t), jnp.sin(t)
        return jnp.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])

    def rz(t):
        c, s = jnp.cos(t), jnp.sin(t)
        return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    ry = jnp.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    return rx(X[0] - math.pi) @ rz(q1) @ rx(math.pi / 2 - X[1]) @ ry


def reduced(X: jnp.ndarray, T: jnp.ndarray, q1: jnp.ndarray, branch: int) -> Reduced:
    """q2..q6 eliminated from q1 (eq. 14, 16, 18, 20, 21) and the residual F(q1) of
    eq. (22), for one pose T (4, 4) and one root ``branch`` (0, 1) of eq. (14)."""
    H = mech.rcm_point(X)
    p, Rt = T[:3, 3], T[:3, :3]
    a = Rt[:, 2]
    d = p - H
    P = _pre(X, q1)
    u = P.T @ jnp.cross(a, d)
    q2 = jnp.arctan2(u[1], u[0]) + branch * math.pi  # eq. (14): s·(a × d) = 0
    q2 = jnp.remainder(q2 + math.pi, 2 * math.pi) - math.pi
    c2, s2 = jnp.cos(q2), jnp.sin(q2)
    R3 = P @ jnp.array([[c2, -s2, 0.0], [s2, c2, 0.0], [0.0, 0.0, 1.0]])
    s = R3[:, 1]
    W = R3.T @ Rt
    a3 = W[:, 2]
    q5 = jnp.arcsin(jnp.clip(a3[1], -1.0, 1.0))  # eq. (20)
    q4 = jnp.arctan2(-a3[2], a3[0])  # eq. (18)
    Rw = ik._wrist_rot(jnp.stack([q4, q5])[None])[0]
    G = Rw.T @ W
    q6 = jnp.arctan2(G[1, 0], G[0, 0])  # eq. (21)
    c4, s4, c5, s5 = jnp.cos(q4), jnp.sin(q4), jnp.cos(q5), jnp.sin(q5)
    y5 = R3 @ jnp.stack([-c4 * s5, c5, s4 * s5])
    e = d - X[3] * y5  # I − H when the pose is reached
    q3 = jnp.dot(e, s)  # eq. (16)
    F = jnp.dot(d, a) - q3 * jnp.dot(s, a)  # eq. (22): (I − H − q3 s)·a
    return Reduced(F, jnp.stack([q1, q2, q3, q4, q5, q6]))


class PaperResult(NamedTuple):
    q: jnp.ndarray  # (6,)
    success: jnp.ndarray  # bool
    step_deg: jnp.ndarray  # the step h at which the returned root was bracketed
    n_solutions: jnp.ndarray  # valid roots found at that step
    pos_err: jnp.ndarray
    rot_err: jnp.ndarray


def _newton(f, lo, hi, iters: int):
    """Root of f in [lo, hi] (f(lo), f(hi) of opposite signs): Newton's step (eq. 24),
    replaced by bisection when it leaves the bracket."""
    flo = f(lo)

    def body(_, c):
        a, b, fa, x = c
        fx, dfx = jax.jvp(f, (x,), (jnp.ones_like(x),))
        same = jnp.sign(fx) == jnp.sign(fa)
        a, fa, b = jnp.where(same, x, a), jnp.where(same, fx, fa), jnp.where(same, b, x)
        xn = x - fx / dfx
        inside = (xn - jnp.minimum(a, b)) * (xn - jnp.maximum(a, b)) < 0
        xn = jnp.where(
            inside & jnp.isfinite(xn) & (fx != 0), xn, jnp.where(fx == 0, x, 0.5 * (a + b))
        )
        return a, b, fa, xn

    _, _, _, x = jax.lax.fori_loop(0, iters, body, (lo, hi, flo, 0.5 * (lo + hi)))
    return x


def solve(
    X: jnp.ndarray,
    T: jnp.ndarray,
    q_prev: jnp.ndarray | None = None,
    h0_deg: float = 20.0,
    levels: int = 4,
    newton_iters: int = 50,
    tol: float = 1e-9,
) -> PaperResult:
    """The paper's IK for one pose T (4, 4) (``jax.vmap`` it over poses): scan q1 over
    [−90°, 90°] from θ0 = −90° with step h0, h0/2, … (``levels`` steps), Newton on every
    sign change of F for both roots of eq. (14); the first step with a valid root (within
    the joint ranges, FK within ``tol`` mm / rad) wins, and among its roots the one
    closest to ``q_prev`` (default: mid-range) is returned."""
    X = jnp.asarray(X, T.dtype)
    lo, hi = jnp.asarray(mech.LOWER, T.dtype), jnp.asarray(mech.UPPER, T.dtype)
    q_prev = 0.5 * (lo + hi) if q_prev is None else jnp.asarray(q_prev, T.dtype)
    n_fine = int(round(180.0 / (h0_deg / 2 ** (levels - 1))))
    grid = jnp.linspace(lo[0], hi[0], n_fine + 1, dtype=T.dtype)
    Fg = jnp.stack([jax.vmap(lambda t, b=b: reduced(X, T, t, b).F)(grid) for b in (0, 1)])
    # every bracket of every step and both roots of eq. (14), solved in one vmapped Newton
    i0, br, lv = [], [], []
    for k in range(levels):
        stride = 2 ** (levels - 1 - k)
        idx = np.arange(0, n_fine, stride)
        for b in (0, 1):
            i0.append(np.stack([idx, idx + stride], -1))
            br.append(np.full(len(idx), b))
            lv.append(np.full(len(idx), k))
    ii, branch, level = np.concatenate(i0), np.concatenate(br), jnp.asarray(np.concatenate(lv))
    fa, fb = Fg[branch, ii[:, 0]], Fg[branch, ii[:, 1]]
    bracket = (jnp.sign(fa) != jnp.sign(fb)) & jnp.isfinite(fa) & jnp.isfinite(fb)
    bj = jnp.asarray(branch, T.dtype)

    def root(a_, b_, ok, bb):
        def f(x):
            return reduced(X, T, x, bb).F

        t = jnp.where(ok, _newton(f, a_, b_, newton_iters), a_)
        return reduced(X, T, t, bb).q

    q = jax.vmap(root)(grid[ii[:, 0]], grid[ii[:, 1]], bracket, bj)
    ok, pe, re = ik._evaluate(X, jnp.broadcast_to(T, (len(ii), 4, 4)), q, lo, hi,
                              ik.Options(success_pos=tol, success_rot=tol))  # fmt: skip
    ok = ok & bracket
    first = jnp.min(jnp.where(ok, level, levels))
    pick = ok & (level == first)
    dist = jnp.where(pick, ik._branch_dist(q, q_prev[None], ik.Options()), jnp.inf)
    i = jnp.argmin(dist)
    step = h0_deg / 2.0 ** jnp.minimum(first, levels - 1)
    # distinct roots at that step (a root on a grid point shows up in two brackets)
    qi = jnp.where(pick[:, None], q, jnp.inf)
    dup = (
        jnp.all(jnp.abs(qi[:, None, :] - qi[None, :, :]) < 1e-6, -1) & pick[:, None] & pick[None, :]
    )
    first_of = jnp.argmax(dup, axis=1) == jnp.arange(q.shape[0])
    n_sol = jnp.sum(pick & first_of)
    return PaperResult(q[i], jnp.any(ok), step, n_sol, pe[i], re[i])
