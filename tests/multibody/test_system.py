"""System level: the Drake twin vs the TITOP LFR model and vs the rigid inertia from kinematics."""

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.multibody.cross_check import (  # noqa: E402
    VALIDATION_OMEGA,
    compare_systems,
    run_validation,
    titop_state_space,
    validation_cases,
)
from oos_drake.multibody.operating_point import (  # noqa: E402
    acceleration_response,
    linearize_at,
    operating_point,
    set_operating_point,
)
from oos_drake.multibody.scenario_plant import (  # noqa: E402
    build_scenario_diagram,
    set_spring_damper,
    twin_diagram,
)
from oos_drake.scenario.data import load_scenario  # noqa: E402
from oos_drake.scenario.kinematics import rigid_spatial_inertia_at_G1  # noqa: E402
from oos_drake.scenario.model import (  # noqa: E402
    build_docking_model,
    build_mission_model,
    configuration_values,
)
from oos_drake.scenario.timeline import mission_timeline  # noqa: E402

SCENARIO = load_scenario("paper")
TIMELINE = mission_timeline(SCENARIO)
OMEGA = VALIDATION_OMEGA  # 400 frequencies, 0.01 .. 100 Hz


@pytest.fixture(scope="module")
def mission_model():
    return build_mission_model(SCENARIO)


def _titop_at(model, configuration, extra=None):
    values = {
        k: float(v)
        for k, v in configuration_values(
            configuration.alpha, configuration.theta, configuration.delta_C1, configuration.delta_C2
        ).items()
    }
    values.update(extra or {})
    return titop_state_space(model, values)


def _linearize(configuration, label=""):
    """The twin linearized at one configuration (rigid connections), via the public path."""
    point = operating_point(configuration, label=label)
    return linearize_at(point, twin_diagram(SCENARIO, point.connection))


def _dc_gain(system):
    """Exact G(0) = D - C A^-1 B of a minimal acceleration model (no pole at 0)."""
    return system.D - system.C @ np.linalg.solve(system.A, system.B)


@pytest.mark.parametrize("name", ["1", "2", "3", "4", "5", "6"])
def test_six_moments_match_titop(mission_model, name):
    configuration = TIMELINE.moments[name].configuration
    point = operating_point(configuration)
    drake = acceleration_response(linearize_at(point, twin_diagram(SCENARIO, point.connection)))
    result = compare_systems(
        f"moment {name}", drake, _titop_at(mission_model, configuration), OMEGA
    )
    assert result.max_relative_error <= 1e-6
    assert result.pole_error <= 1e-4 and result.zero_error <= 1e-4
    assert result.n_states[0] == result.n_states[1]


@pytest.mark.parametrize("name", ["1", "2", "3", "4", "5", "6"])
def test_low_frequency_gain_is_inverse_rigid_inertia_from_kinematics(name):
    """Independent of TITOP: G(0) = D_G1^-1 with D_G1 summed from the forward kinematics."""
    configuration = TIMELINE.moments[name].configuration
    drake = acceleration_response(_linearize(configuration, name))
    expected = np.linalg.inv(rigid_spatial_inertia_at_G1(SCENARIO, configuration))
    np.testing.assert_allclose(
        _dc_gain(drake), expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max()
    )


def test_random_mission_times_match_titop(mission_model):
    rng = np.random.default_rng(2024)
    for time in rng.uniform(SCENARIO.mission.t_start, SCENARIO.mission.t_end, 3):
        drake = acceleration_response(_linearize(TIMELINE.configuration(time)))
        titop = _titop_at(mission_model, TIMELINE.configuration(time))
        result = compare_systems(f"t={time:.1f}", drake, titop, OMEGA[::4])
        assert result.passed, result


@pytest.mark.parametrize("stiffness", [0.1, 1e3, 1e5])
def test_docking_phase_7_matches_titop(stiffness):
    cases = [c for c in validation_cases(SCENARIO, [stiffness]) if c.label.startswith("phase 7")]
    (result,) = run_validation(SCENARIO, cases=cases)
    assert result.passed, result


def test_docking_phase_8_matches_titop():
    cases = [c for c in validation_cases(SCENARIO, [1.0, 1e4]) if c.label.startswith("phase 8")]
    results = run_validation(SCENARIO, cases=cases)
    assert len(results) == 4
    assert all(r.passed for r in results), results


@pytest.mark.slow
def test_full_validation_passes():
    results = run_validation(SCENARIO)
    assert len(results) == 6 + 7 + 14
    assert all(r.passed for r in results), [r for r in results if not r.passed]


def test_bushing_parameters_change_in_the_context_without_rebuild():
    """One diagram, one context: SM1 stiffness set in the context reproduces TITOP at each value."""
    handles = build_scenario_diagram("spring_damper")
    context = handles.diagram.CreateDefaultContext()
    named = TIMELINE.docking_phases["7"]
    model = build_docking_model("7", SCENARIO)
    previous = None
    for k in (10.0, 1e4):
        point = operating_point(named.configuration, {"SM1": (k, 100.0)})
        drake = acceleration_response(linearize_at(point, handles, context))
        extra = {
            f"{q}_SM1": v
            for q, v in (("k_shear", k), ("k_tors", k), ("d_shear", 100.0), ("d_tors", 100.0))
        }
        titop = _titop_at(model, named.configuration, extra)
        result = compare_systems(f"k={k}", drake, titop, OMEGA[::4])
        assert result.passed, result
        response = drake(2j * np.pi * 1.0)
        if previous is not None:
            assert np.linalg.norm(response - previous) > 1e-3 * np.linalg.norm(previous)
        previous = response
    # the parameters live in the context
    set_spring_damper(handles, context, "SM2", (3.0, 4.0), (5.0, 6.0))
    plant_context = handles.plant.GetMyContextFromRoot(context)
    bushing = handles.bushings["SM2"]
    np.testing.assert_array_equal(bushing.GetForceStiffnessConstants(plant_context), [3.0] * 3)
    np.testing.assert_array_equal(bushing.GetTorqueDampingConstants(plant_context), [6.0] * 3)
    with pytest.raises(ValueError, match="SM1: stiffness must be finite and >= 0"):
        set_spring_damper(handles, context, "SM1", -1.0, 0.0)


def test_rate_and_attitude_outputs_integrate_the_angular_acceleration():
    system = _linearize(TIMELINE.moments["3"].configuration, "3")
    for w in (0.3, 5.0, 40.0):
        s = 1j * w
        response = system(s)
        wdot = response[3:6]
        rate_error = np.linalg.norm(response[6:9] - wdot / s) / np.linalg.norm(wdot / s)
        attitude_error = np.linalg.norm(response[9:12] - wdot / s**2) / np.linalg.norm(wdot / s**2)
        assert rate_error < 1e-9 and attitude_error < 1e-9


def test_mass_matrix_positive_definite_and_operating_point_is_equilibrium():
    for connection, name in (("hub", "5"), ("arm", "3"), ("spring_damper", "8")):
        handles = build_scenario_diagram(connection)
        context = handles.diagram.CreateDefaultContext()
        named = TIMELINE.named[name]
        springs = {sm: (1e3, 100.0) for sm in named.spring_dampers} or None
        set_operating_point(handles, context, operating_point(named.configuration, springs))
        plant_context = handles.plant.GetMyContextFromRoot(context)
        assert np.linalg.eigvalsh(handles.plant.CalcMassMatrix(plant_context)).min() > 0
        handles.diagram.get_input_port(0).FixValue(context, np.zeros(6))
        derivatives = handles.diagram.EvalTimeDerivatives(context).CopyToVector()
        assert np.abs(derivatives).max() < 1e-6


def test_mixed_connection_is_refused():
    from oos_drake.multibody.scenario_plant import connection_for

    with pytest.raises(ValueError, match="cannot|not a configuration"):
        connection_for(1.0, 1.0)
    with pytest.raises(ValueError, match="connection must be one of"):
        build_scenario_diagram("glued")


def test_bad_operating_point_requests_are_refused():
    with pytest.raises(ValueError, match="needs one configuration"):
        operating_point(TIMELINE.sample(3))
    with pytest.raises(ValueError, match="outside the mission"):
        TIMELINE.configuration(-5.0)
    handles = build_scenario_diagram("hub")
    point = operating_point(TIMELINE.moments["2"].configuration)  # arm-clamped configuration
    with pytest.raises(ValueError, match="needs a 'arm' diagram"):
        linearize_at(point, handles)


def test_nonlinear_simulation_agrees_with_linearization_for_small_torques():
    """The twin is a real multibody model: simulate it (continuous plant, locked drive joints)
    under a small constant torque and compare with the linear model's forced response."""
    import control
    from pydrake.systems.analysis import Simulator

    point = operating_point(TIMELINE.moments["5"].configuration)
    handles = build_scenario_diagram(point.connection)
    context = handles.diagram.CreateDefaultContext()
    set_operating_point(handles, context, point)
    wrench = np.array([0.0, 0.0, 0.0, 0.05, 0.02, -0.03])  # [N, N m]
    handles.diagram.GetInputPort("W_ext_G1").FixValue(context, wrench)
    simulator = Simulator(handles.diagram, context)
    simulator.get_mutable_integrator().set_target_accuracy(1e-8)
    times = np.linspace(0.0, 2.0, 21)
    output = handles.diagram.GetOutputPort("y_G1")
    nonlinear = []
    for t in times:
        simulator.AdvanceTo(t)
        nonlinear.append(output.Eval(simulator.get_context()).copy())
    nonlinear = np.array(nonlinear)[:, 6:12]  # angular rate and attitude
    linear = control.forced_response(
        linearize_at(point, handles), T=times, U=np.tile(wrench, (times.size, 1)).T
    ).outputs.T[:, 6:12]
    error = np.abs(nonlinear - linear).max(axis=0) / np.abs(linear).max(axis=0)
    assert error.max() < 5e-3, error
    assert np.abs(linear).max() > 1e-5  # the torque did move the hub
