"""The command line: argument parsing and printing over the application layer (``designopt.app``).
``designopt.cli.commands`` holds the commands; ``setup`` what every command does first; ``ik``
the ``designopt ik`` command."""

from designopt.cli.commands import console, main

__all__ = ["console", "main"]
