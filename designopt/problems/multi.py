"""Multi-objective benchmark problems with known Pareto fronts (all objectives minimised).

- ZDT1, ZDT2, ZDT3 (Zitzler, Deb & Thiele, "Comparison of multiobjective evolutionary
  algorithms: empirical results", 2000): D = 30 on [0, 1]^D, two objectives,
  f1 = x1, g = 1 + 9·Σ_{i≥2} x_i/(D − 1), f2 = g·h(f1, g) with h = 1 − √(f1/g) (convex
  front), 1 − (f1/g)² (concave) and 1 − √(f1/g) − (f1/g)·sin(10π f1) (five disconnected
  pieces). The front is g = 1 (x2..xD = 0).
- DTLZ2 (Deb, Thiele, Laumanns & Zitzler, "Scalable test problems for evolutionary
  multiobjective optimization", 2005): m objectives, D = m + k − 1 (k = 10 by default:
  D = 12 for m = 3) on [0, 1]^D, g = Σ_{i≥m} (x_i − 0.5)², f_j = (1 + g)·Π cos(x_i π/2)…
  sin(·); the front is the unit sphere's positive orthant (Σ f_j² = 1, g = 0).
- BNH (Binh & Korn 1997) and SRN (Srinivas & Deb, "Multiobjective optimization using
  nondominated sorting in genetic algorithms", 1994): two objectives, two constraints
  g ≤ 0, two variables. SRN's constraints cut its unconstrained front, so its front is
  only found through constrained domination: the line x1 = −2.5 (where ∇f1 ∥ −∇f2) for
  x2 ≥ 2.5, continued by the constraint boundaries where they are active — the line
  x1 = 3·x2 − 10 up to f1's constrained minimum (1.1, 3.7) and the circle
  x1² + x2² = 225 beyond x1 = −2.5 (the often quoted "x1 = −2.5, x2 ∈ [2.5, 14.79]" is
  only the middle piece; ``true_front`` samples all three and keeps the non-dominated
  part, checked against a brute-force scan in tests/test_nsga2.py). BNH's front:
  x1 = x2 ∈ [0, 3], then x2 = 3, x1 ∈ [3, 5] (its constraints are inactive there).

``MULTI_FUNCTIONS`` maps a name to (objective function, constraints or None, box, default
dim, default m); ``multi_benchmark(name, dim=None, n_objectives=None)`` builds the
``Problem`` (``n_objectives`` set, ``info`` naming the function) and
``true_front(name, n_points, n_objectives)`` samples its Pareto front (for IGD+ and the
optimal hypervolume). ``benchmarks.py`` holds the single-objective functions the same way.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from designopt.numerics.pareto import non_dominated
from designopt.problems.base import Problem


def zdt1(x):
    f1 = x[:, 0]
    g = 1.0 + 9.0 * jnp.sum(x[:, 1:], axis=1) / (x.shape[1] - 1)
    return jnp.stack([f1, g * (1.0 - jnp.sqrt(f1 / g))], axis=1)


def zdt2(x):
    f1 = x[:, 0]
    g = 1.0 + 9.0 * jnp.sum(x[:, 1:], axis=1) / (x.shape[1] - 1)
    return jnp.stack([f1, g * (1.0 - (f1 / g) ** 2)], axis=1)


def zdt3(x):
    f1 = x[:, 0]
    g = 1.0 + 9.0 * jnp.sum(x[:, 1:], axis=1) / (x.shape[1] - 1)
    h = 1.0 - jnp.sqrt(f1 / g) - (f1 / g) * jnp.sin(10.0 * jnp.pi * f1)
    return jnp.stack([f1, g * h], axis=1)


def dtlz2(x, m: int):
    """DTLZ2 with m objectives (the first m − 1 variables are the angles)."""
    g = jnp.sum((x[:, m - 1 :] - 0.5) ** 2, axis=1)
    th = x[:, : m - 1] * (jnp.pi / 2)
    # cos(π/2) is −4.4e-8 in float32: clamped at 0 (exact on [0, π/2]), else designs at
    # x_i = 1 get a negative objective that falls as g grows and crowd the front's edges
    c, s = jnp.maximum(jnp.cos(th), 0.0), jnp.maximum(jnp.sin(th), 0.0)
    cols = []
    for j in range(m):  # f_j = (1+g) Π_{i<m−1−j} cos θ_i · (sin θ_{m−1−j} if j > 0)
        f = jnp.prod(c[:, : m - 1 - j], axis=1)
        if j > 0:
            f = f * s[:, m - 1 - j]
        cols.append((1.0 + g) * f)
    return jnp.stack(cols, axis=1)


def bnh(x):
    x1, x2 = x[:, 0], x[:, 1]
    return jnp.stack([4 * x1**2 + 4 * x2**2, (x1 - 5) ** 2 + (x2 - 5) ** 2], axis=1)


def bnh_constraints(x):
    x1, x2 = x[:, 0], x[:, 1]
    return jnp.stack([(x1 - 5) ** 2 + x2**2 - 25.0, 7.7 - (x1 - 8) ** 2 - (x2 + 3) ** 2], axis=1)


def srn(x):
    x1, x2 = x[:, 0], x[:, 1]
    return jnp.stack([2 + (x1 - 2) ** 2 + (x2 - 1) ** 2, 9 * x1 - (x2 - 1) ** 2], axis=1)


def srn_constraints(x):
    x1, x2 = x[:, 0], x[:, 1]
    return jnp.stack([x1**2 + x2**2 - 225.0, x1 - 3 * x2 + 10.0], axis=1)


class MultiFunction(NamedTuple):
    fn: Callable  # x (M, D) [, m] → F (M, m)
    constraints: Callable | None  # x (M, D) → G (M, n_c), g ≤ 0
    lower: tuple[float, ...] | float  # per variable (fixed D) or one value for all
    upper: tuple[float, ...] | float
    dim: int  # default D (None: m + 9 for DTLZ)
    n_objectives: int  # default m
    scalable: bool  # m may be chosen (DTLZ)
    fixed_dim: bool  # D may not be chosen (BNH, SRN)


MULTI_FUNCTIONS: dict[str, MultiFunction] = {
    "zdt1": MultiFunction(zdt1, None, 0.0, 1.0, 30, 2, False, False),
    "zdt2": MultiFunction(zdt2, None, 0.0, 1.0, 30, 2, False, False),
    "zdt3": MultiFunction(zdt3, None, 0.0, 1.0, 30, 2, False, False),
    "dtlz2": MultiFunction(dtlz2, None, 0.0, 1.0, 12, 3, True, False),
    "bnh": MultiFunction(bnh, bnh_constraints, (0.0, 0.0), (5.0, 3.0), 2, 2, False, True),
    "srn": MultiFunction(srn, srn_constraints, (-20.0, -20.0), (20.0, 20.0), 2, 2, False, True),
}


@functools.cache
def _problem_fn(name: str, m: int):
    """One swarm function per (function, m): problems share compiled kernels."""
    e = MULTI_FUNCTIONS[name]

    def fn(p, X, key):
        F = e.fn(X, m) if e.scalable else e.fn(X)
        return F, {f"f{j + 1}": F[:, j] for j in range(m)}

    return fn


@functools.cache
def _constraint_fn(name: str):
    g = MULTI_FUNCTIONS[name].constraints
    return None if g is None else (lambda p, X: g(X))


def multi_benchmark(name: str, dim: int | None = None, n_objectives: int | None = None) -> Problem:
    """A multi-objective test problem by name (``MULTI_FUNCTIONS``) as a ``Problem`` with
    ``n_objectives`` set; ``dim`` and (DTLZ only) ``n_objectives`` override the defaults
    (DTLZ2: D = m + 9 unless given)."""
    key = str(name).lower()
    if key not in MULTI_FUNCTIONS:
        raise ValueError(
            f"unknown multi-objective benchmark {name!r}; known: {', '.join(MULTI_FUNCTIONS)}"
        )
    e = MULTI_FUNCTIONS[key]
    m = e.n_objectives if n_objectives is None else int(n_objectives)
    if m != e.n_objectives and not e.scalable:
        raise ValueError(f"{key} has {e.n_objectives} objectives; n_objectives={m} given")
    if m < 2:
        raise ValueError(f"n_objectives must be ≥ 2, got {m}")
    if dim is not None and e.fixed_dim and dim != e.dim:
        raise ValueError(f"{key} has dim {e.dim}; dim={dim} given")
    D = (m + 9 if e.scalable else e.dim) if dim is None else int(dim)
    need = m if e.scalable else 2
    if D < need:
        raise ValueError(f"dim must be ≥ {need} for {key} with {m} objectives, got {D}")
    lower = np.broadcast_to(np.asarray(e.lower, np.float64), (D,)).copy()
    upper = np.broadcast_to(np.asarray(e.upper, np.float64), (D,)).copy()
    info = {"function": key, "dim": D, "n_objectives": m}
    return Problem(tuple(f"x{i}" for i in range(D)), lower, upper, _problem_fn(key, m), None,
                   info, _constraint_fn(key), n_objectives=m)  # fmt: skip


def _simplex_grid(m: int, n: int) -> np.ndarray:
    """Das & Dennis points on the unit simplex with about n points (m objectives)."""
    h = 1
    while _count(m, h + 1) <= n:
        h += 1
    pts = []

    def rec(prefix, left, k):
        if k == m - 1:
            pts.append([*prefix, left])
            return
        for i in range(left + 1):
            rec([*prefix, i], left - i, k + 1)

    rec([], h, 0)
    return np.asarray(pts, np.float64) / h


def _count(m: int, h: int) -> int:
    from math import comb

    return comb(h + m - 1, m - 1)


def true_front(name: str, n_points: int = 1000, n_objectives: int | None = None) -> np.ndarray:
    """A sample (n, m) of the Pareto front of ``name`` (ZDT3: the non-dominated part of
    the curve g = 1; DTLZ2: Das-Dennis directions scaled onto the unit sphere, about
    ``n_points`` of them)."""
    key = str(name).lower()
    if key not in MULTI_FUNCTIONS:
        raise ValueError(f"unknown multi-objective benchmark {name!r}")
    e = MULTI_FUNCTIONS[key]
    m = e.n_objectives if n_objectives is None else int(n_objectives)
    t = np.linspace(0.0, 1.0, n_points)
    if key == "zdt1":
        return np.stack([t, 1 - np.sqrt(t)], axis=1)
    if key == "zdt2":
        return np.stack([t, 1 - t**2], axis=1)
    if key == "zdt3":
        t = np.linspace(0.0, 1.0, 20 * n_points)
        F = np.stack([t, 1 - np.sqrt(t) - t * np.sin(10 * np.pi * t)], axis=1)
        F = F[non_dominated(F)]
        return F[np.linspace(0, len(F) - 1, min(n_points, len(F))).round().astype(int)]
    if key == "dtlz2":
        W = _simplex_grid(m, n_points)
        return W / np.linalg.norm(W, axis=1, keepdims=True)
    if key == "srn":  # the three pieces that can be Pareto-optimal, non-dominated part
        u = np.linspace(0.0, 1.0, 4 * n_points)
        x2 = 2.5 + u * (np.sqrt(225.0 - 6.25) - 2.5)  # x1 = −2.5 (∇f1 ∥ −∇f2)
        line = 2.5 + 1.2 * u  # on x1 = 3·x2 − 10 (g2 active), up to f1's minimum there
        th = np.arccos(-2.5 / 15) + u * (np.pi / 2 - 0.01)  # on x1² + x2² = 225 (g1 active)
        X = np.concatenate([np.stack([np.full_like(x2, -2.5), x2], 1),
                            np.stack([3 * line - 10, line], 1),
                            np.stack([15 * np.cos(th), 15 * np.sin(th)], 1)])  # fmt: skip
        X = X[np.asarray(srn_constraints(jnp.asarray(X))).max(axis=1) <= 1e-9]
        F = np.asarray(srn(jnp.asarray(X)))
        F = F[non_dominated(F)]
        F = F[np.argsort(F[:, 0])]
        return F[np.linspace(0, len(F) - 1, min(n_points, len(F))).round().astype(int)]
    if key == "bnh":
        s = 5 * t  # x1 = x2 ∈ [0, 3], then x2 = 3, x1 ∈ [3, 5]
        x1, x2 = s, np.minimum(s, 3.0)
        return np.asarray(bnh(jnp.asarray(np.stack([x1, x2], axis=1))))
    raise ValueError(f"no known front for {key!r}")
