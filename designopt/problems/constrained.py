"""Constrained benchmark problems with known optima (constraints g(x) ≤ 0).

- ``sphere_linear(D)``: min Σ x² s.t. Σ x ≥ 1 on [−5, 5]^D; optimum x_i = 1/D, f* = 1/D
  (the constraint is active).
- ``g06``: CEC 2006 problem g06 (Liang et al. 2006): min (x1 − 10)³ + (x2 − 20)³ s.t.
  −(x1 − 5)² − (x2 − 5)² + 100 ≤ 0, (x1 − 6)² + (x2 − 5)² − 82.81 ≤ 0, 13 ≤ x1 ≤ 100,
  0 ≤ x2 ≤ 100; f* = −6961.81387558015 at (14.095, 0.84296), a thin crescent of a feasible
  region (0.0066 % of the box) with both constraints active.
- ``g08``: CEC 2006 g08: min −sin³(2π x1)·sin(2π x2)/(x1³ (x1 + x2)) s.t.
  x1² − x2 + 1 ≤ 0, 1 − x1 + (x2 − 4)² ≤ 0 on [0, 10]²; f* = −0.0958250414180359 at
  (1.2279713, 4.2453733).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from designopt.problems.base import Problem


def _sphere_fn(p, X, key):
    y = jnp.sum(X * X, axis=1)
    return y, {"f": y}


def _sphere_cons(p, X):
    return (1.0 - jnp.sum(X, axis=1))[:, None]


def _g06_fn(p, X, key):
    y = (X[:, 0] - 10.0) ** 3 + (X[:, 1] - 20.0) ** 3
    return y, {"f": y}


def _g06_cons(p, X):
    x1, x2 = X[:, 0], X[:, 1]
    return jnp.stack(
        [-((x1 - 5.0) ** 2) - (x2 - 5.0) ** 2 + 100.0, (x1 - 6.0) ** 2 + (x2 - 5.0) ** 2 - 82.81],
        axis=1,
    )


def _g08_fn(p, X, key):
    x1, x2 = X[:, 0], X[:, 1]
    y = -(jnp.sin(2 * jnp.pi * x1) ** 3) * jnp.sin(2 * jnp.pi * x2) / (x1**3 * (x1 + x2))
    return y, {"f": y}


def _g08_cons(p, X):
    x1, x2 = X[:, 0], X[:, 1]
    return jnp.stack([x1 * x1 - x2 + 1.0, 1.0 - x1 + (x2 - 4.0) ** 2], axis=1)


def sphere_linear(dim: int = 5) -> Problem:
    names = tuple(f"x{i}" for i in range(dim))
    info = {"function": "sphere_linear", "optimum": np.full(dim, 1.0 / dim), "f_opt": 1.0 / dim}
    return Problem(
        names, np.full(dim, -5.0), np.full(dim, 5.0), _sphere_fn, None, info, _sphere_cons
    )


def g06() -> Problem:
    info = {"function": "g06", "optimum": np.array([14.09500000000000064, 0.8429607892154795668]),
            "f_opt": -6961.81387558015}  # fmt: skip
    return Problem(("x1", "x2"), np.array([13.0, 0.0]), np.array([100.0, 100.0]), _g06_fn, None,
                   info, _g06_cons)  # fmt: skip


def g08() -> Problem:
    info = {"function": "g08", "optimum": np.array([1.22797135260752599, 4.24537336612274885]),
            "f_opt": -0.0958250414180359}  # fmt: skip
    return Problem(("x1", "x2"), np.array([0.0, 0.0]), np.array([10.0, 10.0]), _g08_fn, None,
                   info, _g08_cons)  # fmt: skip


CONSTRAINED = {"sphere_linear": sphere_linear, "g06": g06, "g08": g08}
