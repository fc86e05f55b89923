"""Any flight-software rate (issue 30 item 5): nothing assumes the paper's 10 Hz.

``oos run`` on a 5 Hz scenario stopped at the confirmation stage (``mission option log_rate
10.0 Hz must divide control_rate 5.0 Hz``): the logging rates are now derived from the
scenario's flight-software rate.
"""

import math

import numpy as np
import pytest

from oos_drake.analysis.confirm import CONFIRM_LOG_RATE_HZ, ConfirmOptions, confirm_mission_options
from oos_drake.multibody.mission import MissionOptions, logging_rate
from oos_drake.scenario.data import load_scenario


def _divides(log_rate: float, control_rate: float) -> bool:
    ratio = control_rate / log_rate
    return abs(ratio - round(ratio)) <= 1e-9


@pytest.mark.parametrize(
    ("control_rate", "wanted", "expected"),
    [(10.0, 10.0, 10.0), (5.0, 10.0, 5.0), (3.0, 10.0, 3.0), (7.0, 2.0, 1.75), (100.0, 10.0, 10.0),
     (10.0, 1.0, 1.0), (5.0, 1.0, 1.0), (2.5, 1.0, 0.8333333333333334), (1.0, 10.0, 1.0),
     (30.0, 7.0, 6.0)],
)  # fmt: skip
def test_logging_rate_is_the_fastest_divisor_at_most_the_wanted_rate(
    control_rate, wanted, expected
):
    rate = logging_rate(control_rate, wanted)
    assert rate == pytest.approx(expected, rel=1e-12)
    assert rate <= wanted * (1 + 1e-12) and _divides(rate, control_rate)
    # the next faster divisor is above the wanted rate (or there is none)
    n = round(control_rate / rate)
    assert n == 1 or control_rate / (n - 1) > wanted


def test_logging_rate_refuses_non_positive_rates():
    with pytest.raises(ValueError, match="control_rate must be > 0"):
        logging_rate(0.0, 1.0)
    with pytest.raises(ValueError, match="wanted must be > 0"):
        logging_rate(5.0, math.nan)


@pytest.mark.parametrize(("rate", "log_rate"), [(5.0, 5.0), (3.0, 3.0), (7.0, 7.0), (10.0, 10.0),
                                                (100.0, 10.0), (1.5, 1.5), (2.5, 2.5)])  # fmt: skip
def test_confirmation_runs_at_any_flight_software_rate(paper_scenario, rate, log_rate):
    """The piece that failed: the confirmation's mission options at the scenario's rate (the
    paper's 10 Hz keeps its 10 Hz logging, so its confirmation is unchanged)."""
    scenario = load_scenario(paper_scenario.source, {"control.flight_software_rate_hz": rate})
    options = confirm_mission_options(scenario, ConfirmOptions())
    assert options.control_rate == rate
    assert options.log_rate == pytest.approx(log_rate, rel=1e-12)
    assert options.log_rate <= CONFIRM_LOG_RATE_HZ and _divides(options.log_rate, rate)


@pytest.mark.parametrize("rate", [5.0, 3.0, 7.0, 10.0, 2.5])
def test_mission_options_take_the_scenarios_rate(paper_scenario, rate):
    scenario = load_scenario(paper_scenario.source, {"control.flight_software_rate_hz": rate})
    options = MissionOptions().resolved(scenario)
    assert options.control_rate == rate
    assert options.log_rate <= 1.0 and _divides(options.log_rate, rate)
    # an explicit rate wins over the scenario's
    assert MissionOptions(control_rate=20.0).resolved(scenario).control_rate == 20.0


def test_paper_mission_options_unchanged(paper_scenario):
    options = MissionOptions().resolved(paper_scenario)
    assert (options.control_rate, options.log_rate) == (10.0, 1.0)


def test_a_log_rate_that_does_not_divide_is_refused_with_a_suggestion():
    with pytest.raises(ValueError, match=r"log_rate 10.0 Hz must divide control_rate 5.0 Hz.*5"):
        MissionOptions(control_rate=5.0, log_rate=10.0)


@pytest.mark.drake
def test_mission_diagram_logs_at_a_divisor_of_a_7_hz_flight_software(paper_scenario):
    """The Drake mission built for a 7 Hz flight software logs at 1 Hz (7 samples apart)."""
    from oos_drake.multibody.mission import make_mission_diagram

    scenario = load_scenario(paper_scenario.source, {"control.flight_software_rate_hz": 7.0})
    handles = make_mission_diagram(scenario=scenario)
    assert handles.options.control_rate == 7.0 and handles.options.log_rate == 1.0
    assert handles.flight_software.design.period == pytest.approx(1 / 7.0, rel=1e-12)


@pytest.mark.drake
def test_confirmation_twin_runs_the_users_5_hz_scenario():
    """What stopped ``oos run`` on a 5 Hz scenario: the confirmation's twin (its options, its
    own SDF files, the 5 Hz flight software) built and run on a frozen window; the log is
    sampled every flight-software period (0.2 s)."""
    from pathlib import Path

    from oos_drake.multibody.mission import make_mission_diagram
    from oos_drake.multibody.mission_sim import MissionSimulation
    from oos_drake.scenario.timeline import mission_timeline

    scenario = load_scenario(Path(__file__).parents[1] / "data" / "user_chaser.toml")
    assert scenario.control.flight_software_rate_hz == 5.0
    options = confirm_mission_options(scenario, ConfirmOptions())
    handles = make_mission_diagram(
        options, scenario=scenario, timeline=mission_timeline(scenario).frozen(400.0)
    )
    assert handles.flight_software.design.period == pytest.approx(0.2, rel=1e-12)
    result = MissionSimulation(handles).run({}, seed=1, start=400.0, end=404.0)
    times = result.timeseries["time [s]"].to_numpy()
    np.testing.assert_allclose(np.diff(times), 0.2, rtol=1e-9)
    assert times[0] == pytest.approx(400.0) and times[-1] == pytest.approx(404.0)
    assert np.all(np.isfinite(result.timeseries[[f"phi_{a} [rad]" for a in "xyz"]].to_numpy()))
