"""The main job, ``oos run``: model -> controller -> analysis -> confirmation of the worst cases
on the Drake twin -> classical and disk margins (continuous and sampled loops, at
:data:`MARGIN_CONFIGURATIONS` mission configurations) -> mu-guided campaign -> report.

Each stage writes one folder under ``--out``. A stage is skipped when its folder holds a stamp
(``stage.json``) whose key matches the current inputs: the key hashes the part of the scenario
file the stage reads (``--scenario``: the physical data and mission for the model and the Drake
check, plus its ``[control]`` section for the controller and everything after it; parsed content,
so editing a comment recomputes nothing), the source code of the packages the stage depends on,
the stage options and the keys of the stages it reads. A stage is computed in a temporary
folder that replaces the old one only when it succeeds, so an interrupted ``oos run`` never
leaves a half-written stage behind; the campaign stage instead resumes (no finished run is lost
or repeated). The campaign spec must be written for the same scenario (its ``scenario`` key).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

from oos_drake import __version__
from oos_drake.app.args import add_parallel_arguments, add_scenario_argument
from oos_drake.files import atomic_folder
from oos_drake.resources import package_path

PACKAGE_ROOT = package_path("oos_drake")
DEFAULT_CAMPAIGN = package_path("oos_drake.campaign", "specs", "paper.toml")
STAMP = "stage.json"
#: Mission configurations of the margins stage (``oos margins --configurations``): equally
#: spaced, a coarser grid than the analysis' (about 1 s per configuration on 2 cores).
MARGIN_CONFIGURATIONS = 12


def _digest(*parts: str | bytes) -> str:
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part if isinstance(part, bytes) else part.encode())
        digest.update(b"\0")
    return digest.hexdigest()


def source_key(*packages: str) -> str:
    """Hash of the package's top-level modules (``blas.py``, ``processes.py``, ... which every
    package may use) and the sources of ``packages`` (``oos_drake.<name>``)."""
    files = sorted(PACKAGE_ROOT.glob("*.py"))
    for package in packages:
        files += sorted((PACKAGE_ROOT / package).rglob("*.py"))
    return _digest(__version__, *(f.read_bytes() for f in files))


def scenario_keys(path: str | Path) -> dict[str, str]:
    """Hashes of a scenario file's parsed content: ``"physical"`` (everything but ``[control]``)
    and ``"control"`` (the ``[control]`` section)."""
    import tomllib

    try:
        document = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"scenario {path}: invalid TOML ({error})") from None
    control = document.pop("control", None)
    return {
        "physical": _digest(json.dumps(document, sort_keys=True)),
        "control": _digest(json.dumps(control, sort_keys=True)),
    }


def stage_keys(
    scenario: str | Path, campaign_spec: str | Path, quick: bool, grid_only: bool = False
) -> dict[str, str]:
    """The key of every stage of ``oos run`` (see the module docstring)."""
    parts = scenario_keys(scenario)
    quick_options = ["--configurations", "40"] if quick else []
    analysis_options = ["--grid-only"] if grid_only else []
    keys = {"model": _digest(parts["physical"], source_key("lfr", "titop", "scenario"))}
    keys["validate"] = _digest(keys["model"], source_key("multibody"))
    keys["controller"] = _digest(
        keys["model"], parts["control"], source_key("control", "robust"), *quick_options
    )
    keys["analysis"] = _digest(
        keys["controller"], source_key("analysis", "robust"), *quick_options, *analysis_options
    )
    keys["confirm"] = _digest(keys["analysis"], keys["validate"])  # analysis: analysis/, robust/
    keys["margins"] = _digest(keys["analysis"], str(MARGIN_CONFIGURATIONS))
    keys["campaign"] = _digest(
        keys["analysis"],
        keys["validate"],
        source_key("campaign"),
        Path(campaign_spec).read_bytes(),
    )
    # the report reads every stage; the campaign's own results are added by report_key
    keys["report"] = _digest(*keys.values(), source_key("report"))
    return keys


def report_key(key: str, campaign: Path | None) -> str:
    """The report stage's key: ``key`` (its inputs' keys) and the campaign report's tables
    (the campaign resumes instead of being stamped, so its results are hashed; None: no
    campaign)."""
    tables = sorted((campaign / "report").glob("*.parquet")) if campaign is not None else []
    return _digest(key, *(f"{f.name}:{f.read_bytes().hex()}" for f in tables))


def _stage_done(folder: Path, key: str) -> bool:
    stamp = folder / STAMP
    return stamp.is_file() and json.loads(stamp.read_text()).get("key") == key


def run_stage(
    name: str,
    folder: Path,
    key: str,
    work: Callable[[Path], None],
    timings: dict[str, float | None] | None = None,
) -> bool:
    """Run ``work(tmp_folder)`` unless ``folder`` is stamped with ``key``; True if it ran.

    ``timings[name]`` receives the stage's wall time in seconds, or None when it was skipped.
    """
    timings = {} if timings is None else timings
    if _stage_done(folder, key):
        print(f"[oos run] {name}: up to date in {folder} (skipped)")
        timings[name] = None
        return False
    print(f"[oos run] {name} -> {folder}")
    start = time.perf_counter()

    def stamped(tmp: Path) -> None:
        work(tmp)
        stamp = {"key": key, "stage": name, "seconds": time.perf_counter() - start}
        (tmp / STAMP).write_text(json.dumps(stamp) + "\n")

    atomic_folder(folder, stamped)
    timings[name] = time.perf_counter() - start
    print(f"[oos run] {name}: done in {timings[name]:.1f} s")
    return True


def _check_campaign_scenario(campaign_spec: Path, scenario: Path) -> None:
    """The campaign's dispersions are written for one scenario: it must be ``scenario``."""
    import tomllib

    from oos_drake.campaign.spec import spec_scenario

    document = tomllib.loads(campaign_spec.read_text(encoding="utf-8"))
    options = document.get("simulator", {}).get("options", {})
    spec_file = spec_scenario(document.get("scenario", options.get("scenario")), campaign_spec)
    if spec_file.read_bytes() != scenario.read_bytes():
        raise ValueError(
            f"campaign spec {campaign_spec} is written for scenario {spec_file}, not {scenario}: "
            f"pass --campaign with a spec whose `scenario` key names it"
        )


def default_campaign(scenario: Path) -> Path:
    """The shipped campaign spec of a scenario file: ``specs/<file stem>.toml`` when the
    package ships one (``heavy_target``, ``flexible_satellite``), else ``paper.toml``."""
    own = DEFAULT_CAMPAIGN.parent / f"{Path(scenario).stem}.toml"
    return own if own.is_file() else DEFAULT_CAMPAIGN


def run_pipeline(args: argparse.Namespace) -> int:
    """Run every stage of the main job into ``args.out``; returns the exit status."""
    from oos_drake.app.campaign import campaign_report, pipeline_campaign_options
    from oos_drake.app.synth import pipeline_controller_options
    from oos_drake.app.tree import joint_space_scenario
    from oos_drake.scenario.data import scenario_path
    from oos_drake.scenario.tree_scenario import unsupported_stages

    source = scenario = scenario_path(args.scenario)
    campaign_spec = Path(args.campaign or default_campaign(scenario))
    if not campaign_spec.is_file():
        raise ValueError(f"campaign spec {campaign_spec}: file not found")
    controller = Path(args.out) / "controller" / "controller.json"
    campaign_options = pipeline_campaign_options(  # checked before anything is written
        campaign_spec,
        Path(args.out) / "analysis" / "worst_cases.parquet",
        controller,
        args.workers,
        getattr(args, "scheduler", None),
    )
    controller_options = pipeline_controller_options(  # checked before anything is written
        quick=args.quick, workers=args.workers, scheduler=getattr(args, "scheduler", None)
    )
    # a tree's tip-pose waypoints solved by inverse kinematics: the stages read the joint-space copy
    scenario = joint_space_scenario(scenario, Path(args.out) / "scenario")
    skipped = unsupported_stages(scenario)  # a schema-2 tree: said, never silent
    if "campaign" not in skipped:  # (the spec names the file given; its simulator solves tips)
        _check_campaign_scenario(campaign_spec, source)
    # (a namespace made by a caller before --grid-only existed proves the whole axis)
    grid_only = ["--grid-only"] if getattr(args, "grid_only", False) else []
    keys = stage_keys(scenario, campaign_spec, args.quick, grid_only=bool(grid_only))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float | None] = {}
    start = time.perf_counter()
    print(f"[oos run] scenario: {scenario}")
    for name, why in skipped.items():
        print(f"[oos run] {name}: SKIPPED for this scenario: {why}")
        if name in ("controller", "analysis", "confirm", "margins"):
            shutil.rmtree(out / name, ignore_errors=True)  # no stale results in the report

    run_stage(
        "model",
        out / "model",
        keys["model"],
        _model_stage(scenario, figures="model figures" not in skipped),
        timings,
    )
    run_stage(
        "validate", out / "validate", keys["validate"], lambda d: _validate(d, scenario), timings
    )
    stages = {  # in order: each stage reads the folders of those before it
        "controller": _controller_stage(controller_options, scenario),
        "analysis": _analysis_stage(args, scenario, controller, grid_only=bool(grid_only)),
        "confirm": _confirm_stage(args, scenario, controller, out / "analysis"),
        "margins": _margins_stage(scenario, controller, out / "analysis"),
    }
    for name, work in stages.items():  # stage functions (typed results), no command lines
        if name not in skipped:
            run_stage(name, out / name, keys[name], work, timings)

    campaign = out / f"campaign-{keys['campaign'][:10]}"
    campaign_start = time.perf_counter()
    if "campaign" in skipped:
        campaign = None
    else:
        _campaign_stage(campaign_options)(campaign)
        campaign_report(campaign)
        _replay_worst_run(campaign)
        timings["campaign + report"] = time.perf_counter() - campaign_start

    def write_timings():
        total = time.perf_counter() - start
        (out / "timings.json").write_text(
            json.dumps(
                {
                    "scenario": str(scenario),
                    "stages_s": timings,
                    "total_s": total,
                    "skipped": skipped,
                },
                indent=1,
            )
            + "\n"
        )
        return total

    write_timings()  # the report shows the wall times of the stages before it
    run_stage(
        "report",
        out / "report",
        report_key(keys["report"], campaign),
        lambda d: _report(d, out, campaign),
        timings,
    )
    report = _publish_report(out)
    total = write_timings()

    print("\n[oos run] wall time per stage:")
    for name, seconds in timings.items():
        shown = "skipped (up to date)" if seconds is None else f"{seconds:8.1f} s"
        print(f"  {name:28s} {shown}")
    for name, why in skipped.items():
        print(f"  {name:28s} SKIPPED: {why}")
    print(f"  {'total':28s} {total:8.1f} s")
    print("\n[oos run] finished. Where to look:")
    for label, path in (
        ("model figures", out / "model"),
        ("Drake vs TITOP validation", out / "validate" / "validate.txt"),
        ("controller", controller),
        ("robust analysis", out / "analysis"),
        ("worst cases on the Drake twin", out / "confirm" / "confirmation.parquet"),
        ("gain/phase/delay/disk margins", out / "margins" / "margins.png"),
        ("campaign results", campaign / "runs.parquet" if campaign else None),
        ("campaign report", campaign / "report" if campaign else None),
        ("report (one page)", out / "report.html"),
    ):
        print(f"  {label:28s} {path if path is not None and path.exists() else 'not run'}")
    print()
    _print_headlines(out, campaign, report)
    return 0


def _model_stage(scenario: Path, *, figures: bool):
    """The model stage of ``oos run``: ``work(folder)`` building the mission LFR of
    ``scenario`` (:func:`oos_drake.app.scenario.model`, what ``oos model info --out FOLDER``
    and, with ``figures``, ``oos model figures --out FOLDER`` run), its block table and figures
    written in ``folder``; returns its :class:`~oos_drake.app.scenario.ModelResult`.
    Occurrence counts that differ from the paper's stop the pipeline (exit status 1, as the
    command's)."""

    def work(folder: Path):
        from oos_drake.app.scenario import FigureOptions, model
        from oos_drake.scenario.data import load_scenario

        result = model(
            load_scenario(str(scenario)), folder, figures=FigureOptions() if figures else None
        )
        if result.status:
            raise SystemExit(result.status)
        return result

    return work


def _controller_stage(options, scenario: Path):
    """The controller stage of ``oos run``: ``work(folder)`` designing the controller of
    ``scenario`` with ``options`` (:func:`oos_drake.app.synth.pipeline_controller_options`;
    :func:`oos_drake.app.synth.controller`, what ``oos synth --workers N [--scheduler S]
    [--configurations 40]`` runs) and writing it in ``folder``; returns its
    :class:`~oos_drake.app.synth.ControllerResult`. An infeasible tuning stops the pipeline
    (exit status 1, as the command's)."""

    def work(folder: Path):
        from oos_drake.app.synth import controller
        from oos_drake.scenario.data import load_scenario

        result = controller(load_scenario(str(scenario)), options, folder)
        if result.status != "ok":
            raise SystemExit(1)
        return result

    return work


def _analysis_stage(args, scenario: Path, controller: Path, *, grid_only: bool):
    """The analysis stage of ``oos run``: ``work(folder)`` computing the
    :class:`~oos_drake.analysis.results.AnalysisResult` of the stage's controller
    (:func:`oos_drake.app.analyze.analyze`, what ``oos analyze --controller CONTROLLER
    --workers N [--configurations 40] [--grid-only]`` runs) and writing it in ``folder``."""

    def work(folder: Path):
        from oos_drake.app.analyze import analysis_controller, analyze, pipeline_analysis_options
        from oos_drake.scenario.data import load_scenario

        loaded = load_scenario(str(scenario))
        options = pipeline_analysis_options(
            loaded,
            quick=args.quick,
            workers=args.workers,
            scheduler=getattr(args, "scheduler", None),
            grid_only=grid_only,
        )
        return analyze(loaded, analysis_controller(controller, loaded), options, folder)

    return work


def _margins_stage(scenario: Path, controller: Path, analysis: Path):
    """The margins stage of ``oos run``: ``work(folder)`` computing the
    :class:`~oos_drake.analysis.margins.MarginsResult` of the stage's controller at
    :data:`MARGIN_CONFIGURATIONS` mission configurations with the rays of ``analysis``
    (:func:`oos_drake.app.analyze.margins`, what ``oos margins --analysis ANALYSIS
    --controller CONTROLLER --configurations 12 --quiet`` runs) and writing it in ``folder``."""

    def work(folder: Path):
        from oos_drake.app.analyze import margins, margins_controller, pipeline_margins_options
        from oos_drake.scenario.data import load_scenario

        loaded = load_scenario(str(scenario))
        options = pipeline_margins_options(analysis, MARGIN_CONFIGURATIONS)
        return margins(loaded, margins_controller(controller, loaded), options, folder)

    return work


def _confirm_stage(args, scenario: Path, controller: Path, analysis: Path):
    """The confirmation stage of ``oos run``: ``work(folder)`` computing the
    :class:`~oos_drake.analysis.confirm.ConfirmationResult` of the ``analysis`` folder with the
    stage's controller on ``--workers`` processes (:func:`oos_drake.app.analyze.confirm`,
    what ``oos confirm --analysis ANALYSIS --controller CONTROLLER --workers N [--scheduler S]``
    runs) and writing it in ``folder``."""

    def work(folder: Path):
        from oos_drake.app.analyze import confirm, confirm_inputs, pipeline_confirm_options

        options = pipeline_confirm_options(args.workers, getattr(args, "scheduler", None))
        inputs = confirm_inputs(analysis, controller, str(scenario))
        return confirm(*inputs, options, folder)

    return work


def _campaign_stage(options):
    """The campaign stage of ``oos run``: ``work(folder)`` running the campaign of ``options``
    (:func:`oos_drake.app.campaign.pipeline_campaign_options`) into ``folder``, or resuming
    the one there (:func:`oos_drake.app.campaign.campaign`, what ``oos campaign run SPEC
    --out FOLDER --worst-cases W --simulator-option controller=C --workers N [--scheduler S]``
    or ``oos campaign resume FOLDER --workers N [--scheduler S]`` runs); returns its
    :class:`~oos_drake.campaign.runner.CampaignSummary`."""

    def work(folder: Path):
        from oos_drake.app.campaign import campaign

        return campaign(options, folder)

    return work


def _replay_worst_run(campaign: Path) -> Path | None:
    """The 3-D replay of the campaign's worst run (``replay/case_N.html``, for the report:
    :func:`oos_drake.app.campaign.replay`), unless it is there already; its path. A campaign
    whose simulator has no 3-D model gets none (one line says why; None)."""
    import pandas as pd

    from oos_drake.app.campaign import replay
    from oos_drake.campaign.replay import replay_path

    worst = campaign / "report" / "worst_runs.parquet"
    table = pd.read_parquet(worst) if worst.is_file() else pd.DataFrame()
    if table.empty or "run_id" not in table:
        return None
    run_id = int(table["run_id"].iloc[0])
    path = replay_path(campaign, run_id)
    if path.is_file():
        return path
    try:
        return replay(campaign, run_id).path
    except (ValueError, FileNotFoundError, KeyError) as error:  # as `oos campaign replay`: status 2
        message = error.args[0] if error.args else error
        print(f"oos campaign: error: {message}", file=sys.stderr)
        return None


def _report(folder: Path, out: Path, campaign: Path) -> None:
    """The report stage: ``folder/report.html`` over the results in ``out`` (published as
    ``out/report.html``: its links are relative to ``out``)."""
    from oos_drake.report import REPORT_FILE, write_report

    write_report(out, campaign, folder / REPORT_FILE, report_dir=out)


def _publish_report(out: Path) -> Path:
    """Copy the report stage's page to ``out/report.html`` (atomically); its path."""
    from oos_drake.files import atomic_write_bytes
    from oos_drake.report import REPORT_FILE

    page = (out / "report" / REPORT_FILE).read_bytes()
    return atomic_write_bytes(out / REPORT_FILE, lambda stream: stream.write(page))


def _print_headlines(out: Path, campaign: Path, report: Path) -> None:
    """The headline numbers of the run and the report's path."""
    from oos_drake.app.report import print_headlines
    from oos_drake.report import headline_numbers, load_run

    try:
        numbers = headline_numbers(load_run(out, campaign))
    except Exception as error:  # noqa: BLE001 - the results are written; only the summary fails
        print(f"[oos run] headline numbers not available ({type(error).__name__}: {error})")
        numbers = []
    print_headlines(numbers, report)


def _validate(folder: Path, scenario: Path) -> None:
    """The validation stage of ``oos run``: the Drake twin (the scenario's own:
    :func:`oos_drake.multibody.scenario_sdf.scenario_sdf_directory`) against the TITOP LFR
    (:func:`oos_drake.app.multibody.validate` with
    :func:`~oos_drake.app.multibody.pipeline_validate_options`, what ``oos validate --scenario
    FILE`` runs), its report saved as ``folder/validate.txt``; a failed configuration stops
    the pipeline (exit status 1, as the command's)."""
    from oos_drake.app.multibody import pipeline_validate_options, validate

    result = validate(scenario, pipeline_validate_options(), folder)
    if result.status:
        raise SystemExit(result.status)


def register(subparsers) -> None:
    """Add ``oos run`` (the main job of ``make run``)."""
    parser = subparsers.add_parser(
        "run",
        help="the main job: model, Drake validation, controller, analysis, confirmation, campaign, "
        "report",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument(
        "--campaign",
        default=None,
        help="campaign spec (default: the shipped spec named as the scenario file, e.g. "
        "flexible_satellite.toml, else paper.toml)",
    )
    add_parallel_arguments(
        parser,
        help="worker processes of the synthesis, the analysis, the confirmation and the campaign",
    )
    parser.add_argument(
        "--quick", action="store_true", help="40 configurations instead of the paper's grids"
    )
    parser.add_argument(
        "--grid-only",
        action="store_true",
        help="analysis upper bounds on the analyzed frequencies only (oos analyze --grid-only); "
        "default: each analyzed configuration's mu peak proved on the whole frequency axis",
    )
    add_scenario_argument(parser)
    parser.set_defaults(func=run_pipeline)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(prog="oos")
    register(parser.add_subparsers(dest="command"))
    sys.exit(run_pipeline(parser.parse_args(["run", *sys.argv[1:]])))
