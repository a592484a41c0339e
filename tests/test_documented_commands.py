"""Every command line the documentation shows runs in a test (#45): README.md, the site's
pages (docs/**/*.md; CHANGELOG.md is not one) and the headers of configs/*.yaml are read for command lines (code blocks, indented
blocks, inline code, YAML comments), and each one is

- run here as written (``SCENARIOS``), in a folder of its own that looks like the
  repository (``configs/`` with the shipped configs at small sample counts, their URDFs
  and data, ``docs/davinci_poses.csv`` and the poses files the docs name), so default
  paths (``results/<study>/...``, ``<config stem>_view.png``) are the ones a user gets;
  a synopsis with placeholders (``designopt report ARCHIVE --html``) runs as a concrete
  command that shows each of its flags;
- or named with the tests elsewhere that run its form (``ELSEWHERE``; those tests must
  exist and show each of its flags);
- or skipped with a reason (``SKIP``: installing, the test suite itself, the benchmark
  scripts' measurements).

A bare mention (``designopt show``, ``designopt report --html``) is covered when a command
of the tables has its subcommand and its flags. A command the docs gain without an entry
fails ``test_every_documented_command_is_run_elsewhere_or_skipped``; an entry whose
command left the docs fails ``test_no_entry_outlives_its_command``."""

from __future__ import annotations

import ast
import copy
import os
import re
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_ik_command import fk as puma_fk  # the PUMA 560's standard-DH FK in NumPy

from designopt.cli.commands import main

ROOT = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent
SELF = Path(__file__).name

# ------------------------------------------------------------------ reading the docs

START = re.compile(
    r"(?:srun\s+)?designopt\s+(?:[a-z][a-z|-]*|--version)\b"
    r"|(?:\.venv/bin/)?python3?\s+(?:-m\s+\S+|benchmarks/\S+|docs/\S+\.py)"
    r"|pip\s+install\b"
    r"|mkdocs\s+(?:serve|build)\b"
)
"""Where a command starts: ``designopt SUBCOMMAND``, ``designopt --version``, ``python
benchmarks/X.py``, ``python -m X``, ``python docs/X.py``, ``pip install``, ``mkdocs
serve|build``."""
STOP = re.compile(r"\s#|→|\s\(|&&|`|\s+&\s*$|;\s")
"""Where a command in a code line ends: a comment, an arrow, a parenthesis, ``&&``."""
SPAN = re.compile(r"(?<!`)`([^`\n]+(?:\n[^`\n]+)?)`(?!`)")
"""Inline code (may wrap onto the next line)."""


def _norm(text: str) -> str:
    return " ".join(text.replace("\\|", "|").split())


def _from_code(text: str) -> list[str]:
    out, pos = [], 0
    while m := START.search(text, pos):
        s = m.start()
        before = text[:s].split()
        if (s and not (text[s - 1].isspace() or text[s - 1] in ":;")) or (
            before and before[-1] in ("from", "import")
        ):
            pos = m.end()
            continue
        e = STOP.search(text, m.end())
        end = e.start() if e else len(text)
        out.append(_norm(text[s:end]).rstrip(" &"))
        pos = max(end, m.end())
    return out


def _from_span(span: str) -> list[str]:
    t = _norm(span)
    return [t] if START.match(t) and not t.startswith("designopt import") else []


def extract(path: Path) -> list[tuple[str, str]]:
    """(command, "file:line") for every command line ``path`` shows."""
    rel = path.relative_to(ROOT).as_posix()
    lines = path.read_text(encoding="utf-8").splitlines()
    found: list[tuple[str, int]] = []
    if path.suffix == ".yaml":  # the header comments
        for i, line in enumerate(lines, 1):
            if line.lstrip().startswith("#"):
                c = line.lstrip()[1:]
                found += [(x, i) for m in SPAN.finditer(c) for x in _from_span(m.group(1))]
                found += [(x, i) for x in _from_code(SPAN.sub(" ", c))]
        return [(c, f"{rel}:{i}") for c, i in found]
    fenced = False
    prose: list[tuple[int, str]] = []
    for i, line in enumerate(lines, 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        indented = line.startswith("    ") and START.match(line.strip())
        if fenced or indented:  # a code line, and inline code in it (a printed command)
            found += [(x, i) for x in _from_code(SPAN.sub(" ", line))]
            found += [(x, i) for m in SPAN.finditer(line) for x in _from_span(m.group(1))]
        else:
            prose.append((i, line))
    text = "\n".join(line for _, line in prose)
    for m in SPAN.finditer(text):
        i = prose[text.count("\n", 0, m.start())][0]
        found += [(x, i) for x in _from_span(m.group(1))]
    return [(c, f"{rel}:{i}") for c, i in found]


def doc_files() -> list[Path]:
    """README.md, every page of the site (docs/ and its folders; docs/changelog.md only
    includes CHANGELOG.md, which is not read: its entries name commands of the past) and
    the configs' headers."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
            *sorted((ROOT / "configs").glob("*.yaml"))]  # fmt: skip


def documented() -> dict[str, list[str]]:
    """Every documented command -> where it is shown."""
    out: dict[str, list[str]] = {}
    for f in doc_files():
        for cmd, where in extract(f):
            out.setdefault(cmd, []).append(where)
    return out


def flags(cmd: str) -> set[str]:
    return set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", cmd))


def subcommands(cmd: str) -> list[str]:
    words = cmd.split()
    i = words.index("designopt") + 1
    return words[i].split("|")


# ------------------------------------------------------------------ what runs here

# A scenario: commands run in order in one fresh folder (a later one may read what an
# earlier one wrote). A step is the documented command, run as written, or (documented
# synopsis, the concrete argv that runs it: every flag the synopsis shows).
SCENARIOS: list[tuple] = [
    # README "Quick start", docs/getting-started/main-job.md, docs/scaling.md,
    # docs/architecture.md (one scenario when two commands run the same program: one
    # folder, one compile)
    ("designopt run configs/master9.yaml",
     "designopt show results/master9/master9.h5",
     "designopt report results/master9/master9.h5 --html",
     "designopt run configs/master9.yaml --seed 4 --out results/m.h5"),
    # the version and the config reference (README, docs/reference/cli.md and config.md)
    ("designopt --version",),
    ("designopt config --keys optimizer",
     ("designopt config --keys PREFIX", "config --keys study.task.ik")),
    # the planar RCM mechanism, PLAS (README, docs/rcm.md, docs/plas.md, their configs)
    ("designopt run configs/rcm.yaml", "designopt report results/rcm/rcm.h5 --html"),
    ("designopt scan configs/rcm_eta.yaml",),
    ("designopt scan configs/rcm_eta_axis.yaml",),
    ("designopt run configs/rcm_teleop.yaml",),
    ("designopt eval configs/rcm.yaml --design a=120 --design c=250",),
    ("designopt run configs/plas.yaml",),
    ("designopt eval configs/plas.yaml --design a2p=138 --design d6=60 --json",),
    ("designopt scan configs/plas_scan.yaml",),
    # fronts (README "Pareto fronts", docs/pareto.md)
    ("designopt run configs/master9_front.yaml",
     "designopt report results/master9/master9_front.h5 --html"),
    ("designopt run configs/planar2r_front.yaml",),
    # serial chains (README "Your own arm", docs/task.md)
    ("designopt view configs/urdf_arm.yaml --design l_wrist=0.02",),
    ("designopt scan configs/planar2r.yaml",),
    ("designopt run configs/planar2r.yaml",),
    ("designopt eval configs/planar2r_task.yaml --design l1=1 --design l2=0.6",),
    ("designopt scan configs/planar2r_task.yaml",),
    ("designopt run configs/planar2r_task.yaml",
     ("designopt show ARCHIVE [--csv [PATH]]",
      "show results/planar2r_task/planar2r_task.h5 --csv results/targets.csv")),
    ("designopt eval configs/puma560_task.yaml --design a2=0.4318 --design d4=0.4318",),
    ("designopt run configs/puma560_task.yaml",),
    ("designopt eval configs/urdf_puma560_task.yaml --design a2=0.4318 d4=0.4318",),
    ("designopt run configs/urdf_puma560_task.yaml",),
    ("designopt run configs/urdf_puma560_front.yaml",
     "designopt report results/urdf_puma560_front/urdf_puma560_front.h5 --html"),
    ("designopt eval configs/urdf_puma560_port.yaml --design a2=0.43 d4=0.43 l_tool=0.4",),
    ("designopt run configs/urdf_puma560_port.yaml",),
    ("designopt eval configs/two_arms_front.yaml --design b=0.6 l2=0.45 l3=0.45",),
    ("designopt eval configs/two_ur5_front.yaml --design a2=0.425 a3=0.39225 b=0.6",),
    ("designopt view configs/two_ur5_front.yaml --design b=0.6 --q 0,-60,80,-110,-90,0",),
    ("designopt run configs/two_ur5_front.yaml",),
    # the planning case (configs/port_placement.yaml, docs/planning.md,
    # docs/getting-started/first-planning.md)
    ("designopt eval configs/port_placement.yaml --design b=0.6 by=0 px=0.03 py0=0 py1=0",
     "designopt view configs/port_placement.yaml --design b=0.6 by=0 px=0.03 py0=0 py1=0",
     "designopt eval configs/port_placement.yaml --design b=0.6,by=0,px=0.03,py0=0,py1=0 "
     "--design b=0.5085,by=-0.018,px=0.021,py0=-0.119,py1=0.126"),
    ("designopt run configs/port_placement.yaml",
     "designopt show results/port_placement/port_placement.h5",
     "designopt show results/port_placement/port_placement.h5 --csv",
     "designopt report results/port_placement/port_placement.h5 --html"),
    # arms of different robots (configs/mixed_setup.yaml, docs/planning.md)
    ("designopt eval configs/mixed_setup.yaml --design b=0.59 by=0.18 px=0.12 py0=-0.09 py1=-0.11 c=0.63",
     "designopt run configs/mixed_setup.yaml",
     "designopt show results/mixed_setup/mixed_setup.h5 --csv",
     "designopt report results/mixed_setup/mixed_setup.h5 --html"),
    ("designopt run configs/two_arms_front.yaml",
     ("designopt report ARCHIVE --html", "report results/two_arms/two_arms_front.h5 --html")),
    # URDF (docs/urdf.md, configs/urdf_*.yaml)
    ("designopt chain configs/urdf_arm.yaml --q 10,20,0.1,30,10,-10",
     ("designopt chain configs/urdf_arm.yaml --q 10,20,0.1,30,10,-10 [--design l_wrist=0.01]",
      "chain configs/urdf_arm.yaml --q 10,20,0.1,30,10,-10 --design l_wrist=0.01")),
    ("designopt eval configs/urdf_arm.yaml --design l_wrist=0.01 --design l_jaw=0.015",),
    ("designopt scan configs/urdf_arm.yaml",),
    ("designopt run configs/urdf_arm.yaml",
     "designopt export results/urdf_arm/urdf_arm.h5 --urdf results/urdf_arm/best.urdf",
     ("designopt export ARCHIVE --urdf OUT.urdf [--overwrite]",
      "export results/urdf_arm/urdf_arm.h5 --urdf results/urdf_arm/best.urdf --overwrite")),
    ("designopt ik configs/urdf_arm.yaml --poses axes.csv --design l_wrist=0.01",),
    ("designopt ik configs/puma560_task.yaml --poses poses.csv",),
    ("designopt ik configs/puma560_task.yaml --poses poses.csv --mode position --csv",),
    ("designopt chain configs/urdf_puma560.yaml --q 0,90,-90,0,0,0",),
    ("designopt eval configs/urdf_puma560.yaml --design a2=0.4318 --design d4=0.4318",),
    # the robot as configured (docs/figures.md, "The robot")
    ("designopt view configs/puma560.yaml --q 10,20,-30,40,50,60",),
    ("designopt view configs/urdf_mesh_arm.yaml --design l_upper=0.4 --q 30,40,0.05 "
     "--html results/urdf_mesh_arm/view.html",),
    (("designopt view CONFIG", "view configs/planar2r.yaml"),),
    ("designopt view configs/two_arms_front.yaml --design b=0.6 --html two_arms.html",),
    ("designopt run configs/urdf_mesh_arm.yaml",
     "designopt report results/urdf_mesh_arm/urdf_mesh_arm.h5 --html"),
    # the da Vinci arm (docs/davinci.md, configs/davinci*.yaml)
    ("designopt ik configs/davinci_ik.yaml --poses docs/davinci_poses.csv",),
    ("designopt ik configs/davinci_ik.yaml --poses my.csv --trajectory",
     "designopt ik configs/davinci_ik.yaml --poses path.csv --trajectory"),
    ("designopt ik configs/davinci_ik.yaml --poses my.csv --csv",
     "designopt show results/davinci/my_ik.h5",
     ("designopt ik CONFIG --poses PATH [--out PATH] [--trajectory] [--overwrite] [--quiet]",
      "ik configs/davinci_ik.yaml --poses my.csv --out results/davinci/my_ik.h5 --trajectory "
      "--overwrite --quiet")),
    ("designopt scan configs/davinci_wrist.yaml",),
    ("designopt run configs/davinci.yaml",),
    ("designopt eval configs/davinci.yaml --design l_IJ=10 --design beta_deg=30.45 --json",),
    # sweeps and benchmarks (README, docs/configs.md, docs/optimizers.md)
    ("designopt sweep configs/sweep_ptpso.yaml",
     ("designopt sweep CONFIG [--out PATH]", "sweep configs/sweep_ptpso.yaml --out results/s.h5")),
    ("designopt bench configs/mo_benchmark.yaml",),
    ("designopt bench configs/pso_benchmark.yaml",),
    # the spherical RCM and the Raven II arm (docs/sphere.md, configs/sphere_rcm.yaml,
    # configs/raven2.yaml)
    ("designopt run configs/sphere_rcm.yaml",),
    ("designopt eval configs/sphere_rcm.yaml --design alpha12=75 --design alpha23=52",),
    ("designopt scan configs/sphere_rcm.yaml",),
    ("designopt run configs/sphere_rcm.yaml --set study.cone.axis_angle_deg=75 --set "
     "study.objective.arc_length=0.5 --set study.constraints.reach_all_deg=30 --out "
     "results/sphere_rcm/hybrid.h5",),
    ("designopt run configs/raven2.yaml",),
    ("designopt eval configs/raven2.yaml --design La12=75 --design La23=52",),
    ("designopt chain configs/raven2.yaml --q 30,90,0.4,0,0,0",),
    ("designopt scan configs/raven2.yaml",),
]  # fmt: skip

# Every documented command runs by default (CI, the README's test command). With
# DESIGNOPT_DOC_COMMANDS=quick only these run: each subcommand, each flag the docs show
# and each default path at least once, on the cheapest configs (about 90 s on 2 cores);
# the others (the IK-based task studies, fronts, benchmarks: 10-100 s each, mostly
# compiling) are skipped, for a quick local run.
QUICK = {
    "designopt run configs/master9.yaml",
    "designopt --version",
    "designopt config --keys optimizer",
    "designopt scan configs/planar2r.yaml",
    "designopt view configs/urdf_arm.yaml --design l_wrist=0.02",
    "designopt view configs/puma560.yaml --q 10,20,-30,40,50,60",
    "designopt view configs/urdf_mesh_arm.yaml --design l_upper=0.4 --q 30,40,0.05 "
    "--html results/urdf_mesh_arm/view.html",
    "designopt view CONFIG",
    "designopt view configs/two_arms_front.yaml --design b=0.6 --html two_arms.html",
    "designopt chain configs/urdf_arm.yaml --q 10,20,0.1,30,10,-10",  # and its [--design]
    "designopt chain configs/urdf_puma560.yaml --q 0,90,-90,0,0,0",
    "designopt run configs/urdf_arm.yaml",
    "designopt sweep configs/sweep_ptpso.yaml",
}
ALL = os.environ.get("DESIGNOPT_DOC_COMMANDS", "all") != "quick"

# The shipped configs at small sizes: merged into the copy under the scenario's configs/
# (a new config needs an entry: test_every_config_has_its_small_sizes).
OPT = {"n_particles": 4, "n_iters": 2, "n_runs": 1}
NSGA = {"n_particles": 8, "n_iters": 2, "n_runs": 1}
TASK = {"indices": {"n_samples": 64}, "task": {"ik": {"n_db": 256}}}


def _final(n: int) -> dict:
    """A run's final re-scoring (#52) on the study's own sample count (by default 4 ×):
    its program has the shapes of `eval`'s of one design, so an `eval` or a run of the
    config after it loads the program from the session's cache instead of compiling
    another."""
    return {"final": {"n_samples": n}}


SMALL: dict[str, dict] = {
    "davinci": {"study": {"indices": {"n_samples": 256, "n_ik": 16}}, "optimizer": OPT}
                | _final(256),
    "davinci_ik": {},
    "davinci_wrist": {"study": {"indices": {"n_samples": 256, "n_ik": 16}},
                      "scan": {"vary": {"l_IJ": {"num": 2}, "beta_deg": {"num": 2}}, "batch": 4}},
    "master9": {"study": {"indices": {"n_samples": 1024}, "n_norm": 8}, "optimizer": OPT}
               | _final(1024),
    "master9_front": {"study": {"indices": {"n_samples": 1024}},
                      "front": {"n_samples": 1024, "max_points": 8}, "optimizer": NSGA},
    "mo_benchmark": {"bench": {"functions": ["zdt1"], "variants": ["nsga2", {
        "name": "nsga2", "label": "nsga2_crowding", "settings": {"survival": "crowding"}}],
        "n_particles": 8, "n_iters": 5, "n_runs": 3}},
    "planar2r": {"study": {"indices": {"n_samples": 512}}, "optimizer": OPT,
                 "scan": {"vary": {"l2": {"num": 3}}}} | _final(512),
    "planar2r_front": {"study": {"indices": {"n_samples": 512}}, "front": {"n_samples": 512},
                       "optimizer": NSGA},
    "planar2r_task": {"study": {"indices": {"n_samples": 256}}, "optimizer": OPT,
                      "scan": {"vary": {"l2": {"num": 3}}}} | _final(256),
    "plas": {"study": {"mismatch": {"n_samples": 256, "n_path": 2}}, "optimizer": OPT}
            | _final(256),
    "plas_scan": {"study": {"mismatch": {"n_samples": 256, "n_path": 2}},
                  "scan": {"vary": {"a2p": {"num": 2}, "d6": {"num": 2}}, "batch": 4}},
    "pso_benchmark": {"bench": {"functions": ["sphere"], "dim": 5, "n_iters": 20, "n_runs": 4,
                                "variants": ["p1", "p3", "cmaes"]}},
    "puma560": {"study": {"indices": {"n_samples": 512}, "objective": {"n_norm": 4}},
                "optimizer": OPT, "scan": {"vary": {"a2": {"num": 2}, "d4": {"num": 2}}}},
    "puma560_task": {"study": TASK, "optimizer": OPT} | _final(64),
    "rcm": {"study": {"eta": {"n_samples": 1024}}, "optimizer": OPT} | _final(1024),
    "rcm_eta": {"study": {"eta": {"n_samples": 1024}}, "scan": {"vary": {"c": {"num": 3}}, "batch": 3}},
    "rcm_eta_axis": {"study": {"eta": {"n_samples": 1024}},
                     "scan": {"vary": {"c": {"num": 3}}, "batch": 3}},
    "rcm_teleop": {},
    "raven2": {"study": {"indices": {"n_samples": 256, "replicates": 2}}, "optimizer": OPT,
               "scan": {"vary": {"La12": {"num": 2}, "La23": {"num": 2}}}} | _final(256),
    "sphere_rcm": {"study": {"index": {"n_samples": 256, "replicates": 2}}, "optimizer": OPT,
                   "scan": {"vary": {"alpha12": {"num": 3}, "alpha23": {"num": 3}},
                            "batch": 9}} | _final(256),
    "sweep_ptpso": {"study": {"indices": {"n_samples": 1024}, "n_norm": 8}, "optimizer": OPT,
                    "sweep": {"vary": {"optimizer.gamma": [1.0e-7, 1.0e-4],
                                       "optimizer.rho_c": [0.5]}}} | _final(1024),
    "two_arms_front": {"study": {"indices": {"n_samples": 32}}, "front": {"n_samples": 64},
                       "optimizer": NSGA},
    "two_ur5_front": {"study": {"indices": {"n_samples": 32}}, "front": {"n_samples": 64},
                      "optimizer": NSGA},
    # the sizes of tests/test_ports_numbers.py's TINY and the final stage of
    # tests/test_verdict.py's tiny planning run: the same programs, compiled once
    "port_placement": {"study": {"indices": {"n_samples": 32}}, "front": {"n_samples": 32},
                       "optimizer": {"n_particles": 4, "n_iters": 2, "n_runs": 1},
                       "final": {"stage": 32, "max_samples": 64}},
    # the search at the study's own IK (tests/test_setup.py's settings): one IK program per
    # robot serves the search, the final stage, the front, `eval` and that file's targets
    "mixed_setup": {"study": {"indices": {"n_samples": 32}, "task": {"ik": {"climb": 0}}},
                    "front": {"n_samples": 32},
                    "optimizer": {"n_particles": 4, "n_iters": 2, "n_runs": 1,
                                  "fidelity": {"study.indices.n_samples": 32,
                                               "study.task.ik.n_best": 8,
                                               "study.task.ik.neighbours": 4,
                                               "study.task.ik.n_db": 4096,
                                               "study.task.ik.n_nearest": 16,
                                               "study.task.ik.rounds": 2}},
                    "final": {"stage": 32, "max_samples": 64}},
    "urdf_arm": {"study": {"indices": {"n_samples": 512}}, "optimizer": OPT,
                 "scan": {"vary": {"l_wrist": {"num": 2}, "l_jaw": {"num": 2}}}} | _final(512),
    "urdf_mesh_arm": {"study": {"indices": {"n_samples": 512}}, "optimizer": OPT} | _final(512),
    "urdf_puma560": {"study": {"indices": {"n_samples": 512}, "objective": {"n_norm": 4}},
                     "optimizer": OPT, "scan": {"vary": {"a2": {"num": 2}, "d4": {"num": 2}}}},
    "urdf_puma560_front": {"study": TASK, "front": {"n_samples": 64}, "optimizer": NSGA},
    "urdf_puma560_port": {"study": TASK, "optimizer": OPT} | _final(64),
    "urdf_puma560_task": {"study": TASK, "optimizer": OPT} | _final(64),
}  # fmt: skip

# ------------------------------------------------------------ what runs elsewhere

HERE = f"{SELF}::test_documented_command_runs"
RESUME = f"{SELF}::test_max_minutes_stops_cleanly_and_the_printed_command_resumes"
PIPELINE_RESUME = "test_pipeline.py::test_interrupted_run_is_marked_incomplete_and_resume_matches"
PIPELINE_RUN = "test_pipeline.py::test_run_with_refine_matches_schema_and_draws_figures"
PLANNING_AGREE = (
    "designopt run configs/port_placement.yaml --set optimizer.n_runs=3 --set "
    "optimizer.n_particles=64 --set optimizer.n_iters=16 --set refine.method=compass"
)
ELSEWHERE: dict[str, list[str]] = {
    PLANNING_AGREE: ["test_compass.py::test_a_fronts_runs_are_polished_by_their_scaled_"
                     "distance_on_the_search_samples"],
    "designopt eval configs/planar2r.yaml --design l1=1 --design l2=0.5 --json":
        ["test_bad_inputs.py::test_design_forms_agree_and_still_go_through_parse_design"],
    "designopt studies": ["test_serial.py::test_scan_and_eval_commands"],
    "designopt run CONFIG [--set KEY=VALUE ...] [--seed N] [--out PATH] [--overwrite] [--resume] "
    "[--max-minutes M] [--dry-run] [--no-figures] [--no-cache] [--quiet]": [
        "test_set_flag.py::test_run_with_set_and_a_list_entry",
        "test_cli.py::test_run_writes_archive_and_same_seed_gives_same_numbers",
        PIPELINE_RESUME, RESUME,
        "test_cli.py::test_bad_max_minutes_and_dry_run",
        "test_cache.py::test_cache_folder_is_honoured_no_cache_writes_nothing_and_numbers_are_identical",
    ],
    "designopt eval CONFIG --design NAME=VALUE ... [--json]":
        ["test_serial.py::test_scan_and_eval_commands"],
    "designopt eval CONFIG --design NAME=VALUE ... [--design ...] [--json]": [
        "test_serial.py::test_scan_and_eval_commands",
        "test_eval_compare.py::test_the_command_prints_a_column_per_design_and_the_paired_difference",
    ],
    "designopt scan CONFIG [--out PATH]": ["test_serial.py::test_scan_and_eval_commands"],
    "designopt ik CONFIG --poses FILE [--mode position|axis|pose] [--design NAME=VALUE ...] "
    "[--csv] [--out PATH] [--trajectory]": [
        "test_ik_command.py::test_pose_csv_solves_and_archives",
        "test_ik_command.py::test_position_mode_from_poses_and_xyz_files_and_design",
        "test_ik_command.py::test_axis_file_and_axis_mode",
        "test_davinci_ik.py::test_quaternion_csv_h5_and_trajectory_agree",
    ],
    "designopt chain CONFIG [--q Q1,...] [--design NAME=VALUE ...]": [
        "test_urdf.py::test_eval_scan_run_chain_export",
        "test_bad_inputs.py::test_one_variable_bound_to_two_joint_origins_drives_both",
    ],
    "designopt view CONFIG [--design NAME=VALUE ...] [--q Q1,...] [--out PATH.png] "
    "[--html OUT.html]": ["test_robot_view.py::test_view_command_draws_the_chain"],
    "designopt report ARCHIVE [--html]":
        [PIPELINE_RUN, "test_meaning.py::test_overwrite_leaves_nothing_of_the_old_archive"],
    "designopt show ARCHIVE --csv": ["test_targets_archive.py::test_targets_group_and_show_csv"],
    "designopt run CONFIG --resume": [PIPELINE_RESUME, RESUME],
    "designopt run ... --resume": [PIPELINE_RESUME, RESUME],
    "designopt run configs/master9.yaml --out results/master9/master9.h5 --seed 0 --quiet --resume":
        [RESUME],
    "designopt run CONFIG --dry-run": [
        "test_cli.py::test_bad_max_minutes_and_dry_run",
        "test_config_fuzz.py::test_the_unmutated_configs_pass_the_dry_run",
    ],
    "designopt run CONFIG.yaml": [HERE],
    "designopt sweep CONFIG.yaml": [HERE],
    "designopt bench CONFIG.yaml": [HERE],
    "designopt scan CONFIG": [HERE],
    "designopt chain CONFIG": ["test_urdf.py::test_cli_reads_a_relative_urdf_path_from_the_config_folder"],
    "designopt export ARCHIVE --urdf OUT.urdf": ["test_urdf.py::test_eval_scan_run_chain_export"],
    "designopt ik CONFIG --poses FILE": ["test_ik_command.py::test_pose_csv_solves_and_archives"],
    "designopt report ARCHIVE": [PIPELINE_RUN],
    "designopt report <out>": [PIPELINE_RUN],
    "designopt show <out>.partial.h5": [PIPELINE_RESUME],
    "designopt show A | head": [f"{SELF}::test_show_into_a_closed_pipe_stops_quietly"],
    # devices and processes: their own subprocess tests (a CPU device count is set before
    # JAX starts, so not in this process), on their own small configs
    "designopt run configs/master9.yaml --devices 4":
        ["test_parallel.py::test_cli_devices_gives_the_same_archive"],
    "designopt run configs/master9.yaml --devices 8":
        ["test_parallel.py::test_cli_devices_gives_the_same_archive"],
    "designopt run configs/master9.yaml --devices 4 --coordinator 127.0.0.1:29400 "
    "--num-processes 2 --process-id 0": ["test_distributed.py::test_two_processes_match_one_device"],
    "designopt run configs/master9.yaml --devices 4 --coordinator 127.0.0.1:29400 "
    "--num-processes 2 --process-id 1": ["test_distributed.py::test_two_processes_match_one_device"],
}  # fmt: skip

OTHER_CONFIG = {  # ELSEWHERE commands whose tests run the form on a config of their own
    c: "device counts are set before JAX starts: a child process each, on a tiny config"
    for c in ELSEWHERE
    if "--devices" in c
} | {
    PLANNING_AGREE: "minutes on the planning case (three runs of 64 × 16, then the polish): "
    "the form, the runs and the polish set by --set, on a small front"
}

BENCH = "a benchmark script: minutes of timed repeats on the full sizes, no pass/fail"
SKIP: dict[str, str] = {
    "python3 -m venv .venv": "makes the environment the tests run in",
    "pip install -e .": "installs the package the tests import",
    'pip install -e ".[test]"': "installs the package and the test dependencies",
    'pip install -e ".[bench]"': "installs the benchmark peers (network)",
    'pip install -e ".[docs]"': "installs the documentation tools (network)",
    "mkdocs build --strict": "tests/test_site.py builds the site so, into a temporary folder, "
                             "and checks its pages",
    "mkdocs serve": "a server that runs until stopped; tests/test_site.py builds the same site",
    "pip install roboticstoolbox-python ikpy": "installs the benchmark peers (network)",
    "python -m pytest -q -n auto --dist loadfile": "the test suite itself",
    "srun designopt run configs/big.yaml --devices 32 --quiet":
        "a SLURM cluster and a cluster's own config (configs/big.yaml is an example name)",
    "python benchmarks/main_job.py --repeat 3": BENCH + " (cold and warm pairs of master9)",
    "python benchmarks/best_solution.py": BENCH + " (its comparison is tests/test_best_solution.py)",
    "python benchmarks/se_honesty.py": BENCH + ": one design at 16 seeds per case, minutes (the "
    "replicated SE's formula and a seeds check: tests/test_se_replications.py)",
    "python benchmarks/plan_seeds.py": BENCH + ": three planning runs and eight common "
    "seeds' scoring, minutes (the race itself: tests/test_verdict.py)",
    "python benchmarks/plan_seeds.py --panda": BENCH + ": the same with two 7-joint Pandas, "
    "minutes",
    "python benchmarks/mo_nsga2.py": BENCH + "; needs pymoo (.[bench])",
    "python benchmarks/mo_nsga2.py [--runs 11] [--repeat 3] [--problems …] [--float32] "
    "[--survival pruning|crowding]": BENCH + "; needs pymoo (.[bench])",
    "python benchmarks/kernels.py": BENCH,
    "python benchmarks/kernels.py --memory": BENCH,
    "python benchmarks/swarm_scoring.py --memory": BENCH,
    "python benchmarks/pso_throughput.py --suite": BENCH + "; evosax and pyswarms from .[bench]",
    "python benchmarks/ptpso_tuning.py": BENCH + " (Fig. 9)",
    "python benchmarks/latency.py": BENCH + ": every shipped config cold and warm, ~20 min",
    "python benchmarks/latency.py --only NAME --programs 4": BENCH,
    "python benchmarks/latency.py --only port_placement --only port_placement-eval":
        BENCH + ": the planning case's run and eval, each cold and warm, ~3 min",
    ".venv/bin/python benchmarks/ik.py": BENCH + "; the peers from .[bench]",
    "python benchmarks/ik.py": BENCH + "; the peers from .[bench]",
    ".venv/bin/python benchmarks/plas.py": "redraws docs/img from results/plas/ archives",
    "python benchmarks/preflight.py": BENCH + " (measured peak memory of every config)",
    "python benchmarks/planning_profile.py": BENCH + " (the planning case's block program timed "
                                             "warm, with the IK's counts)",
    "python benchmarks/scaling.py --reps 5": BENCH + " (device layouts in child processes)",
    "python benchmarks/threads.py": BENCH + ": planning runs on one thread and on every core, "
    "minutes (the same numbers bit for bit: tests/test_concurrency.py)",
    "python benchmarks/threads.py --repeat 2": BENCH + ": as above, two repeats",
    "python docs/make_figures.py": "regenerates docs/img (every shipped config: minutes); the "
                                   "configs run here at small sizes",
    "python docs/make_figures.py --only rcm": "writes docs/img; rcm runs here",
    "python docs/make_figures.py --only urdf_puma560_task urdf_mesh_arm":
        "writes docs/img; both configs run here",
}  # fmt: skip


# ------------------------------------------------------------------ the folder


def _merge(a: dict, b: dict) -> dict:
    out = copy.deepcopy(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _write_csv(path: Path, head: list[str], rows: np.ndarray) -> None:
    path.write_text(",".join(head) + "\n"
                    + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows))  # fmt: skip


def _poses_csv(path: Path) -> None:
    """poses.csv for configs/puma560_task.yaml: 4 full poses (T00..T33) from joints in
    the limits."""
    lim = np.radians([[-160, 160], [-45, 225], [-225, 45], [-110, 170], [-100, 100], [-266, 266]])
    q = lim[:, 0] + (lim[:, 1] - lim[:, 0]) * np.random.default_rng(1).random((4, 6))
    cols = [f"T{i}{j}" for i in range(4) for j in range(4)]
    _write_csv(path, cols, puma_fk(q).reshape(4, 16))  # the middle design's FK


def _axes_csv(path: Path, config: Path) -> None:
    """axes.csv for configs/urdf_arm.yaml at l_wrist = 0.01: 4 tip positions and tool
    axes (x,y,z,ax,ay,az) from joints in the limits, by the study's own FK."""
    import designopt
    from designopt.studies.serial.commands import design_values
    from designopt.studies.serial.mechanism import build

    s = designopt.load_config(config).study
    design = design_values(s, {"l_wrist": 0.01}, str(config))
    mech = build(s)
    full = np.concatenate([[design[k] for k in s.variables], mech.fixed]) * mech.scale
    lo, hi = np.asarray(mech.lower), np.asarray(mech.upper)
    rows = []
    for u in np.random.default_rng(2).random((4, mech.n)):
        R, p = (np.asarray(a) for a in mech.model.fk(full, lo + (hi - lo) * (0.25 + 0.5 * u)))
        rows.append(np.r_[p, R[:, 2]])
    _write_csv(path, ["x", "y", "z", "ax", "ay", "az"], np.array(rows))


def make_tree(folder: Path, needs: str) -> Path:
    """``folder`` laid out as the repository for the documented commands: configs/ with
    every shipped config at its small sizes (URDFs and data linked), docs/davinci_poses.csv,
    and the poses files the docs name (``my.csv``, ``path.csv``: the da Vinci poses;
    ``poses.csv``, ``axes.csv``: made only where ``needs`` names them)."""
    cfgs = folder / "configs"
    cfgs.mkdir(parents=True)
    for sub in ("robots", "data"):
        os.symlink(ROOT / "configs" / sub, cfgs / sub)
    for p in sorted((ROOT / "configs").glob("*.yaml")):
        raw = yaml.safe_load(p.read_text())
        small = _merge(raw, SMALL.get(p.stem, {})) if isinstance(raw, dict) else raw
        (cfgs / p.name).write_text(yaml.safe_dump(small, sort_keys=False))
    (folder / "docs").mkdir()
    shutil.copy(ROOT / "docs" / "davinci_poses.csv", folder / "docs")
    for name in ("my.csv", "path.csv"):
        shutil.copy(ROOT / "docs" / "davinci_poses.csv", folder / name)
    if "poses.csv" in needs:
        _poses_csv(folder / "poses.csv")
    if "axes.csv" in needs:
        _axes_csv(folder / "axes.csv", cfgs / "urdf_arm.yaml")
    return folder


def _steps(scenario: tuple) -> list[tuple[str, list[str]]]:
    """(documented command, argv after ``designopt``) for each step."""
    out = []
    for step in scenario:
        doc, concrete = (step, step.split(None, 1)[1]) if isinstance(step, str) else step
        out.append((doc, shlex.split(concrete)))
    return out


PATHISH = re.compile(r"[\w./-]+\.(?:h5|png|pdf|html|urdf|csv)\b")


def _prints_what_it_says(doc: str, argv: list[str], out: str) -> None:
    """The commands whose output is the point: the version, the config reference."""
    if argv == ["--version"]:
        import designopt

        assert designopt.__version__ in out, f"`{doc}` printed {out!r}"
    if argv[:2] == ["config", "--keys"]:
        prefix = argv[2] if len(argv) > 2 else ""
        assert f"{prefix}." in out, f"`{doc}` names no key under {prefix!r}:\n{out[:2000]}"


def run_steps(scenario: tuple, folder: Path, capsys) -> None:
    for doc, argv in _steps(scenario):
        rc = main(argv)
        out, err = capsys.readouterr()
        assert rc == 0, f"`{doc}` ({' '.join(argv)}): exit {rc}\n{err[-3000:]}"
        _prints_what_it_says(doc, argv, out)
        for line in out.splitlines():  # every file it prints as its output is there
            p = line.removeprefix("archive: ").strip()
            if PATHISH.fullmatch(p):
                assert (folder / p).exists(), f"`{doc}`: {p} printed, not written"


# ------------------------------------------------------------------ the tests


def _id(s: tuple) -> str:
    first = s[0] if isinstance(s[0], str) else s[0][1]
    return first.removeprefix("designopt ").replace(" ", "_")[:80]


def _params() -> list:
    out = []
    for s in SCENARIOS:
        first = _steps(s)[0][0]
        marks = [] if first in QUICK else [pytest.mark.slow, pytest.mark.skipif(
            not ALL, reason="DESIGNOPT_DOC_COMMANDS=quick skips it (10-100 s)")]  # fmt: skip
        out.append(pytest.param(s, marks=marks, id=_id(s)))
    return out


@pytest.mark.parametrize("scenario", _params())
def test_documented_command_runs(scenario, tmp_path, monkeypatch, capsys):
    """Each documented command as written, from a folder laid out as the repository, with
    the shipped config at small sizes: exit 0 and every file it names written. Each
    scenario's compiled programs are dropped after it (tests/compiled.py): the module runs some sixty commands, and holding all
    their executables mapped at once crashed XLA (the kernel's map limit)."""
    from compiled import release_compiled_programs

    text = " ".join(a for _, argv in _steps(scenario) for a in argv)
    folder = make_tree(tmp_path / "repo", text)
    monkeypatch.chdir(folder)
    try:
        run_steps(scenario, folder, capsys)
    finally:
        release_compiled_programs()


def _at_iteration(monkeypatch, iteration: int, action) -> None:
    """The CLI's progress bar calls ``action()`` once ``iteration`` iterations are done
    (as tests/test_pipeline.py's ``_signal_at``)."""
    import contextlib

    from designopt.cli import commands

    @contextlib.contextmanager
    def bar(total, desc):
        done = [0]

        def update(n):
            done[0] += n
            if total is not None and done[0] >= iteration > done[0] - n:
                action()

        yield update

    monkeypatch.setattr(commands, "_progress", lambda quiet: bar)


FAULTS_RESUME = ("designopt run configs/master9.yaml --out results/master9/master9.h5 --seed 0 "
                 "--quiet --resume")  # fmt: skip


def test_max_minutes_stops_cleanly_and_the_printed_command_resumes(tmp_path, monkeypatch, capsys):
    """A SIGTERM (docs/faults.md) and ``--max-minutes`` (README) stop at an iteration
    boundary with exit 143, keep the checkpoint and print the command that resumes it;
    for ``designopt run configs/master9.yaml --quiet`` that is the line docs/faults.md
    shows, and each printed command finishes its run."""
    import signal
    import time

    from designopt.io import writer

    folder = make_tree(tmp_path / "repo", "")
    monkeypatch.chdir(folder)
    cfg = folder / "configs" / "master9.yaml"
    raw = yaml.safe_load(cfg.read_text())
    raw["optimizer"]["n_iters"] = 20
    cfg.write_text(yaml.safe_dump(raw, sort_keys=False))
    # SIGTERM: the printed command is the one docs/faults.md shows
    _at_iteration(monkeypatch, 3, lambda: signal.raise_signal(signal.SIGTERM))
    rc = main(["run", "configs/master9.yaml", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 143, err
    assert "interrupted (SIGTERM)" in err and f"resume with `{FAULTS_RESUME}`" in err, err
    assert (folder / "results/master9/master9.partial.h5").exists()
    monkeypatch.undo()
    monkeypatch.chdir(folder)
    assert main(shlex.split(FAULTS_RESUME)[1:]) == 0, capsys.readouterr().err
    assert (folder / "results/master9/master9.h5").exists()
    assert not (folder / "results/master9/master9.partial.h5").exists()

    # --max-minutes 60, its hour passed after 3 iterations: the same clean stop
    def hour_passed():
        writer.current().deadline = time.monotonic() - 1.0

    _at_iteration(monkeypatch, 3, hour_passed)
    rc = main(["run", "configs/master9.yaml", "--out", "results/mm.h5", "--quiet", "--no-figures",
               "--max-minutes", "60"])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 143, err
    resume = err.split("`")[1]
    assert "--max-minutes 60" in resume and resume.endswith("--resume"), err
    monkeypatch.undo()
    monkeypatch.chdir(folder)
    assert main(shlex.split(resume)[1:]) == 0, capsys.readouterr().err
    assert (folder / "results/mm.h5").exists() and not (folder / "results/mm.partial.h5").exists()


def test_show_into_a_closed_pipe_stops_quietly(tmp_path, monkeypatch, capsys):
    """``designopt show A | head`` (docs/faults.md): the reader going away is exit 141,
    nothing on stderr."""
    folder = make_tree(tmp_path / "repo", "")
    monkeypatch.chdir(folder)
    assert main(["run", "configs/rcm_teleop.yaml", "--quiet", "--no-figures"]) == 0
    capsys.readouterr()

    class Closed:
        def write(self, s):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(32, "Broken pipe")

        def fileno(self):
            raise OSError("not a real stream")

    monkeypatch.setattr("sys.stdout", Closed())
    rc = main(["show", "results/rcm_teleop/rcm_teleop.h5"])
    monkeypatch.undo()
    assert rc == 141
    assert capsys.readouterr().err == ""


# ------------------------------------------------------------ the tables themselves


def _scenario_docs() -> list[str]:
    return [doc for s in SCENARIOS for doc, _ in _steps(s)]


def _covered_mention(cmd: str, known: list[str]) -> bool:
    """A bare mention (a subcommand and flags, nothing else) is covered by a command of
    the tables with its subcommand and every one of its flags."""
    words = cmd.split()
    if words[0] != "designopt" or any(not w.startswith("--") for w in words[2:]):
        return False
    mine = flags(cmd)
    return all(
        any(
            k.startswith("designopt ") and sub in subcommands(k) and mine <= flags(k) for k in known
        )  # fmt: skip
        for sub in subcommands(cmd)
    )


def test_every_documented_command_is_run_elsewhere_or_skipped():
    docs = documented()
    assert len(docs) > 50, "the reader of the docs found almost nothing"
    known = _scenario_docs() + list(ELSEWHERE)
    missing = [f"{c}    ({', '.join(w)})" for c, w in docs.items()
               if c not in known and c not in SKIP and not _covered_mention(c, known)]  # fmt: skip
    assert not missing, (
        "documented commands that no test runs: add each to SCENARIOS (run here), ELSEWHERE "
        "(the tests that run it) or SKIP (why not) in tests/test_documented_commands.py:\n"
        + "\n".join(missing)
    )


def test_no_entry_outlives_its_command():
    docs = documented()
    stale = [c for c in [*_scenario_docs(), *ELSEWHERE, *SKIP] if c not in docs]
    assert not stale, "entries whose command the docs no longer show:\n" + "\n".join(stale)
    both = set(_scenario_docs()) & (set(ELSEWHERE) | set(SKIP)) | set(ELSEWHERE) & set(SKIP)
    assert not both, f"in two tables: {both}"


def test_every_run_here_shows_the_flags_of_its_documented_form():
    """A synopsis runs as a command with every flag it shows; a documented command runs
    as written."""
    for s in SCENARIOS:
        for doc, argv in _steps(s):
            assert argv[0] in subcommands(doc), (doc, argv)
            assert flags(doc) <= set(argv), (doc, argv, flags(doc) - set(argv))
            if "[" not in doc and not re.search(r"\b[A-Z]{3,}\b", doc):
                assert doc.split()[1:] == argv, f"`{doc}` must run as written, not {argv}"


def _functions(path: Path) -> set[str]:
    return {n.name for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.FunctionDef)}


def test_the_tests_named_elsewhere_exist_and_show_the_flags():
    """Each test named in ELSEWHERE exists, and their modules together show the
    subcommand, the config file and every flag of the documented command."""
    for cmd, names in ELSEWHERE.items():
        text = ""
        for name in names:
            file, func = name.split("::")
            assert func in _functions(TESTS / file), f"{cmd}: no test {name}"
            text += (TESTS / file).read_text()
        for sub in subcommands(cmd):
            assert f'"{sub}"' in text, f"{cmd}: {names} never run `{sub}`"
        own = any(n.startswith(SELF) for n in names)  # runs documented lines as text
        for f in flags(cmd):
            assert f'"{f}"' in text or own and f" {f} " in text, f"{cmd}: {names} never pass {f}"
        for w in cmd.split():
            if w.startswith("configs/") and cmd not in OTHER_CONFIG:
                assert Path(w).name in text, f"{cmd}: {names} never use {w}"


def test_every_config_run_here_has_its_small_sizes():
    used = {Path(w).stem for s in SCENARIOS for _, argv in _steps(s) for w in argv
            if w.startswith("configs/")}  # fmt: skip
    assert used <= set(SMALL), f"no small sizes for {used - set(SMALL)}"
    assert set(SMALL) <= {p.stem for p in (ROOT / "configs").glob("*.yaml")}


def test_the_reader_finds_each_kind_of_place():
    """Code blocks, indented blocks, inline code across a line break, a table cell with
    an escaped |, a printed command inside a code block, YAML headers."""
    docs = documented()
    for cmd, where in [
        ("designopt ik configs/davinci_ik.yaml --poses docs/davinci_poses.csv", "docs/davinci.md"),
        ("designopt run configs/rcm.yaml", "README.md"),
        ("python -m pytest -q -n auto --dist loadfile", "README.md"),
        ("mkdocs serve", "README.md"),
        ("designopt config --keys optimizer", "docs/reference/config.md"),
        ("designopt report", "docs/faults.md"),
        ("designopt run configs/master9.yaml --out results/master9/master9.h5 --seed 0 --quiet "
         "--resume", "docs/faults.md"),
        ("designopt export results/urdf_arm/urdf_arm.h5 --urdf results/urdf_arm/best.urdf",
         "configs/urdf_arm.yaml"),
    ]:  # fmt: skip
        assert any(w.startswith(where + ":") for w in docs.get(cmd, [])), (cmd, docs.get(cmd))
    assert any(c.startswith("designopt ik CONFIG --poses FILE [--mode position|axis|pose]")
               for c in docs)  # fmt: skip
    assert not any(c.startswith("designopt import") for c in docs)


def test_quick_names_scenarios():
    firsts = {_steps(s)[0][0] for s in SCENARIOS}
    assert QUICK <= firsts, QUICK - firsts
