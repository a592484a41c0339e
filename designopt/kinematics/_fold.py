"""Trace-time constant folding for scalar expressions (used by the frame kernel).

A *scalar* here is either a Python float (a value known when the kernel is traced: a
structural 0, ±1, cos of a constant twist ...) or a JAX array. The helpers fold the
Python constants away, so products with a structural zero vanish from the traced graph
instead of becoming ``x * 0`` (which XLA must keep for IEEE semantics). Python floats are
weakly typed, so they never promote a float32 computation to float64.
"""

from __future__ import annotations

from typing import Union

import jax.numpy as jnp

Array = jnp.ndarray
Scalar = Union[float, Array]  # noqa: UP007


def is_const(x: object) -> bool:
    return isinstance(x, (int, float))


def neg(a: Scalar) -> Scalar:
    if is_const(a):
        return -float(a)
    return -a


def mul(a: Scalar, b: Scalar) -> Scalar:
    if is_const(a) and is_const(b):
        return float(a) * float(b)
    if is_const(b):
        a, b = b, a
    if is_const(a):
        if a == 0.0:
            return 0.0
        if a == 1.0:
            return b
        if a == -1.0:
            return -b
        return float(a) * b
    return a * b


def add(a: Scalar, b: Scalar) -> Scalar:
    if is_const(a) and is_const(b):
        return float(a) + float(b)
    if is_const(a) and a == 0.0:
        return b
    if is_const(b) and b == 0.0:
        return a
    return a + b


def sub(a: Scalar, b: Scalar) -> Scalar:
    if a is b:
        return 0.0
    if is_const(a) and is_const(b):
        return float(a) - float(b)
    if is_const(b) and b == 0.0:
        return a
    if is_const(a) and a == 0.0:
        return -b
    return a - b


def mul_sub(a: Scalar, b: Scalar, c: Scalar, d: Scalar) -> Scalar:
    """a·b − c·d, folded to an exact 0 when the two products are the same product."""
    if (a is c and b is d) or (a is d and b is c):
        return 0.0
    return sub(mul(a, b), mul(c, d))


def total(xs) -> Scalar:
    """Left-to-right sum with folding."""
    acc: Scalar = 0.0
    for x in xs:
        acc = add(acc, x)
    return acc


def is_design(x: Scalar) -> bool:
    """Per-design arrays are 2-D ((M, 1) or (M, C)); per-sample arrays are 1-D (C,)."""
    return not is_const(x) and jnp.ndim(x) == 2


def where(ok, a: Scalar, b: Scalar) -> Scalar:
    if is_const(a) and is_const(b) and a == b:
        return a
    return jnp.where(ok, a, b)
