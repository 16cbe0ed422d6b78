"""How a command module adds its commands to ``robocell``: the one way to register a command.

Each module of this package that has commands exposes ``register(commands)``
and adds them with :meth:`Commands.add` (a leaf: its parser, which runs
``run(args)``) or :meth:`Commands.group` (a word with commands below it, as
``robocell sim scans``). ``robocell.cli.main`` lists the modules. Every leaf also
takes the global options (``--config``, ``-v``), before or after its name.

A module imports only what building its parsers needs; whatever its commands
run (Zenoh, OpenCV, SciPy, Rerun, the reconstruction) is imported inside
``run``, so that ``robocell --help`` and ``robocell jobs`` start quickly.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["Commands", "Run"]

#: What a leaf command runs: the parsed arguments in, the exit status out.
Run = Callable[[argparse.Namespace], int]


class Commands:
    """The commands below one word of ``robocell`` (``robocell`` itself, or ``robocell sim``)."""

    def __init__(self, subparsers: argparse._SubParsersAction, prefix: str,
                 common: list[argparse.ArgumentParser]) -> None:
        self._subparsers = subparsers
        self._prefix = prefix
        self._common = common

    def add(self, name: str, run: Run, *, help: str, description: str | None = None) -> argparse.ArgumentParser:
        """A command that runs ``run(args)``; returns its parser, to add its own arguments to.

        ``args.command`` is its whole name (``"sim scans"``), for messages.
        """
        parser = self._subparsers.add_parser(name, help=help, description=description or help,
                                             parents=self._common)
        parser.set_defaults(run=run, command=f"{self._prefix}{name}")
        return parser

    def group(self, name: str, *, help: str, description: str | None = None) -> Commands:
        """A word with commands of its own below it (``robocell NAME COMMAND``), one of them required."""
        parser = self._subparsers.add_parser(name, help=help, description=description or help)
        below = parser.add_subparsers(dest=f"_{name}_command", required=True, metavar="COMMAND")
        return Commands(below, f"{self._prefix}{name} ", self._common)
