"""``python -m designopt``: the ``designopt`` command."""

from designopt.cli.commands import console

console()
