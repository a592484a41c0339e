"""The problem abstraction every optimizer and study uses.

A problem is a design box plus a *pure* function ``fn(params, X, key) -> (f, aux)`` that
scores a whole swarm X (M, D) in one call: f (M,) and named sub-objectives aux[name] (M,).
``params`` is a pytree of arrays (fixed lengths, normalisation bounds, sample keys …),
passed as an argument rather than baked into the trace, so one compiled kernel serves a
swarm, a sweep, and ``jax.grad``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

Array = jnp.ndarray
ProblemFn = Callable[[Any, Array, jax.Array], tuple[Array, dict[str, Array]]]


@dataclass(frozen=True, eq=False)
class Problem:
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    fn: ProblemFn
    params: Any = None
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        lo, hi = np.asarray(self.lower, np.float64), np.asarray(self.upper, np.float64)
        if lo.shape != (len(self.names),) or hi.shape != lo.shape:
            raise ValueError(
                f"lower/upper must have shape ({len(self.names)},), got {lo.shape}, {hi.shape}"
            )
        bad = [n for n, a, b in zip(self.names, lo, hi, strict=True) if not a < b]
        if bad:
            raise ValueError(f"lower must be < upper for {bad}")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @property
    def dim(self) -> int:
        return len(self.names)

    def evaluate(self, X: Array, key: jax.Array | None = None) -> tuple[Array, dict[str, Array]]:
        """Fitness (M,) and sub-objectives of a swarm X (M, D)."""
        X = jnp.asarray(X)
        if X.ndim != 2 or X.shape[1] != self.dim:
            raise ValueError(f"X must have shape (M, {self.dim}), got {tuple(X.shape)}")
        key = jax.random.key(0) if key is None else key
        return self.fn(self.params, X, key)
