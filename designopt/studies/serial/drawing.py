"""The serial chain drawn (docs/figures.md, "The robot"): which design, which pose, which
targets. The drawing itself is generic (``designopt.figures.robot``, the report's
``designopt.figures.html.robot``); here the chain's ``SerialModel.joint_frames`` gives the
joint origins, axes and tip frame, and a URDF chain's visuals are placed by
``designopt.kinematics.meshes``.

- The **home pose** (:func:`home`): each joint at 0 where its limits allow it (the pose
  the DH table or the URDF is written in), else at the middle of its limits.
- **Representative targets** of a task (:func:`representatives`): among the reached
  targets, the best-conditioned (largest 1/k at the final design's solution), the
  worst-conditioned and the median one; the report's slider goes through the 1/k
  quantiles 0, 10, 25, 50, 75, 90 and 100 %.
- The **original robot** of a URDF chain: the file's own numbers in every ``set`` field
  (:func:`original_arm`), beside the design at the same pose.
- Link radius: ``study.collision.radius`` where the config has one, else
  ``designopt.figures.robot.THICKNESS`` × the arm's length. Meshes are drawn as the file
  gives them, never stretched: a link whose origin numbers are design variables keeps
  its mesh, moved with its frame (the figure says which links).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.figures.robot import Arm, Cone, Scene, Targets
from designopt.numerics import montecarlo as mc
from designopt.studies.serial import setup
from designopt.studies.serial.mechanism import (  # noqa: F401 (re-exported)
    Mechanism,
    home,
    joint_names,
    joint_values,
)
from designopt.studies.serial.settings import ROWS, SerialSettings, UrdfChain, length_unit

REPRESENTATIVE = (("worst-conditioned", "#9467bd"), ("median", "#1f77b4"),
                  ("best-conditioned", "#2ca02c"))  # fmt: skip
"""The representative targets of a task figure, and their arms' colours."""
QUANTILES = (0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0)
"""1/k quantiles (among reached targets) of the report's slider."""
FIGURE_TRIANGLES = 5000
"""Mesh triangles per robot in a static figure (matplotlib sorts every one)."""


@jax.jit
def _identity(x):
    return x


_JF = jax.jit(lambda m, X, q: m.joint_frames(X, q), static_argnums=0)


def joint_frames(mech: Mechanism, X: np.ndarray, Q: np.ndarray, model: Any = None):
    """(origins (M, C, n+1, 3), axes (M, C, n, 3), tip rotations (M, C, 3, 3)) as NumPy
    for kernel designs X (M, P) and joint values Q (C, n): one jitted call per shape."""
    m = mech.model if model is None else model
    dt = mc.out_dtype()
    X = np.atleast_2d(np.asarray(X, dt))
    Q = np.atleast_2d(np.asarray(Q, dt))
    return tuple(np.asarray(a, np.float64) for a in _JF(m, X, Q))


def full(mech: Mechanism, x: Any) -> np.ndarray:
    """(M, P) kernel parameters of designs x (M, variables) in the config's units."""
    x = np.atleast_2d(np.asarray(x, np.float64))
    fixed = np.broadcast_to(mech.fixed, (x.shape[0], len(mech.fixed)))
    return np.concatenate([x, fixed], -1) * mech.scale


def obstacles_and_ports(s: SerialSettings, design: Any = None) -> dict[str, Any]:
    """A scene's ``obstacles`` (``study.collision``'s, then ``task.body_wall``),
    ``ports`` (each arm's, or ``task.port``, and the camera's) and ``scopes`` (``task.camera``'s incision
    point, or its shaft's far end, and its tip) as :class:`Scene` keywords. ``design``: the variables (a mapping, or a
    sequence in ``s.variables`` order; None: the middle of the box) that place a port
    named by design variables (on ``task.body_wall`` when there is one)."""
    from designopt.studies.serial.reach import ports_of

    obs = list(s.collision.obstacles) if s.collision is not None else []
    if s.task is not None and s.task.body_wall is not None:
        obs.append(s.task.body_wall)  # drawn as the skin (``figures.robot.is_wall``)
    if design is not None and not hasattr(design, "keys"):
        design = dict(zip(s.variables, np.asarray(design, np.float64).tolist(), strict=True))
    scopes = []
    if s.task is not None and s.task.camera is not None:  # the endoscope: incision, tip
        from designopt.studies.serial.placement import camera_at

        mid = {k: (float(lo) + float(hi)) / 2 for k, (lo, hi) in s.variables.items()}
        d = mid if design is None else design
        c = camera_at(s, np.asarray([[d[k] for k in s.variables]], np.float64))[0]
        sh = s.task.camera.shaft
        ax = c[3:] - c[:3]
        n = float(np.linalg.norm(ax))
        if sh is not None and n > 0:  # the rigid shaft, out of the patient
            scopes = [(c[3:] - sh.length * ax / n, c[3:])]
        else:
            scopes = [(c[:3], c[3:])]
    cam = [np.asarray(c[:3])] if scopes else []  # the camera's incision: a port too
    if s.task is None or s.ports()[0] is None:
        return {"obstacles": obs, "ports": cam, "scopes": scopes}
    ports = [ports_of(s, k, [design])[0] for k in range(len(s.ports()))]
    ports = [np.asarray(p) for p in dict.fromkeys(tuple(p.tolist()) for p in ports)]
    return {"obstacles": obs, "ports": ports + cam, "scopes": scopes}


ARM_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf",
               "#bcbd22")  # fmt: skip
"""The arms' colours in a multi-arm drawing."""


def combined(sol: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A multi-arm solution (arrays with a leading arm axis) as one per-target solution:
    ``success`` where every arm reaches the target, ``inv_k`` the arms' mean 1/k there
    (0 elsewhere), the targets; the joints of arm 0."""
    ok = np.all(np.asarray(sol["success"], bool), 0)
    ik = np.where(ok, np.mean(np.asarray(sol["inv_k"], np.float64), 0), 0.0)
    return {"target_p": np.asarray(sol["target_p"]), "success": ok, "inv_k": ik,
            "q": np.asarray(sol["q"])[0]}  # fmt: skip


def _closest(sa: np.ndarray, sb: np.ndarray, n: int = 24) -> tuple[np.ndarray, np.ndarray, float]:
    """Approximately the closest points of two arms' link segments (La, 2, 3), (Lb, 2, 3)
    (each link sampled at n points) and their centre-line distance."""
    t = np.linspace(0, 1, n)[:, None]
    pa = (sa[:, None, 0] + t[None] * (sa[:, None, 1] - sa[:, None, 0])).reshape(-1, 3)
    pb = (sb[:, None, 0] + t[None] * (sb[:, None, 1] - sb[:, None, 0])).reshape(-1, 3)
    d = np.linalg.norm(pa[:, None] - pb[None], axis=-1)
    i, j = np.unravel_index(np.argmin(d), d.shape)
    return pa[i], pb[j], float(d[i, j])


def _tuples(s: SerialSettings, mech: Mechanism, sol: Mapping[str, np.ndarray],
            keys: Mapping[str, Any]) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, list, Any]:  # fmt: skip
    """The tuples of targets of a multi-arm solution as ``arms_free`` draws them (arm
    k's tuple j is target π_k(j)): (π_k per arm, the tuples where every arm reaches its
    own target (N,) bool, the least gap between two arms per tuple, each arm's capsules
    per tuple (N, L, 2, 3) in the world, the collision geometry)."""

    from designopt.studies.serial import bodies

    A = len(s.arms)  # type: ignore[arg-type]
    ok = np.asarray(sol["success"], bool)
    N = ok.shape[1]
    from designopt.studies.serial import taskindex

    grp = taskindex.groups(s)  # the tuples pair targets of one group
    g = bodies.geometry(setup.groups(s)[0].settings, setup.groups(s)[0].mech)
    segs = np.asarray(sol["segments"])  # (A, N, L, 2, 3) world
    P, G = _perms_gaps(keys["samples"], segs, _arm_radii(s), N, A, g is not None,
                       None if grp is None else tuple(int(v) for v in grp))  # fmt: skip
    perm = list(np.asarray(P))
    both = np.all(np.stack([ok[k][perm[k]] for k in range(A)]), 0)
    seg = [segs[k][perm[k]] for k in range(A)]  # (N, L, 2, 3) world
    gap = np.asarray(G, np.float64) if both.any() else np.full(N, np.inf)
    return perm, both, gap, seg, g


@functools.partial(jax.jit, static_argnums=(3, 4, 5, 6))
def _perms_gaps(key: Any, segs: Any, r: Any, N: int, A: int, gaps: bool,
                grp: tuple[int, int] | None) -> tuple[jax.Array, jax.Array]:  # fmt: skip
    """:func:`_tuples`' arrays in one program (one compiled call, not dozens of eager
    operations): the arms' permutations (A, N) as ``arms_free`` draws them (the targets'
    groups ``grp``: ``taskindex.groups``), and each tuple's least gap between two arms
    (N,) (+inf without ``gaps``: no collision geometry)."""
    from designopt.kinematics.collision import arms_clearance
    from designopt.studies.serial import taskindex

    perm = taskindex.perms(jax.random.fold_in(key, 2), N, taskindex.labels(N, grp), A)
    seg = [segs[k][perm[k]] for k in range(A)]
    gap = jnp.full((N,), jnp.inf, segs.dtype)
    if gaps:
        for a in range(A):
            for b in range(a + 1, A):
                gap = jnp.minimum(gap, arms_clearance(seg[a], r[a], seg[b], r[b]))
    return jnp.stack(perm), gap


def _arm_radii(s: SerialSettings) -> Any:
    """Each arm's capsule radii (A, L) as a JAX array (``setup.radii``: an arm of fewer
    capsules repeats its last, as its archived capsules do)."""
    import jax.numpy as jnp

    return setup.radii(s, jnp.float64 if jax.config.jax_enable_x64 else jnp.float32)


def _ordered(both: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """The tuples every arm reaches, by their gap (the tightest first)."""
    idx = np.flatnonzero(both)
    return idx[np.argsort(gap[idx], kind="stable")]


def length_text(v: float, unit: str) -> str:
    """A length for a label: ``7.9 mm`` under 0.1 m (unit ``m``), else ``0.123 m``."""
    if unit == "m" and abs(v) < 0.1:
        return f"{v * 1000:.3g} mm"
    return f"{v:.3g} {unit}"


@dataclass
class TupleStats:
    """The tuples of targets of a multi-arm solution (one target per arm, as
    ``arms_free`` draws them): ``n`` tuples, ``reached`` of them every arm reaches,
    ``colliding`` (bool (n,)) those reached whose arms come closer than the margin,
    the least gap between two arms per tuple (``gap``, inf where not reached by every
    arm), and the reached tuples' numbers by gap (``order``, the tightest first)."""

    n: int
    reached: int
    colliding: np.ndarray
    gap: np.ndarray
    order: np.ndarray

    @property
    def median(self) -> int:
        """The reached tuple of median gap (the lower middle of their gap order)."""
        return int(self.order[(len(self.order) - 1) // 2])

    @property
    def tightest(self) -> int:
        return int(self.order[0])

    @property
    def loosest(self) -> int:
        return int(self.order[-1])

    def count(self) -> str:
        """``7 of 128 tuples collide``."""
        k = int(self.colliding.sum())
        return f"{k} of {self.n} tuples collide{'s' * (k == 1)}"

    def text(self) -> str:
        """``7 of 128 tuples collide (of the 120 every arm reaches); the tightest: tuple
        101``."""
        head = self.count()
        head += f" (of the {self.reached} every arm reaches)" if self.reached < self.n else ""
        return head + f"; the tightest: tuple {self.tightest}" if len(self.order) else head


def tuple_stats(s: SerialSettings, mech: Mechanism, sol: Mapping[str, np.ndarray],
                keys: Mapping[str, Any]) -> TupleStats:  # fmt: skip
    """:class:`TupleStats` of a multi-arm solution ``sol`` (``blocks.solution``)."""
    _, both, gap, _, g = _tuples(s, mech, sol, keys)
    return _stats(both, gap, g)


def _stats(both: np.ndarray, gap: np.ndarray, g: Any) -> TupleStats:
    margin = g.margin if g is not None else 0.0
    gap = np.where(both, gap, np.inf)
    return TupleStats(len(both), int(both.sum()), both & (gap < margin), gap,
                      _ordered(both, gap))  # fmt: skip


def arm_tuples(s: SerialSettings, mech: Mechanism, x: Any, sol: Mapping[str, np.ndarray],
               keys: Mapping[str, Any], budget: int | None = FIGURE_TRIANGLES,
               counted: bool = True,
               ) -> list[tuple[str, list[Arm], list[tuple[np.ndarray, np.ndarray]], list]]:  # fmt: skip
    """Tuples of targets of a multi-arm run (one per arm, drawn as ``arms_free`` draws
    them: arm k's tuple j is target π_k(j)) where every arm reaches its own, in this
    order: the **median** (median gap between the arms: what a surgeon sees first), the
    **tightest** (smallest gap: colliding if any collides) and the loosest; repeats
    dropped. Each: (label, the arms at their solutions with their bases and colours,
    colliding pairs (their closest points), the arms' joints). With ``counted``, the
    median's label says how many tuples collide (:meth:`TupleStats.count`)."""

    from designopt.kinematics.collision import arms_clearance

    A = len(s.arms)  # type: ignore[arg-type]
    perm, both, gap, seg, g = _tuples(s, mech, sol, keys)
    if not both.any():
        return []
    st = _stats(both, gap, g)
    picks = dict.fromkeys([st.median, st.tightest, st.loosest])
    names = {st.loosest: "loosest", st.tightest: "tightest", st.median: "median"}
    r = _arm_radii(s)
    u = length_unit(s)
    out = []
    for j in picks:
        qs = [np.asarray(sol["q"])[k][perm[k][j]] for k in range(A)]
        arms_j = study_arms(s, mech, x, np.stack(qs), budget=budget)
        pairs, coll = [], set()
        for a in range(A):
            for b in range(a + 1, A):
                d = float(np.asarray(arms_clearance(seg[a][j], r[a], seg[b][j], r[b])))
                if d < g.margin:  # type: ignore[union-attr]
                    pa, pb, _ = _closest(seg[a][j], seg[b][j])
                    pairs.append((pa, pb))
                    coll |= {a, b}
        arms_j = [_with_base(a, a.base, colliding=k in coll) for k, a in enumerate(arms_j)]
        what = f"arms {sorted(coll)} collide" if coll else f"gap {length_text(gap[j], u)}"
        label = f"{names[j]} tuple {j}: {what}"
        if names[j] == "median" and counted:
            label += f" ({st.count()})"
        out.append((label, arms_j, pairs, qs))
    return out


def representative(s: SerialSettings, mech: Mechanism, sol: Mapping[str, np.ndarray] | None,
                   keys: Mapping[str, Any] | None = None,
                   ) -> tuple[str, np.ndarray, list[np.ndarray]]:  # fmt: skip
    """One representative tuple of targets of a design's solution ``sol`` (one target
    per arm): (its label, the arms' joints (A, n), the targets). One arm: the reached
    target of median 1/k (:func:`representatives`). Several arms: among the tuples every
    arm reaches (as ``arms_free`` draws them, :func:`arm_tuples`), the one of median gap
    between the arms. The home pose (no target) where nothing is reached or there is no
    task (``sol`` None)."""
    q0 = setup.homes(s)
    A = len(q0)
    if sol is None:
        return "the home pose", q0, []
    p = np.asarray(sol["target_p"], np.float64)
    if s.arms is None:
        reps = representatives(sol)
        if not reps:
            return "no target reached: the home pose", q0, []
        i = reps[1][1]
        return (f"the target of median 1/k (target {i}, 1/k = {float(sol['inv_k'][i]):.3g})",
                np.asarray(sol["q"])[i][None], [p[i]])  # fmt: skip
    perm, both, gap, _, _ = _tuples(s, mech, sol, keys)
    if not both.any():
        return "no tuple every arm reaches: the home pose", q0, []
    order = _ordered(both, gap)
    j = int(order[(len(order) - 1) // 2])
    idx = [int(perm[k][j]) for k in range(A)]
    Q = np.stack([np.asarray(sol["q"])[k][i] for k, i in enumerate(idx)])
    inst = s.instrument_arms()  # (the camera arm's target is the scope's: not starred)
    return (f"the tuple of median gap between the arms (tuple {j}: targets "
            f"{[idx[k] for k in inst]}, gap {length_text(gap[j], length_unit(s))})", Q,
            [p[idx[k]] for k in inst])  # fmt: skip


def design_pose(s: SerialSettings, mech: Mechanism, x: Any,
                keys: Mapping[str, Any]) -> tuple[str, np.ndarray, list[np.ndarray]]:  # fmt: skip
    """Where one design is drawn on its own (a front's designs): under a task, at one
    representative tuple of targets of its IK solution on the run's targets
    (``blocks.solution``, :func:`representative`); else at the home pose. (label,
    joints (A, n), targets)."""
    return design_poses(s, keys, mech, np.asarray(x, np.float64)[None])[0]


def design_poses(s: SerialSettings, keys: Mapping[str, Any], mech: Mechanism, X: Any
                 ) -> list[tuple[str, np.ndarray, list[np.ndarray]]]:  # fmt: skip
    """:func:`design_pose` of several designs X (P, D) (variables; config units) on the
    targets of ``s`` and ``keys`` (a front's: ``figures.front_stream``, where its values
    were measured), their IK solutions in one batch (``blocks.solutions``: P designs
    share the block program's calls, one design's values do not depend on the others';
    within a run, the front's re-scoring computed them already)."""
    from designopt.studies.serial import blocks

    X = np.atleast_2d(np.asarray(X, np.float64))
    if s.indices.measure != "task" or not len(X):
        return [representative(s, mech, None, keys) for _ in X]
    per = blocks.solutions(s, X, keys)
    return [representative(s, mech, blocks.design_of(s, per, i), keys) for i in range(len(X))]


def base_poses(s: SerialSettings, mech: Mechanism, x: Any) -> list[np.ndarray | None]:
    """Each arm's base pose in the world (4 × 4) for design ``x`` (variables; config
    units), from ``study.arms`` (``bodies.base_frames``); [None] (the world) without."""
    if s.arms is None:
        return [None]

    from designopt.studies.serial import bodies

    p = bodies.base_params(s, mech, mc.out_dtype())
    Rb, tb = bodies.base_frames(p, np.asarray(full(mech, x), np.float64), np)
    out: list[np.ndarray | None] = []
    for k in range(len(s.arms)):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Rb[k, 0], tb[k, 0]
        out.append(T)
    return out


def study_arms(s: SerialSettings, mech: Mechanism, x: Any, Q: np.ndarray, *, label: str = "",
               color: str = "#1f77b4", budget: int | None = FIGURE_TRIANGLES, model: Any = None,
               design: Any = "x") -> list[Arm]:  # fmt: skip
    """Every arm of the study for one design ``x`` (variables; config units), each at
    its base in the world (:func:`base_poses`): arm k at joints Q[k] (Q (A, n); (n,):
    every arm at the same joints). One arm (``label``, ``color``) without ``study.arms``;
    else ``<label>: arm k`` (``arm k``) in :data:`ARM_COLOURS`. ``model``, ``design``:
    as :func:`arms` ("original" and None: the original robot of each arm's URDF chain). A
    set-up of several robots draws each arm with its own (``setup.arm_view``), its
    joints the first of Q[k] (the rest NaN)."""
    T = base_poses(s, mech, x)
    Q = np.asarray(Q, np.float64)
    Q = np.broadcast_to(Q, (len(T), Q.shape[-1])) if Q.ndim == 1 else Q
    ms = setup.mechanisms(s)
    out = []
    for k, Tk in enumerate(T):
        who = f"arm {k}" + (", camera" if k == s.camera_arm() else "") + \
            (f" ({setup.robot_name(s, k)})" if setup.mixed(s) else "")  # fmt: skip
        lab = label if Tk is None else (f"{label}: {who}" if label else who)
        col = color if Tk is None else ARM_COLOURS[k % len(ARM_COLOURS)]
        sk, mk = (s, mech) if not setup.mixed(s) else (setup.arm_view(s, k), ms[k])
        mod = model if model != "original" else original_model(sk, mk)
        a = arms(sk, mk, [x], Q[k][None, : mk.n], labels=[lab], colors=[col], budget=budget,
                 model=mod, design=design)[0][0]  # fmt: skip
        out.append(a if Tk is None else _with_base(a, Tk))
    return out


def _with_base(a: Arm, T: Any, colliding: bool | None = None) -> Arm:
    from dataclasses import replace

    return replace(a, base=T, colliding=a.colliding if colliding is None else colliding)


def radius(s: SerialSettings) -> float | None:
    """``study.collision.radius`` where the config has one (the capsules a collision
    check uses), else None (the drawing's default thickness)."""
    r = getattr(getattr(s, "collision", None), "radius", None)
    return float(r) if isinstance(r, int | float) and not isinstance(r, bool) and r > 0 else None


def set_values(s: SerialSettings, design: Mapping[str, float]) -> dict[tuple[str, str], float]:
    """{(joint, field): number (rad, file lengths)} of a URDF chain's ``set`` fields."""
    from designopt.studies.serial.mechanism import set_values as sv

    return sv(s, dict(design))


def _types(s: SerialSettings) -> str:
    return "".join(j.type for j in s.chain.joints)


def meshes(s: SerialSettings, design: Mapping[str, float] | None, q: np.ndarray,
           budget: int | None):  # fmt: skip
    """A URDF chain's visuals at joints q (``designopt.kinematics.meshes.Placed``) for
    ``design`` (None: the file's own numbers); None for a DH chain or no budget."""
    if not isinstance(s.chain, UrdfChain) or not budget:
        return None
    from designopt.kinematics import meshes as km

    values = {} if design is None else set_values(s, design)
    return km.placed(s.chain.imported, s.chain.urdf_text or "", s.chain.urdf_path, values, q,
                     budget)  # fmt: skip


def arms(s: SerialSettings, mech: Mechanism, x: Any, Q: np.ndarray, *, labels: Sequence[str] = (),
         colors: Sequence[str] = (), budget: int | None = FIGURE_TRIANGLES,
         model: Any = None, design: Any = "x") -> list[list[Arm]]:  # fmt: skip
    """Arms [design][pose] of designs x (M, variables; config units) at joints Q (C, n):
    ``labels`` and ``colors`` per pose (cycled), URDF meshes within ``budget`` triangles
    per robot. ``model`` and ``design`` None: the original robot of a URDF chain."""
    X = full(mech, x)
    Q = np.atleast_2d(np.asarray(Q, np.float64))
    P, A, R = joint_frames(mech, X, Q, model)
    r = radius(s)
    out = []
    for i in range(X.shape[0]):
        row = []
        dsg = None if design is None else dict(zip(s.variables, np.atleast_2d(x)[i], strict=True))
        for c in range(Q.shape[0]):
            pm = meshes(s, dsg, Q[c], budget)
            row.append(Arm(P[i, c], A[i, c], R[i, c], radius=r,
                           color=colors[c % len(colors)] if colors else "#1f77b4",
                           label=labels[c % len(labels)] if labels else "",
                           meshes=[] if pm is None else [(V, F) for _, V, F in pm.meshes],
                           types=_types(s)))  # fmt: skip
        out.append(row)
    return out


def original_model(s: SerialSettings, mech: Mechanism):
    """The kernel model of a URDF chain with the file's own numbers in every ``set``
    field (the design columns unused)."""
    from designopt.kinematics import urdf

    return urdf.lower(s.chain.imported, {}, mech.names)  # type: ignore[union-attr]


def original_arm(s: SerialSettings, mech: Mechanism, q: np.ndarray, label: str = "original (the URDF's numbers)",
                 color: str = "#4c72b0", budget: int | None = FIGURE_TRIANGLES) -> Arm:  # fmt: skip
    """The URDF's own robot at joints q."""
    x0 = [0.5 * (lo + hi) for lo, hi in s.variables.values()]  # unused by the model
    return arms(
        s,
        mech,
        [x0],
        q,
        labels=[label],
        colors=[color],
        budget=budget,
        model=original_model(s, mech),
        design=None,
    )[0][0]


def original_arms(s: SerialSettings, mech: Mechanism, x: Any, q: np.ndarray,
                  label: str = "original (the URDF's numbers)", color: str = "#4c72b0",
                  budget: int | None = FIGURE_TRIANGLES) -> list[Arm]:  # fmt: skip
    """The URDF's own robot at joints q, every arm at its base for design ``x`` (the
    bases are design numbers, not the file's)."""
    return study_arms(s, mech, x, q, label=label, color=color, budget=budget,
                      model="original", design=None)  # fmt: skip


def changes(s: SerialSettings, design: Mapping[str, float]) -> list[tuple[str, float, float, str]]:
    """Every ``set`` field of a URDF chain as (key, the file's number, the design's,
    unit): lengths in m, angles in degrees."""
    from designopt.kinematics import meshes as km

    imp = s.chain.imported  # type: ignore[union-attr]
    out = []
    for (jn, f), v in set_values(s, design).items():
        o = km.original(imp, jn, f)
        ang = f in ("roll", "pitch", "yaw")
        out.append((f"{jn}.origin.{f}", math.degrees(o) if ang else o,
                    math.degrees(v) if ang else v, "deg" if ang else "m"))  # fmt: skip
    return out


def changes_text(s: SerialSettings, design: Mapping[str, float], width: int = 60) -> str:
    """The changed ``set`` numbers, one a line (``key: file → design unit``), and how
    many are unchanged."""
    ch = changes(s, design)
    lines = [f"{k}: {a:.4g} → {b:.4g} {u}" for k, a, b, u in ch
             if abs(a - b) > 1e-12 * max(1.0, abs(b))]  # fmt: skip
    same = len(ch) - len(lines)
    if same:
        lines.append(f"{same} other set number{'s' * (same > 1)} as in the file")
    return "\n".join(lines) if lines else "every set number as in the file"


def meshes_note(s: SerialSettings, design: Mapping[str, float] | None, q: np.ndarray,
                budget: int | None = FIGURE_TRIANGLES) -> str:  # fmt: skip
    """What the drawing says of a URDF chain's meshes: how many triangles, which links
    keep their unscaled mesh though an origin they span changed, missing files."""
    pm = meshes(s, design, q, budget)
    if pm is None:
        return ""
    if not pm.meshes and not pm.missing:
        return "no visual meshes in the URDF"
    out = [
        f"meshes: {pm.triangles} triangles"
        + (f" (decimated from {pm.full})" if pm.triangles < pm.full else "")
    ]
    if pm.moved:
        out.append("unscaled (their origins are design numbers): " + ", ".join(pm.moved))
    if pm.missing:
        out.append(f"{len(pm.missing)} mesh file(s) not found, e.g. {pm.missing[0]}")
    return "; ".join(out)


# ------------------------------------------------------------------------ tasks


def representatives(sol: Mapping[str, np.ndarray]) -> list[tuple[str, int]]:
    """[(name, target index)] of :data:`REPRESENTATIVE` among the reached targets (the
    median: the lower middle of their 1/k order); [] when none is reached."""
    ok = np.asarray(sol["success"], bool)
    idx = np.flatnonzero(ok)
    if not idx.size:
        return []
    order = idx[np.argsort(np.asarray(sol["inv_k"])[idx], kind="stable")]
    picks = (order[0], order[(len(order) - 1) // 2], order[-1])
    return [(name, int(i)) for (name, _), i in zip(REPRESENTATIVE, picks, strict=True)]


def slider_targets(sol: Mapping[str, np.ndarray]) -> list[tuple[str, int]]:
    """[(label, target index)] at the 1/k :data:`QUANTILES` among the reached targets."""
    ok = np.asarray(sol["success"], bool)
    idx = np.flatnonzero(ok)
    if not idx.size:
        return []
    order = idx[np.argsort(np.asarray(sol["inv_k"])[idx], kind="stable")]
    out, seen = [], set()
    for qt in QUANTILES:
        i = int(order[int(round(qt * (len(order) - 1)))])
        if i not in seen:
            seen.add(i)
            name = {0.0: "worst", 0.5: "median", 1.0: "best"}.get(qt, f"{qt:.0%}")
            out.append((f"{name} 1/k (target {i})", i))
    return out


def cone(s: SerialSettings, p: np.ndarray, size: float) -> Cone | None:
    """The task's tool-axis cone drawn from the targets' centroid, ``size`` long."""
    ta = s.task.tool_axis if s.task is not None else None
    if ta is None:
        return None
    return Cone(np.asarray(p, np.float64).mean(0), np.asarray(ta.direction, np.float64),
                float(ta.cone), size)  # fmt: skip


def task_scene(s: SerialSettings, mech: Mechanism, x: Any, sol: Mapping[str, np.ndarray],
               budget: int | None = FIGURE_TRIANGLES) -> Scene:  # fmt: skip
    """The task drawn: region, tool-axis cone, targets by 1/k, the final design ``x`` at
    its representative targets' solutions (stars: those targets)."""
    reps = representatives(sol)
    cols = dict(REPRESENTATIVE)
    p = np.asarray(sol["target_p"], np.float64)
    ik = np.asarray(sol["inv_k"])
    out = []
    if reps:
        Q = np.stack([sol["q"][i] for _, i in reps])
        labels = [f"{n}: 1/k = {ik[i]:.3g}" for n, i in reps]
        out = arms(s, mech, [x], Q, labels=labels, colors=[cols[n] for n, _ in reps],
                   budget=budget)[0]  # fmt: skip
    ext = float(np.ptp(p, 0).max()) if len(p) > 1 else 0.0
    size = 0.4 * ext if ext > 0 else 0.1 * max((a.length() for a in out), default=1.0)
    return Scene(arms=out, region=s.task.region if s.task is not None else None,
                 cone=cone(s, p, size),
                 targets=Targets(p, ik, np.asarray(sol["success"], bool), "1/k"),
                 marks=[(p[i], cols[n]) for n, i in reps], **obstacles_and_ports(s, x))  # fmt: skip


def arms_scene(s: SerialSettings, mech: Mechanism, x: Any, sol: Mapping[str, np.ndarray],
               keys: Mapping[str, Any], budget: int | None = FIGURE_TRIANGLES) -> Scene:  # fmt: skip
    """A multi-arm task drawn: region, obstacles, ports, the targets by the arms' mean 1/k
    where every arm reaches them, and every arm at the median tuple of targets (median
    gap between the arms, :func:`arm_tuples`), colliding pairs marked; the title names
    the tuple and how many tuples collide, and which is the tightest."""
    c = combined(sol)
    p = c["target_p"]
    tup = arm_tuples(s, mech, x, sol, keys, budget, counted=False)
    arms_, pairs, title = ([], [], "") if not tup else (tup[0][1], tup[0][2], tup[0][0])
    if tup:
        title += "\n" + tuple_stats(s, mech, sol, keys).text()
    return Scene(arms=arms_, title=title, region=s.task.region if s.task is not None else None,
                 targets=Targets(p, c["inv_k"], c["success"], "1/k"), collisions=pairs,
                 **obstacles_and_ports(s, x))  # fmt: skip


def home_q(s: SerialSettings, mech: Mechanism) -> np.ndarray:
    """The home pose to draw: the chain's (n,), or with arms of several robots every
    arm's own (A, n_max) (``setup.homes``)."""
    return setup.homes(s) if setup.mixed(s) else home(mech)


def hover(s: SerialSettings, label: str, q: np.ndarray, inv_k: float | None = None,
          arm: int | None = None) -> str:
    """The report's hover text of an arm (``arm``: its index, whose robot names the
    joints): its label, 1/k, joint values."""
    from designopt.figures.html import esc

    if arm is not None and setup.mixed(s):
        s = setup.arm_view(s, arm)
        q = np.asarray(q)[: len(s.chain.joints)]
    rows = ", ".join(ROWS[r] for r in s.indices.rows())
    k = "" if inv_k is None else f"<br>1/k ({s.indices.norm}-norm; rows {rows}) = {inv_k:.4g}"
    return (f"<b>{esc(label)}</b>{k}<br>" + esc(joint_values(s, q, "<br>")).replace("&lt;br&gt;", "<br>")
            + "<extra></extra>")  # fmt: skip


def placement_text(s: SerialSettings, g: Mapping[str, Any]) -> str:
    """Each arm's port (the incision point) and base in numbers, from a final group or
    one front design's values (``Study.placement``); "" without them."""
    u = length_unit(s)

    def vec(v: Any) -> str:
        return "(" + ", ".join(f"{float(c) + 0.0:.4f}" for c in v) + ")"

    ports = np.asarray(g["ports"], np.float64).reshape(-1, 3) if "ports" in g else None
    bases = np.asarray(g["bases"], np.float64).reshape(-1, 6) if "bases" in g else None
    if ports is None and bases is None:
        return ""
    out = []
    for k in range(len(ports) if ports is not None else len(bases)):  # type: ignore[arg-type]
        part = [f"port {vec(ports[k])} {u}"] if ports is not None else []
        if bases is not None:
            part.append(f"base {vec(bases[k][:3])} {u}, rpy {vec(bases[k][3:])} deg")
        who = f"arm {k}" + (" (holds the camera)" if k == s.camera_arm() else "")
        out.append(f"{who}: " + ", ".join(part))
    return "; ".join(out)
