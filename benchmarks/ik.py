"""IK of the da Vinci patient-side arm (Applied Sciences 2019): this package's batched
solver against the paper's scan + Newton method, the closed form of the RCM geometry, the
generic solver for any chain (``designopt.kinematics.ik``, also on a PUMA 560) and
(where installed) Robotics Toolbox ik_LM / ik_NR, on the same poses and tolerances.

    .venv/bin/python benchmarks/ik.py [--n 100000] [--paths 100] [--steps 10000]
        [--paper 200] [--peers 200] [--generic 16384] [--repeat 5] [--only generic]

Poses: FK of random joint sets within the joint ranges (f64). Cold: every pose from the
seed database. Trajectory: ``--paths`` smooth joint paths sampled at 1 kHz for ``--steps``
steps, solved by a ``lax.scan`` over time, warm-started. Compile time is reported apart
(first call minus a second call). A pose counts as solved when its errors are ≤ 1e-9 mm
and 1e-9 rad with every joint within its range; peers get the same poses and tolerances.
"""

from __future__ import annotations

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from designopt.studies.davinci import ik, paper  # noqa: E402
from designopt.studies.davinci import mechanism as m  # noqa: E402

X = jnp.asarray(m.table1())
TOL = 1e-9


def timed(fn, *args):
    """(result, compile s, run s): first call minus a timed second call."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    run = time.perf_counter() - t0
    return out, max(first - run, 0.0), run


def row(name, n, run, ok, pe, re, extra=""):
    ok, pe, re = np.asarray(ok), np.asarray(pe), np.asarray(re)

    def q(a):
        return np.quantile(a[ok], [0.5, 0.99, 1.0]) if ok.any() else [np.nan] * 3

    qp, qr = q(pe), q(re)
    print(f"{name:<34} {n:>8} {n / run:>12.4g} {100 * ok.mean():>9.3f}  "
          f"{qp[0]:.1e} {qp[1]:.1e} {qp[2]:.1e}  {qr[0]:.1e} {qr[1]:.1e} {qr[2]:.1e} {extra}")  # fmt: skip


def header(unit: str = "mm"):
    print(
        f"{'solver':<34} {'poses':>8} {'solves/s':>12} {'success%':>9}  "
        f"{'pos err ' + unit + ': p50 p99 max':<25}  {'rot err rad: p50 p99 max':<25}"
    )


def _rtb(T: np.ndarray) -> None:
    import roboticstoolbox as rtb

    a, lo, hi = m.TABLE1, m.LOWER, m.UPPER
    E = rtb.ET

    def lim(j):
        return [float(lo[j]), float(hi[j])]

    ets = (E.Rx(a["alpha"] - np.pi) * E.Rz(qlim=lim(0)) * E.tz(a["l_QH"])
           * E.Rx(np.pi / 2 - a["beta"]) * E.Ry(np.pi / 2) * E.Rz(qlim=lim(1))
           * E.ty(qlim=lim(2)) * E.Rx(-np.pi / 2) * E.Rz(qlim=lim(3)) * E.Rx(np.pi / 2)
           * E.Rz(qlim=lim(4)) * E.ty(a["l_IJ"]) * E.Ry(np.pi / 2) * E.Rz(qlim=lim(5)))  # fmt: skip
    for meth in ("ik_LM", "ik_NR"):
        f = getattr(ets, meth)
        t0 = time.perf_counter()
        sols = [f(t, tol=1e-24, joint_limits=True, ilimit=30, slimit=100) for t in T]
        run = time.perf_counter() - t0
        qs = np.array([s[0] for s in sols])
        R, p = m.ARM.fk(X, jnp.asarray(qs))
        pe, re = ik.pose_errors(R, p, jnp.asarray(T))
        inside = np.all((qs >= lo - 1e-12) & (qs <= hi + 1e-12), -1)
        ok = (np.asarray(pe) <= TOL) & (np.asarray(re) <= TOL) & inside
        row(f"roboticstoolbox {meth} (C++)", len(T), run, ok, pe, re)


def peers(T: np.ndarray) -> None:
    """Robotics Toolbox ik_LM / ik_NR (C++) on the same ETS chain, if installed."""
    try:
        import roboticstoolbox  # noqa: F401
    except ImportError:
        print("roboticstoolbox: not installed (pip install roboticstoolbox-python); skipped")
    else:
        try:
            _rtb(T)
        except Exception as e:  # an API change in a peer must not hide our numbers
            print(f"roboticstoolbox: comparison failed ({type(e).__name__}: {e})")
    try:
        import ikpy  # noqa: F401
    except ImportError:
        print("ikpy: not installed (pip install ikpy); skipped")
    else:
        print("ikpy: installed; its chains are built from URDF links and this ETS chain "
              "(prismatic q3 between revolute joints) is not ported: not compared")  # fmt: skip


PUMA_A = [0, 0.4318, 0.0203, 0, 0, 0]
PUMA_D = [0, 0, 0.15005, 0.4318, 0, 0]
PUMA_ALPHA = [np.pi / 2, 0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0]
PUMA_LO = np.radians([-160, -110, -135, -266, -100, -266.0])


def _rates(fn, args, n: int, repeat: int):
    """(result, compile s, solves/s per repeat): the first call's extra time is the
    compile; then ``repeat`` timed calls."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        runs.append(time.perf_counter() - t0)
    return out, max(first - min(runs), 0.0), n / np.asarray(runs)


def _rtb_puma(q_true: np.ndarray, n: int) -> None:
    """Robotics Toolbox ik_LM / ik_NR (C++, one pose per call) on the same PUMA 560
    (its DH table and limits), position (mask) and full pose, the same tolerances."""
    import roboticstoolbox as rtb

    from designopt.kinematics import ik as gik
    from designopt.kinematics.kernel import dh_model

    links = [rtb.RevoluteDH(a=a, d=d, alpha=al, qlim=[lo, -lo])
             for a, d, al, lo in zip(PUMA_A, PUMA_D, PUMA_ALPHA, PUMA_LO, strict=True)]  # fmt: skip
    ets = rtb.DHRobot(links).ets()
    puma = dh_model("standard", "RRRRRR", PUMA_ALPHA, PUMA_A, PUMA_D, [0] * 6)
    R, p = puma.fk(jnp.zeros(0), jnp.asarray(q_true[:n]))
    # the generic solver's tolerance: 1e-9 × its reach scale L (the largest distance of
    # FK positions at random joints from their mean; here of all the benchmark's poses)
    _, p_all = puma.fk(jnp.zeros(0), jnp.asarray(q_true))
    L = float(np.max(np.linalg.norm(p_all - np.mean(p_all, 0), axis=-1)))
    Ts = [ets.fkine(q).A for q in q_true[:n]]
    dfk = max(np.abs(T[:3, 3] - np.asarray(pi)).max() for T, pi in zip(Ts, p, strict=True))
    print(f"  Robotics Toolbox PUMA: its FK = ours to {dfk:.1e} m")
    for mode, mask in (("position", [1, 1, 1, 0, 0, 0]), ("pose", None)):
        for meth in ("ik_LM", "ik_NR"):
            f = getattr(ets, meth)
            t0 = time.perf_counter()
            sols = [f(T, tol=1e-24, mask=mask, joint_limits=True, ilimit=30, slimit=100)
                    for T in Ts]  # fmt: skip
            run = time.perf_counter() - t0
            qs = np.array([s[0] for s in sols])
            Rq, pq = puma.fk(jnp.zeros(0), jnp.asarray(qs))
            pe, re = gik.errors(pq, Rq, p, R, mode)
            inside = np.all((qs >= PUMA_LO - 1e-12) & (qs <= -PUMA_LO + 1e-12), -1)
            ok = (np.asarray(pe) <= 1e-9 * L) & (np.asarray(re) <= TOL) & inside
            row(f"roboticstoolbox {meth} (PUMA 560, {mode})", n, run, ok, pe, re)


def generic(n: int, repeat: int, n_peers: int) -> None:
    """The generic solver (``designopt.kinematics.ik``: any SerialModel, no chain-specific
    seeding, its default options) on the da Vinci poses and on a PUMA 560 (position,
    position + tool axis, full pose), float64; the rate is the median of ``repeat`` calls
    with the spread, compile apart. Robotics Toolbox on the same PUMA poses, if installed."""
    from designopt.kinematics import ik as gik
    from designopt.kinematics.kernel import dh_model

    rng = np.random.default_rng(1)
    q = rng.uniform(m.LOWER, m.UPPER, (n, 6))
    R, p = m.ARM.fk(X, jnp.asarray(q))
    lo, hi = jnp.asarray(m.LOWER), jnp.asarray(m.UPPER)
    cases = [("da Vinci arm", m.ARM, X, lo, hi, p, R, "pose", "mm")]
    puma = dh_model("standard", "RRRRRR", PUMA_ALPHA, PUMA_A, PUMA_D, [0] * 6)
    plo = jnp.asarray(PUMA_LO)
    qp = rng.uniform(PUMA_LO, -PUMA_LO, (n, 6))
    Rp, pp = puma.fk(jnp.zeros(0), jnp.asarray(qp))
    cases += [("PUMA 560", puma, jnp.zeros(0), plo, -plo, pp, Rp, mode, "m") for mode in gik.MODES]
    print(f"generic solver, defaults {gik.DEFAULTS}; solved: errors within 1e-9 × the "
          "chain's reach scale L (da Vinci: L ≈ 340 mm) and 1e-9 rad, joints within limits")  # fmt: skip
    print(f"{'generic LM':<34} {'poses':>8} {'solves/s median (min-max)':>28} {'success%':>9}"
          f"  compile")  # fmt: skip
    for name, model, x, lo_, hi_, pt, Rt, mode, unit in cases:
        fn = jax.jit(lambda pt, Rt, model=model, x=x, lo_=lo_, hi_=hi_, mode=mode:
                     gik.solve_design(model, x, pt, Rt, lo_, hi_, jax.random.key(0), mode))  # fmt: skip
        r, c, rates = _rates(fn, (pt, Rt), n, repeat)
        ok = np.asarray(r.success)
        print(f"{name + ', ' + mode:<34} {n:>8} {np.median(rates):>11.3g} "
              f"({rates.min():.3g}-{rates.max():.3g})   {100 * ok.mean():>9.3f}  {c:.1f} s "
              f"(max err of the solved: {np.asarray(r.pos_err)[ok].max():.1e} {unit}, "
              f"{np.asarray(r.rot_err)[ok].max():.1e} rad)")  # fmt: skip
    try:
        import roboticstoolbox  # noqa: F401
    except ImportError:
        print("roboticstoolbox: not installed (pip install roboticstoolbox-python); skipped")
        return
    header("m")
    try:
        _rtb_puma(qp, min(n_peers, n))
    except Exception as e:  # an API change in a peer must not hide our numbers
        print(f"roboticstoolbox: comparison failed ({type(e).__name__}: {e})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--paths", type=int, default=100)
    ap.add_argument("--steps", type=int, default=10_000)
    ap.add_argument("--paper", type=int, default=200, help="poses for the paper's method")
    ap.add_argument("--peers", type=int, default=200, help="poses for Robotics Toolbox")
    ap.add_argument("--generic", type=int, default=16384,
                    help="poses for the generic solver (designopt.kinematics.ik)")  # fmt: skip
    ap.add_argument("--repeat", type=int, default=5, help="timed calls of the generic solver")
    ap.add_argument("--only", choices=("all", "generic"), default="all",
                    help="generic: only the generic solver and its peers")  # fmt: skip
    a = ap.parse_args()
    print(f"== da Vinci arm IK (Applied Sciences 2019) == backend={jax.default_backend()} "
          f"cores={os.cpu_count()} load={os.getloadavg()[0]:.1f} f64")  # fmt: skip
    if a.only == "generic":
        generic(a.generic, a.repeat, a.peers)
        print(f"load at the end: {os.getloadavg()[0]:.1f}")
        return
    rng = np.random.default_rng(0)
    q = rng.uniform(m.LOWER, m.UPPER, (a.n, 6))
    T = jax.block_until_ready(m.pose(X, jnp.asarray(q)))

    db, c_db, r_db = timed(jax.jit(ik.build_database), X)
    print(f"seed database: {db.size} FK samples, built in {r_db * 1e3:.1f} ms "
          f"(compile {c_db:.1f} s)")  # fmt: skip
    header()
    cold = jax.jit(lambda T: ik.solve(X, db, T))
    r, c, run = timed(cold, T)
    row("this package: LM, cold from database", a.n, run, r.success, r.pos_err, r.rot_err,
        f"compile {c:.1f} s; iterations p50 {np.median(np.asarray(r.iterations)):.0f}")  # fmt: skip
    fails = int((~np.asarray(r.success)).sum())
    _, reach = jax.jit(ik.closed_form)(X, T)
    print(f"  failures: {fails} (the closed form reaches {int(np.asarray(reach).sum())}/{a.n}); "
          f"max |q - q_true| of the solved: "
          f"{np.abs(np.asarray(r.q) - q)[np.asarray(r.success)].max():.1e}")  # fmt: skip

    # trajectory: smooth joint paths at 1 kHz
    t = np.arange(a.steps) / 1000.0
    base = rng.uniform(m.LOWER + 0.4, m.UPPER - 0.4, (a.paths, 6))
    base[:, 2] = rng.uniform(60, 250, a.paths)
    amp = np.array([0.3, 0.3, 40.0, 1.0, 0.3, 0.3])
    freq = rng.uniform(0.2, 1.0, (a.paths, 6))
    qt = base[None] + amp * np.sin(2 * np.pi * freq[None] * t[:, None, None])
    qt[..., 3] = np.remainder(qt[..., 3] + np.pi, 2 * np.pi) - np.pi
    Tt = jax.block_until_ready(m.pose(X, jnp.asarray(qt.reshape(-1, 6)))).reshape(
        a.steps, a.paths, 4, 4
    )
    traj = jax.jit(lambda T: ik.solve_trajectory(X, db, T))
    rt, c, run = timed(traj, Tt)
    row(f"this package: trajectory ({a.paths} paths)", a.steps * a.paths, run, rt.success,
        rt.pos_err, rt.rot_err, f"compile {c:.1f} s; iterations p50 "
        f"{np.median(np.asarray(rt.iterations)[1:]):.0f}")  # fmt: skip
    one = jax.jit(lambda T: ik.solve_trajectory(X, db, T))
    n1 = min(2000, a.steps)
    r1, c1, run1 = timed(one, Tt[:n1, :1])
    row("this package: trajectory (1 path)", n1, run1, r1.success, r1.pos_err, r1.rot_err,
        f"compile {c1:.1f} s; {run1 / n1 * 1e6:.1f} µs per pose")  # fmt: skip

    cf = jax.jit(lambda T: ik.closed_form(X, T))
    (qc, okc), c, run = timed(cf, T)
    R, p = m.ARM.fk(X, qc)
    pe, re = ik.pose_errors(R, p, T)
    row("closed form (RCM geometry, check)", a.n, run, okc, pe, re, f"compile {c:.1f} s")

    n = a.paper
    pf = jax.jit(jax.vmap(lambda t: paper.solve(X, t)))
    rp, c, run = timed(pf, T[:n])
    row("paper: scan h=20° + Newton (vmap)", n, run, rp.success, rp.pos_err, rp.rot_err,
        f"compile {c:.1f} s; {run / n * 1e3:.2f} ms per pose")  # fmt: skip
    p1 = jax.jit(lambda t: paper.solve(X, t))
    _, c, run1 = timed(p1, T[0])
    print(f"  paper's method, one pose per call: {run1 * 1e3:.2f} ms (paper: 390-484 ms on a "
          f"PC, 16 ms on the controller)")  # fmt: skip
    tq = paper.to_rad(paper.TABLE2_DEG)
    r2 = jax.vmap(lambda t: paper.solve(X, t))(m.pose(X, jnp.asarray(tq)))
    err = np.abs(paper.to_deg(np.asarray(r2.q)) - paper.TABLE2_DEG).max()
    print(f"  Table 2: max |output − input| = {err:.1e} (deg / mm), step h "
          f"{np.asarray(r2.step_deg).tolist()}")  # fmt: skip
    generic(a.generic, a.repeat, a.peers)
    peers(np.asarray(T[: a.peers]))
    print(f"load at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
