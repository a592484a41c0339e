"""Inverse condition numbers 1/k of Jacobians of any shape (seed 000 eq. 35, 51-53).

One public entry point, :func:`inv_cond` (and :func:`cond` = 1/inv_cond), dispatching on
the shape (..., r, n), r ≤ n or r ≥ n, m = min(r, n); G is the m×m Gram matrix of the
smaller side (J Jᵀ for r ≤ n, Jᵀ J otherwise), σ_i the singular values of J.

- norm "2":   σ_min/σ_max in [0, 1].
- norm "fro": 1/(‖J‖_F ‖J⁺‖_F) (J⁺ = J⁻¹ for square J), *raw* in [0, 1/m];
  ``normalized`` multiplies by m so the range is [0, 1] (the Gosselin-Angeles convention).

How (all differentiable, no LAPACK call for m ≤ 8):
- m ≤ 3: closed forms on the entries (square Frobenius: the adjugate, |det J| /
  (‖J‖_F ‖adj J‖_F); otherwise the eigenvalues of G, its determinant by Cauchy-Binet);
- m = 4..8, Frobenius: an unrolled LDLᵀ of G, tr G⁻¹ = ‖J⁺‖_F²; larger: Cholesky;
- m ≥ 4, 2-norm: one-sided Jacobi (``singular_values_sq``).

Numerically singular gives exactly 0, never NaN or inf: σ_min/σ_max ≤ max(r, n)·eps
(numpy's matrix_rank tolerance) for the 2-norm; normalised Frobenius 1/k ≤ max(r, n)·eps
(which implies the same bound on σ_min/σ_max); for m ≥ 4 and the Frobenius norm an LDLᵀ
pivot of G ≤ 4·max(r, n)·eps·tr G (the Gram route's resolution). The gradient there is
finite (the unsafe branches are evaluated on substituted values: the double-where rule).

The frame kernel (``designopt.kinematics.kernel``) calls the same closed forms on a
Jacobian given entry-wise (``_inv_cond_entries``), so its structural zeros are folded.
"""

from __future__ import annotations

import itertools
import math
from typing import Literal

import jax
import jax.numpy as jnp
import jax.scipy.linalg  # noqa: F401
from jax.typing import ArrayLike

from designopt.kinematics import _fold as F

Array = jnp.ndarray
Norm = Literal["fro", "2"]


def _fsqrt(x):
    """sqrt with a finite (zero) gradient at 0 and exact folding of Python constants."""
    if F.is_const(x):
        return math.sqrt(max(float(x), 0.0))
    ok = x > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1.0)), 0.0)


def _fdiv(a, b):
    """a/b, 0 where b == 0 (finite gradient)."""
    if F.is_const(b):
        return F.mul(1.0 / b, a) if b != 0 else 0.0
    ok = b != 0
    return jnp.where(ok, a / jnp.where(ok, b, 1.0), 0.0)


def _det2(a, b, c, d):
    return F.mul_sub(a, d, b, c)


def _cof3(J):
    (a, b, c), (d, e, f), (g, h, i) = J
    return [
        [_det2(e, f, h, i), F.neg(_det2(d, f, g, i)), _det2(d, e, g, h)],
        [F.neg(_det2(b, c, h, i)), _det2(a, c, g, i), F.neg(_det2(a, b, g, h))],
        [_det2(b, c, e, f), F.neg(_det2(a, c, d, f)), _det2(a, b, d, e)],
    ]


def _sumsq(xs):
    return F.total(F.mul(x, x) for x in xs)


def _gram(E):
    """m×m Gram matrix of the smaller side of the r×n entry matrix E (symmetric, folded)."""
    r, n = len(E), len(E[0])
    vecs = E if r <= n else [[E[i][j] for i in range(r)] for j in range(n)]
    m = len(vecs)
    G = [[0.0] * m for _ in range(m)]
    for a in range(m):
        for b in range(a, m):
            G[a][b] = G[b][a] = F.total(F.mul(x, y) for x, y in zip(vecs[a], vecs[b], strict=True))
    return G


def _cauchy_binet(E, m):
    """det G = Σ (m×m minors of E)² (Cauchy-Binet): accurate near rank deficiency, where
    the determinant of the Gram matrix itself would lose half the digits."""
    r, n = len(E), len(E[0])
    T = E if r <= n else [[E[i][j] for i in range(r)] for j in range(n)]  # m × N
    N = len(T[0])
    if math.comb(N, m) > 64:  # many minors: the Gram determinant is cheaper
        G = _gram(E)
        if m == 2:
            return _det2(G[0][0], G[0][1], G[1][0], G[1][1])
        return F.total(F.mul(G[0][j], c) for j, c in enumerate(_cof3(G)[0]))
    acc = 0.0
    for cols in itertools.combinations(range(N), m):
        S = [[T[i][j] for j in cols] for i in range(m)]
        if m == 2:
            d = _det2(S[0][0], S[0][1], S[1][0], S[1][1])
        else:
            d = F.total(F.mul(S[0][j], c) for j, c in enumerate(_cof3(S)[0]))
        acc = F.add(acc, F.mul(d, d))
    return acc


def _sym_eig_ratio(G, detG):
    """sqrt(λ_min/λ_max) of a symmetric positive definite 2×2 or 3×3 matrix (closed form)."""
    m = len(G)
    if m == 2:
        h = F.mul(0.5, F.sub(G[0][0], G[1][1]))
        lmax = F.add(
            F.mul(0.5, F.add(G[0][0], G[1][1])), _fsqrt(F.add(F.mul(h, h), F.mul(G[0][1], G[0][1])))
        )
        return _fdiv(_fsqrt(detG), lmax)
    tr = F.add(F.add(G[0][0], G[1][1]), G[2][2])
    qq = F.mul(1.0 / 3.0, tr)
    b = [F.sub(G[i][i], qq) for i in range(3)]
    off2 = F.add(F.add(F.mul(G[0][1], G[0][1]), F.mul(G[0][2], G[0][2])), F.mul(G[1][2], G[1][2]))
    p2 = F.mul(1.0 / 6.0, F.add(_sumsq(b), F.mul(2.0, off2)))
    p = _fsqrt(p2)
    B = [[b[0], G[0][1], G[0][2]], [G[1][0], b[1], G[1][2]], [G[2][0], G[2][1], b[2]]]
    detB = F.total(F.mul(B[0][j], c) for j, c in enumerate(_cof3(B)[0]))
    rr = _fdiv(detB, F.mul(2.0, F.mul(p2, p)))
    if not F.is_const(rr):
        rr = jnp.clip(rr, -1.0, 1.0)
    phi = jnp.arctan2(_fsqrt(F.sub(1.0, F.mul(rr, rr))), rr) / 3.0
    lmax = F.add(qq, F.mul(F.mul(2.0, p), jnp.cos(phi)))
    s = F.sub(tr, lmax)
    pr = _fdiv(detG, lmax)  # λ_mid·λ_min
    hs = F.mul(0.5, s)
    lmid = F.add(hs, _fsqrt(F.sub(F.mul(hs, hs), pr)))
    lmin = _fdiv(pr, lmid)
    return _fsqrt(_fdiv(lmin, lmax))


_LDL_MAX = 8


def _inv_cond_fro_ldl(E, normalized, eps):
    """Frobenius 1/k for m = 4.._LDL_MAX, unrolled: G = L D Lᵀ (no square roots), then
    ‖J⁺‖_F² = tr(G⁻¹) = Σ_j ‖(L⁻¹)_{j,:}‖²/D_j, all as fused elementwise arithmetic
    (batched LAPACK calls on millions of 6×6 matrices are far slower on CPU).
    Singular: a pivot D_j ≤ 4·max(r, n)·eps·tr G (the Gram route resolves σ_min/σ_max
    down to about sqrt of that)."""
    r, n = len(E), len(E[0])
    m = min(r, n)
    G = _gram(E)
    trG = F.total(G[i][i] for i in range(m))
    L = [[0.0] * m for _ in range(m)]
    D: list = [0.0] * m
    ok = jnp.asarray(trG) > 0
    tol = 4 * max(r, n) * eps
    for j in range(m):
        dj = G[j][j]
        for k in range(j):
            dj = F.sub(dj, F.mul(F.mul(L[j][k], L[j][k]), D[k]))
        ok = ok & (jnp.asarray(dj) > tol * jnp.asarray(trG))
        D[j] = F.where(ok, dj, 1.0)
        inv_d = _fdiv(1.0, D[j])
        for i in range(j + 1, m):
            x = G[i][j]
            for k in range(j):
                x = F.sub(x, F.mul(F.mul(L[i][k], L[j][k]), D[k]))
            L[i][j] = F.mul(x, inv_d)
    # W = L⁻¹ (unit lower triangular), row by row
    W = [[1.0 if a == b else 0.0 for b in range(m)] for a in range(m)]
    for i in range(m):
        for j in range(i):
            W[i][j] = F.neg(F.total(F.mul(L[i][k], W[k][j]) for k in range(j, i)))
    # G⁻¹ = Wᵀ D⁻¹ W: tr = Σ_i (Σ_j W_ij²)/D_i
    tr_inv = F.total(_fdiv(_sumsq(W[i][: i + 1]), D[i]) for i in range(m))
    den = F.mul(F.where(ok, trG, 1.0), tr_inv)
    val = jax.lax.rsqrt(jnp.where(ok, den, 1.0))
    return jnp.where(ok, m * val if normalized else val, 0.0)


def _inv_cond_entries(E, norm="fro", normalized=False, dtype=None):
    """(1/k, det J, det G) of a matrix given entry-wise: E[i][j] is a Python float (a
    structural value, e.g. an exact 0 of a Jacobian pattern) or an array; arrays broadcast
    together. det J is None unless the matrix is square and m ≤ 3; det G (= σ_1²…σ_m²) is
    None for m > 3. Structural zeros are folded away at trace time, so e.g. the 9-DOF
    haptic master's J_v (J20 = J21 = 0) costs what a hand-specialised adjugate costs.
    Conventions: the module docstring.
    """
    if norm not in ("fro", "2"):
        raise ValueError(f"norm must be 'fro' or '2', got {norm!r}")
    r, n = len(E), len(E[0])
    m = min(r, n)
    if dtype is None:
        arrs = [x for row in E for x in row if not F.is_const(x)]
        dtype = jnp.result_type(*arrs) if arrs else jnp.result_type(float)
    eps = float(jnp.finfo(dtype).eps)
    if m > 3 and norm == "fro" and m <= _LDL_MAX:
        res = _inv_cond_fro_ldl(E, normalized, eps)
        return jnp.asarray(res).astype(dtype), None, None
    if m > 3:
        flat = [jnp.asarray(x, dtype) for row in E for x in row]
        shape = jnp.broadcast_shapes(*[x.shape for x in flat])
        flat = [jnp.broadcast_to(x, shape) for x in flat]
        J = jnp.stack(flat, -1).reshape(shape + (r, n))
        return inv_cond(J, norm, normalized), None, None
    det = None
    if r == n:
        if m == 1:
            det = E[0][0]
        elif m == 2:
            det = _det2(E[0][0], E[0][1], E[1][0], E[1][1])
        else:
            C = _cof3(E)
            det = F.total(F.mul(E[0][j], C[0][j]) for j in range(3))
    nJ2 = _sumsq([x for row in E for x in row])  # = tr G
    if m == 1:
        res = jnp.where(jnp.asarray(nJ2) > 0, 1.0, 0.0).astype(dtype)
        return res, det, nJ2
    if det is not None:
        detG = F.mul(det, det)
    else:
        detG = _cauchy_binet(E, m)
    if norm == "fro":
        if r == n and m == 3:
            C = _cof3(E)
            den2 = F.mul(nJ2, _sumsq([x for row in C for x in row]))
            ok = jnp.asarray(den2) > 0
            val = jnp.abs(det) * jax.lax.rsqrt(jnp.where(ok, den2, 1.0))
        elif r == n:  # 2×2: ‖adj J‖_F = ‖J‖_F
            ok = jnp.asarray(nJ2) > 0
            val = jnp.abs(det) / jnp.where(ok, nJ2, 1.0)
        else:
            G = _gram(E)
            tradj = (
                nJ2
                if m == 2
                else F.total(
                    _det2(G[a][a], G[a][b], G[b][a], G[b][b]) for a, b in ((0, 1), (0, 2), (1, 2))
                )
            )
            den = F.mul(nJ2, tradj)
            ok = (jnp.asarray(detG) > 0) & (jnp.asarray(den) > 0)
            val = jnp.sqrt(jnp.where(ok, detG, 1.0) / jnp.where(ok, den, 1.0))
        ok = ok & (m * val > max(r, n) * eps)
        res = jnp.where(ok, m * val if normalized else val, 0.0)
    else:
        G = _gram(E)
        ok = jnp.asarray(detG) > 0
        eye = [[1.0 if a == b else 0.0 for b in range(m)] for a in range(m)]
        Gs = [[F.where(ok, G[a][b], eye[a][b]) for b in range(m)] for a in range(m)]
        val = _sym_eig_ratio(Gs, F.where(ok, detG, 1.0))
        res = jnp.where(ok & (val > max(r, n) * eps), val, 0.0)
    return jnp.asarray(res).astype(dtype), det, detG


def singular_values_sq(J: ArrayLike, sweeps: int | None = None) -> Array:
    """Squared singular values (..., m), m = min(r, n), of (..., r, n) matrices by one-sided
    (Hestenes) Jacobi rotations, in plain elementwise arithmetic.

    Columns of A (J or Jᵀ, whichever has m columns) are rotated pairwise until orthogonal;
    their squared norms are then σ². Relative accuracy (no Gram matrix is formed), no LAPACK
    custom call (XLA on CPU runs batched small SVDs slowly, and we saw a LAPACK SVD inside
    a ``lax.scan`` hang nondeterministically), differentiable. ``sweeps`` defaults to
    enough for convergence to machine precision for m ≤ 12 (quadratic convergence).
    """
    J = jnp.asarray(J)
    r, n = J.shape[-2:]
    A = J if n <= r else jnp.swapaxes(J, -1, -2)  # (..., p, m), p ≥ m
    m = A.shape[-1]
    if m == 1:
        return jnp.sum(A * A, axis=(-2, -1))[..., None]
    sweeps = (6 if m <= 4 else 8 if m <= 8 else 10) if sweeps is None else sweeps
    tiny = jnp.finfo(A.dtype).tiny
    p = A.shape[-2]
    # structure of arrays: cols[j][k] = A[..., k, j], so every operation below is
    # elementwise over the batch (XLA fuses it; stacked small axes ran 10x slower under vmap)
    cols = [[A[..., k, j] for k in range(p)] for j in range(m)]

    def dot(a, b):
        out = a[0] * b[0]
        for k in range(1, p):
            out = out + a[k] * b[k]
        return out

    def sweep(_, cols):
        cols = [list(c) for c in cols]
        for i in range(m - 1):
            for j in range(i + 1, m):
                a, b = cols[i], cols[j]
                alpha, beta, gamma = dot(a, a), dot(b, b), dot(a, b)
                rot = jnp.abs(gamma) > tiny
                g = jnp.where(rot, gamma, 1.0)
                zeta = (beta - alpha) / (2.0 * g)
                t = jnp.sign(zeta) / (jnp.abs(zeta) + jnp.sqrt(1.0 + zeta * zeta))
                t = jnp.where(zeta == 0, 1.0, t)
                c = jax.lax.rsqrt(1.0 + t * t)
                sn = jnp.where(rot, c * t, 0.0)
                c = jnp.where(rot, c, 1.0)
                cols[i] = [c * x - sn * y for x, y in zip(a, b, strict=True)]
                cols[j] = [sn * x + c * y for x, y in zip(a, b, strict=True)]
        return cols

    cols = jax.lax.fori_loop(0, sweeps, sweep, cols)
    return jnp.stack([dot(col, col) for col in cols], -1)


def _ratio_from_sv2(s2: Array, r: int, n: int) -> Array:
    """σ_min/σ_max from squared singular values; 0 when numerically singular."""
    eps = jnp.finfo(s2.dtype).eps
    smax2 = jnp.max(s2, -1)
    smin2 = jnp.min(s2, -1)
    ok = smin2 > (max(r, n) * eps) ** 2 * smax2
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, smin2 / jnp.where(ok, smax2, 1.0), 1.0)), 0.0)


def _fro_cholesky(J: Array, normalized: bool) -> Array:
    """Frobenius 1/k for m > 8: ‖J⁺‖_F² = tr(G⁻¹) from the Cholesky factor of G."""
    r, n = J.shape[-2:]
    m = min(r, n)
    eps = jnp.finfo(J.dtype).eps
    Jt = jnp.swapaxes(J, -1, -2)
    G = J @ Jt if r <= n else Jt @ J
    trG = jnp.trace(G, axis1=-2, axis2=-1)
    L0 = jax.lax.stop_gradient(jnp.linalg.cholesky(G))
    piv = jnp.diagonal(L0, axis1=-2, axis2=-1) ** 2
    ok = jnp.all(jnp.isfinite(piv), -1) & (
        jnp.min(jnp.where(jnp.isfinite(piv), piv, 0.0), -1) > m * eps * trG
    )
    eye = jnp.eye(m, dtype=J.dtype)
    Gs = jnp.where(ok[..., None, None], G, eye)
    L = jnp.linalg.cholesky(Gs)
    Linv = jax.scipy.linalg.solve_triangular(L, jnp.broadcast_to(eye, L.shape), lower=True)
    tr_inv = jnp.sum(Linv * Linv, axis=(-2, -1))
    val = jax.lax.rsqrt(jnp.where(ok, trG, 1.0) * tr_inv)
    return jnp.where(ok, m * val if normalized else val, 0.0)


def inv_cond(
    J: ArrayLike, norm: Norm = "fro", normalized: bool = False, with_volume: bool = False
) -> Array | tuple[Array, Array]:
    """1/k of (..., r, n) matrices of any shape (square; r < n, e.g. a 3×7 position
    Jacobian of a redundant arm; r > n, e.g. a 6×3 Jacobian of a 3-joint arm).

    ``norm`` "2": σ_min/σ_max ∈ [0, 1]; "fro": 1/(‖J‖_F‖J⁺‖_F), raw ∈ [0, 1/m], or ×m
    ∈ [0, 1] with ``normalized`` (m = min(r, n)). Singular → exactly 0, finite gradient.
    The method follows the shape (module docstring). ``with_volume`` also returns
    σ_1⋯σ_m = sqrt(det G) (|det J| for square J; Yoshikawa's manipulability), from the
    same closed form (m ≤ 3) or the same Jacobi singular values (m ≥ 4): (1/k, volume).
    """
    J = jnp.asarray(J)
    if not jnp.issubdtype(J.dtype, jnp.floating):
        J = J.astype(jnp.result_type(float))
    if J.ndim < 2:
        raise ValueError(f"inv_cond needs (..., r, n) input, got shape {J.shape}")
    if norm not in ("fro", "2"):
        raise ValueError(f"norm must be 'fro' or '2', got {norm!r}")
    r, n = J.shape[-2:]
    m = min(r, n)
    if m == 0:
        raise ValueError(f"empty matrix shape {J.shape}")
    if m <= 3:
        E = [[J[..., i, j] for j in range(n)] for i in range(r)]
        res, det, detG = _inv_cond_entries(E, norm, normalized, dtype=J.dtype)
        if not with_volume:
            return res
        vol = jnp.abs(det) if det is not None else _fsqrt(detG)
        return res, jnp.broadcast_to(jnp.asarray(vol, J.dtype), res.shape)
    s2 = singular_values_sq(J) if (with_volume or norm == "2") else None
    if norm == "2":
        res = _ratio_from_sv2(s2, r, n)  # no LAPACK call: see singular_values_sq
    elif m <= _LDL_MAX:
        E = [[J[..., i, j] for j in range(n)] for i in range(r)]
        res = _inv_cond_entries(E, norm, normalized, dtype=J.dtype)[0]
    else:
        res = _fro_cholesky(J, normalized)
    if not with_volume:
        return res
    return res, _fsqrt(jnp.prod(s2, -1))


def cond(J: ArrayLike, norm: Norm = "fro", normalized: bool = False) -> Array:
    """k = 1/:func:`inv_cond` (σ_max/σ_min, or ‖J‖_F‖J⁺‖_F raw ≥ m / normalised ≥ 1);
    +inf for a numerically singular matrix."""
    r = inv_cond(J, norm, normalized)
    return jnp.where(r > 0, 1.0 / jnp.where(r > 0, r, 1.0), jnp.inf)
