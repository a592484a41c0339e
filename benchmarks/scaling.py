"""Strong and weak scaling of swarm scoring and of a PTPSO run over devices (docs/scaling.md).

Each layout runs in its own child process(es), since the device count must be fixed before
JAX starts: 1, 2 and 4 forced host devices in one process, and 2 processes × 1 and × 2
devices joined by jax.distributed (gloo). Efficiency is against the 1-device child of the
same invocation: strong = t1 / (n·tn) (fixed work), weak = t1 / tn (work ∝ n).

The workload is the master9 kernel (float32, the README's main job's study):
- score: f of M designs × 65,536 samples (8 chunks), designs split over the devices
  (``score/designs``) or sample chunks (``score/samples``); strong M = 256, weak M = 64·n;
- ptpso: 10 PTPSO iterations, 32 particles × 16,384 samples, runs split over the
  devices; strong 4 runs, weak n runs.

On a machine with P physical cores, forced host devices share those cores, so the speed-up
is at most about P (2 here): the table measures the engine's overhead and partitioning,
not a GPU node's speed-up.

    python benchmarks/scaling.py [--reps 5] [--layouts 1,2,4,2x1,2x2]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child(devices: int, procs: int, pid: int, coord: str | None, reps: int) -> None:
    """One process of a layout: time every workload, print JSON (process 0)."""
    from designopt.core import devices as dev

    dev.configure(devices, coord, procs if coord else None, pid if coord else None)
    import jax
    import jax.numpy as jnp
    import numpy as np

    from designopt import optim
    from designopt.app import pipeline
    from designopt.studies.master9.objective import problem as master9
    from designopt.studies.master9.settings import Master9Settings

    def problem(n_samples: int, chunk: int):
        s = Master9Settings.model_validate({"name": "master9", "n_norm": 8,
                                            "indices": {"n_samples": n_samples, "chunk": chunk}})  # fmt: skip
        return master9(s, dtype=jnp.float32)

    def timed(fn) -> list[float]:
        fn()  # compile
        out = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t0)
        return out

    n = len(jax.devices())
    P = devices.ParallelSettings
    res: dict[str, object] = {"devices": n, "processes": jax.process_count()}
    pr = problem(65_536, 8192)
    rng = np.random.default_rng(0)
    for mode, M in (("strong", 256), ("weak", 64 * n)):
        X = rng.uniform(pr.lower, pr.upper, (M, pr.dim))
        for axis in ("designs", "samples"):
            key = f"score/{axis}/{mode}"
            if n == 1:
                res[key] = timed(lambda X=X: pipeline.score(pr, X, batch=M))
            elif axis == "designs":
                pl = devices.scoring_plan(P(devices=n))
                res[key] = timed(lambda X=X, pl=pl: pipeline.score(pr, X, batch=M, plan=pl))
            else:
                pl = devices.plan(P(devices=n, axis="samples"), n_runs=1, n_particles=M,
                                   problem=pr)  # fmt: skip
                sp = pl.problem(pr)
                res[key] = timed(lambda X=X, sp=sp: pipeline.score(sp, X, batch=M))
    pr = problem(16_384, 16_384)
    k = jax.random.key(0)
    for mode, runs in (("strong", 4), ("weak", n)):
        kw = dict(n_particles=32, n_iters=10, n_runs=runs, dtype=jnp.float32, chunk_iters=10)
        pl = (
            devices.plan(P(devices=n, axis="runs"), n_runs=runs, n_particles=32) if n > 1 else None
        )
        res[f"ptpso/runs/{mode}"] = timed(
            lambda kw=kw, pl=pl: optim.run("ptpso", pr, k, plan=pl, **kw)
        )
    if n == 1:  # the kernel's flops per design-sample (one chunk, so no loop to count)
        one = problem(8192, 8192)
        X = jnp.asarray(rng.uniform(one.lower, one.upper, (64, one.dim)), jnp.float32)
        cost = jax.jit(one.fn).lower(one.params, X, k).compile().cost_analysis()
        cost = cost[0] if isinstance(cost, list) else cost
        res["flops_per_design_sample"] = float(cost["flops"]) / (64 * 8192)
    if jax.process_index() == 0:
        print("RESULT " + json.dumps(res), flush=True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def launch(layout: str, reps: int) -> dict:
    """Run one layout ('4': one process, 4 devices; '2x2': 2 processes × 2 devices)."""
    procs, per = (int(a) for a in layout.split("x")) if "x" in layout else (1, int(layout))
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    coord = f"127.0.0.1:{free_port()}" if procs > 1 else ""
    cmds = [[sys.executable, __file__, "--child", str(procs * per), str(procs), str(i), coord,
             str(reps)] for i in range(procs)]  # fmt: skip
    ps = [subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env=env, cwd=ROOT) for c in cmds]  # fmt: skip
    outs = [p.communicate(timeout=1800) for p in ps]
    for p, (_, err) in zip(ps, outs, strict=True):
        if p.returncode:
            raise SystemExit(f"layout {layout}: a child failed:\n{err[-3000:]}")
    line = next(ln for ln in outs[0][0].splitlines() if ln.startswith("RESULT "))
    return json.loads(line[7:])


def table(results: dict[str, dict]) -> list[str]:
    """Markdown rows: workload, layout, median time (min-max), speed-up, efficiency."""
    import numpy as np

    base = results["1"]
    rows = ["| workload | layout | devices | time s, median (min–max) | speed-up | efficiency |",
            "|---|---|---|---|---|---|"]  # fmt: skip
    for key in [k for k in base if "/" in k]:
        t1 = float(np.median(base[key]))
        for r in results.values():
            t = np.asarray(r[key])
            n = r["devices"]
            med = float(np.median(t))
            speed = t1 / med
            eff = speed / n if key.endswith("strong") else speed
            name = (
                f"{r['processes']} × {n // r['processes']}" if r["processes"] > 1 else "1 process"
            )
            rows.append(f"| {key} | {name} | {n} | {med:.3f} ({t.min():.3f}–{t.max():.3f}) | "
                        f"{speed:.2f}× | {100 * eff:.0f} % |")  # fmt: skip
    return rows


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        d, procs, pid, coord, reps = sys.argv[2:7]
        child(int(d), int(procs), int(pid), coord or None, int(reps))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--layouts", default="1,2,4,2x1,2x2")
    args = ap.parse_args()
    layouts = args.layouts.split(",")
    if layouts[0] != "1":
        layouts.insert(0, "1")
    results = {}
    before = os.getloadavg()[0]
    for lay in layouts:
        t0 = time.perf_counter()
        results[lay] = launch(lay, args.reps)
        print(f"# layout {lay}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    load = os.getloadavg()
    print(f"cores: {os.cpu_count()}; load average (1 min) before {before:.2f}, after "
          f"{load[0]:.2f}; reps {args.reps}")  # fmt: skip
    print(f"flops per design-sample (master9 f, XLA cost analysis): "
          f"{results['1']['flops_per_design_sample']:.0f}")  # fmt: skip
    print("\n".join(table(results)))


if __name__ == "__main__":
    main()
