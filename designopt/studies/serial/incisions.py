"""The incision points of a planning design: each arm's port on the body wall
(``bodies.port_points``) and the endoscope's (``camera.pose``), and the index
``port_gap``, the least distance between two of them (docs/planning.md)."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.studies.serial import bodies, camera


def incisions(params: dict[str, Any], full: jax.Array, wall: str | None, shared: bool,
              holder: int | None = None) -> jax.Array:  # fmt: skip
    """The incision points (K, M, 3) of designs ``full`` (M, P): each instrument arm's port
    (``bodies.port_points``, on the body wall; one when the arms share ``task.port``,
    ``shared``; not that of the arm ``holder`` that holds the camera, whose port is the
    camera's), then the camera's (``camera.pose``) when there is one."""
    parts = []
    if "scene_port" in params:
        p = bodies.port_points(params, full, wall)
        if holder is not None:
            p = jnp.delete(p, holder, axis=0, assume_unique_indices=True)
        parts.append(p[:1] if shared else p)
    if "scene_camera" in params:
        parts.append(camera.pose(params, full, wall)[0][None])
    return jnp.concatenate(parts)


def port_gap(params: dict[str, Any], full: jax.Array, wall: str | None, shared: bool = False,
             holder: int | None = None) -> jax.Array:  # fmt: skip
    """The ``port_gap`` index (M,): the least distance between two incision points
    (:func:`incisions`: the arms' ports on the body wall and the camera's) of designs
    ``full`` (M, P), in the chain's length unit. Exact (no samples); its gradient is
    finite where two ports meet."""
    p = incisions(params, full, wall, shared, holder)  # (K, M, 3)
    i, j = np.triu_indices(p.shape[0], 1)
    sq = jnp.sum((p[i] - p[j]) ** 2, -1)  # (pairs, M)
    pos = sq > 0
    return jnp.min(jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0), 0)
