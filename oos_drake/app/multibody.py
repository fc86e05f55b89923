"""``oos validate`` (Drake twin vs TITOP model) and ``oos sdf generate|check``.

Examples::

    oos validate                      # moments 1-6, phase 7 and 8 sweeps; exit 1 on failure
    oos validate --scenario FILE      # FILE's TITOP LFR against FILE's own Drake twin
    oos validate --cases moments      # only the six moments
    oos sdf generate                  # rewrite sdf/ from scenario/data/paper.toml
    oos sdf check                     # exit 1 if the committed SDF files are stale
    oos ulinearize examples/servicer/servicer.sdf \
        --parameters examples/servicer/servicer_parameters.toml \
        --input servicer_actuation --output "servicer_state[0,1,2,7,8,9]" --out out/servicer
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from oos_drake.app.args import add_frequency_range, add_out_argument, add_scenario_argument

CASE_GROUPS = ("all", "moments", "phase7", "phase8")


def _select(cases, group: str):
    prefix = {"moments": "moment", "phase7": "phase 7", "phase8": "phase 8"}.get(group)
    return cases if prefix is None else [c for c in cases if c.label.startswith(prefix)]


def _validate(args: argparse.Namespace) -> int:
    from oos_drake.app.tree import is_tree_scenario, validate_tree

    if is_tree_scenario(args.scenario):  # schema 2: the tree's own twin on its timeline
        return validate_tree(args)
    import numpy as np

    from oos_drake.multibody.cross_check import run_validation, validation_cases
    from oos_drake.robust.lfr_analysis import frequency_grid
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario(args.scenario)
    cases = _select(validation_cases(scenario), args.cases)
    omega = frequency_grid(
        omega_range=(2 * np.pi * args.f_min, 2 * np.pi * args.f_max), points=args.frequencies
    )
    print(
        f"Drake twin vs TITOP LFR: 6x6 [F; T]@G1 -> [a; wdot]@G1, {args.frequencies} frequencies "
        f"{args.f_min:g}-{args.f_max:g} Hz; pass: response error <= {args.tolerance:g}, "
        f"poles/zeros <= {args.root_tolerance:g}"
    )
    start = time.perf_counter()
    results = run_validation(
        scenario,
        cases=cases,
        omega=omega,
        response_tolerance=args.tolerance,
        root_tolerance=args.root_tolerance,
        sdf_directory=args.sdf_dir,
    )
    return print_verdict(results, time.perf_counter() - start)


def print_verdict(results, elapsed: float) -> int:
    """Print the validation table and its verdict; exit status 0 when every configuration
    passes, else 1 (``oos validate`` of a schema-1 scenario and of a tree).

    Parameters
    ----------
    results : list of cross_check results
        One per configuration (``label``, ``passed``).
    elapsed : float
        Wall time of the validation [s].
    """
    from oos_drake.multibody.cross_check import format_table

    print(format_table(results))
    failed = [r.label for r in results if not r.passed]
    if failed:
        print(
            f"FAILED: {len(failed)} of {len(results)} configurations ({', '.join(failed)}); "
            f"{elapsed:.1f} s"
        )
        return 1
    print(f"all {len(results)} configurations pass ({elapsed:.1f} s)")
    return 0


def _sdf_generate(args: argparse.Namespace) -> int:
    from oos_drake.multibody.scenario_sdf import write_sdf
    from oos_drake.scenario.data import load_scenario

    paths = write_sdf(args.out, load_scenario(args.scenario))
    for path in paths:
        print(path)
    return 0


def _sdf_check(args: argparse.Namespace) -> int:
    from oos_drake.multibody.scenario_sdf import stale_sdf_files
    from oos_drake.scenario.data import load_scenario

    stale = stale_sdf_files(args.out, load_scenario(args.scenario))
    if stale:
        print(
            f"stale SDF files in {args.out}: {', '.join(stale)} (run `oos sdf generate`)",
            file=sys.stderr,
        )
        return 1
    print(f"SDF files in {args.out} are up to date")
    return 0


def _ulinearize(args: argparse.Namespace) -> int:
    from oos_drake.multibody.uncertain_linearization import (
        load_parameters,
        sdf_plant,
        ulinearize,
    )

    parameters = load_parameters(args.parameters)
    plant, context = sdf_plant(args.model)
    start = time.perf_counter()
    lfr = ulinearize(plant, context, parameters, args.input, args.output)
    elapsed = time.perf_counter() - start
    out = Path(args.out)
    lfr.to_mat(out / f"{args.name}.mat")
    lfr.to_npz(out / f"{args.name}.npz")
    print(
        f"{args.model}: {lfr.nstates} states, {lfr.shape[1]} inputs, {lfr.shape[0]} outputs "
        f"({elapsed:.2f} s)"
    )
    print(lfr.blocks[["name", "repetitions", "nominal", "range"]].to_string(index=False))
    print(f"written: {out / args.name}.mat, {out / args.name}.npz")
    return 0


def register(subparsers) -> None:
    """Add ``validate`` and ``sdf`` to the ``oos`` command line."""
    from oos_drake.multibody.scenario_sdf import SDF_DIRECTORY

    validate = subparsers.add_parser(
        "validate",
        help="cross-check the Drake twin against the TITOP LFR model (table; exit 1 on failure)",
        description="Linearize the Drake twin and substitute the TITOP LFR at the six moments, "
        "docking phase 7 over the stiffness sweep and docking phase 8, and compare frequency "
        "responses, poles and transmission zeros.",
    )
    validate.add_argument("--cases", choices=CASE_GROUPS, default="all")
    validate.add_argument("--frequencies", type=int, default=400, help="number of frequencies")
    add_frequency_range(validate, 0.01, 100.0, what="frequency")
    validate.add_argument(
        "--tolerance", type=float, default=1e-6, help="max relative frequency-response error"
    )
    validate.add_argument(
        "--root-tolerance", type=float, default=1e-4, help="max relative pole/zero mismatch"
    )
    add_scenario_argument(validate)
    validate.add_argument(
        "--sdf-dir",
        type=Path,
        default=None,
        help="SDF directory of the Drake twin (default: the scenario's own twin: the package's "
        "SDF files when they match the scenario, else files generated from it)",
    )
    validate.set_defaults(func=_validate)

    ulin = subparsers.add_parser(
        "ulinearize",
        help="uncertain LFR of an SDF/URDF model with declared physical parameters (.mat, .npz)",
        description="Linearize a Drake model (parsed from MODEL, no gravity, all positions and "
        "velocities zero) into an uncertain LFR whose ureal blocks are the parameters declared in "
        "the TOML file (body mass and inertia, revolute spring stiffness, damping or modal "
        "frequency, bushing stiffness and damping per axis). Writes OUT/NAME.mat (MATLAB "
        "layout, BLK rows and block table) and OUT/NAME.npz; load them with "
        "oos_drake.lfr.load_lfr or `oos robust robstab`.",
    )
    ulin.add_argument("model", type=Path, help="SDF or URDF file")
    ulin.add_argument("--parameters", type=Path, required=True, help="parameter TOML file")
    ulin.add_argument(
        "--input", action="append", required=True,
        help="input port of the plant, optionally with rows: NAME, NAME[i,j], NAME[a:b] "
        "(repeat for several ports)",
    )  # fmt: skip
    ulin.add_argument(
        "--output", action="append", required=True, help="output port (same syntax as --input)"
    )
    add_out_argument(ulin, type=Path)
    ulin.add_argument("--name", default="lfr", help="file stem (default: lfr)")
    ulin.set_defaults(func=_ulinearize)

    sdf = subparsers.add_parser("sdf", help="generate or check the scenario's SDF files")
    sdf_commands = sdf.add_subparsers(dest="sdf_command", metavar="SDF_COMMAND", required=True)
    for name, func, text in (
        ("generate", _sdf_generate, "write the SDF files from the scenario data file"),
        ("check", _sdf_check, "exit 1 if the SDF files differ from the scenario data file"),
    ):
        command = sdf_commands.add_parser(name, help=text)
        add_out_argument(
            command, required=False, default=SDF_DIRECTORY, type=Path, help="SDF directory"
        )
        add_scenario_argument(command)
        command.set_defaults(func=func)
