"""Jacobians from autodiff of any forward-kinematics function (SPEC §2).

``fk(q, params) -> (4, 4)`` for one configuration and one set of parameters (a pytree
of arrays, e.g. a design dict); the helpers vectorise over the leading dimensions of q
and of the parameter leaves, which must broadcast against each other.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

Array = jnp.ndarray


def _batch(fn: Callable[[Array, Any], Array], q: Array, params: Any) -> Array:
    leaves = jax.tree_util.tree_leaves(params)
    lead = jnp.broadcast_shapes(q.shape[:-1], *[jnp.shape(x) for x in leaves])
    qf = jnp.broadcast_to(q, lead + q.shape[-1:]).reshape((-1, q.shape[-1]))
    pf = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, lead).reshape(-1), params)
    out = jax.vmap(fn)(qf, pf)
    return out.reshape(lead + out.shape[1:])


def position_jacobian(fk: Callable[[Array, Any], Array], q: Array, params: Any = None) -> Array:
    """∂p/∂q, shape (..., 3, n), by forward-mode autodiff of the tip position."""
    q = jnp.asarray(q)
    return _batch(jax.jacfwd(lambda x, p: fk(x, p)[:3, 3]), q, params)


def geometric_jacobian(fk: Callable[[Array, Any], Array], q: Array, params: Any = None) -> Array:
    """Geometric Jacobian in the base frame, (..., 6, n): rows v (linear) then ω.

    Column j of the angular block is vee(∂R/∂q_j Rᵀ), exact for any chain, including
    ones with passive joints coupled inside ``fk``.
    """
    q = jnp.asarray(q)

    def one(x: Array, p: Any) -> Array:
        dT, T = jax.jacfwd(lambda y: (fk(y, p), fk(y, p)), has_aux=True)(x)  # (4, 4, n), (4, 4)
        Jv = dT[:3, 3, :]
        W = jnp.einsum("ikn,jk->ijn", dT[:3, :3, :], T[:3, :3])  # skew-symmetric per column
        Jw = jnp.stack([W[2, 1], W[0, 2], W[1, 0]], axis=0)
        return jnp.concatenate([Jv, Jw], axis=0)

    return _batch(one, q, params)
