"""The task's IK calls side by side on the CPU's cores (``designopt.core.concurrency``)
against one after the other, in the same run: a command run in fresh processes with
``DESIGNOPT_THREADS=1`` and with the default (one thread per core), interleaved, warm
(a first run fills a fresh compilation cache), then once each cold (an empty cache),
where the study's own IK program also compiles beside the search. It prints each
repeat's end to end, optimizer and scoring seconds, the medians, their ratio, and
whether the archives are the same bit for bit (they must be).

    python benchmarks/threads.py                                  # configs/port_placement.yaml
    python benchmarks/threads.py --repeat 3 --config configs/two_ur5_front.yaml --cold

Each row is one process; a loaded machine stretches both columns alike only when they
are interleaved, so compare within a run. The CPU, its vector extensions and the load
head the output."""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from latency import cpu  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SPLIT = re.compile(r"wall (?P<wall>[\d.]+) s end to end = .*optimizer (?P<opt>[\d.]+) s \+ "
                   r"scoring (?P<post>[\d.]+) s")  # fmt: skip


def once(config: str, threads: str, cache: str, out: Path) -> dict[str, float]:
    env = os.environ | {"DESIGNOPT_CACHE_DIR": cache, "DESIGNOPT_THREADS": threads}
    r = subprocess.run([sys.executable, "-m", "designopt", "run", config, "--out", str(out),
                        "--overwrite", "--no-figures", "--quiet"], cwd=ROOT, env=env,
                       capture_output=True, text=True)  # fmt: skip
    m = SPLIT.search(r.stdout + r.stderr)
    if r.returncode != 0 or m is None:
        raise SystemExit(f"designopt run {config} failed:\n{r.stdout}\n{r.stderr}")
    return {k: float(v) for k, v in m.groupdict().items()}


def same(a: Path, b: Path) -> bool:
    """Every dataset of two archives equal (NaN equal to NaN), bit for bit."""
    import h5py

    diff: list[str] = []
    with h5py.File(a) as fa, h5py.File(b) as fb:
        def visit(name: str, obj) -> None:
            if isinstance(obj, h5py.Dataset):
                x, y = np.asarray(obj[()]), np.asarray(fb[name][()])
                eq = np.array_equal(x, y, equal_nan=x.dtype.kind in "fc")
                if not eq:
                    diff.append(name)

        fa.visititems(visit)
    for name in diff:
        print(f"  differs: {name}")
    return not diff


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="configs/port_placement.yaml")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--cold", action="store_true", help="also one cold run each")
    args = ap.parse_args()
    n = os.environ.get("DESIGNOPT_THREADS_BENCH", str(len(os.sched_getaffinity(0))))
    print(f"== {args.config}: the IK's calls on {n} threads against 1 ==")
    print(f"CPU {cpu()}; load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        rows: dict[str, list[dict[str, float]]] = {"1": [], n: []}
        if args.cold:
            for th in ("1", n):
                r = once(args.config, th, str(t / f"cold{th}"), t / f"cold{th}.h5")
                print(f"cold, {th} thread(s): {r['wall']:.1f} s end to end (optimizer "
                      f"{r['opt']:.1f} s, scoring {r['post']:.1f} s)")  # fmt: skip
        cache = str(t / "cache")
        once(args.config, "1", cache, t / "fill.h5")
        for i in range(args.repeat):
            for th in ("1", n):
                r = once(args.config, th, cache, t / f"w{th}.h5")
                rows[th].append(r)
                print(f"warm #{i}, {th} thread(s): {r['wall']:.1f} s end to end (optimizer "
                      f"{r['opt']:.1f} s, scoring {r['post']:.1f} s)", flush=True)  # fmt: skip
        for k in ("wall", "opt", "post"):
            a = statistics.median(r[k] for r in rows["1"])
            b = statistics.median(r[k] for r in rows[n])
            print(f"median {k}: {a:.1f} s on 1 thread, {b:.1f} s on {n}: {a / b:.2f}×")
        print("archives the same bit for bit:", same(t / "w1.h5", t / f"w{n}.h5"))


if __name__ == "__main__":
    main()
