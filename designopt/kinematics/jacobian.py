"""Jacobians from autodiff of any forward-kinematics function (SPEC §2).

``fk(q, params) -> (4, 4)`` for one configuration and one set of parameters (a pytree
of arrays, e.g. a design dict or a chain's own ``DHParams``); the helpers vectorise over
the leading dimensions of q and of the parameter leaves.

Broadcasting rule for a parameter leaf of shape S against q of shape B + (n,): the leaf
is split into batch dims and per-configuration ("event") dims, S = S_batch + S_event,
taking the *fewest* trailing event dims such that S_batch broadcasts against B. So a
design dict of scalars or (M, 1) arrays is batched as before, while DHParams leaves of
shape (n,) (one chain) or (M, 1, n) (a swarm, with q of shape (C, n)) keep their
per-joint axis and reach ``fk`` as (n,). Where this is ambiguous (a leaf (k,) whose k
also broadcasts against B) it is read as batched; pass ``event_ndim`` (an int for every
leaf, or a pytree of ints matching ``params``) to say it explicitly.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

Array = jnp.ndarray


def _split(shape: tuple[int, ...], B: tuple[int, ...], e: int | None) -> int:
    """Number of event (trailing, per-configuration) dims of a leaf of this shape."""
    if e is not None:
        if not 0 <= e <= len(shape):
            raise ValueError(f"event_ndim {e} out of range for a leaf of shape {shape}")
        return e
    for e in range(len(shape) + 1):
        try:
            jnp.broadcast_shapes(shape[: len(shape) - e], B)
            return e
        except ValueError:
            continue
    return len(shape)


def _batch(fn: Callable[[Array, Any], Array], q: Array, params: Any, event_ndim=None) -> Array:
    B = q.shape[:-1]
    leaves, tree = jax.tree_util.tree_flatten(params)
    leaves = [jnp.asarray(x) for x in leaves]
    if event_ndim is None or isinstance(event_ndim, int):
        es = [_split(x.shape, B, event_ndim) for x in leaves]
    else:
        es = [
            _split(x.shape, B, e)
            for x, e in zip(leaves, tree.flatten_up_to(event_ndim), strict=True)
        ]
    batch = [x.shape[: x.ndim - e] for x, e in zip(leaves, es, strict=True)]
    lead = jnp.broadcast_shapes(B, *batch)
    qf = jnp.broadcast_to(q, lead + q.shape[-1:]).reshape((-1, q.shape[-1]))
    pf = [
        jnp.broadcast_to(x, lead + x.shape[x.ndim - e :]).reshape((-1,) + x.shape[x.ndim - e :])
        for x, e in zip(leaves, es, strict=True)
    ]
    out = jax.vmap(fn)(qf, jax.tree_util.tree_unflatten(tree, pf))
    return out.reshape(lead + out.shape[1:])


def position_jacobian(
    fk: Callable[[Array, Any], Array], q: Array, params: Any = None, event_ndim=None
) -> Array:
    """∂p/∂q, shape (..., 3, n), by forward-mode autodiff of the tip position."""
    q = jnp.asarray(q)
    return _batch(jax.jacfwd(lambda x, p: fk(x, p)[:3, 3]), q, params, event_ndim)


def geometric_jacobian(
    fk: Callable[[Array, Any], Array], q: Array, params: Any = None, event_ndim=None
) -> Array:
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

    return _batch(one, q, params, event_ndim)
