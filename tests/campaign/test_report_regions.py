"""Report, like with like, on synthetic campaign tables (no simulation): per region the
analysis' worst-case gains beside the nonlinear worst metric, mu beside the confirmed stability
boundary, weighted empirical CDFs."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pandas as pd
import pytest

from oos_drake.app.campaign import main as cli_main
from oos_drake.campaign import store
from oos_drake.campaign.executors import RunResult
from oos_drake.campaign.report import (
    CONFIRMATION_COLUMNS,
    weighted_ecdf,
    write_report,
)
from oos_drake.campaign.runner import record_result
from oos_drake.campaign.spec import SPEC_DIRECTORY

from .spec_texts import prepare_campaign

#: Worst-case gains written for the synthetic regions: metric -> (lower, upper) per region.
GAINS = {"ape": [(0.8, 0.9), (0.3, 0.35), (1.2, 1.5)], "peak_torque": [(0.2, 0.25)] * 3}


def _synthetic_campaign(root, *, name="campaign"):
    """A mu-guided campaign of the cheap simulator whose runs are written directly from known
    metrics (ape grows with the run id, region 2's runs fail), with gains in its worst cases."""
    table = pd.read_parquet(SPEC_DIRECTORY / "demo_worst_cases.parquet")
    for metric, values in GAINS.items():
        table[f"wcgain:{metric} lower [-]"] = [v[0] for v in values]
        table[f"wcgain:{metric} upper [-]"] = [v[1] for v in values]
    worst_cases = root / "worst_cases_in.parquet"
    table.to_parquet(worst_cases)
    text = (SPEC_DIRECTORY / "demo_mu.toml").read_text().replace("n_runs = 200", "n_runs = 40")
    spec_path = root / "mu.toml"
    spec_path.write_text(text)
    directory, spec, plan = prepare_campaign(spec_path, root / name, worst_cases)
    ape = 0.0079 * (0.2 + plan["run_id"].to_numpy() / 40) * np.where(plan["region"] == 2, 3, 1)
    for (_, row), value in zip(plan.iterrows(), ape, strict=True):
        metrics = {"ape": float(value), "peak_torque": 0.5, "rms_attitude": value / 3}
        result = RunResult(int(row["run_id"]), "ok", "", metrics, None, 0.1, "test:1", 1, 0.1)
        record_result(directory, spec, row, result)
    store.consolidate(directory)
    return directory, plan, ape


def _confirmation(path):
    table = pd.DataFrame(
        {
            "study": ["mission", "mission", "docking-7"],
            "subset": ["total", "real", "total"],
            "time [s]": [1418.0, 1418.0, 255.0],
            "critical frequency [Hz]": [0.82, 0.81, 0.6],
            "mu lower [-]": [0.377, 0.370, 0.5],
            "mu upper [-]": [0.387, 0.375, 0.52],
            "alpha linear continuous [-]": [2.6, 2.68, 1.95],
            "alpha linear sampled [-]": [2.5, 2.6, 1.9],
            "alpha nonlinear [-]": [2.45, 2.62, np.nan],
            "alpha physical max [-]": [np.inf, np.inf, 1.4],
            "oscillation frequency [Hz]": [0.83, 0.81, np.nan],
            "status": ["confirmed", "confirmed", "not physical"],
        }
    )
    path.mkdir(parents=True, exist_ok=True)
    table.to_parquet(path / "confirmation.parquet")
    return table


def _not_blank(path):
    image = matplotlib.image.imread(path)
    assert image.shape[0] > 200 and image.shape[1] > 400
    assert image[..., :3].std() > 0.05


def test_regions_compare_worst_case_gain_with_the_nonlinear_worst_metric(tmp_path, monkeypatch):
    """Per region: the gains written by the analysis and the largest metric / requirement of
    the region's runs; the distribution figure draws weighted ECDFs (importance weights)."""
    import matplotlib.axes

    calls = {"step": 0, "hist": 0}
    for method in calls:
        original = getattr(matplotlib.axes.Axes, method)

        def counting(self, *args, _original=original, _name=method, **kwargs):
            calls[_name] += 1
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(matplotlib.axes.Axes, method, counting)
    directory, plan, ape = _synthetic_campaign(tmp_path)
    assert not np.all(plan["weight"] == 1.0)
    report = write_report(directory, worst=0)
    assert calls["step"] == 2 * 3 and calls["hist"] == 0  # 3 metrics: weighted + as drawn
    regions = report.tables["regions"].set_index("region")
    for region in range(3):
        runs = plan["region"].to_numpy() == region
        assert runs.any()
        # independent: the largest ape / requirement of the region's runs, from the inputs
        expected = ape[runs].max() / 0.0079
        got = regions.loc[region, "worst ape / requirement (nonlinear) [-]"]
        assert got == pytest.approx(expected, rel=1e-12)
        assert regions.loc[region, "worst peak_torque / requirement (nonlinear) [-]"] == 0.25
        for metric, values in GAINS.items():
            assert regions.loc[region, f"wcgain {metric} lower [-]"] == values[region][0]
            assert regions.loc[region, f"wcgain {metric} upper [-]"] == values[region][1]
        assert regions.loc[region, "runs"] == runs.sum()
    names = {p.name for p in report.figures}
    assert "regions_performance.png" in names and "regions_prediction.png" not in names
    assert "stability_confirmation.png" not in names  # no oos confirm table: left out
    assert "no oos confirm table" in report.text
    _not_blank(directory / "report" / "regions_performance.png")
    _not_blank(directory / "report" / "metric_distributions.png")


def test_confirmation_is_read_from_the_run_layout_or_given(tmp_path, capsys):
    directory, _, _ = _synthetic_campaign(tmp_path)
    given = _confirmation(tmp_path / "elsewhere")
    report = write_report(directory, worst=0, confirm=tmp_path / "elsewhere")
    table = report.tables["confirmation"]
    np.testing.assert_allclose(table["alpha certified (1/mu upper) [-]"], 1 / given["mu upper [-]"])
    np.testing.assert_allclose(
        table["alpha destabilizing (1/mu lower) [-]"], 1 / given["mu lower [-]"]
    )
    np.testing.assert_allclose(
        table["nonlinear / linear continuous [-]"],
        given["alpha nonlinear [-]"] / given["alpha linear continuous [-]"],
    )
    assert set(CONFIRMATION_COLUMNS) <= set(table.columns)
    _not_blank(directory / "report" / "stability_confirmation.png")
    # the oos run layout: <out>/confirm beside <out>/campaign
    _confirmation(tmp_path / "confirm")
    report = write_report(directory, worst=0)
    assert "stability_confirmation.png" in {p.name for p in report.figures}
    # a --confirm folder without the table: exit 2, one line
    assert cli_main(["campaign", "report", str(directory), "--confirm", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "confirmation.parquet" in err


def test_performance_confirmation_is_reported_beside_the_campaigns_worst_run(tmp_path):
    """oos confirm's performance table is copied into the campaign report and its largest twin
    ratio printed with the analysis' bounds and the campaign's worst run (from the inputs)."""
    directory, _, ape = _synthetic_campaign(tmp_path)
    _confirmation(tmp_path / "elsewhere")
    given = pd.DataFrame(
        {
            "channel": ["e_p", "e_u"],
            "subset": ["total", "total"],
            "time [s]": [269.2, 0.0],
            "frequency [Hz]": [0.0807, 0.1407],
            "gain lower [-]": [1.179, 0.655],
            "gain upper [-]": [1.199, 0.662],
            "gain linear sampled [-]": [1.2803, 0.7681],
            "gain twin [-]": [1.2809, 0.7],
            "status": ["twin violated (1.28)", "twin met (0.7)"],
        }
    )
    given.to_parquet(tmp_path / "elsewhere" / "performance_confirmation.parquet")
    report = write_report(directory, worst=0, confirm=tmp_path / "elsewhere")
    pd.testing.assert_frame_equal(report.tables["performance_confirmation"], given)
    assert (directory / "report" / "performance_confirmation.parquet").is_file()
    assert "worst performance ratio on the twin: 1.281" in report.text
    assert "APE requirement violated: e_p total" in report.text
    assert "[1.179, 1.199]" in report.text
    assert f"the campaign's worst run: {ape.max() / 0.0079:.4g}" in report.text
    # without the file: no table, no sentence
    (tmp_path / "elsewhere" / "performance_confirmation.parquet").unlink()
    report = write_report(directory, worst=0, confirm=tmp_path / "elsewhere")
    assert "performance_confirmation" not in report.tables
    assert not (directory / "report" / "performance_confirmation.parquet").exists()
    assert "worst performance ratio" not in report.text


def test_weighted_ecdf_equals_the_ecdf_of_repeated_samples():
    values = np.array([3.0, 1.0, 2.0, 4.0, np.nan])
    weights = np.array([1.0, 2.0, 1.0, 0.0, 5.0])  # the sample [1, 1, 2, 3]
    x, cdf = weighted_ecdf(values, weights)
    sample = np.array([1.0, 1.0, 2.0, 3.0])
    for value, probability in zip(x, cdf, strict=True):
        assert probability == pytest.approx(np.mean(sample <= value), rel=1e-12)
