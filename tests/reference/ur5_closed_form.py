"""The best free IK solution at a target, in closed form (issue #52's oracle).

Pure NumPy, sharing no code with ``designopt``'s kinematics:

- :func:`read_chain` reads a URDF's joints (``xml.etree``) from ``base`` to ``tip`` and
  :class:`Chain` is its forward kinematics as the product of the joints' transforms
  (origin xyz, rpy = Rz·Ry·Rx, a rotation about the joint's axis), with the position
  Jacobian of the tip, column i = a_i × (p − o_i) (base frame).
- :class:`UR5` reads the UR5's standard DH table off that chain (d1, a2, a3, d4, d5, d6:
  the URDF's joint origins, checked to have the UR's structure) and enumerates the up to
  8 analytic branches of the flange pose (shoulder left/right × wrist up/down × elbow
  up/down; Hawkins, "Analytic inverse kinematics for the Universal Robots UR-5/UR-10
  arms", 2013, as in ``ur_kinematics``), every branch closed form. The DH base is the
  URDF's ``base_link`` turned by π about z (the UR's ``base`` frame), the DH flange the
  URDF's ``tool0``; the joint angles are the URDF's, with no offsets. (The URDF writes
  π/2 as 1.57079632679: the DH FK and the URDF's differ by ~1e-11 m, which
  :func:`check_dh` measures.)
- :func:`best_axis`: a target's tip position p and tool axis z with the roll ψ about z
  free. Every branch on a grid of ψ (``n_grid`` points over 2π), then a golden-section
  refinement of each local maximum of each branch's free 1/k (the bracket its two grid
  neighbours; a maximum on the boundary of the free set is approached from inside).
  Every value it keeps is that of an enumerated solution that exists, lies within the
  joint limits (a joint whose range spans 2π takes q ± 2π) and is free (``free``:
  a predicate on joints, e.g. the study's collision check, :func:`study_free`).
- :func:`best_planar3r`: the planar 3R arm (DH a = l1, l2, l3, position targets in its
  plane): the redundant angle φ of the last link swept the same way, 2 elbow branches
  at each φ.

1/k is σ_min/σ_max of the tip's position Jacobian (3 × n; 2 × 3 for the planar arm), from
the eigenvalues of J Jᵀ.

:func:`study_free` is the one link to ``designopt``: the collision check of a serial
study's config (``taskindex.chunk_values``' ``accept``: the capsules of
``bodies.geometry``, the obstacles, the self-collision pairs, the port's exemption and
the anatomy inside it, ``bodies.obstacle_and_self`` ≥ the margin) on a batch of joint
vectors, and the port's insertion range. The enumeration does not use it.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
UR5_URDF = ROOT / "configs/robots/ur5/ur5_instrument.urdf"
TWO_PI = 2.0 * math.pi
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0

# ------------------------------------------------------------------ rotations


def rot_x(a: Any) -> np.ndarray:
    a = np.asarray(a, np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)  # fmt: skip


def rot_y(a: Any) -> np.ndarray:
    a = np.asarray(a, np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)  # fmt: skip


def rot_z(a: Any) -> np.ndarray:
    a = np.asarray(a, np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)  # fmt: skip


def rpy(r: float, p: float, y: float) -> np.ndarray:
    """URDF's fixed-axis roll-pitch-yaw: Rz(y) Ry(p) Rx(r)."""
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def axis_angle(axis: np.ndarray, q: Any) -> np.ndarray:
    """Rodrigues: rotations (..., 3, 3) by angles q (...) about the unit ``axis``."""
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    q = np.asarray(q, np.float64)[..., None, None]
    return np.eye(3) + np.sin(q) * K + (1 - np.cos(q)) * (K @ K)


def homogeneous(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    R, p = np.asarray(R, np.float64), np.asarray(p, np.float64)
    shape = np.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    T = np.zeros((*shape, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    R, p = T[..., :3, :3], T[..., :3, 3]
    Rt = np.swapaxes(R, -1, -2)
    return homogeneous(Rt, -np.einsum("...ij,...j->...i", Rt, p))


# ------------------------------------------------------------------ the URDF chain


@dataclass(frozen=True)
class Joint:
    name: str
    type: str  # revolute, continuous, prismatic, fixed
    xyz: np.ndarray
    rpy: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float

    @property
    def origin(self) -> np.ndarray:
        return homogeneous(rpy(*self.rpy), self.xyz)


def read_chain(path: str | Path, base: str, tip: str,
               origin: dict[str, float] | None = None) -> list[Joint]:  # fmt: skip
    """The joints from link ``base`` to link ``tip`` of a URDF file, in order.

    ``origin``: {"joint.origin.x|y|z|roll|pitch|yaw": value} replaces those numbers (a
    study's ``chain.set`` at a design)."""
    root = ET.parse(path).getroot()
    by_child = {}
    for j in root.findall("joint"):
        by_child[j.find("child").get("link")] = j  # type: ignore[union-attr]
    path_: list[Joint] = []
    link = tip
    while link != base:
        if link not in by_child:
            raise ValueError(f"{path}: no path from {base} to {tip}")
        j = by_child[link]
        o = j.find("origin")
        xyz = np.array([float(v) for v in (o.get("xyz", "0 0 0") if o is not None
                                           else "0 0 0").split()])  # fmt: skip
        r = np.array([float(v) for v in (o.get("rpy", "0 0 0") if o is not None
                                         else "0 0 0").split()])  # fmt: skip
        a = j.find("axis")
        axis = np.array([float(v) for v in (a.get("xyz") if a is not None else "1 0 0").split()])
        lim = j.find("limit")
        lo = float(lim.get("lower", "-inf")) if lim is not None else -math.inf
        hi = float(lim.get("upper", "inf")) if lim is not None else math.inf
        if j.get("type") == "continuous":
            lo, hi = -math.inf, math.inf
        path_.append(Joint(j.get("name"), j.get("type"), xyz, r, axis, lo, hi))  # type: ignore[arg-type]
        link = j.find("parent").get("link")  # type: ignore[union-attr]
    path_.reverse()
    fields = {"x": ("xyz", 0), "y": ("xyz", 1), "z": ("xyz", 2), "roll": ("rpy", 0),
              "pitch": ("rpy", 1), "yaw": ("rpy", 2)}  # fmt: skip
    for key, v in (origin or {}).items():
        name, _, fld = key.split(".")
        k = [i for i, jj in enumerate(path_) if jj.name == name]
        if len(k) != 1:
            raise ValueError(f"{key}: no joint '{name}' on the path")
        arr, i = fields[fld]
        new = getattr(path_[k[0]], arr).copy()
        new[i] = float(v)
        path_[k[0]] = Joint(**{**path_[k[0]].__dict__, arr: new})
    return path_


class Chain:
    """Forward kinematics of a URDF path: T = Π origin_j · Rot(axis_j, q_j)."""

    def __init__(self, joints: list[Joint]) -> None:
        bad = [j.name for j in joints if j.type == "prismatic"]
        if bad:
            raise ValueError(f"prismatic joints are not supported here: {bad}")
        self.joints = joints
        self.active = [j for j in joints if j.type in ("revolute", "continuous")]
        self.n = len(self.active)
        self.lower = np.array([j.lower for j in self.active])
        self.upper = np.array([j.upper for j in self.active])

    def frames(self, q: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(tip pose (..., 4, 4), each active joint's origin (..., n, 3) and unit axis
        (..., n, 3)), base frame. (R and p kept apart, a joint's rotation by Rodrigues'
        formula R·Rot(a, q) = R + sin q·(R K) + (1 − cos q)·(R K²): products with
        constant matrices only.)"""
        q = np.asarray(q, np.float64)
        R = np.broadcast_to(np.eye(3), (*q.shape[:-1], 3, 3)).copy()
        p = np.zeros((*q.shape[:-1], 3))

        o, a = [], []
        k = 0
        for j in self.joints:
            p = p + np.sum(R * j.xyz, -1)
            R = R @ rpy(*j.rpy)
            if j.type == "fixed":
                continue
            ax = j.axis / np.linalg.norm(j.axis)
            K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
            o.append(p)
            a.append(np.sum(R * ax, -1))
            s, c = np.sin(q[..., k])[..., None, None], np.cos(q[..., k])[..., None, None]
            R = R + s * (R @ K) + (1 - c) * (R @ (K @ K))
            k += 1
        return homogeneous(R, p), np.stack(o, -2), np.stack(a, -2)

    def fk(self, q: Any) -> np.ndarray:
        return self.frames(q)[0]

    def position_jacobian(self, q: Any) -> np.ndarray:
        """(..., 3, n): the tip's linear velocity per joint rate, base frame."""
        T, o, a = self.frames(q)
        return np.swapaxes(np.cross(a, T[..., None, :3, 3] - o), -1, -2)


def inv_k(J: np.ndarray) -> np.ndarray:
    """σ_min/σ_max of matrices (..., r, n) with r ≤ n (the eigenvalues of J Jᵀ)."""
    lam = np.linalg.eigvalsh(J @ np.swapaxes(J, -1, -2))
    return np.sqrt(np.clip(lam[..., 0], 0.0, None) / lam[..., -1])


def wrap(q: Any) -> np.ndarray:
    """Angles into (−π, π]."""
    q = np.asarray(q, np.float64)
    return q - TWO_PI * np.ceil((q - math.pi) / TWO_PI)


def in_limits(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, tol: float = 1e-12
              ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(q moved by multiples of 2π to its smallest value ≥ lower, whether every joint
    then lies within [lower, upper]) for revolute joints (..., n)."""
    lo = np.where(np.isfinite(lower), lower, -math.pi)
    k = np.ceil((lo - tol - q) / TWO_PI)
    qq = q + TWO_PI * k
    return qq, np.all(qq <= upper + tol, -1)


# ------------------------------------------------------------------ the UR5


def _dh(theta: Any, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH: Rz(θ) Tz(d) Tx(a) Rx(α), (..., 4, 4)."""
    theta = np.asarray(theta, np.float64)
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    T = np.zeros((*theta.shape, 4, 4))
    T[..., 0, 0], T[..., 0, 1], T[..., 0, 2], T[..., 0, 3] = ct, -st * ca, st * sa, a * ct
    T[..., 1, 0], T[..., 1, 1], T[..., 1, 2], T[..., 1, 3] = st, ct * ca, -ct * sa, a * st
    T[..., 2, 1], T[..., 2, 2], T[..., 2, 3] = sa, ca, d
    T[..., 3, 3] = 1.0
    return T


UR5_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
              "wrist_2_joint", "wrist_3_joint")  # fmt: skip
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)


class UR5:
    """The UR5 of ``ur5_instrument.urdf`` (or a copy with another instrument): the DH
    table read off the URDF path, the instrument's fixed transform from the flange
    (``tool0``), and every IK branch in closed form."""

    def __init__(self, urdf: str | Path = UR5_URDF, origin: dict[str, float] | None = None,
                 tip: str = "instrument_tip") -> None:  # fmt: skip
        """``origin``: URDF numbers replaced (:func:`read_chain`; radians), e.g. the upper
        arm ``elbow_joint.origin.z``, the forearm ``wrist_1_joint.origin.z``, the
        instrument's tilt ``instrument_joint.origin.roll``."""
        joints = read_chain(urdf, "base_link", tip, origin)
        self.chain = Chain(joints)
        names = [j.name for j in self.chain.active]
        if tuple(names) != UR5_JOINTS:
            raise ValueError(f"not a UR5 path: {names}")
        J = {j.name: j for j in joints}
        h = math.pi / 2
        expect = {  # joint: (xyz entries that must be 0, rpy, axis)
            "shoulder_pan_joint": ((0, 1), (0, 0, 0), (0, 0, 1)),
            "shoulder_lift_joint": ((0, 2), (0, h, 0), (0, 1, 0)),
            "elbow_joint": ((0,), (0, 0, 0), (0, 1, 0)),
            "wrist_1_joint": ((0, 1), (0, h, 0), (0, 1, 0)),
            "wrist_2_joint": ((0, 2), (0, 0, 0), (0, 0, 1)),
            "wrist_3_joint": ((0, 1), (0, 0, 0), (0, 1, 0)),
        }
        for n, (zero, r, ax) in expect.items():
            j = J[n]
            ok = (np.allclose(j.xyz[list(zero)], 0, atol=1e-12) and np.allclose(j.rpy, r, atol=1e-10)
                  and np.allclose(j.axis, ax, atol=0))  # fmt: skip
            if not ok:
                raise ValueError(f"{n}: not the UR5's joint structure")
        self.d1 = J["shoulder_pan_joint"].xyz[2]
        self.a2 = -J["elbow_joint"].xyz[2]
        self.a3 = -J["wrist_1_joint"].xyz[2]
        self.d4 = (J["shoulder_lift_joint"].xyz[1] + J["elbow_joint"].xyz[1]
                   + J["wrist_2_joint"].xyz[1])  # fmt: skip
        self.d5 = J["wrist_3_joint"].xyz[2]
        k = [j.name for j in joints].index("wrist_3_joint")
        fixed = joints[k + 1 :]
        if not fixed or fixed[0].type != "fixed" or not np.allclose(fixed[0].rpy, (-h, 0, 0), atol=1e-10) \
                or not np.allclose(fixed[0].xyz[[0, 2]], 0, atol=1e-12):  # fmt: skip
            raise ValueError("the joint after wrist_3 is not the UR5's tool0")
        self.d6 = fixed[0].xyz[1]
        self.flange_tip = np.eye(4)  # tool0 → tip
        for j in fixed[1:]:
            if j.type != "fixed":
                raise ValueError(f"{j.name}: a moving joint after the flange")
            self.flange_tip = self.flange_tip @ j.origin
        self.base_dh = homogeneous(rot_z(math.pi), np.zeros(3))  # base_link → DH base
        self.dh = ((self.d1, 0.0), (0.0, self.a2), (0.0, self.a3), (self.d4, 0.0),
                   (self.d5, 0.0), (self.d6, 0.0))  # (d, a) per row  # fmt: skip

    # --- forward kinematics
    def dh_fk(self, q: Any) -> np.ndarray:
        """The flange (``tool0``) in the DH base frame, (..., 4, 4)."""
        q = np.asarray(q, np.float64)
        T = np.broadcast_to(np.eye(4), (*q.shape[:-1], 4, 4))
        for i, ((d, a), al) in enumerate(zip(self.dh, ALPHA, strict=True)):
            T = T @ _dh(q[..., i], d, a, al)
        return T

    def tip_fk_dh(self, q: Any) -> np.ndarray:
        """The tip in ``base_link`` by the DH table (``base_dh`` · DH · instrument)."""
        return self.base_dh @ self.dh_fk(q) @ self.flange_tip

    # --- inverse kinematics
    def ik_flange(self, T06: np.ndarray, tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
        """Every branch of the flange poses T06 (..., 4, 4) (DH base frame): joints
        (..., 8, 6) in (−π, π] and whether each branch exists (..., 8). Branch
        b = 4·i + 2·j + k: shoulder i, wrist j, elbow k."""
        d1, a2, a3, d4, d5, d6 = self.d1, self.a2, self.a3, self.d4, self.d5, self.d6
        T06 = np.asarray(T06, np.float64)
        sh = T06.shape[:-2]
        n, s, a, p = (T06[..., :3, i] for i in range(4))
        p5 = p - d6 * a
        r = np.hypot(p5[..., 0], p5[..., 1])
        ok1 = r >= abs(d4) - tol
        c = np.clip(d4 / np.maximum(r, 1e-300), -1.0, 1.0)
        phi = np.arctan2(p5[..., 1], p5[..., 0])
        q = np.zeros((*sh, 8, 6))
        ok = np.zeros((*sh, 8), bool)
        for i, sg1 in enumerate((1.0, -1.0)):
            q1 = phi + sg1 * np.arccos(c) + math.pi / 2
            s1, c1 = np.sin(q1), np.cos(q1)
            c5 = (p[..., 0] * s1 - p[..., 1] * c1 - d4) / d6
            ok5 = np.abs(c5) <= 1.0 + tol
            c5 = np.clip(c5, -1.0, 1.0)
            for j, sg5 in enumerate((1.0, -1.0)):
                q5 = sg5 * np.arccos(c5)
                s5 = np.sin(q5)
                sgn = np.where(s5 >= 0, 1.0, -1.0)
                # q6 (``ur_kinematics``); where sin q5 = 0 the wrist is singular and any
                # q6 will do: 0
                y6 = -sgn * (s[..., 0] * s1 - s[..., 1] * c1)
                x6 = sgn * (n[..., 0] * s1 - n[..., 1] * c1)
                q6 = np.where(np.abs(s5) > 1e-12, np.arctan2(y6, x6), 0.0)
                T01 = _dh(q1, d1, 0.0, ALPHA[0])
                T45 = _dh(q5, d5, 0.0, ALPHA[4])
                T56 = _dh(q6, d6, 0.0, ALPHA[5])
                T14 = inverse(T01) @ T06 @ inverse(T45 @ T56)
                x, y = T14[..., 0, 3], T14[..., 1, 3]
                c3 = (x * x + y * y - a2 * a2 - a3 * a3) / (2 * a2 * a3)
                ok3 = np.abs(c3) <= 1.0 + tol
                c3 = np.clip(c3, -1.0, 1.0)
                for k, sg3 in enumerate((1.0, -1.0)):
                    q3 = sg3 * np.arccos(c3)
                    q2 = np.arctan2(y, x) - np.arctan2(a3 * np.sin(q3), a2 + a3 * np.cos(q3))
                    q4 = np.arctan2(T14[..., 1, 0], T14[..., 0, 0]) - q2 - q3
                    b = 4 * i + 2 * j + k
                    q[..., b, :] = wrap(np.stack([q1, q2, q3, q4, q5, q6], -1))
                    ok[..., b] = ok1 & ok5 & ok3
        return q, ok

    def ik_tip(self, T_tip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every branch of tip poses (..., 4, 4) in ``base_link``."""
        T06 = inverse(self.base_dh) @ T_tip @ inverse(self.flange_tip)
        return self.ik_flange(T06)

    def inv_k(self, q: Any) -> np.ndarray:
        """1/k of the tip's 3 × 6 position Jacobian (URDF chain)."""
        return inv_k(self.chain.position_jacobian(q))

    @property
    def roll_free(self) -> bool:
        """Whether the tip's position depends on joint 6 (the instrument leaves its axis):
        otherwise the roll about the tool axis moves q6 alone, and neither 1/k nor the
        links' capsules depend on it."""
        tip = self.flange_tip[:3, 3]
        # tool0's z is joint 6's axis: the tip on it has x = y = 0, and a tool axis
        # along it has z = ±e_z
        return not (np.allclose(tip[:2], 0, atol=1e-12)
                    and np.allclose(np.abs(self.flange_tip[2, 2]), 1, atol=1e-12))  # fmt: skip


def check_dh(ur: UR5, n: int = 256, seed: int = 0) -> float:
    """The largest distance (m, and rotation entries) between the URDF chain's tip pose
    and the DH table's at random joints."""
    q = np.random.default_rng(seed).uniform(-math.pi, math.pi, (n, 6))
    return float(np.max(np.abs(ur.chain.fk(q) - ur.tip_fk_dh(q))))


def axis_frames(p: np.ndarray, z: np.ndarray, psi: Any) -> np.ndarray:
    """Tip poses (..., 4, 4): position p (..., 3), z axis z (..., 3) (unit), and the roll
    ψ (...) about z: x = cos ψ e1 + sin ψ e2 with e1 ⊥ z fixed by z, e2 = z × e1."""
    z = np.asarray(z, np.float64)
    ref = np.where((np.abs(z[..., :1]) < 0.9), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    e1 = np.cross(ref, z)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(z, e1)
    psi = np.asarray(psi, np.float64)[..., None]
    x = np.cos(psi) * e1 + np.sin(psi) * e2
    y = np.cross(z, x)
    return homogeneous(
        np.stack([x, y, np.broadcast_to(z, x.shape)], -1), np.broadcast_to(p, x.shape)
    )


# ------------------------------------------------------------------ 1-D maximisation


def golden_max(f: Callable[[np.ndarray], np.ndarray], a: np.ndarray, b: np.ndarray,
               iters: int = 48) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Golden-section search for the maxima of K functions at once: ``f`` maps K
    abscissae (K,) to values (K,) (−inf where infeasible), on brackets [a, b] (K,). Returns
    (the best value evaluated, where) for each; every returned value is one ``f``
    gave. The bracket shrinks by 0.618 a step: 48 steps take 0.0175 rad to ~1e-12."""
    a, b = np.asarray(a, np.float64).copy(), np.asarray(b, np.float64).copy()
    c = b - GOLDEN * (b - a)
    d = a + GOLDEN * (b - a)
    fc, fd = f(c), f(d)
    best = np.where(fd > fc, fd, fc)
    arg = np.where(fd > fc, d, c)
    for _ in range(iters):
        left = fc >= fd  # the maximum is in [a, d]: c becomes the new d; else in [c, b]
        a, b = np.where(left, a, c), np.where(left, d, b)
        x = np.where(left, b - GOLDEN * (b - a), a + GOLDEN * (b - a))
        fx = f(x)
        c, d, fc, fd = (np.where(left, x, d), np.where(left, c, x),
                        np.where(left, fx, fd), np.where(left, fc, fx))  # fmt: skip
        better = fx > best
        best, arg = np.where(better, fx, best), np.where(better, x, arg)
    return best, arg


def _local_maxima(F: np.ndarray) -> np.ndarray:
    """Profiles F (..., G), the last axis cyclic → the grid points that are local maxima
    (finite, ≥ both neighbours)."""
    left, right = np.roll(F, 1, -1), np.roll(F, -1, -1)
    return np.isfinite(F) & (F >= left) & (F >= right)


def refine(fn: Callable[[np.ndarray, np.ndarray], np.ndarray], F: np.ndarray,
           grid: np.ndarray, near: float = 0.05, iters: int = 48
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The best of profiles F (N, B, G) (N targets, B branches, −inf where there is no
    free solution) on a cyclic ``grid`` (G,), refined: every local maximum within
    ``near`` of its target's best grid value is searched by :func:`golden_max` between
    its grid neighbours, ``fn(rows (K, 2) (target, branch), abscissae (K,))`` giving the
    values. Returns (best (N,), its branch (N,), its abscissa (N,)); −inf where no free
    solution was found."""
    N, B, G = F.shape
    flat = F.reshape(N, B * G)
    j = np.argmax(flat, -1)
    best = flat[np.arange(N), j]
    br, arg = j // G, grid[j % G]
    cand = _local_maxima(F) & (F >= (best - near)[:, None, None])
    t, b, g = np.nonzero(cand)
    if len(t):
        h = grid[1] - grid[0]
        rows = np.stack([t, b], -1)
        val, x = golden_max(lambda xs: fn(rows, xs), grid[g] - h, grid[g] + h, iters)
        up = val > best[t]
        for tt, bb, vv, xx in zip(t[up], b[up], val[up], x[up], strict=True):
            if vv > best[tt]:
                best[tt], br[tt], arg[tt] = vv, bb, xx
    return best, br, arg


# ------------------------------------------------------------------ the UR5's best solution


Free = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""free(q (K, 6), target rows (K,)) → bool (K,): whether the joints are free at the target."""


def lazy_free(V: np.ndarray, check: Callable[[np.ndarray, np.ndarray], np.ndarray],
              near: float) -> np.ndarray:  # fmt: skip
    """Profiles V (N, ...) (−inf where no solution) with the points that are not free set
    to −inf, asking ``check(targets (K,), flat indices into V[t] (K,))`` → free (K,) only
    of the points that can matter: each target's points in descending V, until V falls
    more than ``near`` below the best free value found. (A point more than ``near`` below
    that cannot be the best nor a local maximum within ``near`` of it: whatever its
    freedom, its neighbours' test against it is decided.) Unasked points read −inf."""
    N = V.shape[0]
    flat = V.reshape(N, -1)
    M = flat.shape[1]
    order = np.argsort(-flat, 1, kind="stable")
    Vs = np.take_along_axis(flat, order, 1)
    free_s = np.zeros((N, M), bool)
    best = np.full(N, -np.inf)
    pos = np.zeros(N, np.int64)
    step = 8
    ar = np.arange(N)
    while True:
        head = Vs[ar, np.minimum(pos, M - 1)]
        act = (pos < M) & np.isfinite(head) & (head >= best - near)
        if not act.any():
            break
        t = np.nonzero(act)[0]
        j = pos[t, None] + np.arange(step)
        jj = np.minimum(j, M - 1)
        vv = Vs[t[:, None], jj]
        m = (j < M) & np.isfinite(vv) & (vv >= (best[t] - near)[:, None])
        tt = np.broadcast_to(t[:, None], j.shape)[m]
        kk, vsel = jj[m], vv[m]
        ok = check(tt, order[tt, kk])
        free_s[tt, kk] = ok
        np.maximum.at(best, tt[ok], vsel[ok])
        pos[t] += step
        step = min(2 * step, 512)
    out = np.full((N, M), -np.inf)
    np.put_along_axis(out, order, np.where(free_s, Vs, -np.inf), 1)
    return out.reshape(V.shape)


def best_axis(ur: UR5, p: np.ndarray, z: np.ndarray, free: Free | None = None,
              n_grid: int = 720, iters: int = 48, near: float = 0.05,
              reachable: np.ndarray | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """The best free 1/k at every target: tip positions p (N, 3), tool axes z (N, 3)
    (unit), the roll about z free. ``reachable`` (N,) bool: targets that count at all
    (e.g. within a port's insertion range; default all). Returns ``best`` (N,) (0 where
    no free solution exists), ``reached`` (N,) bool, ``q`` (N, 6) the best solution,
    ``psi`` (N,) its roll, ``branch`` (N,), ``n_branches`` (N,) the branches that exist
    (within the limits; free or not) at that roll, ``profile`` (N, 8, G) the grid's
    free values (−inf: none, or not asked, :func:`lazy_free`).

    A straight instrument (the tip on joint 6's axis, :attr:`UR5.roll_free` false) is
    solved at one roll: the roll then moves q6 alone."""
    p, z = np.asarray(p, np.float64), np.asarray(z, np.float64)
    N = len(p)
    reach = np.ones(N, bool) if reachable is None else np.asarray(reachable, bool)
    G = n_grid if ur.roll_free else 1
    grid = np.arange(G) * (TWO_PI / G) - math.pi

    def branches(rows: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q, ok = ur.ik_tip(axis_frames(p[rows], z[rows], psi))  # (K, 8, 6), (K, 8)
        q, lim = in_limits(q, ur.chain.lower, ur.chain.upper)
        return q, ok & lim & reach[rows, None]

    rows = np.repeat(np.arange(N), G)
    q, ok = branches(rows, np.tile(grid, N))
    V = np.full(ok.shape, -np.inf)
    V[ok] = ur.inv_k(q[ok])
    V = np.moveaxis(V.reshape(N, G, 8), 1, 2)  # (N, 8, G)
    qg = np.moveaxis(q.reshape(N, G, 8, 6), 1, 2)
    if free is not None:
        V = lazy_free(V, lambda t, k: free(qg[t, k // G, k % G], t), near)

    def fn(rb: np.ndarray, xs: np.ndarray) -> np.ndarray:
        qa, oka = branches(rb[:, 0], xs)
        ar = np.arange(len(rb))
        qb, okb = qa[ar, rb[:, 1]], oka[ar, rb[:, 1]]
        v = np.full(len(rb), -np.inf)
        v[okb] = ur.inv_k(qb[okb])
        if free is not None and okb.any():
            fr = np.zeros(len(rb), bool)
            fr[okb] = free(qb[okb], rb[okb, 0])
            v[~fr] = -np.inf
        return v

    if G > 1:
        best, br, psi = refine(fn, V, grid, near, iters)
    else:
        br = np.argmax(V[..., 0], -1)
        best, psi = V[np.arange(N), br, 0], np.full(N, grid[0])
    qa, oka = branches(np.arange(N), psi)
    got = np.isfinite(best)
    return {"best": np.where(got, best, 0.0), "reached": got, "q": qa[np.arange(N), br],
            "psi": psi, "branch": br, "n_branches": oka.sum(-1), "profile": V}  # fmt: skip


# ------------------------------------------------------------------ planar 3R


def planar3r_ik(p: np.ndarray, phi: Any, l: tuple[float, float, float]
                ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The planar 3R (DH a = l1, l2, l3, α = 0): both elbow branches for tip positions p
    (..., 2) with the last link at angle φ (...): joints (..., 2, 3) in (−π, π] and
    whether each exists (..., 2)."""
    l1, l2, l3 = l
    phi = np.asarray(phi, np.float64)
    w = p - l3 * np.stack([np.cos(phi), np.sin(phi)], -1)
    c2 = (np.sum(w * w, -1) - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    ok = np.abs(c2) <= 1.0
    c2 = np.clip(c2, -1.0, 1.0)
    qs = []
    for sg in (1.0, -1.0):
        q2 = sg * np.arccos(c2)
        q1 = np.arctan2(w[..., 1], w[..., 0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
        qs.append(wrap(np.stack([q1, q2, phi - q1 - q2], -1)))
    return np.stack(qs, -2), np.stack([ok, ok], -1)


def planar3r_fk(q: np.ndarray, l: tuple[float, float, float]) -> np.ndarray:
    a1, a12, a123 = q[..., 0], q[..., 0] + q[..., 1], q[..., 0] + q[..., 1] + q[..., 2]
    x = l[0] * np.cos(a1) + l[1] * np.cos(a12) + l[2] * np.cos(a123)
    y = l[0] * np.sin(a1) + l[1] * np.sin(a12) + l[2] * np.sin(a123)
    return np.stack([x, y], -1)


def planar3r_jacobian(q: np.ndarray, l: tuple[float, float, float]) -> np.ndarray:
    """(..., 2, 3): the tip's planar velocity per joint rate."""
    a = np.cumsum(q, -1)
    cx = np.asarray(l) * np.cos(a)
    cy = np.asarray(l) * np.sin(a)
    # d(tip)/dq_i = sum over links k >= i
    sx = np.flip(np.cumsum(np.flip(cx, -1), -1), -1)
    sy = np.flip(np.cumsum(np.flip(cy, -1), -1), -1)
    return np.stack([-sy, sx], -2)


def best_planar3r(p: np.ndarray, l: tuple[float, float, float], lower: np.ndarray | None = None,
                  upper: np.ndarray | None = None, n_grid: int = 720, iters: int = 48,
                  near: float = 0.05) -> dict[str, np.ndarray]:  # fmt: skip
    """The best 1/k of the 2 × 3 position Jacobian at planar targets p (N, 2) over the
    redundant angle φ and both elbow branches (joint limits ``lower``/``upper`` (3,) rad,
    default none). Returns ``best`` (N,) (0 where unreachable), ``reached``, ``q``
    (N, 3), ``phi``, ``branch``, ``profile`` (N, 2, G)."""
    p = np.asarray(p, np.float64)
    N = len(p)
    lo = np.full(3, -np.inf) if lower is None else np.asarray(lower, np.float64)
    hi = np.full(3, np.inf) if upper is None else np.asarray(upper, np.float64)

    def values(rows: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q, ok = planar3r_ik(p[rows], phi, l)  # (K, 2, 3), (K, 2)
        q, lim = in_limits(q, lo, hi)
        v = inv_k(planar3r_jacobian(q, l))
        return np.where(ok & lim, v, -np.inf), q

    grid = np.arange(n_grid) * (TWO_PI / n_grid) - math.pi
    t_all = np.repeat(np.arange(N), n_grid)
    F, _ = values(t_all, np.tile(grid, N))
    F = np.moveaxis(F.reshape(N, n_grid, 2), 1, 2)

    def fn(rows: np.ndarray, xs: np.ndarray) -> np.ndarray:
        return values(rows[:, 0], xs)[0][np.arange(len(rows)), rows[:, 1]]

    best, br, phi = refine(fn, F, grid, near, iters)
    _, q = values(np.arange(N), phi)
    got = np.isfinite(best)
    return {"best": np.where(got, best, 0.0), "reached": got, "q": q[np.arange(N), br],
            "phi": phi, "branch": br, "profile": F}  # fmt: skip


# ------------------------------------------------------------------ the study's collision check


_CLEARANCE: dict[str, Callable] = {}


def study_free(s: Any, x: dict[str, float], targets: np.ndarray) -> tuple[Free, np.ndarray, dict]:
    """The collision check and the port's insertion range of a one-arm serial study ``s``
    (a validated config's ``study``) at design ``x`` ({variable: value}, config units),
    for targets (N, 3): (free(q (K, n), target rows (K,)) → bool (K,), the targets
    within the insertion range (N,) bool, what it used: {"port", "insertion"}).

    ``free`` is what ``taskindex.chunk_values``' ``accept`` asks of a converged seed:
    the clearance of the design's capsules at q (``bodies.obstacle_and_self``: the
    obstacles, with the port's exemption and the anatomy inside the patient, and the
    self-collision pairs) at least the margin."""
    import jax
    import jax.numpy as jnp

    from designopt.studies.serial import bodies, taskindex
    from designopt.studies.serial.mechanism import build

    if s.arms is not None:
        raise ValueError("study_free: one arm only")
    dt = jnp.float64
    mech = build(s)
    geo = bodies.geometry(s, mech)
    sc_p = taskindex.scene_params(s, dt, mech)
    xv = np.array([float(x[k]) for k in s.variables])
    full = jnp.asarray(np.concatenate([xv, mech.fixed]) * mech.scale, dt)[None]  # (1, P)
    targets = np.asarray(targets, np.float64)
    has_port = s.ports()[0] is not None
    wall = None if s.task.body_wall is None else s.task.body_wall.shape
    port = np.asarray(bodies.port_points(sc_p, full, wall))[0, 0] if has_port else None
    ins = np.asarray(sc_p["scene_insertion"])[0]
    if port is not None:
        depth = np.linalg.norm(targets - port, axis=-1)
        inside = (depth >= ins[0]) & (depth <= ins[1]) & (depth > 0)
    else:
        inside = np.ones(len(targets), bool)
    info = {"port": port, "insertion": ins}
    if geo is None:
        return (lambda q, rows: np.ones(len(q), bool)), inside, info
    margin = float(sc_p["scene_geometry"]["margin"])
    key = s.model_dump_json()
    if key not in _CLEARANCE:  # one compiled program per study, any design and port
        obst, inner, gp = sc_p["scene_obstacles"], sc_p.get("scene_inside"), sc_p["scene_geometry"]

        @jax.jit
        def clearance(full: jax.Array, pa: jax.Array, q: jax.Array, pt: jax.Array) -> jax.Array:
            X = jnp.broadcast_to(full, (q.shape[0], full.shape[1]))
            seg = geo.items(mech.model, X, q)  # (K, L, 2, 3)
            if not has_port:
                return bodies.obstacle_and_self(geo, obst, seg, None, None, None, gp)
            zz = pt - pa
            zz = zz / jnp.maximum(jnp.linalg.norm(zz, axis=-1, keepdims=True), 1e-300)
            P = jnp.broadcast_to(pa, pt.shape)
            return bodies.obstacle_and_self(geo, obst, seg, P, zz, inner, gp)

        _CLEARANCE[key] = clearance
    clearance = _CLEARANCE[key]
    pa = jnp.asarray(np.zeros(3) if port is None else port, dt)

    def free(q: np.ndarray, rows: np.ndarray, chunk: int = 1024) -> np.ndarray:
        K = len(q)
        out = np.zeros(K, bool)
        # fixed shapes: one compiled program however many joints are asked
        for i in range(0, K, chunk):
            qq, pp = q[i : i + chunk], targets[rows[i : i + chunk]]
            m = len(qq)
            if m < chunk:
                qq = np.concatenate([qq, np.repeat(qq[-1:], chunk - m, 0)])
                pp = np.concatenate([pp, np.repeat(pp[-1:], chunk - m, 0)])
            c = np.asarray(clearance(full, pa, jnp.asarray(qq, dt), jnp.asarray(pp, dt)))[:m]
            out[i : i + m] = c >= margin
        free.calls += (K + chunk - 1) // chunk  # type: ignore[attr-defined]
        free.asked += K  # type: ignore[attr-defined]
        return out

    free.calls = free.asked = 0  # type: ignore[attr-defined]
    return free, inside, info


def study_ur5(s: Any, x: dict[str, float]) -> UR5:
    """The :class:`UR5` of a serial study's URDF chain at design ``x`` (config units): the
    study's ``chain.set`` applied, each entry a number or a variable's value (angles in
    degrees there, radians here)."""
    ch = s.chain
    over = {}
    for k, v in ch.set.items():
        val = float(x[v]) if isinstance(v, str) else float(v)
        over[k] = math.radians(val) if k.rsplit(".", 1)[-1] in ("roll", "pitch", "yaw") else val
    return UR5(Path(ch.urdf_path or ch.urdf), over, tip=ch.tip)
