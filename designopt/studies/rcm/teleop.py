"""Master-slave incremental mapping (seed 003 §4.1, eq. 33-34), replayed as one lax.scan.

At row k the master's tip increment Δm = m_k − m_{k−1} (zero while the clutch is held,
so the master can be repositioned without moving the slave) is rotated into the slave
frame and scaled by 1/s (s:1 master-to-slave, e.g. 2:1), added to the slave's commanded
tip (eq. 33), and solved by the arm's IK (eq. 30-32). A target outside the reachable set
is clamped: its joints are clipped to their ranges (a projection in joint space, not the
Euclidean nearest point), the commanded tip becomes FK of the clipped joints, and the row
is flagged with the distance it was moved.

Departure from eq. (33): the next increment is added to the *commanded* tip, not to the
tip measured from the encoders (r_T0 of eq. 34); with a servo lag the measured tip would
feed the lag back as a drift. The servo is modelled as a pure delay of ``delay_ms`` (the
paper measured 60-80 ms, §4.2.1): the achieved joints at row k are the commands of row
k − delay/dt. Tracking error = |commanded tip − achieved tip|.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from designopt.studies.rcm import mechanism as m

COLUMNS = ("t", "x", "y", "z", "clutch")


class Trajectory(NamedTuple):
    t: np.ndarray  # (N,) s
    master: np.ndarray  # (N, 3) mm
    clutch: np.ndarray  # (N,) bool


def read_csv(path: str | Path) -> Trajectory:
    """A master trajectory: a CSV with the header ``t,x,y,z,clutch`` (s, mm, 0/1), time
    strictly increasing. ValueError naming the file and line for anything else."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"trajectory '{p}': file not found")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"trajectory '{p}': not a UTF-8 text file (byte {e.start})") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise ValueError(f"trajectory '{p}': empty file; expected the header {','.join(COLUMNS)}")
    head = [h.strip() for h in rows[0]]
    if head != list(COLUMNS):
        raise ValueError(f"trajectory '{p}', line 1: header {head} is not {list(COLUMNS)}")
    vals = []
    for i, row in enumerate(rows[1:], start=2):
        if not row or all(not x.strip() for x in row):
            continue
        if len(row) != len(COLUMNS):
            raise ValueError(
                f"trajectory '{p}', line {i}: {len(row)} fields, expected {len(COLUMNS)}"
            )
        try:
            v = [float(x) for x in row]
        except ValueError:
            raise ValueError(f"trajectory '{p}', line {i}: not a number in {row}") from None
        if not np.all(np.isfinite(v)):
            raise ValueError(f"trajectory '{p}', line {i}: NaN or inf in {row}")
        if v[4] not in (0.0, 1.0):
            raise ValueError(f"trajectory '{p}', line {i}: clutch must be 0 or 1, got {row[4]}")
        if vals and not v[0] > vals[-1][0]:
            raise ValueError(f"trajectory '{p}', line {i}: time {v[0]} does not increase")
        vals.append(v)
    if len(vals) < 2:
        raise ValueError(f"trajectory '{p}': needs at least two samples, got {len(vals)}")
    a = np.asarray(vals)
    return Trajectory(a[:, 0], a[:, 1:4], a[:, 4] > 0.5)


def synthetic(rate_hz: float = 100.0) -> Trajectory:
    """The shipped example (configs/data/rcm_master_square.csv): the master traces a
    100 mm square (the 50 mm square of seed 003 §4.2.1 at 2:1) in 4 s per side, holds the
    clutch half-way along the third side to move back 60 mm, and finishes the square."""
    dt = 1.0 / rate_hz
    corners = np.array([[0, 0, 0], [100, 0, 0], [100, 100, 0], [0, 100, 0], [0, 0, 0]], float)
    pts, clutch = [np.zeros(3)], [False]
    for k in range(4):
        n = int(round(4.0 * rate_hz))
        s = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, n + 1) / n)  # smooth start and stop
        seg = corners[k] + s[:, None] * (corners[k + 1] - corners[k])
        if k == 2:  # clutch: reposition the master 60 mm back along +x, 1 s
            h = n // 2
            pts += list(seg[:h])
            clutch += [False] * h
            m_back = int(rate_hz)
            back = seg[h - 1] + np.linspace(0, 1, m_back + 1)[1:, None] * np.array([60.0, 0, 0])
            pts += list(back)
            clutch += [True] * m_back
            seg = seg[h:] + np.array([60.0, 0, 0])
            pts += list(seg)
            clutch += [False] * len(seg)
            corners[3:] += np.array([60.0, 0, 0])
            continue
        pts += list(seg)
        clutch += [False] * len(seg)
    P = np.asarray(pts)
    return Trajectory(np.arange(len(P)) * dt, P, np.asarray(clutch))


def write_csv(traj: Trajectory, path: str | Path) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for t, p, c in zip(traj.t, traj.master, traj.clutch, strict=True):
            w.writerow([f"{t:.4f}", f"{p[0]:.6f}", f"{p[1]:.6f}", f"{p[2]:.6f}", int(c)])


def rotation_xyz(deg: Any) -> np.ndarray:
    """R = Rz(γ) Ry(β) Rx(α) for fixed-axis angles (α, β, γ) in degrees."""
    a, b, g = np.deg2rad(np.asarray(deg, float))
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(g), -np.sin(g), 0], [np.sin(g), np.cos(g), 0], [0, 0, 1]])
    return rz @ ry @ rx


class Replay(NamedTuple):
    target: jax.Array  # (N, 3) eq. (33) target before clamping
    command: jax.Array  # (N, 3) commanded tip (clamped target)
    q: jax.Array  # (N, 3) commanded joints θ1 (rad), d1, d2
    clamped: jax.Array  # (N,) bool
    clamp_dist: jax.Array  # (N,) |target − command|


@jax.jit
def replay(master: jax.Array, clutch: jax.Array, q0: jax.Array, design: jax.Array,
           R: jax.Array, scale: jax.Array, lower: jax.Array, upper: jax.Array) -> Replay:  # fmt: skip
    """eq. (33) over the whole trajectory as one lax.scan; design = (a, c, L), joint
    ranges lower/upper (θ1 in rad), master-to-slave ratio ``scale`` (s:1)."""
    a, c, L = design[0], design[1], design[2]
    tip0 = m.arm_fk(q0[0], q0[1], q0[2], a, c, L)
    dm = jnp.diff(master, axis=0, prepend=master[:1])
    dm = jnp.where(clutch[:, None], 0.0, dm)

    def step(tip, d):
        target = tip + (R @ d) / scale
        q = jnp.stack(m.arm_ik(target, a, c, L))
        qc = jnp.clip(q, lower, upper)
        cmd = m.arm_fk(qc[0], qc[1], qc[2], a, c, L)
        dist = jnp.linalg.norm(target - cmd)
        clamped = jnp.any(q != qc)
        return cmd, Replay(target, cmd, qc, clamped, jnp.where(clamped, dist, 0.0))

    _, out = jax.lax.scan(step, tip0, dm)
    return out


def achieved(q: jax.Array, q0: jax.Array, delay_steps: int) -> jax.Array:
    """Joints the servo reaches: the command of ``delay_steps`` rows earlier (q0 before)."""
    if delay_steps <= 0:
        return q
    head = jnp.broadcast_to(q0, (min(delay_steps, q.shape[0]), 3))
    return jnp.concatenate([head, q[: q.shape[0] - delay_steps]], 0)[: q.shape[0]]
