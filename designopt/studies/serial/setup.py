"""The operating-room set-up: which robot each arm is, as one value the kernels, figures,
report and archive read (issue #67).

Every arm is ``study.chain`` unless it carries its own robot (``arms.<k>.chain``, with its
capsules' ``radius`` and its ``tool_radius``). Arms of one robot form a :class:`Group`,
solved in one batch (one IK per robot in the block program, not one per arm): its
settings are a single-robot *view* of the
study (:func:`view`: the group's chain, collision radii and arms), so the kernel
(``taskindex.chunk_values``) knows one chain at a time. A set-up of one robot is one group
whose view is the study itself: every existing config runs the program it ran before.

The kernel (``taskindex.setup_values``, ``taskindex.group_params``) reads this module;
the groups' values are put back in arm order (:func:`merged`): an arm's joints padded to
the longest chain's count with NaN (no such joint), its capsules to the most capsules by
repeating its last (the same distances), so that the reduction sees (A, M, N, ...) as
with copies of one chain; the arms' radii go with them as (A, L) (:func:`radii`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.studies.serial.settings import SerialSettings

ARM_PARAMS = ("q_lower", "q_upper", "arm_const", "arm_col", "arm_sign", "scene_insertion",
              "scene_port", "scene_geometry")  # fmt: skip
"""The ``params`` entries that belong to a group's arms (its robot's joint limits, its
arms' bases, insertion ranges and ports, its capsules' radii): a mixed set-up's
``params["setup"]`` holds them per group (``taskindex.group_params``)."""


@dataclass(frozen=True)
class Group:
    """Arms of one robot: their indices in ``study.arms``, the single-robot view of the
    study that scores them (:func:`view`) and its chain (``mechanism.Mechanism``)."""

    arms: tuple[int, ...]
    settings: SerialSettings
    mech: Any


def robot_key(s: SerialSettings, k: int) -> str:
    """What makes arm ``k``'s robot: its chain and capsules (equal keys share a group)."""
    a = s.arms[k]  # type: ignore[index]
    chain = s.chain if a.chain is None else a.chain
    return json.dumps([chain.model_dump(mode="json", exclude={"urdf_path"}), a.radius,
                       a.tool_radius, a.role], sort_keys=True)  # fmt: skip


def view(s: SerialSettings, arms: tuple[int, ...]) -> SerialSettings:
    """The study as the arms ``arms`` (all of one robot) see it: their chain, their
    capsules' radii and tool radius in ``collision``, only these arms, each without a
    robot of its own (not validated again: a view of one arm is a one-arm set-up)."""
    a = s.arms[arms[0]]  # type: ignore[index]
    bare = {"chain": None, "radius": None, "tool_radius": None}  # the view's own robot now
    upd: dict[str, Any] = {"arms": [s.arms[k].model_copy(update=bare) for k in arms]}  # type: ignore[index]
    if a.chain is not None:
        upd["chain"] = a.chain
    c = s.collision
    if c is not None and (a.radius is not None or a.tool_radius is not None):
        cu = {k: v for k, v in (("radius", a.radius), ("tool_radius", a.tool_radius))
              if v is not None}  # fmt: skip
        upd["collision"] = c.model_copy(update=cu)
    if a.role == "camera":  # one pose per replication (taskindex.camera_values): no runs of
        # neighbouring targets to seed from
        task = s.task  # type: ignore[union-attr]
        upd["task"] = task.model_copy(update={"ik": task.ik.model_copy(update={"neighbours": 0})})
    return s.model_copy(update=upd)


def mixed(s: SerialSettings) -> bool:
    """Whether some arm carries a robot of its own (``arms.<k>.chain``, ``radius`` or
    ``tool_radius``) or holds the camera (``role: camera``: its own group, whose target is
    the scope's pose, ``taskindex.setup_values``)."""
    return s.arms is not None and any(
        a.chain is not None or a.radius is not None or a.tool_radius is not None
        or a.role == "camera" for a in s.arms)  # fmt: skip


def groups(s: SerialSettings) -> tuple[Group, ...]:
    """The arms grouped by robot, in order of first appearance; one group with the study
    itself as its view when no arm carries its own robot (also without ``arms``)."""
    from designopt.studies.serial.mechanism import build

    key = s.model_dump_json()
    if key not in _GROUPS:
        if not mixed(s):
            gs = (Group(tuple(range(n_arms(s))), s, build(s)),)
        else:
            by: dict[str, list[int]] = {}
            for k in range(n_arms(s)):
                by.setdefault(robot_key(s, k), []).append(k)
            views = [view(s, tuple(v)) for v in by.values()]
            gs = tuple(Group(tuple(v), w, build(w)) for v, w in zip(by.values(), views, strict=True))
        while len(_GROUPS) >= 16:
            _GROUPS.pop(next(iter(_GROUPS)))
        _GROUPS[key] = gs
    return _GROUPS[key]


_GROUPS: dict[str, tuple[Group, ...]] = {}


def arm_view(s: SerialSettings, k: int) -> SerialSettings:
    """The study as arm ``k`` alone sees it (its robot; without ``arms``, the study)."""
    if s.arms is None:
        return s
    for g in groups(s):
        if k in g.arms:
            return g.settings if len(g.arms) == 1 else view(g.settings, (g.arms.index(k),))
    raise IndexError(k)


def n_arms(s: SerialSettings) -> int:
    return 1 if s.arms is None else len(s.arms)


def mechanisms(s: SerialSettings) -> list[Any]:
    """Each arm's chain (``mechanism.Mechanism``), in arm order (one without ``arms``)."""
    out: list[Any] = [None] * n_arms(s)
    for g in groups(s):
        for k in g.arms:
            out[k] = g.mech
    return out


def homes(s: SerialSettings) -> np.ndarray:
    """Every arm's home pose (A, :func:`n_joints`), NaN past an arm's own joints."""
    from designopt.studies.serial.mechanism import home

    ms = mechanisms(s)
    n = max(m.n for m in ms)
    return np.stack([np.concatenate([home(m), np.full(n - m.n, np.nan)]) for m in ms])


def robot_name(s: SerialSettings, k: int) -> str:
    """Arm ``k``'s robot in words: its URDF file's name, or "DH, n joints"."""
    from pathlib import Path

    from designopt.studies.serial.settings import UrdfChain

    ch = arm_view(s, k).chain
    return Path(ch.urdf).name if isinstance(ch, UrdfChain) else f"DH, {len(ch.joints)} joints"


def joint_attrs(s: SerialSettings) -> dict[str, Any]:
    """The archive's joint attributes of a set-up of several robots: ``joints`` q1 … qn
    (n the most joints of any arm; an arm's q is NaN past its own), ``types`` and
    ``q_units`` per column where every arm that has the joint agrees (else "mixed"),
    ``arm_robots`` (each arm's, :func:`robot_name`; " (camera)" after the arm that holds
    the endoscope, whose targets' q is its replication's pose), and each arm's own joint names,
    types and units as JSON (``arm_joints``, ``arm_types``, ``arm_q_units``)."""
    from designopt.studies.serial.mechanism import joint_names
    from designopt.studies.serial.settings import length_unit

    u = length_unit(s)
    names, types = [], []
    for k in range(n_arms(s)):
        v = arm_view(s, k)
        names.append(list(joint_names(v)))
        types.append([j.type for j in v.chain.joints])
    n = max(len(t) for t in types)
    col = [{t[j] for t in types if j < len(t)} for j in range(n)]
    ctype = [c.pop() if len(c) == 1 else "mixed" for c in col]
    return {"joints": [f"q{j + 1}" for j in range(n)], "types": ctype,
            "q_units": ["rad" if t == "R" else u if t == "P" else "mixed" for t in ctype],
            "arm_robots": [robot_name(s, k) + (" (camera)" if k == s.camera_arm() else "")
                           for k in range(n_arms(s))],  # fmt: skip
            "arm_joints": json.dumps(names), "arm_types": json.dumps(types),
            "arm_q_units": json.dumps([["rad" if t == "R" else u for t in ts] for ts in types])}


def n_joints(s: SerialSettings) -> int:
    """The most joints of any arm's chain (the width of a mixed set-up's ``q``)."""
    return max(len(arm_view(s, k).chain.joints) for k in range(n_arms(s)))


def radii(s: SerialSettings, dtype: Any) -> jax.Array:
    """Every arm's capsule radii (A, L), L the most capsules of any arm, an arm with
    fewer padded with its last (:func:`merged` repeats its last capsule)."""
    from designopt.studies.serial import bodies

    rows: list[Any] = [None] * n_arms(s)
    for g in groups(s):
        r = bodies.geometry(g.settings, g.mech).radii  # type: ignore[union-attr]
        for k in g.arms:
            rows[k] = r
    L = max(len(r) for r in rows)
    return jnp.asarray(np.asarray([list(r) + [r[-1]] * (L - len(r)) for r in rows], np.float64),
                       dtype)  # fmt: skip


def merged(s: SerialSettings, outs: list[dict[str, Any]], M: int, xp: Any = jnp
           ) -> dict[str, Any]:  # fmt: skip
    """The groups' chunk values (each (A_g·M, C, ...), arm-major) as one set-up's
    (A·M, C, ...) in arm order: ``q`` padded to :func:`n_joints` with NaN, ``segments``
    to the most capsules by repeating each arm's last."""
    gs = groups(s)
    n = max(o["q"].shape[-1] for o in outs)
    L = max((o["segments"].shape[-3] for o in outs if "segments" in o), default=0)
    parts: dict[str, list[Any]] = {}
    for g, o in zip(gs, outs, strict=True):
        Ag = len(g.arms)
        for key, v in o.items():
            v = v.reshape(Ag, M, *v.shape[1:])
            if key == "q" and v.shape[-1] < n:
                pad = xp.full((*v.shape[:-1], n - v.shape[-1]), xp.nan, v.dtype)
                v = xp.concatenate([v, pad], -1)
            elif key == "segments" and v.shape[-3] < L:
                last = xp.repeat(v[..., -1:, :, :], L - v.shape[-3], -3)
                v = xp.concatenate([v, last], -3)
            parts.setdefault(key, []).append(v)
    order = np.concatenate([np.asarray(g.arms) for g in gs])
    inv = np.argsort(order)
    out = {}
    for key, vs in parts.items():
        v = xp.concatenate(vs, 0)[inv]
        out[key] = v.reshape(-1, *v.shape[2:])
    return out
