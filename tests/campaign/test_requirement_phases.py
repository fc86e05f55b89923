"""Requirements per mission phase, and the phase and time of every violation in the report."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from oos_drake.campaign.report import violations_table
from oos_drake.campaign.runner import run_campaign
from oos_drake.campaign.spec import load_spec, parse_spec, spec_to_toml

from .spec_texts import BASE_SPEC

BOUND = 0.0002  # [rad]: tight, so that both phases would violate it


def _spec(phases: str) -> str:
    text = BASE_SPEC.replace('sampler = "monte-carlo"', 'sampler = "phase-stratified"')
    text = text.replace(
        '[window]\nkind = "event"\nevent = "capture"\nbefore = 5.0\nafter = 40.0\n', ""
    )
    text = text.replace('omega_capture = { distribution = "normal", mean = 0.0, std = 0.004 }', "")
    text = text.replace("ape = { max = 0.0079 }", f"ape = {{ max = {BOUND}, phases = {phases} }}")
    return text.replace("n_runs = 12", "n_runs = 16").replace(
        'signals = ["theta_hub", "torque_command"]', 'signals = ["theta_hub"]'
    )


def test_requirement_applies_only_in_its_phases(write_spec, tmp_path):
    path = write_spec(_spec('["capture-end"]'))
    spec = load_spec(path)
    assert parse_spec(spec_to_toml(spec), source=path) == spec  # the resolved copy keeps phases
    ((start, end),) = spec.requirements[0].spans
    assert start == spec.info.events["capture"] and end == spec.info.duration
    run_campaign(
        write_spec(_spec('["capture-end"]'), name="run"), tmp_path / "c", workers=1, progress=False
    )
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    before = runs["window"] == "phase:start-capture"
    assert before.any() and (~before).any()
    # not checked before the capture, even where the metric exceeds the bound
    assert (runs.loc[before, "ape [rad]"] > BOUND).any()
    assert runs.loc[before, "pass_ape"].all()
    after = runs[~before]
    np.testing.assert_array_equal(after["pass_ape"], after["ape [rad]"] <= BOUND)
    violations = violations_table(tmp_path / "c", spec, runs)
    ape = violations[violations["requirement"].str.startswith("ape")]
    assert len(ape) == int((~after["pass_ape"]).sum()) > 0
    assert (ape["phase"] == "capture-end").all()
    for _, row in ape.iterrows():  # independent: first sample of |theta| above the bound
        series = pd.read_parquet(tmp_path / "c" / "timeseries" / f"run_{row['run_id']:06d}.parquet")
        t, theta = series["time [s]"].to_numpy(), series["theta_hub [rad]"].to_numpy()
        expected = t[np.flatnonzero((np.abs(theta) > BOUND) & (t >= start))[0]]
        assert row["first violation time [s]"] == expected
        inside = (t >= start) & (t <= end)
        assert row["peak time (logged) [s]"] == t[inside][np.argmax(np.abs(theta[inside]))]


def test_unknown_phase_is_refused(write_spec):
    with pytest.raises(ValueError, match=r"requirements\.ape: unknown phase 'docking'"):
        load_spec(write_spec(_spec('["docking"]')))
