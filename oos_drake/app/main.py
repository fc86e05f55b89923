"""The ``oos`` command line.

Each command module of :mod:`oos_drake.app` has ``register(subparsers)``; this module only
collects them, so that a capability adds its commands without touching this file.
The options shared by the commands (one name each) and the exit status 2 of a user-fixable
error come from :mod:`oos_drake.app.args`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from oos_drake import __version__
from oos_drake.app.args import run_command

#: Command modules whose ``register(subparsers)`` adds commands, in ``--help`` order.
COMMAND_MODULES = (
    "oos_drake.app.scenario",
    "oos_drake.app.multibody",
    "oos_drake.app.tree",
    "oos_drake.app.synth",
    "oos_drake.app.robust",
    "oos_drake.app.analyze",
    "oos_drake.app.campaign",
    "oos_drake.app.pipeline",
    "oos_drake.app.report",
)


def build_parser() -> argparse.ArgumentParser:
    """Return the ``oos`` argument parser with every available subcommand."""
    parser = argparse.ArgumentParser(
        prog="oos",
        description="oos_drake: uncertain LFR models, Drake twin, robust control and campaigns "
        "for a flexible on-orbit-servicing spacecraft.",
    )
    parser.add_argument("--version", action="version", version=f"oos_drake {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_name in COMMAND_MODULES:
        importlib.import_module(module_name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``oos`` console script; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    return run_command(args)


if __name__ == "__main__":
    sys.exit(main())
