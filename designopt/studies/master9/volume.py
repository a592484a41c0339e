"""Point-cloud workspace volumes of the 9-DOF master's position mechanism (cross-checks).

- ``voxel_volume``: occupancy of a regular grid of voxel centres, where a centre counts
  as reachable iff the closed-form position IK finds joints within limits (exact
  membership, so no sampling-density bias; error ~ surface × h / 2, largely cancelling).
- ``hull_volume``: convex hull of FK samples (scipy, optional); ≥ the true volume since
  the workspace is not convex. The paper's published volumes are consistent with a hull.
"""

from __future__ import annotations

from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from designopt.studies.master9 import mechanism as m


def _cloud(design: Mapping[str, float], n: int, key: jax.Array, limits: np.ndarray) -> np.ndarray:
    lo, hi = jnp.asarray(limits[:, 0]), jnp.asarray(limits[:, 1])
    q = jax.random.uniform(key, (n, 3), jnp.float64, lo, hi)
    return np.asarray(m.position(q, design))


def voxel_volume(
    design: Mapping[str, float],
    h: float = 4.0,
    limits: np.ndarray | None = None,
    chunk: int = 2_000_000,
) -> float:
    """Volume (mm³) of the reachable set of (q1, q2, q3) within ``limits`` on an h-mm grid."""
    limits = m.POSITION_LIMITS if limits is None else np.asarray(limits)
    d = {**m.default_design(), **design}
    pts = _cloud(d, 200_000, jax.random.key(0), limits)
    lo = pts.min(0) - 2 * h
    hi = pts.max(0) + 2 * h
    axes = [np.arange(lo[i] + h / 2, hi[i], h) for i in range(3)]
    shape = tuple(len(a) for a in axes)
    lo_l, hi_l = jnp.asarray(limits[:, 0]), jnp.asarray(limits[:, 1])

    @jax.jit
    def count(idx, valid):
        i = idx // (shape[1] * shape[2])
        j = (idx // shape[2]) % shape[1]
        k = idx % shape[2]
        p = jnp.stack(
            [jnp.asarray(axes[0])[i], jnp.asarray(axes[1])[j], jnp.asarray(axes[2])[k]], -1
        )
        q, ok = m.ik_position(p, d)
        inside = ok & jnp.all((q >= lo_l) & (q <= hi_l), -1)
        return jnp.sum(inside & valid)

    total = int(np.prod(shape))
    n = 0
    for start in range(0, total, chunk):
        idx = jnp.arange(start, start + chunk)
        valid = idx < total
        n += int(count(jnp.where(valid, idx, 0), valid))
    return n * h**3


def hull_volume(
    design: Mapping[str, float], n: int = 200_000, seed: int = 0, limits: np.ndarray | None = None
) -> float:
    """Convex-hull volume (mm³) of n FK samples; needs scipy (the ``test``/``bench`` extras)."""
    try:
        from scipy.spatial import ConvexHull
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("hull_volume needs scipy: pip install 'designopt[test]'") from e
    limits = m.POSITION_LIMITS if limits is None else np.asarray(limits)
    d = {**m.default_design(), **design}
    return float(ConvexHull(_cloud(d, n, jax.random.key(seed), limits)).volume)
