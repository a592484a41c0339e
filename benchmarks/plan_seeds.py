"""The same plan from any seed? (issue #66's check "any seed")

Runs a planning config as shipped (``designopt run CONFIG --seed s --no-figures``) at
each ``--seed``, timing each run end to end, and reads each run's answer from its
archive: the final stage's verdict, the designs it calls *best* or *equivalent* (a tied
set), or the front's designs where the run had no race. The answers are pooled, and every
pooled design is scored at ``--check`` common seeds (``designopt.evaluate``, the study's
own settings, ``--samples`` targets per seed; the seeds start at 1000, apart from the
runs' and the race's). For every seed's answer and every pooled design P it asks: does
the answer hold a design A not worse than P by more than max(margin, 2 paired SE) in any
objective (the margins of ``final.margin``, else its documented defaults; the paired SE
from the spread of A − P over the common seeds)? The check passes when every answer
covers every pooled design.

    python benchmarks/plan_seeds.py                                # the shipped planning case
    python benchmarks/plan_seeds.py --seed 0 --seed 1 --seed 2 --check 8
    python benchmarks/plan_seeds.py --config my_case.yaml --json out.json
    python benchmarks/plan_seeds.py --keep runs/ --also other/run_1.h5   # a stricter pool
    python benchmarks/plan_seeds.py --panda --keep panda/   # two 7-joint Pandas instead

``--panda`` writes the planning case with each UR5 replaced by a Franka Panda (7 joints,
Franka's kinematics with a 0.3 m straight instrument: benchmarks/se_honesty.py's URDF)
into the ``--keep`` folder (else a temporary one) and checks that.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def answer(path: Path) -> tuple[list[str], np.ndarray, list[str], dict]:
    """(variables, the answer's designs (k, D), their verdicts, the front's objectives
    {name: sense}) of one run's archive."""
    import designopt

    rec = designopt.load(path)
    names = list(rec.names)
    g = rec.groups.get("verdict") if hasattr(rec, "groups") else None
    pareto = getattr(rec.config.study, "pareto", None) or {}
    senses = {k: (v if isinstance(v, str) else next(iter(v))) for k, v in pareto.items()}
    if g:
        verdict = [v.decode() if isinstance(v, bytes) else str(v) for v in np.asarray(g["verdict"])]
        X = np.atleast_2d(np.asarray(g["x"], np.float64))
        keep = [i for i, v in enumerate(verdict) if v in ("best", "equivalent")]
        return names, X[keep], [verdict[i] for i in keep], senses
    X = np.atleast_2d(np.asarray(rec.X, np.float64))
    return names, X, ["front"] * len(X), senses


def panda_case(folder: Path) -> Path:
    """The shipped planning case with two Pandas (module docstring), written into
    ``folder``: its URDF and config (the mesh files by absolute path)."""
    import yaml
    from se_honesty import panda_urdf

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "panda.urdf").write_text(panda_urdf())
    raw = yaml.safe_load((ROOT / "configs/port_placement.yaml").read_text())
    st = raw["study"]
    st["chain"] = {"urdf": str(folder / "panda.urdf"), "base": "panda_link0",
                   "tip": "instrument_tip"}  # fmt: skip
    st["collision"]["radius"] = [0.06] * 6 + [0.004]  # the last: link 7 to the tip, the shaft
    for ob in st["collision"]["obstacles"]:
        if "file" in ob:
            ob["file"] = str(ROOT / "configs" / ob["file"])
    raw["output"] = str(folder / "panda_placement.h5")
    path = folder / "panda_placement.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default=str(ROOT / "configs/port_placement.yaml"))
    ap.add_argument("--seed", action="append", type=int, help="a run's seed (repeat); 0, 1, 2")
    ap.add_argument("--check", type=int, default=8, help="common seeds for the check (8)")
    ap.add_argument("--samples", type=int, default=256, help="targets per check seed (256)")
    ap.add_argument("--json", help="also write the numbers here")
    ap.add_argument("--keep", help="keep the runs' archives in this folder and reuse them")
    ap.add_argument("--also", action="append", default=[],
                    help="another run's archive (repeat): its answer joins the pool as a "
                         "design to cover (a stricter check), but need not cover itself")
    ap.add_argument("--panda", action="store_true",
                    help="check the planning case with two Franka Pandas (module docstring)")
    a = ap.parse_args(argv)
    seeds = a.seed or [0, 1, 2]
    if a.panda:
        a.config = str(panda_case(Path(a.keep or tempfile.mkdtemp())))
    for path in a.also:
        if not Path(path).is_file():
            print(f"plan_seeds: --also {path}: no such archive", file=sys.stderr)
            return 2
    import designopt

    cfg0 = designopt.load_config(a.config)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load "
          f"{load:.1f}; {a.config}; runs at seeds {seeds}")  # fmt: skip
    out: dict = {"seeds": seeds, "runs": {}}
    answers = {}
    with tempfile.TemporaryDirectory() as tmp:
        for s in seeds:
            h5 = Path(a.keep or tmp) / f"run_{s}.h5"
            t = time.perf_counter()
            if h5.exists():
                print(f"seed {s}: reusing {h5}")
            r = subprocess.CompletedProcess([], 0) if h5.exists() else subprocess.run([sys.executable, "-m", "designopt", "run", a.config, "--seed",
                                str(s), "--no-figures", "--quiet", "--out", str(h5)],
                               capture_output=True, text=True, cwd=ROOT)  # fmt: skip
            wall = time.perf_counter() - t
            if r.returncode != 0:
                print(r.stdout[-2000:], r.stderr[-2000:])
                return 1
            names, X, verdict, senses = answer(h5)
            answers[s] = X
            print(f"seed {s}: {wall:.1f} s end to end (a fresh process); its answer: {len(X)} design(s) ("
                  + ", ".join(sorted(set(verdict))) + ")")  # fmt: skip
            for x, v in zip(X, verdict, strict=True):
                print("    " + ", ".join(f"{n}={val:.4f}" for n, val in zip(names, x, strict=True))
                      + f"  [{v}]")  # fmt: skip
            out["runs"][s] = {"wall_s": wall, "X": X.tolist(), "verdict": verdict}
    extra = []
    for path in a.also:  # reference answers: pooled, not judged
        names, X, verdict, senses = answer(Path(path))
        extra.append(X)
        print(f"also {path}: {len(X)} design(s) ({', '.join(sorted(set(verdict)))}) join the pool")
    out["also"] = list(a.also)
    pool = np.unique(np.round(np.concatenate(list(answers.values()) + extra), 12), axis=0)
    objs = list(senses)
    sign = np.array([1.0 if senses[k] == "max" else -1.0 for k in objs])
    margins = cfg0.final.margin or {}
    shares = {"arms_ok", "arms_free", "instrument_ok", "reach", "reach_all", "collision_free"}
    marg = np.array([float(margins.get(k, cfg0.final.SHARE_MARGIN if k in shares
                                       or k.startswith("reach_") else cfg0.final.MARGIN))
                     for k in objs])  # fmt: skip
    print(f"\n{len(pool)} pooled designs scored at {a.check} common seeds × {a.samples} targets")
    V = np.zeros((a.check, len(pool), len(objs)))
    for c in range(a.check):
        cfg = designopt.load_config(a.config, {"seed": 1000 + c,
                                               "study.indices.n_samples": a.samples})
        res = designopt.evaluate(cfg, [dict(zip(names, x, strict=True)) for x in pool])
        V[c] = np.stack([np.asarray(res[k], np.float64) for k in objs], -1) * sign
    mean = V.mean(0)
    for i, x in enumerate(pool):
        print(f"  P{i}: " + ", ".join(f"{n}={v:.4f}" for n, v in zip(names, x, strict=True))
              + "  " + ", ".join(f"{k} {m * sg:.4f}" for k, m, sg in
                                 zip(objs, mean[i], sign, strict=True)))  # fmt: skip
    idx = {tuple(np.round(x, 12)): i for i, x in enumerate(pool)}
    ok_all = True
    for s, X in answers.items():
        mine = [idx[tuple(np.round(x, 12))] for x in X]
        lines = []
        for p in range(len(pool)):
            best = None
            for i in mine:  # A covers P: A − P ≥ −max(margin, 2 SE) in every objective
                d = V[:, i] - V[:, p]
                se = d.std(0, ddof=1) / np.sqrt(a.check) if a.check > 1 else np.zeros(len(objs))
                slack = d.mean(0) + np.maximum(marg, 2 * se)
                if np.all(slack >= 0):
                    best = i
                    break
            if best is None:
                lines.append(f"P{p} not covered")
        ok_all &= not lines
        print(f"seed {s}'s answer (P{', P'.join(map(str, mine))}): "
              + ("covers every pooled design" if not lines else "; ".join(lines)))  # fmt: skip
        out["runs"][s]["covers"] = not lines
    print("\nany seed: " + ("every answer covers the pooled designs" if ok_all
                            else "an answer misses a pooled design"))  # fmt: skip
    out |= {"pool": pool.tolist(), "mean": (mean * sign).tolist(), "margins": marg.tolist(),
            "objectives": objs, "covers": bool(ok_all)}  # fmt: skip
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
