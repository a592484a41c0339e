"""The pre-flight memory estimate against the measured peak (issue #38 §4).

For each config: ``designopt run CONFIG --dry-run`` (the estimate it prints), then the
real run in a fresh subprocess, ``--no-figures --quiet --no-cache --out <tmp> --overwrite``
(figures are drawn in forked children, which would not count), whose peak resident set
is the kernel's ``ru_maxrss`` of that child (``os.wait4``; the same number as
``/usr/bin/time -v``'s "Maximum resident set size"). Prints config, estimate, measured
peak, their ratio and whether it is within 1.5× (either way), with the estimate's terms
(``designopt.app.preflight.memory``), the CPU model, core count, load and date. Memory,
not time, is measured: a busy machine slows the runs but barely moves their peaks
(XLA's compiler threads do: see docs/faults.md).

    python benchmarks/preflight.py                   # all (puma560_task: ~1.5-3 min)
    python benchmarks/preflight.py --quick           # without the task (IK) configs
    python benchmarks/preflight.py --only master9    # one config (repeatable)
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ("master9", "master9_front", "planar2r_front", "puma560_task", "urdf_puma560_task")
"""The main job, two fronts and the task (IK) study, DH and URDF (the last where present)."""
SLOW = ("puma560_task", "urdf_puma560_task")  # left out by --quick
TOLERANCE = 1.5
UNITS = {"B": 1, "kB": 1e3, "MB": 1e6, "GB": 1e9, "TB": 1e12, "PB": 1e15}
ESTIMATE = re.compile(r"pre-flight: about ([\d.]+) (B|kB|MB|GB|TB|PB) of memory")


def _cli() -> list[str]:
    return [sys.executable, "-m", "designopt"]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env


def estimate(config: Path, extra: list[str] = ()) -> float:
    """Bytes of the estimate ``run CONFIG --dry-run`` prints."""
    r = subprocess.run([*_cli(), "run", str(config), "--dry-run", *extra], capture_output=True,
                       text=True, env=_env(), cwd=ROOT)  # fmt: skip
    m = ESTIMATE.search(r.stdout + r.stderr)
    if r.returncode != 0 or m is None:
        raise RuntimeError(f"{config}: dry run failed ({r.returncode}): {r.stderr.strip()}")
    return float(m.group(1)) * UNITS[m.group(2)]


def peak(config: Path, out: Path, extra: list[str] = ()) -> tuple[float, float]:
    """(peak resident bytes, wall s) of the real run in a fresh subprocess."""
    cmd = [*_cli(), "run", str(config), "--no-figures", "--quiet", "--no-cache",
           "--out", str(out), "--overwrite", *extra]  # fmt: skip
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env(),
                         cwd=ROOT)  # fmt: skip
    err = p.stderr.read() if p.stderr else b""
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"{config}: run failed ({p.returncode}): {err.decode()[-400:]}")
    return usage.ru_maxrss * 1024.0, time.perf_counter() - t0  # ru_maxrss: KiB on Linux


def terms(config: Path) -> str:
    """The estimate's terms, MB, from designopt.app.preflight in this process."""
    try:
        from designopt.app.config import load
        from designopt.app.preflight import estimate as est
        from designopt.studies import get

        cfg = load(config)[0]
        parts = est(cfg, get(cfg.study.name)).parts
    except Exception as e:  # an older tree without Estimate.parts: say so, go on
        return f"({type(e).__name__})"
    return ", ".join(f"{k} {v / 1e6:.0f}" for k, v in parts.items() if v)


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", action="append", metavar="NAME",
                    help="a config name (configs/NAME.yaml); repeatable")  # fmt: skip
    ap.add_argument("--quick", action="store_true", help=f"leave out {', '.join(SLOW)}")
    a = ap.parse_args(argv)
    names = a.only or [n for n in CONFIGS if not (a.quick and n in SLOW)]
    sys.path.insert(0, str(ROOT))
    print(f"# pre-flight memory estimate vs measured peak RSS, "
          f"{datetime.datetime.now().isoformat(timespec='minutes')}")  # fmt: skip
    print(f"# CPU: {cpu_model()}, {os.cpu_count()} cores; load average "
          f"{os.getloadavg()[0]:.1f} at the start; Python {platform.python_version()}")  # fmt: skip
    print(f"{'config':<20} {'estimate':>9} {'peak':>9} {'ratio':>6} {'within':>7} "
          f"{'run s':>6}  estimate's terms (MB)")  # fmt: skip
    bad = 0
    with tempfile.TemporaryDirectory(prefix="preflight-") as tmp:
        for name in names:
            config = ROOT / "configs" / f"{name}.yaml"
            if not config.exists():
                print(f"{name:<20} (no configs/{name}.yaml here)")
                continue
            e = estimate(config)
            p, wall = peak(config, Path(tmp) / f"{name}.h5")
            r = e / p
            ok = 1 / TOLERANCE <= r <= TOLERANCE
            bad += not ok
            print(f"{name:<20} {e / 1e6:>6.0f} MB {p / 1e6:>6.0f} MB {r:>6.2f} "
                  f"{'yes' if ok else 'NO':>7} {wall:>6.0f}  {terms(config)}", flush=True)  # fmt: skip
    print(f"# load average {os.getloadavg()[0]:.1f} at the end; MB = 10^6 bytes")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
