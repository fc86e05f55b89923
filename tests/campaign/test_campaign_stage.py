"""The campaign stage of ``oos run`` as a function call with typed options:
:func:`oos_drake.app.campaign.campaign` runs the campaign of a
:class:`~oos_drake.campaign.runner.CampaignOptions` into its folder, or resumes the one there,
and returns the :class:`~oos_drake.campaign.runner.CampaignSummary`; ``oos run`` builds the
options ``oos campaign run`` builds from the command line the pipeline used to run. The
campaigns here run on the cheap flexible-attitude simulator (runs of a few ms)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from oos_drake.app.campaign import campaign, campaign_options, pipeline_campaign_options
from oos_drake.app.main import build_parser, main
from oos_drake.campaign import store
from oos_drake.campaign.runner import CampaignOptions
from oos_drake.campaign.spec import SPEC_DIRECTORY

from .spec_texts import BASE_SPEC

#: Columns of a run row that depend on the machine, not on the run.
TIMING = ["wall time [s]", "cpu time [s]", "worker"]


def _mu_guided_spec(tmp_path: Path) -> Path:
    """The shipped ``demo_mu`` spec (mu-guided, flexible-attitude) with 12 runs."""
    text = (SPEC_DIRECTORY / "demo_mu.toml").read_text()
    assert text.count("\nn_runs = 200\n") == 1
    path = tmp_path / "demo_mu.toml"
    path.write_text(text.replace("\nn_runs = 200\n", "\nn_runs = 12\n"))
    return path


def _runs(folder: Path) -> pd.DataFrame:
    return pd.read_parquet(folder / "runs.parquet").drop(columns=TIMING)


@pytest.mark.parametrize("scheduler", [None, "dask"])
def test_pipeline_options_are_the_command_lines(tmp_path, monkeypatch, scheduler):
    """The former argv of the stage, ``oos campaign run SPEC --out D --workers N [--scheduler
    S] --worst-cases W --simulator-option controller=ABSOLUTE``, parsed by ``oos campaign
    run``'s own parser, gives the options the pipeline now passes (the controller made
    absolute against the working directory, as the argv was)."""
    monkeypatch.chdir(tmp_path)
    spec, worst = tmp_path / "spec.toml", tmp_path / "analysis" / "worst_cases.parquet"
    controller = Path("out") / "controller" / "controller.json"  # relative, as --out may be
    extra = ["--scheduler", scheduler] if scheduler else []
    argv = ["campaign", "run", str(spec), "--out", "d", "--workers", "3", *extra]
    argv += ["--worst-cases", str(worst)]
    argv += ["--simulator-option", f"controller={(tmp_path / controller).resolve()}"]
    expected = campaign_options(build_parser().parse_args(argv))
    given = pipeline_campaign_options(spec, worst, controller, 3, scheduler)
    assert given == expected
    assert given.simulator_options == {"controller": str(tmp_path / controller)}
    assert (given.workers, given.scheduler, given.progress) == (3, scheduler, True)


def test_the_pipeline_calls_the_stage_with_its_options(tmp_path, monkeypatch):
    """``oos run``'s campaign stage is the function, called with the options and the folder
    (the stage function recorded), not an ``oos`` command line."""
    import oos_drake.app.campaign as app_campaign
    import oos_drake.app.pipeline as pipeline

    calls = []
    monkeypatch.setattr(app_campaign, "campaign", lambda *args: calls.append(args) or "summary")
    assert not hasattr(pipeline, "_oos")  # no command lines left in the pipeline
    options = CampaignOptions(tmp_path / "spec.toml", workers=2)
    assert pipeline._campaign_stage(options)(tmp_path / "c") == "summary"
    assert calls == [(options, tmp_path / "c")]


def test_the_stage_runs_then_resumes_as_the_command_does(tmp_path):
    """A new folder: the stage runs the campaign, the same runs as ``oos campaign run`` with
    the same options (mu-guided, a simulator option overridden; runs.parquet identical but
    for the timing columns, plan and spec byte-identical). A folder holding a campaign: the
    stage resumes it (runs only the missing runs, as ``oos campaign resume``). A folder
    without a spec (a campaign killed before its spec was written): cleared and run."""
    spec = _mu_guided_spec(tmp_path)
    worst = SPEC_DIRECTORY / "demo_worst_cases.parquet"
    command = tmp_path / "command"
    argv = ["campaign", "run", str(spec), "--out", str(command), "--workers", "1", "--quiet"]
    argv += ["--worst-cases", str(worst), "--simulator-option", "torque_limit=2.5"]
    assert main(argv) == 0

    options = CampaignOptions(
        spec, worst, {"torque_limit": 2.5}, workers=1, progress=False
    )  # what campaign_options builds from argv
    assert options == campaign_options(build_parser().parse_args(argv))
    stage = tmp_path / "stage"
    summary = campaign(options, stage)
    assert (summary.n_runs, summary.executed, summary.skipped) == (12, 12, 0)
    pd.testing.assert_frame_equal(_runs(stage), _runs(command), check_exact=True)
    for name in (store.PLAN_FILE, store.SPEC_FILE, store.WORST_CASES_FILE):
        assert (stage / name).read_bytes() == (command / name).read_bytes(), name

    first = _runs(stage)
    for run_id in (3, 7):  # as if killed before these two finished
        store.run_file(stage, run_id).unlink()
    summary = campaign(options, stage)
    assert (summary.n_runs, summary.executed, summary.skipped) == (12, 2, 10)
    pd.testing.assert_frame_equal(_runs(stage), first, check_exact=True)
    summary = campaign(options, stage)
    assert (summary.executed, summary.skipped) == (0, 12)

    killed = tmp_path / "killed"
    killed.mkdir()
    (killed / store.PLAN_FILE).write_bytes(b"half")
    assert campaign(options, killed).executed == 12
    pd.testing.assert_frame_equal(_runs(killed), first, check_exact=True)


def test_bad_options_are_refused(tmp_path, capsys, write_spec):
    """One line naming the option, exit status 2, nothing written (``oos campaign run``
    formerly wrote the campaign folder before its executor refused ``--workers 0``)."""
    with pytest.raises(ValueError, match="--workers 0: need at least 1 worker"):
        CampaignOptions(Path("demo"), workers=0)
    with pytest.raises(ValueError, match="nowhere"):
        CampaignOptions(Path("demo"), scheduler="nowhere")
    spec = write_spec(BASE_SPEC)
    for bad, named in (
        (["--workers", "0"], "--workers 0"),
        (["--simulator-option", "oops"], "--simulator-option 'oops'"),
        (["--worst-cases", str(tmp_path / "none.parquet")], "none.parquet"),
    ):
        out = tmp_path / "o"
        assert main(["campaign", "run", str(spec), "--out", str(out), "--quiet", *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and named in err[0], err
        assert not out.exists()
    with pytest.raises(ValueError, match="--workers 0"):  # oos run: before any stage
        pipeline_campaign_options(spec, tmp_path / "w.parquet", tmp_path / "c.json", 0)


def test_the_worst_runs_replay_is_a_function_call(tmp_path, monkeypatch, capsys):
    """``oos run``'s replay of the campaign's worst run calls
    :func:`oos_drake.app.campaign.replay` (no command line): a simulator without a 3-D model
    gives the one line ``oos campaign replay`` prints (its exit status 2) and no file; a
    replay made prints what the command prints, and one already there is not made again."""
    import oos_drake.app.pipeline as pipeline
    import oos_drake.campaign.replay as replay_module
    from oos_drake.app.campaign import campaign_report
    from oos_drake.campaign.replay import ReplayResult, replay_path

    folder = tmp_path / "c"
    spec = _mu_guided_spec(tmp_path)
    campaign(
        CampaignOptions(spec, SPEC_DIRECTORY / "demo_worst_cases.parquet", progress=False), folder
    )
    campaign_report(folder)
    worst = int(pd.read_parquet(folder / "report" / "worst_runs.parquet")["run_id"].iloc[0])
    capsys.readouterr()
    assert main(["campaign", "replay", str(folder), "--case", str(worst)]) == 2
    command = capsys.readouterr().err
    assert "has no 3D model to replay" in command and command.count("\n") == 1
    assert pipeline._replay_worst_run(folder) is None
    assert capsys.readouterr().err == command
    assert not (folder / "replay").exists()

    made = []

    def fake_replay(directory, run_id, *, speed=None, meshcat=None):
        path = replay_path(directory, run_id)
        path.parent.mkdir(exist_ok=True)
        path.write_text("<html></html>")
        made.append((Path(directory), run_id, speed))
        return ReplayResult(path, run_id, 10.0, 20.0, 5.0, 51, 2.0, "diverged", "boom", 13)

    monkeypatch.setattr(replay_module, "replay_case", fake_replay)
    assert main(["campaign", "replay", str(folder), "--case", str(worst)]) == 0
    printed = capsys.readouterr().out
    assert "note: run" in printed and f"replay: {replay_path(folder, worst)}" in printed
    replay_path(folder, worst).unlink()
    assert pipeline._replay_worst_run(folder) == replay_path(folder, worst)
    assert capsys.readouterr().out == printed
    assert pipeline._replay_worst_run(folder) == replay_path(folder, worst)  # there: not made
    assert made == [(folder, worst, None)] * 2
