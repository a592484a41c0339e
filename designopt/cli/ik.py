"""``designopt ik CONFIG --poses FILE``: inverse kinematics of the chain of any study that
declares ``Study.ik`` (an :class:`IKHook`), for every target of a CSV or HDF5 file
(README.md, docs/archive.md); the targets file's format is ``designopt.io.poses``.

Targets file (rows counted from 1, the first row after the header):

- CSV with a header row, any column order: ``x,y,z`` (positions), ``x,y,z,ax,ay,az``
  (positions and unit tool axes, the tool frame's z axis), ``x,y,z,qw,qx,qy,qz``
  (positions and unit quaternions) or ``T00,T01,…,T33`` (row-major 4×4 poses);
- HDF5 with a dataset ``poses`` (N, 4, 4).

Lengths are in the chain's own length unit. ``--mode position|axis|pose`` solves for
fewer rows than the file gives (e.g. positions only from full poses); asking for more
than it gives is an error. Every row is checked first (NaN/inf, a non-unit quaternion or
axis, a rotation not orthonormal, a reflection, a bad bottom row): one ConfigError naming
the file and the row (exit 2 from the CLI), nothing written.

The study's hook does everything that is the study's own (its design, solver, joint names
and units, extra options such as a trajectory mode); this module reads and checks the
targets, picks the mode, claims the outputs, archives an ``IKRecord`` through
``archive.save`` and prints its summary. It reaches studies through the registry only.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from designopt.cli.setup import design_argument
from designopt.core.errors import ConfigError
from designopt.io.poses import read_targets
from designopt.kinematics.ikjob import IKHook, IKJob
from designopt.kinematics.poses import MODES, choose_mode

PROGRESS_MIN = 20_000
"""Targets from which a progress bar shows."""


def _own_options(hook: IKHook) -> dict[str, Any]:
    """{dest: default} of a hook's own flags."""
    if hook.arguments is None:
        return {}
    tmp = argparse.ArgumentParser(add_help=False)
    hook.arguments(tmp)
    return vars(tmp.parse_args([]))


def _hooks() -> dict[str, IKHook]:
    from designopt.studies import STUDIES

    return {n: st.ik for n, st in STUDIES.items() if getattr(st, "ik", None) is not None}


# ---------------------------------------------------------------------------- command


def add_parser(sub: Any) -> None:
    """Add ``designopt ik`` to the CLI's subparsers: the generic flags, then each
    study's own flags (``IKHook.arguments``) under its name."""
    hooks = _hooks()
    k = sub.add_parser(
        "ik",
        help="inverse kinematics of a study's chain for the targets of a CSV or HDF5 file",
        description="Solve the inverse kinematics of the config's chain for every target "
        "of a file: CSV with a header row and the columns x,y,z (positions), "
        "x,y,z,ax,ay,az (positions and tool axes), x,y,z,qw,qx,qy,qz or T00..T33 "
        "(row-major 4x4 poses); or HDF5 with a dataset 'poses' (N, 4, 4); lengths in the "
        "chain's unit. Writes ik/q, ik/success, ik/pos_err, ik/rot_err and what the "
        "study's solver adds (README.md, docs/archive.md). Studies with inverse "
        "kinematics: " + (", ".join(hooks) or "none") + ".",
    )
    k.add_argument("config", help="config (YAML) of a study with inverse kinematics")
    k.add_argument("--poses", required=True, metavar="PATH", help="targets file (.csv or .h5)")
    k.add_argument("--mode", choices=MODES, default=None,
                   help="what to match: position, axis (position + tool z axis) or pose; "
                        "default the most the file gives and the study solves")  # fmt: skip
    design_argument(
        k,
        "design values, one or several after one flag or the flag repeated "
        "(others: the config's design)",
    )
    k.add_argument("--out", default=None, metavar="PATH",
                   help="archive path (default results/<study>/<poses name>_ik.h5)")  # fmt: skip
    k.add_argument("--csv", action="store_true",
                   help="also write the joints, one row per target, to <archive stem>_joints.csv")  # fmt: skip
    k.add_argument("--seed", type=int, default=None, help="override the config's seed")
    k.add_argument("--overwrite", action="store_true", help="replace an existing archive")
    k.add_argument("--no-cache", action="store_true", help="do not keep compiled programs")
    k.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    for name, hook in hooks.items():
        if hook.arguments is not None:
            hook.arguments(k.add_argument_group(f"study '{name}'"))
    k.set_defaults(func=cmd_ik, writes=True)


def _foreign(args: argparse.Namespace, study: str) -> dict[str, Any]:
    """This study's own option values; another study's flag given is a ConfigError."""
    hooks = _hooks()
    mine = _own_options(hooks[study])
    for other, hook in hooks.items():
        for dest, default in _own_options(hook).items():
            if other != study and dest not in mine and getattr(args, dest, default) != default:
                raise ConfigError(f"--{dest.replace('_', '-')}: an option of study '{other}', "
                                  f"not of study '{study}'")  # fmt: skip
    return {d: getattr(args, d, v) for d, v in mine.items()}


def cmd_ik(args: argparse.Namespace) -> int:
    """``designopt ik CONFIG --poses PATH [...]``: read and check the targets, solve them
    with the study's hook, archive an IKRecord (``--csv``: the joints too), print."""
    import jax

    from designopt.app.job import base_attrs
    from designopt.app.records import bind
    from designopt.cli.setup import load_args, parse_design
    from designopt.core.keys import streams
    from designopt.core.timing import Stopwatch
    from designopt.io import archive, writer
    from designopt.results import IKRecord
    from designopt.results import ik as iktext
    from designopt.studies import STUDIES

    cfg, text = load_args(args)
    name = cfg.study.name
    hook = getattr(STUDIES[name], "ik", None)
    if hook is None:
        have = ", ".join(f"'{n}'" for n in _hooks()) or "none"
        raise ConfigError(f"{args.config}: study '{name}' has no inverse kinematics "
                          f"(studies with it: {have})")  # fmt: skip
    opts = _foreign(args, name)
    if cfg.precision != "float64":
        raise ConfigError(f"{args.config}: key 'precision': the IK needs float64 "
                          "(errors of 1e-9); set precision: float64")  # fmt: skip
    jax.config.update("jax_enable_x64", True)
    design = hook.design(cfg.study, parse_design(args.design), args.config)
    poses = Path(args.poses)
    targets = read_targets(poses, hook.tol(cfg.study))
    mode = choose_mode(targets, args.mode, hook.modes, name, poses)
    out = Path(args.out or f"results/{name}/{poses.stem}_ik.h5")
    writer.claim(out, args.overwrite)
    csv_out = iktext.csv_path(out) if args.csv else None
    if csv_out is not None:
        writer.claim(csv_out, args.overwrite)
    keys = streams(cfg.seed)
    show = not args.quiet and len(targets) >= PROGRESS_MIN
    from tqdm import tqdm

    bar = tqdm(total=len(targets), desc="ik", unit="target", disable=not show)
    with Stopwatch() as sw, bar:
        job = IKJob(cfg.study, design, targets, mode, keys["samples"], opts, bar.update)
        try:
            sol = hook.solve(job)
        except ValueError as e:
            raise ConfigError(f"{poses}: {e}") from None
    attrs = {"targets": mode, "poses_file": str(poses), "n": len(targets), "design": design,
             "joint_names": list(sol.joint_names), "units": sol.units} | sol.attrs  # fmt: skip
    tree = {"ik": {**sol.arrays, **targets.tree(), "attrs": attrs}}
    root = base_attrs("ik", cfg, text, keys, args.config) | {
        "wall_time_s": sw.wall, "compile_time_s": sw.compile, "run_time_s": sw.run}  # fmt: skip
    rec = bind(IKRecord(root, tree, cfg))
    archive.save(out, rec, overwrite=args.overwrite)
    if csv_out is not None:
        writer.write_file(csv_out, rec.csv_text().encode(), "joints CSV")
    if not args.quiet:
        for line in sol.lines:
            print(line)
        for line in rec.summary()[1:]:
            print(line)
        print(f"wall {sw.wall:.1f} s = compile {sw.compile:.1f} s + run {sw.run:.1f} s")
        print(f"wrote {out}" + (f" and {csv_out}" if csv_out is not None else ""))
    return 0
