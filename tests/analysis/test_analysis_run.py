"""A small, fast configuration of the whole analysis: files, documented columns, certificates."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from oos_drake.analysis.controller import baseline_controller
from oos_drake.analysis.run import AnalysisOptions, compute_analysis
from oos_drake.analysis.stability import SweepOptions
from oos_drake.analysis.tightening import TightenOptions
from oos_drake.analysis.writers import summary_json, write_analysis
from oos_drake.scenario.data import load_scenario

PAPER = load_scenario("paper")

FAST = AnalysisOptions(
    configurations=3,
    frequency_range_hz=(0.05, 2.0),
    points_per_decade=4,
    sweep=SweepOptions(
        upper_iterations=20,
        n_jobs=1,
        converge_iterations=40,
        continuation_iterations=10,
        lower_restarts=1,
        lower_iterations=20,
    ),
    docking_phases=("7",),
    docking_points=3,
    performance_models=1,
    performance_points=4,
    certify_iterations=60,
    tighten=TightenOptions(rounds=1, peak_levels=1, search_models=1, iterations=(60,)),
    sensitivity_iterations=40,
    open_loop_samples=4,
    sensitivity=True,
    time_check=True,
    time_check_duration=60.0,
    guarantee=False,  # the whole-axis guarantee has its own tests
    progress=False,
)


@pytest.fixture(scope="module")
def analysis_result(paper_scenario):
    """The computed analysis (:class:`AnalysisResult`), nothing written."""
    controller = baseline_controller(paper_scenario)
    return compute_analysis(controller, FAST, scenario=paper_scenario, log=lambda *_: None)


@pytest.fixture(scope="module")
def analysis(tmp_path_factory, analysis_result):
    """The analysis written by :func:`write_analysis`: ``(folder, summary, controller)``."""
    out = tmp_path_factory.mktemp("analysis")
    summary = write_analysis(analysis_result, out, log=lambda *_: None)
    return out, summary, analysis_result.controller


def test_written_files_are_the_result(analysis, analysis_result):
    """The writer adds nothing and loses nothing: every table read back equals the result's
    (exactly, dtypes included), ``summary.json`` is the result's summary plus the files and
    the figures' time, and every listed file exists."""
    out, summary, _ = analysis
    tables = analysis_result.tables()
    assert {p.stem for p in out.glob("*.parquet")} == set(tables)
    assert "worst_cases" in tables
    for name, table in tables.items():
        pd.testing.assert_frame_equal(
            pd.read_parquet(out / f"{name}.parquet"), table, check_exact=True
        )
    saved = json.loads((out / "summary.json").read_text())
    expected = json.loads(summary_json(analysis_result.summary()))
    for key in set(saved) | set(expected):
        if key not in ("files", "timings_s"):
            assert saved[key] == expected[key], key
    assert set(saved["timings_s"]) == set(expected["timings_s"]) | {
        "figures",
        "spike resolution, all studies",
        "total",
    }
    assert saved == json.loads(summary_json(summary))  # what write_analysis returned
    for name in saved["files"].values():
        assert (out / name).is_file(), name
    assert "time_signals" not in saved["files"]  # written, not listed (as before the split)


def test_files_and_summary(analysis):
    out, summary, _ = analysis
    for name in (
        "mu_mission.parquet",
        "stability_peaks.parquet",
        "worst_perturbations.parquet",
        "performance.parquet",
        "docking_7.parquet",
        "sensitivity.parquet",
        "time_check.parquet",
        "worst_cases.parquet",
        "summary.json",
        "mu_mission.png",
        "performance.png",
        "mu_docking.png",
        "sensitivity.png",
        "time_check.png",
        "open_loop_effects.parquet",
        "open_loop_effects.png",
    ):
        assert (out / name).is_file(), name
    saved = json.loads((out / "summary.json").read_text())
    assert saved["controller"]["label"] == "baseline"
    assert saved["mission"]["configurations"] == 3


def test_tables_have_documented_columns(analysis):
    out, _, _ = analysis
    from oos_drake.analysis.performance import PERFORMANCE_COLUMNS
    from oos_drake.analysis.sensitivity import SENSITIVITY_COLUMNS
    from oos_drake.analysis.time_check import TIME_COLUMNS
    from oos_drake.robust.tables import SWEEP_COLUMNS

    assert list(pd.read_parquet(out / "mu_mission.parquet").columns) == SWEEP_COLUMNS
    assert list(pd.read_parquet(out / "performance.parquet").columns) == PERFORMANCE_COLUMNS
    assert list(pd.read_parquet(out / "sensitivity.parquet").columns) == SENSITIVITY_COLUMNS
    assert list(pd.read_parquet(out / "time_check.parquet").columns) == TIME_COLUMNS
    peaks = pd.read_parquet(out / "stability_peaks.parquet")
    for col in (
        "subset",
        "time [s]",
        "frequency [Hz]",
        "mu upper [-]",
        "mu lower [-]",
        "gap [%]",
        "margin [-]",
        "stiffness [N/m or N m/rad]",
        "mu upper at critical [-]",
    ):
        assert col in peaks.columns, col
    sweep = pd.read_parquet(out / "mu_mission.parquet")
    assert set(sweep["subset"]) == {
        "total",
        "real",
        "modal",
        "mechanical",
        "additive",
        "multiplicative",
    }
    assert np.all(sweep["mu lower [-]"] <= sweep["mu upper [-]"] * (1 + 1e-9))


def test_every_table_names_the_unit_of_its_quantities(analysis):
    """Every float column of every Parquet table of the analysis is ``name [unit]`` (``[-]``
    when dimensionless): labels, indices, counts and flags are not floats."""
    out, _, _ = analysis
    unit = re.compile(r"^[^\[\]]+ \[[^\[\]]+\]$")
    tables = sorted(out.glob("*.parquet"))
    assert {p.name for p in tables} >= {
        "mu_mission.parquet",
        "docking_7.parquet",
        "stability_peaks.parquet",
        "worst_cases.parquet",
        "performance.parquet",
    }
    for path in tables:
        table = pd.read_parquet(path)
        bare = [c for c in table.columns if table[c].dtype.kind == "f" and not unit.match(c)]
        assert not bare, (path.name, bare)


def test_worst_cases_file_reads_back_with_the_campaign_schema(analysis):
    out, _, _ = analysis
    from oos_drake.analysis.models import mission_closed_loop
    from oos_drake.analysis.worst_cases import block_parameters
    from oos_drake.campaign.worst_cases import read_worst_cases

    _, _, controller = analysis
    params = block_parameters(mission_closed_loop(controller, [0.0], PAPER).system)
    regions = read_worst_cases(out / "worst_cases.parquet", params)
    assert {r.subset.split(",")[0] for r in regions}
    table = pd.read_parquet(out / "worst_cases.parquet")
    assert "wc:w1_SA3 [rad/s]" in table.columns and "wc:Delta_add [-]" in table.columns
    # every region carries the worst-case gains of the channels bounding the campaign's APE and
    # wheel command at its own configuration: an upper bound cannot be below the nominal gain
    # (delta = 0 is in every set), and the performance table holds that configuration
    performance = pd.read_parquet(out / "performance.parquet")
    for region in regions:
        assert set(region.gains) == {"ape", "peak_torque"}
        for metric, channel in (("ape", "e_p"), ("peak_torque", "e_u")):
            low, high = region.gains[metric]
            rows = performance[
                (performance["time [s]"] == region.time) & (performance["channel"] == channel)
            ]
            assert len(rows) > 0
            assert 0 < low <= high * (1 + 1e-9)
            assert high >= rows["gain nominal [-]"].max() * (1 - 1e-6)


def test_peak_bounds_meet(analysis):
    """Every certificate is consistent and honest.

    lower <= upper at the critical frequency <= largest upper bound; the reported gap is the gap
    of the peak, ``(max upper - best lower) / max upper``; where no spike is left it is within
    the target; LTI-only subsets (additive, multiplicative) meet within 5 %.
    """
    out, summary, _ = analysis
    peaks = pd.read_parquet(out / "stability_peaks.parquet")
    target = 100 * FAST.tighten.target_gap
    for _, row in peaks.iterrows():
        assert row["mu lower [-]"] > 0 or row["subset"] == "mechanical"
        assert row["mu lower [-]"] <= row["mu upper at critical [-]"] * (1 + 1e-9)
        assert row["mu upper at critical [-]"] <= row["mu upper [-]"] * (1 + 1e-9)
        up, lo = row["mu upper [-]"], row["mu lower [-]"]
        np.testing.assert_allclose(row["gap [%]"], 100 * (up - lo) / up, rtol=1e-9, atol=1e-9)
        if row["spikes left"] == 0 and lo > 0:
            assert row["gap [%]"] <= target * (1 + 1e-6) + 1e-9, (row["study"], row["subset"])
        if row["subset"] in ("additive", "multiplicative"):
            assert row["gap [%]"] < 5.0, (row["study"], row["subset"], row["gap [%]"])
    sweep = pd.read_parquet(out / "mu_mission.parquet")
    for _, row in peaks[peaks["study"] == "mission"].iterrows():
        grid_max = sweep.loc[sweep["subset"] == row["subset"], "mu upper [-]"].max()
        assert grid_max <= row["mu upper [-]"] * (1 + 1e-9)  # the peak covers every analyzed point


def test_additive_peak_is_certified_exactly(analysis):
    """A single full block: mu = sigma_max, so the bounds must meet (within 1 %)."""
    out, _, _ = analysis
    peaks = pd.read_parquet(out / "stability_peaks.parquet")
    add = peaks[peaks["subset"] == "additive"].iloc[0]
    assert add["gap [%]"] < 1.0


def test_time_check_nominal_is_stable(analysis):
    out, _, _ = analysis
    t = pd.read_parquet(out / "time_check.parquet")
    assert bool(t.loc[t["case"] == "nominal", "stable"].iloc[0])
    assert np.all(t["torque requirement [N m]"] == 2.0)


def test_worst_perturbation_destabilizes_at_the_reported_frequency(analysis):
    """Independent check with usubs: the certified total-set perturbation (size = margin)
    puts a closed-loop pole on j omega_crit; 90 % of it leaves the loop stable."""
    from peak_oracle import certify_peak

    from oos_drake.analysis.models import mission_closed_loop, mission_times
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.lfr import usubs

    out, _, controller = analysis
    peaks = pd.read_parquet(out / "stability_peaks.parquet")
    total = peaks[(peaks["study"] == "mission") & (peaks["subset"] == "total")].iloc[0]
    times = mission_times(FAST.configurations, PAPER)
    arr = mission_closed_loop(controller, times, PAPER).system
    members = uncertainty_subsets(arr.uncertainty)["total"]
    cert = certify_peak(
        arr,
        "total",
        members,
        int(total["model"]),
        float(total["frequency [Hz]"]),
        points=5,
        upper_iterations=30,
    )
    assert cert.mu_lower > 0 and cert.mu_lower <= cert.mu_upper * (1 + 1e-9)
    one = arr.model(int(total["model"]))
    closed = usubs(one, cert.worst_case_normalized, normalized=True)
    poles = np.linalg.eigvals(np.asarray(closed.A))
    w = 2 * np.pi * cert.frequency
    assert np.min(np.abs(poles - 1j * w)) < 1e-3 * max(w, 1.0)
    smaller = {k: 0.9 * v for k, v in cert.worst_case_normalized.items()}
    inside = usubs(one, smaller, normalized=True)
    assert np.max(np.linalg.eigvals(np.asarray(inside.A)).real) < 0


@pytest.mark.parametrize(
    "option, culprit",
    [
        (["--docking", "9"], "'9'"),
        (["--configurations", "0"], "configurations"),
        (["--f-min", "1", "--f-max", "0.5"], "frequency_range_hz"),
    ],
)
def test_bad_analyze_options_exit_2_and_write_nothing(tmp_path, capsys, option, culprit):
    """Checked before any work (a bad docking phase used to fail after the mission sweep,
    leaving mu_mission.parquet behind)."""
    from oos_drake.app.main import main

    out = tmp_path / "analysis"
    assert main(["analyze", "--out", str(out), *option]) == 2
    message = capsys.readouterr().err.strip().splitlines()
    assert len(message) == 1 and culprit in message[0], message
    assert list(tmp_path.iterdir()) == []


def test_analyze_refuses_an_out_folder_that_is_not_an_analysis(tmp_path, capsys):
    from oos_drake.app.main import main

    (tmp_path / "precious.txt").write_text("keep me")
    assert main(["analyze", "--out", str(tmp_path), "--configurations", "2"]) == 2
    assert "holds something other than an analysis" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["precious.txt"]
