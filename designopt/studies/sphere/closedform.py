"""Closed forms of the spherical RCM's index at (α12, α23) = (90°, 90°) (docs/sphere.md):
the references the Monte-Carlo estimate is tested against. numpy only, float64.

With both link angles 90°, z1·z2 = 0 and z2·u = 0, so the Jacobian's columns z1 × u and
z2 × u are orthogonal with norms sin φ and 1 (φ the angle between axis 1 and the tool):
1/k = sin φ at every direction (sin φ ≤ 1), and every direction is reached (φ from 0 to
180°). The index is then the mean of sin φ over the cone's cap. With the cap of half-angle
β about an axis at angle γ from axis 1, a direction at angle t from the cap's axis and
azimuth ψ about it has cos φ = cos t cos γ + sin t sin γ cos ψ, and:

- γ = 0 (the cone about axis 1): φ = t, mean = (β/2 − sin 2β/4)/(1 − cos β);
- γ = 90° (the cone's axis ⟂ axis 1): sin φ = √(1 − sin²t cos²ψ); its mean over ψ is
  (2/π)E(sin t) (E the complete elliptic integral of the second kind), and with
  (2/π)E(k) = Σ a_n k^{2n}, a_n = −(C(2n, n)/4ⁿ)²/(2n − 1), the mean over the cap is
  Σ a_n I_n/(1 − cos β), I_n = ∫_{cos β}^1 (1 − x²)ⁿ dx, by the recurrence
  I_n = (2n I_{n−1} − cos β sin^{2n} β)/(2n + 1), I_0 = 1 − cos β; the terms fall as
  sin^{2n} β (β = 30°: 4⁻ⁿ);
- any γ: (1/(2π(1 − cos β))) ∫ sin²φ Λ(φ) dφ, Λ(φ) = 2 arccos((cos β − cos φ cos γ)
  /(sin φ sin γ)) the azimuthal width of the cap at φ (:func:`mean_right_angles_quad`).
"""

from __future__ import annotations

import math

import numpy as np


def inv_cond_right_angles(phi: np.ndarray) -> np.ndarray:
    """1/k at (90°, 90°) of the direction at angle φ (rad) from axis 1: |sin φ|."""
    return np.abs(np.sin(phi))


def mean_axis_cone(half_angle: float) -> float:
    """The index at (90°, 90°) for the cone about axis 1 (γ = 0), half-angle β (rad)."""
    b = float(half_angle)
    return (b / 2.0 - math.sin(2.0 * b) / 4.0) / (1.0 - math.cos(b))


def mean_perpendicular_cone(
    half_angle: float, tol: float = 1e-17, max_terms: int = 100_000
) -> float:
    """The index at (90°, 90°) for a cone whose axis is ⟂ axis 1 (γ = 90°), half-angle β
    (rad, 0 < β < 90°): the series above, summed until a term is below ``tol``."""
    b = float(half_angle)
    if not 0.0 < b < math.pi / 2:
        raise ValueError(f"half_angle must lie in (0, π/2), got {b}")
    cb, sb2 = math.cos(b), math.sin(b) ** 2
    i_n, bn, p = 1.0 - cb, 1.0, 1.0  # I_0, C(0,0)/4^0, sin^0 β
    total = i_n  # a_0 = 1
    for n in range(1, max_terms):
        bn *= (2 * n - 1) / (2 * n)
        p *= sb2
        i_n = (2 * n * i_n - cb * p) / (2 * n + 1)
        term = -(bn * bn) / (2 * n - 1) * i_n
        total += term
        if abs(term) < tol * (1.0 - cb):
            break
    return total / (1.0 - cb)


def _gauss(a: float, b: float, f, n: int) -> float:
    """∫_a^b f by Gauss-Legendre after φ = a + (b − a)(1 − cos πs)/2 (a square-root edge
    of the integrand becomes smooth in s)."""
    if b <= a:
        return 0.0
    x, w = np.polynomial.legendre.leggauss(n)
    s = 0.5 * (x + 1.0)
    phi = a + (b - a) * 0.5 * (1.0 - np.cos(np.pi * s))
    dphi = (b - a) * 0.5 * np.pi * np.sin(np.pi * s) * 0.5
    return float(np.sum(w * f(phi) * dphi))


def mean_right_angles_quad(half_angle: float, axis_angle: float, n: int = 400) -> float:
    """The index at (90°, 90°) for any cone (half-angle β, axis at γ from axis 1; rad):
    the one-dimensional integral above, split where Λ changes form."""
    b, g = float(half_angle), float(axis_angle)
    cb, cg, sg = math.cos(b), math.cos(g), math.sin(g)

    def width(phi: np.ndarray) -> np.ndarray:
        den = np.sin(phi) * sg
        with np.errstate(divide="ignore", invalid="ignore"):
            x = (cb - np.cos(phi) * cg) / den
        x = np.where(den > 0, x, np.where(np.cos(phi) * cg >= cb, -np.inf, np.inf))
        return 2.0 * np.arccos(np.clip(x, -1.0, 1.0))

    f = lambda phi: np.sin(phi) ** 2 * width(phi)  # noqa: E731
    lo, hi = max(0.0, g - b), min(math.pi, g + b)
    cuts = sorted({lo, hi} | {c for c in (b - g, 2 * math.pi - g - b) if lo < c < hi})
    total = sum(_gauss(a, c, f, n) for a, c in zip(cuts[:-1], cuts[1:], strict=True))
    return total / (2.0 * math.pi * (1.0 - cb))


def mean_right_angles(half_angle: float, axis_angle: float) -> float:
    """The index at (90°, 90°): the exact forms for γ = 0, 90° and 180°, the quadrature
    otherwise (rad)."""
    g = float(axis_angle)
    if g == 0.0 or g == math.pi:
        return mean_axis_cone(half_angle)
    if g == math.pi / 2 and half_angle < math.pi / 2:
        return mean_perpendicular_cone(half_angle)
    return mean_right_angles_quad(half_angle, g)
