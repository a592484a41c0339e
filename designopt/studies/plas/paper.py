"""Seed 004's printed closed forms and numbers (numpy, float64), for the tests and
docs/plas.md. Nothing here is used by the objective: the study computes everything on the
kernel chains of ``mechanism`` and these forms check them.

Symbols as printed: C_i = cos θ_i, S_i = sin θ_i, C23 = cos(θ2 + θ3); angles in rad,
lengths in mm. In the master's printed forms the seed writes a2 for the master's a2'.
"""

from __future__ import annotations

import numpy as np

# §3.4 and §4.1: the design and the numbers to reproduce
A2, A3, D5, A2P, D6 = 50.0, 15.0, 30.0, 138.0, 60.0
REPRODUCE = {
    # joint: (master rotation deg, slave rotation deg, tip travel mm) (Fig. 20-22)
    2: (30.0, 62.5, 103.6),
    3: (30.0, 40.0, 31.4),  # "about 40 degrees"
    4: (30.0, 60.0, 31.4),
}
TIP_ERRORS = {30.0: 8.5, 60.0: 4.46}  # θ3 (deg) → error (mm) of Fig. 23-24
COUNTERBALANCE = {"r": 9.0, "M": 240.5, "L": 18.8, "l": 3.4, "theta_deg": 25.0}  # cm, g
COUNTERBALANCE_MASS = 460.0  # g, "about 460 g"

TABLE6 = {
    1: "On / Off switch",
    2: "(C23(d6 C4) + a2' C2) / (C23(a3 + d5 C4) + a2 C2)",
    3: "(d6 C4) / (a3 + d5 C4)",
    4: "d6 / d5",
    5: "1",
    6: "1",
}


def _cs(t):
    return np.cos(t), np.sin(t)


def eq5(t2, t3, t4, t5, a2=A2P, d6=D6, as_printed: bool = False) -> np.ndarray:
    """Eq. (5): the master's ⁰T₆ (…, 4, 4) from its u, v, w, p columns.

    As printed, the S2·C3 terms of u_y, v_y and p_y carry the wrong sign: the printed
    matrix is not a rotation (RᵀR ≠ I) and p ≠ a2(C2, S2, 0) + d6·w although w is the
    tool axis. ``as_printed=False`` (default) flips those three signs, which makes eq. (5)
    agree with eq. (9) (the same chain written in frame 2, ``eq9_frame2``) and with the
    reconstructed Table 3; ``as_printed=True`` gives the text verbatim.
    """
    C2, S2 = _cs(t2)
    C3, S3 = _cs(t3)
    C4, S4 = _cs(t4)
    C5, S5 = _cs(t5)
    sg = 1.0 if as_printed else -1.0  # sign of the S2·C3 terms in the y row
    u = [(S2 * C4 + C2 * C3 * S4) * S5 - C2 * S3 * C5,
         -(C2 * C4 + sg * S2 * C3 * S4) * S5 - S2 * S3 * C5,
         S3 * S4 * S5 + C3 * C5]  # fmt: skip
    v = [(S2 * C4 + C2 * C3 * S4) * C5 + C2 * S3 * S5,
         -(C2 * C4 + sg * S2 * C3 * S4) * C5 + S2 * S3 * S5,
         S3 * S4 * C5 - C3 * S5]  # fmt: skip
    w = [C2 * C3 * C4 - S2 * S4, S2 * C3 * C4 + C2 * S4, S3 * C4]
    p = [a2 * C2 - d6 * (S2 * S4 - C2 * C3 * C4),
         a2 * S2 + d6 * (C2 * S4 - sg * S2 * C3 * C4),
         d6 * S3 * C4]  # fmt: skip
    shape = np.broadcast(t2, t3, t4, t5).shape
    T = np.zeros((*shape, 4, 4))
    for j, col in enumerate((u, v, w, p)):
        for i in range(3):
            T[..., i, j] = col[i]
    T[..., 3, 3] = 1.0
    return T


def eq9_frame2(t3, t4, t5, a2=A2P, d6=D6) -> np.ndarray:
    """Eq. (9), right-hand side: ²T_E = ²T₃³T₄⁴T₅⁵T_E (…, 4, 4) of the master (frame 2 is
    the base frame turned by θ2)."""
    C3, S3 = _cs(t3)
    C4, S4 = _cs(t4)
    C5, S5 = _cs(t5)
    rows = [
        [C3 * S4 * S5 - S3 * C5, S3 * S5 - C3 * S4 * C5, C3 * C4, a2 + d6 * C3 * C4],
        [-C4 * S5, -C4 * C5, S4, d6 * S4],
        [C3 * C5 + S3 * S4 * S5, S3 * S4 * C5 - C3 * S5, S3 * C4, d6 * S3 * C4],
    ]
    shape = np.broadcast(t3, t4, t5).shape
    T = np.zeros((*shape, 4, 4))
    for i in range(3):
        for j in range(4):
            T[..., i, j] = rows[i][j]
    T[..., 3, 3] = 1.0
    return T


def eq18_j1(t2, t3, t4, a2=A2P, d6=D6) -> np.ndarray:
    """Eq. (18): the master's J1 (…, 3, 6) over (d1', θ2, θ3, θ4, θ5, d6') as printed
    (its p_y row is the derivative of the printed, sign-slipped p_y of eq. 5)."""
    C2, S2 = _cs(t2)
    C3, S3 = _cs(t3)
    C4, S4 = _cs(t4)
    z = np.zeros(np.broadcast(t2, t3, t4).shape)
    rows = [
        [z, -a2 * S2 - d6 * (C2 * S4 + S2 * C3 * C4), -d6 * C2 * S3 * C4,
         -d6 * (S2 * C4 + C2 * C3 * S4), z, z],
        [z, a2 * C2 + d6 * (-S2 * S4 - C2 * C3 * C4), d6 * S2 * S3 * C4,
         d6 * (C2 * C4 + S2 * C3 * S4), z, z],
        [z + 1, z, d6 * C3 * C4, -d6 * S3 * S4, z, z + 1],
    ]  # fmt: skip
    return np.stack([np.stack(r, -1) for r in rows], -2)


def eq22_slave(t2, t3, t4, a2=A2, a3=A3, d5=D5) -> np.ndarray:
    """Eq. (22): the reduced slave's tip position (…, 3)."""
    C2, S2 = _cs(t2)
    C3, S3 = _cs(t3)
    C4, S4 = _cs(t4)
    px = a3 * (C2 * C3 - S2 * S3) + a2 * C2 + d5 * C4 * (C2 * C3 - S2 * S3)
    py = a3 * (C2 * S3 + S2 * C3) + a2 * S2 + d5 * C4 * (C2 * S3 + S2 * C3)
    return np.stack(np.broadcast_arrays(px, py, d5 * S4), -1)


def master_reduced(t2, t3, t4, a2p=A2P, d6=D6) -> np.ndarray:
    """The reduced master's tip position printed after Table 5 (…, 3)."""
    C2, S2 = _cs(t2)
    C3, S3 = _cs(t3)
    C4, S4 = _cs(t4)
    px = a2p * C2 + d6 * C4 * (C2 * C3 - S2 * S3)
    py = a2p * S2 + d6 * C4 * (C2 * S3 + S2 * C3)
    return np.stack(np.broadcast_arrays(px, py, d6 * S4), -1)


def eq25_slave_velocity(t, rates, a2=A2, a3=A3, d5=D5) -> np.ndarray:
    """Eq. (25): (v_x, v_y, v_z) of the reduced slave for angles t (…, 3) and joint
    rates (…, 3) of (θ2, θ3, θ4)."""
    t2, t3, t4 = t[..., 0], t[..., 1], t[..., 2]
    r2, r3, r4 = rates[..., 0], rates[..., 1], rates[..., 2]
    S2, C2 = np.sin(t2), np.cos(t2)
    S23, C23 = np.sin(t2 + t3), np.cos(t2 + t3)
    S4, C4 = np.sin(t4), np.cos(t4)
    B = a3 + d5 * C4
    vx = (-S23 * B - a2 * S2) * r2 + (-S23 * B) * r3 + (-d5 * S4 * C23) * r4
    vy = (C23 * B + a2 * C2) * r2 + (C23 * B) * r3 + (-d5 * S4 * S23) * r4
    vz = (d5 * C4) * r4
    return np.stack([vx, vy, vz], -1)


def eq26_master_velocity(t, rates, a2p=A2P, d6=D6) -> np.ndarray:
    """Eq. (26): (v_x, v_y, v_z) of the reduced master."""
    t2, t3, t4 = t[..., 0], t[..., 1], t[..., 2]
    r2, r3, r4 = rates[..., 0], rates[..., 1], rates[..., 2]
    S2, C2 = np.sin(t2), np.cos(t2)
    S23, C23 = np.sin(t2 + t3), np.cos(t2 + t3)
    S4, C4 = np.sin(t4), np.cos(t4)
    A = d6 * C4
    vx = (-S23 * A - a2p * S2) * r2 + (-S23 * A) * r3 + (-d6 * S4 * C23) * r4
    vy = (C23 * A + a2p * C2) * r2 + (C23 * A) * r3 + (-d6 * S4 * S23) * r4
    vz = (d6 * C4) * r4
    return np.stack([vx, vy, vz], -1)


def eq28_factors(t2, t3, t4, a2=A2, a3=A3, d5=D5, a2p=A2P, d6=D6):
    """Eq. (28) / Table 6: (k2, k3, k4), θ'_slave = k θ'_master."""
    C2, C23, C4 = np.cos(t2), np.cos(t2 + t3), np.cos(t4)
    k2 = (C23 * (d6 * C4) + a2p * C2) / (C23 * (a3 + d5 * C4) + a2 * C2)
    k3 = (d6 * C4) / (a3 + d5 * C4)
    k4 = np.broadcast_to(d6 / d5, np.shape(k2))
    return k2, k3, k4


def eq29_error(t2, t3, t4, a2=A2, a3=A3, d5=D5, a2p=A2P, d6=D6):
    """Eq. (29): the v_x error per unit master joint-2 rate (mm/rad), as printed:
    (S23(d6C4) + a2'S2) − k2 (S23(a3 + d5C4) + a2S2)."""
    S2, S23 = np.sin(t2), np.sin(t2 + t3)
    C4 = np.cos(t4)
    k2 = eq28_factors(t2, t3, t4, a2, a3, d5, a2p, d6)[0]
    return (S23 * (d6 * C4) + a2p * S2) - k2 * (S23 * (a3 + d5 * C4) + a2 * S2)


def eq1_counterbalance(M=240.5, L=18.8, r=9.0, l=3.4, theta_deg=25.0) -> float:  # noqa: E741
    """§2.1.2 eq. (1): m = M(L cos θ − r sin θ)/(r sin θ + l cos θ)."""
    t = np.deg2rad(theta_deg)
    return M * (L * np.cos(t) - r * np.sin(t)) / (r * np.sin(t) + l * np.cos(t))


# ------------------------------------------------------------------ §4.1 experiments


def single_joint_motion(joint: int, deg: float = 30.0, n: int = 2001):
    """Fig. 20-22: master joint ``joint`` (2, 3, 4) from 0 to ``deg``, the others at 0;
    the slave joint follows θ'_s = k θ'_m with eq. (28) evaluated along the way.
    Returns (slave rotation deg, master tip path mm, slave tip path mm)."""
    t = np.linspace(0.0, np.deg2rad(deg), n)
    zero = np.zeros_like(t)
    tm = [zero, zero, zero]
    tm[joint - 2] = t
    k = eq28_factors(*tm)[joint - 2]
    ts = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(t))])
    ss = [zero, zero, zero]
    ss[joint - 2] = ts
    pm = master_reduced(*tm)
    ps = eq22_slave(*ss)
    path = lambda p: float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))  # noqa: E731
    return float(np.rad2deg(ts[-1])), path(pm), path(ps)


def tip_error_readings(theta3_deg: float, deg: float = 30.0, n: int = 4001) -> dict[str, float]:
    """Fig. 23-24: master joint 2 from 0 to ``deg`` with joint 3 held at ``theta3_deg``
    (joint 4 at 0). Every reading of "the error" the text allows, in mm:

    slave joint 3 at the same angle as the master's ("same") or mapped by k3 ("mapped");
    slave joint 2 driven by a constant k2 taken at the start ("k2 const") or by eq. (28)
    along the way at the master's angles ("k2 master") or at the slave's ("k2 slave");
    error as the end-point distance of the two tip displacements ("end"), the largest
    such distance along the way ("max"), the difference of the path lengths ("path"),
    of the chord lengths ("chord"), and the integral of eq. (29) over the motion
    ("eq29", the v_x error integrated over the master's joint-2 rotation).
    """
    t3 = np.deg2rad(theta3_deg)
    tm = np.linspace(0.0, np.deg2rad(deg), n)
    h = tm[1] - tm[0]
    out: dict[str, float] = {}
    for s3_name, t3s in (("same", t3), ("mapped", eq28_factors(0.0, t3, 0.0)[1] * t3)):
        runs = {}
        runs["k2 const"] = eq28_factors(0.0, t3, 0.0)[0] * tm
        k = eq28_factors(tm, t3, 0.0)[0]
        runs["k2 master"] = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * h)])
        ys = [0.0]
        for _ in range(n - 1):  # RK4 of θ2s' = k2(θ2s, θ3s)
            y = ys[-1]
            f = lambda y, t3s=t3s: eq28_factors(y, t3s, 0.0)[0]  # noqa: E731
            a = f(y)
            b = f(y + h / 2 * a)
            c = f(y + h / 2 * b)
            d = f(y + h * c)
            ys.append(y + h / 6 * (a + 2 * b + 2 * c + d))
        runs["k2 slave"] = np.array(ys)
        pm = master_reduced(tm, t3, 0.0)
        for rname, t2s in runs.items():
            ps = eq22_slave(t2s, t3s, 0.0)
            dm, ds = pm - pm[0], ps - ps[0]
            e = np.linalg.norm(dm - ds, axis=1)
            lm = np.sum(np.linalg.norm(np.diff(pm, axis=0), axis=1))
            ls = np.sum(np.linalg.norm(np.diff(ps, axis=0), axis=1))
            tag = f"{s3_name}, {rname}"
            out[f"{tag}: end"] = float(e[-1])
            out[f"{tag}: max"] = float(e.max())
            out[f"{tag}: path"] = float(abs(lm - ls))
            out[f"{tag}: chord"] = float(abs(np.linalg.norm(dm[-1]) - np.linalg.norm(ds[-1])))
    err = eq29_error(tm, t3, 0.0)
    out["eq29"] = float(abs(np.sum(0.5 * (err[1:] + err[:-1]) * h)))
    return out
