"""Condition numbers of Jacobians (seed 000 eq. 35 and appendix eq. 51-52).

Conventions, stated once for the whole API:
- ``cond_2``  = σ_max/σ_min (≥ 1).  ``cond_fro`` = ‖J‖_F·‖J⁻¹‖_F (≥ n for n×n, *raw*;
  pass ``normalized=True`` for k/n ≥ 1, the Gosselin-Angeles convention).
- ``inv_*`` return 1/k in [0, 1] (2-norm, or normalised Frobenius) or [0, 1/n] (raw
  Frobenius). A singular matrix gives exactly 0, never NaN or inf, and the gradient of
  ``inv_cond_fro3`` stays finite there.
"""

from __future__ import annotations

from typing import Literal

import jax.numpy as jnp
from jax.typing import ArrayLike

Array = jnp.ndarray


def _safe_div(num: Array, den: Array) -> Array:
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def cofactors3(J: ArrayLike) -> Array:
    """Cofactor matrix C of a (..., 3, 3) matrix; adj(J) = Cᵀ and det J = Σ_j J_0j C_0j."""
    J = jnp.asarray(J)
    a, b, c = J[..., 0, 0], J[..., 0, 1], J[..., 0, 2]
    d, e, f = J[..., 1, 0], J[..., 1, 1], J[..., 1, 2]
    g, h, i = J[..., 2, 0], J[..., 2, 1], J[..., 2, 2]
    rows = [
        [e * i - f * h, f * g - d * i, d * h - e * g],
        [c * h - b * i, a * i - c * g, b * g - a * h],
        [b * f - c * e, c * d - a * f, a * e - b * d],
    ]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def det3(J: ArrayLike) -> Array:
    """Determinant of (..., 3, 3) by cofactor expansion (no LU, differentiable)."""
    J = jnp.asarray(J)
    return jnp.sum(J[..., 0, :] * cofactors3(J)[..., 0, :], axis=-1)


def inv_cond_fro3(J: ArrayLike, normalized: bool = False) -> Array:
    """1/k_F for 3×3 matrices in closed form: |det J| / (‖J‖_F ‖adj J‖_F), no SVD.

    ‖J⁻¹‖_F = ‖adj J‖_F/|det J| (seed 000 eq. 51-52). Raw values lie in [0, 1/3];
    ``normalized`` multiplies by 3 so that the range is [0, 1].
    """
    J = jnp.asarray(J)
    if J.shape[-2:] != (3, 3):
        raise ValueError(f"inv_cond_fro3 needs (..., 3, 3) input, got shape {J.shape}")
    C = cofactors3(J)
    det = jnp.sum(J[..., 0, :] * C[..., 0, :], axis=-1)
    nJ2 = jnp.sum(J * J, axis=(-2, -1))
    nC2 = jnp.sum(C * C, axis=(-2, -1))
    den2 = nJ2 * nC2
    ok = den2 > 0
    den = jnp.sqrt(jnp.where(ok, den2, 1.0))
    r = jnp.where(ok, jnp.abs(det) / den, 0.0)
    return 3.0 * r if normalized else r


def _svals(J: ArrayLike) -> Array:
    J = jnp.asarray(J)
    if J.shape[-1] != J.shape[-2]:
        raise ValueError(f"condition numbers here need square matrices, got shape {J.shape}")
    return jnp.linalg.svd(J, compute_uv=False)  # descending


def _rank_deficient(s: Array) -> Array:
    """σ_min ≤ n·eps·σ_max: numerically singular (numpy.linalg.matrix_rank's tolerance)."""
    eps = jnp.finfo(s.dtype).eps
    return s[..., -1] <= s.shape[-1] * eps * s[..., 0]


def inv_cond_2(J: ArrayLike) -> Array:
    """σ_min/σ_max in [0, 1]; exactly 0 for numerically singular matrices (and J = 0)."""
    s = _svals(J)
    return jnp.where(_rank_deficient(s), 0.0, _safe_div(s[..., -1], s[..., 0]))


def cond_2(J: ArrayLike) -> Array:
    """σ_max/σ_min (seed 000 eq. 35); +inf for a singular matrix."""
    r = inv_cond_2(J)
    return jnp.where(r > 0, 1.0 / jnp.where(r > 0, r, 1.0), jnp.inf)


def inv_cond_fro(J: ArrayLike, normalized: bool = False) -> Array:
    """1/(‖J‖_F ‖J⁻¹‖_F) for any square size (3×3 uses the closed form)."""
    J = jnp.asarray(J)
    if J.shape[-2:] == (3, 3):
        return inv_cond_fro3(J, normalized)
    s = _svals(J)
    n = J.shape[-1]
    ok = ~_rank_deficient(s)
    s_safe = jnp.where(ok[..., None], s, 1.0)
    kf = jnp.sqrt(jnp.sum(s_safe**2, -1)) * jnp.sqrt(jnp.sum(1.0 / s_safe**2, -1))
    r = jnp.where(ok, 1.0 / kf, 0.0)
    return n * r if normalized else r


def cond_fro(J: ArrayLike, normalized: bool = False) -> Array:
    """‖J‖_F·‖J⁻¹‖_F (raw, ≥ n) or k/n when normalized; +inf for singular matrices."""
    r = inv_cond_fro(J, normalized)
    return jnp.where(r > 0, 1.0 / jnp.where(r > 0, r, 1.0), jnp.inf)


def inv_cond(J: ArrayLike, norm: Literal["fro", "2"] = "fro", normalized: bool = False) -> Array:
    """Dispatch: 1/k in the chosen norm. ``normalized`` only affects the Frobenius norm."""
    if norm == "fro":
        return inv_cond_fro(J, normalized)
    if norm == "2":
        return inv_cond_2(J)
    raise ValueError(f"norm must be 'fro' or '2', got {norm!r}")
