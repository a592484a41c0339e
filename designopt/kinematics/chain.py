"""Serial chains described as data: DH tables and elementary-transform sequences.

A chain's *structure* (convention, joint types, which element a joint drives) is static
Python data; its *numbers* (link lengths, twists, offsets) are array inputs, so one
compiled kernel serves a whole swarm of designs, a sweep, and ``jax.grad``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple

import jax.numpy as jnp
from jax.typing import ArrayLike

from designopt.kinematics import transforms as tf

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


ETKind = Literal["Rx", "Ry", "Rz", "Tx", "Ty", "Tz"]
_ET_FN = {
    "Rx": tf.rotx,
    "Ry": tf.roty,
    "Rz": tf.rotz,
    "Tx": tf.transx,
    "Ty": tf.transy,
    "Tz": tf.transz,
}


@dataclass(frozen=True)
class ET:
    """One elementary transform: ``kind`` with value ``const + params[param] + q[joint]``.

    ``param`` names a design parameter (array input), ``joint`` a joint index; either may be
    None. Rotations are revolute joints, translations prismatic.
    """

    kind: ETKind
    joint: int | None = None
    param: str | None = None
    const: float = 0.0
    scale: float = 1.0  # multiplies the param (e.g. -1 for Rx(-alpha))

    def __post_init__(self) -> None:
        if self.kind not in _ET_FN:
            raise ValueError(f"elementary transform kind must be one of {sorted(_ET_FN)}")


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
