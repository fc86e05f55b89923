"""The scenario's ``[control]`` section: defaults, validation, and each field family reaching the
loop it claims to change (checked against closed forms, not against numbers the code printed)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from oos_drake.control.analysis_model import (
    close_loop,
    uncertain_plant,
    weighted_interconnection_open,
)
from oos_drake.control.components import DesignSpecification
from oos_drake.lfr import usubs
from oos_drake.scenario.data import (
    DEFAULT_SCENARIO_PATH,
    ScenarioError,
    load_scenario,
    scenario_path,
)
from oos_drake.scenario.model import build_mission_model, mission_values

TWO_PI = 2 * np.pi
PAPER_TEXT = DEFAULT_SCENARIO_PATH.read_text()


def spec_with(**overrides) -> DesignSpecification:
    """The specification of the paper's scenario with ``[control]`` numbers overridden."""
    values = {f"control.{k.replace('__', '.')}": v for k, v in overrides.items()}
    return DesignSpecification.from_requirements(load_scenario(None, values).control)


@pytest.fixture(scope="module")
def plant(paper_scenario):
    """Nominal rotational plant of the paper at t = 400 s (arm holding the target)."""
    model = usubs(build_mission_model(paper_scenario), mission_values([400.0], paper_scenario))
    model = model.model(0)
    return model.nominal


def poles(system) -> np.ndarray:
    return np.linalg.eigvals(np.asarray(system.A, dtype=float))


def has_pole(all_poles, pole, rtol=1e-9) -> bool:
    return bool(np.min(np.abs(all_poles - pole)) <= rtol * abs(pole))


# ---------------------------------------------------------------------------------------------
# the paper's file is the default
# ---------------------------------------------------------------------------------------------
def test_paper_control_section_is_the_default_specification_field_by_field():
    loaded = DesignSpecification.from_requirements(load_scenario().control)
    default = DesignSpecification()
    for field in dataclasses.fields(DesignSpecification):
        assert getattr(loaded, field.name) == getattr(default, field.name), field.name
    control = load_scenario().control
    assert control.torque_limit == 2.0 and control.flight_software_rate_hz == 10.0


def test_paper_control_section_matches_the_mission_defaults():
    """Torque bound and software rate of the Drake mission (its option defaults; the rate is
    the scenario's)."""
    pytest.importorskip("pydrake")
    from oos_drake.multibody.mission import MissionOptions

    scenario = load_scenario()
    control = scenario.control
    assert MissionOptions().torque_limit == control.torque_limit
    assert MissionOptions().resolved(scenario).control_rate == control.flight_software_rate_hz


def test_shipped_names_resolve():
    assert scenario_path("paper") == DEFAULT_SCENARIO_PATH.resolve()
    assert load_scenario("heavy_target").name == "heavy_target"
    with pytest.raises(
        ValueError,
        match="shipped scenarios: flexible_satellite, geo_satellite, heavy_target, paper, "
        "servicer_7dof",
    ):
        scenario_path("no_such_scenario")


# ---------------------------------------------------------------------------------------------
# bad values: one line naming the field
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        ("control.pointing_requirement", -0.001, "control.pointing_requirement: must be > 0 rad"),
        ("control.torque_limit", 0.0, "control.torque_limit: must be > 0 N m"),
        ("control.flight_software_rate_hz", -10.0, "control.flight_software_rate_hz: must be > 0"),
        ("control.sensors.star_tracker_cutoff_hz", 0.0, "control.sensors.star_tracker_cutoff_hz"),
        ("control.sensors.gyro_noise", -1.0, "control.sensors.gyro_noise: must be > 0 rad/s"),
        ("control.actuators.wheel_damping", -0.1, "control.actuators.wheel_damping"),
        ("control.rolloff.order", 0, "control.rolloff.order: must be an integer in 1..12"),
        ("control.rolloff.cutoff_hz", 6.0, "control.rolloff.cutoff_hz: 6 Hz must be below"),
        ("control.weights.disturbance_gains.1", -1.0, "control.weights.disturbance_gains"),
        ("control.weights.multiplicative_diagonal", 0.0, "control.weights.multiplicative_diagonal"),
        ("control.no_such_field", 1.0, "control.no_such_field: unknown path"),
    ],
)
def test_bad_control_values_name_the_field(path, value, message):
    with pytest.raises(ScenarioError, match=message.replace(".", r"\.")) as info:
        load_scenario(None, {path: value})
    assert "\n" not in str(info.value)


def test_unknown_and_missing_control_keys(tmp_path):
    extra = tmp_path / "extra.toml"
    extra.write_text(PAPER_TEXT.replace("[control]\n", "[control]\nslew_rate = 1.0\n"))
    with pytest.raises(ScenarioError, match="control: unknown key 'slew_rate'"):
        load_scenario(extra)
    missing = tmp_path / "missing.toml"
    missing.write_text(PAPER_TEXT.replace("torque_limit = 2.0 ", "torque_limits = 2.0 "))
    with pytest.raises(ScenarioError, match="did you mean 'torque_limit'"):
        load_scenario(missing)


# ---------------------------------------------------------------------------------------------
# every field family reaches the loop
# ---------------------------------------------------------------------------------------------
def test_sensor_cutoffs_move_the_filter_poles():
    """SST and GYRO are first-order low-passes: poles at -2 pi f_c (three axes each)."""
    open_loop = poles(weighted_interconnection_open(spec_with(sensors__star_tracker_cutoff_hz=3.0)))
    assert np.sum(np.isclose(open_loop, -TWO_PI * 3.0, rtol=1e-9)) == 3
    assert not has_pole(open_loop, -TWO_PI * 8.0)
    gyro = poles(weighted_interconnection_open(spec_with(sensors__gyro_cutoff_hz=50.0)))
    assert np.sum(np.isclose(gyro, -TWO_PI * 50.0, rtol=1e-9)) == 3


def test_wheel_model_moves_the_actuator_poles():
    """RW = w^2 / (s^2 + 2 xi w s + w^2): poles -xi w +- j w sqrt(1 - xi^2)."""
    w, xi = TWO_PI * 40.0, 0.5
    open_loop = poles(
        weighted_interconnection_open(
            spec_with(actuators__wheel_frequency_hz=40.0, actuators__wheel_damping=xi)
        )
    )
    assert has_pole(open_loop, complex(-xi * w, w * np.sqrt(1 - xi**2)))
    assert not has_pole(open_loop, complex(-0.7 * TWO_PI * 200, TWO_PI * 200 * np.sqrt(0.51)))


def test_rolloff_order_and_cutoff_move_the_butterworth_poles():
    """Butterworth of order n: poles w_c exp(j pi (2k + n + 1) / (2n)), k = 0..n-1."""
    n, fc = 2, 0.4
    open_loop = poles(
        weighted_interconnection_open(spec_with(rolloff__order=n, rolloff__cutoff_hz=fc))
    )
    for k in range(n):
        assert has_pole(open_loop, TWO_PI * fc * np.exp(1j * np.pi * (2 * k + n + 1) / (2 * n)))
    paper_pole = TWO_PI * 0.7 * np.exp(1j * np.pi * 5 / 8)
    assert not has_pole(open_loop, paper_pole)


def test_disturbance_denominator_moves_the_weight_pole():
    """W_n,ext = g / (a s + b): pole at -b / a."""
    open_loop = poles(
        weighted_interconnection_open(spec_with(weights__disturbance_denominator__1=0.5))
    )
    assert np.sum(np.isclose(open_loop, -0.5 / 2.236, rtol=1e-9)) == 3


def test_pointing_requirement_and_torque_bound_scale_the_performance_outputs(plant):
    """e_p = phi / W_p and e_u = u / torque_limit: halving W_p doubles the e_p rows, doubling
    the torque bound halves the e_u rows, and nothing else changes."""
    K = np.hstack([30.0 * np.eye(3), 300.0 * np.eye(3)])
    omega = TWO_PI * np.array([0.01, 0.3, 2.0])

    def response(**overrides):
        loop = close_loop(plant, K, spec_with(**overrides))
        return loop.nominal.freqresp(omega)

    paper = response()
    tight = response(pointing_requirement=0.0079 / 2)
    strong = response(torque_limit=4.0)
    np.testing.assert_allclose(tight[:, :3], 2 * paper[:, :3], rtol=1e-9)
    np.testing.assert_allclose(tight[:, 3:], paper[:, 3:], rtol=1e-9)
    np.testing.assert_allclose(strong[:, 3:], paper[:, 3:] / 2, rtol=1e-9)
    np.testing.assert_allclose(strong[:, :3], paper[:, :3], rtol=1e-9)


def test_additive_weight_scales_delta_add(plant):
    """P_hat = P + W_add Delta_add: with Delta_add = E (static, normalized), P_hat - P = W_add E."""
    E = np.array([[0.5, -0.2, 0.1], [0.0, 0.3, 0.2], [-0.1, 0.0, 0.4]])
    omega = TWO_PI * np.array([0.05, 0.8])
    P = plant[3:6, 3:6].freqresp(omega)
    for db in (-75.0, -60.0):
        spec = spec_with(weights__additive_weight_db=db)
        P_hat = uncertain_plant(plant, spec, multiplicative=False)
        fixed = usubs(P_hat, {"Delta_add": E}, normalized=True)
        np.testing.assert_allclose(
            fixed.freqresp(omega) - P,
            np.broadcast_to(10 ** (db / 20) * E, P.shape),
            rtol=1e-8,
            atol=1e-14,
        )
