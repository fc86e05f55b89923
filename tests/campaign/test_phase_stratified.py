"""The phase-stratified sampler: the whole mission covered, runs per phase in proportion to its
duration, and the report's stratified estimate with the phase weights."""

from __future__ import annotations

import textwrap

import pandas as pd
import pytest

from oos_drake.campaign.estimators import campaign_estimate
from oos_drake.campaign.runner import load_campaign, run_campaign

SPEC = textwrap.dedent(
    """
    name = "phases"
    n_runs = 30
    random_seed = 9
    sampler = "phase-stratified"
    metrics = ["ape"]

    [simulator]
    name = "tests.campaign.synthetic_sim:make_simulator"

    [dispersions]
    a = { distribution = "uniform", low = 0.0, high = 1.0 }
    b = { distribution = "uniform", low = 0.0, high = 1.0 }

    [requirements]
    ape = { max = 0.004 }
    """
)


def test_phase_stratified_campaign(write_spec, tmp_path):
    run_campaign(write_spec(SPEC), tmp_path / "c", workers=1, progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    # synthetic mission: 100 s, capture at 10 s -> phases of 10 % and 90 % of the duration
    counts = runs["window"].value_counts().to_dict()
    assert counts == {"phase:start-capture": 3, "phase:capture-end": 27}
    spans = runs.groupby("window")[["window start [s]", "window end [s]"]].first()
    assert spans.loc["phase:start-capture"].tolist() == [0.0, 10.0]
    assert spans.loc["phase:capture-end"].tolist() == [10.0, 100.0]
    spec, _ = load_campaign(tmp_path / "c")
    violated = ~runs["pass_ape"]
    interval = campaign_estimate(spec, runs, violated.to_numpy())
    by_phase = violated.groupby(runs["window"]).mean()
    expected = 0.1 * by_phase["phase:start-capture"] + 0.9 * by_phase["phase:capture-end"]
    assert 0 < violated.sum() < len(runs)
    assert interval.estimate == pytest.approx(expected, rel=1e-12)
    assert interval.method == "stratified pooled Clopper-Pearson"
    assert interval.low <= expected <= interval.high
    assert expected <= interval.upper < 1


def test_phase_stratified_refuses_a_window(write_spec):
    from oos_drake.campaign.spec import load_spec

    text = SPEC + '\n[window]\nkind = "event"\nevent = "capture"\nbefore = 1.0\nafter = 5.0\n'
    with pytest.raises(ValueError, match=r"\[window\]: the phase-stratified sampler"):
        load_spec(write_spec(text))
