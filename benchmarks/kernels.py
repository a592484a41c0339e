"""FK + Jacobian + inverse condition number throughput: the generic frame kernel
(designopt.kinematics.kernel) against hand-derived closed forms.

50 designs × 20,000 configurations, float32 and float64, in configurations per second:
- master9 (seed 000): numpy closed form (baseline), the hand closed form, the generic
  kernel; FK + J + 1/k and the dexterity part
  alone (J_v + 1/k_F + power sums) against study A's specialised kernel (the one
  benchmarks/swarm_scoring.py times); compile times; agreement with the closed form;
- a 6-joint textbook arm (PUMA 560, standard DH), the same arm read from its URDF
  (configs/robots/puma560.urdf; the URDF/DH speed ratio and the URDF compile time are
  printed) and a da Vinci-like ET chain;
- the Robotics Toolbox's jacob0 per configuration, where the ``bench`` extra is installed.
Every timing is repeated; "best [median – worst]" is printed.

    python benchmarks/kernels.py [--designs 50] [--configs 20000] [--repeats 7]
                                 [--memory]

``--memory`` streams 10^7 samples × 100 designs of the 6-joint arm through the kernel in
chunks (lax.scan, accumulating Σ 1/k and Σ (1/k)²) in a fresh process and prints that
process's peak resident memory.
"""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)  # we measure float64 too

import argparse  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _timing import best_of, compile_time, header  # noqa: E402

from designopt.kinematics import ET, inv_cond  # noqa: E402
from designopt.kinematics.kernel import dh_model, et_model  # noqa: E402
from designopt.numerics import montecarlo as mc  # noqa: E402
from designopt.studies.master9 import mechanism as m  # noqa: E402
from designopt.studies.master9.indices import (  # noqa: E402
    _features,
    inv_cond_fro_jv,
    jv_entries,
)

HP = np.pi / 2


def numpy_reference(q: np.ndarray, D: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form P (eq. 4), J_v (eq. 34, fixed) and 1/k_F via the adjugate, in numpy."""
    a1, a3, a4, d3 = (D[k][:, None] for k in ("a1", "a3", "a4", "d3"))
    q1, q2, q3 = q[None, :, 0], q[None, :, 1], q[None, :, 2]
    s12, c12, c3, s3 = np.sin(q1 + q2), np.cos(q1 + q2), np.cos(q3), np.sin(q3)
    w = a3 * c3 + a4
    px = a1 * np.cos(q1) + d3 * c12 + w * s12
    j12 = w * c12 - d3 * s12
    j22 = w * s12 + d3 * c12
    J = np.zeros(px.shape + (3, 3))
    J[..., 0, 0] = j12 - a1 * np.sin(q1)
    J[..., 0, 1] = j12
    J[..., 0, 2] = -a3 * s12 * s3
    J[..., 1, 0] = j22 + a1 * np.cos(q1)
    J[..., 1, 1] = j22
    J[..., 1, 2] = a3 * c12 * s3
    J[..., 2, 2] = -a3 * c3
    C = np.linalg.inv(J) * np.linalg.det(J)[..., None, None]
    r = np.abs(np.linalg.det(J)) / np.sqrt((J**2).sum((-1, -2)) * (C**2).sum((-1, -2)))
    return px, r


# ------------------------------------------------------------------------ models


def master9_model():
    """SPEC §3.1 as data: modified DH, 7 active → 9 chain joints (q4 = −q3, q5 = −q1 − q2);
    a1, a3, d3 are the design variables, the Table 5 lengths fixed chain data."""
    C = np.zeros((9, 7))
    for i, j in [(0, 0), (1, 1), (2, 2), (5, 3), (6, 4), (7, 5), (8, 6)]:
        C[i, j] = 1.0
    C[3, 2] = -1.0
    C[4, 0] = C[4, 1] = -1.0
    fx = m.FIXED_DEFAULTS
    return dh_model(
        "modified",
        ("R",) * 9,
        alpha=[0, 0, -HP, 0, HP, 0, -HP, HP, HP],
        a=[0, "a1", 0, "a3", fx["a4"], fx["a5"], 0, 0, 0],
        d=[0, -fx["d2"], "d3", 0, fx["d5"], fx["d6"], 0, 0, 0],
        theta=[0, -HP, 0, 0, 0, -HP, 0, HP, -HP],
        variables=("a1", "a3", "d3"),
        coupling=C,
    )


PUMA_X = np.array([431.8, 20.32, 149.09, 433.07])  # a2, a3, d3, d4 (mm)


def puma_model():
    return dh_model(
        "standard",
        "RRRRRR",
        alpha=[HP, 0.0, -HP, HP, -HP, 0.0],
        a=[0, "a2", "a3", 0, 0, 0],
        d=[0, 0, "d3", "d4", 0, 0],
        theta=[0.0] * 6,
        variables=("a2", "a3", "d3", "d4"),
    )


def puma_urdf_model():
    """The same PUMA 560 read from its URDF (configs/robots/puma560.urdf, frames matched to
    the DH table), a2, a3, d3, d4 bound to the joint origins (the kernel's URDF import)."""
    from pathlib import Path

    from designopt.kinematics import urdf

    path = Path(__file__).resolve().parents[1] / "configs" / "robots" / "puma560.urdf"
    imp = urdf.import_path(urdf.parse(path.read_text(), str(path)), None, "tool0")
    names = ("a2", "a3", "d3", "d4")
    keys = [("joint3", "x"), ("joint4", "x"), ("joint4", "z"), ("joint5", "z")]
    return urdf.lower(imp, {k: (0.0, ((i, 1.0),)) for i, k in enumerate(keys)}, names)


def davinci_model():
    """A da Vinci-like ET chain (SPEC §4 form): RCM offset l_QH, insertion q3 (prismatic),
    wrist offset l_IJ and tool length l_tool as length variables; angles fixed."""
    al = np.deg2rad(20.0)
    beta = np.deg2rad(30.45)
    chain = (
        ET("Rx", const=-(np.pi - al)),
        ET("Rz", joint=0),
        ET("Tz", param="l_QH"),
        ET("Rx", const=-(beta - HP)),
        ET("Ry", const=HP),
        ET("Rz", joint=1),
        ET("Ty", joint=2),
        ET("Rx", const=-HP),
        ET("Rz", joint=3),
        ET("Rx", const=HP),
        ET("Rz", joint=4),
        ET("Ty", param="l_IJ"),
        ET("Ry", const=HP),
        ET("Rz", joint=5),
        ET("Tz", param="l_tool"),
    )
    return et_model(chain, variables=("l_QH", "l_IJ", "l_tool"))


# ------------------------------------------------------------------------ timing


def timings(fn, n: int) -> tuple[float, float, float]:
    """(best, median, worst) wall time of n calls."""
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return min(ts), float(np.median(ts)), max(ts)


def fmt(total: int, t: tuple[float, float, float]) -> str:
    b, med, w = t
    return (
        f"{total / b:10.3e} configs/s [{total / med:9.2e} – {total / w:9.2e}]"
        f"  ({b * 1e3:7.2f} ms best)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--designs", type=int, default=50)
    ap.add_argument("--configs", type=int, default=20_000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-autodiff", action="store_true", help=argparse.SUPPRESS)  # no-op now
    ap.add_argument("--memory", action="store_true")
    ap.add_argument("--memory-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory_only:  # a fresh process, so that its peak RSS is the streamed run's
        memory_run()
        return
    header("kernels: FK + Jacobian + 1/k, generic frame kernel vs closed forms")
    M, N, R = args.designs, args.configs, args.repeats
    rng = np.random.default_rng(0)
    Dn = {k: np.full(M, v) for k, v in m.default_design().items()}
    Dn["a1"] = rng.uniform(250, 350, M)
    Dn["a3"] = rng.uniform(250, 350, M)
    Dn["d3"] = rng.uniform(50, 150, M)
    Xn = np.stack([Dn["a1"], Dn["a3"], Dn["d3"]], 1)
    qn = np.asarray(m.sample_joints(jax.random.key(0), N))
    total = M * N
    model = master9_model()
    print(f"master9, {M} designs x {N} configurations")

    t_np = best_of(lambda: numpy_reference(qn, Dn), 3)
    print(
        f"numpy closed form (float64):          {total / t_np:12.3e} configs/s  ({t_np * 1e3:8.1f} ms)"
    )

    ratio_closed: dict[str, float] = {}
    ratio_spec: dict[str, float] = {}
    compiles: list[float] = []
    for dtype in (jnp.float32, jnp.float64):
        name = jnp.dtype(dtype).name
        q = jnp.asarray(qn, dtype)
        D = {k: jnp.asarray(v, dtype)[:, None] for k, v in Dn.items()}
        X = jnp.asarray(Xn, dtype)
        a4 = D["a4"]

        @jax.jit
        def closed_path(q, D):
            P = m.position(q[:, :3], D)
            return P, inv_cond(m.jacobian_v_closed(q[:, :3], D))

        @jax.jit
        def generic_path(X, q):
            r, p = model.inv_cond(X, q, rows=(0, 1, 2), cols=(0, 1, 2), with_position=True)
            return p, r

        @jax.jit
        def specialised_dex(X, q, a4):
            x = {"a1": X[:, 0:1], "a3": X[:, 1:2], "d3": X[:, 2:3], "a4": a4}
            det, r = inv_cond_fro_jv(jv_entries(x, _features(q)))
            ps = mc.power_sums(jnp.abs(det), r)
            return mc.mean(ps).value, mc.std(ps).value

        @jax.jit
        def generic_dex(X, q):
            r, det = model.inv_cond(X, q, rows=(0, 1, 2), cols=(0, 1, 2), with_det=True)
            ps = mc.power_sums(jnp.abs(det), r)
            return mc.mean(ps).value, mc.std(ps).value

        print(f"-- {name}")
        res = {}
        paths = [
            ("closed form                    ", lambda: closed_path(q, D)),
            ("generic kernel FK+J+1/k        ", lambda: generic_path(X, q)),
            ("specialised dexterity (study A)", lambda: specialised_dex(X, q, a4)),
            ("generic dexterity (J_v+1/k_F)  ", lambda: generic_dex(X, q)),
        ]
        for label, fn in paths:
            tc = compile_time(fn)
            t = timings(fn, R)
            res[label.strip()] = t
            if label.startswith("generic"):
                compiles.append(tc)
            print(
                f"jax {label} ({name}): {fmt(total, t)}  compile {tc:5.2f} s  = {t_np / t[0]:6.1f}x numpy"
            )
        rc = res["closed form"][0] / res["generic kernel FK+J+1/k"][0]
        rs = res["specialised dexterity (study A)"][0] / res["generic dexterity (J_v+1/k_F)"][0]
        rc_med = res["closed form"][1] / res["generic kernel FK+J+1/k"][1]
        rs_med = res["specialised dexterity (study A)"][1] / res["generic dexterity (J_v+1/k_F)"][1]
        ratio_closed[name], ratio_spec[name] = rc, rs
        print(
            f"   generic/closed = {rc:.2f} (medians {rc_med:.2f}); generic/specialised dexterity = {rs:.2f} (medians {rs_med:.2f})"
        )
        pg, rg = generic_path(X, q)
        pc, rcf = closed_path(q, D)
        _, rn = numpy_reference(qn, Dn)
        dr = float(jnp.max(jnp.abs(rg - rcf)))
        dp = float(jnp.max(jnp.abs(pg - pc)) / jnp.max(jnp.abs(pc)))
        gd, gc = generic_dex(X, q), specialised_dex(X, q, a4)
        dg = float(jnp.max(jnp.abs(gd[0] - gc[0])))
        tol = 1e-5 if dtype == jnp.float32 else 1e-12
        print(
            f"   agreement with the closed form: max|Δ1/k| = {dr:.1e}, max|Δp|/max|p| = {dp:.1e},"
            f" max|ΔGCI| = {dg:.1e} (target {tol:.0e}: {'met' if max(dr, dg) <= tol else 'MISSED'});"
            f" |closed - numpy| = {float(np.abs(np.asarray(rcf, np.float64) - rn).max()):.1e}"
        )

    # ------------------------------------------------------------ other chains
    puma_X = PUMA_X * rng.uniform(0.8, 1.2, (M, 4))
    puma_q = lambda n: np.random.default_rng(7).uniform(-np.pi, np.pi, (n, 6))  # noqa: E731
    best: dict[str, float] = {}
    for label, mdl, Xc, qgen in (
        ("6-joint textbook arm (PUMA 560, standard DH)", puma_model(), puma_X, puma_q),
        ("the same PUMA 560 from its URDF (configs/robots/puma560.urdf)", puma_urdf_model(),
         puma_X, puma_q),
        ("da Vinci-like ET chain (6 joints, 1 prismatic)", davinci_model(),
         np.array([784.29, 10.0, 50.0]) * rng.uniform(0.8, 1.2, (M, 3)),
         lambda n: np.concatenate([rng.uniform(-1.5, 0, (n, 2)), rng.uniform(50, 300, (n, 1)),
                                   rng.uniform(-1.5, 1.5, (n, 3))], 1)),
    ):  # fmt: skip
        qc = qgen(N)
        print(f"{label}: FK + 6x6 J (v rows / 500 mm) + normalised 1/k_F, {M} x {N}")
        for dtype in (jnp.float32, jnp.float64):
            Xd, qd = jnp.asarray(Xc, dtype), jnp.asarray(qc, dtype)

            @jax.jit
            def full(X, q, mdl=mdl):
                R, p, J = mdl.fk_jacobian(X, q, char_length=500.0)
                r = mdl.inv_cond(X, q, char_length=500.0, normalized=True)
                return R, p, r

            @jax.jit
            def fk_j(X, q, mdl=mdl):
                return mdl.fk_jacobian(X, q)

            for lab, fn in (("FK+J+1/k", full), ("FK+J    ", fk_j)):
                tc = compile_time(lambda fn=fn: fn(Xd, qd))
                t = timings(lambda fn=fn: fn(Xd, qd), R)
                print(
                    f"   generic {lab} ({jnp.dtype(dtype).name}): {fmt(total, t)}  compile {tc:5.2f} s"
                )
                tag = "DH" if "standard DH" in label else "URDF" if "URDF" in label else ""
                best[(tag, lab.strip(), jnp.dtype(dtype).name)] = (t, tc)
    for (_tag, lab, dt), (t_dh, _) in [(k, v) for k, v in best.items() if k[0] == "DH"]:
        t_u, tc_u = best[("URDF", lab, dt)]
        print(
            f"PUMA 560 {lab} ({dt}): URDF chain at {t_dh[0] / t_u[0]:.2f}x the DH chain's speed "
            f"(medians {t_dh[1] / t_u[1]:.2f}x; target >= 0.8), URDF compile {tc_u:.2f} s "
            "(target <= 2 s)"
        )

    try:
        import roboticstoolbox as rtb

        robot = rtb.models.DH.Puma560()
        qs = rng.uniform(-np.pi, np.pi, (2000, 6))
        t0 = time.perf_counter()
        for qi in qs:
            robot.jacob0(qi)
        dt = time.perf_counter() - t0
        print(f"Robotics Toolbox Puma560.jacob0, per configuration: {len(qs) / dt:10.3e} configs/s")
    except ImportError:
        print("Robotics Toolbox: not installed (pip install -e '.[bench]'), column skipped")

    if args.memory:
        out = subprocess.run(
            [sys.executable, __file__, "--memory-only"], capture_output=True, text=True
        )
        print(out.stdout.strip() or out.stderr.strip()[-2000:])

    print(
        f"generic/closed f32 = {ratio_closed['float32']:.2f}, f64 = {ratio_closed['float64']:.2f}; "
        f"generic/specialised f32 = {ratio_spec['float32']:.2f}; compile max = {max(compiles):.2f} s"
    )


def memory_run(n_samples: int = 10_000_000, M: int = 100, chunk: int = 20_000) -> None:
    """10^7 samples × 100 designs of the 6-joint arm, streamed in chunks (float32)."""
    mdl = puma_model()
    rng = np.random.default_rng(1)
    X = jnp.asarray(PUMA_X * rng.uniform(0.8, 1.2, (M, 4)), jnp.float32)
    n_chunks = -(-n_samples // chunk)
    lo = jnp.full(6, -np.pi, jnp.float32)
    hi = jnp.full(6, np.pi, jnp.float32)

    @jax.jit
    def run(X, key):
        def body(acc, k):
            u = mc.unit_samples(key, k * chunk, chunk, 6, "uniform", jnp.float32)
            r = mdl.inv_cond(X, lo + (hi - lo) * u, char_length=500.0, normalized=True)
            return (acc[0] + r.sum(1), acc[1] + (r * r).sum(1)), None

        z = jnp.zeros(M, jnp.float32)
        (s1, s2), _ = jax.lax.scan(body, (z, z), jnp.arange(n_chunks))
        return s1, s2

    t0 = time.perf_counter()
    s1, s2 = jax.block_until_ready(run(X, jax.random.key(0)))
    dt = time.perf_counter() - t0
    n = n_chunks * chunk
    mean = s1 / n
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    print(
        f"--memory: {n:.0e} samples x {M} designs, 6-joint arm, chunk {chunk} (float32): "
        f"{dt:.1f} s ({n * M / dt:.2e} configs/s), peak RSS {peak:.2f} GB, "
        f"mean 1/k[0] = {float(mean[0]):.4f}"
    )


if __name__ == "__main__":
    main()
