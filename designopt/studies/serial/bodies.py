"""The serial study's bodies: link capsules, ports, obstacles and several arms (docs/task.md).

Under ``study.collision`` every link of the chain is a capsule (``links: auto``) from its
joint's origin to the next joint's origin (the tip for the last), of the configured
radius, so the shapes follow the design variables. Links of zero length in every design
(e.g. between the coincident joints of a spherical wrist) are points inside their
neighbours' capsules and are left out. The self-collision pairs are the non-adjacent
pairs of the remaining links, less the pairs that overlap in nearly every configuration
(≥ :data:`ALWAYS` of 512 joint draws at the middle design: two links that meet at a short
offset link, whose capsules overlap wherever the joints are) — the "always in
collision" pairs a MoveIt set-up also disables; they are listed by :func:`describe`.

With a port the instrument passes through the body wall there: the part of the chain
beyond the port plane (through the port, normal to the tool axis) is inside the patient
and is not checked against the obstacles (the patient's body, the table). The link that
crosses the plane is cut twice its radius before it: its capsule touches the body wall
at the port, and that neighbourhood (the trocar's) is not checked. So a tool leaning more
than 60° from a half-space's normal at the port reads as touching it. Links before it
are checked in full, and every link in the self-collision check.

Several arms (``study.arms``) are copies of the chain at base frames T_k(x) (their
``xyz``/``rpy`` entries numbers or design variables): each arm solves the task in its own
base frame, and its capsules are placed in the world by T_k for the obstacle and the
arm-against-arm checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics import collision as col
from designopt.studies.serial.mechanism import Mechanism
from designopt.studies.serial.settings import SerialSettings


@partial(jax.jit, static_argnums=0)
def _origins(model: Any, X: jax.Array, q: jax.Array) -> jax.Array:
    """Joint origins (M, C, n + 1, 3): one compiled call (op by op, the set-up checks
    compiled some hundred one-op programs)."""
    return model.joint_frames(X, q)[0]


@partial(jax.jit, static_argnums=(0, 3))
def _ends(model: Any, X: jax.Array, q: jax.Array, links: tuple[int, ...]) -> jax.Array:
    """Capsule end points (M, C, L, 2, 3) of the kept links: one compiled call."""
    return _segments(model.joint_frames(X, q)[0], links)


@partial(jax.jit, static_argnums=2)
def _pair_gaps(seg: jax.Array, radii: jax.Array, pairs: tuple) -> jax.Array:
    """Capsule distances (C, len(pairs)) of the link pairs of segments (C, L, 2, 3)."""
    i, j = np.asarray(pairs).T
    return col.capsule_capsule(seg[:, i, 0], seg[:, i, 1], radii[i], seg[:, j, 0],
                               seg[:, j, 1], radii[j])  # fmt: skip


@jax.jit
def _link_gaps(seg: jax.Array, radii: jax.Array, obst: Any) -> jax.Array:
    """Each link's clearance to the obstacles (C, L) of segments (C, L, 2, 3)."""
    return jnp.stack([col.clearance(seg[:, j : j + 1], radii[j : j + 1], obst)
                      for j in range(seg.shape[1])], -1)  # fmt: skip


ALWAYS = 0.95
"""A link pair whose capsules overlap in at least this share of random configurations
(at the middle design) is not checked (it would collide everywhere)."""


@dataclass(frozen=True)
class Geometry:
    """What the collision checks need that does not change with the design: the
    capsules (``links: auto``: the chain links kept; ``links: urdf``: the URDF's shapes,
    ``urdf`` = (imported path, bindings, capsules in their link frames)), their radii,
    the self-collision pairs (indices into the capsules) and the pairs left out as
    always overlapping."""

    links: tuple[int, ...]
    radii: tuple[float, ...]
    pairs: tuple[tuple[int, int], ...]
    always: tuple[tuple[int, int], ...]
    margin: float
    self_check: bool
    cap: float  # the longest reach of any design: a clearance counts at most this much
    names: tuple[str, ...] = ()  # what each capsule is, for messages
    urdf: Any = None

    def outer(self, model: Any, X: jax.Array, q: jax.Array) -> jax.Array:
        """Capsule end points (M, C, L, 2, 3) for designs X (M, P) and joints q (C, n)."""
        if self.urdf is None:
            return _ends(model, X, q, self.links)
        from designopt.kinematics.urdf_collision import world_capsules

        imp, bindings, caps = self.urdf
        return world_capsules(imp, bindings, caps, X, q)[0]

    def items(self, model: Any, X: jax.Array, q: jax.Array) -> jax.Array:
        """Capsule end points (B, L, 2, 3) of items: designs X (B, P), joints q (B, n)."""
        return jax.vmap(lambda x, qq: self.outer(model, x[None], qq[None])[0, 0])(X, q)


def _middle(mech: Mechanism, s: SerialSettings) -> np.ndarray:
    lo, hi = s.box()[1:]
    return np.concatenate([(np.asarray(lo) + np.asarray(hi)) / 2, mech.fixed]) * mech.scale


def geometry(s: SerialSettings, mech: Mechanism) -> Geometry | None:
    """The study's link capsules and pairs (None without ``study.collision``), found by
    evaluating the chain at set-up (also when called while a program is traced)."""
    if s.collision is None:
        return None
    key = s.model_dump_json()
    if key not in _GEOMETRY:
        try:  # at set-up: the jitted helpers run as compiled programs
            _GEOMETRY[key] = _geometry(s, mech)
        except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
            # first asked while a program is traced: evaluated op by op (some fifty
            # one-op programs, hence not the first choice)
            with jax.ensure_compile_time_eval():
                _GEOMETRY[key] = _geometry(s, mech)
    return _GEOMETRY[key]


_GEOMETRY: dict[str, Geometry] = {}


def _geometry(s: SerialSettings, mech: Mechanism) -> Geometry:
    c = s.collision
    assert c is not None
    rng = np.random.default_rng(0)
    lo, hi = s.box()[1:]
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    X = np.concatenate([lo + (hi - lo) * rng.uniform(size=(8, len(lo))),
                        np.broadcast_to(mech.fixed, (8, len(mech.fixed)))], 1) * mech.scale  # fmt: skip
    X = np.concatenate([X, _middle(mech, s)[None]])
    xl = np.concatenate([lo, mech.fixed]) * mech.scale
    xh = np.concatenate([hi, mech.fixed]) * mech.scale
    cap = mech.model.reach_bound(np.minimum(xl, xh), np.maximum(xl, xh), mech.lower, mech.upper)
    if c.links == "urdf":
        return _urdf_geometry(s, mech, c, cap)
    q = mech.lower + (mech.upper - mech.lower) * rng.uniform(size=(64, mech.n))
    P = np.asarray(_origins(mech.model, jnp.asarray(X), jnp.asarray(q)))
    n = mech.model.n_chain
    radius = list(c.radius) if isinstance(c.radius, list) else [float(c.radius)] * n  # type: ignore[arg-type]
    length = np.linalg.norm(np.diff(P, axis=-2), axis=-1).max(axis=(0, 1))  # (n,)
    scale = max(float(np.abs(P).max()), 1e-12)
    links = tuple(i for i in range(n) if length[i] > 1e-9 * scale)
    if not links:
        raise ValueError("collision: every link of the chain has zero length")
    radii = tuple(radius[i] for i in links)
    g = Geometry(links, radii, (), (), float(c.margin), bool(c.self_), cap,
                 tuple(f"link {i + 1}" for i in links))  # fmt: skip
    pairs = col.nonadjacent_pairs(len(links)) if c.self_ else ()
    return _drop_always(g, s, mech, pairs, rng)


def _urdf_geometry(s: SerialSettings, mech: Mechanism, c: Any, cap: float) -> Geometry:
    """``links: urdf``: a capsule per ``<collision>`` element of the path's links; the
    pairs are those of links that are not neighbours on the path."""
    from designopt.kinematics.urdf_collision import capsules, path_links
    from designopt.studies.serial.mechanism import urdf_bindings

    ch = s.chain
    imp = ch.imported  # type: ignore[union-attr]
    caps = tuple(capsules(ch.urdf_text, ch.urdf_path, imp))  # type: ignore[union-attr]
    if not caps:
        raise ValueError(f"collision.links: the URDF has no <collision> shape on the links "
                         f"from '{imp.base}' to '{imp.tip}'; use links: auto with a radius")  # fmt: skip
    order = path_links(imp)
    pos = [order.index(k.link) for k in caps]
    pairs = tuple((i, j) for i in range(len(caps)) for j in range(i + 1, len(caps))
                  if abs(pos[i] - pos[j]) >= 2) if c.self_ else ()  # fmt: skip
    g = Geometry(tuple(range(len(caps))), tuple(float(k.radius) for k in caps), (), (),
                 float(c.margin), bool(c.self_), cap, tuple(k.link for k in caps),
                 (imp, urdf_bindings(s), caps))  # fmt: skip
    return _drop_always(g, s, mech, pairs, np.random.default_rng(0))


def _drop_always(g: Geometry, s: SerialSettings, mech: Mechanism, pairs: tuple,
                 rng: np.random.Generator) -> Geometry:  # fmt: skip
    """``g`` with the self-collision ``pairs``, less those overlapping in ≥ ALWAYS of 512
    random configurations at the middle design."""
    from dataclasses import replace

    if not pairs:
        return g
    q = mech.lower + (mech.upper - mech.lower) * rng.uniform(size=(512, mech.n))
    seg = np.asarray(g.outer(mech.model, jnp.asarray(_middle(mech, s))[None], jnp.asarray(q)))[0]
    d = np.asarray(_pair_gaps(seg, np.asarray(g.radii), tuple(pairs)))
    keep, always = [], []
    for p, ij in enumerate(pairs):
        (always if np.mean(d[:, p] < g.margin) >= ALWAYS else keep).append(ij)
    return replace(g, pairs=tuple(keep), always=tuple(always))


def _segments(P: Any, links: tuple[int, ...]) -> Any:
    """(..., L, 2, 3) capsule end points of the kept links from joint origins (..., n + 1, 3)."""
    xp = np if isinstance(P, np.ndarray) else jnp
    idx = np.asarray(links)
    return xp.stack([P[..., idx, :], P[..., idx + 1, :]], -2)


def describe(g: Geometry) -> str:
    """One line on the capsules: links, radii, pairs checked and left out."""
    left = f"; left out as always overlapping: {list(g.always)}" if g.always else ""
    return (f"capsules on {', '.join(g.names)} (radii {list(g.radii)}), "
            f"{len(g.pairs)} self-collision pair(s){left}")  # fmt: skip


# ------------------------------------------------------------------- base frames


def rpy_matrix(r: Any, p: Any, y: Any) -> jax.Array:
    """R = Rz(y)·Ry(p)·Rx(r) (radians), (..., 3, 3)."""
    cr, sr, cp, sp, cy, sy = (jnp.cos(r), jnp.sin(r), jnp.cos(p), jnp.sin(p), jnp.cos(y),
                              jnp.sin(y))  # fmt: skip
    return jnp.stack([
        jnp.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
        jnp.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
        jnp.stack([-sp, cp * sr, cp * cr], -1),
    ], -2)  # fmt: skip


def base_params(s: SerialSettings, mech: Mechanism, dtype: Any) -> dict[str, jax.Array]:
    """The arms' base entries as arrays: ``arm_const`` (A, 6) (xyz in length units, rpy in
    rad) and ``arm_col`` (A, 6) int, the design column (variables then fixed, kernel
    units) an entry reads, −1 for a number, and ``arm_sign`` (A, 6), −1 for "-name".
    Empty without ``arms``."""
    if s.arms is None:
        return {}
    const = np.zeros((len(s.arms), 6))
    cols = -np.ones((len(s.arms), 6), np.int32)
    sign = np.ones((len(s.arms), 6))
    for k, a in enumerate(s.arms):
        for i, v in enumerate((*a.base.xyz, *a.base.rpy)):
            if isinstance(v, str):
                cols[k, i] = mech.names.index(v.removeprefix("-"))
                sign[k, i] = -1.0 if v.startswith("-") else 1.0
            else:
                const[k, i] = math.radians(v) if i >= 3 else float(v)
    ports = np.asarray(s.ports() if s.ports()[0] is not None else np.zeros((0, 3)))
    out = {"arm_const": jnp.asarray(const, dtype), "arm_col": jnp.asarray(cols),
           "arm_sign": jnp.asarray(sign, dtype)}  # fmt: skip
    return out | ({"arm_port": jnp.asarray(ports, dtype)} if len(ports) else {})


def base_frames(params: dict[str, Any], full: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(R (A, M, 3, 3), t (A, M, 3)) of every arm's base for designs ``full`` (M, P)."""
    c, k = params["arm_const"].astype(full.dtype), params["arm_col"]
    sg = params["arm_sign"].astype(full.dtype)
    v = c[:, None, :] + jnp.where(k[:, None, :] >= 0,
                                  sg[:, None, :] * jnp.moveaxis(full[:, jnp.maximum(k, 0)], 0, 1),
                                  0.0)  # fmt: skip
    return rpy_matrix(v[..., 3], v[..., 4], v[..., 5]), v[..., :3]


# ---------------------------------------------------------------------- clearance


def cut_at_port(seg: jax.Array, port: jax.Array, z: jax.Array, radii: jax.Array) -> jax.Array:
    """The capsule end points (..., L, 2, 3) with the part inside the patient removed:
    links before the last link that starts before the port plane (through ``port``
    (..., 3), normal the tool axis ``z`` (..., 3)) are kept; that link, the one through
    the port, is cut 2·r (its radii ``radii`` (L,)) before the plane, since its capsule
    touches the body wall at the port (the trocar's neighbourhood is not checked); the
    links after it (inside) collapse onto the cut piece, so they add nothing to a minimum
    over the links."""
    a, b = seg[..., 0, :], seg[..., 1, :]
    sa = jnp.sum((a - port[..., None, :]) * z[..., None, :], -1)  # (..., L)
    sb = jnp.sum((b - port[..., None, :]) * z[..., None, :], -1)
    L = seg.shape[-3]
    idx = jnp.arange(L)
    c = jnp.max(jnp.where(sa < 0, idx, 0), -1)  # the last link starting before the plane
    length = jnp.linalg.norm(b - a, axis=-1)
    t = jnp.where(sb > sa, -sa / jnp.where(sb > sa, sb - sa, 1.0), 1.0)  # the crossing
    t = jnp.clip(t - 2 * radii / jnp.maximum(length, 1e-300), 0.0, 1.0)
    cut_b = a + t[..., None] * (b - a)

    def at_c(v):  # (..., L, 3) -> (..., 3) at link c
        return jnp.take_along_axis(v, jnp.broadcast_to(c[..., None, None], (*c.shape, 1, 3)),
                                   -2)[..., 0, :]  # fmt: skip

    cut = jnp.stack([at_c(a), at_c(cut_b)], -2)  # (..., 2, 3)
    return jnp.where((idx >= c[..., None])[..., None, None], cut[..., None, :, :], seg)


def obstacle_and_self(g: Geometry, obst: Any, seg: jax.Array, port: jax.Array | None,
                      z: jax.Array | None) -> jax.Array:  # fmt: skip
    """The clearance (...,) of one arm's capsules (..., L, 2, 3) (world frame): the least
    signed distance to the obstacles (the part beyond the port excluded) and between its
    non-adjacent links, at most ``g.cap`` (the longest reach: finite where nothing is
    checked)."""
    r = jnp.asarray(g.radii, seg.dtype)
    cut = seg if port is None else cut_at_port(seg, port, z, r)
    d = col.clearance(cut, r, obst, ())
    if g.pairs:
        d = jnp.minimum(d, col.clearance(seg, r, None, g.pairs))
    return jnp.minimum(d, g.cap)  # +inf where nothing is checked


def check(s: SerialSettings, mech: Mechanism) -> None:
    """ValueError naming ``collision.obstacles.<i>`` when a link of the middle design
    overlaps that obstacle in every one of 256 random configurations (e.g. a base link
    standing in the table's half-space): every target would be unreached. The port's
    exemption is not applied here, so a link through the port is not counted."""
    g = geometry(s, mech)
    c = s.collision
    if g is None or c is None or not c.obstacles:
        return
    rng = np.random.default_rng(1)
    q = mech.lower + (mech.upper - mech.lower) * rng.uniform(size=(256, mech.n))
    full = _middle(mech, s)[None]
    S = np.asarray(g.outer(mech.model, jnp.asarray(full), jnp.asarray(q)))[0]  # (256, L, 2, 3)
    frames = [(np.eye(3), np.zeros(3))]
    if s.arms is not None:
        p = base_params(s, mech, jnp.float64 if jax.config.jax_enable_x64 else jnp.float32)
        Rb, tb = (np.asarray(v, np.float64) for v in base_frames(p, jnp.asarray(full)))
        frames = [(Rb[k, 0], tb[k, 0]) for k in range(len(s.arms))]
    last = len(g.links) - 1
    radii = jnp.asarray(g.radii)
    for i, ob in enumerate(c.obstacles):
        op = col.obstacle_params([ob], radii.dtype)
        for k, (R, t) in enumerate(frames):
            seg = S @ R.T + t  # (256, L, 2, 3)
            gaps = np.asarray(_link_gaps(jnp.asarray(seg, radii.dtype), radii, op))
            for j in range(len(g.links)):
                if j == last and s.ports()[min(k, len(s.ports()) - 1)] is not None:
                    continue  # the link through the port may touch the body wall
                if np.all(gaps[:, j] < g.margin):
                    arm = f" of arm {k}" if s.arms is not None else ""
                    raise ValueError(
                        f"collision.obstacles.{i}: {g.names[j]}{arm} overlaps this "
                        f"{ob.shape} in every configuration of the middle design (e.g. a "
                        "base standing inside the table's half-space): every target would "
                        "be unreached; move the obstacle or the base"
                    )
