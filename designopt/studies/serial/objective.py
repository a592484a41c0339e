"""The serial study's indices and objective as a swarm Problem.

Over the joint box Q (samples shared by the whole swarm, streamed in chunks):
- ``gci``: mean of 1/k of the selected Jacobian rows (2-norm or Frobenius);
- ``gcsei``: its standard deviation;
- ``manipulability``: mean of sqrt(det J Jᵀ) (sqrt(det JᵀJ) when rows > joints);
- ``volume``: ∫_Q sqrt(det Jv Jvᵀ) dq = ∫_Q |det Jv| dq, for a square position Jacobian.
Means use the joint measure (w = 1) or the Cartesian one (w = |det J|, square J).
Each comes with its delta-method standard error (``designopt.numerics.montecarlo``), or, with the
``rqmc`` sampler, the spread of R independently shifted replicates (docs/indices.md). The
objective is f = Σ w_i index_i (or of the indices normalised over a Halton sample of the
design box, as in study A); ``f_se`` is the bound Σ |w_i| se_i (the estimates share
samples), or under rqmc the replicate spread of f itself.

Under ``measure: task`` the indices are those of a task workspace instead (reach, gci,
gci_q05, manipulability, joint_margin at the IK solutions of the task's targets;
``taskindex``), and f's SE is exact for its mean-type terms. ``constraints`` may bound
any index (``{index: reach, ge: 0.99}``) beside the linear ones on the variables.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.kinematics.conditioning import inv_cond
from designopt.numerics import montecarlo as mc
from designopt.problems import normalise
from designopt.problems.base import Problem, Staged, na_worst, reads_indices
from designopt.studies.serial import blocks, camera, incisions, taskindex
from designopt.studies.serial.mechanism import Mechanism, build
from designopt.studies.serial.settings import IndexConstraint, SerialSettings
from designopt.studies.serial.taskindex import design_full


def measures(
    J: jnp.ndarray, norm: str, normalized: bool
) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """(1/k, manipulability, |det J| or 0 if J is not square) of (..., r, n) Jacobians;
    manipulability = σ_1⋯σ_m = sqrt(det J Jᵀ) (sqrt(det JᵀJ) when r > n), |det J| if square
    (``conditioning.inv_cond`` with ``with_volume``: one closed form or one Jacobi SVD)."""
    r, n = J.shape[-2:]
    inv_k, man = inv_cond(J, norm, normalized, with_volume=True)
    return inv_k, man, man if r == n else jnp.zeros_like(man)


def chunk_sums(mech: Mechanism, s: SerialSettings, full: jnp.ndarray, q: jnp.ndarray):
    """Power sums of (1/k, manipulability, |det J|) for designs ``full`` (M, V) in kernel
    units at joint samples q (C, n)."""
    ind = s.indices
    rows = ind.rows()
    J = mech.model.jacobian(full, q, rows=rows)
    if ind.length_scale != 1.0 and any(r >= 3 for r in rows):
        sc = jnp.asarray([1.0 if r < 3 else ind.length_scale for r in rows], J.dtype)
        J = J * sc[:, None]
    inv_k, man, adet = measures(J, ind.norm, ind.normalized)
    w = adet if ind.measure == "cartesian" else jnp.ones_like(inv_k)
    return (mc.power_sums(w, inv_k), mc.power_sums(w, man),
            mc.power_sums(adet, jnp.ones_like(adet)))  # fmt: skip


def build_task_fn(mech: Mechanism, s: SerialSettings, dtype: Any) -> tuple[Any, Staged]:
    """(the swarm function under ``measure: task``, the same in two stages): the task
    indices with their SEs and f = Σ w·index. f's SE is the spread of the per-target sum
    of its mean-type terms (exact: they share the targets) plus |w|·SE for ``gci_q05``
    (a bound). The stages (``Problem.staged``): the per-target values in one compiled
    block program per structure (``blocks``), then their reduction to the indices."""
    weights = s.weights()
    names, w = list(weights), list(weights.values())

    gap = s.has_port_gap()
    shared = s.shared_port()
    view = s.task is not None and s.task.camera is not None
    holder = s.camera_arm()  # the arm that holds the scope, if one does
    inst = taskindex.instruments(s)
    wall = None if s.task is None or s.task.body_wall is None else s.task.body_wall.shape

    def fn(params, X, key):
        per = taskindex.per_target(mech, s, params, design_full(params, X, dtype), dtype)
        return from_per(params, per, X)

    def reduce(params, X, key, chunks):
        return from_per(params, blocks.assembled(s, chunks, X.shape[0],
                                                 params["target_p"].shape[0]), X)  # fmt: skip

    def from_per(params, per, X):
        est = taskindex.estimates_of(s, mech, per, params)
        full = design_full(params, X, dtype)
        if gap:  # exact: a function of the design alone (no samples, SE 0)
            g = incisions.port_gap(params, full, wall, shared, holder)
            est["port_gap"] = (g, jnp.zeros_like(g))
        seen = None
        if view:  # the endoscope's view of the targets: no IK
            seen = camera.seen(params, full, wall, params["target_p"]).astype(dtype)
            if holder is not None:  # seen while its arm holds the scope (its replication's)
                seen = seen * per["success"][holder].astype(dtype)
            G, run = taskindex.groups(s)
            est["view_ok"] = taskindex.share(seen, taskindex.labels(seen.shape[-1], (G, run)), G)
        out = {}
        for k, (v, se) in est.items():
            out[k], out[k + "_se"] = v, se
        cnt = taskindex.counts_of(s, mech, per, params)
        if seen is not None:  # a share of the targets: counted for the final stage's race
            cnt["view_ok"] = (jnp.sum(seen, -1), seen.shape[-1])
        for k, (n, of) in cnt.items():
            out[k + "_n"], out[k + "_of"] = n.astype(dtype), jnp.full_like(n, of, dtype)
        b = params["bounds"]
        f = normalise.weighted_sum([search_value(k, est[k][0], wk > 0)
                                    for k, wk in zip(names, w, strict=True)], b, w)  # fmt: skip
        lin = [i for i, k in enumerate(names) if taskindex.mean_type(k)]
        f_se = jnp.zeros_like(f)
        if lin:
            c = normalise.weighted_sum([taskindex.values(per, names[i], inst) for i in lin],
                                       b[jnp.asarray(lin)], [w[i] for i in lin])  # fmt: skip
            G, run = taskindex.groups(s)  # batch means over the replications (issue #65)
            f_se = taskindex.mean_se(c, taskindex.labels(c.shape[-1], (G, run)), G)
        for i, k in enumerate(names):
            if not taskindex.mean_type(k):  # an n/a term is a search value: no SE
                se = jnp.nan_to_num(out[k + "_se"], nan=0.0)
                f_se = f_se + abs(w[i]) * se / jnp.abs(b[i, 1] - b[i, 0])
        return f, out | {"f_se": f_se}

    calls = -(-taskindex.n_targets(s) // taskindex.chunk(s))  # a block's chunks of targets
    return fn, Staged(blocks.values(s, dtype), reduce, blocks.DESIGNS, blocks.least(s), calls)


def search_value(name: str, v: jax.Array, minimised: bool) -> jax.Array:
    """The value a search ranks: an n/a ratio (NaN, ``taskindex.NA_WORST``) at the worst
    end of its range for the search's sense, any other index as it is."""
    if name not in taskindex.NA_WORST:
        return v
    return na_worst(v, *taskindex.NA_WORST[name], minimised)


def constraints_fn(s: SerialSettings, names: tuple[str, ...], params: dict[str, Any],
                   dtype: Any) -> tuple[Any, list[dict[str, Any]]]:  # fmt: skip
    """(g(params, X[, aux]) -> G (M, n_c), feasible when ≤ 0, or None; the constraints as
    archived). Linear ones G = A x − b (``lin_A``, ``lin_b`` in params); index bounds
    ge − index or index − le read the indices fn computed (``reads_indices``)."""
    lin, idx = s.linear_constraints(), s.index_constraints()
    if not (lin or idx):
        return None, []
    if lin:
        A = np.zeros((len(lin), len(names)))
        rhs = np.zeros(len(lin))
        for i, c in enumerate(lin):
            sign = 1.0 if c.le is not None else -1.0  # ≥ ge becomes −Σ ≤ −ge
            for k, v in c.terms.items():
                A[i, names.index(k)] = sign * v
            rhs[i] = sign * (c.le if c.le is not None else c.ge)
        params["lin_A"] = jnp.asarray(A, dtype)
        params["lin_b"] = jnp.asarray(rhs, dtype)

    def linear(p, X):
        """G = A x − b (M, n_c): the linear constraints, feasible when ≤ 0."""
        return X @ p["lin_A"].astype(X.dtype).T - p["lin_b"].astype(X.dtype)

    def bound(c: IndexConstraint, b: jax.Array, aux: Mapping[str, jax.Array]) -> jax.Array:
        v = search_value(c.index, aux[c.index], c.le is not None)  # n/a: violated most
        return b - v if c.ge is not None else v - b

    archived = [c.model_dump(exclude_none=True) for c in s.constraints]
    if not idx:
        return linear, archived
    # the bounds are inputs (editing one compiles nothing); which side each is on is not
    params["idx_b"] = jnp.asarray([c.ge if c.ge is not None else c.le for c in idx], dtype)

    @reads_indices
    def with_indices(p, X, aux):
        b = p["idx_b"].astype(X.dtype)
        cols = [bound(c, b[i], aux)[:, None].astype(X.dtype) for i, c in enumerate(idx)]
        return jnp.concatenate(([linear(p, X)] if lin else []) + cols, -1)

    return with_indices, archived


def build_fn(mech: Mechanism, s: SerialSettings, dtype: Any, mesh: Any = None):
    """The pure swarm function fn(params, X, key) -> (f, indices with *_se); with a
    ``mesh``, its sample chunks are spread over the mesh's ``samples`` axis."""
    ind = s.indices
    names = s.index_names()
    weights = s.weights()
    lo = np.asarray(mech.lower)
    hi = np.asarray(mech.upper)
    qvol = float(np.prod(hi - lo))
    pl = mc.plan(ind.n_samples, ind.chunk, ind.sampler, ind.replicates)

    def indices(params, X):
        full = design_full(params, X, dtype)
        lo_, hi_ = params["q_lower"].astype(dtype), params["q_upper"].astype(dtype)

        def sums(k):
            u = mc.chunk_points(params["sample_key"], k, pl, mech.n, dtype)
            q = lo_ + (hi_ - lo_) * u
            return mc.to_replicate(chunk_sums(mech, s, full, q), k, pl)

        init = tuple(mc.zero_sums((X.shape[0],), pl, dtype) for _ in range(3))
        ps_k, ps_m, ps_v = mc.scan_chunks(sums, init, pl.n_chunks, mesh)
        out = {}
        for k, est in (("gci", mc.mean(ps_k)), ("gcsei", mc.std(ps_k)),
                       ("manipulability", mc.mean(ps_m)), ("volume", mc.box_integral(ps_v, qvol))):  # fmt: skip
            if k in names:
                out[k], out[k + "_se"] = est.value, est.se
        return out

    def fn(params, X, key):
        rep = indices(params, X)  # per replicate (last axis) under rqmc
        out = {}
        for k in rep:
            if not k.endswith("_se"):
                out[k], out[k + "_se"] = mc.combine(rep[k], rep[k + "_se"], pl)
        b = params["bounds"]  # (len(weights), 2): min, max per weighted index
        vals, ses = [rep[k] for k in weights], [out[k + "_se"] for k in weights]
        f, f_se = normalise.weighted_sum(vals, b, list(weights.values()), ses)
        if pl.replicates > 1:  # f per replicate: its SE from the replicates' spread
            f, f_se = mc.combine(f, None, pl)
        return f, out | {"f_se": f_se}

    return fn


def problem(s: SerialSettings, keys: Mapping[str, jax.Array], dtype: Any) -> Problem:
    """The serial study's Problem: design box from ``variables``, objective from
    ``objective`` (normalised over ``n_norm`` Halton designs when ``normalize: true``)."""
    dtype = jnp.dtype(dtype)
    mech = build(s)
    names, lower, upper = s.box()
    weights = s.weights()
    task = s.indices.measure == "task"
    if task and dtype != jnp.float64:  # the config refuses it (needs_float64); the API too
        raise ValueError(f"{s.needs_float64()}: set precision: float64")
    staged = None
    if task:
        fn, staged = build_task_fn(mech, s, dtype)
    else:
        fn = build_fn(mech, s, dtype)
    params = {
        "fixed": jnp.asarray(mech.fixed, dtype),
        "scale": jnp.asarray(mech.scale, dtype),
        "q_lower": jnp.asarray(mech.lower, dtype),
        "q_upper": jnp.asarray(mech.upper, dtype),
        "sample_key": keys["samples"],
        "bounds": normalise.unit_bounds(len(weights), dtype),
    }
    if task:  # once per run, shared by the swarm (common random numbers)
        from designopt.studies.serial import bodies

        params |= (taskindex.targets(s, keys["samples"], dtype) | bodies.base_params(s, mech, dtype)
                   | taskindex.scene_params(s, dtype, mech) | taskindex.group_params(s, dtype))  # fmt: skip
    # the constraints' arrays join params first: the probe's params are the run's
    cons, archived = constraints_fn(s, names, params, dtype)
    norm_bounds = None
    b = np.asarray([[0.0, 1.0]] * len(weights))  # params["bounds"]: unit rows unless normalised
    if s.objective.get("normalize", False):
        n_norm = int(s.objective.get("n_norm", 64))
        from designopt.core import exported

        ident = exported.fingerprint(s.model_dump(mode="json"), getattr(s, "config_dir", None))
        b = normalise.probe_bounds(fn, params, tuple(weights), lower, upper, n_norm, keys, dtype,
                                   staged=staged, constraints=cons, identity=ident)  # fmt: skip
        params["bounds"] = jnp.asarray(b, dtype)
        norm_bounds = {k: b[i].tolist() for i, k in enumerate(weights)}
    ind = s.indices
    if task:
        n_used = taskindex.n_targets(s)
    else:
        n_used = mc.plan(ind.n_samples, ind.chunk, ind.sampler, ind.replicates).n_used
    info = {
        "study": "serial",
        "n_samples_used": n_used,
        "fixed": dict(s.fixed),
        "rows": list(s.indices.rows()),
        "measure": s.indices.measure,
        "weights": weights,
        "norm_bounds": norm_bounds,
        "dtype": dtype.name,
    }
    if archived:
        info["constraints"] = archived
    if task:
        info["task"] = {"mode": taskindex.mode(s), "n_targets": n_used}
    typed = {"n_samples_used": n_used, "norm_bounds": b,
             "na_range": {k: v for k, v in taskindex.NA_WORST.items() if k in s.index_names()}}  # fmt: skip
    if task:  # the targets' indices need every target at once: no sample sharding
        return Problem(names, lower, upper, fn, params, info, cons, staged=staged, **typed)

    def shard_samples(mesh: Any) -> Problem:
        sharded = build_fn(mech, s, dtype, mesh)
        return Problem(names, lower, upper, sharded, params, info, cons, **typed)

    return Problem(names, lower, upper, fn, params, info, cons, shard_samples, **typed)
