"""Frame-based kinematics kernel: FK, geometric Jacobian and 1/k of any serial chain.

One model serves a swarm: ``X`` (M, D) holds M designs (the columns named by
``model.variables``), ``q`` (C, n_active) the C joint samples they all share. Every
output has leading dims (M, C); a 1-D X (one design) drops the M axis, a 1-D q (one
configuration) the C axis.

How it is built (docs/kinematics.md has the long version):

- A chain is lowered to elementary steps, rotations about and translations along a frame
  axis, whose values are linear in the design variables and in the active joints
  (``const + Σ s_k X_k + Σ c_j q_j``; joint couplings enter through the c_j).
- The walk along the chain happens in Python when the kernel is traced. Rotations about
  the same axis are merged symbolically (so the haptic master's q4 = −q3 parallelogram cancels
  exactly and Rz(q1)·Rz(q2 − π/2)·Rz(−q1 − q2) folds to Rz(−π/2)), constant twists that
  are multiples of π/2 become exact signed permutations, and every product with a known
  0 or ±1 is folded away (``_fold``). Trigonometry is computed once per distinct linear
  combination of joints.
- The Jacobian comes from the frames: a revolute column is z_i × (p_n − p_i), a
  prismatic one z_i; p_n − p_i is the sum of the translation steps after joint i, so
  structural zeros (z × z) are known at trace time.
- Positions are kept as a *linear form in the length variables*: p = B_0 + Σ_k L_k B_k,
  each B_k a per-sample array. As long as no angle depends on a design variable, every
  rotation is per-sample, all B_k are (C,) arrays computed once for the swarm, and only
  the final contraction with the lengths runs at (M, C). Where an angle depends on a
  design variable, the rotations after it are per design ((M, C) arrays) and the steps
  they touch are contracted at once (per-design frames for the affected part).
  The choice is made from the chain's data, with no flag.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from designopt.kinematics import _fold as F
from designopt.kinematics.conditioning import _inv_cond_entries

Array = jnp.ndarray
Scalar = F.Scalar
Vec3 = tuple[Scalar, Scalar, Scalar]

_AXES = {"x": 0, "y": 1, "z": 2}
_HALF_PI = math.pi / 2
_MAX_PENDING = 3


ETKind = Literal["Rx", "Ry", "Rz", "Tx", "Ty", "Tz"]
ET_KINDS: tuple[str, ...] = ("Rx", "Ry", "Rz", "Tx", "Ty", "Tz")


@dataclass(frozen=True)
class ET:
    """One elementary transform of an ``et_model`` chain: ``kind`` (a rotation about or a
    translation along a frame axis) with value ``const + scale·X[param] + q_chain[joint]``.

    ``param`` names a design variable, ``joint`` a chain joint index; either may be None.
    Rotations driven by a joint are revolute joints, translations prismatic.
    """

    kind: ETKind
    joint: int | None = None
    param: str | None = None
    const: float = 0.0
    scale: float = 1.0  # multiplies the param (e.g. -1 for Rx(-alpha))

    def __post_init__(self) -> None:
        if self.kind not in ET_KINDS:
            raise ValueError(f"elementary transform kind must be one of {sorted(ET_KINDS)}")


class _Lin(NamedTuple):
    """const + Σ_k s_k X_k + Σ_j c_j q_j (trace-time description of a step's value)."""

    const: float
    xc: tuple[tuple[int, float], ...]  # (variable index, scale), sorted, no zeros
    qc: tuple[float, ...]  # one coefficient per active joint

    def __add__(self, o: _Lin) -> _Lin:  # type: ignore[override]
        xs: dict[int, float] = dict(self.xc)
        for k, s in o.xc:
            xs[k] = xs.get(k, 0.0) + s
        return _Lin(
            self.const + o.const,
            tuple(sorted((k, s) for k, s in xs.items() if s != 0.0)),
            tuple(a + b for a, b in zip(self.qc, o.qc, strict=True)),
        )

    def is_zero_angle(self) -> bool:
        if self.xc or any(c != 0.0 for c in self.qc):
            return False
        r = math.remainder(self.const, 2 * math.pi)
        return abs(r) < 1e-12

    def sig(self) -> tuple:
        return (round(self.const, 12), self.xc, self.qc)


@dataclass(frozen=True)
class _Step:
    kind: Literal["R", "T"]
    axis: int
    value: _Lin
    joint: int | None  # chain joint index (for the Jacobian) or None


def _parse_entry(v: Any, variables: Sequence[str]) -> tuple[float, tuple[tuple[int, float], ...]]:
    """A table entry: float, variable name, (name, scale) or (name, scale, const)."""
    if isinstance(v, str):
        v = (v, 1.0, 0.0)
    if isinstance(v, tuple | list):
        name = v[0]
        scale = float(v[1]) if len(v) > 1 else 1.0
        const = float(v[2]) if len(v) > 2 else 0.0
        if name not in variables:
            raise ValueError(f"unknown design variable {name!r}; variables are {tuple(variables)}")
        xc = ((variables.index(name), scale),) if scale != 0.0 else ()
        return const, xc
    return float(v), ()


def _entry_names(v: Any) -> list[str]:
    if isinstance(v, str):
        return [v]
    if isinstance(v, tuple | list) and v and isinstance(v[0], str):
        return [v[0]]
    return []


@dataclass(frozen=True)
class SerialModel:
    """A serial chain lowered to frame steps, with a linear joint coupling.

    Build with ``dh_model`` or ``et_model``. ``coupling`` (n_chain, n_active) and
    ``offset`` (n_chain,) map active joints to chain joints: q_chain = C q + offset.
    """

    steps: tuple[_Step, ...]
    joint_types: tuple[str, ...]  # per chain joint, "R" or "P"
    variables: tuple[str, ...]
    coupling: tuple[tuple[float, ...], ...]
    offset: tuple[float, ...]
    _shared: bool = field(default=True, compare=False)

    @property
    def n_active(self) -> int:
        return len(self.coupling[0]) if self.coupling else 0

    @property
    def n_chain(self) -> int:
        return len(self.joint_types)

    @property
    def shares_rotations(self) -> bool:
        """True when no rotation depends on a design variable: every frame rotation is
        per-sample and the Jacobian is B_0(q) + Σ_k L_k B_k(q) for the whole swarm."""
        return all(not (s.kind == "R" and s.value.xc) for s in self.steps)

    def per_design(self) -> SerialModel:
        """The same model evaluated without shared bases (each design's frames computed
        in full): for tests and benchmarks of the fallback path."""
        return SerialModel(
            self.steps, self.joint_types, self.variables, self.coupling, self.offset, False
        )

    def reach_bound(self, x_lower: ArrayLike, x_upper: ArrayLike, q_lower: ArrayLike,
                    q_upper: ArrayLike) -> float:  # fmt: skip
        """An upper bound of the tip's distance from the base origin over every design in
        the box [x_lower, x_upper] (kernel units: rad for angles) and every configuration
        in [q_lower, q_upper] (active joints): rotations keep lengths, so |p| is at most
        the sum over translation steps of the largest |value| a step takes, each value
        being linear in the design and the joints (its largest magnitude over a box is
        |value at the centre| + Σ |coefficient| · half-width). Exact for a straight chain
        stretched out; the sum of the link lengths along the chain otherwise."""
        xl, xu = np.asarray(x_lower, np.float64), np.asarray(x_upper, np.float64)
        ql, qu = np.asarray(q_lower, np.float64), np.asarray(q_upper, np.float64)
        xm, xh = (xl + xu) / 2, (xu - xl) / 2
        C, off = np.asarray(self.coupling, np.float64).reshape(self.n_chain, -1), self.offset
        total = 0.0
        for s in self.steps:
            if s.kind != "T":
                continue
            v = s.value
            mid = v.const + sum(c * xm[k] for k, c in v.xc)
            half = sum(abs(c) * xh[k] for k, c in v.xc)
            if s.joint is not None:  # a prismatic joint adds q_chain = C q_active + offset
                mid += float(C[s.joint] @ ((ql + qu) / 2)) + off[s.joint]
                half += float(np.abs(C[s.joint]) @ ((qu - ql) / 2))
            total += abs(mid) + half
        return float(total)

    # ------------------------------------------------------------------ evaluation
    def _walk(self, X: ArrayLike, q: ArrayLike) -> tuple[_Walk, Array, Array, bool]:
        X, q, single = _prep(X, q, len(self.variables), self.n_active)
        w = _Walk(self, X, q)
        for s in self.steps:
            w.step(s)
        return w, X, q, single

    def fk(self, X: ArrayLike, q: ArrayLike) -> tuple[Array, Array]:
        """Tip rotation (M, C, 3, 3) and position (M, C, 3)."""
        w, X, q, single = self._walk(X, q)
        rot, pos = w.seal((w.rot_entries(), w.pos_lins()))
        return _squeeze((w.rot_array(rot), w.pos_array(pos)), single)

    def joint_frames(self, X: ArrayLike, q: ArrayLike) -> tuple[Array, Array, Array]:
        """Where the chain's joints are: (origins (M, C, n_chain + 1, 3), axes (M, C,
        n_chain, 3), tip rotation (M, C, 3, 3)). ``origins[..., i, :]`` is the point at
        which chain joint i acts (the start of its rotation or translation step), the
        last one the tip; ``axes[..., i, :]`` is joint i's unit axis in the base frame.
        Link i runs from origin i to origin i + 1 (the segments a drawing and the
        ``links: auto`` collision capsules use); origins[..., -1, :] equals ``fk``'s
        position and the tip rotation its rotation."""
        w, X, q, single = self._walk(X, q)
        n = self.n_chain
        marks = [w.joints[i][2] for i in range(n)] + [len(w.incs)]
        pos: list[list[dict]] = []
        acc: dict[int | None, Vec3] = {}
        t = 0
        for mk in marks:  # running prefix sums of the translation steps
            while t < mk:
                k, f, col = w.incs[t]
                acc = dict(acc)
                acc[k] = _axpy(acc.get(k), f, col)
                t += 1
            pos.append([{k: v[i] for k, v in acc.items()} for i in range(3)])
        axes = [list(w.joints[i][1]) for i in range(n)]
        pos, axes, rot = w.seal((pos, axes, w.rot_entries()))
        P = jnp.stack([w.pos_array(p) for p in pos], -2)
        A = jnp.stack([jnp.stack([w.full(x) for x in a], -1) for a in axes], -2)
        return _squeeze((P, A, w.rot_array(rot)), single)

    def jacobian(
        self,
        X: ArrayLike,
        q: ArrayLike,
        rows: Sequence[int] | None = None,
        cols: Sequence[int] | None = None,
        char_length: float | None = None,
    ) -> Array:
        """Geometric Jacobian (M, C, len(rows), len(cols)) in the base frame.

        Rows vx vy vz wx wy wz (default all six), columns the active joints (default all).
        ``char_length`` divides the linear-velocity rows (so that a full 6×n Jacobian
        of a revolute arm is dimensionless). Unrequested entries are never traced.
        """
        w, X, q, single = self._walk(X, q)
        E = w.jacobian_entries(_rows(rows), _cols(cols, self.n_active), char_length)
        return _squeeze((w.stack(w.seal(E)),), single)[0]

    def fk_jacobian(
        self,
        X: ArrayLike,
        q: ArrayLike,
        rows: Sequence[int] | None = None,
        cols: Sequence[int] | None = None,
        char_length: float | None = None,
    ) -> tuple[Array, Array, Array]:
        """(R, p, J) from one walk along the chain."""
        w, X, q, single = self._walk(X, q)
        E = w.jacobian_entries(_rows(rows), _cols(cols, self.n_active), char_length)
        rot, pos, E = w.seal((w.rot_entries(), w.pos_lins(), E))
        return _squeeze((w.rot_array(rot), w.pos_array(pos), w.stack(E)), single)

    def inv_cond(
        self,
        X: ArrayLike,
        q: ArrayLike,
        rows: Sequence[int] | None = None,
        cols: Sequence[int] | None = None,
        norm: Literal["fro", "2"] = "fro",
        normalized: bool = False,
        char_length: float | None = None,
        with_position: bool = False,
        with_det: bool = False,
    ):
        """1/k of the selected Jacobian block, (M, C), computed entry-wise so that the
        structural zeros of the block are folded into the conditioning formulas
        (the closed forms of ``conditioning.inv_cond``, on the entries). ``with_position`` also returns p (M, C, 3);
        ``with_det`` also returns det J (square blocks up to 3×3, e.g. |det J_v| weights).
        Returns r, or a tuple (r, [p], [det]) in that order.
        """
        w, X, q, single = self._walk(X, q)
        E = w.jacobian_entries(_rows(rows), _cols(cols, self.n_active), char_length)
        E, pos = w.seal((E, w.pos_lins() if with_position else None))
        E = [[w.contract(e) for e in row] for row in E]
        r, det, _ = _inv_cond_entries(E, norm, normalized, dtype=w.dtype)
        out = [w.full(r)]
        if with_position:
            out.append(w.pos_array(pos))
        if with_det:
            if det is None:
                raise ValueError("with_det needs a square Jacobian block of size ≤ 3")
            out.append(w.full(det))
        out = _squeeze(tuple(out), single)
        return out[0] if len(out) == 1 else out


def _rows(rows: Sequence[int] | None) -> tuple[int, ...]:
    r = tuple(range(6)) if rows is None else tuple(int(i) for i in rows)
    if any(i < 0 or i > 5 for i in r):
        raise ValueError(f"rows must be in 0..5 (vx vy vz wx wy wz), got {r}")
    return r


def _cols(cols: Sequence[int] | None, n: int) -> tuple[int, ...]:
    c = tuple(range(n)) if cols is None else tuple(int(i) for i in cols)
    if any(i < 0 or i >= n for i in c):
        raise ValueError(f"cols must be active joint indices in 0..{n - 1}, got {c}")
    return c


def _prep(X: ArrayLike, q: ArrayLike, D: int, n: int) -> tuple[Array, Array, tuple[bool, bool]]:
    X, q = jnp.asarray(X), jnp.asarray(q)
    dtype = jnp.result_type(X, q)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    X, q = X.astype(dtype), q.astype(dtype)
    single = (X.ndim == 1, q.ndim == 1)
    if X.ndim == 1:
        X = X[None]
    if q.ndim == 1:
        q = q[None]
    if X.ndim != 2 or X.shape[1] != D:
        raise ValueError(f"X must have shape (M, {D}) (one column per variable), got {X.shape}")
    if q.ndim != 2 or q.shape[1] != n:
        raise ValueError(f"q must have shape (C, {n}) (active joints), got {q.shape}")
    return X, q, single


def _squeeze(out: tuple, single: tuple[bool, bool]) -> tuple:
    """Drop the M axis for a 1-D X (one design) and the C axis for a 1-D q."""
    sx, sq = single
    if sq:
        out = tuple(o[:, 0] for o in out)
    if sx:
        out = tuple(o[0] for o in out)
    return out


def _rot_vec(axis: int, c: Scalar, s: Scalar, v: Vec3) -> Vec3:
    """Rot_axis(c, s) · v with folding."""
    x, y, z = v
    if axis == 2:
        return (F.sub(F.mul(c, x), F.mul(s, y)), F.add(F.mul(s, x), F.mul(c, y)), z)
    if axis == 0:
        return (x, F.sub(F.mul(c, y), F.mul(s, z)), F.add(F.mul(s, y), F.mul(c, z)))
    return (F.add(F.mul(c, x), F.mul(s, z)), y, F.sub(F.mul(c, z), F.mul(s, x)))


def _cross(a: Vec3, b: Vec3) -> Vec3:
    if a is b:
        return (0.0, 0.0, 0.0)
    return (
        F.mul_sub(a[1], b[2], a[2], b[1]),
        F.mul_sub(a[2], b[0], a[0], b[2]),
        F.mul_sub(a[0], b[1], a[1], b[0]),
    )


def _axpy(acc: Vec3 | None, f: Scalar, v: Vec3) -> Vec3:
    fv = (F.mul(f, v[0]), F.mul(f, v[1]), F.mul(f, v[2]))
    if acc is None:
        return fv
    return (F.add(acc[0], fv[0]), F.add(acc[1], fv[1]), F.add(acc[2], fv[2]))


_E = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


_MATERIALIZE = "stack"
_GROUP = 8


def _materialize(leaves: list[Array]) -> list[Array]:
    """The same values; the 1-D (per-sample) ones computed once, not fused downstream."""
    if _MATERIALIZE == "none":
        return leaves
    if _MATERIALIZE == "each":
        return [
            jnp.sum(jnp.stack([x, jnp.zeros_like(x)]), axis=0) if jnp.ndim(x) == 1 else x
            for x in leaves
        ]
    groups: dict[tuple, list[int]] = {}
    for i, x in enumerate(leaves):
        if jnp.ndim(x) == 1:
            groups.setdefault((x.shape, jnp.result_type(x)), []).append(i)
    out = list(leaves)
    chunks = [ids[c : c + _GROUP] for ids in groups.values() for c in range(0, len(ids), _GROUP)]
    for ids in chunks:
        S = jnp.stack([leaves[i] for i in ids])
        S = jnp.sum(jnp.stack([S, jnp.zeros_like(S)]), axis=0)
        for r, i in enumerate(ids):
            out[i] = S[r]
    return out


class _Walk:
    """One trace-time walk along the chain for given X (M, D) and q (C, n)."""

    def __init__(self, model: SerialModel, X: Array, q: Array) -> None:
        self.model = model
        self.dtype = X.dtype
        self.M, self.C = X.shape[0], q.shape[0]
        self.xcol = [X[:, k][:, None] for k in range(X.shape[1])]  # (M, 1)
        self.qcol = [q[:, j] for j in range(q.shape[1])]  # (C,)
        self.trig_q: dict[tuple, tuple[Array, Array]] = {}
        self.trig_x: dict[tuple, tuple[Array, Array]] = {}
        self.cols: dict[tuple, Vec3] = {}
        self.R: tuple[Vec3, Vec3, Vec3] = _E  # committed rotation, by columns
        self.version = 0
        self.pend: list[tuple[int, _Lin]] = []
        self.incs: list[tuple[int | None, Scalar, Vec3]] = []  # (key, factor, column)
        self.joints: dict[int, tuple[str, Vec3, int]] = {}

    # --------------------------------------------------------------- scalars
    def _qsum(self, qc: Sequence[float]) -> Scalar:
        return F.total(F.mul(c, self.qcol[j]) for j, c in enumerate(qc) if c != 0.0)

    def _xsum(self, xc: Iterable[tuple[int, float]]) -> Scalar:
        return F.total(F.mul(s, self.xcol[k]) for k, s in xc)

    def trig(self, a: _Lin) -> tuple[Scalar, Scalar]:
        c: Scalar = 1.0
        s: Scalar = 0.0
        nz = [x for x in a.qc if x != 0.0]
        if nz:
            flip = nz[0] < 0
            key = tuple(-x for x in a.qc) if flip else a.qc
            if key not in self.trig_q:
                ang = self._qsum(key)
                self.trig_q[key] = (jnp.cos(ang), jnp.sin(ang))
            c, s = self.trig_q[key]
            if flip:
                s = -s
        n = round(a.const / _HALF_PI)
        r = a.const - n * _HALF_PI
        for _ in range(n % 4):  # exact quarter turns: (c, s) -> (-s, c)
            c, s = F.neg(s), c
        if abs(r) >= 1e-12:
            cr, sr = math.cos(r), math.sin(r)
            c, s = F.sub(F.mul(c, cr), F.mul(s, sr)), F.add(F.mul(s, cr), F.mul(c, sr))
        if a.xc:
            if a.xc not in self.trig_x:
                ang = self._xsum(a.xc)
                self.trig_x[a.xc] = (jnp.cos(ang), jnp.sin(ang))
            cx, sx = self.trig_x[a.xc]
            c, s = F.sub(F.mul(c, cx), F.mul(s, sx)), F.add(F.mul(s, cx), F.mul(c, sx))
        return c, s

    # -------------------------------------------------------------- rotations
    def col(self, axis: int) -> Vec3:
        """Column ``axis`` of the current rotation R·P_1···P_k (cached)."""
        pend = list(self.pend)
        if pend and pend[-1][0] == axis:
            pend.pop()  # a rotation about the axis leaves it unchanged
        key = (self.version, tuple((ax, a.sig()) for ax, a in pend), axis)
        if key not in self.cols:
            v: Vec3 = _E[axis]
            for ax, a in reversed(pend):
                c, s = self.trig(a)
                v = _rot_vec(ax, c, s, v)
            R = self.R
            self.cols[key] = tuple(
                F.total(F.mul(v[j], R[j][i]) for j in range(3)) for i in range(3)
            )  # type: ignore[assignment]
        return self.cols[key]

    def _push_rot(self, axis: int, a: _Lin) -> None:
        if a.is_zero_angle():
            return
        if self.pend and self.pend[-1][0] == axis:
            merged = self.pend.pop()[1] + a
            if not merged.is_zero_angle():
                self.pend.append((axis, merged))
            return
        if len(self.pend) == _MAX_PENDING:
            ax, b = self.pend.pop(0)
            c, s = self.trig(b)
            R = self.R
            new = [R[0], R[1], R[2]]
            i, j = [(1, 2), (2, 0), (0, 1)][ax]  # the plane the rotation acts in
            # R·Rot: column i -> c R_i + s R_j, column j -> -s R_i + c R_j
            new[i] = _axpy(_axpy(None, c, R[i]), s, R[j])
            new[j] = _axpy(_axpy(None, F.neg(s), R[i]), c, R[j])
            self.R = (new[0], new[1], new[2])
            self.version += 1
        self.pend.append((axis, a))

    def step(self, s: _Step) -> None:
        m = self.model
        val = s.value
        if s.joint is not None:
            i = s.joint
            val = val + _Lin(m.offset[i], (), m.coupling[i])
            self.joints[i] = (m.joint_types[i], self.col(s.axis), len(self.incs))
        if s.kind == "R":
            self._push_rot(s.axis, val)
            return
        col = self.col(s.axis)
        base = F.add(val.const, self._qsum(val.qc))
        design_col = any(F.is_design(x) for x in col)
        if not m._shared or (design_col and val.xc):
            f = F.add(base, self._xsum(val.xc))
            if not (F.is_const(f) and f == 0.0):
                self.incs.append((None, f, col))
            return
        if not (F.is_const(base) and base == 0.0):
            self.incs.append((None, base, col))
        for k, sc in val.xc:
            self.incs.append((k, sc, col))

    # ---------------------------------------------------------------- outputs
    def full(self, x: Scalar) -> Array:
        return jnp.broadcast_to(jnp.asarray(x, self.dtype), (self.M, self.C))

    def contract(self, lin: dict[int | None, Scalar]) -> Scalar:
        """B_0 + Σ_k X_k B_k: the only step that runs at (M, C) in the shared path."""
        acc = lin.get(None, 0.0)
        for k in sorted(k for k in lin if k is not None):
            acc = F.add(acc, F.mul(self.xcol[k], lin[k]))
        return acc

    def stack(self, E: list[list[dict]]) -> Array:
        rows = [jnp.stack([self.full(self.contract(e)) for e in row], -1) for row in E]
        return jnp.stack(rows, -2)

    def _sum_incs(self, weights: Sequence[float] | None = None, skip: Vec3 | None = None):
        acc: dict[int | None, Vec3] = {}
        for t, (k, f, col) in enumerate(self.incs):
            wt = 1.0 if weights is None else weights[t]
            if wt == 0.0 or col is skip:
                continue
            acc[k] = _axpy(acc.get(k), F.mul(wt, f), col)
        return acc

    def seal(self, tree):
        """Materialise the per-sample arrays the outputs use before the (M, C) stage.

        Left to itself, XLA on CPU fuses the per-sample trigonometry into the (M, C)
        loops and recomputes it for every design (measured: ~10× slower on the haptic master's chain), and
        the result of a swarm row then depends on M in the last bit. A reduction is a
        producer XLA does not fuse into elementwise consumers, so the per-sample arrays
        pass through one (a sum with zeros, exact); ``optimization_barrier`` would not
        do: the CPU compiler removes it before fusion.
        """
        leaves: list[Array] = []

        def collect(t):
            if isinstance(t, dict):
                return {k: collect(v) for k, v in t.items()}
            if isinstance(t, list):
                return [collect(v) for v in t]
            if isinstance(t, tuple):
                return tuple(collect(v) for v in t)
            if t is None or F.is_const(t):
                return t
            leaves.append(t)
            return len(leaves) - 1

        idx = collect(tree)
        sealed = _materialize(leaves)

        def rebuild(t, i):
            if isinstance(i, dict):
                return {k: rebuild(t[k], i[k]) for k in i}
            if isinstance(i, list):
                return [rebuild(a, b) for a, b in zip(t, i, strict=True)]
            if isinstance(i, tuple):
                return tuple(rebuild(a, b) for a, b in zip(t, i, strict=True))
            if i is None or isinstance(t, float | int) or F.is_const(t):
                return t
            return sealed[i]

        return rebuild(tree, idx)

    def pos_lins(self) -> list[dict]:
        p = self._sum_incs()
        return [{k: v[i] for k, v in p.items()} for i in range(3)]

    def pos_array(self, lins: list[dict]) -> Array:
        return jnp.stack([self.full(self.contract(e)) for e in lins], -1)

    def rot_entries(self) -> list[list[Scalar]]:
        cols = [self.col(j) for j in range(3)]
        return [[cols[j][i] for j in range(3)] for i in range(3)]

    def rot_array(self, R: list[list[Scalar]]) -> Array:
        return jnp.stack([jnp.stack([self.full(x) for x in row], -1) for row in R], -2)

    def _seg(self, lo: int, hi: int, coef: float, z: Vec3, acc: dict) -> None:
        """acc += coef · Σ_{lo ≤ t < hi} (steps not along z)."""
        if coef == 0.0:
            return
        for k, f, col in self.incs[lo:hi]:
            if col is not z:
                acc[k] = _axpy(acc.get(k), F.mul(coef, f), col)

    def jacobian_entries(
        self, rows: tuple[int, ...], cols: tuple[int, ...], char_length: float | None
    ) -> list[list[dict]]:
        """Entries of the selected Jacobian block as linear forms {key: scalar}.

        Revolute chain joint i: v_i = z_i × (p_n − p_i), where p_n − p_i is the sum of
        the translation steps after joint i (steps along z_i itself are dropped: z × z =
        0 exactly). Chain columns combine into active ones through the coupling; chain
        joints sharing the same axis object (e.g. the haptic master's q1/q5 and q3/q4 pairs) are
        combined before the cross product, so their cancellation is exact.
        """
        m = self.model
        n_inc = len(self.incs)
        need = sorted({i for i in range(m.n_chain) for j in cols if m.coupling[i][j] != 0.0})
        # suffix sums S(t) = Σ_{t' ≥ t} steps, at the joint positions
        marks = sorted({self.joints[i][2] for i in need} | {n_inc})
        snaps: dict[int, dict] = {n_inc: {}}
        acc: dict[int | None, Vec3] = {}
        t = n_inc
        for mk in reversed(marks[:-1]):
            while t > mk:
                t -= 1
                k, f, col = self.incs[t]
                acc = dict(acc)
                acc[k] = _axpy(acc.get(k), f, col)
            snaps[mk] = acc

        def nxt(idx: int) -> int:
            return next(x for x in marks if x > idx) if idx < n_inc else n_inc

        single: dict[int, dict] = {}  # joint i -> z_i × (p_n − p_i), cached

        def v_single(i: int) -> dict:
            if i not in single:
                _, z, idx = self.joints[i]
                S: dict = {}
                self._seg(idx, nxt(idx), 1.0, z, S)
                for k, v in snaps[nxt(idx)].items():
                    S[k] = _axpy(S.get(k), 1.0, v)
                single[i] = {k: _cross(z, v) for k, v in S.items()}
            return single[i]

        colsE: list[tuple[dict[int | None, Vec3], Vec3]] = []
        for j in cols:
            lin: dict[int | None, Vec3] = {}
            ang: Vec3 = (0.0, 0.0, 0.0)
            groups: dict[int, list[tuple[int, float]]] = {}
            for i in need:
                c = m.coupling[i][j]
                if c == 0.0:
                    continue
                jt, z, idx = self.joints[i]
                if jt == "P":
                    lin[None] = _axpy(lin.get(None), c, z)
                    continue
                groups.setdefault(id(z), []).append((i, c))
            for members in groups.values():
                z = self.joints[members[0][0]][1]
                ctot = sum(c for _, c in members)
                if ctot != 0.0:
                    ang = _axpy(ang, ctot, z)
                if len(members) == 1:
                    i, c = members[0]
                    for k, v in v_single(i).items():
                        lin[k] = _axpy(lin.get(k), c, v)
                    continue
                # Σ c_g (p_n − p_g) over members with the same axis, then one cross product
                members = sorted(members, key=lambda ic: self.joints[ic[0]][2])
                S: dict = {}
                cum = 0.0
                for (i, c), nx in zip(members, members[1:] + [None], strict=True):
                    cum += c
                    lo = self.joints[i][2]
                    hi = self.joints[nx[0]][2] if nx is not None else nxt(lo)
                    self._seg(lo, hi, cum, z, S)
                if ctot != 0.0:
                    last = self.joints[members[-1][0]][2]
                    for k, v in snaps[nxt(last)].items():
                        S[k] = _axpy(S.get(k), ctot, v)
                for k, v in S.items():
                    lin[k] = _axpy(lin.get(k), 1.0, _cross(z, v))
            colsE.append((lin, ang))
        scale = 1.0 if char_length is None else 1.0 / float(char_length)
        E = []
        for r in rows:
            row = []
            for lin, ang in colsE:
                if r < 3:
                    e = {k: F.mul(scale, v[r]) for k, v in lin.items()}
                else:
                    e = {None: ang[r - 3]}
                row.append({k: v for k, v in e.items() if not (F.is_const(v) and v == 0.0)})
            E.append(row)
        return E


# ---------------------------------------------------------------------- builders


def _coupling(
    coupling: Any, n_chain: int
) -> tuple[tuple[tuple[float, ...], ...], tuple[float, ...]]:
    if coupling is None:
        C = np.eye(n_chain)
        off = np.zeros(n_chain)
    else:
        if (
            isinstance(coupling, tuple)
            and len(coupling) == 2
            and np.ndim(coupling[0]) == 2
            and np.ndim(coupling[1]) == 1
        ):
            C, off = np.asarray(coupling[0], float), np.asarray(coupling[1], float)
        else:
            C, off = np.asarray(coupling, float), np.zeros(n_chain)
        if C.ndim != 2 or C.shape[0] != n_chain:
            raise ValueError(
                f"coupling must have shape (n_chain={n_chain}, n_active), got {C.shape}"
            )
        if off.shape != (n_chain,):
            raise ValueError(f"coupling offset must have shape ({n_chain},), got {off.shape}")
    return tuple(tuple(float(x) for x in r) for r in C), tuple(float(x) for x in off)


def _variables(variables: Sequence[str] | None, used: list[str]) -> tuple[str, ...]:
    if variables is None:
        return tuple(dict.fromkeys(used))
    variables = tuple(variables)
    missing = [u for u in used if u not in variables]
    if missing:
        raise ValueError(f"design variable(s) {missing} not in variables {variables}")
    return variables


def dh_model(
    convention: Literal["standard", "modified"],
    joint_types: Sequence[str],
    alpha: Sequence[Any],
    a: Sequence[Any],
    d: Sequence[Any],
    theta: Sequence[Any],
    variables: Sequence[str] | None = None,
    coupling: Any = None,
) -> SerialModel:
    """A DH table as a ``SerialModel``.

    Each entry of alpha, a, d, theta is a float (rad, mm), a variable name (a column of
    X), or ``(name, scale[, const])`` for const + scale·X[name]. The joint variable adds
    to θ (revolute) or d (prismatic). Standard: T_i = Rz(θ) Tz(d) Tx(a) Rx(α); modified:
    T_i = Rx(α_{i-1}) Tx(a_{i-1}) Rz(θ_i) Tz(d_i) (row i holds α_{i-1}, a_{i-1}).
    ``coupling``: None (active = chain joints), an (n_chain, n_active) matrix C, or a pair
    (C, offset): q_chain = C q_active + offset.
    """
    if convention not in ("standard", "modified"):
        raise ValueError(f"DH convention must be 'standard' or 'modified', got {convention!r}")
    jts = tuple(joint_types)
    bad = [t for t in jts if t not in ("R", "P")]
    if bad:
        raise ValueError(f"joint types must be 'R' or 'P', got {bad}")
    n = len(jts)
    for name, col in (("alpha", alpha), ("a", a), ("d", d), ("theta", theta)):
        if len(col) != n:
            raise ValueError(f"{name} must have {n} entries (one per joint), got {len(col)}")
    used = [u for col in (alpha, a, d, theta) for v in col for u in _entry_names(v)]
    variables = _variables(variables, used)
    Cm, off = _coupling(coupling, n)
    nA = len(Cm[0])
    zq = (0.0,) * nA

    def lin(v):
        c, xc = _parse_entry(v, variables)
        return _Lin(c, xc, zq)

    steps: list[_Step] = []
    for i, jt in enumerate(jts):
        th = _Step("R", 2, lin(theta[i]), i if jt == "R" else None)
        dd = _Step("T", 2, lin(d[i]), i if jt == "P" else None)
        aa = _Step("T", 0, lin(a[i]), None)
        al = _Step("R", 0, lin(alpha[i]), None)
        steps += [th, dd, aa, al] if convention == "standard" else [al, aa, th, dd]
    return SerialModel(tuple(steps), jts, variables, Cm, off)


def et_model(
    elements: Sequence[ET | tuple],
    variables: Sequence[str] | None = None,
    coupling: Any = None,
    n_chain: int | None = None,
) -> SerialModel:
    """An elementary-transform chain as a ``SerialModel``.

    ``elements``: a sequence of ``ET`` or of tuples ``(kind, joint, param, const, scale)``
    (trailing fields optional). Each value is
    const + scale·X[param] + q_chain[joint]; rotations driven by a joint are revolute,
    translations prismatic. ``coupling`` as in ``dh_model`` (chain joints are the ET
    joint indices 0..n_chain-1).
    """
    els = tuple(e if isinstance(e, ET) else ET(*e) for e in elements)
    js = [e.joint for e in els if e.joint is not None]
    nc = (max(js) + 1 if js else 0) if n_chain is None else n_chain
    if sorted(js) != list(range(nc)):
        raise ValueError(f"each chain joint 0..{nc - 1} must drive exactly one element, got {js}")
    used = [e.param for e in els if e.param is not None]
    variables = _variables(variables, used)
    Cm, off = _coupling(coupling, nc)
    nA = len(Cm[0]) if Cm else 0
    zq = (0.0,) * nA
    types = [""] * nc
    steps = []
    for e in els:
        xc = ((variables.index(e.param), float(e.scale)),) if e.param is not None else ()
        kind = "R" if e.kind[0] == "R" else "T"
        if e.joint is not None:
            types[e.joint] = "R" if kind == "R" else "P"
        steps.append(_Step(kind, _AXES[e.kind[1]], _Lin(float(e.const), xc, zq), e.joint))
    return SerialModel(tuple(steps), tuple(types), variables, Cm, off)
