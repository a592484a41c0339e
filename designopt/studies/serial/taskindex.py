"""The serial study's indices under ``measure: task`` (docs/task.md): every task sample is
a target, solved by the batched IK of every design (``designopt.kinematics.ik``), and
the indices are means (or a quantile) over the targets at the solutions:

- ``reach``: the share of targets solved within tolerance and joint limits;
- ``gci``: the mean 1/k of the configured Jacobian block, an unreached target counting 0;
- ``gci_q05``: the 5 % quantile of the same per-target values (the worst-case dexterity);
- ``manipulability``: the mean sqrt(det J Jᵀ), 0 where unreached;
- ``joint_margin``: the mean over targets of min_i min(q_i − lo_i, hi_i − q_i)/((hi_i − lo_i)/2)
  (1 at mid-range, 0 on a limit), 0 where unreached.

The targets are drawn once per run from the ``samples`` stream (``designopt.kinematics.task``) and
travel in ``params``: every design of the swarm is scored on the same targets (common
random numbers), and one compiled program serves every design and every target set of
that size.

Standard errors: batch means over R independent replications (``study.task.replications``,
default :data:`REPLICATIONS`; issue #65). The targets fall into R interleaved groups
(:func:`groups`: target t in group (t // r) % R, runs of r = 1 target, or of
``ik.NEIGHBOUR_GROUP`` with ``task.ik.neighbours``), and each group's IK draws its own FK
database and seeds (``ik.solve``'s ``groups``): the groups are i.i.d. replications of the
whole estimator, targets and IK draws together. One database shared by every target made
the targets' values correlated, and the i.i.d. SE sd/√N was 4-17× below the spread over
seeds. Every index is computed over all targets (the point estimate); its SE is the
spread of the groups' values: for a mean or a share √(Σ_g (S_g − r̂ n_g)² / (G(G − 1))) / n̄
over the G non-empty groups' sums S_g and counts n_g (:func:`batch_se`: the SD of the
group means / √G for equal groups; a ratio estimator with the denominator's group sums
for n_g), shares never below their Agresti–Coull SE (positive where every target, or
none, counts); ``gci_q05`` the SD of the groups' 5 % quantiles / √G, never below the
order-statistic SE (half the distance between the order statistics N·p ± √(N·p(1−p))).
The arms' target tuples pair distinct targets of one group (:func:`perms`), so a tuple's
value is its group's. With R = 1 the i.i.d. SEs of before.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics import ik
from designopt.kinematics.conditioning import inv_cond
from designopt.studies.serial.mechanism import Mechanism
from designopt.studies.serial.settings import SerialSettings

Q = 0.05  # gci_q05
MEANS = ("reach", "gci", "manipulability", "joint_margin")
"""The indices that are means over the targets (their per-target values add up); under
``collision`` ``clearance`` too (:func:`mean_type`)."""


def mean_type(name: str) -> bool:
    """Whether the index ``name`` is a mean over the targets (:func:`values` gives them)."""
    return name in MEANS or name == "clearance"


REPLICATIONS = 8
"""Independent replications (groups of targets, each with its own IK database and seeds)
whose spread is a task index's SE, unless ``study.task.replications`` says otherwise.
The SE's own relative error is about 1/√(2(R − 1)): 27 % at 8."""


def replications(s: SerialSettings) -> int:
    """R: ``study.task.replications`` (default :data:`REPLICATIONS`; no task: 1)."""
    return 1 if s.task is None else int(s.task.replications)


def groups(s: SerialSettings) -> tuple[int, int]:
    """(R, r): the replication groups of the task's targets, target t in group
    (t // r) % R (``ik.group_of``): runs of r = ``ik.NEIGHBOUR_GROUP`` targets with
    ``task.ik.neighbours`` (a neighbour is of the target's group), else of 1."""
    run = ik.NEIGHBOUR_GROUP if s.task is not None and s.task.ik.neighbours else 1
    return replications(s), run


def labels(N: int, grp: tuple[int, int] | None) -> jax.Array | None:
    """(N,) int32: each target's group (None without groups or with one)."""
    if grp is None or grp[0] <= 1:
        return None
    return ik.group_of(jnp.arange(N, dtype=jnp.int32), *grp)


def _sums(x: jax.Array, lab: jax.Array, G: int) -> jax.Array:
    """(..., G): the sums of x (..., N) over each group's targets."""
    return x @ (lab[:, None] == jnp.arange(G)[None, :]).astype(x.dtype)


def batch_se(y: jax.Array, lab: jax.Array, G: int, x: jax.Array | None = None) -> jax.Array:
    """The batch-means SE (...,) of Σy/Σx along the last axis (x: 1, i.e. the mean of y)
    from the groups ``lab`` (N,) of G: √(Σ_g (Y_g − r X_g)² / (G'(G' − 1))) / (ΣX/G'), Y_g
    and X_g the groups' sums, r = ΣY/ΣX, G' the non-empty groups (the SD of the group
    means / √G' for equal groups); NaN with fewer than 2 groups or ΣX = 0."""
    n = _sums(jnp.ones(lab.shape, y.dtype), lab, G)  # (G,)
    Y = _sums(y, lab, G)
    X = jnp.broadcast_to(n, Y.shape) if x is None else _sums(x, lab, G)
    full = n > 0
    Gp = jnp.sum(full).astype(y.dtype)
    sx = jnp.sum(X, -1)
    ok = (Gp >= 2) & (sx > 0)
    r = jnp.sum(Y, -1) / jnp.where(ok, sx, 1.0)
    res = jnp.where(full, Y - r[..., None] * X, 0.0)
    var = jnp.sum(res * res, -1) / jnp.where(ok, Gp * (Gp - 1), 1.0)
    return jnp.where(ok, jnp.sqrt(var) / jnp.where(ok, sx / Gp, 1.0), jnp.nan)


def mean_se(v: jax.Array, lab: jax.Array | None, G: int = 1) -> jax.Array:
    """The SE of the mean of v (..., N) along N: :func:`batch_se` over the groups, or
    sd/√N without them (or with fewer than 2 non-empty groups)."""
    iid = jnp.std(v, -1, ddof=1) / np.sqrt(v.shape[-1])
    if lab is None:
        return iid
    se = batch_se(v, lab, G)
    return jnp.where(jnp.isnan(se), iid, se)  # fewer than 2 groups: the i.i.d. SE


def estimates_of(s: SerialSettings, mech: Mechanism, per: dict[str, jax.Array],
                 params: dict[str, Any]) -> dict[str, tuple[jax.Array, jax.Array]]:  # fmt: skip
    """:func:`estimates` with the study's replication groups (:func:`groups`), arms, radii
    and margin (``bodies.geometry``)."""
    inst = instruments(s)
    if s.collision is None:
        return estimates(per, grp=groups(s), inst=inst)
    key = jax.random.fold_in(params["sample_key"], 2)  # the arms' target tuples
    sc_p = params if "scene_insertion" in params else scene_params(s, per["success"].dtype, mech)
    gp = sc_p["scene_geometry"]
    return estimates(per, key, gp["radii"], gp["margin"], sc_p.get("scene_band"), groups(s),
                     inst)  # fmt: skip


def instruments(s: SerialSettings) -> tuple[int, ...] | None:
    """The instrument arms' indices where an arm holds the camera (the task's means are
    theirs), else None (every arm)."""
    return None if s.camera_arm() is None else s.instrument_arms()


def scene_params(s: SerialSettings, dtype: Any, mech: Mechanism | None = None) -> dict[str, Any]:
    """The scene's numbers as ``params`` entries, so that one compiled program serves any
    values of them (only their counts shape it): ``scene_obstacles`` (the collision
    obstacles grouped by shape, ``collision.obstacle_params``; empty groups without
    ``collision``), ``scene_insertion`` (A or 1, 2) each arm's insertion range [d0, d1]
    (d1 = ∞ without one) and, with ports, ``scene_port`` and ``scene_wall``
    (``bodies.port_params``: a port's entries may be design variables), ``scene_inside``
    (the obstacles marked ``inside``), ``scene_band`` (``task.instrument_angle``) and
    ``scene_geometry`` (the capsules' radii, the margin: ``bodies.geometry_params``;
    ``mech``: the chain, else built here). (The arms' bases are
    ``bodies.base_params``'s, the targets :func:`targets`'.) Made on the host."""
    from designopt.kinematics.collision import obstacle_params
    from designopt.studies.serial import bodies

    obst = [] if s.collision is None else s.collision.obstacles
    outer = [o for o in obst if not getattr(o, "inside", False)]
    inner = [o for o in obst if getattr(o, "inside", False)]
    out = {"scene_obstacles": obstacle_params(outer, dtype),
           "scene_insertion": jnp.asarray(np.asarray(s.insertions(), np.float64), dtype)}  # fmt: skip
    if s.task is not None:  # the distinct IK solutions sought (best_slots: one program)
        out["ik_n_best"] = jnp.asarray(s.task.ik.n_best, jnp.int32)
    if inner:  # the anatomy: checked against the instrument beyond the port plane
        out["scene_inside"] = obstacle_params(inner, dtype)
    band = None if s.task is None else s.task.instrument_angle
    if band is not None and s.arms is not None:  # [lo, hi] in degrees
        out["scene_band"] = jnp.asarray(np.asarray(band, np.float64), dtype)
    if s.collision is not None:
        from designopt.studies.serial import setup
        from designopt.studies.serial.mechanism import build

        if setup.mixed(s):  # the margin; each arm's radii: setup.group_params
            g0 = setup.groups(s)[0]
            out |= bodies.geometry_params(bodies.geometry(g0.settings, g0.mech), dtype)
        else:
            out |= bodies.geometry_params(bodies.geometry(s, mech or build(s)), dtype)
    from designopt.studies.serial.camera import camera_params

    return out | bodies.port_params(s, dtype) | camera_params(s, dtype)


def group_params(s: SerialSettings, dtype: Any) -> dict[str, Any]:
    """A mixed set-up's extra ``params``: ``setup`` (one dict per group of its
    ``setup.ARM_PARAMS``, the group's view's) and ``scene_geometry``'s radii as (A, L)
    (``setup.radii``). Empty for a set-up of one robot."""
    from designopt.studies.serial import bodies, setup

    if not setup.mixed(s):
        return {}
    per = []
    for g in setup.groups(s):
        v, mech = g.settings, g.mech
        dt = np.dtype(jnp.dtype(dtype))
        p = {"q_lower": jnp.asarray(np.asarray(mech.lower, dt)),
             "q_upper": jnp.asarray(np.asarray(mech.upper, dt))}  # fmt: skip
        p |= bodies.base_params(v, mech, dtype) | scene_params(v, dtype, mech)
        per.append({k: p[k] for k in setup.ARM_PARAMS if k in p})
    out: dict[str, Any] = {"setup": tuple(per)}
    if s.collision is not None:
        gp = dict(per[0]["scene_geometry"])
        gp["radii"] = setup.radii(s, dtype)
        out["scene_geometry"] = gp
    return out


def counts_of(s: SerialSettings, mech: Mechanism, per: dict[str, jax.Array],
              params: dict[str, Any]) -> dict[str, tuple[jax.Array, int]]:  # fmt: skip
    """:func:`counts` with the arms' target tuples of :func:`estimates_of`."""
    if s.collision is None:
        return counts(per, inst=instruments(s))
    return counts(per, jax.random.fold_in(params["sample_key"], 2), groups(s), instruments(s))


BEST_SLOTS = 8
"""Solution slots of the IK program for any ``study.task.ik.n_best`` from 2 to this
(:func:`best_slots`): the count itself is an input (``params["ik_n_best"]``,
``ik.solve``'s ``n_keep``), so settings that differ only in it (a search that ranks by
the best of 2 under ``optimizer.fidelity``, a re-scoring by the best of 8) run one
compiled program."""


def best_slots(n_best: int) -> int:
    """The IK program's solution slots for ``n_best``: 1 for 1 (the first solution: no
    comparison in the program), else at least :data:`BEST_SLOTS`."""
    return 1 if n_best == 1 else max(int(n_best), BEST_SLOTS)


def options(s: SerialSettings) -> ik.IKOptions:
    """The IK settings of ``study.task.ik`` as solver options (every field: the schema's
    defaults are the solver's, but for ``n_best`` = 2 where the solver's is 1), with
    ``n_best`` the program's slots (:func:`best_slots`; the count sought is an input)."""
    o = s.task.ik  # type: ignore[union-attr]
    return ik.IKOptions(**{k: getattr(o, k) for k in ik.IKOptions._fields}
                        | {"n_best": best_slots(o.n_best)})  # fmt: skip


def mode(s: SerialSettings) -> ik.Mode:
    """``axis`` with a tool-axis cone or a port (the roll about the tool axis is free),
    else ``position``."""
    axis = s.task.tool_axis is not None or s.ports()[0] is not None  # type: ignore[union-attr]
    return "axis" if axis else "position"


def n_targets(s: SerialSettings) -> int:
    """N: the points of a points file, else ``indices.n_samples``."""
    from designopt.kinematics.task import Points

    reg = s.task.region  # type: ignore[union-attr]
    return len(reg.xyz()) if isinstance(reg, Points) else s.indices.n_samples


CHUNK = 1024
"""Targets per chunk unless ``indices.chunk`` says otherwise (at most the task's count):
one call of the block program (``designopt.studies.serial.blocks``) solves
:data:`blocks.DESIGNS` designs × a chunk. Each call builds its designs' FK databases
(which one program hoists out of its chunk loop): 16 designs × 1,024 targets took 0.32 s
in one call and 0.52 s in four of 256 (urdf_puma560_task). A front's re-scoring keeps
its run's chunk, so a run of 256 targets and its re-scoring on 1,024 share a program."""


def chunk(s: SerialSettings) -> int:
    """Targets per chunk: ``indices.chunk`` when given, else :data:`CHUNK` (at most the
    task's count; with ``task.ik.neighbours`` rounded up to a multiple of
    ``ik.NEIGHBOUR_GROUP``). The chunks' seeds are those of one piece (``ik.solve``'s ``t0``), so
    the chunk changes no value, only the programs' shapes and memory."""
    ind = s.indices
    c = min(ind.chunk if "chunk" in ind.model_fields_set else CHUNK, n_targets(s))
    if s.task.ik.neighbours:  # type: ignore[union-attr]  # whole runs of neighbours: a
        # chunk of the whole task rounded up (its padding is no one's neighbour), so that
        # a re-scoring on more targets, which keeps the chunk, cuts no run either
        c = -(-c // ik.NEIGHBOUR_GROUP) * ik.NEIGHBOUR_GROUP
    return c


def targets(s: SerialSettings, key: jax.Array, dtype: Any) -> dict[str, jax.Array]:
    """The task's targets as ``params`` entries: ``target_p`` (N, 3) and, with a tool
    axis, ``target_R`` (N, 3, 3) (its last column is the sampled tool axis). (With a
    port, each design's tool frames come from its own port, in :func:`per_target`.)"""
    from designopt.kinematics import task as tk

    task = s.task.model_copy(update={"port": None})  # type: ignore[union-attr]  # (per_target's)
    p, R = tk.targets(task, key, n_targets(s), dtype)
    return {"target_p": p} | ({} if R is None else {"target_R": R})


def design_full(params: Mapping[str, Any], X: jax.Array, dtype: Any) -> jax.Array:
    """(M, P) kernel parameters: the variables X (M, V) then the fixed values, deg → rad."""
    X = X.astype(dtype)
    fixed = jnp.broadcast_to(params["fixed"].astype(dtype), (X.shape[0], params["fixed"].shape[0]))
    return jnp.concatenate([X, fixed], axis=1) * params["scale"].astype(dtype)


def per_target(mech: Mechanism, s: SerialSettings, params: dict[str, Any], full: jax.Array,
               dtype: Any, opts: ik.IKOptions | None = None) -> dict[str, jax.Array]:  # fmt: skip
    """Per arm, design and target (A, M, N) (A = 1 without ``arms``): success, converged,
    1/k, manipulability, joint margin (all 0 where unreached), clearance (under
    ``collision``: the kept solution's, 0 where unreached) and the joints q
    (A, M, N, n), for designs ``full`` (M, P) in kernel units; with ``arms`` also the
    kept solutions' capsules in the world (``segments`` (A, M, N, L, 2, 3)) and the tool
    axes (``axis``). The targets go through :func:`chunk_values` in chunks of
    :func:`chunk` (``lax.map``); the last chunk is padded with copies of the last target
    and cut off again (:func:`chunked_targets`, :func:`assemble`). ``opts``: the solver's
    options (default :func:`options`). Under ``collision`` the IK keeps trying seeds
    until a converged solution is collision-free (``bodies``). (The staged scoring,
    ``designopt.studies.serial.blocks``, calls :func:`chunk_values` chunk by chunk as a
    program of its own: the same values.)"""
    N, M = params["target_p"].shape[0], full.shape[0]
    pc, Rc, t0 = chunked_targets(params, chunk(s), dtype)
    out = jax.lax.map(lambda a: setup_values(mech, s, params, full, a[0], a[1], a[2], dtype, opts),
                      (pc, Rc, t0))  # each (n_chunks, A·M, C, ...)  # fmt: skip
    return assemble(out, len(s.arms) if s.arms is not None else 1, M, N)


def chunked_targets(params: dict[str, Any], C: int, dtype: Any, xp: Any = jnp
                    ) -> tuple[Any, Any, Any]:  # fmt: skip
    """The targets in chunks of C: (positions (n_chunks, C, 3), tool frames
    (n_chunks, C, 3, 3) or None, each chunk's first target index (n_chunks,) int32), the
    last chunk padded with copies of the last target (``xp``: jnp, or np on the host)."""
    dt = np.dtype(dtype)
    p = xp.asarray(params["target_p"]).astype(dt)
    R = xp.asarray(params["target_R"]).astype(dt) if "target_R" in params else None
    N = p.shape[0]
    n_chunks = -(-N // C)
    pad = n_chunks * C - N

    def padded(a):
        return xp.concatenate([a, xp.repeat(a[-1:], pad, 0)]) if pad else a

    pc = padded(p).reshape(n_chunks, C, 3)
    Rc = None if R is None else padded(R).reshape(n_chunks, C, 3, 3)
    return pc, Rc, xp.arange(n_chunks, dtype=xp.int32) * C


def assemble(out: dict[str, Any], A: int, M: int, N: int, xp: Any = jnp) -> dict[str, Any]:
    """:func:`chunk_values`' outputs stacked over the chunks (n_chunks, A·M, C, ...) as
    (A, M, N, ...) (the padded targets cut off; ``xp``: jnp, or np on the host)."""
    return {k: xp.moveaxis(v, 0, 1).reshape(A, M, v.shape[0] * v.shape[2], *v.shape[3:])[:, :, :N]
            for k, v in out.items()}  # fmt: skip


def chunk_values(mech: Mechanism, s: SerialSettings, params: dict[str, Any], full: jax.Array,
                 pt: jax.Array, Rt: jax.Array | None, t0: jax.Array, dtype: Any,
                 opts: ik.IKOptions | None = None, profile: bool = False
                 ) -> dict[str, jax.Array]:  # fmt: skip
    """:func:`per_target`'s values of designs ``full`` (M, P) at one chunk of C targets
    (``pt`` (C, 3), ``Rt`` (C, 3, 3) or None; ``t0``: the index of its first target in
    the task, which the IK's seeds hash): each (A·M, C, ...), arm-major. Reads the scene
    (:func:`scene_params`), the joint limits, the arms' bases and the IK's key from
    ``params``, never the targets. ``pt`` (M, C, 3): each design's own C targets (the
    camera arm's: :func:`setup_values`; ``Rt`` then None). ``profile``: also the IK's
    seeds tried per target (``ik_tries``) and converged seeds refused for a collision
    (``ik_refused``) (benchmarks/planning_profile.py)."""
    from designopt.kinematics.task import port_frames
    from designopt.studies.serial import bodies

    ind, md = s.indices, mode(s)
    opts = options(s) if opts is None else opts
    rows = ind.rows()
    lo, hi = params["q_lower"].astype(dtype), params["q_upper"].astype(dtype)
    M, C = full.shape[0], pt.shape[-2]
    own = pt.ndim == 3  # each design its own targets (M, C, 3)
    ptb = pt[None] if own else pt[None, None]  # (1, M|1, C, 3)

    def at(m, t):  # the target of rows m (designs of the tiled X) and chunk entries t
        return pt[m % M, t] if own else pt[t]

    geo = bodies.geometry(s, mech)
    arms = s.arms is not None
    A = len(s.arms) if arms else 1
    # the scene's numbers are inputs (:func:`scene_params`): editing them compiles nothing
    sc_p = params if "scene_insertion" in params else scene_params(s, dtype, mech)
    gp = sc_p.get("scene_geometry")
    obst = None if geo is None else jax.tree_util.tree_map(lambda a: a.astype(dtype),
                                                             sc_p["scene_obstacles"])  # fmt: skip
    inner = None if geo is None or "scene_inside" not in sc_p else \
        jax.tree_util.tree_map(lambda a: a.astype(dtype), sc_p["scene_inside"])  # fmt: skip
    has_port = s.ports()[0] is not None
    ins = sc_p["scene_insertion"].astype(dtype)  # (A or 1, 2): each arm's [d0, d1]
    d0, d1 = ins[:, :1, None], ins[:, 1:, None]  # (A or 1, 1, 1)
    wall = None if s.task.body_wall is None else s.task.body_wall.shape  # type: ignore[union-attr]
    # each arm's port for each design (A or 1, M, 3): its entries may be design variables
    port = bodies.port_points(sc_p, full.astype(dtype), wall) if has_port else None
    moved = s.designed_ports()  # the design moves a port (static: it shapes the IK's batch)
    if arms:
        Rb, tb = bodies.base_frames(params, full)  # (A, M, 3, 3), (A, M, 3)
        X = jnp.tile(full, (A, 1))  # (A·M, P), arm-major
    else:
        X = full
    key = jax.random.fold_in(params["sample_key"], 1)  # the IK's seeds: not the targets'
    sc = jnp.asarray([1.0 if r < 3 else ind.length_scale for r in rows], dtype)
    half = (hi - lo) / 2

    scope = None  # the endoscope's shaft (camera.shaft): a capsule per design (not the
    # camera arm's: it holds the scope)
    if geo is not None and "scene_camera" in sc_p and "shaft" in sc_p["scene_camera"] \
            and s.camera_arm() is None:  # fmt: skip
        from designopt.kinematics.collision import capsule_capsule
        from designopt.studies.serial import camera

        scope = camera.shaft(sc_p, full.astype(dtype), wall)

    def clearance(m, pt, q):  # the clearance of items: rows m of X (B,), targets pt (B, 3)
        seg = geo.items(mech.model, X[m], q)  # type: ignore[union-attr]  # (B, L, 2, 3)
        a = m // M
        if arms:  # arm a's capsules in the world frame
            seg = jnp.einsum("bij,blej->blei", Rb[a, m % M], seg) + tb[a, m % M][:, None, None]
        if port is None:
            c = bodies.obstacle_and_self(geo, obst, seg, None, None, None, gp)  # type: ignore[arg-type]
        else:
            pa = port[a, m % M]  # (B, 3)
            z = pt - pa
            z = z / jnp.maximum(jnp.linalg.norm(z, axis=-1, keepdims=True), 1e-300)
            c = bodies.obstacle_and_self(geo, obst, seg, pa, z, inner, gp)  # type: ignore[arg-type]
        if scope is not None:  # every capsule, the instrument inside the patient too
            s0, s1, rs = scope
            d = capsule_capsule(seg[..., 0, :], seg[..., 1, :], gp["radii"].astype(dtype),
                                s0[m % M][:, None], s1[m % M][:, None], rs)  # type: ignore[index]  # fmt: skip
            c = jnp.minimum(c, jnp.min(d, -1))
        return c, seg

    # with a port, the tool axes point from the port to the targets: (A|1, M|1, C, 3, 3)
    # (a port no design variable moves is every design's: one set of frames)
    Rw = None if port is None else \
        port_frames(ptb, (port if moved or own else port[:, :1])[:, :, None, :])  # fmt: skip
    if arms:  # each arm's targets in its own base frame, (A·M, C, ...)
        pl = jnp.einsum("amji,amcj->amci", Rb, ptb - tb[:, :, None, :])
        p_ik = pl.reshape(A * M, C, 3)
        R_ik = None if Rw is None else jnp.einsum(
            "amji,amcjk->amcik", Rb, jnp.broadcast_to(Rw, (A, M, C, 3, 3))
        ).reshape(A * M, C, 3, 3)  # fmt: skip
    elif Rw is None:
        p_ik, R_ik = pt, Rt
    elif moved:  # each design's own targets' frames: (M, C, ...)
        p_ik, R_ik = jnp.broadcast_to(pt, (M, C, 3)), Rw[0]
    else:
        p_ik, R_ik = pt, Rw[0, 0]

    def jac(q):  # the study's Jacobian block (A·M, C, rows, n) at joints q (A·M, C, n)
        return jax.vmap(lambda x, q: mech.model.jacobian(x, q, rows=rows))(X, q)

    def score(m, t, q):  # what "best" means at a target (items: rows m of X, joints q)
        J = jax.vmap(lambda x, q: mech.model.jacobian(x, q, rows=rows))(X[m], q)
        return inv_cond(J * sc[:, None], ind.norm, ind.normalized)

    accept = None
    if geo is not None:

        def accept(m, t, q):
            return clearance(m, at(m, t), q)[0] >= gp["margin"].astype(dtype)  # type: ignore[index]

        if s.task.ik.best == "clearance":  # type: ignore[union-attr]

            def score(m, t, q):  # as far from the anatomy (and the rest) as the arm can be
                return clearance(m, at(m, t), q)[0]

    # a design equal to an earlier one of the block (a padded block's copies, particles
    # that met) is solved once: its representative's solutions are copied (ik.solve)
    rep = ik.representatives(full)
    if arms:
        rep = (jnp.arange(A, dtype=jnp.int32)[:, None] * M + rep[None]).reshape(-1)
    hopeless = None
    if port is not None:  # a target out of an arm's insertion range is a failure whatever
        # the joints (below): one seed for it, not all of them
        depth = jnp.linalg.norm(ptb - port[:, :, None, :], axis=-1)  # (A|1, M, C)
        inside = (depth >= d0) & (depth <= d1) & (depth > 0)
        hopeless = jnp.broadcast_to(~inside, (A, M, C)).reshape(A * M, C)
        if inner is not None:  # so is a target whose instrument meets the anatomy
            blocked = _shaft_blocked(mech, geo, full, lo, hi, port, ptb, depth, inner, gp, rep,
                                     ~hopeless, A, M, C)  # fmt: skip
            hopeless = hopeless | blocked
    R_, run = groups(s)  # each replication group its own database (issue #65)
    res = ik.solve(mech.model, X, p_ik, R_ik, lo, hi, key, md, opts, score, accept, t0, rep,
                   hopeless, sc_p["ik_n_best"] if "ik_n_best" in sc_p else s.task.ik.n_best,  # type: ignore[union-attr]
                   R_, run)  # fmt: skip
    J = jac(res.q)
    inv_k, man = inv_cond(J * sc[:, None], ind.norm, ind.normalized, with_volume=True)
    ok, conv = res.success, res.converged
    if hopeless is not None:  # the insertion depth |target − port|: each arm's own range
        ok, conv = ok & ~hopeless, conv & ~hopeless
    margin = jnp.min(jnp.minimum(res.q - lo, hi - res.q) / half, -1)
    z = jnp.zeros_like(inv_k)
    out = {"success": ok.astype(dtype), "converged": conv.astype(dtype),
           "inv_k": jnp.where(ok, inv_k, z), "manipulability": jnp.where(ok, man, z),
           "joint_margin": jnp.where(ok, jnp.clip(margin, 0.0, 1.0), z),
           "q": res.q, "pos_err": res.pos_err, "rot_err": res.rot_err}  # fmt: skip
    if profile:
        out |= {"ik_tries": res.tries, "ik_refused": res.refused}
    if geo is not None:
        m_all = jnp.repeat(jnp.arange(X.shape[0]), C)
        t_all = jnp.tile(jnp.arange(C), X.shape[0])
        qf = res.q.reshape(-1, res.q.shape[-1])
        _, seg = clearance(m_all, at(m_all, t_all), qf)  # the capsules of all (cheap FK)
        # the clearance (the costly part) of the kept solutions that count: reached, of a
        # representative design (the rest copy theirs)
        need = (ok.reshape(rep.shape[0], C) & (rep == jnp.arange(rep.shape[0]))[:, None])
        c = ik.on_rows(lambda r: clearance(m_all[r], at(m_all[r], t_all[r]), qf[r])[0],
                       need.reshape(-1), ik.CHECK_ROWS).reshape(-1, C)[rep]  # fmt: skip
        out["clearance"] = jnp.where(ok, c.reshape(ok.shape), z)
        if arms:
            out["segments"] = seg.reshape(*ok.shape, *seg.shape[1:])
    if arms:  # each arm's tool axis in the world (the tip frame's z): instrument_angle
        Rt_ = jax.vmap(lambda x, q: mech.model.fk(x, q)[0])(X, res.q)  # (A·M, C, 3, 3)
        zt = jnp.einsum("amij,amcj->amci", Rb, Rt_[..., 2].reshape(A, M, C, 3))
        out["axis"] = zt.reshape(A * M, C, 3)
    return out


def setup_values(mech: Any, s: SerialSettings, params: dict[str, Any], full: jax.Array,
                 pt: jax.Array, Rt: jax.Array | None, t0: jax.Array, dtype: Any,
                 opts: Any = None, profile: bool = False) -> dict[str, jax.Array]:  # fmt: skip
    """:func:`chunk_values` of the whole set-up (``setup``): the study's own for one robot
    (``mech`` its chain), else each group's on its view, its chain and its
    ``params["setup"]`` entries, put together in arm order by ``setup.merged``."""
    from designopt.studies.serial import setup

    if not setup.mixed(s):
        return chunk_values(mech, s, params, full, pt, Rt, t0, dtype, opts, profile)
    outs = []
    for g, gp in zip(setup.groups(s), params["setup"], strict=True):
        if g.settings.camera_arm() is not None:
            outs.append(camera_values(g, s, params | gp, full, pt.shape[0], t0, dtype, opts,
                                      profile))  # fmt: skip
            continue
        outs.append(chunk_values(g.mech, g.settings, params | gp, full, pt, Rt, t0, dtype, opts,
                                 profile))  # fmt: skip
    return setup.merged(s, outs, full.shape[0])


def camera_values(g: Any, s: SerialSettings, params: dict[str, Any], full: jax.Array, C: int,
                  t0: jax.Array, dtype: Any, opts: Any = None, profile: bool = False
                  ) -> dict[str, jax.Array]:  # fmt: skip
    """The camera arm's values (``arms.<k>.role: camera``, group ``g``) at a chunk of C of
    the task's targets, (M, C, ...) as :func:`chunk_values`' of an arm: its one target is
    the scope's pose (``camera.pose``: the tip, the axis from the camera port), solved once
    per replication group (R targets per design, target j of group j, with the IK's key
    folded apart from the instrument arms'), and each task target takes its own group's
    solution, so that the replications' spread covers the camera arm's IK draw too and
    ``arms_ok``'s tuples (of one group) meet one camera pose."""
    from designopt.studies.serial import camera

    R, run = groups(s)
    wall = None if s.task.body_wall is None else s.task.body_wall.shape  # type: ignore[union-attr]
    tip = camera.pose(params, full.astype(dtype), wall)[1]  # (M, 3)
    pc = jnp.broadcast_to(tip[:, None], (tip.shape[0], R, 3))
    o = None if opts is None else opts._replace(neighbours=0)
    p = params | {"sample_key": jax.random.fold_in(params["sample_key"], 7)}
    out = chunk_values(g.mech, g.settings, p, full, pc, None, jnp.zeros((), jnp.int32), dtype, o,
                       profile)  # (M, R, ...)  # fmt: skip
    lab = jnp.zeros((C,), jnp.int32) if R <= 1 else ik.group_of(t0 + jnp.arange(C, dtype=jnp.int32),
                                                               R, run)  # fmt: skip
    return {k: v[:, lab] for k, v in out.items()}


SHAFT_SLACK = 1e-6
"""How far (the chain's length unit) beyond the margin a target's instrument line must
meet the anatomy for :func:`_shaft_blocked` to call the target hopeless: many times the
IK's tolerance, so that no converged solution's shaft can clear what its line does not."""


def _shaft_blocked(mech: Mechanism, geo: Any, full: jax.Array, lo: jax.Array, hi: jax.Array,
                   port: jax.Array, pt: jax.Array, depth: jax.Array, inner: Any,  # pt (1, M|1, C, 3)
                   gp: dict[str, Any], rep: jax.Array, asked: jax.Array, A: int, M: int,
                   C: int) -> jax.Array:  # fmt: skip
    """(A·M, C) bool: targets whose every solution the collision check refuses, because the
    instrument beyond the port meets the anatomy. Through a port, a converged solution's
    tool axis runs from the port to the target, so where the chain's last capsule (the
    instrument, rigid with the tip's link) lies on the tip's z axis, ends at the tip and
    is longer than the insertion depth, the part of it beyond the port plane is the
    segment from the port to the target whatever the joints (``bodies.inside_pieces``):
    when that segment's clearance to the anatomy (the instrument's radius) is below the
    margin by :data:`SHAFT_SLACK`, no solution is accepted. Asked only where ``asked``
    (an arm's target in its range) of the representative designs (``rep``)."""
    from designopt.kinematics import collision as col

    dt = full.dtype
    tol = jnp.asarray(1e-9, dt) * (1 + jnp.max(jnp.abs(full)))

    def shaft(f):  # the instrument's shape at joints lo + f·(hi − lo): (on the axis, length)
        q = jnp.broadcast_to(lo + f * (hi - lo), (M, lo.shape[0]))
        seg = geo.items(mech.model, full, q)[:, -1]  # (M, 2, 3)
        R, p = jax.vmap(mech.model.fk)(full, q)
        z = R[..., 2]
        da, db = (jnp.linalg.norm(seg[:, k] - p, axis=-1) for k in (0, 1))
        far = jnp.where((da > db)[:, None], seg[:, 0], seg[:, 1])
        near = jnp.minimum(da, db)
        v = far - p
        off = jnp.linalg.norm(jnp.cross(z, v), axis=-1)
        on = (near <= tol) & (off <= tol) & (jnp.sum(v * z, -1) < 0)
        return on, jnp.linalg.norm(v, axis=-1)

    on0, l0 = shaft(0.25)
    on1, l1 = shaft(0.6)
    on = on0 & on1 & (jnp.abs(l0 - l1) <= tol)  # (M,)
    need = (asked.reshape(A, M, C) & on[None, :, None]
            & (depth < l0[None, :, None] - SHAFT_SLACK)
            & (rep.reshape(A, M) == jnp.arange(A * M).reshape(A, M))[..., None])  # fmt: skip
    ends = jnp.stack(jnp.broadcast_arrays(port[:, :, None, :], pt), -2)
    ends = jnp.broadcast_to(ends, (A, M, C, 2, 3)).reshape(-1, 1, 2, 3)
    tr = gp["tool_radius"].astype(dt)
    d = ik.on_rows(lambda r: col.clearance(ends[r], tr, inner, ()), need.reshape(-1),
                   ik.CHECK_ROWS)  # fmt: skip
    blocked = need.reshape(-1) & (d < gp["margin"].astype(dt) - SHAFT_SLACK)
    return blocked.reshape(A * M, C)[rep]


def quantile(v: jax.Array, q: float = Q, lab: jax.Array | None = None, G: int = 1
             ) -> tuple[jax.Array, jax.Array]:  # fmt: skip
    """(the q-quantile of v (M, N) along N (linear interpolation), its SE): the
    order-statistic SE, half the spread of the order statistics at ranks
    N·q ± √(N·q(1−q)) (the distribution-free ±1-SE band of an i.i.d. sample's quantile).
    With groups ``lab`` (N,) of G it is scaled by what the groups add to the share of
    values at or below the quantile (Bahadur's representation: the quantile's error is
    that share's error over the density there): the batch-means SE of that share
    (:func:`batch_se`) over its i.i.d. SE √(q(1−q)/N), never below 1. (The spread of the
    groups' own quantiles, tried first, claimed 0.036 for a quantile that was 0 at
    every seed: a group of 16 targets may hold no unreached one.)"""
    N = v.shape[-1]
    srt = jnp.sort(v, -1)
    val = jnp.quantile(v, q, axis=-1)
    d = float(np.sqrt(N * q * (1 - q)))
    lo_r = int(np.clip(np.floor(N * q - d), 0, N - 1))
    hi_r = int(np.clip(np.ceil(N * q + d), 0, N - 1))
    se = (srt[..., hi_r] - srt[..., lo_r]) / 2
    if lab is None:
        return val, se
    below = (v <= val[..., None]).astype(v.dtype)
    deff = batch_se(below, lab, G) / np.sqrt(q * (1 - q) / N)
    return val, se * jnp.maximum(jnp.nan_to_num(deff, nan=1.0), 1.0)


def values(per: dict[str, jax.Array], name: str, inst: tuple[int, ...] | None = None
           ) -> jax.Array:  # fmt: skip
    """The per-target values (M, N) whose mean is the index ``name`` (a MEANS entry or
    ``clearance``): with several arms, the mean over the arms at each target (the
    instrument arms ``inst`` where one holds the camera, :func:`instruments`)."""
    v = per["success"] if name == "reach" else per["inv_k" if name == "gci" else name]
    return jnp.mean(v if inst is None else v[jnp.asarray(inst)], 0)


def share(x: jax.Array, lab: jax.Array | None = None, G: int = 1
          ) -> tuple[jax.Array, jax.Array]:  # fmt: skip
    """(mean, SE) of 0/1 values (M, N) along N: the Agresti–Coull SE (sd/√N is 0 when
    every target (or none) counts, which claims too much; √(p̃(1 − p̃)/(N + 4)) with
    p̃ = (x + 2)/(N + 4) stays positive there and equals the usual SE to O(1/N)); with
    groups ``lab`` of G never below the batch-means SE (:func:`batch_se`)."""
    N = x.shape[-1]
    pt = (jnp.sum(x, -1) + 2.0) / (N + 4.0)
    se = jnp.sqrt(pt * (1.0 - pt) / (N + 4.0))
    if lab is not None:
        se = jnp.maximum(se, jnp.nan_to_num(batch_se(x, lab, G), nan=0.0))
    return jnp.mean(x, -1), se


N_MIN = 30
"""A ratio estimator whose denominator counts fewer items (tuples every arm reaches,
converged targets) is not reported: its value and SE are NaN (printed ``n/a``), and a
search ranks it worst (``NA_WORST``)."""
RATIOS = ("collision_free", "arms_free", "instrument_angle")
"""The ratio estimators among the indices: each archived with ``<name>_n``, its
denominator's count, and ``<name>_of``, the count it is out of."""
NA_WORST = {k: (0.0, 180.0 if k == "instrument_angle" else 1.0) for k in RATIOS}
"""The range of each index that can be n/a: a search puts an n/a value at the end of it
that its sense ranks worst (0 when maximised, 1 when minimised)."""


def ratio(y: jax.Array, x: jax.Array, n_min: int = N_MIN, lab: jax.Array | None = None,
          G: int = 1) -> tuple[jax.Array, jax.Array]:  # fmt: skip
    """The ratio estimator Σy/Σx of 0/1 values y ≤ x along the last axis (the share of
    the counted items that pass) with its delta-method SE √(Σ(y − r x)² / (N (N − 1))) / x̄,
    never below the Agresti–Coull SE of Σy of Σx (:func:`share`: a share of 0 or 1 is
    not exact); NaN and NaN where Σx < ``n_min`` (a ratio over a handful of items claims
    what the sample cannot show). With groups ``lab`` (N,) of G: the batch-means SE of
    the ratio (:func:`batch_se`) in place of the delta method's."""
    N = y.shape[-1]
    sx, sy = jnp.sum(x, -1), jnp.sum(y, -1)
    ok = sx >= max(n_min, 1)
    r = jnp.where(ok, sy / jnp.where(ok, sx, 1.0), 0.0)
    res = y - r[..., None] * x
    se = jnp.sqrt(jnp.sum(res * res, -1) / (N * (N - 1))) / jnp.where(ok, sx / N, 1.0)
    if lab is not None:
        se = jnp.nan_to_num(batch_se(y, lab, G, x), nan=0.0)
    pt = (sy + 2.0) / (sx + 4.0)
    se = jnp.maximum(se, jnp.sqrt(pt * (1.0 - pt) / (sx + 4.0)))
    return jnp.where(ok, r, jnp.nan), jnp.where(ok, se, jnp.nan)


def counts(per: dict[str, jax.Array], key: jax.Array | None = None,
           grp: tuple[int, int] | None = None, inst: tuple[int, ...] | None = None
           ) -> dict[str, tuple[jax.Array, int]]:  # fmt: skip
    """(denominator count (M,), out of) of each ratio estimator :func:`estimates` gives:
    ``collision_free``: the instrument arms' (``inst``, else every arm's) converged
    targets of A·N; ``arms_free``: tuples every arm reaches of N."""
    A, M, N = per["success"].shape
    out = {}
    ii = tuple(range(A)) if inst is None else tuple(inst)
    if "clearance" in per:
        out["collision_free"] = (jnp.sum(per["converged"][jnp.asarray(ii)], (0, 2)), len(ii) * N)
    if A > 1 and key is not None and "segments" in per:
        out["arms_free"] = (jnp.sum(_tuples(per, key, labels(N, grp))[0], -1), N)
        if "axis" in per and len(ii) >= 2:
            out["instrument_angle"] = out["arms_free"]
    return out


def ratio_mean(y: jax.Array, x: jax.Array, n_min: int = N_MIN, lab: jax.Array | None = None,
               G: int = 1) -> tuple[jax.Array, jax.Array]:  # fmt: skip
    """The mean of ``y`` over the items where the 0/1 ``x`` is 1, along the last axis
    (the ratio estimator Σ x y / Σ x), with its delta-method SE
    √(Σ x² (y − r)² / (N (N − 1))) / x̄ (with groups ``lab`` of G: the batch-means one,
    :func:`batch_se`); NaN and NaN where Σx < ``n_min``."""
    N = y.shape[-1]
    sx = jnp.sum(x, -1)
    ok = sx >= max(n_min, 1)
    r = jnp.where(ok, jnp.sum(x * y, -1) / jnp.where(ok, sx, 1.0), 0.0)
    res = x * (y - r[..., None])
    se = jnp.sqrt(jnp.sum(res * res, -1) / (N * (N - 1))) / jnp.where(ok, sx / N, 1.0)
    if lab is not None:
        se = jnp.nan_to_num(batch_se(x * y, lab, G, x), nan=0.0)
    return jnp.where(ok, r, jnp.nan), jnp.where(ok, se, jnp.nan)


def perms(key: jax.Array, N: int, lab: jax.Array | None, A: int) -> list[jax.Array]:
    """The arms' target permutations [π_0, …, π_{A−1}] of the tuples (π_0 the identity):
    without groups, π_k an independent random permutation from ``fold_in(key, k)``; with
    groups ``lab`` (N,), the targets of each group in one random order (from
    ``fold_in(key, 1)``) and π_k(j) the target k places after j in its group's order,
    cyclically: a tuple's targets are of one group and distinct (a target paired with
    itself puts both instruments' tips at one point: 1/16 of the tuples with groups of
    16, where a random permutation has a fixed point at a share of 1/N_g)."""
    ident = jnp.arange(N)
    if lab is None:
        return [ident] + [jax.random.permutation(jax.random.fold_in(key, k), N)
                          for k in range(1, A)]  # fmt: skip
    u = jax.random.uniform(jax.random.fold_in(key, 1), (N,))
    order = jnp.argsort(lab.astype(u.dtype) + u)  # by group, at random within
    at = jnp.zeros((N,), order.dtype).at[order].set(ident.astype(order.dtype))  # j's place
    count = jnp.sum(lab[:, None] == lab[None, :], 1)  # each target's group size (N,)
    start = jnp.sum(lab[None, :] < lab[:, None], 1)  # where its group starts in ``order``
    return [ident] + [order[start + (at - start + k) % count] for k in range(1, A)]


def instrument_angles(per: dict[str, jax.Array], key: jax.Array,
                      lab: jax.Array | None = None, pair: tuple[int, int] = (0, 1)
                      ) -> jax.Array:  # fmt: skip
    """The angle (degrees, (M, N)) between the tool axes (``per["axis"]``, world frame) of
    the first two instrument arms ``pair`` at each target tuple of :func:`_tuples` (the
    triangulation of the two instruments; ``lab``: the targets' groups, :func:`perms`)."""
    A, M, N = per["success"].shape
    perm = perms(key, N, lab, pair[1] + 1)[pair[1]]
    a, b = per["axis"][pair[0]], per["axis"][pair[1]][:, perm]
    c = jnp.clip(jnp.sum(a * b, -1), -1.0, 1.0)
    return jnp.degrees(jnp.arccos(c))


def _tuples(per: dict[str, jax.Array], key: jax.Array, lab: jax.Array | None = None
            ) -> tuple[jax.Array, list[jax.Array]]:  # fmt: skip
    """(every arm reaches its target of the tuple (M, N), the arms' kept capsules per tuple
    [(M, N, L, 2, 3)] × A): tuple j takes arm k's target π_k(j), π_0 the identity and π_k
    the k-th permutation drawn from ``key`` (with groups ``lab``, within each group:
    :func:`perms`)."""
    A, M, N = per["success"].shape
    perm = perms(key, N, lab, A)
    ok = jnp.prod(jnp.stack([per["success"][k][:, perm[k]] for k in range(A)]), 0)
    seg = [per["segments"][k][:, perm[k]] for k in range(A)]
    return ok, seg


def estimates(per: dict[str, jax.Array], key: jax.Array | None = None,
              radii: tuple[float, ...] = (), margin: float = 0.0, band: Any = None,
              grp: tuple[int, int] | None = None, inst: tuple[int, ...] | None = None
              ) -> dict[str, tuple[jax.Array, jax.Array]]:  # fmt: skip
    """(value, SE) (M,) of every task index from the per-target values (A, M, N).
    ``inst``: the instrument arms where one arm holds the camera (:func:`instruments`):
    the means, ``reach``, ``gci_q05`` and ``collision_free`` are theirs, the camera arm
    counts in ``reach_<k>`` (the share of targets whose replication's scope pose it holds),
    ``reach_all`` and the arms' tuples (``arms_ok``, ``arms_free``).
    ``grp``: the targets' replication groups (:func:`groups`), whose spread the SEs are
    (batch means; the module's docstring); None: the i.i.d. SEs.

    With several arms (A > 1): ``reach``, ``gci`` and the other means are means over the
    arms and targets (their SE the spread of the per-target means over the arms, never
    below the Agresti–Coull SE for ``reach``); ``reach_<k>`` each arm's share;
    ``reach_all`` the share of targets every arm reaches; ``arms_free`` (needs ``key``,
    the arms' ``radii`` and the ``margin``): one target per arm, arm k's the k-th
    independent permutation of the targets (arm 0's the identity), and among the tuples
    every arm reaches, the share whose kept solutions keep every arm at least ``margin``
    from every other (capsule against capsule), a ratio estimator (n/a under
    :data:`N_MIN` such tuples); ``arms_ok`` the unconditional share of the tuples that
    every arm reaches and whose arms keep that margin (Agresti–Coull SE): what a front or
    an objective should trade, since a ratio's denominator is the optimiser's to shrink.
    ``collision_free``: of the converged targets, the share whose solution is also free
    of collisions (n/a under :data:`N_MIN` converged targets). With the tool axes
    (``per["axis"]``): ``instrument_angle``, the mean angle (degrees) between arm 0's
    and arm 1's tool axes over the tuples every arm reaches (:func:`ratio_mean`, n/a
    under :data:`N_MIN` such tuples), and with ``band`` = [lo, hi] (degrees, an array)
    ``instrument_ok``: the unconditional share of the tuples that every arm reaches free
    of the others whose angle lies in the band."""
    A, M, N = per["success"].shape
    lab = labels(N, grp)
    G = 1 if lab is None else grp[0]  # type: ignore[index]
    ii = tuple(range(A)) if inst is None else tuple(inst)
    Ai = len(ii)

    def of(name):  # the instrument arms' values (Ai, M, N)
        return per[name] if inst is None else per[name][jnp.asarray(ii)]

    lab_a = None if lab is None else jnp.tile(lab, Ai)  # the (Ai·N) values' groups, arm-major
    out = {}
    for k in MEANS + (("clearance",) if "clearance" in per else ()):
        v = values(per, k, inst)
        out[k] = (jnp.mean(v, -1), mean_se(v, lab, G))
    if Ai == 1:
        out["reach"] = share(of("success")[0], lab, G)
    else:
        out["reach"] = (out["reach"][0], jnp.maximum(jnp.nan_to_num(out["reach"][1], nan=0.0), share(
            jnp.moveaxis(of("success"), 0, 1).reshape(M, Ai * N))[1]))  # fmt: skip
    out["gci_q05"] = quantile(jnp.moveaxis(of("inv_k"), 0, 1).reshape(M, Ai * N), Q, lab_a, G)
    if "clearance" in per:
        out["collision_free"] = ratio(jnp.sum(of("success"), 0), jnp.sum(of("converged"), 0),
                                      N_MIN, lab, G)  # fmt: skip
    if A > 1:
        from designopt.kinematics.collision import arms_clearance

        for k in range(A):
            out[f"reach_{k}"] = share(per["success"][k], lab, G)
        out["reach_all"] = share(jnp.prod(per["success"], 0), lab, G)
        if key is None or "segments" not in per:
            return out  # arms_free needs the tuples' key and the kept capsules
        ok, seg = _tuples(per, key, lab)
        r = jnp.asarray(radii, seg[0].dtype)  # (L,), or each arm's (A, L) (a mixed set-up)
        gap = None
        for a in range(A):
            for b in range(a + 1, A):
                ra, rb = (r[a], r[b]) if r.ndim == 2 else (r, r)
                d = arms_clearance(seg[a], ra, seg[b], rb)
                gap = d if gap is None else jnp.minimum(gap, d)
        free = (gap >= margin).astype(ok.dtype)  # type: ignore[operator]
        out["arms_ok"] = share(ok * free, lab, G)
        out["arms_free"] = ratio(ok * free, ok, N_MIN, lab, G)
        if "axis" in per and Ai >= 2:
            ang = instrument_angles(per, key, lab, (ii[0], ii[1]))
            out["instrument_angle"] = ratio_mean(ang, ok, N_MIN, lab, G)
            if band is not None:
                lo, hi = band[0].astype(ang.dtype), band[1].astype(ang.dtype)
                out["instrument_ok"] = share(ok * free * ((ang >= lo) & (ang <= hi)), lab, G)
    return out


def structure_key(s: SerialSettings) -> str:
    """What shapes :func:`per_target`'s program, as text: the settings without the
    scene's numbers, which travel in ``params`` (:func:`scene_params`, the targets,
    ``bodies.base_params``): the region's kind (a points file: its count), whether there
    are ports and insertion ranges, the obstacles' count per shape, the arms' base
    entries that name a variable (a number's value left out); the objective and the
    constraints, which the program does not read, left out too. Two settings with one
    key run in one compiled program."""
    import json

    from designopt.kinematics.task import Points

    d = s.model_dump(mode="json")
    d.pop("objective", None)
    d.pop("constraints", None)
    d.pop("pareto", None)
    task = d.get("task")
    if task is not None:
        task["ik"]["n_best"] = best_slots(s.task.ik.n_best)  # the count is an input
        reg = s.task.region  # type: ignore[union-attr]
        task["region"] = (f"points:{len(reg.xyz())}" if isinstance(reg, Points)
                          else str(task["region"].get("shape")))  # fmt: skip
        task["port"] = _entry_names(task.get("port"))
        task["insertion"] = task.get("insertion") is not None
        cam = task.get("camera")  # its numbers are inputs; only a shaft adds to the program
        task["camera"] = None if cam is None else {"shaft": cam.get("shaft") is not None}
        w = task.get("body_wall")
        if w is not None:  # its kind (a mesh: and its triangles' count) shapes the program
            mesh = w.get("shape") == "mesh"
            n_tri = s.task.body_wall.triangles()[0].shape[0] if mesh else None  # type: ignore[union-attr]
            task["body_wall"] = [w.get("shape"), n_tri]
    col = d.get("collision")
    if col is not None:
        obs = col.get("obstacles", [])
        shapes = [("inside " if o.get("inside") else "") + str(o.get("shape")) for o in obs]
        res = [int(o.get("resolution", 64)) for o in obs if o.get("shape") == "mesh"]
        col["obstacles"] = {k: shapes.count(k) for k in sorted(set(shapes))}
        if res:  # meshes share one grid array of the largest resolution
            col["mesh_resolution"] = max(res)
    for a in d.get("arms") or []:
        a["port"] = _entry_names(a.get("port"))
        a["insertion"] = a.get("insertion") is not None
        for f in ("xyz", "rpy"):
            a["base"][f] = [v if isinstance(v, str) else "#" for v in a["base"][f]]
    return json.dumps(d, sort_keys=True)


def _entry_names(row: Any) -> Any:
    """A port's entries with the numbers left out (False: no port)."""
    return False if row is None else [v if isinstance(v, str) else "#" for v in row]
