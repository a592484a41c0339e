"""Independent references for the kinematics tests: 4×4 homogeneous-matrix products and
``jax.jacfwd`` through them. These were the package's first chain types (``DHChain``,
``ETChain``, the autodiff ``geometric_jacobian``); the frame kernel
(``designopt.kinematics.kernel.SerialModel``) is the only chain type of the product, and
these stay here as a second, independent implementation to test it against.

- ``DHChain(joint_types, convention).fk(DHParams, q)``: product of the DH link transforms
  of ``designopt.kinematics.transforms`` (standard or modified).
- ``ETChain(elements).fk(params, q)``: product of elementary transforms (``ET``).
- ``geometric_jacobian(fk, q, params)``: (…, 6, n) by forward-mode autodiff of a 4×4 FK,
  rows v then ω, column j of ω = vee(∂R/∂q_j Rᵀ). Parameter leaves broadcast against q's
  leading dims with their own trailing ("event") dims kept: the fewest trailing dims whose
  removal lets the rest broadcast against q.shape[:-1] (``event_ndim`` to say it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from designopt.kinematics import transforms as tf
from designopt.kinematics.kernel import ET

Array = jnp.ndarray


def matmul4(A: Array, B: Array) -> Array:
    """Batched product of small homogeneous matrices as a fused multiply-sum.

    XLA on CPU runs batched 4×4 ``dot_general`` far slower than this elementwise form,
    which fuses with the trigonometry around it.
    """
    return jnp.sum(A[..., :, :, None] * B[..., None, :, :], axis=-2)


class DHParams(NamedTuple):
    """Link parameters of a DH table, each of shape (..., n) (leading dims: designs).

    For the modified convention ``alpha``/``a`` are α_{i-1}/a_{i-1} of row i.
    ``theta`` and ``d`` hold the constant parts; the joint variable is added to ``theta``
    (revolute) or ``d`` (prismatic).
    """

    alpha: Array
    a: Array
    d: Array
    theta: Array


@dataclass(frozen=True)
class DHChain:
    """A DH table as data, like the Robotics Toolbox's link tables.

    convention: "standard" (T = Rz(θ) Tz(d) Tx(a) Rx(α)) or "modified"
    (T = Rx(α_{i-1}) Tx(a_{i-1}) Rz(θ_i) Tz(d_i)); joint_types: "R" or "P" per row.
    """

    joint_types: tuple[str, ...]
    convention: Literal["standard", "modified"] = "modified"

    def __post_init__(self) -> None:
        if self.convention not in ("standard", "modified"):
            raise ValueError(
                f"DH convention must be 'standard' or 'modified', got {self.convention!r}"
            )
        bad = [t for t in self.joint_types if t not in ("R", "P")]
        if bad:
            raise ValueError(f"joint types must be 'R' or 'P', got {bad}")

    @property
    def n(self) -> int:
        return len(self.joint_types)

    def link_transforms(self, params: DHParams, q: ArrayLike) -> list[Array]:
        """The n link transforms ^{i-1}T_i, each (..., 4, 4); q: (..., n)."""
        q = jnp.asarray(q)
        if q.shape[-1] != self.n:
            raise ValueError(f"q must have last dimension {self.n}, got shape {q.shape}")
        out = []
        for i, jt in enumerate(self.joint_types):
            th = params.theta[..., i] + (q[..., i] if jt == "R" else 0.0)
            d = params.d[..., i] + (q[..., i] if jt == "P" else 0.0)
            if self.convention == "modified":
                out.append(tf.dh_modified(params.alpha[..., i], params.a[..., i], th, d))
            else:
                out.append(tf.dh_standard(th, d, params.a[..., i], params.alpha[..., i]))
        return out

    def fk(self, params: DHParams, q: ArrayLike, all_frames: bool = False) -> Array:
        """Base-to-tip transform (..., 4, 4); with all_frames, (..., n+1, 4, 4) incl. base."""
        Ts = self.link_transforms(params, q)
        T = jnp.broadcast_to(jnp.eye(4, dtype=Ts[0].dtype), Ts[0].shape)
        frames = [T]
        for Ti in Ts:
            T = matmul4(T, Ti)
            frames.append(T)
        return jnp.stack(frames, axis=-3) if all_frames else T


_ET_FN = {
    "Rx": tf.rotx,
    "Ry": tf.roty,
    "Rz": tf.rotz,
    "Tx": tf.transx,
    "Ty": tf.transy,
    "Tz": tf.transz,
}


@dataclass(frozen=True)
class ETChain:
    """A sequence of elementary transforms (the da Vinci chain of seed 002 eq. 1-3)."""

    elements: tuple[ET, ...]

    @property
    def n(self) -> int:
        js = [e.joint for e in self.elements if e.joint is not None]
        return max(js) + 1 if js else 0

    def fk(self, params: dict[str, ArrayLike], q: ArrayLike) -> Array:
        q = jnp.asarray(q)
        if q.shape[-1] != self.n:
            raise ValueError(f"q must have last dimension {self.n}, got shape {q.shape}")
        T = None
        for e in self.elements:
            v = jnp.asarray(e.const, dtype=q.dtype)
            if e.param is not None:
                if e.param not in params:
                    raise ValueError(f"missing chain parameter {e.param!r}")
                v = v + e.scale * jnp.asarray(params[e.param], dtype=q.dtype)
            if e.joint is not None:
                v = v + q[..., e.joint]
            Ti = _ET_FN[e.kind](v)
            T = Ti if T is None else matmul4(T, Ti)
        return T


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
