"""`oos campaign run --worst-cases` points a mu-guided spec at another analysis output."""

import pandas as pd
import pytest

from oos_drake.campaign.spec import SPEC_DIRECTORY

from .spec_texts import prepare_campaign

CAMPAIGNS = SPEC_DIRECTORY


def test_override_replaces_the_regions(tmp_path):
    original = pd.read_parquet(CAMPAIGNS / "demo_worst_cases.parquet")
    shifted = original.copy()
    shifted = shifted.iloc[:1]  # one region only: the plan must follow the override
    override = tmp_path / "wc.parquet"
    shifted.to_parquet(override)
    _, spec, plan = prepare_campaign(CAMPAIGNS / "demo_mu.toml", tmp_path / "out", override)
    assert len(spec.regions) == 1
    assert (tmp_path / "out" / "worst_cases.parquet").read_bytes() == override.read_bytes()


def test_override_on_a_plain_sampler_gives_the_peak_frequency(tmp_path):
    """A sampler not guided by mu (Latin hypercube, plain Monte Carlo) takes only the frequency
    of the analysis' peak (largest mu_upper) from a worst-cases file; a missing file is refused
    before anything is written."""
    with pytest.raises(ValueError, match="x.parquet: file not found"):
        prepare_campaign(CAMPAIGNS / "demo.toml", tmp_path / "out", tmp_path / "x.parquet")
    assert not (tmp_path / "out").exists()
    table = pd.read_parquet(CAMPAIGNS / "demo_worst_cases.parquet")
    table["frequency [Hz]"] = [0.3, 0.7, 0.2][: len(table)]
    table["mu upper [-]"] = [1.0, 2.0, 1.5][: len(table)]
    table["mu lower [-]"] = table["mu upper [-]"]
    override = tmp_path / "wc.parquet"
    table.to_parquet(override)
    _, spec, plan = prepare_campaign(CAMPAIGNS / "demo.toml", tmp_path / "out", override)
    assert spec.sampler.kind == "latin-hypercube"
    assert (plan["region"] == -1).all()
    assert (plan["frequency [Hz]"] == 0.7).all()
    assert (tmp_path / "out" / "worst_cases.parquet").is_file()


def test_simulator_option_override_reaches_the_resolved_spec(tmp_path):
    _, spec, _ = prepare_campaign(
        CAMPAIGNS / "demo.toml", tmp_path / "out", simulator_options={"torque_limit": 1.5}
    )
    assert spec.simulator.option_dict["torque_limit"] == 1.5
    assert spec.simulator.option_dict["control_rate"] == 10.0  # untouched options kept
    assert "torque_limit = 1.5" in (tmp_path / "out" / "spec.toml").read_text()


def test_unknown_simulator_option_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match="no_such_option"):
        prepare_campaign(
            CAMPAIGNS / "demo.toml", tmp_path / "out", simulator_options={"no_such_option": 1}
        )
    assert not (tmp_path / "out").exists()


def test_worst_case_value_at_a_bound_up_to_round_off_is_accepted_and_clipped(tmp_path):
    from oos_drake.campaign.spec import load_spec

    base = pd.read_parquet(CAMPAIGNS / "demo_worst_cases.parquet")
    spec = load_spec(CAMPAIGNS / "demo_mu.toml")
    column = next(c for c in base.columns if c.startswith("wc:"))
    name = column[3:].split(" [")[0]
    parameter = next(p for p in spec.info.parameters if p.name == name)
    for value, accepted in ((parameter.lower * (1 - 1e-13), True), (parameter.lower * 0.9, False)):
        table = base.copy()
        table[column] = value
        path = tmp_path / f"wc_{accepted}.parquet"
        table.to_parquet(path)
        if accepted:
            _, spec2, _ = prepare_campaign(CAMPAIGNS / "demo_mu.toml", tmp_path / "ok", path)
            assert min(r.perturbation[name] for r in spec2.regions) == parameter.lower
        else:
            with pytest.raises(ValueError, match="outside the range"):
                prepare_campaign(CAMPAIGNS / "demo_mu.toml", tmp_path / "bad", path)
