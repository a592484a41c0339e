"""Regenerate the example figures of docs/figures.md (docs/img/fig_*.png).

Every shipped config is run at reduced sample counts (a few minutes on 2 cores in all),
its archive written under ``--work`` (default ``/tmp/designopt_figures``), its figures drawn
beside it, and one figure per study copied into ``docs/img``::

    python docs/make_figures.py                 # every config, then copy the examples
    python docs/make_figures.py --only rcm_eta  # one config (names: CONFIGS below)
    python docs/make_figures.py --no-copy       # draw only (look at them under --work)

The figures of an existing archive are redrawn with ``designopt report ARCHIVE``.
"""

from __future__ import annotations

import argparse
import copy
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]

# config name -> (command, overrides merged into the YAML: small sample counts; for
# `view`, the command's arguments)
OPT = {"n_particles": 8, "n_iters": 6, "n_runs": 2}
CONFIGS: dict[str, tuple[str, dict | list]] = {
    "davinci": ("run", {"study": {"indices": {"n_samples": 512, "n_ik": 64}}, "optimizer": OPT}),
    "davinci_wrist": (
        "scan",
        {
            "study": {"indices": {"n_samples": 512, "n_ik": 64}},
            "scan": {"vary": {"l_IJ": {"num": 8}, "beta_deg": {"num": 5}}, "batch": 40},
        },
    ),  # fmt: skip
    "master9": (
        "run",
        {"study": {"indices": {"n_samples": 8192}, "n_norm": 8}, "optimizer": OPT},
    ),  # fmt: skip
    "planar2r": ("run", {"study": {"indices": {"n_samples": 4000}}, "optimizer": OPT}),
    "planar2r_scan": (
        "scan",
        {"study": {"indices": {"n_samples": 4000}}, "scan": {"vary": {"l2": {"num": 25}}}},
    ),  # fmt: skip
    "plas": ("run", {"study": {"mismatch": {"n_samples": 512, "n_path": 4}}, "optimizer": OPT}),
    "plas_scan": (
        "scan",
        {
            "study": {"mismatch": {"n_samples": 512, "n_path": 4}},
            "scan": {"vary": {"a2p": {"num": 9}, "d6": {"num": 8}}, "batch": 72},
        },
    ),  # fmt: skip
    "puma560": (
        "run",
        {"study": {"indices": {"n_samples": 4096}, "objective": {"n_norm": 8}}, "optimizer": OPT},
    ),  # fmt: skip
    "puma560_scan": (
        "scan",
        {
            "study": {"indices": {"n_samples": 4096}, "objective": {"n_norm": 8}},
            "scan": {"vary": {"a2": {"num": 6}, "d4": {"num": 6}}},
        },
    ),  # fmt: skip
    "rcm": ("run", {"study": {"eta": {"n_samples": 8192}}, "optimizer": OPT}),
    "rcm_eta": (
        "scan",
        {"study": {"eta": {"n_samples": 8192}}, "scan": {"vary": {"c": {"num": 41}}, "batch": 41}},
    ),  # fmt: skip
    "rcm_eta_axis": (
        "scan",
        {"study": {"eta": {"n_samples": 8192}}, "scan": {"vary": {"c": {"num": 41}}, "batch": 41}},
    ),  # fmt: skip
    "rcm_teleop": ("run", {}),
    "urdf_puma560_task": (
        "run",
        {"study": {"indices": {"n_samples": 256}, "task": {"ik": {"n_db": 512}}}, "optimizer": OPT},
    ),  # fmt: skip
    "urdf_mesh_arm": ("view", ["--design", "l_upper=0.4", "--q", "30,40,0.05"]),
    "sweep_ptpso": (
        "sweep",
        {
            "study": {"indices": {"n_samples": 2048}, "n_norm": 8},
            "optimizer": {"n_particles": 8, "n_iters": 6, "n_runs": 2},
        },
    ),  # fmt: skip
    "pso_benchmark": (
        "bench",
        {
            "bench": {
                "dim": 10,
                "n_iters": 200,
                "n_runs": 8,
                "variants": ["p1", "p3", "p5", "cmaes"],
            }
        },
    ),  # fmt: skip
}

# one example per study: (config name, figure file) -> docs/img/fig_<study>.png
EXAMPLES = {
    "master9": ("master9", "fig13_dexterity_maps.png"),
    "davinci": ("davinci", "workspace.png"),
    "plas": ("plas", "mismatch_map.png"),
    "rcm": ("rcm", "eta_c.png"),
    "rcm_teleop": ("rcm_teleop", "teleop.png"),
    "serial": ("puma560", "dexterity_map.png"),
    "scan": ("rcm_eta", "scan_c.png"),
    "bench": ("pso_benchmark", "convergence_curves.png"),
    "task_robot": ("urdf_puma560_task", "task.png"),
    "workspace_robot": ("urdf_puma560_task", "workspace.png"),
    "robot_compare": ("urdf_puma560_task", "robot.png"),
    "view": ("urdf_mesh_arm", "urdf_mesh_arm.png"),
}


def merge(a: dict, b: dict) -> dict:
    """``a`` with ``b`` merged in, nested dicts key by key."""
    out = copy.deepcopy(a)
    for k, v in b.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def source(name: str) -> Path:
    return ROOT / "configs" / f"{name.removesuffix('_scan') if name.startswith(('planar2r', 'puma560')) else name}.yaml"  # fmt: skip


def generate(name: str, work: Path) -> Path:
    """Run config ``name`` small into ``work``; returns the folder of its figures."""
    cmd, over = CONFIGS[name]
    src = source(name)
    if cmd == "view":  # the robot as configured: one figure, beside nothing
        work.mkdir(parents=True, exist_ok=True)
        args = ["designopt", "view", str(src), *over, "--out", str(work / f"{name}.png")]
        subprocess.run(args, check=True)
        return work
    raw = merge(yaml.safe_load(src.read_text()), over)
    st = raw.get("study", {})
    if "trajectory" in st:  # relative to the config's folder
        st["trajectory"] = str((src.parent / st["trajectory"]).resolve())
    if "urdf" in st.get("chain", {}):  # the same
        st["chain"]["urdf"] = str((src.parent / st["chain"]["urdf"]).resolve())
    raw.pop("output", None)
    work.mkdir(parents=True, exist_ok=True)
    cfg = work / f"{name}.yaml"
    cfg.write_text(yaml.safe_dump(raw, sort_keys=False))
    out = work / f"{name}.h5"
    args = ["designopt", cmd, str(cfg), "--out", str(out), "--overwrite", "--quiet"]
    subprocess.run(args, check=True)
    return work if cmd == "bench" else work / f"{out.stem}_figures"  # bench: beside it


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--work", type=Path, default=Path("/tmp/designopt_figures"))
    p.add_argument("--only", nargs="*", choices=sorted(CONFIGS), default=None)
    p.add_argument("--no-copy", action="store_true")
    a = p.parse_args(argv)
    folders = {}
    for name in a.only or CONFIGS:
        folders[name] = generate(name, a.work)
        print(f"{name}: {folders[name]}")
    if not a.no_copy:
        img = ROOT / "docs" / "img"
        for study, (name, fig) in EXAMPLES.items():
            if name in folders and (folders[name] / fig).exists():
                shutil.copy(folders[name] / fig, img / f"fig_{study}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
