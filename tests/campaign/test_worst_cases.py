"""worst_cases.parquet schema, validation, and a mu-guided campaign end to end."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from oos_drake.campaign.attitude_sim import FlexibleAttitudeSimulator
from oos_drake.campaign.runner import run_campaign
from oos_drake.campaign.spec import load_spec
from oos_drake.campaign.worst_cases import WorstCaseRegion, read_worst_cases, write_worst_cases

from .spec_texts import BASE_SPEC

PARAMETERS = FlexibleAttitudeSimulator().parameters()
REGIONS = (
    WorstCaseRegion(
        0,
        "capture",
        100.0,
        0.21,
        1.4,
        1.35,
        "omega_capture,J_hub",
        {"omega_capture": 0.0095, "J_hub": 410.0},
    ),
    WorstCaseRegion(4, "late", 120.0, 0.5, 0.7, 0.6, "k_dock", {"k_dock": 150.0}),
)


def test_round_trip_and_schema(tmp_path):
    path = write_worst_cases(REGIONS, PARAMETERS, tmp_path / "wc.parquet")
    table = pd.read_parquet(path)
    assert list(table.columns[:7]) == [
        "region",
        "configuration",
        "time [s]",
        "frequency [Hz]",
        "mu upper [-]",
        "mu lower [-]",
        "subset",
    ]
    assert {"wc:J_hub [kg m^2]", "wc:k_dock [N m/rad]", "wc:omega_capture [rad/s]"} <= set(table)
    assert np.isnan(table.loc[1, "wc:J_hub [kg m^2]"])
    assert read_worst_cases(path, PARAMETERS) == REGIONS


@pytest.mark.parametrize(
    "mutate, message",
    [
        (
            lambda t: t.rename(columns={"wc:J_hub [kg m^2]": "wc:J_hubb [kg m^2]"}),
            "unknown block 'J_hubb'",
        ),
        (
            lambda t: t.rename(columns={"wc:J_hub [kg m^2]": "wc:J_hub [g cm^2]"}),
            "has unit 'g cm\\^2'",
        ),
        (
            lambda t: t.assign(**{"mu lower [-]": [2.0, 0.6]}),
            "mu_lower 2.0 must be <= mu_upper 1.4",
        ),
        (lambda t: t.drop(columns="subset"), "missing column\\(s\\) subset"),
        (
            lambda t: t.assign(**{"wc:J_hub [kg m^2]": [5000.0, np.nan]}),
            "outside the range of J_hub",
        ),
        (lambda t: t.assign(region=[1, 1]), "duplicated region ids"),
        (lambda t: t.assign(region=[-1, 1]), "region ids must be >= 0"),
    ],
)
def test_bad_worst_cases_rejected(tmp_path, mutate, message):
    path = write_worst_cases(REGIONS, PARAMETERS, tmp_path / "wc.parquet")
    mutate(pd.read_parquet(path)).to_parquet(path)
    with pytest.raises(ValueError, match=message):
        read_worst_cases(path, PARAMETERS)


def _mu_spec(write_spec, tmp_path, n_runs=30, window=None):
    write_worst_cases(REGIONS, PARAMETERS, tmp_path / "worst_cases.parquet")
    text = BASE_SPEC.replace('sampler = "monte-carlo"\n', "").replace(
        "n_runs = 12", f"n_runs = {n_runs}"
    )
    text = text.replace(
        "[simulator]",
        '[sampler]\nkind = "mu-guided"\nworst_cases = '
        '"worst_cases.parquet"\ndefensive_fraction = 0.25\nspread = 0.05\n\n[simulator]',
    )
    if window:
        text = text.replace('kind = "event"\nevent = "capture"', window)
    return write_spec(text)


def test_mu_guided_campaign_records_weights_regions_and_copies_worst_cases(write_spec, tmp_path):
    spec_path = _mu_spec(write_spec, tmp_path)
    spec = load_spec(spec_path)
    out = tmp_path / "mu"
    run_campaign(spec_path, out, progress=False)
    runs = pd.read_parquet(out / "runs.parquet")
    assert (out / "worst_cases.parquet").is_file()
    assert set(runs["region"]) <= {-1, 0, 4}
    assert (runs["weight"] > 0).all() and (runs["weight"] <= 1 / 0.25 + 1e-12).all()
    # runs drawn from region 0 sit near its worst case (spread 5% of the dispersion width)
    near = runs[runs["region"] == 0]
    assert len(near) > 0
    width = 0.02  # omega_capture support [-0.01, 0.01] (normal truncated to the range)
    assert (np.abs(near["omega_capture [rad/s]"] - 0.0095) < 5 * 0.05 * width).all()
    assert spec.regions == REGIONS

    from oos_drake.campaign.report import write_report

    report = write_report(out)
    regions = report.tables["regions"]
    assert regions["runs"].sum() == 30
    assert regions.set_index("region").loc[0, "runs"] == (runs["region"] == 0).sum()
    assert "runs per region" in report.text
    # no worst-case gains in this file: no performance comparison figure (mu is not set beside
    # a performance metric any more)
    assert {p.name for p in report.figures}.isdisjoint(
        {"regions_prediction.png", "regions_performance.png"}
    )
    observed = regions.set_index("region").loc[0, "worst ratio (nonlinear) [-]"]
    near_ratio = np.maximum(near["ape [rad]"] / 0.0079, near["peak_torque [N m]"] / 2.0)
    assert observed == near_ratio.max()


def test_critical_window_centres_runs_on_region_times(write_spec, tmp_path):
    spec_path = _mu_spec(write_spec, tmp_path, n_runs=20, window='kind = "critical"')
    spec = load_spec(spec_path)
    from oos_drake.campaign.samplers import make_plan

    plan = make_plan(spec)
    starts = {0: 95.0, 4: 115.0}
    for _, row in plan.iterrows():
        region = int(row["window"].removeprefix("region:"))
        assert row["window start [s]"] == starts[region]
        assert row["window end [s]"] == starts[region] + 45.0
        if row["region"] != -1:
            assert region == row["region"]


def test_worst_case_gains_round_trip_and_are_checked(tmp_path):
    """Optional ``wcgain:<metric> lower|upper [-]`` columns: written, read back per region
    (NaN pairs left out), refused when lower exceeds upper or a bound is missing."""
    from dataclasses import replace

    regions = (
        replace(REGIONS[0], gains={"ape": (0.8, 0.9), "peak_torque": (0.1, 0.2)}),
        replace(REGIONS[1], gains={"ape": (0.4, 0.45)}),
    )
    path = write_worst_cases(regions, PARAMETERS, tmp_path / "wc.parquet")
    table = pd.read_parquet(path)
    assert {"wcgain:ape lower [-]", "wcgain:peak_torque upper [-]"} <= set(table.columns)
    back = read_worst_cases(path, PARAMETERS)
    assert [dict(r.gains) for r in back] == [dict(r.gains) for r in regions]
    bad = table.copy()
    bad.loc[0, "wcgain:ape lower [-]"] = 1.5
    bad.to_parquet(tmp_path / "bad.parquet")
    with pytest.raises(ValueError, match="wcgain:ape lower"):
        read_worst_cases(tmp_path / "bad.parquet", PARAMETERS)
    table.drop(columns="wcgain:ape upper [-]").to_parquet(tmp_path / "half.parquet")
    with pytest.raises(ValueError, match="needs both"):
        read_worst_cases(tmp_path / "half.parquet", PARAMETERS)


def test_a_file_with_the_old_column_names_reads_the_same(tmp_path):
    """Files written before the ``name [unit]`` convention (``mu_upper``, ``mu_lower``) still
    read, to the same regions; a file mixing both names is refused in one line."""
    path = write_worst_cases(REGIONS, PARAMETERS, tmp_path / "wc.parquet")
    table = pd.read_parquet(path)
    old = table.rename(columns={"mu upper [-]": "mu_upper", "mu lower [-]": "mu_lower"})
    old.to_parquet(tmp_path / "old.parquet")
    assert read_worst_cases(tmp_path / "old.parquet", PARAMETERS) == REGIONS
    table.assign(mu_upper=table["mu upper [-]"]).to_parquet(tmp_path / "mixed.parquet")
    with pytest.raises(ValueError, match="both old and new column names"):
        read_worst_cases(tmp_path / "mixed.parquet", PARAMETERS)
