"""The ``oos`` command line.

Each subpackage that offers commands has a ``cli`` module with ``register(subparsers)``; this
module only collects them, so that a capability adds its commands without touching this file.
Errors that a user can fix (bad data, bad spec, unknown names) are ``ValueError``s: they are
printed as one line and give exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: Subpackage modules whose ``register(subparsers)`` adds commands, in ``--help`` order.
COMMAND_MODULES = (
    "oos_drake.scenario.cli",
    "oos_drake.multibody.cli",
    "oos_drake.control.cli",
    "oos_drake.robust.cli",
    "oos_drake.analysis.cli",
    "oos_drake.campaign.cli",
    "oos_drake.pipeline",
)


def build_parser() -> argparse.ArgumentParser:
    """Return the ``oos`` argument parser with every available subcommand."""
    parser = argparse.ArgumentParser(
        prog="oos",
        description="oos_drake: uncertain LFR models, Drake twin, robust control and campaigns "
        "for a flexible on-orbit-servicing spacecraft.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_name in COMMAND_MODULES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name and module_name.startswith(exc.name):
                continue  # capability not built yet
            raise
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``oos`` console script; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        status = args.func(args)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        message = exc.args[0] if exc.args else exc
        print(f"oos {args.command}: error: {message}", file=sys.stderr)
        return 2
    return int(status or 0)


if __name__ == "__main__":
    sys.exit(main())
