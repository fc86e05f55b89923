"""``oos campaign run|resume|rerun|report|replay|falsify``: campaigns from the command line.

Examples::

    oos campaign run demo --out out/demo --workers 2
    oos campaign run demo --out out/demo --scheduler local     # local Dask cluster
    oos campaign resume out/demo                  # after a crash or kill -9
    oos campaign rerun out/demo --case 17         # recompute run 17, compare with the record
    oos campaign report out/demo                  # figures + tables in out/demo/report
    oos campaign replay out/demo --case 17        # 3D replay in out/demo/replay/case_17.html
    oos campaign falsify demo --budget 200        # search the worst case (out/falsify/demo)
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from pathlib import Path

import pandas as pd

from oos_drake.app.args import (
    add_out_argument,
    add_parallel_arguments,
    add_quiet_argument,
    run_command,
)


def _add_controller_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--controller",
        default=None,
        metavar="JSON",
        help="controller.json flown by the simulator (its 'controller' option; default: the "
        "scenario's baseline PD)",
    )


def _add_executor_options(parser: argparse.ArgumentParser) -> None:
    add_parallel_arguments(
        parser,
        workers=os.cpu_count() or 1,
        help="worker processes (default: CPU count; 1 runs in this process)",
    )
    add_quiet_argument(parser, old=True)


def _print_summary(summary) -> None:
    counts = ", ".join(f"{k}: {v}" for k, v in sorted(summary.status_counts.items()))
    print(
        f"campaign {summary.directory}: {summary.n_runs} runs ({summary.executed} run now, "
        f"{summary.skipped} already done); status {counts}; {summary.n_pass} passed every "
        f"requirement"
    )
    print(f"results: {Path(summary.directory) / 'runs.parquet'}")
    print(f"next: oos campaign report {summary.directory}")


def _parse_options(pairs: list[str] | None) -> dict:
    """``KEY=VALUE`` strings -> dict; a VALUE that parses as JSON is taken as JSON."""
    options = {}
    for pair in pairs or ():
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"--simulator-option {pair!r}: expected KEY=VALUE")
        try:
            options[key] = json.loads(value)
        except json.JSONDecodeError:
            options[key] = value
    return options


#: Simulators whose ``controller`` option is the flown controller (default: the baseline PD).
_FLY_A_CONTROLLER = (
    "oos_drake.campaign.drake_simulator:make_simulator",
    "oos_drake.campaign.tree_simulator:make_simulator",
)


def _simulator_options(args: argparse.Namespace) -> dict:
    """The simulator options of ``--simulator-option`` and ``--controller``."""
    options = _parse_options(args.simulator_option)
    if args.controller is not None:
        if "controller" in options:
            raise ValueError("--controller and --simulator-option controller=...: give one")
        path = Path(args.controller)
        if not path.is_file():
            raise ValueError(f"--controller {args.controller}: no such file")
        options["controller"] = str(path.resolve())
    return options


def _controller_note(spec, options: dict) -> str | None:
    """What to say when a simulator that flies a controller got none: it then flies the
    scenario's baseline PD, not the loop the analysis certified."""
    recipe = spec.simulator
    if recipe.factory in _FLY_A_CONTROLLER and "controller" not in {
        **recipe.option_dict,
        **options,
    }:
        return (
            "note: no --controller was given: the mission flew the scenario's baseline PD, not "
            "a synthesized controller"
        )
    return None


def campaign_options(args: argparse.Namespace):
    """The :class:`~oos_drake.campaign.runner.CampaignOptions` of ``oos campaign run``'s
    arguments (checked: nothing is written with a bad one)."""
    from oos_drake.campaign.runner import CampaignOptions

    return CampaignOptions(
        spec=Path(args.spec),
        worst_cases=Path(args.worst_cases) if args.worst_cases is not None else None,
        simulator_options=_simulator_options(args),
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )


def pipeline_campaign_options(
    spec: str | Path,
    worst_cases: str | Path,
    controller: str | Path,
    workers: int,
    scheduler: str | None = None,
):
    """The campaign options of ``oos run``: the campaign ``spec`` guided by the analysis'
    ``worst_cases`` and flying ``controller`` on ``workers`` processes of ``scheduler`` (what
    ``oos campaign run SPEC --worst-cases W --simulator-option controller=C --workers N
    [--scheduler S]`` builds; ``controller`` made absolute)."""
    from oos_drake.campaign.runner import CampaignOptions

    return CampaignOptions(
        spec=Path(spec),
        worst_cases=Path(worst_cases),
        simulator_options={"controller": str(Path(controller).resolve())},
        workers=workers,
        scheduler=scheduler,
    )


def _run_campaign(options, out: Path):
    """Run the campaign of ``options`` into the new folder ``out``, print its summary;
    returns the :class:`~oos_drake.campaign.runner.CampaignSummary`."""
    from oos_drake.campaign.runner import run_campaign
    from oos_drake.campaign.spec import load_spec

    summary = run_campaign(
        options.spec,
        out,
        workers=options.workers,
        scheduler=options.scheduler,
        progress=options.progress,
        worst_cases=options.worst_cases,
        simulator_options=options.simulator_options,
    )
    _print_summary(summary)
    spec = load_spec(options.spec, worst_cases=options.worst_cases)
    if note := _controller_note(spec, options.simulator_options):
        print(note)
    return summary


def campaign(options, out: str | Path):
    """The campaign stage of ``oos run``: resume the campaign in ``out`` when it holds one
    (its ``spec.toml``: no finished run is lost or repeated), else run the campaign of
    ``options`` into ``out`` (what a campaign killed before its spec was written left there
    removed first); prints the summary.

    Parameters
    ----------
    options : CampaignOptions
        From :func:`pipeline_campaign_options` (a resumed campaign takes only its workers,
        scheduler and progress bar: the rest is the folder's).
    out : Path
        The campaign folder.

    Returns
    -------
    CampaignSummary
    """
    from oos_drake.campaign.runner import resume_campaign
    from oos_drake.campaign.store import SPEC_FILE

    out = Path(out)
    if (out / SPEC_FILE).is_file():
        print(f"campaign: resuming {out}")
        summary = resume_campaign(
            out, workers=options.workers, scheduler=options.scheduler, progress=options.progress
        )
        _print_summary(summary)
        return summary
    shutil.rmtree(out, ignore_errors=True)
    print(f"campaign -> {out}")
    return _run_campaign(options, out)


def campaign_report(directory: str | Path, worst: int = 5, confirm: str | Path | None = None):
    """Write the report of the campaign in ``directory`` (``DIR/report``), print its text;
    returns the :class:`~oos_drake.campaign.report.CampaignReport`."""
    from oos_drake.campaign.report import write_report

    report = write_report(directory, worst=worst, confirm=confirm)
    print(report.text)
    print(f"report: {report.directory}")
    return report


def _run(args: argparse.Namespace) -> int:
    from oos_drake.campaign.spec import load_spec

    options = campaign_options(args)
    spec = load_spec(options.spec, worst_cases=options.worst_cases)
    out = args.out if args.out is not None else Path("out") / "campaigns" / spec.name
    _run_campaign(options, Path(out))
    return 0


def _resume(args: argparse.Namespace) -> int:
    from oos_drake.campaign.runner import resume_campaign

    summary = resume_campaign(
        args.directory,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )
    _print_summary(summary)
    return 0


def _rerun(args: argparse.Namespace) -> int:
    from oos_drake.campaign.runner import rerun_case

    result = rerun_case(args.directory, args.case)
    row = result.row.iloc[0]
    columns = [
        c
        for c in result.row.columns
        if "[" in c or c.startswith("pass") or c in ("run_id", "seed", "status", "error")
    ]
    with pd.option_context("display.max_rows", None, "display.float_format", "{:.10g}".format):
        print(row[columns].to_string())
    if result.identical is None:
        print(f"run {args.case} has no recorded result yet")
        return 0
    with pd.option_context("display.float_format", "{:.17g}".format):
        print(result.comparison.to_string())
    for package, (then, now) in result.environment_changes.items():
        print(f"note: {package} was {then} when the campaign ran, is {now} now")
    if result.identical:
        print(f"run {args.case}: metrics and status reproduced exactly")
        return 0
    print(f"run {args.case}: DIFFERS from the recorded result", file=sys.stderr)
    return 1


def _report(args: argparse.Namespace) -> int:
    campaign_report(args.directory, worst=args.worst, confirm=args.confirm)
    return 0


def _parse_window(text: str | None) -> tuple[float, float] | None:
    """``"START,END"`` [s] -> ``(start, end)``; a bad text is a ``ValueError`` naming it."""
    if text is None:
        return None
    try:
        start, end = (float(x) for x in text.split(","))
    except ValueError:
        raise ValueError(f"--window {text!r}: expected START,END in seconds") from None
    return start, end


def _falsify(args: argparse.Namespace) -> int:
    from oos_drake.campaign.falsify import falsify
    from oos_drake.campaign.spec import load_spec

    spec = load_spec(args.spec, worst_cases=args.worst_cases)
    out = args.out if args.out is not None else Path("out") / "falsify" / spec.name
    simulator_options = _simulator_options(args)
    result = falsify(
        args.spec,
        out,
        budget=args.budget,
        workers=args.workers,
        scheduler=args.scheduler,
        worst_cases=args.worst_cases,
        progress=not args.quiet,
        simulator_options=simulator_options,
        confirm=args.confirm,
        window=_parse_window(args.window),
        search=args.search,
    )
    print(result.sentence())
    if result.reused:
        print(f"resumed: {result.reused} points taken from the folder, {result.evaluated} run now")
    with pd.option_context("display.width", 160, "display.float_format", "{:.6g}".format):
        print(result.best.drop(labels=["unit coordinates", "error"]).to_string())
    print(f"every evaluated point: {Path(result.directory) / 'falsification.parquet'}")
    if note := _controller_note(spec, simulator_options):
        print(note)
    return 0


def replay(directory: str | Path, run_id: int, *, speed: float | None = None):
    """The 3-D replay of run ``run_id`` of the campaign in ``directory``
    (:func:`oos_drake.campaign.replay.replay_case`: re-simulated, written as
    ``DIR/replay/case_N.html``), its summary printed; what ``oos campaign replay DIR --case N``
    runs and ``oos run`` calls for the campaign's worst run.

    Returns
    -------
    ReplayResult

    Raises
    ------
    ValueError
        Not a campaign directory, an unknown run, a simulator without a 3-D model or a bad
        ``speed`` (nothing written).
    """
    from oos_drake.campaign.replay import replay_case

    result = replay_case(directory, run_id, speed=speed)
    span = f"t = {result.start:g} .. {result.end:g} s"
    print(
        f"run {result.run_id}: {span}, {result.frames} frames at {result.frame_rate:g} Hz, "
        f"played at {result.speed:g}x ({result.bytes / 1e6:.1f} MB)"
    )
    if result.status != "ok":
        print(f"note: run {result.run_id} {result.status}: {result.error}")
    print(f"replay: {result.path}")
    return result


def _replay(args: argparse.Namespace) -> int:
    replay(args.directory, args.case, speed=args.speed)
    return 0


def register(subparsers) -> None:
    """Add ``oos campaign ...`` to the ``oos`` parser."""
    campaign = subparsers.add_parser(
        "campaign",
        help="Monte Carlo campaigns (run, resume, rerun, report, replay)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = campaign.add_subparsers(dest="campaign_command", metavar="ACTION", required=True)

    run = commands.add_parser("run", help="validate a spec and run the campaign")
    run.add_argument(
        "spec",
        help="campaign spec (TOML file), or the name of a shipped spec: demo, demo_mu, paper, "
        "paper_mc, paper_phases, heavy_target",
    )
    add_out_argument(
        run,
        required=False,
        help="campaign directory (default: out/campaigns/<name>); must not exist",
    )
    run.add_argument(
        "--worst-cases",
        default=None,
        metavar="PARQUET",
        help="mu-guided: use this worst_cases.parquet (e.g. from oos analyze), not the spec's",
    )
    _add_controller_option(run)
    run.add_argument(
        "--simulator-option",
        action="append",
        metavar="KEY=VALUE",
        help="override a simulator option of the spec (repeatable; VALUE may be JSON)",
    )
    _add_executor_options(run)
    run.set_defaults(func=_run)

    resume = commands.add_parser("resume", help="finish an interrupted campaign")
    resume.add_argument("directory", help="campaign directory")
    _add_executor_options(resume)
    resume.set_defaults(func=_resume)

    rerun = commands.add_parser("rerun", help="recompute one run and compare with its record")
    rerun.add_argument("directory", help="campaign directory")
    rerun.add_argument("--case", type=int, required=True, help="run id")
    rerun.set_defaults(func=_rerun)

    report = commands.add_parser("report", help="figures and summary tables")
    report.add_argument("directory", help="campaign directory")
    report.add_argument("--worst", type=int, default=5, help="worst runs to plot (default 5)")
    report.add_argument(
        "--confirm",
        default=None,
        metavar="DIR",
        help="folder of oos confirm's confirmation.parquet: the stability boundary of the "
        "nonlinear twin against mu (default: <campaign>/../confirm when it exists)",
    )
    report.set_defaults(func=_report)

    falsify = commands.add_parser(
        "falsify",
        help="search the dispersion box for the worst nonlinear run (not an estimation)",
    )
    falsify.add_argument("spec", help="campaign spec (TOML file) or the name of a shipped spec")
    add_out_argument(
        falsify,
        required=False,
        help="folder of the search (default: out/falsify/<name>); the folder of the same search "
        "is resumed",
    )
    falsify.add_argument(
        "--budget", type=int, default=200, help="largest number of runs (default 200)"
    )
    falsify.add_argument(
        "--worst-cases",
        default=None,
        metavar="PARQUET",
        help="the analysis' worst_cases.parquet: its worst cases start the search",
    )
    falsify.add_argument(
        "--confirm",
        default=None,
        metavar="DIR",
        help="oos confirm folder: compare the worst found with the certified worst-case gains "
        "and the twin run of the worst perturbation and input (performance_confirmation.parquet); "
        "its worst cases (perturbation and sinusoidal input) start the search",
    )
    falsify.add_argument(
        "--window",
        default=None,
        metavar="START,END",
        help="simulated window of every run [s] instead of the spec's (a sinusoidal input needs "
        "time to reach its steady state)",
    )
    falsify.add_argument(
        "--search",
        choices=("evolution", "local"),
        default="evolution",
        help="evolution: differential evolution over the box (default); local: gradient ascent "
        "with a line search from the best starting point (climbs past the worst cases)",
    )
    _add_controller_option(falsify)
    falsify.add_argument(
        "--simulator-option",
        action="append",
        metavar="KEY=VALUE",
        help="override a simulator option of the spec (repeatable; VALUE may be JSON)",
    )
    _add_executor_options(falsify)
    falsify.set_defaults(func=_falsify)

    replay = commands.add_parser(
        "replay", help="self-contained HTML 3D replay of one run (Drake mission, Meshcat)"
    )
    replay.add_argument("directory", help="campaign directory")
    replay.add_argument("--case", type=int, required=True, help="run id")
    replay.add_argument(
        "--speed",
        type=float,
        default=None,
        help="playback speed: simulated seconds per second of animation (default: the "
        "smallest of 1, 2, 5, 10, 25, 50, 100 x that plays the run within a minute)",
    )
    replay.set_defaults(func=_replay)


def main(argv: list[str] | None = None) -> int:
    """``python -m oos_drake.app.campaign campaign ...``: the campaign commands alone.

    Same behaviour as ``oos campaign ...`` (a user-fixable error prints one line and returns 2),
    without importing the other subpackages' commands.
    """
    parser = argparse.ArgumentParser(prog="oos")
    register(parser.add_subparsers(dest="command", metavar="COMMAND", required=True))
    return run_command(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
