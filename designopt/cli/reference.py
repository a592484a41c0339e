"""``designopt config --keys [PREFIX]``: the config-key reference, generated from the
models the validator uses (:mod:`designopt.app.reference`): every key with its type,
default, range and description, for a terminal; ``--markdown`` prints the whole
reference as the documentation site's Markdown page. An unknown prefix is a ConfigError
naming it, with close matches (exit 2 from the CLI)."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub: Any) -> None:
    """Add ``designopt config`` to the CLI's subparsers (``func``: :func:`run`)."""
    c = sub.add_parser(
        "config",
        help="describe the config keys (type, default, range, meaning)",
        description="Print the config-key reference, generated from the validator's models: "
        "every key of a run config (its sections and each study's settings) and of a "
        "benchmark config, with its type, default, range and description. PREFIX selects a "
        "key and the keys below it (e.g. optimizer, study.task.ik) or a study's keys (its "
        "name, e.g. serial).",
    )
    c.add_argument("--keys", nargs="?", const="", default=None, metavar="PREFIX",
                   help="list the keys under PREFIX (default: every key)")  # fmt: skip
    c.add_argument(
        "--markdown",
        action="store_true",
        help="print the whole reference as Markdown (the documentation page)",
    )
    c.add_argument(
        "--width",
        type=int,
        default=None,
        metavar="N",
        help="wrap the text at N columns (default: the terminal's, 60 to 100)",
    )
    c.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the reference (``--markdown``) or the keys under ``--keys PREFIX`` (every key
    without a flag); 0. An unknown prefix raises ConfigError (exit 2 from the CLI)."""
    from designopt.app import reference
    from designopt.core.errors import ConfigError

    if args.markdown and args.keys is not None:
        raise ConfigError("config: give --keys or --markdown, not both")
    if args.width is not None and args.width < 20:
        raise ConfigError(f"config: --width {args.width}: give at least 20 columns")
    if args.markdown:
        print(reference.markdown())
    else:
        print(reference.text(args.keys or None, width=args.width), end="")
    return 0
