"""`oos campaign run --worst-cases` points a mu-guided spec at another analysis output."""

from pathlib import Path

import pandas as pd
import pytest

from oos_drake.campaign.runner import prepare_campaign

CAMPAIGNS = Path(__file__).resolve().parents[2] / "campaigns"


def test_override_replaces_the_regions(tmp_path):
    original = pd.read_parquet(CAMPAIGNS / "demo_worst_cases.parquet")
    shifted = original.copy()
    shifted = shifted.iloc[:1]  # one region only: the plan must follow the override
    override = tmp_path / "wc.parquet"
    shifted.to_parquet(override)
    _, spec, plan = prepare_campaign(CAMPAIGNS / "demo_mu.toml", tmp_path / "out", override)
    assert len(spec.regions) == 1
    assert (tmp_path / "out" / "worst_cases.parquet").read_bytes() == override.read_bytes()


def test_override_on_plain_monte_carlo_is_refused(tmp_path):
    with pytest.raises(ValueError, match="not mu-guided"):
        prepare_campaign(CAMPAIGNS / "demo.toml", tmp_path / "out", tmp_path / "x.parquet")
    assert not (tmp_path / "out").exists()
