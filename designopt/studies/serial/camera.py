"""The endoscope of a planning study (``study.task.camera``, docs/planning.md): where its
tip sits and what it sees, as pure functions of the design and the scene's arrays.

The scope passes through its own port (the design's point projected onto the body wall,
as the arms' ports are) along the line to ``aim`` (the task region's centre unless
given). Its tip goes in to the depth that puts ``aim`` in the middle of the working band,
clipped to ``insertion``: d = clip(|aim − port| − (near + far)/2, d0, d1). A target t is
*seen* when, with v = t − tip,

- its distance lies in the band: near ≤ |v| ≤ far;
- it lies in the field of view: the angle between v and the scope's axis is at most
  half of ``fov``;
- the line of sight, the segment from the tip to t, keeps a positive distance from every
  ``inside`` obstacle (the anatomy occludes; the instruments do not).

With ``shaft`` the scope is also a capsule from its tip ``length`` back along its axis
(through the port and out of the patient) that every arm's links and instrument keep
``collision.margin`` from: the IK refuses a solution that meets it, as it refuses one
that meets an obstacle (``taskindex.chunk_values``).

``view_ok`` is the share of the task's targets seen (Agresti–Coull SE, never below the
replications' batch-means SE: ``taskindex``'s shares). It needs no IK: one (M, N) array
operation per design block.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics import collision as col
from designopt.kinematics.task import region_center_radius
from designopt.studies.serial import bodies
from designopt.studies.serial.settings import SerialSettings


def aim(s: SerialSettings) -> np.ndarray:
    """The point the scope looks at (3,): ``camera.aim``, else the task region's centre."""
    cam = s.task.camera  # type: ignore[union-attr]
    if cam.aim is not None:
        return np.asarray(cam.aim, np.float64)
    return region_center_radius(s.task.region)[0]  # type: ignore[union-attr]


def camera_params(s: SerialSettings, dtype: Any) -> dict[str, Any]:
    """The camera's numbers as ``params`` (``scene_camera``: its port's entries ``const``,
    ``col``, ``sign`` (1, 3) as ``bodies.port_params``'s, ``aim`` (3,), ``cos_half`` (the
    cosine of half the field of view), ``band`` (2,), ``insertion`` (2,)), so that editing
    any of them compiles nothing. Empty without a camera."""
    cam = None if s.task is None else s.task.camera
    if cam is None:
        return {}
    const, cols, sign = bodies._entries((*s.variables, *s.fixed), [cam.port])
    ins = cam.insertion if cam.insertion is not None else (0.0, math.inf)
    return {"scene_camera": {
        "const": jnp.asarray(const, dtype), "col": jnp.asarray(cols),
        "sign": jnp.asarray(sign, dtype), "aim": jnp.asarray(aim(s), dtype),
        "cos_half": jnp.asarray(math.cos(math.radians(cam.fov) / 2), dtype),
        "band": jnp.asarray(np.asarray(cam.band, np.float64), dtype),
        "insertion": jnp.asarray(np.asarray(ins, np.float64), dtype)}
        | ({} if cam.shaft is None else {"shaft": jnp.asarray(
            np.asarray([cam.shaft.length, cam.shaft.radius], np.float64), dtype)})}  # fmt: skip


def pose(params: dict[str, Any], full: jax.Array, wall: str | None
         ) -> tuple[jax.Array, jax.Array, jax.Array]:  # fmt: skip
    """(incision point (M, 3), tip (M, 3), unit axis (M, 3)) of the scope for designs
    ``full`` (M, P): the port on the body wall of kind ``wall`` (None: the design's
    point), the axis towards ``aim``, the tip at the depth of the module docstring."""
    from designopt.kinematics import wall as kw

    sc = params["scene_camera"]
    dt = full.dtype
    p = bodies._values(sc["const"], sc["col"], sc["sign"], full)  # (1, M, 3)
    if wall is not None:
        p = kw.project(wall, params["scene_wall"], p)
    p = p[0]
    v = sc["aim"].astype(dt) - p
    n = jnp.linalg.norm(v, axis=-1, keepdims=True)
    z = v / jnp.maximum(n, jnp.finfo(dt).tiny)
    band, ins = sc["band"].astype(dt), sc["insertion"].astype(dt)
    d = jnp.clip(n - (band[0] + band[1]) / 2, ins[0], ins[1])
    return p, p + d * z, z


def shaft(params: dict[str, Any], full: jax.Array, wall: str | None
          ) -> tuple[jax.Array, jax.Array, jax.Array]:  # fmt: skip
    """The scope's rigid shaft as a capsule for designs ``full`` (M, P): (tip (M, 3), the
    far end ``length`` back along the axis (M, 3), radius ()) (``camera.shaft``)."""
    _, tip, z = pose(params, full, wall)
    sh = params["scene_camera"]["shaft"].astype(full.dtype)
    return tip, tip - sh[0] * z, sh[1]


def seen(params: dict[str, Any], full: jax.Array, wall: str | None, pt: jax.Array
         ) -> jax.Array:  # fmt: skip
    """(M, N) bool: which targets ``pt`` (N, 3) the scope of each design sees (module
    docstring); the anatomy is ``params["scene_inside"]`` when there is one."""
    sc = params["scene_camera"]
    dt = full.dtype
    _, tip, z = pose(params, full, wall)
    v = pt.astype(dt)[None] - tip[:, None]  # (M, N, 3)
    r = jnp.linalg.norm(v, axis=-1)
    band = sc["band"].astype(dt)
    ok = (r >= band[0]) & (r <= band[1])
    ok = ok & (jnp.sum(v * z[:, None], -1) >= r * sc["cos_half"].astype(dt))
    if "scene_inside" in params:
        inner = jax.tree_util.tree_map(lambda a: a.astype(dt), params["scene_inside"])
        seg = jnp.stack([jnp.broadcast_to(tip[:, None], v.shape),
                         jnp.broadcast_to(pt.astype(dt)[None], v.shape)], -2)[..., None, :, :]  # fmt: skip
        ok = ok & (col.clearance(seg, jnp.zeros((1,), dt), inner) > 0)
    return ok
