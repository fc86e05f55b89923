"""The main job's stage mechanics: skipped when up to date, atomic on failure, timed."""

import json
import subprocess
import sys

import pandas as pd
import pytest

from oos_drake.app.pipeline import STAMP, run_stage, source_key


def _writer(text, calls):
    def work(folder):
        calls.append(folder)
        (folder / "result.txt").write_text(text)

    return work


def test_stage_runs_once_per_key_and_records_its_time(tmp_path):
    calls, timings = [], {}
    folder = tmp_path / "stage"
    assert run_stage("demo", folder, "key-1", _writer("a", calls), timings)
    assert (folder / "result.txt").read_text() == "a"
    assert json.loads((folder / STAMP).read_text())["key"] == "key-1"
    assert timings["demo"] >= 0.0

    assert not run_stage("demo", folder, "key-1", _writer("b", calls), timings)
    assert len(calls) == 1 and timings["demo"] is None
    assert (folder / "result.txt").read_text() == "a"

    assert run_stage("demo", folder, "key-2", _writer("c", calls), timings)
    assert (folder / "result.txt").read_text() == "c"


def test_failed_stage_keeps_the_previous_result(tmp_path):
    folder = tmp_path / "stage"
    run_stage("demo", folder, "key-1", _writer("good", []))

    def crash(tmp):
        (tmp / "result.txt").write_text("half")
        raise RuntimeError("killed")

    with pytest.raises(RuntimeError):
        run_stage("demo", folder, "key-2", crash)
    assert (folder / "result.txt").read_text() == "good"
    assert json.loads((folder / STAMP).read_text())["key"] == "key-1"


def test_source_key_depends_on_the_packages():
    assert source_key("lfr") == source_key("lfr")
    assert source_key("lfr") != source_key("lfr", "titop")


def test_missing_campaign_spec_is_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "oos_drake.app.main", "run", "--out", str(out)]
        + ["--campaign", "no.toml"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2
    assert "no.toml" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.slow
def test_oos_run_quick_end_to_end_then_everything_up_to_date(quick_run):
    """``make run ARGS=--quick`` from the command line: every stage, the printed map of results
    and ``timings.json``; a second call recomputes nothing and the campaign resumes with no run
    left to do. (The run is the session's ``quick_run``, whose folder the report's browser
    test reads too.)"""
    out, command, first = quick_run.out, quick_run.command, quick_run.result
    assert first.returncode == 0, first.stderr[-3000:]
    timings = json.loads((out / "timings.json").read_text())
    assert set(timings["stages_s"]) == {
        "model",
        "validate",
        "controller",
        "analysis",
        "confirm",
        "margins",
        "campaign + report",
        "report",
    }
    assert all(v is not None and v > 0 for v in timings["stages_s"].values())
    for stage in ("model", "validate", "controller", "analysis", "confirm", "margins", "report"):
        assert (out / stage / STAMP).is_file(), stage
    confirmation = pd.read_parquet(out / "confirm" / "confirmation.parquet")
    assert set(confirmation["study"]) == set(
        pd.read_parquet(out / "analysis" / "stability_peaks.parquet")["study"]
    )
    controller = json.loads((out / "controller" / "controller.json").read_text())
    assert len(controller["configurations"]["time [s]"]) == 40
    summary = json.loads((out / "analysis" / "summary.json").read_text())
    assert summary["mission"]["configurations"] == 40
    (campaign,) = out.glob("campaign-*")
    runs = pd.read_parquet(campaign / "runs.parquet")
    plan = pd.read_parquet(campaign / "plan.parquet")
    assert sorted(runs["run_id"]) == sorted(plan["run_id"])
    assert (campaign / "report").is_dir()
    for label in (
        "controller",
        "robust analysis",
        "worst cases on the Drake twin",
        "gain/phase/delay/disk margins",
        "campaign results",
    ):
        assert label in first.stdout
    assert f"report: {out / 'report.html'}" in first.stdout

    second = subprocess.run(command, capture_output=True, text=True, timeout=3000)
    assert second.returncode == 0, second.stderr[-3000:]
    again = json.loads((out / "timings.json").read_text())["stages_s"]
    assert [k for k, v in again.items() if v is not None] == ["campaign + report"]
    assert "0 run now" in second.stdout


def _record_models(monkeypatch, models):
    """Replace the model stage's function by a recorder of ``(scenario file, figure options)``
    (into ``models``)."""
    from types import SimpleNamespace

    import oos_drake.app.scenario as app_scenario

    def record(scenario, out, figures=None):
        models.append((scenario.source, figures))
        return SimpleNamespace(status=0)

    monkeypatch.setattr(app_scenario, "model", record)


def _record_analyses(
    monkeypatch, analyses, margins=None, confirms=None, campaigns=None, controllers=None
):
    """Replace the analysis stage's computation by a recorder of ``(controller, options)``,
    the margins and confirmation stages' likewise (into ``margins``, ``confirms``, when
    given), the campaign stage and its report by a recorder of ``(options, folder)`` and
    ``("report", folder)`` (into ``campaigns``), the controller stage by a recorder of
    ``(scenario file, options)`` (into ``controllers``)."""
    from types import SimpleNamespace

    import oos_drake.app.analyze as analyze
    import oos_drake.app.campaign as app_campaign
    import oos_drake.app.synth as synth

    controllers = [] if controllers is None else controllers
    monkeypatch.setattr(
        synth,
        "controller",
        lambda scenario, options, out: (
            controllers.append((scenario.source, options)) or SimpleNamespace(status="ok")
        ),
    )
    margins = [] if margins is None else margins
    confirms = [] if confirms is None else confirms
    campaigns = [] if campaigns is None else campaigns
    monkeypatch.setattr(app_campaign, "campaign", lambda *args: campaigns.append(args))
    monkeypatch.setattr(
        app_campaign, "campaign_report", lambda folder: campaigns.append(("report", folder))
    )
    monkeypatch.setattr(analyze, "confirm_inputs", lambda *args: args)
    monkeypatch.setattr(
        analyze,
        "confirm",
        lambda analysis, controller, scenario, options, out: confirms.append((controller, options)),
    )
    monkeypatch.setattr(analyze, "analysis_controller", lambda path, scenario, loop=None: path)
    monkeypatch.setattr(
        analyze,
        "analyze",
        lambda scenario, controller, options, out: analyses.append((controller, options)),
    )
    monkeypatch.setattr(analyze, "margins_controller", lambda path, scenario, delay_s=None: path)
    monkeypatch.setattr(
        analyze,
        "margins",
        lambda scenario, controller, options, out: margins.append((controller, options)),
    )


def test_oos_run_passes_the_scheduler_to_the_stages_with_parallel_work(tmp_path, monkeypatch):
    """``oos run --scheduler dask --workers 3``: the stages that run on the executors
    (synthesis, analysis, confirmation, campaign) get both, the report runs as without them
    (stages replaced by a recorder)."""
    import oos_drake.app.pipeline as pipeline
    from oos_drake.app.campaign import pipeline_campaign_options
    from oos_drake.app.main import build_parser

    calls, analyses, margins, confirms, campaigns, controllers = [], [], [], [], [], []
    _record_models(monkeypatch, calls)
    monkeypatch.setattr(pipeline, "_validate", lambda folder, scenario: None)
    _record_analyses(monkeypatch, analyses, margins, confirms, campaigns, controllers)
    argv = ["run", "--out", str(tmp_path), "--scheduler", "dask", "--workers", "3"]
    assert pipeline.run_pipeline(build_parser().parse_args(argv)) == 0
    ((controller, options),) = analyses  # the analysis stage: a function call, not argv
    assert controller == tmp_path / "controller" / "controller.json"
    ((broken, margin_options),) = margins  # the margins stage too: no workers, no scheduler
    assert broken == tmp_path / "controller" / "controller.json"
    assert margin_options.analysis == tmp_path / "analysis"
    assert margin_options.configurations == pipeline.MARGIN_CONFIGURATIONS
    assert (options.sweep.scheduler, options.sweep.n_jobs) == ("dask", 3)
    ((confirmed, confirm_options),) = confirms  # the confirmation stage: a function call
    assert confirmed == tmp_path / "controller" / "controller.json"
    assert (confirm_options.scheduler, confirm_options.workers) == ("dask", 3)
    ((_, controller_options),) = controllers  # the controller stage: a function call
    assert (controller_options.scheduler, controller_options.workers) == ("dask", 3)
    from oos_drake.app.scenario import FigureOptions
    from oos_drake.scenario.data import scenario_path

    # the model stage: a function call on the scenario, the figures drawn (no parallel work)
    assert calls == [(scenario_path(None), FigureOptions())]
    key = pipeline.stage_keys(scenario_path(None), pipeline.DEFAULT_CAMPAIGN, False)["campaign"]
    folder = tmp_path / f"campaign-{key[:10]}"
    assert campaigns == [
        (
            pipeline_campaign_options(
                pipeline.DEFAULT_CAMPAIGN,
                tmp_path / "analysis" / "worst_cases.parquet",
                tmp_path / "controller" / "controller.json",
                3,
                "dask",
            ),
            folder,
        ),
        ("report", folder),
    ]


def test_oos_run_proves_the_whole_axis_unless_grid_only(tmp_path, monkeypatch):
    """``oos run`` analyzes with the whole-axis guarantee (``oos analyze``'s default);
    ``oos run --grid-only`` passes ``--grid-only`` to the analysis stage only, and the analysis
    key (and so the stages after it) changes with it (stages replaced by a recorder)."""
    import oos_drake.app.pipeline as pipeline
    from oos_drake.app.main import build_parser

    analyses = []
    _record_analyses(monkeypatch, analyses)
    for i, extra in enumerate(([], ["--grid-only"])):
        _record_models(monkeypatch, [])
        monkeypatch.setattr(pipeline, "_validate", lambda folder, scenario: None)
        argv = ["run", "--out", str(tmp_path / str(i)), *extra]
        assert pipeline.run_pipeline(build_parser().parse_args(argv)) == 0
    assert [options.guarantee for _, options in analyses] == [True, False]
    from oos_drake.scenario.data import scenario_path

    scenario, campaign = scenario_path(None), pipeline.DEFAULT_CAMPAIGN
    keys = pipeline.stage_keys(scenario, campaign, False)
    grid_only = pipeline.stage_keys(scenario, campaign, False, grid_only=True)
    assert keys["controller"] == grid_only["controller"]
    assert keys["analysis"] != grid_only["analysis"] and keys["campaign"] != grid_only["campaign"]
