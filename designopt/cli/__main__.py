"""``python -m designopt.cli``: the ``designopt`` command."""

from designopt.cli.commands import console

console()
