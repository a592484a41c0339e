"""Time to first result, as a new user meets it (issue #36): every shipped config's command
in a fresh process, first with an empty compilation cache (cold), then with the cache it
filled (warm).

For each command it prints one row: end to end (the process's wall time), start-up
(process start to the config loaded), compile (JAX tracing + XLA compiling of the whole
command, figures included, from its own summary, summed over the threads that compile),
XLA programs, run (end to end less start-up and compile: the arithmetic, drawing and
writing; ``-`` where that is negative: compiling ran beside the work, on another core, and
cannot be split off), figures (their wall time,
their compiling included), and the time to the first finished iteration (when the progress bar
first shows an iteration done: everything before it is start-up, set-up and compiling).
A ``run`` prints its own split (``wall … end to end = start-up … + figures …; compile …``);
``scan``, ``sweep`` and ``eval`` print their compile time; the other columns are then
``-``. The CPU model, its vector extensions, the load and the date head the table.

    python benchmarks/latency.py                   # every shipped config (about 30 min on 2 cores)
    python benchmarks/latency.py --only master9 --only puma560-eval
    python benchmarks/latency.py --list            # the commands it would run
    python benchmarks/latency.py --only davinci --programs 5   # and where the compile goes

``--programs N`` runs every command once more, cold, with ``JAX_LOG_COMPILES=1`` (the
logging costs a little: not in the table's rows) and prints its N programs with the
longest XLA compilation, and its tracing and lowering time in all.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent

# (name, command after `designopt`); {out} is a fresh output path of the repeat
COMMANDS: list[tuple[str, list[str]]] = [
    ("master9", ["run", "configs/master9.yaml", "--out", "{out}.h5"]),
    ("master9_front", ["run", "configs/master9_front.yaml", "--out", "{out}.h5"]),
    ("davinci", ["run", "configs/davinci.yaml", "--out", "{out}.h5"]),
    ("davinci_wrist", ["run", "configs/davinci_wrist.yaml", "--out", "{out}.h5"]),
    ("rcm", ["run", "configs/rcm.yaml", "--out", "{out}.h5"]),
    ("rcm_teleop", ["run", "configs/rcm_teleop.yaml", "--out", "{out}.h5"]),
    ("rcm_eta", ["scan", "configs/rcm_eta.yaml", "--out", "{out}.h5"]),
    ("plas", ["run", "configs/plas.yaml", "--out", "{out}.h5"]),
    ("plas_scan", ["scan", "configs/plas_scan.yaml", "--out", "{out}.h5"]),
    ("planar2r", ["run", "configs/planar2r.yaml", "--out", "{out}.h5"]),
    ("planar2r_front", ["run", "configs/planar2r_front.yaml", "--out", "{out}.h5"]),
    ("planar2r_task", ["run", "configs/planar2r_task.yaml", "--out", "{out}.h5"]),
    ("puma560", ["run", "configs/puma560.yaml", "--out", "{out}.h5"]),
    ("puma560_task", ["run", "configs/puma560_task.yaml", "--out", "{out}.h5"]),
    ("urdf_arm", ["run", "configs/urdf_arm.yaml", "--out", "{out}.h5"]),
    ("urdf_puma560", ["run", "configs/urdf_puma560.yaml", "--out", "{out}.h5"]),
    ("urdf_puma560_task", ["run", "configs/urdf_puma560_task.yaml", "--out", "{out}.h5"]),
    ("urdf_puma560_front", ["run", "configs/urdf_puma560_front.yaml", "--out", "{out}.h5"]),
    ("urdf_puma560_port", ["run", "configs/urdf_puma560_port.yaml", "--out", "{out}.h5"]),
    ("two_arms_front", ["run", "configs/two_arms_front.yaml", "--out", "{out}.h5"]),
    ("two_ur5_front", ["run", "configs/two_ur5_front.yaml", "--out", "{out}.h5"]),
    ("port_placement", ["run", "configs/port_placement.yaml", "--out", "{out}.h5"]),
    ("urdf_mesh_arm", ["run", "configs/urdf_mesh_arm.yaml", "--out", "{out}.h5"]),
    ("sweep_ptpso", ["sweep", "configs/sweep_ptpso.yaml", "--out", "{out}.h5"]),
    ("mo_benchmark", ["bench", "configs/mo_benchmark.yaml", "--out", "{out}.h5"]),
    ("puma560-eval", ["eval", "configs/puma560.yaml", "--design", "a2=0.4", "d4=0.4"]),
    ("urdf_puma560_task-eval", ["eval", "configs/urdf_puma560_task.yaml", "--design",
                                "a2=0.4318", "d4=0.4318"]),
    ("urdf_puma560_view", ["view", "configs/urdf_puma560_task.yaml", "--out", "{out}.png"]),
    ("urdf_puma560_port-eval", ["eval", "configs/urdf_puma560_port.yaml", "--design",
                                "a2=0.43", "d4=0.43", "l_tool=0.4"]),
    ("urdf_puma560_port-moved", ["eval", "configs/urdf_puma560_port.yaml", "--design",
                                 "a2=0.43", "d4=0.43", "l_tool=0.4",
                                 "--set", "study.task.port=[0.51,0.11,-0.2]"]),
    ("port_placement-eval", ["eval", "configs/port_placement.yaml", "--design",
                             "b=0.6,by=0,px=0.03,py0=0,py1=0"]),
    ("port_placement-compare", ["eval", "configs/port_placement.yaml", "--design",
                                "b=0.6,by=0,px=0.03,py0=0,py1=0", "--design",
                                "b=0.5085,by=-0.018,px=0.021,py0=-0.119,py1=0.126"]),
    ("port_placement-show", ["show", "{tmp}/port_placement-warm.h5"]),
    ("port_placement_mesh", ["run", "configs/port_placement.yaml", "--set",
                             "study.task.body_wall={{shape: mesh, file: data/abdomen.stl}}",
                             "--out", "{out}.h5"]),
]  # fmt: skip
"""The shipped configs' commands (`pso_benchmark.yaml` runs for minutes: not here)."""
EDITS = {"urdf_puma560_port-moved": "urdf_puma560_port-eval",
         "port_placement-compare": "port_placement-eval",
         "port_placement-show": "port_placement"}
"""A scene edit (``--set``) run once with the cache of the command it edits (which must
run first): what editing the scene costs after one warm run; likewise the paired
comparison of two layouts after one layout's ``eval``, and ``show`` of the planning run's
warm archive (``{tmp}``: the folder of the rows' outputs)."""

END_TO_END = re.compile(
    r"wall (?P<wall>[\d.]+) s end to end = start-up (?P<startup>[\d.]+) s .*figures "
    r"(?P<figures>[\d.]+) s .*compile (?P<compile>[\d.]+) s (?:of it|summed over threads) "
    r"\((?P<n>\d+) XLA programs\)"
)
COMPILE = re.compile(r"compile (?P<compile>[\d.]+) s")
PROGRAMS = re.compile(r"\((?P<n>\d+) XLA programs\)")
LOGGED = re.compile(
    r"Finished (?P<what>XLA compilation of|tracing|jaxpr to MLIR module conversion) "
    r"(?P<name>\S+).* in (?P<s>[\d.e+-]+) sec"
)
FIRST_ITERATION = re.compile(r":\s+\d+%\|[^|]*\|\s*(?P<n>\d+)/\d+")


def cpu() -> str:
    """The CPU model and its widest vector extension (they change the arithmetic)."""
    model, flags = "unknown CPU", set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name") and model == "unknown CPU":
                model = line.split(":", 1)[1].strip()
            if line.startswith("flags"):
                flags = set(line.split(":", 1)[1].split())
    except OSError:
        pass
    ext = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "no AVX2"
    return f"{model} ({ext}), {os.cpu_count()} cores"


def _stream(pipe, t0: float, out: list[tuple[float, str]]) -> None:
    """Lines of a pipe with their time since t0, split at \\n and at tqdm's \\r."""
    buf = ""
    for ch in iter(lambda: pipe.read(1), ""):
        if ch in "\r\n":
            if buf:
                out.append((time.perf_counter() - t0, buf))
            buf = ""
        else:
            buf += ch
    if buf:
        out.append((time.perf_counter() - t0, buf))


def one(argv: list[str], cache: Path, out: str, log: bool = False) -> dict[str, Any]:
    """One command in a fresh process with ``cache`` as its compilation cache (``log``:
    with JAX's compile log, its lines in ``row["log"]``)."""
    env = dict(os.environ, DESIGNOPT_CACHE_DIR=str(cache), PYTHONUNBUFFERED="1")
    if log:
        env["JAX_LOG_COMPILES"] = "1"
    exe = Path(sys.executable).with_name("designopt")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "designopt.cli"]
    cmd += [a.format(out=out, tmp=str(Path(out).parent)) for a in argv] + (
        ["--overwrite"] if argv[0] not in ("eval", "view", "show") else []
    )
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)  # fmt: skip
    lines: list[tuple[float, str]] = []
    errs: list[tuple[float, str]] = []
    threads = [threading.Thread(target=_stream, args=(p.stdout, t0, lines)),
               threading.Thread(target=_stream, args=(p.stderr, t0, errs))]  # fmt: skip
    for t in threads:
        t.start()
    rc = p.wait()
    wall = time.perf_counter() - t0
    for t in threads:
        t.join()
    if rc != 0:
        tail = "\n".join(ln for _, ln in (lines + errs)[-15:])
        raise SystemExit(f"{' '.join(cmd)} failed ({rc}):\n{tail}")
    row: dict[str, Any] = {"wall": wall, "log": [ln for _, ln in errs if "Finished" in ln]}
    text = "\n".join(ln for _, ln in lines)
    m = END_TO_END.search(text)
    if m:
        row |= {k: float(m[k]) for k in ("startup", "figures", "compile")} | {"n": int(m["n"])}
    elif argv[0] != "show":  # show prints the archived run's times, not its own
        c, n = COMPILE.search(text), PROGRAMS.search(text)
        if c:
            row["compile"] = float(c["compile"])
        if n:
            row["n"] = int(n["n"])
    first = next((t for t, ln in errs if (f := FIRST_ITERATION.search(ln)) and int(f["n"]) > 0),
                 None)  # fmt: skip
    if first is not None:
        row["first"] = first
    if "compile" in row:  # everything but starting and compiling: arithmetic, drawing, writing
        run = wall - float(row.get("startup", 0.0)) - float(row["compile"])
        if run >= 0.0:  # else the compiling overlapped the work: no such split
            row["run"] = run
    return row


def fmt(row: dict, k: str) -> str:
    v = row.get(k)
    return "-" if v is None else (f"{v:d}" if isinstance(v, int) else f"{v:.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", action="append", default=[], metavar="NAME",
                    help="only this command (repeat); names: --list")  # fmt: skip
    ap.add_argument("--list", action="store_true", help="print the commands and stop")
    ap.add_argument("--programs", type=int, default=0, metavar="N",
                    help="also a logged cold run of each: its N longest XLA compilations")  # fmt: skip
    args = ap.parse_args()
    todo = [(n, c) for n, c in COMMANDS if not args.only or n in args.only]
    if args.list or not todo:
        for n, c in COMMANDS:
            print(f"{n:<24} designopt {' '.join(c)}")
        return
    print(f"{cpu()}; load {os.getloadavg()[0]:.1f}; {time.strftime('%Y-%m-%d %H:%M')}")
    head = ["command", "cache", "end to end", "start-up", "compile", "programs", "run",
            "figures", "first iteration"]  # fmt: skip
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    keys = ("wall", "startup", "compile", "n", "run", "figures", "first")
    with tempfile.TemporaryDirectory(prefix="designopt-latency-") as tmp:
        for name, argv in todo:
            cache = Path(tmp) / f"cache-{name}"  # empty: the first run compiles everything
            edit = EDITS.get(name)
            if edit is not None:
                cache = Path(tmp) / f"cache-{edit}"
            for which in ("cold", "warm") if edit is None else ("edited",):
                row = one(argv, cache, str(Path(tmp) / f"{name}-{which}"))
                print(f"| {name} | {which} | " + " | ".join(fmt(row, k) for k in keys) + " |",
                      flush=True)  # fmt: skip
        for name, argv in todo if args.programs else ():
            row = one(argv, Path(tmp) / f"log-{name}", str(Path(tmp) / f"{name}-log"), log=True)
            print(f"\n{name}, cold, logged: {profile(row['log'], args.programs)}", flush=True)


def profile(lines: list[str], n: int) -> str:
    """The n programs with the longest XLA compilation (seconds, × how many of that name)
    and the tracing and lowering time in all, from JAX's compile log."""
    xla: dict[str, list[float]] = {}
    trace = 0.0
    for ln in lines:
        m = LOGGED.search(ln)
        if m and m["what"] == "XLA compilation of":
            xla.setdefault(m["name"], []).append(float(m["s"]))
        elif m:
            trace += float(m["s"])
    top = sorted(xla.items(), key=lambda kv: -sum(kv[1]))[:n]
    total = sum(sum(v) for v in xla.values())
    parts = ", ".join(f"{k} {sum(v):.1f}" + (f" ({len(v)}×)" if len(v) > 1 else "")
                      for k, v in top)  # fmt: skip
    return (
        f"XLA {total:.1f} s in {sum(len(v) for v in xla.values())} programs ({parts}); "
        f"tracing and lowering {trace:.1f} s"
    )


if __name__ == "__main__":
    main()
