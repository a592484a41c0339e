"""Pareto tools: dominance, non-dominated sorting, crowding distance, hypervolume, IGD+.

All objectives are minimised. Constraints enter as the total violation v ≥ 0 of each point
(v = 0: feasible) through Deb's constrained domination (Deb, Pratap, Agarwal & Meyarivan,
"A fast and elitist multiobjective genetic algorithm: NSGA-II", 2002): a feasible point
dominates an infeasible one, of two infeasible points the one with less violation
dominates, and two feasible points compare by Pareto dominance.

Two families with the same numbers:

- JAX (jit-able, vmappable, fixed shapes; used inside the optimizer's scan):
  ``dominance_matrix``, ``front_ranks``, ``crowding_distance``, ``hypervolume_jax``
  (exact for 2 and 3 objectives). The dominance matrix is O(n²·m), fine for the few hundred
  points of a population.
- numpy (the final front, host side): ``dominance_matrix_np``, ``front_ranks_np``,
  ``non_dominated``, ``crowding_distance_np``, ``hypervolume`` (exact for any number of
  objectives: a sort and a sum in 2-D, slices of 2-D sums in 3-D, recursive slicing above)
  and ``igd_plus``.

Hypervolume (Zitzler & Thiele, "Multiobjective optimization using evolutionary
algorithms — a comparative case study", 1998): the Lebesgue measure of the region
dominated by the points and bounded by the reference point r; only points strictly inside
the box (every f_k < r_k) count. In 2-D, with points sorted by f1,
HV = Σ_i (x_{i+1} − x_i)·(r_2 − min_{j≤i} y_j) (x_{n+1} = r_1); dominated points drop out by
themselves through the running minimum. In 3-D the same sum is taken over the slices
between consecutive f3 values, each slice holding the points below it:
HV = Σ_i (z_{i+1} − z_i)·A_i, A_i the 2-D hypervolume of the points with z ≤ z_i: O(n²)
work with n×n arrays in JAX (exact, no sampling). IGD+ (Ishibuchi, Masuda, Tanigaki &
Nojima, "Modified distance calculation in generational distance and inverted generational
distance", 2015): the mean over reference-front points z of min_a ‖max(a − z, 0)‖.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

Array = jnp.ndarray


# ---------------------------------------------------------------- JAX (inside the loop)


def dominance_matrix(F: Array, v: Array | None = None) -> Array:
    """(n, n) bool, [i, j] = point i dominates point j by Deb's constrained domination
    (plain Pareto dominance when ``v`` is None)."""
    le = jnp.all(F[:, None, :] <= F[None, :, :], axis=-1)
    lt = jnp.any(F[:, None, :] < F[None, :, :], axis=-1)
    pareto = le & lt
    if v is None:
        return pareto
    feas = v == 0
    return jnp.where(feas[:, None] & feas[None, :], pareto, v[:, None] < v[None, :])


def front_ranks(F: Array, v: Array | None = None, n_stop: int | None = None) -> Array:
    """Non-dominated sorting: the front index of every point (0 = non-dominated), int32.

    Fronts are peeled one at a time (a ``while_loop``, one O(n²) pass each) until at least
    ``n_stop`` points are ranked (default: all); points left unranked get rank n."""
    n = F.shape[0]
    dom = dominance_matrix(F, v)
    stop = n if n_stop is None else min(int(n_stop), n)

    def cond(c):
        r, k, done = c
        return (done < stop) & (k < n)

    def body(c):
        r, k, done = c
        rem = r == n
        dominated = jnp.any(dom & rem[:, None], axis=0)
        new = rem & ~dominated
        return jnp.where(new, k, r), k + 1, done + jnp.sum(new, dtype=jnp.int32)

    r0 = jnp.full(n, n, jnp.int32)
    r, _, _ = jax.lax.while_loop(cond, body, (r0, jnp.int32(0), jnp.int32(0)))
    return r


def _big(F: Array) -> Array:
    """The stand-in for a non-finite objective value (NaN and ±inf, a failed design):
    √(largest float), 1.3e154 in float64 and 1.8e19 in float32. Not the largest float
    itself: a front's range then reaches it, and a compiled division by that range
    becomes a product with its reciprocal, a subnormal that the CPU flushes to 0."""
    return jnp.asarray(math.sqrt(float(jnp.finfo(F.dtype).max)), F.dtype)


def crowding_distance(F: Array, rank: Array) -> Array:
    """NSGA-II's crowding distance of every point within its front (``rank``), as pymoo
    0.6 computes it: per objective the gap between the two neighbours divided by the
    front's range, summed and divided by m; the extremes of a front get +inf, an objective
    with zero range in a front adds 0, a front of ≤ 2 points is all +inf. Unranked points
    (rank n) form one more group; their value is unused."""
    n, m = F.shape
    F = jnp.where(jnp.isfinite(F), F, _big(F))
    counts = jnp.zeros(n + 1, jnp.int32).at[rank].add(1)

    def one(fk):
        idx = jnp.lexsort((fk, rank))  # by front, then by f_k (stable)
        rs, fs = rank[idx], fk[idx]
        prev_same = jnp.concatenate([jnp.zeros(1, bool), rs[1:] == rs[:-1]])
        next_same = jnp.concatenate([rs[:-1] == rs[1:], jnp.zeros(1, bool)])
        fprev = jnp.concatenate([fs[:1], fs[:-1]])
        fnext = jnp.concatenate([fs[1:], fs[-1:]])
        lo = jax.ops.segment_min(fs, rs, num_segments=n + 1)[rs]
        hi = jax.ops.segment_max(fs, rs, num_segments=n + 1)[rs]
        norm = hi - lo
        safe = jnp.where(norm > 0, norm, 1.0)
        d = jnp.where(prev_same & next_same, (fnext - fprev) / safe, jnp.inf)
        d = jnp.where(norm > 0, d, 0.0)
        return jnp.zeros(n, F.dtype).at[idx].set(d)

    cd = jnp.sum(jax.vmap(one, in_axes=1, out_axes=1)(F), axis=1) / m
    return jnp.where(counts[rank] <= 2, jnp.inf, cd)


def prune_last_front(F: Array, rank: Array, n: int, tie: Array) -> tuple[Array, Array]:
    """Survival with the last front pruned one point at a time (Kukkonen & Deb, "Improved
    pruning of non-dominated solutions based on crowding distance for bi-objective
    optimization problems", 2006): the fronts before the one that crosses n are kept whole;
    from that front the point of least crowding distance (ties: least ``tie``) is removed
    and its neighbours' distances are recomputed, until n points remain. The neighbours
    are kept as one doubly linked list per objective, so a removal costs O(m) updates and
    one arg-min, not a new sort. Returns (mask of the n kept, crowding distance: within
    the pruned front among its survivors, elsewhere :func:`crowding_distance`)."""
    N, m = F.shape
    F = jnp.where(jnp.isfinite(F), F, _big(F))
    counts = jnp.zeros(N + 1, jnp.int32).at[rank].add(1)
    last = jnp.argmax(jnp.cumsum(counts) >= n)  # the front that crosses n
    before, L = rank < last, rank == last
    need = n - jnp.sum(before, dtype=jnp.int32)
    n_last = jnp.sum(L, dtype=jnp.int32)
    pos = jnp.arange(N)
    prev, nxt, rng_ = [], [], []
    for k in range(m):
        o = jnp.lexsort((F[:, k], ~L))  # the last front first, ascending in f_k
        inside = pos < n_last
        p_o = jnp.where(inside & (pos > 0), jnp.roll(o, 1), -1)
        n_o = jnp.where(inside & (pos < n_last - 1), jnp.roll(o, -1), -1)
        prev.append(jnp.full(N, -1, jnp.int32).at[o].set(p_o.astype(jnp.int32)))
        nxt.append(jnp.full(N, -1, jnp.int32).at[o].set(n_o.astype(jnp.int32)))
        fk = jnp.where(L, F[:, k], jnp.nan)
        rng_.append(jnp.nanmax(fk) - jnp.nanmin(fk))

    def dist(i, prev, nxt):  # crowding distance of points i among the alive of the front
        total = jnp.zeros(i.shape, F.dtype)
        for k in range(m):
            p, q = prev[k][i], nxt[k][i]
            gap = (F[jnp.maximum(q, 0), k] - F[jnp.maximum(p, 0), k]) / jnp.where(
                rng_[k] > 0, rng_[k], 1.0
            )
            term = jnp.where((p < 0) | (q < 0), jnp.inf, gap)
            total = total + jnp.where(rng_[k] > 0, term, 0.0)
        return jnp.where(n_last <= 2, jnp.inf, total / m)

    d = jnp.where(L, dist(pos, prev, nxt), jnp.inf)

    def cond(c):
        return c[0] > need

    def body(c):
        alive_n, alive, d, prev, nxt = c
        dm = jnp.where(alive, jnp.nan_to_num(d, nan=0.0, posinf=jnp.inf), jnp.inf)
        lowest = alive & (dm == jnp.min(dm))
        j = jnp.argmin(jnp.where(lowest, tie, jnp.inf))
        prev, nxt = list(prev), list(nxt)
        hit = []
        for k in range(m):
            p, q = prev[k][j], nxt[k][j]
            nxt[k] = nxt[k].at[jnp.where(p >= 0, p, N)].set(q, mode="drop")
            prev[k] = prev[k].at[jnp.where(q >= 0, q, N)].set(p, mode="drop")
            hit += [p, q]
        alive = alive.at[j].set(False)
        h = jnp.stack(hit)
        d = d.at[jnp.where(h >= 0, h, N)].set(dist(jnp.maximum(h, 0), prev, nxt), mode="drop")
        return alive_n - 1, alive, d.at[j].set(jnp.inf), tuple(prev), tuple(nxt)

    c = (n_last, L, d, tuple(prev), tuple(nxt))
    _, alive, d, _, _ = jax.lax.while_loop(cond, body, c)
    crowd = jnp.where(L, d, crowding_distance(F, rank))
    return before | alive, crowd


def _hv2_jax(x: Array, y: Array, r0: Array, r1: Array) -> Array:
    o = jnp.argsort(x)
    xs, ys = x[o], y[o]
    xn = jnp.concatenate([xs[1:], r0[None]])
    return jnp.sum((xn - xs) * (r1 - jax.lax.cummin(ys)))


def hypervolume_jax(F: Array, ref: Array, valid: Array | None = None) -> Array:
    """Exact hypervolume of the points F (n, m) with ``valid`` (n,) bool (e.g. feasible)
    against ``ref`` (m,), for m = 2 or 3 (NaN for m > 3: use the numpy ``hypervolume`` on
    the final front). Jit-able and vmappable; 3-D costs O(n²)."""
    n, m = F.shape
    ref = jnp.asarray(ref, F.dtype)
    inside = jnp.all(F < ref, axis=1)
    if valid is not None:
        inside = inside & valid
    G = jnp.where(inside[:, None], F, ref)  # outside points sit on r: zero contribution
    if m == 2:
        return _hv2_jax(G[:, 0], G[:, 1], ref[0], ref[1])
    if m != 3:
        return jnp.full((), jnp.nan, F.dtype)
    oz = jnp.argsort(G[:, 2])
    zs = G[oz, 2]
    zn = jnp.concatenate([zs[1:], ref[2:]])
    zrank = jnp.zeros(n, jnp.int32).at[oz].set(jnp.arange(n, dtype=jnp.int32))
    ox = jnp.argsort(G[:, 0])
    xs, ys, zr = G[ox, 0], G[ox, 1], zrank[ox]
    xn = jnp.concatenate([xs[1:], ref[:1]])

    def area(i):  # 2-D hypervolume of the points in slices ≤ i
        y = jnp.where(zr <= i, ys, ref[1])
        return jnp.sum((xn - xs) * (ref[1] - jax.lax.cummin(y)))

    A = jax.vmap(area)(jnp.arange(n, dtype=jnp.int32))
    return jnp.sum((zn - zs) * A)


# ---------------------------------------------------------------- numpy (final fronts)


def _as_front(F) -> np.ndarray:
    F = np.asarray(F, np.float64)
    if F.ndim != 2:
        raise ValueError(f"F must be a 2-D array (n points, m objectives), got shape {F.shape}")
    return F


def dominance_matrix_np(F, v=None) -> np.ndarray:
    """numpy ``dominance_matrix``: [i, j] = i dominates j (Deb's constrained domination)."""
    F = _as_front(F)
    le = np.all(F[:, None, :] <= F[None, :, :], axis=-1)
    lt = np.any(F[:, None, :] < F[None, :, :], axis=-1)
    pareto = le & lt
    if v is None:
        return pareto
    v = np.asarray(v, np.float64)
    feas = v == 0
    return np.where(feas[:, None] & feas[None, :], pareto, v[:, None] < v[None, :])


def front_ranks_np(F, v=None) -> np.ndarray:
    """Front index of every point (0 = non-dominated) by peeling fronts (the brute-force
    reference for ``front_ranks``)."""
    dom = dominance_matrix_np(F, v)
    n = dom.shape[0]
    r = np.full(n, -1)
    k = 0
    while (r < 0).any():
        rem = r < 0
        new = rem & ~np.any(dom & rem[:, None], axis=0)
        r[new] = k
        k += 1
    return r


def _nd2(F: np.ndarray) -> np.ndarray:
    """2-D Pareto non-dominated mask by one sort (O(n log n)); equal points all kept."""
    n = F.shape[0]
    o = np.lexsort((F[:, 1], F[:, 0]))
    f1, f2 = F[o, 0], F[o, 1]
    cm = np.minimum.accumulate(f2)
    new = f2 < np.concatenate([[np.inf], cm[:-1]])
    first = np.maximum.accumulate(np.where(new, np.arange(n), 0))  # first holder of cm
    pm = np.concatenate([[np.inf], cm[:-1]])  # min f2 of the earlier points
    pf = np.concatenate([[np.inf], f1[first[:-1]]])  # its smallest f1
    dominated = (pm < f2) | ((pm == f2) & (pf < f1))
    out = np.empty(n, bool)
    out[o] = ~dominated
    return out


def _nd(F: np.ndarray, chunk: int) -> np.ndarray:
    n, m = F.shape
    if m == 2 and np.all(~np.isnan(F)):
        return _nd2(F)
    out = np.ones(n, bool)
    for s in range(0, n, chunk):
        A = F[s : s + chunk]
        le = np.all(F[:, None, :] <= A[None, :, :], axis=-1)  # [i, j]: F_i ≤ A_j
        lt = np.any(F[:, None, :] < A[None, :, :], axis=-1)
        out[s : s + chunk] = ~(le & lt).any(axis=0)
    return out


def non_dominated(F, v=None, chunk: int = 2048) -> np.ndarray:
    """Bool mask of the points no other point dominates (Deb's constrained domination
    with ``v``: the feasible non-dominated points, or, when none is feasible, every point
    of least violation). O(n log n) for 2 objectives, else O(n²·m) in chunks."""
    F = _as_front(F)
    if v is None:
        return _nd(F, chunk)
    v = np.asarray(v, np.float64).reshape(-1)
    feas = v == 0
    if not feas.any():
        return v == v.min()
    out = np.zeros(F.shape[0], bool)
    out[feas] = _nd(F[feas], chunk)
    return out


def crowding_distance_np(F, rank) -> np.ndarray:
    """numpy ``crowding_distance`` (pymoo 0.6's ``calc_crowding_distance`` per front)."""
    F = _as_front(F)
    rank = np.asarray(rank)
    out = np.zeros(F.shape[0])
    for k in np.unique(rank):
        idx = np.flatnonzero(rank == k)
        Fk = F[idx]
        n, m = Fk.shape
        if n <= 2:
            out[idx] = np.inf
            continue
        d = np.zeros(n)
        for j in range(m):
            o = np.argsort(Fk[:, j], kind="stable")
            f = Fk[o, j]
            norm = f[-1] - f[0]
            if norm == 0:
                continue
            dj = np.empty(n)
            dj[0] = dj[-1] = np.inf
            dj[1:-1] = (f[2:] - f[:-2]) / norm
            d[o] += dj
        out[idx] = d / m
    return out


def _hv2(P: np.ndarray, r: np.ndarray) -> float:
    o = np.lexsort((P[:, 1], P[:, 0]))
    xs, ys = P[o, 0], P[o, 1]
    xn = np.append(xs[1:], r[0])
    return float(np.sum((xn - xs) * (r[1] - np.minimum.accumulate(ys))))


def _hv3(P: np.ndarray, r: np.ndarray) -> float:
    n = P.shape[0]
    oz = np.argsort(P[:, 2], kind="stable")
    zs = P[oz, 2]
    zn = np.append(zs[1:], r[2])
    zrank = np.empty(n, int)
    zrank[oz] = np.arange(n)
    ox = np.lexsort((P[:, 1], P[:, 0]))
    xs, ys, zr = P[ox, 0], P[ox, 1], zrank[ox]
    w = np.append(xs[1:], r[0]) - xs
    total = 0.0
    for i in range(n):  # slice i: the points with z ≤ z_i
        if zn[i] == zs[i]:
            continue
        y = np.where(zr <= i, ys, r[1])
        total += (zn[i] - zs[i]) * float(np.sum(w * (r[1] - np.minimum.accumulate(y))))
    return total


def _hv(P: np.ndarray, r: np.ndarray) -> float:
    n, m = P.shape
    if n == 0:
        return 0.0
    if m == 1:
        return float(r[0] - P[:, 0].min())
    if m == 2:
        return _hv2(P, r)
    if m == 3:
        return _hv3(P, r)
    # m ≥ 4: slice along the last objective (hypervolume by slicing objectives, exact)
    o = np.argsort(P[:, -1], kind="stable")
    P = P[o]
    zn = np.append(P[1:, -1], r[-1])
    total = 0.0
    for i in range(n):
        h = zn[i] - P[i, -1]
        if h <= 0:
            continue
        Q = P[: i + 1, :-1]
        Q = Q[non_dominated(Q)]
        total += h * _hv(Q, r[:-1])
    return total


def hypervolume(F, ref) -> float:
    """Exact hypervolume of the points F (n, m) against the reference point ``ref`` (m,);
    points not strictly inside the box (some f_k ≥ r_k) and non-finite points add nothing."""
    F = _as_front(F)
    r = np.asarray(ref, np.float64).reshape(-1)
    if r.shape[0] != F.shape[1]:
        raise ValueError(
            f"reference point has {r.shape[0]} values, the front has {F.shape[1]} objectives"
        )
    P = F[np.all(np.isfinite(F), axis=1) & np.all(F < r, axis=1)]
    if P.shape[0] == 0:
        return 0.0
    P = P[non_dominated(P)]
    return _hv(P, r)


def igd_plus(F, reference_front, chunk: int = 1024) -> float:
    """IGD+ of the points F (n, m) against a sampled true front Z (k, m): the mean over z
    of min over points a of ‖max(a − z, 0)‖ (0 when F covers Z; lower is better)."""
    F = _as_front(F)
    Z = _as_front(reference_front)
    if F.shape[1] != Z.shape[1]:
        raise ValueError(f"F has {F.shape[1]} objectives, the reference front {Z.shape[1]}")
    if F.shape[0] == 0:
        return float("inf")
    d = np.empty(Z.shape[0])
    for s in range(0, Z.shape[0], chunk):
        diff = np.maximum(F[None, :, :] - Z[s : s + chunk, None, :], 0.0)
        d[s : s + chunk] = np.sqrt(np.sum(diff * diff, axis=-1)).min(axis=1)
    return float(d.mean())


def thin(F: np.ndarray, n: int) -> np.ndarray:
    """Indices of at most ``n`` rows of a front F, dropping the most crowded first
    (the extremes, with infinite crowding distance, always stay)."""
    keep = np.arange(len(F))
    while len(keep) > n:
        d = crowding_distance_np(F[keep], np.zeros(len(keep), np.int32))
        keep = np.delete(keep, int(np.argmin(d)))
    return keep
