"""``oos analyze``: the paper's worst-case analysis (section 4) as tables and figures."""

from __future__ import annotations

import argparse

from oos_drake.analysis.stability import SweepOptions
from oos_drake.cli import add_deprecated_alias


def _controller(path):
    from oos_drake.analysis.controller import baseline_controller, load_controller

    if path:
        return load_controller(path)
    from oos_drake.analysis.loop import rotational_channels
    from oos_drake.control.baseline import TUNING_TIME_S
    from oos_drake.lfr import usubs
    from oos_drake.scenario.model import build_mission_model, mission_values

    plant = usubs(build_mission_model(), mission_values([TUNING_TIME_S])).model(0)
    return baseline_controller(rotational_channels(plant).nominal)


def _write_atomically(out, work):
    """Run ``work(tmp)`` in a sibling temporary folder that replaces ``out`` only when it
    succeeds: a failed or interrupted analysis leaves no half-written result folder. An
    existing ``out`` is replaced only if it holds a previous analysis (``summary.json``)."""
    import shutil
    from pathlib import Path

    out = Path(out).resolve()
    if out.exists() and any(out.iterdir()) and not (out / "summary.json").is_file():
        raise ValueError(f"--out {out} exists and holds something other than an analysis")
    tmp = out.with_name(f".{out.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        result = work(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if out.exists():
        shutil.rmtree(out)
    tmp.rename(out)
    return result


def run_analyze(args) -> int:
    """Run the analysis; exit status 0."""
    from oos_drake.analysis.run import AnalysisOptions, run_analysis

    controller = _controller(args.controller)
    if controller.label == "baseline":
        print(
            "WARNING: no --controller given: analyzing the BASELINE PD controller "
            "(paper section 3.1), not a synthesized one"
        )
    from oos_drake.analysis.tightening import TightenOptions

    sweep = SweepOptions(
        upper_iterations=args.iterations,
        n_jobs=args.workers,
        refine_iterations=args.refine_iterations,
    )
    tighten = TightenOptions(target_gap=args.target_gap, rounds=args.spike_rounds)
    options = AnalysisOptions(
        configurations=args.configurations,
        frequency_range_hz=(args.f_min, args.f_max),
        points_per_decade=args.points_per_decade,
        sweep=sweep,
        tighten=tighten,
        spike_budget=args.spike_budget,
        docking_phases=tuple(p for p in args.docking.split(",") if p),
        docking_points=args.docking_points,
        performance_models=args.performance_models,
        performance_points=args.performance_points,
        sensitivity=not args.no_sensitivity,
        time_check=not args.no_time_check,
        guarantee=args.guarantee,
        progress=not args.quiet,
        plant=args.plant,
    )
    summary = _write_atomically(args.out, lambda tmp: run_analysis(controller, tmp, options))
    m = summary["mission"]
    print(f"controller: {controller.label} ({controller.source}); plants: {args.plant}")
    print(
        f"mission: mu peak <= {m['mu_peak_upper']:.4g} "
        f"certified >= {m['mu_peak_lower']:.4g} (gap {m['gap_percent']:.2g} %) at "
        f"t = {m['peak_time_s']:.1f} s, f = {m['peak_frequency_hz']:.3g} Hz "
        f"(largest upper bound at t = {m['upper_peak_time_s']:.1f} s, "
        f"{m['upper_peak_frequency_hz']:.3g} Hz); stability margin "
        f"{m['stability_margin']:.3g} (paper: mu < 0.79 at 275 s, 0.55 Hz)"
    )
    for s in summary["subsets"]:
        print(
            f"  {s['subset']:>14s}: mu in [{s['mu_lower']:.4g}, {s['mu_upper']:.4g}] "
            f"(gap {s['gap [%]']:.2g} %) at t = {s['time [s]']:.0f} s, "
            f"{s['frequency [Hz]']:.3g} Hz; spikes left {s['spikes_left']} "
            f"({s['spike_stop']}{', BUDGET EXHAUSTED' if s['budget_exhausted'] else ''})"
        )
    for phase, pk in summary["docking"].items():
        print(
            f"docking {phase}: mu in [{pk['mu_lower']:.4g}, {pk['mu_upper']:.4g}] "
            f"(gap {pk['gap [%]']:.2g} %) at k = {pk['stiffness']:.3g}, "
            f"f = {pk['frequency [Hz]']:.3g} Hz; spikes left {pk['spikes_left']} "
            f"({pk['spike_stop']}{', BUDGET EXHAUSTED' if pk['budget_exhausted'] else ''})"
        )
    print(f"total time {summary['timings_s']['total']:.1f} s; outputs in {args.out}")
    return 0


def register(subparsers) -> None:
    """Add ``oos analyze``."""
    parser = subparsers.add_parser(
        "analyze",
        help="worst-case mu analysis over the mission and the docking phases (paper section 4)",
        description="Robust stability (mu bounds over configurations x frequencies x uncertainty "
        "subsets), worst-case performance, docking phases 7/8, sensitivity, time-domain check; "
        "writes Parquet tables, PNG figures and worst_cases.parquet.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--controller",
        default=None,
        help="controller JSON from `oos synth` (default: the BASELINE PD)",
    )
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument(
        "--configurations", type=int, default=330, help="equally spaced mission configurations"
    )
    parser.add_argument("--f-min", type=float, default=0.005, help="lowest grid frequency [Hz]")
    parser.add_argument("--f-max", type=float, default=5.0, help="highest grid frequency [Hz]")
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
    parser.add_argument("--docking", default="7,8", help="docking phases (comma-separated)")
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
    parser.add_argument("--workers", type=int, default=2, help="worker processes")
    parser.add_argument(
        "--plant",
        choices=("lfr", "drake"),
        default="lfr",
        help="uncertain plants: the TITOP LFR (default) or LFRs extracted from the Drake twin "
        "by ulinearize (same blocks; needs pydrake)",
    )
    parser.add_argument(
        "--guarantee",
        action="store_true",
        help="also prove each configuration's mu peak on the whole frequency axis (D-G scalings "
        "validated on intervals; several times the grid-only mu stages: see DESIGN.md)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    add_deprecated_alias(parser, "--fmin", "--f-min", type=float)
    add_deprecated_alias(parser, "--fmax", "--f-max", type=float)
    add_deprecated_alias(parser, "--jobs", "--workers", type=int)
    parser.set_defaults(func=run_analyze)
