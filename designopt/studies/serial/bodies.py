"""The serial study's bodies: link capsules, ports, obstacles and several arms (docs/task.md).

Under ``study.collision`` every link of the chain is a capsule (``links: auto``) from its
joint's origin to the next joint's origin (the tip for the last), of the configured
radius, so the shapes follow the design variables. Links of zero length in every design
(e.g. between the coincident joints of a spherical wrist) are points inside their
neighbours' capsules and are left out. The self-collision pairs are the non-adjacent
pairs of the remaining links (``links: urdf``: the shapes of links that are not
neighbours on the path), less the pairs whose sampled distances say they cannot inform
the check (:func:`select_pairs`, as a MoveIt set-up disables pairs): "always in
collision" (overlapping in ≥ :data:`ALWAYS` of 512 joint draws at the middle design: two
links that meet at a short offset link), "always near" (within :data:`NEAR` × (r_i + r_j)
of touching in every draw of every sampled design: the capsules of two shapes with one
short link between them, whose distance the joints hardly change and whose overlaps are
the slack of the bounding capsules, not a collision of the shapes) and "never near"
(never within that distance: they cannot collide). They are listed by :func:`describe`
and :func:`pair_lines`.

With a port the instrument passes through the body wall there: the distal part of the
chain, from the last capsule (in path order) that has a part on the outer side of the
port plane (through the port, normal to the tool axis) to the tip, is inside the patient
and is not checked against the obstacles (the patient's body, the table): every capsule
after that one lies wholly beyond the plane, and that one, the capsule through the port,
is cut twice its radius before the plane: it touches the body wall at the port, and that
neighbourhood (the trocar's) is not checked. So a tool leaning more than 60° from a
half-space's normal at the port reads as touching it. Every capsule before it is checked
in full, also where it lies beyond the port plane: an elbow that dips below the plane
away from the port is not in the port, and may touch the patient or the table. Every
capsule counts in the self-collision check.

Several arms (``study.arms``) are copies of the chain at base frames T_k(x) (their
``xyz``/``rpy`` entries numbers or design variables): each arm solves the task in its own
base frame, and its capsules are placed in the world by T_k for the obstacle and the
arm-against-arm checks.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from designopt.kinematics import collision as col
from designopt.studies.serial.mechanism import Mechanism, home
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
NEAR = 0.25
"""A self-collision pair is *near* in a configuration when its capsules' signed distance is
below ``margin + NEAR·(r_i + r_j)`` (a quarter of the two radii: a length in the
capsules' own scale, so in any length unit). A pair near in every sampled configuration
of every sampled design is left out as "always near", one near in none as "never near"
(:func:`select_pairs`)."""
PAIR_CONFIGS = 512
"""Random joint configurations per sampled design for the choice of the pairs."""
PAIR_DESIGNS = 8
"""Random designs in the box sampled beside the middle one (and the box's corners, up to
:data:`PAIR_CORNERS` of them) for the choice of the pairs."""
PAIR_CORNERS = 16
"""The box's 2^P corners are sampled too when there are at most this many (P ≤ 4): a
pair comes closest where the links between its shapes are shortest or longest."""


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
    near: tuple[tuple[int, int], ...] = ()  # left out: near in every sampled configuration
    never: tuple[tuple[int, int], ...] = ()  # left out: near in none
    bands: tuple[tuple[int, int, float, float], ...] = ()  # (i, j, least, largest distance)
    tool_radius: float = 0.0  # the instrument's radius inside the patient (inside obstacles)

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
        try:  # at set-up: the jitted helpers run as compiled programs, in float64 whatever
            # JAX's mode (the CLI validates a config, and so runs the study's checks that
            # ask for it first, before it turns 64-bit mode on: in float32 a link of zero
            # length, e.g. a Panda's between joints 5 and 6, measured ~1e-8 and was kept,
            # and a later process that skipped the checks dropped it)
            with contextlib.nullcontext() if jax.config.jax_enable_x64 else jax.enable_x64(True):
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
                 tuple(f"link {i + 1}" for i in links), tool_radius=_tool_radius(c, radii))  # fmt: skip
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
                 (imp, urdf_bindings(s), caps),
                 tool_radius=_tool_radius(c, tuple(float(k.radius) for k in caps)))  # fmt: skip
    return _drop_always(g, s, mech, pairs, np.random.default_rng(0))


def _tool_radius(c: Any, radii: tuple[float, ...]) -> float:
    """``collision.tool_radius``, else the last capsule's radius (the instrument's)."""
    r = getattr(c, "tool_radius", None)
    return float(radii[-1] if r is None else r)


def _drop_always(g: Geometry, s: SerialSettings, mech: Mechanism, pairs: tuple,
                 rng: np.random.Generator) -> Geometry:  # fmt: skip
    """``g`` with the self-collision ``pairs`` that :func:`select_pairs` keeps."""
    from dataclasses import replace

    if not pairs:
        return g
    return replace(g, **select_pairs(g, s, mech, pairs, rng))


def select_pairs(g: Geometry, s: SerialSettings, mech: Mechanism,
                 pairs: tuple[tuple[int, int], ...],
                 rng: np.random.Generator) -> dict[str, tuple]:  # fmt: skip
    """Which candidate self-collision ``pairs`` (index pairs into ``g``'s capsules) are
    checked: ``{"pairs", "always", "near", "never", "bands"}``.

    The capsules are placed at :data:`PAIR_CONFIGS` random joint configurations (uniform
    in the limits) at the middle design, the box's corners (up to :data:`PAIR_CORNERS`)
    and :data:`PAIR_DESIGNS` random designs of the box; d is a pair's signed distance, m
    the margin, δ = :data:`NEAR`·(r_i + r_j). A pair is left out when it is

    - *always in collision*: d < m in ≥ :data:`ALWAYS` of the configurations at the
      middle design (two links meeting at a short offset link overlap wherever the joints
      are; MoveIt's set-up disables these too);
    - *always near*: d < m + δ in every sampled configuration of every sampled design.
      Its distance is pinned by the shapes, not by the joints or the design (two shapes
      with one short link between them, e.g. a UR5's wrist 1 and wrist 3): it would set
      the clearance's minimum to a few millimetres everywhere, and its overlaps are the
      slack of the bounding capsules rather than a collision of the shapes;
    - *never near*: d ≥ m + δ everywhere: it cannot collide (MoveIt's "never in
      collision", with δ as a buffer for the configurations not drawn).

    ``bands`` holds every candidate's (i, j, least d, largest d) over the sample."""
    q = mech.lower + (mech.upper - mech.lower) * rng.uniform(size=(PAIR_CONFIGS, mech.n))
    lo, hi = (np.asarray(v, np.float64) for v in s.box()[1:])
    V = lo + (hi - lo) * rng.uniform(size=(PAIR_DESIGNS, len(lo)))
    if 0 < 2 ** len(lo) <= PAIR_CORNERS:
        bits = (np.arange(2 ** len(lo))[:, None] >> np.arange(len(lo))) & 1
        V = np.concatenate([np.where(bits == 1, hi, lo), V])
    X = np.concatenate([V, np.broadcast_to(mech.fixed, (len(V), len(mech.fixed)))], 1)
    X = np.concatenate([_middle(mech, s)[None], X * mech.scale])  # the middle design first
    seg = np.asarray(g.outer(mech.model, jnp.asarray(X), jnp.asarray(q)))  # (D, C, L, 2, 3)
    r = np.asarray(g.radii, np.float64)
    d = np.asarray(_pair_gaps(jnp.asarray(seg.reshape(-1, *seg.shape[2:])), jnp.asarray(r),
                              tuple(pairs))).reshape(len(X), len(q), len(pairs))  # fmt: skip
    out: dict[str, list] = {"pairs": [], "always": [], "near": [], "never": [], "bands": []}
    for p, (i, j) in enumerate(pairs):
        near = g.margin + NEAR * (r[i] + r[j])
        dp = d[..., p]
        out["bands"].append((i, j, float(dp.min()), float(dp.max())))
        if np.mean(dp[0] < g.margin) >= ALWAYS:
            out["always"].append((i, j))
        elif dp.max() < near:
            out["near"].append((i, j))
        elif dp.min() >= near:
            out["never"].append((i, j))
        else:
            out["pairs"].append((i, j))
    return {k: tuple(v) for k, v in out.items()}


def _segments(P: Any, links: tuple[int, ...]) -> Any:
    """(..., L, 2, 3) capsule end points of the kept links from joint origins (..., n + 1, 3)."""
    xp = np if isinstance(P, np.ndarray) else jnp
    idx = np.asarray(links)
    return xp.stack([P[..., idx, :], P[..., idx + 1, :]], -2)


def describe(g: Geometry) -> str:
    """One line on the capsules: links, radii, pairs checked and left out."""
    left = "".join(f"; left out as {what}: {list(v)}" for what, v in (
        ("always overlapping", g.always), ("always near", g.near), ("never near", g.never))
        if v)  # fmt: skip
    return (f"capsules on {', '.join(g.names)} (radii {list(g.radii)}), "
            f"{len(g.pairs)} self-collision pair(s){left}")  # fmt: skip


def capsule_labels(g: Geometry) -> list[str]:
    """A name for each capsule: ``link i`` (``links: auto``), or the URDF link's name, with
    ``#k`` when the link has several shapes, and the shape it bounds (a mesh's file)."""
    if g.urdf is None:
        return list(g.names)
    caps = g.urdf[2]
    out = []
    for k, c in enumerate(caps):
        same = [m for m, d in enumerate(caps) if d.link == c.link]
        tag = f"#{same.index(k)}" if len(same) > 1 else ""
        what = c.kind + (f" {c.filename.rsplit('/', 1)[-1]}" if c.filename else "")
        out.append(f"{c.link}{tag} ({what})" if what else f"{c.link}{tag}")
    return out


def pair_lines(s: SerialSettings, mech: Mechanism | None = None,
               design: Mapping[str, float] | None = None,
               q: ArrayLike | None = None, top: int = 3) -> list[str]:  # fmt: skip
    """Lines on the collision check for ``designopt chain``/``view``: the capsules and
    their radii; every candidate self-collision pair, checked or left out and why
    (:func:`select_pairs`), with its least and largest sampled distance; then, at
    ``design`` (variables in the config's units; those not given at the middle of their
    box) and joints ``q`` (active joints, rad for R and length units for P, as the kernel
    takes them; default the home pose), the clearance and the ``top`` least terms that
    set it (self-collision pairs, and each capsule against each obstacle, in each arm's
    base frame; the port's exemption is not applied: it depends on the target).
    No ``study.collision``: one line saying so."""
    from designopt.studies.serial.mechanism import build, home, joint_values
    from designopt.studies.serial.settings import length_unit

    mech = build(s) if mech is None else mech
    g = geometry(s, mech)
    c = s.collision
    if g is None or c is None:
        return ["collision: none (no study.collision section): nothing is checked"]
    u = length_unit(s)
    lab = capsule_labels(g)
    kind = "the URDF's <collision> shapes" if g.urdf is not None else "the chain's links"
    lines = [f"collision: {len(g.radii)} capsules on {kind}, margin {g.margin:g} {u}"]
    lines += [f"  [{k}] {lab[k]}: radius {r:.4g} {u}" for k, r in enumerate(g.radii)]
    band = {(i, j): (lo, hi) for i, j, lo, hi in g.bands}
    if not g.self_check:
        lines.append("self-collision: off (collision.self: false)")
    else:
        groups = (("checked", g.pairs), ("always in collision", g.always),
                  ("always near", g.near), ("never near", g.never))  # fmt: skip
        n = sum(len(v) for _, v in groups)
        lines.append(
            f"self-collision pairs: {len(g.pairs)} checked of {n} candidates (near: closer than "
            f"margin + {NEAR:g}·(r_i + r_j); sampled at {PAIR_CONFIGS} random configurations "
            f"of the middle design, the box's corners (up to {PAIR_CORNERS}) and "
            f"{PAIR_DESIGNS} random designs)"
        )
        for what, P in groups:
            for i, j in P:
                lo, hi = band.get((i, j), (math.nan, math.nan))
                lines.append(f"  {what:<19} {lab[i]} × {lab[j]}: sampled distance "
                             f"[{lo:+.4g}, {hi:+.4g}] {u}")  # fmt: skip
    x = dict(design or {})
    lo, hi = s.box()[1:]
    xv = [float(x[k]) if k in x else (float(a) + float(b)) / 2
          for k, a, b in zip(s.variables, lo, hi, strict=True)]  # fmt: skip
    full = np.concatenate([xv, mech.fixed]) * mech.scale
    qv = home(mech) if q is None else np.asarray(q, np.float64).reshape(mech.n)
    seg = np.asarray(g.outer(mech.model, jnp.asarray(full[None]), jnp.asarray(qv[None])))[0]
    r = jnp.asarray(g.radii, jnp.float64)
    terms: list[tuple[float, str]] = []
    if g.pairs:
        d = np.asarray(_pair_gaps(jnp.asarray(seg), r, tuple(g.pairs)))[0]
        terms += [(float(d[p]), f"{lab[i]} × {lab[j]}") for p, (i, j) in enumerate(g.pairs)]
    frames = [("", np.eye(3), np.zeros(3))]
    if s.arms is not None:
        bp = base_params(s, mech, jnp.float64)
        Rb, tb = base_frames(bp, np.asarray(full[None], np.float64), np)
        frames = [(f" of arm {k}", Rb[k, 0], tb[k, 0]) for k in range(len(s.arms))]
    for o, ob in enumerate(c.obstacles):
        op = col.obstacle_params([ob], jnp.float64)
        for arm, R, tr in frames:
            w = seg @ R.T + tr  # (1, L, 2, 3) in the world
            gaps = np.asarray(_link_gaps(jnp.asarray(w), r, op))[0]
            terms += [(float(gaps[k]), f"{lab[k]}{arm} × collision.obstacles.{o} ({ob.shape})")
                      for k in range(len(lab))]  # fmt: skip
    design_txt = ", ".join(f"{k} = {v:g}" for k, v in zip(s.variables, xv, strict=True))
    at = f"at {design_txt}; {joint_values(s, qv)}"
    if not terms:
        return [*lines, f"{at}: nothing is checked (no kept pair, no obstacle)"]
    terms.sort(key=lambda v: v[0])
    least = terms[0][0]
    state = "collision" if least < g.margin else "free"
    lines.append(f"{at}: clearance {least:+.4g} {u} ({state} by margin {g.margin:g} {u}); "
                 f"least terms:")  # fmt: skip
    lines += [f"  {v:+.4g} {u}  {what}" for v, what in terms[:top]]
    return lines


# ------------------------------------------------------------------- base frames


def rpy_matrix(r: Any, p: Any, y: Any, xp: Any = jnp) -> Any:
    """R = Rz(y)·Ry(p)·Rx(r) (radians), (..., 3, 3) (``xp``: jnp, or np on the host)."""
    cr, sr, cp, sp, cy, sy = (xp.cos(r), xp.sin(r), xp.cos(p), xp.sin(p), xp.cos(y),
                              xp.sin(y))  # fmt: skip
    return xp.stack([
        xp.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
        xp.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
        xp.stack([-sp, cp * sr, cp * cr], -1),
    ], -2)  # fmt: skip


def base_column(s: SerialSettings, mech: Mechanism) -> np.ndarray:
    """The base column's top (3,): where the chain's first joint acts, in the base frame,
    at the middle of the design box (``links: auto``'s capsules start there: the column
    from the base origin to it is the base link, checked at set-up by
    ``plancheck``). The origin itself when the first joint acts at the base."""
    with contextlib.nullcontext() if jax.config.jax_enable_x64 else jax.enable_x64(True):
        P = _origins(mech.model, jnp.asarray(_middle(mech, s)[None]),
                     jnp.asarray(home(mech)[None]))  # fmt: skip
    return np.asarray(P, np.float64)[0, 0, 0]


def _entries(names: tuple[str, ...], rows: list[tuple[Any, ...]], angles: tuple[int, ...] = ()
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """(const, col, sign) (K, W) of K rows of base or port entries: a number's value (an
    angle column of ``angles`` in rad), the design column (variables then fixed) a name
    reads (−1 for a number), −1 for "-name"."""
    W = len(rows[0]) if rows else 0
    const, cols, sign = np.zeros((len(rows), W)), -np.ones((len(rows), W), np.int32), \
        np.ones((len(rows), W))  # fmt: skip
    for k, row in enumerate(rows):
        for i, v in enumerate(row):
            if isinstance(v, str):
                cols[k, i] = names.index(v.removeprefix("-"))
                sign[k, i] = -1.0 if v.startswith("-") else 1.0
            else:
                const[k, i] = math.radians(v) if i in angles else float(v)
    return const, cols, sign


def base_params(s: SerialSettings, mech: Mechanism, dtype: Any) -> dict[str, jax.Array]:
    """The arms' base entries as arrays: ``arm_const`` (A, 6) (xyz in length units, rpy in
    rad) and ``arm_col`` (A, 6) int, the design column (variables then fixed, kernel
    units) an entry reads, −1 for a number, and ``arm_sign`` (A, 6), −1 for "-name".
    Empty without ``arms``. (The ports: :func:`port_params`.)"""
    if s.arms is None:
        return {}
    rows = [(*a.base.xyz, *a.base.rpy) for a in s.arms]
    const, cols, sign = _entries(tuple(mech.names), rows, (3, 4, 5))
    return {"arm_const": jnp.asarray(const, dtype), "arm_col": jnp.asarray(cols),
            "arm_sign": jnp.asarray(sign, dtype)}  # fmt: skip


def port_params(s: SerialSettings, dtype: Any) -> dict[str, Any]:
    """Each arm's port entries (A or 1, 3) as ``scene_port`` {const, col, sign} (as
    :func:`base_params`'), and with ``task.body_wall`` the wall's numbers as
    ``scene_wall`` (``wall.wall_params``). Empty without ports."""
    from designopt.kinematics.wall import wall_params

    ports = s.ports()
    if ports[0] is None:
        return {}
    const, cols, sign = _entries((*s.variables, *s.fixed), list(ports))
    out: dict[str, Any] = {"scene_port": {"const": jnp.asarray(const, dtype),
                                          "col": jnp.asarray(cols),
                                          "sign": jnp.asarray(sign, dtype)}}  # fmt: skip
    wall = s.task.body_wall  # type: ignore[union-attr]
    return out | ({} if wall is None else {"scene_wall": wall_params(wall, dtype)})


def _values(const: Any, col: Any, sign: Any, full: Any, xp: Any = jnp) -> Any:
    """The entries (K, M, W) for designs ``full`` (M, P) (:func:`_entries`' arrays;
    ``xp``: jnp, or np on the host)."""
    col = xp.asarray(col)
    c, sg = xp.asarray(const).astype(full.dtype), xp.asarray(sign).astype(full.dtype)
    return c[:, None, :] + xp.where(col[:, None, :] >= 0,
                                    sg[:, None, :] * xp.moveaxis(full[:, xp.maximum(col, 0)], 0, 1),
                                    0.0)  # fmt: skip


def base_frames(params: dict[str, Any], full: Any, xp: Any = jnp) -> tuple[Any, Any]:
    """(R (A, M, 3, 3), t (A, M, 3)) of every arm's base for designs ``full`` (M, P)
    (``xp``: jnp in a kernel; np on the host, where a set-up check or a figure needs a
    few frames: no program to compile)."""
    v = _values(params["arm_const"], params["arm_col"], params["arm_sign"], full, xp)
    return rpy_matrix(v[..., 3], v[..., 4], v[..., 5], xp), v[..., :3]


def port_points(params: dict[str, Any], full: jax.Array, wall: str | None) -> jax.Array:
    """Every arm's port (A or 1, M, 3) for designs ``full`` (M, P), projected onto the
    body wall of kind ``wall`` (``wall.project``) when there is one (ports are lengths:
    a design column's kernel unit is the config's)."""
    from designopt.kinematics import wall as kw

    sp = params["scene_port"]
    v = _values(sp["const"], sp["col"], sp["sign"], full)
    return v if wall is None else kw.project(wall, params["scene_wall"], v)


# ---------------------------------------------------------------------- clearance


def cut_at_port(seg: jax.Array, port: jax.Array, z: jax.Array, radii: jax.Array) -> jax.Array:
    """The capsule end points (..., L, 2, 3) with the part inside the patient taken out of
    the obstacle check. With s(x) = (x − ``port``)·``z`` (``port`` (..., 3), ``z`` the tool
    axis (..., 3), pointing into the body), let c be the last capsule, in path order, with
    a part on the outer side of the port plane (an end with s < 0). Capsules before c are
    kept whole, wherever they are (an elbow below the plane away from the port may touch
    the patient). c, the capsule through the port, keeps its centre line from its outer
    end to 2·r (its radius, ``radii`` (L,)) before its crossing of the plane (the whole of
    it when it does not reach that far): its capsule touches the body wall at the port,
    and the trocar's neighbourhood is not checked. The capsules after c lie wholly beyond
    the plane (the instrument inside the patient) and collapse onto c's kept piece, so
    they add nothing to a minimum over the capsules. When no capsule has a part on the
    outer side, nothing is taken out. Either end of a capsule may be the outer one (a
    URDF shape's capsule has no direction)."""
    a, b = seg[..., 0, :], seg[..., 1, :]
    sa = jnp.sum((a - port[..., None, :]) * z[..., None, :], -1)  # (..., L)
    sb = jnp.sum((b - port[..., None, :]) * z[..., None, :], -1)
    L = seg.shape[-3]
    idx = jnp.arange(L)
    c = jnp.max(jnp.where(jnp.minimum(sa, sb) < 0, idx, -1), -1)  # -1: none outside
    swap = (sb < sa)[..., None]
    o, i = jnp.where(swap, b, a), jnp.where(swap, a, b)  # outer end, inner end
    so, si = jnp.minimum(sa, sb), jnp.maximum(sa, sb)
    length = jnp.linalg.norm(i - o, axis=-1)
    up = si > so
    t = jnp.where(up, -so / jnp.where(up, si - so, 1.0), jnp.inf)  # the crossing, from o
    t = jnp.clip(t - 2 * radii / jnp.maximum(length, 1e-300), 0.0, 1.0)
    cut_b = o + t[..., None] * (i - o)
    cc = jnp.maximum(c, 0)

    def at_c(v):  # (..., L, 3) -> (..., 3) at capsule c
        return jnp.take_along_axis(v, jnp.broadcast_to(cc[..., None, None], (*cc.shape, 1, 3)),
                                   -2)[..., 0, :]  # fmt: skip

    cut = jnp.stack([at_c(o), at_c(cut_b)], -2)  # (..., 2, 3)
    out = (idx >= c[..., None]) & (c[..., None] >= 0)
    return jnp.where(out[..., None, None], cut[..., None, :, :], seg)


def inside_pieces(seg: jax.Array, port: jax.Array, z: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The part of the chain beyond the port plane (the instrument inside the patient):
    (pieces (..., L, 2, 3), inside (..., L) bool). With c the capsule through the port
    (:func:`cut_at_port`), its piece runs from its crossing of the plane to its inner
    end, and the capsules after c are whole; the others are not inside (``inside``
    False, their piece left as it is). Nothing is inside when no capsule has a part on
    the outer side (no port crossing) or when c does not reach the plane."""
    a, b = seg[..., 0, :], seg[..., 1, :]
    sa = jnp.sum((a - port[..., None, :]) * z[..., None, :], -1)  # (..., L)
    sb = jnp.sum((b - port[..., None, :]) * z[..., None, :], -1)
    idx = jnp.arange(seg.shape[-3])
    c = jnp.max(jnp.where(jnp.minimum(sa, sb) < 0, idx, -1), -1)  # -1: none outside
    swap = (sb < sa)[..., None]
    o, i = jnp.where(swap, b, a), jnp.where(swap, a, b)  # outer end, inner end
    so, si = jnp.minimum(sa, sb), jnp.maximum(sa, sb)
    cross = si > 0  # the inner end is beyond the plane (so < 0 at c)
    t = jnp.clip(-so / jnp.where(si > so, si - so, 1.0), 0.0, 1.0)
    first = jnp.stack([o + t[..., None] * (i - o), i], -2)  # c's piece: crossing to inner end
    at_c = (idx == c[..., None])[..., None, None]
    pieces = jnp.where(at_c, first, seg)
    inside = (c[..., None] >= 0) & ((idx > c[..., None]) | ((idx == c[..., None]) & cross))
    return pieces, inside


def geometry_params(g: Geometry | None, dtype: Any) -> dict[str, Any]:
    """The geometry's numbers as ``params`` (``scene_geometry``: the capsules' ``radii``
    (L,), the ``margin``, the instrument's ``tool_radius`` and the ``cap`` on a
    clearance), so that editing a radius or the margin compiles nothing (while the
    self-collision pairs they select stay the same). Empty without collisions."""
    if g is None:
        return {}
    return {"scene_geometry": {"radii": jnp.asarray(np.asarray(g.radii, np.float64), dtype),
                               "margin": jnp.asarray(g.margin, dtype),
                               "tool_radius": jnp.asarray(g.tool_radius, dtype),
                               "cap": jnp.asarray(g.cap, dtype)}}  # fmt: skip


def obstacle_and_self(g: Geometry, obst: Any, seg: jax.Array, port: jax.Array | None,
                      z: jax.Array | None, inside: Any = None,
                      gp: dict[str, Any] | None = None) -> jax.Array:  # fmt: skip
    """The clearance (...,) of one arm's capsules (..., L, 2, 3) (world frame): the least
    signed distance to the obstacles (the part beyond the port excluded), between its
    non-adjacent links and, with a port, of the part beyond the port plane (its radius
    ``g.tool_radius``, :func:`inside_pieces`) to the obstacles ``inside`` (the anatomy),
    at most ``g.cap`` (the longest reach: finite where nothing is checked). ``gp``: the
    geometry's numbers as arrays (:func:`geometry_params`; None: ``g``'s)."""
    gp = geometry_params(g, seg.dtype)["scene_geometry"] if gp is None else gp
    r = gp["radii"].astype(seg.dtype)
    cut = seg if port is None else cut_at_port(seg, port, z, r)
    d = col.clearance(cut, r, obst, ())
    if g.pairs:
        d = jnp.minimum(d, col.clearance(seg, r, None, g.pairs))
    if inside is not None and port is not None:
        pieces, mask = inside_pieces(seg, port, z)  # type: ignore[arg-type]
        tr = gp["tool_radius"].astype(seg.dtype)
        di = col.clearance(pieces[..., :, None, :, :], tr, inside, ())  # (..., L)
        d = jnp.minimum(d, jnp.min(jnp.where(mask, di, jnp.inf), -1))
    return jnp.minimum(d, gp["cap"].astype(seg.dtype))  # +inf where nothing is checked


def check(s: SerialSettings, mech: Mechanism, ids: tuple[int, ...] | None = None) -> None:
    """ValueError naming ``collision.obstacles.<i>`` when a link of the middle design
    overlaps that obstacle in every one of 256 random configurations (e.g. a base link
    standing in the table's half-space): every target would be unreached. The port's
    exemption is not applied here, so a link through the port is not counted. ``ids``:
    the arms' numbers in the study when ``s`` is a view of some of them
    (``setup.groups``)."""
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
        Rb, tb = base_frames(p, np.asarray(full, np.float64), np)
        frames = [(Rb[k, 0], tb[k, 0]) for k in range(len(s.arms))]
    last = len(g.links) - 1
    radii = jnp.asarray(g.radii)
    for i, ob in enumerate(c.obstacles):
        if getattr(ob, "inside", False):
            continue  # the anatomy: only the instrument beyond the port meets it
        op = col.obstacle_params([ob], radii.dtype)
        for k, (R, t) in enumerate(frames):
            seg = S @ R.T + t  # (256, L, 2, 3)
            gaps = np.asarray(_link_gaps(jnp.asarray(seg, radii.dtype), radii, op))
            for j in range(len(g.links)):
                if j == last and s.ports()[min(k, len(s.ports()) - 1)] is not None:
                    continue  # the link through the port may touch the body wall
                if np.all(gaps[:, j] < g.margin):
                    arm = f" of arm {k if ids is None else ids[k]}" if s.arms is not None else ""
                    raise ValueError(
                        f"collision.obstacles.{i}: {g.names[j]}{arm} overlaps this "
                        f"{ob.shape} in every configuration of the middle design (e.g. a "
                        "base standing inside the table's half-space): every target would "
                        "be unreached; move the obstacle or the base"
                    )
