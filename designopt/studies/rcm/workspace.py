"""The Monte-Carlo workspace of the 3-DOF arm (seed 003 §3.2, Fig. 6): joint samples
uniform in (θ1, d1, d2), their tips by eq. (24), and the workspace volume
V = ∫_Q |det ∂P/∂q| dq = |Q|·mean |det| (mechanism.arm_det) with its standard error.
The map is one-to-one on the branch d > 0 (the tip beyond R), so the integral is the
volume of the point cloud's region; where d changes sign in Q it counts overlaps twice
(reported as ``d_min`` < 0)."""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from designopt.numerics import montecarlo as mc
from designopt.studies.rcm import mechanism as m


class Workspace(NamedTuple):
    points: jax.Array  # (n, 3) tip positions, mm
    joints: jax.Array  # (n, 3) θ1 (rad), d1, d2
    volume: jax.Array  # mm³
    volume_se: jax.Array
    d_min: jax.Array  # smallest insertion depth over the samples


@partial(jax.jit, static_argnames=("n",))
def sample(key: jax.Array, design: jax.Array, lower: jax.Array, upper: jax.Array,
           n: int) -> Workspace:  # fmt: skip
    """n uniform joint samples of the box [lower, upper] (θ1 in rad) for the design
    (a, c, L): tips, and the volume ± SE."""
    dt = design.dtype
    a, c, L = design[0], design[1], design[2]
    q = lower + (upper - lower) * jax.random.uniform(key, (n, 3), dt)
    P = m.arm_fk(q[:, 0], q[:, 1], q[:, 2], a, c, L)
    det = m.arm_det(q[:, 1], q[:, 2], a, c)
    vol = mc.box_integral(mc.power_sums(det, jnp.ones_like(det)), jnp.prod(upper - lower))
    d = m.depth(q[:, 1], q[:, 2], a, c)
    return Workspace(P, q, vol.value, vol.se, jnp.min(d))


def built(key: jax.Array, n: int = 100_000, L: float = 0.0, dtype: Any = None) -> Workspace:
    """The built arm's workspace (Tables 1-2; L = 0 puts R at the origin)."""
    dt = mc.out_dtype(dtype)
    lo = jnp.asarray([np.deg2rad(-38.0), 22.0, 35.0], dt)
    hi = jnp.asarray([np.deg2rad(38.0), 215.0, 200.0], dt)
    return sample(key, jnp.asarray([m.BUILT["a"], m.BUILT["c"], L], dt), lo, hi, n)
