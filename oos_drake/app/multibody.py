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
from dataclasses import dataclass
from pathlib import Path

from oos_drake.app.args import add_frequency_range, add_out_argument, add_scenario_argument

CASE_GROUPS = ("all", "moments", "phase7", "phase8")


def _select(cases, group: str):
    prefix = {"moments": "moment", "phase7": "phase 7", "phase8": "phase 8"}.get(group)
    return cases if prefix is None else [c for c in cases if c.label.startswith(prefix)]


@dataclass(frozen=True)
class ValidateOptions:
    """Options of the validation stage (:func:`compute_validation`): what ``oos validate``'s
    arguments hold (:func:`validate_options`; ``oos run`` passes the defaults,
    :func:`pipeline_validate_options`). Checked when made: a bad value is a one-line
    ``ValueError`` naming the option.

    Attributes
    ----------
    cases : str
        Configurations compared (``--cases``): one of :data:`CASE_GROUPS` (schema-1 scenarios).
    frequencies : int
        Number of frequencies (``--frequencies``), at least 1.
    f_min_hz, f_max_hz : float
        Frequency range [Hz] (``--f-min``, ``--f-max``), ``0 < f_min_hz <= f_max_hz``.
    tolerance : float
        Largest relative frequency-response error that passes (``--tolerance``), > 0.
    root_tolerance : float
        Largest relative pole/zero mismatch that passes (``--root-tolerance``), > 0.
    sdf_dir : Path or None
        SDF directory of the Drake twin (``--sdf-dir``; None: the scenario's own twin).
    """

    cases: str = "all"
    frequencies: int = 400
    f_min_hz: float = 0.01
    f_max_hz: float = 100.0
    tolerance: float = 1e-6
    root_tolerance: float = 1e-4
    sdf_dir: Path | None = None

    def __post_init__(self):
        if self.cases not in CASE_GROUPS:
            raise ValueError(f"--cases must be one of {', '.join(CASE_GROUPS)}, got {self.cases!r}")
        if not self.frequencies >= 1:
            raise ValueError(f"--frequencies {self.frequencies}: must be at least 1")
        if not 0 < self.f_min_hz <= self.f_max_hz:
            raise ValueError(
                f"--f-min {self.f_min_hz:g} / --f-max {self.f_max_hz:g} Hz: need 0 < f-min <= f-max"
            )
        for option, value in (
            ("--tolerance", self.tolerance),
            ("--root-tolerance", self.root_tolerance),
        ):
            if not value > 0:
                raise ValueError(f"{option} {value:g}: must be > 0")


@dataclass(frozen=True)
class ValidationResult:
    """Outcome of the validation stage (:func:`compute_validation`).

    Attributes
    ----------
    text : str
        The report ``oos validate`` prints (header, table, verdict), as ``validate.txt``
        holds it.
    status : int
        0 when every configuration passes, else 1 (``oos validate``'s exit status).
    results : tuple of CaseResult
        One per configuration (of the mission timeline for a tree).
    elapsed_s : float
        Wall time of the comparison [s].
    """

    text: str
    status: int
    results: tuple = ()
    elapsed_s: float = 0.0


def validate_options(args: argparse.Namespace) -> ValidateOptions:
    """The :class:`ValidateOptions` of ``oos validate``'s arguments ``args``."""
    return ValidateOptions(
        cases=args.cases,
        frequencies=args.frequencies,
        f_min_hz=args.f_min,
        f_max_hz=args.f_max,
        tolerance=args.tolerance,
        root_tolerance=args.root_tolerance,
        sdf_dir=args.sdf_dir,
    )


def pipeline_validate_options() -> ValidateOptions:
    """The validation options of ``oos run``: ``oos validate``'s defaults (what
    ``oos validate --scenario FILE`` builds)."""
    return ValidateOptions()


def compute_validation(scenario_file, options: ValidateOptions, progress=print):
    """Compare the Drake twin with the TITOP LFR of ``scenario_file`` (``oos validate``).

    Parameters
    ----------
    scenario_file : str or Path or None
        The scenario (a file or a shipped name; None: the paper's). A schema-2 tree is
        validated by :func:`oos_drake.app.tree.compute_tree_validation`.
    options : ValidateOptions
    progress : callable or None
        Receives each header line before the (long) comparison starts.

    Returns
    -------
    ValidationResult
    """
    from oos_drake.app.tree import is_tree_scenario

    if is_tree_scenario(scenario_file):  # schema 2: the tree's own twin on its timeline
        from oos_drake.app.tree import compute_tree_validation

        return compute_tree_validation(scenario_file, options, progress)
    import numpy as np

    from oos_drake.multibody.cross_check import run_validation, validation_cases
    from oos_drake.robust.lfr_analysis import frequency_grid
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario(None if scenario_file is None else str(scenario_file))
    cases = _select(validation_cases(scenario), options.cases)
    omega = frequency_grid(
        omega_range=(2 * np.pi * options.f_min_hz, 2 * np.pi * options.f_max_hz),
        points=options.frequencies,
    )
    header = (
        f"Drake twin vs TITOP LFR: 6x6 [F; T]@G1 -> [a; wdot]@G1, {options.frequencies} "
        f"frequencies {options.f_min_hz:g}-{options.f_max_hz:g} Hz; pass: response error <= "
        f"{options.tolerance:g}, poles/zeros <= {options.root_tolerance:g}"
    )
    if progress is not None:
        progress(header)
    start = time.perf_counter()
    results = run_validation(
        scenario,
        cases=cases,
        omega=omega,
        response_tolerance=options.tolerance,
        root_tolerance=options.root_tolerance,
        sdf_directory=options.sdf_dir,
    )
    elapsed = time.perf_counter() - start
    lines, status = verdict_lines(results, elapsed)
    return ValidationResult("\n".join([header, *lines]) + "\n", status, tuple(results), elapsed)


def write_validation(result: ValidationResult, folder) -> Path:
    """Write the validation report ``validate.txt`` in ``folder``; its path."""
    from oos_drake.files import atomic_write_bytes

    text = result.text.encode()
    return atomic_write_bytes(Path(folder) / "validate.txt", lambda stream: stream.write(text))


def validate(scenario_file, options: ValidateOptions, out) -> ValidationResult:
    """The validation stage of ``oos run``: :func:`compute_validation` with its report printed
    (as ``oos validate`` prints it) and written in ``out`` (``validate.txt``).

    Returns
    -------
    ValidationResult
        ``.status`` 1: a configuration failed (written all the same).
    """
    result = print_validation(scenario_file, options)
    write_validation(result, out)
    return result


def print_validation(scenario_file, options: ValidateOptions) -> ValidationResult:
    """:func:`compute_validation` printing its report (``oos validate``, a schema-1 scenario
    or a tree): the header when the comparison starts, the rest when it ends."""
    printed = []

    def progress(line: str) -> None:
        print(line)
        printed.append(line)

    result = compute_validation(scenario_file, options, progress=progress)
    print(result.text[sum(len(line) + 1 for line in printed) :], end="")
    return result


def _validate(args: argparse.Namespace) -> int:
    return print_validation(args.scenario, validate_options(args)).status


def verdict_lines(results, elapsed: float) -> tuple[list[str], int]:
    """The validation table and its verdict (lines), and the exit status: 0 when every
    configuration passes, else 1 (``oos validate`` of a schema-1 scenario and of a tree).

    Parameters
    ----------
    results : list of cross_check results
        One per configuration (``label``, ``passed``).
    elapsed : float
        Wall time of the validation [s].
    """
    from oos_drake.multibody.cross_check import format_table

    lines = [format_table(results)]
    failed = [r.label for r in results if not r.passed]
    if failed:
        lines.append(
            f"FAILED: {len(failed)} of {len(results)} configurations ({', '.join(failed)}); "
            f"{elapsed:.1f} s"
        )
        return lines, 1
    lines.append(f"all {len(results)} configurations pass ({elapsed:.1f} s)")
    return lines, 0


def print_verdict(results, elapsed: float) -> int:
    """Print :func:`verdict_lines` (the table and its verdict); the exit status."""
    lines, status = verdict_lines(results, elapsed)
    for line in lines:
        print(line)
    return status


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
