"""Command line of the spacecraft tree (schema version 2), until ``oos`` takes tree files.

Usage::

    python -m oos_drake.multibody.tree_cli check FILE_OR_NAME [--angle BODY=RAD ...]
    python -m oos_drake.multibody.tree_cli sdf FILE_OR_NAME DIRECTORY
    python -m oos_drake.multibody.tree_cli convert V1_FILE_OR_NAME OUT.toml

``check`` loads the tree, builds its TITOP LFR and its Drake twin (SDF generated from the same
file into a temporary folder) and prints the comparison (max relative response error, pole and
zero errors); exit status 0 when it passes, 1 when it does not. ``sdf`` writes the tree's SDF
files. ``convert`` writes the schema-2 tree of a schema-1 scenario's chaser
(:func:`oos_drake.scenario.tree_migration.tree_document_from_v1`) and names what it left out.
Invalid data: one line ``error: <body>: <field> ...`` on stderr, exit status 2, nothing
written.
"""

from __future__ import annotations

import argparse
import sys

from oos_drake.scenario.data import ScenarioError
from oos_drake.scenario.tree import load_tree

__all__ = ["main"]


def _angles(items: list[str]) -> dict[str, float]:
    angles = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            angles[name] = float(value)
        except ValueError:
            raise ScenarioError(name or item, f"--angle needs BODY=RAD, got {item!r}") from None
    return angles


def _convert(scenario: str, output: str) -> int:
    from pathlib import Path

    import tomli_w

    from oos_drake.scenario.tree import parse_tree
    from oos_drake.scenario.tree_migration import tree_document_from_v1

    try:
        document, dropped = tree_document_from_v1(scenario)
        parse_tree(document)  # what is written must load
    except (ScenarioError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    Path(output).write_text(tomli_w.dumps(document))
    print(f"wrote {output}; not converted (no place in schema 2 yet): {', '.join(dropped)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command; return the exit status (2 on invalid input)."""
    parser = argparse.ArgumentParser(prog="python -m oos_drake.multibody.tree_cli")
    commands = parser.add_subparsers(dest="command", required=True)
    check = commands.add_parser("check", help="TITOP LFR vs Drake twin of a tree scenario")
    check.add_argument("tree", help="tree scenario file or shipped name")
    check.add_argument("--angle", action="append", default=[], help="BODY=RAD joint angle")
    check.add_argument("--tolerance", type=float, default=1e-6, help="max relative error")
    sdf = commands.add_parser("sdf", help="write the SDF files of a tree scenario")
    sdf.add_argument("tree", help="tree scenario file or shipped name")
    sdf.add_argument("directory", help="output folder")
    convert = commands.add_parser("convert", help="schema-1 scenario -> schema-2 tree (chaser)")
    convert.add_argument("scenario", help="schema-1 scenario file or shipped name")
    convert.add_argument("output", help="tree file to write (.toml)")
    args = parser.parse_args(argv)
    if args.command == "convert":
        return _convert(args.scenario, args.output)
    try:
        tree = load_tree(args.tree)
        angles = _angles(args.angle) if args.command == "check" else {}
        tree.joint_angles(angles)  # known bodies, within their limits
    except (ScenarioError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    # Drake only past validation: invalid input fails fast and writes nothing
    from oos_drake.multibody.cross_check import format_table
    from oos_drake.multibody.tree_plant import check_tree
    from oos_drake.multibody.tree_sdf import write_tree_sdf

    if args.command == "sdf":
        for path in write_tree_sdf(tree, args.directory):
            print(path)
        return 0
    result = check_tree(tree, angles, response_tolerance=args.tolerance)
    print(format_table([result]))
    return 0 if result.passed else 1


if __name__ == "__main__":
    sys.exit(main())
