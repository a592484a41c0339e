"""Where a planning case's per-target time goes (issue #54): the task's block program
(``taskindex.chunk_values``: 16 designs × the chunk's targets, both arms) timed warm on
three sets of designs, with the IK's own counts (seeds tried per target, converged seeds
refused by the collision check), beside the unit costs of its parts measured alone in
the same run: one collision check (the arm's capsules against the body wall's mesh, the
anatomy and each other), one LM block of steps, the FK database.

    python benchmarks/planning_profile.py                           # configs/port_placement.yaml
    python benchmarks/planning_profile.py --config configs/two_ur5_front.yaml --repeat 5

Rows: ``naive`` (docs/planning.md's layout, 16 copies of it: one design's cost, since a
block solves each distinct design once), ``swarm`` (16 designs drawn uniformly in the
box: a search's block) and ``centre`` (the box's middle, 16 copies). Columns: the
block's warm wall time (median of ``--repeat``, with the spread), targets reached, seeds
tried per (design, arm, target) item, refused seeds per item, the collision checks' share
of the time estimated from their count × the unit cost, and the collision-free solutions
per second (bash benchmarks/gpu.sh runs it on a GPU). The CPU, its vector
extensions and the load head the output: the numbers only compare within one run."""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

ROOT = Path(__file__).resolve().parent.parent
NAIVE = {"b": 0.6, "by": 0.0, "px": 0.03, "py0": 0.0, "py1": 0.0}


def cpu() -> str:
    name, flags = platform.processor() or "?", ""
    try:
        text = Path("/proc/cpuinfo").read_text()
        name = next(ln.split(":", 1)[1].strip() for ln in text.splitlines()
                    if ln.startswith("model name"))  # fmt: skip
        fl = next(ln for ln in text.splitlines() if ln.startswith("flags")).split()
        flags = " ".join(f for f in ("avx2", "avx512f", "fma") if f in fl)
    except (OSError, StopIteration):
        pass
    return f"{name} ({os.cpu_count()} cores; {flags or 'no AVX2'})"


def timed(fn, repeat: int) -> tuple[float, float, float, object]:
    out = jax.block_until_ready(fn())  # compiled (and warmed) first
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), min(ts), max(ts), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="configs/port_placement.yaml")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    os.chdir(ROOT)

    from designopt.app.config import load
    from designopt.core.keys import streams
    from designopt.kinematics import ik
    from designopt.studies.serial import blocks, bodies, taskindex

    cfg, _ = load(args.config)
    s = cfg.study
    dt = jnp.float64
    mech, p = blocks.host_params(s, streams(cfg.seed), dt)  # the run's params
    C = taskindex.chunk(s)
    pc, Rc, t0 = taskindex.chunked_targets(p, C, dt, np)
    names = list(s.variables)
    lo = np.array([s.variables[k][0] for k in names])
    hi = np.array([s.variables[k][1] for k in names])
    rng = np.random.default_rng(0)
    sets = {"naive": np.repeat([[NAIVE.get(k, 0.5 * (a + b)) for k, a, b in zip(names, lo, hi, strict=True)]],
                               16, 0),
            "swarm": lo + rng.random((16, len(names))) * (hi - lo),
            "centre": np.repeat([0.5 * (lo + hi)], 16, 0)}  # fmt: skip

    @jax.jit
    def block(p, X, pt, Rt, t0):
        full = taskindex.design_full(p, X, dt)
        return taskindex.chunk_values(mech, s, p, full, pt, Rt, t0, dt, profile=True)

    # the unit costs, alone: a collision check, an LM block (ik.solve without a check on
    # the same chain), the FK database
    geo = bodies.geometry(s, mech)
    n_unit = 1024
    q = jnp.asarray(np.asarray(mech.lower) + rng.random((n_unit, mech.n))
                    * (np.asarray(mech.upper) - np.asarray(mech.lower)))  # fmt: skip
    full1 = taskindex.design_full(p, jnp.asarray(sets["centre"][:1]), dt)
    X1 = jnp.repeat(full1, n_unit, 0)
    print(f"== {args.config}: the task's block program, warm ==")
    print(f"CPU {cpu()}; load {os.getloadavg()[0]:.1f}; JAX {jax.__version__}; "
          f"{time.strftime('%Y-%m-%d')}")  # fmt: skip
    check_ms = float("nan")
    if geo is not None:
        obst = p["scene_obstacles"]
        inner = p.get("scene_inside")
        gp = p["scene_geometry"]
        wall = None if s.task.body_wall is None else s.task.body_wall.shape
        port = (bodies.port_points(p, full1, wall)[0, 0] if s.ports()[0] is not None else None)
        ptu = jnp.asarray(pc.reshape(-1, 3)[np.arange(n_unit) % pc.reshape(-1, 3).shape[0]])

        @jax.jit
        def check(X, q, pt):
            seg = geo.items(mech.model, X, q)
            if port is None:
                return bodies.obstacle_and_self(geo, obst, seg, None, None, None, gp)
            pa = jnp.broadcast_to(port, pt.shape)
            z = pt - pa
            z = z / jnp.linalg.norm(z, axis=-1, keepdims=True)
            return bodies.obstacle_and_self(geo, obst, seg, pa, z, inner, gp)

        med, _, _, _ = timed(lambda: check(X1, q, ptu), args.repeat)
        check_ms = 1e3 * med / n_unit
    lo_q, hi_q = jnp.asarray(mech.lower), jnp.asarray(mech.upper)
    p_reach = jax.vmap(lambda x, q: mech.model.fk(x, q)[1])(X1[:256], q[:256])
    R_reach = jax.vmap(lambda x, q: mech.model.fk(x, q)[0])(X1[:256], q[:256])
    md = taskindex.mode(s)
    opts = taskindex.options(s)
    solve = jax.jit(lambda: ik.solve(mech.model, full1, p_reach,
                                     None if md == "position" else R_reach, lo_q, hi_q,
                                     jax.random.key(1), md, opts))  # fmt: skip
    med, _, _, r = timed(solve, args.repeat)
    steps = float(np.sum(np.asarray(r.tries)))  # seeds; each at most opts.iters steps
    seed_ms = 1e3 * med / max(steps, 1)
    print(f"unit costs: one collision check {check_ms:.4f} ms (batch of {n_unit}); one IK seed "
          f"on reachable targets {seed_ms:.4f} ms ({steps / 256:.2f} seeds per target, no "
          "check)")  # fmt: skip
    A = len(s.arms) if s.arms is not None else 1
    print(f"{'designs':8} {'block s':>16} {'reached':>8} {'seeds/item':>11} {'most':>5} {'1 seed':>7} "
          f"{'refused/item':>13} {'checks':>8} {'checks s':>9} {'free solves/s':>14}")  # fmt: skip
    for name, Xs in sets.items():
        X = jnp.asarray(Xs)
        outs, meds, los, his = [], 0.0, 0.0, 0.0
        for i in range(len(t0)):
            Rt = None if Rc is None else jnp.asarray(Rc[i])
            med, lo_t, hi_t, out = timed(lambda: block(p, X, jnp.asarray(pc[i]), Rt,
                                                       jnp.asarray(t0[i])), args.repeat)  # fmt: skip
            outs.append(out)
            meds, los, his = meds + med, los + lo_t, his + hi_t
        tries = np.concatenate([np.asarray(o["ik_tries"]) for o in outs], 1)
        refused = np.concatenate([np.asarray(o["ik_refused"]) for o in outs], 1)
        ok = np.concatenate([np.asarray(o["success"]) for o in outs], 1)
        distinct = len(np.unique(Xs, axis=0))
        rows = tries.reshape(A, 16, -1)[:, :distinct]  # the solved (representative) items
        conv = int(np.sum(np.concatenate([np.asarray(o["converged"]) for o in outs], 1)
                          .reshape(A, 16, -1)[:, :distinct]))  # fmt: skip
        n_checks = int(refused.reshape(A, 16, -1)[:, :distinct].sum()) + 2 * conv
        free = int(ok.reshape(A, 16, -1)[:, :distinct].sum())  # collision-free solutions
        print(f"{name:8} {meds:7.2f} ({los:.2f}-{his:.2f}) {ok.mean():8.3f} "
              f"{rows.mean():11.2f} {rows.max():5d} {np.mean(rows == 1):7.2f} "
              f"{refused.reshape(A, 16, -1)[:, :distinct].mean():13.2f} {n_checks:8d} "
              f"{n_checks * check_ms / 1e3:9.3f} {free / meds:14.0f}")  # fmt: skip
    print("seeds/item: seeds tried per (arm, distinct design, target), most: at one; 1 seed: the share "
          "solved (or given up) with its first; checks: collision checks of converged seeds "
          "(the refused ones, and twice each kept one: in the loop and afresh at the end), "
          "× the unit cost = checks s; free solves/s: the collision-free solutions of the "
          "distinct designs' items per second of the block")  # fmt: skip


if __name__ == "__main__":
    main()
