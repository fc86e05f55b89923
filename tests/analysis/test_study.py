"""``oos study``: the sweep syntax, the margin crossing, bad input, and a tiny real study."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from oos_drake.analysis.study import StudyOptions, Sweep, field_unit, margin_crossing, run_study
from oos_drake.cli import main


def test_sweep_parse_and_units():
    sweep = Sweep.parse("hubs.RH2.mass=25:100:4")
    assert sweep.path == "hubs.RH2.mass" and sweep.values == (25.0, 50.0, 75.0, 100.0)
    assert sweep.column == "hubs.RH2.mass [kg]"
    assert field_unit("array_models.SA3_4.frequencies_hz.0") == "Hz"
    assert field_unit("control.pointing_requirement") == "rad"
    assert field_unit("hubs.RH2.mass_uncertainty_percent") == "%"
    assert field_unit("mission.arm_waypoints.times.3") == "s"


@pytest.mark.parametrize(
    "text", ["hubs.RH2.mass", "hubs.RH2.mass=1:2", "=1:2:3", "m=a:2:3", "m=1:2:1", "m=2:2:3"]
)
def test_bad_ranges_are_one_line_errors(text):
    with pytest.raises(ValueError, match="--vary"):
        Sweep.parse(text)


@pytest.mark.parametrize(
    ("vary", "message"),
    [
        ("hubs.RH9.mass=1:2:2", "hubs.RH9.mass: unknown path: no 'RH9' in hubs"),
        ("hubs.RH2=1:2:2", "hubs.RH2: is not a number"),
        ("hubs.RH2.mass=-5:5:2", "RH2: mass must be > 0"),
        ("control.torque_limit=0:1:2", "control.torque_limit: must be > 0 N m"),
        ("hubs.RH2.mass=1:2", "expected PATH=start:stop:n"),
    ],
)
def test_cli_rejects_bad_input_with_status_2_and_writes_nothing(tmp_path, capsys, vary, message):
    out = tmp_path / "study"
    assert main(["study", "--vary", vary, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not out.exists() and not list(tmp_path.iterdir())


def test_margin_crossing_interpolates_linearly():
    table = pd.DataFrame(
        {
            "x [kg]": [0.0, 10.0, 20.0],
            "margin lower [-]": [2.0, 1.5, 0.5],  # crosses 1 at 15
            "margin upper [-]": [3.0, 2.0, 1.5],  # never crosses
        }
    )
    assert margin_crossing(table, "x [kg]") == {"certified": 15.0, "attained": None}


@pytest.mark.slow
def test_tiny_mass_study_reaches_the_model(tmp_path):
    """Two target masses, three mission configurations, no docking phase (~1 min idle)."""
    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.models import mission_closed_loop, mission_times
    from oos_drake.scenario.data import load_scenario

    options = StudyOptions(workers=2)
    options = replace(
        options,
        analysis=replace(
            options.analysis,
            configurations=3,
            docking_phases=(),
            performance_models=2,
            performance_points=4,
            spike_budget=20.0,
        ),
    )
    sweep = Sweep.parse("hubs.RH2.mass=25:400:2")
    table = run_study(None, sweep, tmp_path / "study", options, progress=False)
    saved = pd.read_parquet(tmp_path / "study" / "study.parquet")
    pd.testing.assert_frame_equal(saved, table)
    assert (tmp_path / "study" / "study.png").stat().st_size > 0
    assert list(table["hubs.RH2.mass [kg]"]) == [25.0, 400.0]
    np.testing.assert_allclose(table["margin lower [-]"], 1 / table["mu upper [-]"], rtol=1e-12)
    np.testing.assert_allclose(table["margin upper [-]"], 1 / table["mu lower [-]"], rtol=1e-12)
    assert np.all(table["mu lower [-]"] <= table["mu upper [-]"] * (1 + 1e-9))
    for i, mass in enumerate(sweep.values):
        # the swept mass reached the analyzed model: its worst-case target mass lies in +-10 %
        point = tmp_path / "study" / "points" / str(i) / "analysis"
        worst = pd.read_parquet(point / "worst_cases.parquet")["wc:m_RH2 [kg]"].dropna()
        assert len(worst) and np.all(np.abs(worst / mass - 1) <= 0.1 + 1e-9)
        # nominal stability counted again from the closed-loop eigenvalues
        scenario = load_scenario(None, {sweep.path: mass})
        controller = scenario_controller(None, scenario)
        loop = mission_closed_loop(controller, mission_times(3, scenario), scenario)
        stable = int((np.linalg.eigvals(np.asarray(loop.system.A)).real.max(axis=-1) < 0).sum())
        assert table["nominal stable models [-]"][i] == stable


@pytest.mark.slow
def test_tiny_synthesis_study_tunes_on_each_value(tmp_path):
    """--synthesize: each value's controller is tuned with that value's [control] (~15 s idle)."""
    import json

    from oos_drake.control.synthesis import SynthesisOptions

    options = StudyOptions(
        workers=2,
        synthesize=True,
        synthesis_configurations=6,
        synthesis=SynthesisOptions(workers=1, restarts=0, max_iterations=20, worst_case_rounds=1),
    )
    options = replace(
        options,
        analysis=replace(
            options.analysis,
            configurations=3,
            docking_phases=(),
            performance_models=2,
            performance_points=4,
            spike_budget=20.0,
        ),
    )
    sweep = Sweep.parse("control.pointing_requirement=0.004:0.008:2")
    table = run_study("heavy_target", sweep, tmp_path / "study", options, progress=False)
    for i, requirement in enumerate(sweep.values):
        record = json.loads(
            (tmp_path / "study" / "points" / str(i) / "controller" / "controller.json").read_text()
        )
        assert record["design_specification"]["pointing_requirement"] == requirement
        assert record["scenario"]["overrides"] == {sweep.path: requirement}
        assert record["scenario"]["name"] == "heavy_target"
        assert table["gamma [-]"][i] == record["gamma"]
        assert table["controller"][i] == "synthesized"
