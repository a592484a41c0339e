"""The README's main job, timed as a new user meets it: cold compilation cache, then warm.

Each repeat runs ``designopt run configs/master9.yaml --out <tmp>`` (figures included)
twice as a subprocess with ``DESIGNOPT_CACHE_DIR`` set to a fresh, empty folder: first cold,
then warm (same folder). It prints the stages (start-up, setup, optimizer, scoring/polish,
archive, figures, exit; compile time and XLA compilations from the run's summary line),
the end-to-end wall time, the figures redrawn by ``designopt report`` (whole process, and
after imports in-process), and the ratio of end-to-end time to the arithmetic-only time
(optimizer + scoring/polish with compile time excluded, from the archive's attributes).

    python benchmarks/main_job.py [--repeat 2] [--config configs/master9.yaml]
        [--set optimizer.objective_program=fused] [--no-report]

``--set KEY=VALUE`` (repeatable) runs a copy of the config with that dotted key set (the
value read as YAML), written beside the temporary archives (a config that names files
relative to its folder needs them there too); ``--no-report`` skips the ``designopt
report`` timings.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_LAST: dict[str, float] = {}  # CPU time and load average around the last subprocess
TARGETS = {"cold": 10.0, "warm": 5.0, "report": 3.0}  # seconds, on 2 cores (issues #14, #27)
SUMMARY = re.compile(
    r"wall (?P<total>[\d.]+) s end to end = start-up (?P<startup>[\d.]+) s \+ setup "
    r"(?P<setup>[\d.]+) s \+ optimizer (?P<optimizer>[\d.]+) s \+ scoring (?P<post>[\d.]+) s "
    r"\+ figures (?P<figures>[\d.]+) s \+ archive and the rest (?P<rest>[\d.]+) s; compile "
    r"(?P<compile>[\d.]+) s of it \((?P<n>\d+) XLA programs\)"
)
REPORT_AFTER_IMPORTS = """
import sys, time
from pathlib import Path
from designopt.app import pipeline
from designopt.core.timing import Stopwatch
import designopt.figures, designopt.studies.master9.figures  # noqa: F401 (imports first)
with Stopwatch() as sw:
    pipeline.draw_figures(Path(sys.argv[1]))
print(f"{sw.wall} {sw.compile} {sw.compilations}")
"""


def _cli() -> list[str]:
    exe = Path(sys.executable).with_name("designopt")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "designopt.cli"]


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _timed_lines(cmd: list[str], env: dict[str, str]) -> tuple[float, list[tuple[float, str]]]:
    """Run cmd; return (wall s, [(seconds since start, line)]) of its stdout and stderr."""
    _LAST["cpu0"], _LAST["load0"] = _cpu(), os.getloadavg()[0]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)  # fmt: skip
    lines = [(time.perf_counter() - t0, ln.rstrip("\n")) for ln in p.stdout]
    rc = p.wait()
    wall = time.perf_counter() - t0
    _LAST["cpu"], _LAST["load"] = _cpu() - _LAST["cpu0"], max(_LAST["load0"], os.getloadavg()[0])
    if rc != 0:
        sys.exit(f"{' '.join(cmd)} failed ({rc}):\n" + "\n".join(ln for _, ln in lines[-20:]))
    return wall, lines


def one_run(config: str, out: Path, cache: Path) -> dict[str, float]:
    """The main job once, figures included, with the given compilation cache folder."""
    from designopt.io import archive

    env = os.environ | {"DESIGNOPT_CACHE_DIR": str(cache), "PYTHONUNBUFFERED": "1"}
    e2e, lines = _timed_lines([*_cli(), "run", config, "--out", str(out), "--quiet"], env)
    cpu, load = _LAST["cpu"], _LAST["load"]
    m = next((SUMMARY.search(ln) for _, ln in lines if SUMMARY.search(ln)), None)
    if m is None:
        sys.exit("no summary line in the run's output:\n" + "\n".join(ln for _, ln in lines))
    s = {k: float(v) for k, v in m.groupdict().items()}
    at = archive.read(out)["attrs"]
    by_stage = at.get("compile_time_by_stage")  # per-stage compile time, where archived
    pso_post_compile = (by_stage["optimizer"] + by_stage["scoring_polish"] if by_stage
                        else at["compile_time_s"])  # else all of it: a lower bound  # fmt: skip
    # a lower bound at most: with the whole compile time subtracted it can reach 0 (no ratio)
    arith = at["optimizer_time_s"] + at["post_time_s"] - pso_post_compile
    return {
        "end_to_end": e2e,
        "startup": s["startup"],  # Python, imports, the config
        "setup": s["setup"],
        "optimizer": s["optimizer"],
        "scoring_polish": s["post"],
        "compile": s["compile"],
        "compilations": s["n"],
        "figures": s["figures"],
        "exit": e2e - s["total"] + s["rest"],  # archive, printing, the process's exit
        "arithmetic": max(arith, 0.0),
        "ratio": e2e / arith if arith > 0.05 else float("nan"),
        "exact_arithmetic": float(by_stage is not None),
        "cpu": cpu,  # user + system seconds of the run's process (all its threads)
        "load": load,  # 1-minute load average, the larger of before and after
    }


def report_times(out: Path, cache: Path) -> dict[str, float]:
    """``designopt report`` on the archive: whole process, and after imports in-process."""
    env = os.environ | {"DESIGNOPT_CACHE_DIR": str(cache)}
    whole, _ = _timed_lines([*_cli(), "report", str(out)], env)
    r = subprocess.run([sys.executable, "-c", REPORT_AFTER_IMPORTS, str(out)], cwd=ROOT,
                       env=env, capture_output=True, text=True, check=True)  # fmt: skip
    wall, comp, n = r.stdout.split()[-3:]
    return {"report_process": whole, "report": float(wall), "report_compile": float(comp),
            "report_compilations": float(n)}  # fmt: skip


def _spread(vals: list[float]) -> str:
    if len(vals) == 1:
        return f"{vals[0]:7.2f}"
    return f"{statistics.median(vals):7.2f} (min {min(vals):.2f}, max {max(vals):.2f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="configs/master9.yaml")
    ap.add_argument("--repeat", type=int, default=2, help="cold + warm pairs (default 2)")
    ap.add_argument("--keep", action="store_true", help="keep the temp folder")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="run a copy of the config with this dotted key set (repeatable)")  # fmt: skip
    ap.add_argument("--no-report", action="store_true", help="skip the report timings")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="designopt_main_job_"))
    if args.set:
        import yaml

        from designopt.app.config import set_key

        raw = yaml.safe_load((ROOT / args.config).read_text())
        for kv in args.set:
            k, _, v = kv.partition("=")
            set_key(raw, k, yaml.safe_load(v))
        args.config = str(tmp / Path(args.config).name)
        Path(args.config).write_text(yaml.safe_dump(raw, sort_keys=False))
        print(f"config {args.config}: {', '.join(args.set)}")
    res: dict[str, list[dict[str, float]]] = {"cold": [], "warm": []}
    try:
        for r in range(args.repeat):
            cache = tmp / f"cache{r}"  # fresh and empty: the first run is cold
            cache.mkdir()
            for phase in ("cold", "warm"):
                out = tmp / f"{phase}{r}" / "m9.h5"
                d = one_run(args.config, out, cache)
                if not args.no_report:
                    d |= report_times(out, cache)
                d["cache_mb"] = sum(f.stat().st_size for f in cache.rglob("*") if f.is_file()) / 1e6
                res[phase].append(d)
                rep = "" if args.no_report else f", report {d['report']:.2f} s"
                print(f"[{r + 1}/{args.repeat}] {phase}: end to end {d['end_to_end']:.1f} s, "
                      f"compile {d['compile']:.1f} s ({d['compilations']:.0f} programs), figures "
                      f"{d['figures']:.1f} s{rep}", flush=True)  # fmt: skip
    finally:
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)
    plat = os.environ.get("JAX_PLATFORMS") or "JAX's default platform"
    print(f"\n{args.config}, {os.cpu_count()} CPU cores, {plat}, {args.repeat} repeat(s); "
          "seconds, median (min, max)")  # fmt: skip
    rows = [("start-up (imports, config, archive write)", "startup"), ("setup", "setup"),
            ("optimizer", "optimizer"), ("scoring/polish", "scoring_polish"),
            ("  of which compile (all stages)", "compile"), ("XLA compilations", "compilations"),
            ("figures (in the run)", "figures"), ("exit", "exit"),
            ("END TO END", "end_to_end"), ("  CPU time of the run (user + sys)", "cpu"),
            ("  load average around the run", "load"), ("arithmetic only (PSO + scoring)", "arithmetic"),
            ("ratio end to end / arithmetic", "ratio"),
            ("report: whole process", "report_process"),
            ("report: after imports", "report"), ("  of which compile", "report_compile"),
            ("compilation cache (MB)", "cache_mb")]  # fmt: skip
    rows = [(label, k) for label, k in rows if k in res["cold"][0]]  # --no-report: fewer
    print(f"{'stage':<44}{'cold':<34}{'warm':<34}")
    for label, k in rows:
        print(f"{label:<44}" + "".join(f"{_spread([d[k] for d in res[p]]):<34}"
                                       for p in ("cold", "warm")))  # fmt: skip
    if not all(d["exact_arithmetic"] for d in res["cold"]):
        print("(arithmetic = optimizer + scoring/polish − the run's whole compile time: the "
              "archive has no per-stage compile time, so this is a lower bound)")  # fmt: skip
    print(f"\ntargets (2 cores): cold ≤ {TARGETS['cold']:g} s, warm ≤ {TARGETS['warm']:g} s end "
          f"to end, report ≤ {TARGETS['report']:g} s after imports")  # fmt: skip
    for phase, key, tgt in (("cold", "end_to_end", "cold"), ("warm", "end_to_end", "warm"),
                            ("warm", "report", "report")):  # fmt: skip
        if key not in res[phase][0]:
            continue
        med = statistics.median(d[key] for d in res[phase])
        ok = "met" if med <= TARGETS[tgt] else "MISSED"
        stages = {k: statistics.median(d[k] for d in res[phase])
                  for k in ("startup", "setup", "optimizer", "scoring_polish", "figures")}  # fmt: skip
        worst = max(stages, key=stages.get)
        print(f"  {tgt:<6} {med:6.2f} s vs ≤ {TARGETS[tgt]:.0f} s: {ok}"
              + (f"; largest stage: {worst} ({stages[worst]:.1f} s)" if ok == "MISSED" and
                 key == "end_to_end" else ""))  # fmt: skip


if __name__ == "__main__":
    main()
