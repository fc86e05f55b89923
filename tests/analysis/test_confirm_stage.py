"""The confirmation stage as a typed result:
:func:`~oos_drake.analysis.confirm.compute_confirmation` returns a
:class:`~oos_drake.analysis.confirm.ConfirmationResult` and writes nothing,
:func:`~oos_drake.analysis.writers.write_confirmation` writes exactly its tables and one figure
per peak with nonlinear runs, and ``oos run`` calls it with the options ``oos confirm`` builds
from the command line the pipeline used to run. The Drake runs are replaced by recorders where
they are not the point; one real peak (linear only, no twin run) goes through the whole stage."""

import os

import numpy as np
import pandas as pd
import pytest

import oos_drake.analysis.confirm as confirm_module
import oos_drake.analysis.performance_twin as performance_twin
from oos_drake.analysis.confirm import (
    PEAK_SUMMARY_COLUMNS,
    ConfirmationOptions,
    ConfirmOptions,
    Peak,
    compute_confirmation,
)
from oos_drake.analysis.controller import scenario_controller
from oos_drake.analysis.performance_twin import (
    PERFORMANCE_CONFIRMATION_COLUMNS,
    PERFORMANCE_SUMMARY_COLUMNS,
    GainCase,
)
from oos_drake.analysis.writers import write_confirmation
from oos_drake.app.analyze import confirm_options, pipeline_confirm_options
from oos_drake.app.main import build_parser

PEAKS = [
    Peak("mission", "real", 255.0, np.nan, 2.0, 0.3, 0.31, {"m_RH2": 1.0}),
    Peak("mission", "modal", 1418.0, np.nan, 3.0, 0.2, 0.21, {"w1_SA1": -1.0}),
    Peak("docking-7", "total", np.nan, 1e4, 4.0, 0.1, 0.11, {"k_SM1": 1.0}),
]
CASES = [GainCase("e_p", "total", 300.0, 0.5, 0.1, 0.2, 0.21)]


def _fake_peak(peak, controller, scenario, options):
    """A confirmation row named after the peak; histories (both sides) for the mission's, a
    crossing the analysis missed (``ABOVE``) for the modal one."""
    row = {column: float(len(peak.subset)) for column in PEAK_SUMMARY_COLUMNS[2:-1]}
    row |= {"study": peak.study, "subset": peak.subset, "status": f"fake {peak.subset}"}
    row["notes"] = "a; mu >= 0.4, ABOVE the upper bound" if peak.subset == "modal" else ""
    if peak.study != "mission":
        return row, pd.DataFrame()
    t = np.linspace(0.0, 45.0, 451)
    sides = []
    for side, alpha, growth in (("stable", 0.99, -0.05), ("unstable", 1.01, 0.05)):
        phi = 1e-4 * np.exp(growth * t) * np.sin(2 * np.pi * 0.3 * t)
        sides.append(
            pd.DataFrame({"time [s]": t} | {f"phi_{a} [rad]": phi for a in "xyz"}).assign(
                side=side, **{"alpha [-]": alpha}
            )
        )
    history = pd.concat(sides, ignore_index=True).assign(study=peak.study, subset=peak.subset)
    return row, history


def _fake_gain(case, controller, scenario, subsets, options=None):
    row = {column: 0.5 for column in PERFORMANCE_CONFIRMATION_COLUMNS}
    return row | {"channel": case.channel, "subset": case.subset, "status": "fake"}


@pytest.fixture(scope="module")
def computed(paper_scenario, tmp_path_factory):
    """``(result, folder)``: the stage on :data:`PEAKS` and :data:`CASES` with the twin
    replaced (one worker: the tasks run in this process), the empty ``folder`` as working
    directory."""
    patch = pytest.MonkeyPatch()
    patch.setattr(confirm_module, "confirm_peak", _fake_peak)
    patch.setattr(performance_twin, "confirm_gain_case", _fake_gain)
    folder = tmp_path_factory.mktemp("cwd")
    controller = scenario_controller(None, paper_scenario)
    here = os.getcwd()
    os.chdir(folder)
    try:
        options = ConfirmationOptions(progress=False)
        result = compute_confirmation(PEAKS, CASES, controller, paper_scenario, options)
    finally:
        os.chdir(here)
        patch.undo()
    return result, folder


def test_compute_confirmation_writes_nothing(computed):
    result, folder = computed
    assert list(folder.iterdir()) == []
    assert list(result.confirmation["subset"]) == [p.subset for p in PEAKS]  # peaks' order
    assert list(result.performance["channel"]) == ["e_p"]
    assert set(result.histories["subset"]) == {"real", "modal"}  # the docking one has none


def test_written_files_are_the_result(tmp_path, computed):
    """Every table read back equals ``result.tables()``; one figure per peak with histories;
    ``summary.json`` read back equals ``result.summary()``; nothing else."""
    import json

    result, _ = computed
    summary = write_confirmation(result, tmp_path)
    assert json.loads((tmp_path / "summary.json").read_text()) == summary == result.summary()
    assert set(result.tables()) == {
        "confirmation",
        "confirmation_histories",
        "performance_confirmation",
    }
    for stem, table in result.tables().items():
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / f"{stem}.parquet"), table)
    figures = {"confirmation_mission_real.png", "confirmation_mission_modal.png"}
    assert {p.name for p in tmp_path.iterdir()} == {
        *(f"{s}.parquet" for s in result.tables()),
        *figures,
        "summary.json",
    }
    assert all((tmp_path / f).stat().st_size > 10_000 for f in figures)


def test_summary_is_the_tables(computed):
    """The summary's peaks and gains are the tables' rows (its columns), the warnings the
    ``ABOVE`` notes, the scenario and controller the stage's."""
    result, _ = computed
    summary = result.summary()
    expected = result.confirmation[list(PEAK_SUMMARY_COLUMNS)].to_dict(orient="records")
    assert summary["peaks"] == expected
    assert [p["status"] for p in summary["peaks"]] == [f"fake {p.subset}" for p in PEAKS]
    performance = result.performance[list(PERFORMANCE_SUMMARY_COLUMNS)]
    assert summary["performance"] == performance.to_dict(orient="records")
    assert summary["warnings"] == ["mission modal: mu >= 0.4, ABOVE the upper bound"]
    assert summary["scenario"]["source"] == str(result.scenario.source)
    assert summary["controller"]["label"] == "baseline"


def test_an_empty_analysis_gives_empty_tables(tmp_path, paper_scenario):
    controller = scenario_controller(None, paper_scenario)
    result = compute_confirmation([], [], controller, paper_scenario, ConfirmationOptions())
    assert result.confirmation.empty and result.histories.empty
    assert list(result.performance.columns) == PERFORMANCE_CONFIRMATION_COLUMNS
    assert result.summary()["peaks"] == [] and result.summary()["performance"] == []
    write_confirmation(result, tmp_path)
    files = {f"{s}.parquet" for s in result.tables()} | {"summary.json"}
    assert {p.name for p in tmp_path.iterdir()} == files


def test_a_real_peak_beyond_nyquist_goes_through_the_stage(tmp_path, paper_scenario):
    """A peak with complex blocks critical beyond the flight software's Nyquist frequency
    (5 Hz at the paper's 10 Hz): no discrete realization, so no twin run; its row is the
    linear continuous prediction and the status says so, the histories are empty."""
    controller = scenario_controller(None, paper_scenario)
    omega = 2 * np.pi * 6.0
    peak = Peak("mission", "additive", 255.0, np.nan, omega, 0.1, 0.1, {"Delta_add": np.eye(3)})
    options = ConfirmationOptions(ConfirmOptions(alpha_limit=0.5), progress=False)
    result = compute_confirmation([peak], [], controller, paper_scenario, options)
    (row,) = result.confirmation.to_dict(orient="records")
    assert row["status"].startswith("linear only")
    assert row["critical frequency [Hz]"] == pytest.approx(6.0)
    assert np.isnan(row["alpha linear sampled [-]"]) and row["nonlinear runs"] == 0
    assert result.histories.empty
    write_confirmation(result, tmp_path)
    pd.testing.assert_frame_equal(
        pd.read_parquet(tmp_path / "confirmation.parquet"), result.confirmation
    )
    # summary.json: the table's summary columns (NaN where the table has NaN), read back
    import json

    (peak_summary,) = json.loads((tmp_path / "summary.json").read_text())["peaks"]
    expected = result.confirmation[list(PEAK_SUMMARY_COLUMNS)]
    pd.testing.assert_frame_equal(pd.DataFrame([peak_summary]), expected, check_dtype=False)
    assert np.isnan(peak_summary["alpha linear sampled [-]"])


@pytest.mark.parametrize("scheduler", [None, "dask"])
def test_pipeline_options_are_the_command_lines(tmp_path, scheduler):
    """The former argv of the stage, ``oos confirm --analysis A --controller C --workers N
    [--scheduler S] --out D --scenario F``, parsed by ``oos confirm``'s own parser, gives the
    options the pipeline now passes."""
    extra = ["--scheduler", scheduler] if scheduler else []
    argv = ["confirm", "--analysis", str(tmp_path / "analysis"), "--controller", "c.json"]
    argv += ["--workers", "3", *extra, "--out", "d", "--scenario", "paper"]
    expected = confirm_options(build_parser().parse_args(argv))
    given = pipeline_confirm_options(3, scheduler)
    assert given == expected
    assert given.twin == ConfirmOptions() and given.progress  # defaults: the bar is shown
    assert (given.workers, given.scheduler) == (3, scheduler)


def test_the_pipeline_calls_the_stage_with_its_folders(tmp_path, monkeypatch):
    """``oos run``'s confirm stage reads the analysis folder and the controller of the run, on
    the run's scenario, and writes in the stage's folder (the stage function recorded)."""
    import oos_drake.app.analyze as analyze
    from oos_drake.app.pipeline import _confirm_stage

    calls = []
    monkeypatch.setattr(
        analyze, "confirm_inputs", lambda *args: calls.append(("inputs", args)) or (1, 2, 3, 4)
    )
    monkeypatch.setattr(analyze, "confirm", lambda *args: calls.append(("confirm", args)))
    args = build_parser().parse_args(["run", "--workers", "3"])
    scenario, controller = tmp_path / "s.toml", tmp_path / "controller.json"
    _confirm_stage(args, scenario, controller, tmp_path / "analysis")(tmp_path / "confirm")
    assert calls == [
        ("inputs", (tmp_path / "analysis", controller, str(scenario))),
        ("confirm", (1, 2, 3, 4, pipeline_confirm_options(3), tmp_path / "confirm")),
    ]


def test_bad_options_are_refused(tmp_path, capsys):
    """One line naming the option, exit status 2, nothing written."""
    from oos_drake.app.main import main

    with pytest.raises(ValueError, match="--workers 0: need at least 1 worker"):
        ConfirmationOptions(workers=0)
    with pytest.raises(ValueError, match="alpha_limit"):
        ConfirmationOptions(ConfirmOptions(alpha_limit=-1.0))
    for bad, named in (
        (["--workers", "0"], "--workers 0"),
        (["--alpha-limit", "0"], "alpha_limit"),
    ):
        out = tmp_path / "o"
        argv = ["confirm", "--analysis", str(tmp_path / "missing"), "--out", str(out), *bad]
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and named in err[0], err
        assert not out.exists()
