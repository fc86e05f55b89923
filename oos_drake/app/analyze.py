"""``oos analyze``: the paper's worst-case analysis (section 4) as tables and figures."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from oos_drake.analysis.controller import recorded_controller, scenario_controller
from oos_drake.analysis.stability import TIGHT_GAP, SweepOptions
from oos_drake.app.args import (
    add_deprecated_alias,
    add_frequency_range,
    add_loop_arguments,
    add_out_argument,
    add_parallel_arguments,
    add_quiet_argument,
    add_scenario_argument,
    loop_specification,
)
from oos_drake.files import atomic_folder


def _read_summary(analysis) -> dict:
    """The ``summary.json`` of the ``oos analyze`` folder ``analysis`` (``--analysis``)."""
    record = Path(analysis) / "summary.json"
    if not record.is_file():
        raise ValueError(f"--analysis {analysis}: no summary.json (not an oos analyze folder)")
    return json.loads(record.read_text())


def run_analyze(args) -> int:
    """``oos analyze``: :func:`analyze` with the command line's options; exit status 0."""
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario(args.scenario)
    controller = analysis_controller(args.controller, scenario, args)
    options = analysis_options(args, scenario)
    atomic_folder(
        args.out,
        lambda tmp: analyze(scenario, controller, options, tmp),
        marker="summary.json",
        what="an analysis",
    )
    print(f"outputs in {args.out}")
    return 0


def analysis_options(args, scenario):
    """The :class:`~oos_drake.analysis.run.AnalysisOptions` of ``oos analyze``'s arguments
    ``args`` (``--docking`` default: ``scenario``'s docking phases)."""
    from oos_drake.analysis.run import AnalysisOptions
    from oos_drake.analysis.tightening import TightenOptions

    sweep = SweepOptions(
        upper_iterations=args.iterations,
        n_jobs=args.workers,
        scheduler=args.scheduler,
        refine_iterations=args.refine_iterations,
    )
    tighten = TightenOptions(target_gap=args.target_gap, rounds=args.spike_rounds)
    return AnalysisOptions(
        configurations=args.configurations,
        frequency_range_hz=(args.f_min, args.f_max),
        points_per_decade=args.points_per_decade,
        sweep=sweep,
        tighten=tighten,
        spike_budget=args.spike_budget,
        docking_phases=_docking_phases(args.docking, scenario),
        docking_points=args.docking_points,
        performance_models=args.performance_models,
        performance_points=args.performance_points,
        sensitivity=not args.no_sensitivity,
        time_check=not args.no_time_check,
        guarantee=args.guarantee,
        guarantee_tight=args.guarantee_tight,
        progress=not args.quiet,
        plant=args.plant,
    )


def analysis_controller(path, scenario, loop=None):
    """The controller ``oos analyze`` and ``oos run`` analyze: ``path`` (a ``controller.json``;
    None: the BASELINE PD) on ``scenario``'s design data, with the loop model of ``loop``
    (``--sampled`` / ``--delay``; None: the continuous loop)."""
    loop = loop or argparse.Namespace(sampled=False, delay=None)
    controller = scenario_controller(path, scenario)
    return dataclasses.replace(controller, spec=loop_specification(controller.spec, loop))


def pipeline_analysis_options(
    scenario, *, quick: bool, workers: int, scheduler=None, grid_only: bool = False
):
    """The analysis options of ``oos run``: ``oos analyze``'s defaults, 40 configurations with
    ``quick``, the whole-axis guarantee unless ``grid_only``."""
    from oos_drake.analysis.run import AnalysisOptions

    return AnalysisOptions(
        configurations=40 if quick else AnalysisOptions.configurations,
        sweep=SweepOptions(n_jobs=workers, scheduler=scheduler),
        docking_phases=_docking_phases(None, scenario),
        guarantee=not grid_only,
    )


def analyze(scenario, controller, options, out):
    """The analysis stage: compute the analysis, write it in ``out``, print its peaks.

    Parameters
    ----------
    scenario : Scenario
    controller : Controller
        From :func:`analysis_controller`.
    options : AnalysisOptions
    out : Path
        The (new) output folder.

    Returns
    -------
    AnalysisResult
    """
    from oos_drake.analysis.run import compute_analysis
    from oos_drake.analysis.writers import write_analysis

    if controller.label == "baseline":
        print(
            "WARNING: no --controller given: analyzing the BASELINE PD controller "
            "(paper section 3.1), not a synthesized one"
        )
    result = compute_analysis(controller, options, scenario=scenario)
    summary = write_analysis(result, out)
    print(f"scenario: {scenario.name} ({scenario.source})")
    loop = summary["loop"]
    print(
        f"controller: {controller.label} ({controller.source}); plants: {options.plant}; loop: "
        + (
            f"sampled at {loop['sample_rate_hz']:g} Hz (hold order {loop['hold_order']}, delay "
            f"{loop['delay_s']:g} s)"
            if loop["sampled"]
            else "continuous"
        )
    )
    for line in peak_lines(summary):
        print(line)
    print(f"total time {summary['timings_s']['total']:.1f} s")
    return result


def _docking_phases(value: str | None, scenario) -> tuple[str, ...]:
    """``--docking``'s phases; None: every docking phase of the scenario (a tree's: the docked
    phases that start a docking, ``TreeMissionSpan.docking_phases``)."""
    if value is None:
        return tuple(str(p.name) for p in scenario.mission.docking_phases)
    return tuple(p for p in value.split(",") if p)


FELL_BACK = "from a fallback cover: the tight level did not close (--guarantee-tight)"
"""Printed beside a guaranteed bound whose cover fell back to a higher starting level at one
configuration at least (``guarantee fell back`` in ``stability_peaks.parquet``): still proved
on the whole axis, but less tight than asked."""


def peak_lines(summary: dict) -> list[str]:
    """The printed peaks of an analysis summary: the mission's, each subset's, each docking
    phase's, one line each.

    Every peak is shown as ``mu in [lower, upper]``: the best certified lower bound found
    (grid, refinement, searches) and the upper bound of its scope (the whole-axis guarantee,
    or the analyzed points with --grid-only); the grid's largest upper bound only beside it.
    A guaranteed bound whose cover fell back to a higher level says so (:data:`FELL_BACK`).

    Parameters
    ----------
    summary : dict
        The ``summary.json`` of :func:`~oos_drake.analysis.run.run_analysis`.

    Returns
    -------
    list of str
    """
    m = summary["mission"]
    if m.get("mu_peak_upper_scope") == "whole axis":
        scope = (
            f"<= {m['mu_peak_upper']:.4g} on the whole frequency axis "
            f"(guaranteed; largest upper bound on the grid {m['mu_peak_upper_grid']:.4g}),"
        )
    else:  # the upper bound of the grid holds where it was computed, not between
        scope = (
            f"<= {m['mu_peak_upper']:.4g} on the analyzed frequencies only "
            "(--grid-only: not proved between them),"
        )
    if m.get("guarantee_fell_back"):
        scope += f" {FELL_BACK},"
    lines = [
        f"mission: mu peak {scope} "
        f"certified >= {m['mu_peak_lower']:.4g} (gap {m['gap_percent']:.2g} %) at "
        f"t = {m['peak_time_s']:.1f} s, f = {m['peak_frequency_hz']:.3g} Hz "
        f"(largest upper bound at t = {m['upper_peak_time_s']:.1f} s, "
        f"{m['upper_peak_frequency_hz']:.3g} Hz); stability margin "
        f"{m['stability_margin']:.3g}",
        "  (for comparison only, the paper's published value: mu < 0.79 near 275 s)",
    ]
    for s in summary["subsets"]:
        where = f"t = {s['time [s]']:.0f} s, {s['frequency [Hz]']:.3g} Hz"
        bounds = (s["mu lower [-]"], s["mu upper [-]"], s["mu upper scope"], s["mu upper grid [-]"])
        lines.append(f"  {s['subset']:>14s}: " + _peak_line(*bounds, s, where))
    for phase, pk in summary["docking"].items():
        where = f"k = {pk['stiffness']:.3g}, f = {pk['frequency [Hz]']:.3g} Hz"
        bounds = (pk["mu_lower"], pk["mu_upper"], pk["mu_upper_scope"], pk["mu_upper_grid"])
        lines.append(f"docking {phase}: " + _peak_line(*bounds, pk, where))
    return lines


def _peak_line(lower, upper, scope, grid_upper, peak: dict, where: str) -> str:
    """``mu in [lower, upper] (upper: SCOPE; grid <= ..) (gap ..) at WHERE; spikes left ..``:
    one certified peak of the summary (``peak``: its gap and spike-resolution entries).

    ``[lower, upper]`` is the peak's interval: the best certified lower bound and the upper
    bound of ``scope`` (the whole-axis guarantee, or the analyzed points with --grid-only);
    the grid's largest upper bound is shown beside it, never as the peak's."""
    fell_back = peak.get("guarantee fell back", peak.get("guarantee_fell_back", False))
    scope = f"{scope}, {FELL_BACK}" if fell_back else scope
    axis = f"(upper: {scope}; largest on the grid {grid_upper:.4g}) "
    exhausted = ", BUDGET EXHAUSTED" if peak["budget exhausted"] else ""
    return (
        f"mu in [{lower:.4g}, {upper:.4g}] {axis}(gap {peak['gap [%]']:.2g} %) at {where}; "
        f"spikes left {peak['spikes left']} ({peak['spike stop']}{exhausted})"
    )


def run_margins(args) -> int:
    """``oos margins``: :func:`margins` with the command line's options; exit status 0."""
    from oos_drake.scenario.data import load_scenario

    scenario_file = args.scenario
    if args.analysis:
        # the rays are the analysis' blocks: its scenario (--scenario must be that one)
        recorded = _read_summary(args.analysis).get("scenario")
        scenario_file = _analysis_scenario(recorded, args.analysis, args.scenario)
    scenario = load_scenario(scenario_file)
    controller = margins_controller(args.controller, scenario, args.delay)
    options = margins_options(args)
    atomic_folder(
        args.out,
        lambda tmp: margins(scenario, controller, options, tmp),
        marker="summary.json",
        what="an analysis",
    )
    print(f"outputs in {args.out}")
    return 0


def margins_options(args):
    """The :class:`~oos_drake.analysis.margins.MarginsOptions` of ``oos margins``' arguments."""
    from oos_drake.analysis.margins import MarginsOptions

    analysis = Path(args.analysis) if args.analysis else None
    return MarginsOptions(args.configurations, analysis, progress=not args.quiet)


def pipeline_margins_options(analysis, configurations: int):
    """The margins options of ``oos run``: ``configurations`` mission configurations, the rays
    of the ``analysis`` folder, no progress bar (what ``oos margins --analysis ANALYSIS
    --configurations N --quiet`` builds)."""
    from oos_drake.analysis.margins import MarginsOptions

    return MarginsOptions(configurations, Path(analysis), progress=False)


def margins_controller(path, scenario, delay_s=None):
    """The controller ``oos margins`` and ``oos run`` break: ``path`` (a ``controller.json``;
    None: the BASELINE PD) on ``scenario``'s design data, the computation delay ``delay_s``
    [s] of its sampled loops (``--delay``; None: the specification's)."""
    controller = scenario_controller(path, scenario)
    if delay_s is not None:
        if delay_s < 0:
            raise ValueError(f"--delay must be >= 0 s, got {delay_s}")
        controller = dataclasses.replace(
            controller, spec=dataclasses.replace(controller.spec, computation_delay_s=delay_s)
        )
    return controller


def margins(scenario, controller, options, out):
    """The margins stage: compute the margins, write them in ``out``, print the worst.

    Parameters
    ----------
    scenario : Scenario
    controller : Controller
        From :func:`margins_controller`.
    options : MarginsOptions
    out : Path
        The (new) output folder.

    Returns
    -------
    MarginsResult
    """
    from oos_drake.analysis.margins import compute_margins
    from oos_drake.analysis.writers import write_margins

    result = compute_margins(controller, scenario, options)
    record = write_margins(result, out)
    for loop, values in record["worst"].items():
        print(
            f"{loop:>14s}: worst over the mission: GM {values['gain margin upper [dB]']:.3g} dB, "
            f"PM {values['phase margin [deg]']:.3g} deg, DM {values['delay margin [s]']:.3g} s, "
            f"disk {values['disk margin [-]']:.3g} (multiloop "
            f"{values['multiloop disk margin [-]']:.3g})"
        )
    for ray in record.get("rays", []):
        print(
            f"ray {ray['ray']} at t = {ray['time [s]']:.0f} s: boundary continuous "
            f"{ray['boundary continuous [-]']:.4g}, sampled model "
            f"{ray['boundary sampled model [-]']:.4g}, exact sampled "
            f"{ray['boundary sampled [-]']:.4g}"
        )
    print(f"{record['time_s']:.1f} s")
    return result


def _analysis_scenario(record, analysis, given) -> str | None:
    """The scenario file an analysis ran on (``record``: its ``summary.json`` scenario entry;
    None for analyses written before scenarios were recorded: the paper's). ``given``
    (``--scenario``) must be that file.

    Raises
    ------
    ValueError
        The file changed since the analysis, the analysis overrode scenario values (an
        ``oos study`` point), or ``--scenario`` names another scenario.
    """
    import hashlib

    from oos_drake.scenario.data import scenario_path

    if record is None:
        path = scenario_path(None)
    else:
        path = Path(record["file"])
        if not path.is_file() or (
            hashlib.sha256(path.read_bytes()).hexdigest() != record.get("sha256")
        ):
            raise ValueError(
                f"--analysis {analysis}: its scenario file {path} is gone or changed since the "
                "analysis; re-run oos analyze"
            )
        if record.get("overrides"):
            raise ValueError(
                f"--analysis {analysis}: it overrides scenario values {record['overrides']} "
                "(an oos study point); confirm a plain analysis of a scenario file"
            )
    if given is not None and scenario_path(given).read_bytes() != path.read_bytes():
        raise ValueError(f"--scenario {given}: not the scenario of --analysis {analysis} ({path})")
    return str(path)


def confirm_inputs(analysis, path=None, scenario_file=None):
    """What the confirmation of the ``oos analyze`` folder ``analysis`` reads: ``(peaks,
    gain_cases, controller, scenario)``.

    The certified peaks (:func:`~oos_drake.analysis.confirm.read_peaks`) and worst-case gains
    (:func:`~oos_drake.analysis.performance_twin.read_gain_cases`) of the folder; the
    controller of ``path`` (``--controller``), else the one the analysis recorded (its gains
    must be the analysis', ``summary.json``); the scenario the analysis ran on
    (:func:`_analysis_scenario`; ``scenario_file``, ``--scenario``, must be that one).

    Raises
    ------
    ValueError
        Not an analysis folder, a controller gone or with other gains, another scenario.
    """
    from oos_drake.analysis.confirm import read_peaks
    from oos_drake.analysis.performance_twin import read_gain_cases
    from oos_drake.scenario.data import load_scenario

    peaks = read_peaks(analysis)
    summary = _read_summary(analysis)
    scenario = _analysis_scenario(summary.get("scenario"), analysis, scenario_file)
    recorded = summary.get("controller", {})
    if path is None and recorded.get("label") == "synthesized":
        path = recorded.get("source")
        if not path or not Path(path).exists():
            raise ValueError(
                f"--analysis {analysis}: its controller {path} is gone; pass --controller"
            )
    scenario = load_scenario(scenario)
    controller = scenario_controller(path, scenario)
    if not controller.system.equals(recorded_controller(recorded, controller.system)):
        raise ValueError(
            f"--controller {path}: its gains differ from those the analysis {analysis} used"
        )
    return peaks, read_gain_cases(analysis), controller, scenario


def confirm_options(args):
    """The :class:`~oos_drake.analysis.confirm.ConfirmationOptions` of ``oos confirm``'s
    arguments."""
    from oos_drake.analysis.confirm import ConfirmationOptions, ConfirmOptions

    return ConfirmationOptions(
        ConfirmOptions(alpha_limit=args.alpha_limit),
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )


def pipeline_confirm_options(workers: int, scheduler=None):
    """The confirmation options of ``oos run``: ``oos confirm``'s defaults on ``workers``
    processes of ``scheduler`` (what ``oos confirm --workers N [--scheduler S]`` builds)."""
    from oos_drake.analysis.confirm import ConfirmationOptions

    return ConfirmationOptions(workers=workers, scheduler=scheduler)


def run_confirm(args) -> int:
    """``oos confirm``: :func:`confirm` with the command line's options; exit status 0."""
    from oos_drake.analysis.confirm import CONFIRMATION_FILE

    options = confirm_options(args)
    inputs = confirm_inputs(args.analysis, args.controller, args.scenario)
    out = Path(args.out) if args.out else Path(args.analysis).parent / "confirm"
    atomic_folder(
        out,
        lambda tmp: confirm(*inputs, options, tmp),
        marker=CONFIRMATION_FILE,
        what="a confirmation",
    )
    print(f"outputs in {out}")
    return 0


def confirm(peaks, gain_cases, controller, scenario, options, out):
    """The confirmation stage: confirm the analysis' certified peaks and worst-case gains on
    the Drake twin, write them in ``out``, print the table.

    Parameters
    ----------
    peaks, gain_cases, controller, scenario
        From :func:`confirm_inputs`.
    options : ConfirmationOptions
    out : Path
        The (new) output folder.

    Returns
    -------
    ConfirmationResult
    """
    from oos_drake.analysis.confirm import compute_confirmation
    from oos_drake.analysis.performance_twin import summary_line
    from oos_drake.analysis.writers import write_confirmation

    result = compute_confirmation(peaks, gain_cases, controller, scenario, options)
    summary = write_confirmation(result, out)
    print(f"scenario: {summary['scenario']['name']} ({summary['scenario']['source']})")
    print(f"controller: {controller.label} ({controller.source})")
    print(
        f"{'study':>10s} {'subset':>14s} {'f crit':>8s} {'a cont':>7s} {'a samp':>7s} "
        f"{'a phys':>7s} {'a nonl':>7s} {'f osc':>7s}  status"
    )
    for r in summary["peaks"]:
        print(
            f"{r['study']:>10s} {r['subset']:>14s} {r['critical frequency [Hz]']:8.4g} "
            f"{r['alpha linear continuous [-]']:7.4g} {r['alpha linear sampled [-]']:7.4g} "
            f"{r['alpha physical max [-]']:7.4g} {r['alpha nonlinear [-]']:7.4g} "
            f"{r['oscillation frequency [Hz]']:7.4g}  {r['status']}"
        )
    for warning in summary["warnings"]:  # a crossing the analysis missed: said where it is read
        print(f"WARNING {warning}")
    if summary["performance"]:
        print("worst-case gains on the twin (gain > 1: requirement violated):")
    for row in summary["performance"]:
        print("  " + summary_line(row))
    print(f"confirmation in {summary['time_s']:.1f} s")
    return result


def run_study_command(args) -> int:
    """``oos study``: one table and one figure of the margin against a swept scenario value."""
    from oos_drake.analysis.study import StudyOptions, Sweep, run_study

    sweep = Sweep.parse(args.vary)
    analysis = dataclasses.replace(
        StudyOptions().analysis,
        configurations=args.configurations,
        docking_points=args.docking_points,
        docking_phases=tuple(p for p in args.docking.split(",") if p),
    )
    options = StudyOptions(
        controller=args.controller,
        synthesize=args.synthesize,
        synthesis_configurations=args.synthesis_configurations,
        analysis=analysis,
        workers=args.workers,
        scheduler=args.scheduler,
    )
    table = atomic_folder(
        args.out,
        lambda tmp: run_study(args.scenario, sweep, tmp, options, not args.quiet),
        marker="summary.json",
        what="an analysis",
    )
    summary = json.loads((Path(args.out) / "summary.json").read_text())
    columns = [
        sweep.column,
        "mu upper [-]",
        "mu lower [-]",
        "margin lower [-]",
        "margin upper [-]",
        "worst study",
        "pointing worst gain upper [-]",
    ]
    if args.synthesize:
        columns.append("gamma [-]")
    print(table[columns].to_string(index=False))
    crossing = summary["margin_reaches_1"]
    print(
        f"margin 1 reached: certified lower bound at {crossing['certified']}, attained upper "
        f"bound at {crossing['attained']} ({sweep.column}; None: not within the sweep)"
    )
    print(f"outputs in {args.out}: study.parquet, study.csv, study.png, points/")
    return 0


def _register_study(subparsers) -> None:
    parser = subparsers.add_parser(
        "study",
        help="parameter study: the certified robustness margin against one scenario value",
        description="Sweep one number of the scenario file (--vary PATH=start:stop:n, PATH a "
        "dotted path such as hubs.RH2.mass or control.pointing_requirement), re-run the mu "
        "analysis (and with --synthesize the synthesis) for each value in parallel, and write "
        "one table (study.parquet/.csv) and one figure (study.png) of the margin 1/mu (upper "
        "and lower bound) against the value.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    add_scenario_argument(parser)
    parser.add_argument("--vary", required=True, metavar="PATH=start:stop:n", help="swept value")
    add_out_argument(parser)
    parser.add_argument(
        "--controller",
        default=None,
        help="controller JSON analyzed at every value (default: the BASELINE PD tuned on each "
        "value's scenario); with --synthesize, the start of each synthesis",
    )
    parser.add_argument(
        "--synthesize", action="store_true", help="re-synthesize the controller at every value"
    )
    parser.add_argument(
        "--configurations", type=int, default=40, help="mission configurations per analysis"
    )
    parser.add_argument(
        "--synthesis-configurations",
        type=int,
        default=40,
        help="mission configurations per synthesis",
    )
    parser.add_argument("--docking", default="7,8", help="docking phases (comma-separated)")
    parser.add_argument("--docking-points", type=int, default=40, help="stiffness values")
    add_parallel_arguments(parser, help="values analyzed in parallel")
    add_quiet_argument(parser)
    parser.set_defaults(func=run_study_command)


def _common_arguments(parser, *, configurations: int) -> None:
    """``--controller``, ``--out`` and ``--configurations`` of ``oos analyze`` / ``oos margins``."""
    parser.add_argument(
        "--controller",
        default=None,
        help="controller JSON from `oos synth` (default: the BASELINE PD)",
    )
    add_out_argument(parser)
    parser.add_argument(
        "--configurations",
        type=int,
        default=configurations,
        help="equally spaced mission configurations",
    )


def register(subparsers) -> None:
    """Add ``oos analyze``, ``oos margins``, ``oos confirm`` and ``oos study``."""
    _register_study(subparsers)
    parser = subparsers.add_parser(
        "analyze",
        help="worst-case mu analysis over the mission and the docking phases (paper section 4)",
        description="Robust stability (mu bounds over configurations x frequencies x uncertainty "
        "subsets), worst-case performance, docking phases 7/8, sensitivity, time-domain check; "
        "writes Parquet tables, PNG figures and worst_cases.parquet.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    _common_arguments(parser, configurations=330)
    add_frequency_range(parser, 0.005, 5.0)
    parser.add_argument(
        "--points-per-decade",
        type=int,
        default=12,
        help="common grid density (plus points on lightly damped poles)",
    )
    parser.add_argument(
        "--iterations",
        type=int,
        default=30,
        help="BFGS iterations of the mu upper bound on the grid",
    )
    parser.add_argument(
        "--refine-iterations",
        type=int,
        default=100,
        help="BFGS iterations at the peak refinement points",
    )
    parser.add_argument(
        "--target-gap",
        type=float,
        default=0.03,
        help="certified peaks: resolve upper bounds above (1 + gap) x best lower bound",
    )
    parser.add_argument(
        "--spike-rounds", type=int, default=6, help="rounds of the spike resolution per subset"
    )
    parser.add_argument(
        "--spike-budget",
        type=float,
        default=240.0,
        help="wall-clock budget of the spike resolution of the whole analysis [s] (each subset "
        "also stops after 90 s); where it is spent, the peaks table says so",
    )
    parser.add_argument(
        "--docking",
        default=None,
        help="docking phases (comma-separated; default: the scenario's, the paper's 7,8; "
        "a schema-2 tree's: its docked phases that start a docking)",
    )
    parser.add_argument("--docking-points", type=int, default=300, help="stiffness values")
    parser.add_argument(
        "--performance-models",
        type=int,
        default=6,
        help="configurations of the worst-case gain study",
    )
    parser.add_argument(
        "--performance-points",
        type=int,
        default=24,
        help="frequencies of the worst-case gain study",
    )
    parser.add_argument("--no-sensitivity", action="store_true", help="skip the sensitivity table")
    parser.add_argument("--no-time-check", action="store_true", help="skip the time-domain check")
    add_parallel_arguments(parser)
    parser.add_argument(
        "--plant",
        choices=("lfr", "drake"),
        default="lfr",
        help="uncertain plants: the TITOP LFR (default) or LFRs extracted from the Drake twin "
        "by ulinearize (same blocks; needs pydrake)",
    )
    whole_axis = parser.add_mutually_exclusive_group()
    whole_axis.add_argument(
        "--grid-only",
        dest="guarantee",
        action="store_false",
        help="upper bounds on the analyzed frequencies only, not proved between them (faster: "
        "see docs/ANALYSIS-RESULTS.md); default: each analyzed configuration's mu peak is "
        "proved on the whole frequency axis (D-G scalings validated on intervals)",
    )
    whole_axis.add_argument(
        "--guarantee",
        dest="guarantee",
        action="store_true",
        help="prove each analyzed configuration's mu peak on the whole frequency axis (the "
        "default; explicit for scripts)",
    )
    parser.set_defaults(guarantee=True)
    parser.add_argument(
        "--guarantee-tight",
        type=float,
        default=TIGHT_GAP,
        help="whole-axis guarantee: relative margin [-] of the first level of the covers above "
        "the largest mu bound found (0.015: 1.5 %%); a configuration whose cover does not close "
        "there is covered again from (1 + --target-gap) x the lower bound (stability_peaks: "
        "'guarantee fell back')",
    )
    add_loop_arguments(parser)
    add_quiet_argument(parser)
    add_scenario_argument(parser)
    add_deprecated_alias(parser, "--fmin", "--f-min", type=float)
    add_deprecated_alias(parser, "--fmax", "--f-max", type=float)
    add_deprecated_alias(parser, "--jobs", "--workers", type=int)
    parser.set_defaults(func=run_analyze)

    parser = subparsers.add_parser(
        "margins",
        help="loop-at-a-time gain/phase/delay and disk margins over the mission, continuous and "
        "sampled-data loops",
        description="Breaks the attitude loop at the wheel input at each mission configuration "
        "(nominal plant) and writes margins.parquet and margins.png for the continuous loop, the "
        "exact sampled-data loop of the flight software and the rational hold model of "
        "`oos analyze --sampled`; with --analysis, the stability boundary of the three loops "
        "along the analysis' worst real-parameter perturbations (ray_boundaries.parquet).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    _common_arguments(parser, configurations=60)
    parser.add_argument(
        "--delay",
        type=float,
        default=None,
        help="computation delay of the sampled loops [s] (default: DesignSpecification."
        "computation_delay_s, 0)",
    )
    parser.add_argument(
        "--analysis",
        default=None,
        help="an `oos analyze` output folder: also compare the stability boundaries along its "
        "worst real-parameter perturbations",
    )
    add_scenario_argument(parser)
    add_quiet_argument(parser)
    parser.set_defaults(func=run_margins)

    confirm = subparsers.add_parser(
        "confirm",
        help="confirm each certified worst case of an analysis on the nonlinear Drake twin",
        description="For each certified mu peak: the stability boundary along the worst "
        "perturbation's ray (scaled by alpha) for the continuous and the sampled-data linear "
        "loops, the physical limit of the parameters, and the nonlinear boundary on the frozen "
        "Drake mission by bisection; writes confirmation.parquet, time histories and figures. "
        "For each worst-case gain (performance.parquet): the twin driven by the worst input "
        "with the worst perturbation against the linear and sampled-data gains "
        "(performance_confirmation.parquet).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    confirm.add_argument("--analysis", required=True, help="folder written by `oos analyze`")
    confirm.add_argument(
        "--controller",
        default=None,
        help="controller JSON (default: the one the analysis recorded in summary.json)",
    )
    add_out_argument(
        confirm, required=False, help="output directory (default: ANALYSIS/../confirm)"
    )
    confirm.add_argument(
        "--alpha-limit",
        type=float,
        default=4.0,
        help="largest perturbation scale alpha searched on the twin [-] (the boundary beyond it "
        "is reported as not reached)",
    )
    add_scenario_argument(confirm, default="the one the analysis folder records")
    add_parallel_arguments(confirm)
    add_quiet_argument(confirm)
    confirm.set_defaults(func=run_confirm)
