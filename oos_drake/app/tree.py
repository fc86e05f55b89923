"""``oos tree ...`` and ``oos validate`` of a spacecraft tree (scenario schema version 2).

Usage::

    oos tree check FILE_OR_NAME [--angle BODY=RAD ...]   # TITOP vs Drake at one configuration
    oos tree sdf FILE_OR_NAME DIRECTORY                  # write the tree's SDF files
    oos tree convert V1_FILE_OR_NAME OUT.toml            # schema-1 scenario -> schema-2 tree
    oos tree solve FILE_OR_NAME OUT.toml                 # tip waypoints -> joint waypoints (IK)
    oos validate --scenario FILE_OR_NAME                 # every configuration of its timeline

``check`` loads the tree, builds its TITOP LFR and its Drake twin (SDF generated from the same
file into a temporary folder) and prints the comparison (max relative response error, pole and
zero errors); exit status 0 when it passes, 1 when it does not. ``sdf`` writes the tree's SDF
files. ``convert`` writes the schema-2 tree of a schema-1 scenario's chaser
(:func:`oos_drake.scenario.tree_migration.tree_document_from_v1`) and names what it left out.
``solve`` writes the same tree with every tip-pose waypoint replaced by the joint angles its
inverse kinematics gives (:func:`joint_space_document`): the scenario layer, below the Drake
twin, reads such a file's timeline directly, so ``oos synth``, ``oos analyze`` and ``oos margins``
run on it; ``oos run`` does this itself (:func:`joint_space_scenario`).
``oos validate`` on a schema-2 file (:func:`compute_tree_validation`, printed by
:func:`validate_tree`) checks the TITOP LFR against the
tree's own twin on every configuration of the mission timeline
(:meth:`oos_drake.scenario.tree_mission.Timeline.configurations`). Invalid data: one line
``oos <command>: error: <body>: <field> ...`` on stderr, exit status 2, nothing written.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import tomllib
from pathlib import Path

from oos_drake.scenario.data import ScenarioError
from oos_drake.scenario.tree import TREE_SCHEMA_VERSION, load_tree, tree_path

__all__ = [
    "register",
    "is_tree_scenario",
    "compute_tree_validation",
    "validate_tree",
    "joint_space_document",
    "joint_space_scenario",
]


def _angles(items: list[str]) -> dict[str, float]:
    angles = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            angles[name] = float(value)
        except ValueError:
            raise ScenarioError(name or item, f"--angle needs BODY=RAD, got {item!r}") from None
    return angles


def is_tree_scenario(scenario: str | Path | None) -> bool:
    """Whether ``--scenario`` names a schema-2 tree (a shipped tree's name, or a TOML file whose
    ``schema_version`` is 2); None (the paper's) and schema-1 files are not."""
    if scenario is None:
        return False
    try:
        path = tree_path(scenario)
    except ValueError:
        return False
    try:
        with path.open("rb") as stream:
            return tomllib.load(stream).get("schema_version") == TREE_SCHEMA_VERSION
    except (OSError, tomllib.TOMLDecodeError):
        return False  # the schema-1 loader reports it


def compute_tree_validation(scenario, options, progress=None):
    """``oos validate`` of a tree, computed: the TITOP LFR against the tree's own Drake twin
    (generated from the file) on every configuration of its mission timeline. Writes nothing.

    Parameters
    ----------
    scenario : str or Path
        The tree (a schema-2 file or a shipped tree's name).
    options : oos_drake.app.multibody.ValidateOptions
        ``frequencies``, ``f_min_hz``, ``f_max_hz`` [Hz], ``tolerance`` and ``root_tolerance``;
        the twin is always the tree's own (``sdf_dir`` and ``cases`` are for schema-1
        scenarios).
    progress : callable or None
        Receives each line of the header (the comparison, then each tip waypoint reached)
        before the (long) comparison starts.

    Returns
    -------
    oos_drake.app.multibody.ValidationResult
        The report (header, table, verdict), the exit status (1 if a configuration fails), one
        result per configuration of the timeline and the wall time [s].

    Raises
    ------
    ScenarioError
        Invalid data, or a tip waypoint out of reach (exit status 2).
    """
    import numpy as np

    from oos_drake.app.multibody import ValidationResult, verdict_lines

    tree = load_tree(scenario)  # invalid data: ScenarioError -> exit status 2
    from oos_drake.multibody.tree_ik import mission_timeline
    from oos_drake.multibody.tree_plant import (
        build_captured_diagram,
        build_docked_diagram,
        build_tree_diagram,
        check_tree,
    )
    from oos_drake.robust.lfr_analysis import frequency_grid
    from oos_drake.scenario.tree import captured_tree, docked_tree

    start = time.perf_counter()
    handles = build_tree_diagram(tree)
    timeline = mission_timeline(tree, handles)  # out of reach: ScenarioError -> exit status 2
    configurations = timeline.configurations()
    omega = frequency_grid(
        omega_range=(2 * np.pi * options.f_min_hz, 2 * np.pi * options.f_max_hz),
        points=options.frequencies,
    )
    header = [
        f"{tree.name}: Drake twin of the tree vs TITOP LFR, 6x6 [F; T]@G -> [a; wdot]@G of "
        f"{tree.root}, {len(configurations)} configurations of the timeline "
        f"({timeline.duration:g} s), {options.frequencies} frequencies {options.f_min_hz:g}-"
        f"{options.f_max_hz:g} Hz; pass: response error <= {options.tolerance:g}, "
        f"poles/zeros <= {options.root_tolerance:g}"
    ]
    header += [
        f"tip waypoint {phase}: port {solution.port} reached within "
        f"{solution.position_error:.2e} m, {solution.orientation_error:.2e} rad"
        for phase, solution in timeline.tip_solutions.items()
    ]
    for line in header if progress is not None else ():
        progress(line)
    models = {None: (tree, handles)}  # connection -> (model tree, twin)
    results, seen = [], {}
    for configuration in configurations:
        captured, docked = configuration.captured, configuration.docked
        angles = tuple(configuration.angles.values())
        # the target welded (one twin per capture) or on its spring-damper (one per rest pose)
        connection = captured if docked is None else (docked, angles)
        if connection not in models and docked is None:
            models[connection] = (
                captured_tree(tree, *captured),
                build_captured_diagram(tree, *captured),
            )
        elif connection not in models:
            models[connection] = (
                docked_tree(tree, docked),
                build_docked_diagram(tree, docked, configuration.angles),
            )
        model_tree, model_handles = models[connection]
        key = (connection, angles)
        if key not in seen:  # a joint held through a phase repeats a configuration
            seen[key] = check_tree(
                model_tree,
                dict(configuration.angles),
                handles=model_handles,
                omega=omega,
                response_tolerance=options.tolerance,
                root_tolerance=options.root_tolerance,
            )
        label = f"t={configuration.time:g} s {configuration.phase}"
        if captured:
            label += f" [{'+'.join(captured)}]"
        if docked:
            label += f" [{'~'.join(docked.connection)}]"
        results.append(dataclasses.replace(seen[key], label=label))
    elapsed = time.perf_counter() - start
    lines, status = verdict_lines(results, elapsed)
    return ValidationResult("\n".join([*header, *lines]) + "\n", status, tuple(results), elapsed)


def validate_tree(args: argparse.Namespace) -> int:
    """``oos validate`` of a tree: :func:`compute_tree_validation` with ``oos validate``'s
    options (``args``), its report printed (the header when the comparison starts, the table
    and verdict when it ends); the exit status, 1 if a configuration fails."""
    from oos_drake.app.multibody import print_validation, validate_options

    return print_validation(args.scenario, validate_options(args)).status


def _convert(args: argparse.Namespace) -> int:
    import tomli_w

    from oos_drake.scenario.tree import parse_tree
    from oos_drake.scenario.tree_migration import tree_document_from_v1

    document, dropped = tree_document_from_v1(args.scenario)
    parse_tree(document)  # what is written must load
    Path(args.output).write_text(tomli_w.dumps(document))
    print(f"wrote {args.output}; not converted (no place in schema 2 yet): {', '.join(dropped)}")
    return 0


def joint_space_document(scenario: str | Path) -> tuple[dict, dict]:
    """The tree file ``scenario`` with its tip-pose waypoints solved into joint waypoints.

    Each ``[mission.phases.tip]`` is solved once on the tree's Drake twin
    (:func:`oos_drake.multibody.tree_ik.mission_timeline`: from the previous waypoint, residual
    within 1e-6 m and rad) and replaced by the chain's angles in the phase's ``joints``
    [rad]; everything else is the file's. The result loads as a tree whose timeline the
    scenario layer builds without inverse kinematics, with the same joint angles at every
    instant.

    Parameters
    ----------
    scenario : str or Path
        A schema-2 tree file or a shipped tree's name.

    Returns
    -------
    document : dict
        The TOML document (``tomli_w.dumps``); the file's own when it has no tip waypoint.
    solutions : dict
        ``{phase: IkSolution}`` of the solved waypoints (with their residuals).

    Raises
    ------
    ScenarioError
        Invalid tree, or ``mission.<phase>.tip: inverse kinematics misses the pose by ...``.
    """
    from oos_drake.scenario.tree import parse_tree

    source = tree_path(scenario)
    with source.open("rb") as stream:
        document = tomllib.load(stream)
    tree = load_tree(source)
    if tree.mission is None or not tree.mission.has_tip_waypoints:
        return document, {}
    from oos_drake.multibody.tree_ik import mission_timeline

    timeline = mission_timeline(tree)
    for raw, phase in zip(document["mission"]["phases"], tree.mission.phases, strict=True):
        if phase.tip is not None:
            del raw["tip"]
            raw["joints"] = {**raw.get("joints", {}), **timeline.tip_solutions[phase.name].angles}
    parse_tree(document, source)  # what is written must load
    return document, dict(timeline.tip_solutions)


def joint_space_scenario(scenario: str | Path, folder: str | Path) -> Path:
    """The tree file the stages of ``oos run`` read: ``scenario`` itself when its mission has
    no tip-pose waypoint (or it is a schema-1 file), else its joint-space copy
    (:func:`joint_space_document`) written to ``folder/<file name>`` (a comment gives the
    source and each waypoint's residual). The copy's first line is a key (hash of the source
    file's bytes and of the code that solves it, ``oos_drake.multibody`` and
    ``oos_drake.scenario``): a copy with the current key is reused without solving again
    (``oos run`` resuming), any other is rewritten.

    Parameters
    ----------
    scenario : str or Path
        Scenario file (any schema) or shipped name.
    folder : str or Path
        Where the joint-space copy goes (created).

    Returns
    -------
    Path
    """
    import tomli_w

    if not is_tree_scenario(scenario):
        return Path(scenario)
    source = tree_path(scenario)
    key = f"# joint-space key {_joint_space_key(source)}"
    path = Path(folder) / source.name
    if path.is_file() and path.read_text().partition("\n")[0] == key:
        return path  # solved from the same file by the same code
    document, solutions = joint_space_document(source)
    if not solutions:
        return source
    lines = [
        key,
        f"# {source}: its tip-pose waypoints solved into joint waypoints by oos_drake.app.tree"
        ".joint_space_document (inverse kinematics on the tree's Drake twin)",
    ]
    lines += [
        f"# {phase}: port {s.port} within {s.position_error:.3g} m, {s.orientation_error:.3g} rad"
        for phase, s in solutions.items()
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n" + tomli_w.dumps(document))
    return path


def _joint_space_key(source: Path) -> str:
    """Hash of a tree file's bytes and of the sources that solve its tip waypoints."""
    import hashlib

    from oos_drake.app.pipeline import source_key

    code = source_key("multibody", "scenario").encode()
    return hashlib.sha256(source.read_bytes() + b"\0" + code).hexdigest()


def _solve(args: argparse.Namespace) -> int:
    import tomli_w

    document, solutions = joint_space_document(args.tree)
    Path(args.output).write_text(tomli_w.dumps(document))
    for phase, s in solutions.items():
        print(
            f"tip waypoint {phase}: port {s.port} within {s.position_error:.2e} m, "
            f"{s.orientation_error:.2e} rad"
        )
    print(f"wrote {args.output} ({len(solutions)} tip waypoint(s) solved)")
    return 0


def _sdf(args: argparse.Namespace) -> int:
    tree = load_tree(args.tree)
    from oos_drake.multibody.tree_sdf import write_tree_sdf  # Drake only past validation

    for path in write_tree_sdf(tree, args.directory):
        print(path)
    return 0


def _check(args: argparse.Namespace) -> int:
    tree = load_tree(args.tree)
    angles = _angles(args.angle)
    tree.joint_angles(angles)  # known bodies, within their limits
    from oos_drake.multibody.cross_check import format_table
    from oos_drake.multibody.tree_plant import check_tree

    result = check_tree(tree, angles, response_tolerance=args.tolerance)
    print(format_table([result]))
    return 0 if result.passed else 1


def register(subparsers) -> None:
    """Add ``tree check|sdf|convert|solve`` to the ``oos`` command line."""
    tree = subparsers.add_parser(
        "tree",
        help="spacecraft trees (scenario schema 2): check, sdf, convert, solve",
        description="Commands on a scenario file of schema version 2 (the spacecraft as a tree "
        "of bodies). `oos validate --scenario TREE` checks every configuration of its timeline.",
    )
    commands = tree.add_subparsers(dest="tree_command", metavar="ACTION", required=True)
    check = commands.add_parser("check", help="TITOP LFR vs Drake twin of a tree at one angle set")
    check.add_argument("tree", help="tree scenario file or shipped name")
    check.add_argument("--angle", action="append", default=[], help="BODY=RAD joint angle")
    check.add_argument("--tolerance", type=float, default=1e-6, help="max relative error")
    check.set_defaults(func=_check)
    sdf = commands.add_parser("sdf", help="write the SDF files of a tree scenario")
    sdf.add_argument("tree", help="tree scenario file or shipped name")
    sdf.add_argument("directory", help="output folder")
    sdf.set_defaults(func=_sdf)
    convert = commands.add_parser("convert", help="schema-1 scenario -> schema-2 tree (chaser)")
    convert.add_argument("scenario", help="schema-1 scenario file or shipped name")
    convert.add_argument("output", help="tree file to write (.toml)")
    convert.set_defaults(func=_convert)
    solve = commands.add_parser(
        "solve", help="tree with its tip-pose waypoints solved into joint waypoints (IK)"
    )
    solve.add_argument("tree", help="tree scenario file or shipped name")
    solve.add_argument("output", help="tree file to write (.toml)")
    solve.set_defaults(func=_solve)
