"""Uncertainty declared once: the scenario's ranges are the campaign's default dispersions; a spec
only overrides them, and a contradicting override is refused unless it says so."""

from __future__ import annotations

import re
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest

from oos_drake.app.campaign import main
from oos_drake.campaign.distributions import TruncatedNormal, Uniform
from oos_drake.campaign.spec import load_spec, parse_spec, spec_to_toml

from . import synthetic_sim


def _spec(dispersion_line: str = "") -> str:
    return (
        textwrap.dedent(
            """
        name = "declared"
        n_runs = 4
        random_seed = 3
        metrics = ["ape"]

        [simulator]
        name = "tests.campaign.synthetic_sim:make_declared_simulator"

        [dispersions]
        a = { distribution = "uniform", low = 0.0, high = 1.0 }
        """
        )
        + dispersion_line
        + "\n\n[requirements]\nape = { max = 0.01 }\n"
    )


def _declared_range():
    r = synthetic_sim.W1_PERCENT / 100  # from the "scenario" data, not from the simulator
    return synthetic_sim.W1_NOMINAL * (1 - r), synthetic_sim.W1_NOMINAL * (1 + r)


def test_the_scenario_range_is_the_default_dispersion(write_spec):
    spec = load_spec(write_spec(_spec()))
    assert spec.dispersions["w1"] == Uniform(*_declared_range())
    assert set(spec.dispersions) == {"a", "w1"}  # undeclared parameters stay nominal


def test_a_shape_override_keeps_the_scenario_range(write_spec):
    line = 'w1 = { distribution = "normal", mean = 8.0, std = 0.5 }'
    law = load_spec(write_spec(_spec(line))).dispersions["w1"]
    assert law == TruncatedNormal(8.0, 0.5, *_declared_range())


def test_the_same_range_written_out_is_accepted(write_spec):
    low, high = _declared_range()
    line = f'w1 = {{ distribution = "uniform", low = {low:.6f}, high = {high:.6f} }}'
    low_read, high_read = load_spec(write_spec(_spec(line))).dispersions["w1"].support
    np.testing.assert_allclose((low_read, high_read), _declared_range(), rtol=1e-6)


def test_a_wider_range_needs_widen_and_survives_the_resolved_copy(write_spec):
    line = 'w1 = { distribution = "uniform", low = 6.0, high = 10.0 }'
    with pytest.raises(ValueError, match=r"dispersions\.w1: .* wider than the scenario's"):
        load_spec(write_spec(_spec(line)))
    path = write_spec(_spec(line.replace(" }", ", widen = true }")), name="wide")
    spec = load_spec(path)
    assert spec.dispersions["w1"] == Uniform(6.0, 10.0)
    text = spec_to_toml(spec)
    assert tomllib.loads(text)["dispersions"]["w1"]["override"] is True
    assert parse_spec(text, source=path) == spec


def test_an_undeclared_parameter_refuses_override_keys(write_spec):
    line = 'b = { distribution = "uniform", low = 0.0, high = 1.0, override = true }'
    with pytest.raises(ValueError, match=r"dispersions\.b: override only apply"):
        load_spec(write_spec(_spec(line)))


def test_cli_refuses_a_contradicting_spec_and_writes_nothing(write_spec, tmp_path, capsys):
    line = 'w1 = { distribution = "uniform", low = 6.5, high = 9.7 }'
    spec = write_spec(_spec(line))
    out = tmp_path / "campaign"
    assert main(["campaign", "run", str(spec), "--out", str(out), "--quiet"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "dispersions.w1" in error and "contradicts the scenario's uncertainty" in error
    assert not out.exists()
    # saying so makes it a deliberate choice
    spec = write_spec(_spec(line.replace(" }", ", override = true }")), name="ok")
    assert main(["campaign", "run", str(spec), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    assert Path(out, "runs.parquet").is_file()


@pytest.mark.drake
@pytest.mark.parametrize("name", ["paper", "paper_mc", "paper_phases", "heavy_target"])
def test_shipped_specs_disperse_the_scenario_ranges(name):
    """The shipped Drake specs no longer repeat the ranges: the dispersions of the target hub
    and of the arrays' first modes are nominal +- percent of the scenario file."""
    from oos_drake.campaign.spec import SPEC_DIRECTORY
    from oos_drake.scenario.data import scenario_path

    spec_text = (SPEC_DIRECTORY / f"{name}.toml").read_text()
    scenario_name = tomllib.loads(spec_text).get("scenario")
    data = tomllib.loads(Path(scenario_path(scenario_name)).read_text())
    # plain Monte Carlo around the capture: the mu-guided sampler would need the analysis' file
    text = re.sub(r"\[sampler\].*?(?=\[simulator\])", "", spec_text, flags=re.S)
    text = text.replace('kind = "critical"', 'kind = "event"\nevent = "capture"')
    spec = parse_spec(text, source=SPEC_DIRECTORY / f"{name}.toml")
    expected = _expected_ranges(data)
    assert expected  # the scenario declares some uncertainty
    for block, (low, high) in expected.items():
        assert spec.dispersions[block] == Uniform(*spec.dispersions[block].support)
        np.testing.assert_allclose(spec.dispersions[block].support, (low, high), rtol=1e-9)
    # the LTI blocks need a worst-case region's critical frequency to be realized: without the
    # analysis' file they stay nominal unless the spec names them (shape only: the scenario's
    # [-1, 1]; the sampler then refuses the campaign without the file)
    named = tomllib.loads(spec_text)["dispersions"]
    for axis in ("xx", "xy", "zz"):
        block = f"Delta_mul_{axis}"
        if block in named:
            assert spec.dispersions[block] == Uniform(-1.0, 1.0)
        else:
            assert block not in spec.dispersions


def _expected_ranges(data) -> dict:
    """``nominal * (1 +- percent / 100)`` of every declared uncertain hub mass, inertia moment
    and first mode, read from the scenario TOML."""
    expected = {}
    for name, hub in data["hubs"].items():
        r = hub["mass_uncertainty_percent"] / 100
        if r > 0:
            expected[f"m_{name}"] = (hub["mass"] * (1 - r), hub["mass"] * (1 + r))
        for i, axis in enumerate(("xx", "yy", "zz")):
            r = hub["inertia_uncertainty_percent"][i] / 100
            moment = hub["inertia"][i][i]
            if r > 0:
                expected[f"J{axis}_{name}"] = (moment * (1 - r), moment * (1 + r))
    for name, array in data["arrays"].items():
        model = data["array_models"][array["model"]]
        r = model["first_mode_uncertainty_percent"] / 100
        omega = 2 * np.pi * model["frequencies_hz"][0]  # [rad/s]
        if r > 0:
            expected[f"w1_{name}"] = (omega * (1 - r), omega * (1 + r))
    return expected
