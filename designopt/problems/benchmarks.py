"""Benchmark test functions (seed 000 Table 2, SPEC §3.3) as swarm problems.

Each takes X (M, D) and returns (M,). Optional shift s (seeded): f_s(x) = f(x − s), so the
optimum moves to x* + s and an optimizer biased toward the box centre is exposed.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from designopt.problems.base import Problem


def sphere(x):
    return jnp.sum(x * x, axis=-1)


def rastrigin(x):
    return 10.0 * x.shape[-1] + jnp.sum(x * x - 10.0 * jnp.cos(2 * jnp.pi * x), axis=-1)


def griewank(x):
    i = jnp.arange(1, x.shape[-1] + 1, dtype=x.dtype)
    return 1.0 + jnp.sum(x * x, axis=-1) / 4000.0 - jnp.prod(jnp.cos(x / jnp.sqrt(i)), axis=-1)


def ackley(x):
    D = x.shape[-1]
    a = -20.0 * jnp.exp(-0.2 * jnp.sqrt(jnp.sum(x * x, axis=-1) / D))
    return a - jnp.exp(jnp.sum(jnp.cos(2 * jnp.pi * x), axis=-1) / D) + 20.0 + jnp.e


def rosenbrock(x):
    return jnp.sum(100.0 * (x[..., 1:] - x[..., :-1] ** 2) ** 2 + (1.0 - x[..., :-1]) ** 2, axis=-1)


def schwefel226(x):
    return 418.9828872724338 * x.shape[-1] - jnp.sum(x * jnp.sin(jnp.sqrt(jnp.abs(x))), axis=-1)


# name: (function, half-width of the standard box, optimum coordinate)
FUNCTIONS = {
    "sphere": (sphere, 100.0, 0.0),
    "rastrigin": (rastrigin, 5.12, 0.0),
    "griewank": (griewank, 600.0, 0.0),
    "ackley": (ackley, 32.768, 0.0),
    "rosenbrock": (rosenbrock, 30.0, 1.0),
    "schwefel226": (schwefel226, 500.0, 420.9687462275036),
}


def optimum(name: str, dim: int, shift: np.ndarray | None = None) -> np.ndarray:
    x = np.full(dim, FUNCTIONS[name][2])
    return x if shift is None else x + shift


@functools.cache
def _problem_fn(name: str):
    """One swarm function per test function (cached: shifted and unshifted problems share
    it, and so share the optimizer's compiled kernel; the shift is an array parameter)."""
    f = FUNCTIONS[name][0]

    def fn(p, X, key):
        y = f(X - p["shift"].astype(X.dtype))
        return y, {"f": y}

    return fn


def benchmark(name: str, dim: int = 30, shift: int | None = None) -> Problem:
    """A test function as a Problem on its standard box; ``shift`` seeds a random shift of
    the optimum, drawn so the shifted optimum stays inside 80 % of the box."""
    if name not in FUNCTIONS:
        raise ValueError(f"unknown benchmark function {name!r}; known: {sorted(FUNCTIONS)}")
    if dim < 1:
        raise ValueError(f"dim must be ≥ 1, got {dim}")
    f, half, xopt = FUNCTIONS[name]
    if shift is None:
        s = np.zeros(dim)
    else:
        with jax.enable_x64(True):  # the same float64 shift whatever the caller's x64 setting
            u = np.asarray(
                jax.random.uniform(jax.random.key(shift), (dim,), jnp.float64, -1.0, 1.0)
            )
        room = 0.8 * half - abs(xopt)
        s = u * room
    params = {"shift": jnp.asarray(s)}
    fn = _problem_fn(name)
    lower, upper = np.full(dim, -half), np.full(dim, half)
    info = {
        "function": name,
        "dim": dim,
        "shift_seed": shift,
        "shift": s,
        "optimum": optimum(name, dim, s),
    }
    return Problem(tuple(f"x{i}" for i in range(dim)), lower, upper, fn, params, info)
