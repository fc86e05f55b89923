"""The cheap flexible-attitude simulator against independent computations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate

from oos_drake.campaign.attitude_sim import FlexibleAttitudeSimulator, make_simulator
from oos_drake.campaign.simulator import (
    MissionWindow,
    RunCase,
    SimulationDiverged,
    Simulator,
    SimulatorRecipe,
    build_simulator,
)

from .simulator_contract import check_simulator


def _nominal(sim, **changes):
    values = {p.name: p.nominal for p in sim.parameters()}
    values.update(changes)
    return values


def test_protocol_and_registry():
    sim = build_simulator(SimulatorRecipe.create("flexible-attitude", {"control_rate": 4.0}))
    assert isinstance(sim, Simulator) and sim.control_rate == 4.0
    assert {"J_hub", "f_array", "k_dock"} <= {p.name for p in sim.parameters()}
    kinds = {p.kind.value for p in sim.parameters()}
    assert {"real_block", "stiffness", "initial_condition", "lti"} <= kinds
    with pytest.raises(ValueError, match="unknown option"):
        make_simulator(rate=3)


def test_free_array_mode_frequency_matches_two_inertia_closed_form():
    sim = FlexibleAttitudeSimulator()
    values = _nominal(sim, f_array=0.4, J_hub=450.0)
    A, _ = sim.continuous_model(values, docked=False)
    k_a = sim.array_modal_inertia * (2 * math.pi * 0.4) ** 2
    j_h, j_a = 450.0, sim.array_modal_inertia
    expected = math.sqrt(k_a * (j_h + j_a) / (j_h * j_a))  # free-free two-inertia mode [rad/s]
    frequencies = np.abs(np.linalg.eigvals(A))  # natural frequencies |lambda|
    assert np.min(np.abs(frequencies - expected)) < 1e-6 * expected


def test_docked_model_conserves_angular_momentum():
    sim = FlexibleAttitudeSimulator()
    values = _nominal(sim, k_dock=3e4, c_dock=120.0, J_target=200.0)
    A, B = sim.continuous_model(values, docked=True)
    inertia = np.array([values["J_hub"], sim.array_modal_inertia, values["J_target"]])
    # d/dt sum(J_i w_i) = hub torque, whatever the springs and dampers
    np.testing.assert_allclose(inertia @ A[3:, :], 0.0, atol=1e-9)
    assert inertia @ B[3:] == pytest.approx(1.0, rel=1e-12)


def test_zero_order_hold_matches_an_ode_solver():
    sim = FlexibleAttitudeSimulator(control_rate=5.0, star_tracker_noise=0.0, gyro_noise=0.0)
    values = _nominal(sim, theta0=0.004, omega0=0.002)
    out = sim.run(RunCase(0, 1, values, MissionWindow(80.0, 110.0)))
    kp, kd = sim.gains()
    # independent integration: RK45 over each held-torque interval, same controller
    x = np.zeros(6)
    x[:3], x[3:] = 0.004, 0.002
    theta = [x[0]]
    for k in range(150):
        t = 80.0 + 0.2 * k
        if abs(t - 100.0) < 1e-9:
            x[2], x[5] = x[0], x[3] + values["omega_capture"]
        A, B = sim.continuous_model(values, docked=t >= 100.0 - 1e-9)
        u = min(max(-kp * x[0] - kd * x[3], -3.0), 3.0)
        torque = u + values["T_ext"]
        sol = scipy.integrate.solve_ivp(
            lambda _, y, A=A, B=B, torque=torque: A @ y + B * torque,
            (0, 0.2),
            x,
            rtol=1e-10,
            atol=1e-13,
        )
        x = sol.y[:, -1]
        theta.append(x[0])
    np.testing.assert_allclose(out.timeseries["theta_hub [rad]"], theta, rtol=0, atol=1e-9)


def test_disturbance_and_actuator_gain_reach_the_model():
    sim = FlexibleAttitudeSimulator(star_tracker_noise=0.0, gyro_noise=0.0)
    kp, _ = sim.gains()
    values = _nominal(sim, T_ext=0.04, delta_mul=-0.25, omega_capture=0.0)
    out = sim.run(RunCase(0, 1, values, MissionWindow(150.0, 300.0)))
    # static balance (1 + delta_mul) * (-Kp theta) + T_ext = 0
    expected = 0.04 / (kp * 0.75)
    assert out.timeseries["theta_hub [rad]"].iloc[-1] == pytest.approx(expected, rel=1e-3)


def test_loss_of_attitude_raises_simulation_diverged():
    sim = FlexibleAttitudeSimulator()
    with pytest.raises(SimulationDiverged, match="divergence limit"):
        sim.run(RunCase(0, 1, _nominal(sim, omega0=0.1), MissionWindow(0.0, 300.0)))


def test_same_seed_same_run_other_seed_other_noise():
    sim = FlexibleAttitudeSimulator()
    values = _nominal(sim)
    window = MissionWindow(90.0, 120.0)
    a = sim.run(RunCase(0, 11, values, window)).metrics
    assert sim.run(RunCase(0, 11, values, window)).metrics == a
    assert sim.run(RunCase(0, 12, values, window)).metrics != a


def test_zero_order_hold_model_matches_ode_integration():
    """(Ad, Bd) over one period equal a tight ODE integration of x' = A x + B u, u held."""
    sim = FlexibleAttitudeSimulator(control_rate=2.0)
    values = _nominal(sim)
    for docked in (False, True):
        A, B = sim.continuous_model(values, docked)
        Ad, Bd = sim.discrete_model(values, docked)
        period = 1.0 / sim.control_rate
        for column, x0, u in [(None, np.zeros(6), 1.0)] + [
            (j, np.eye(6)[j], 0.0) for j in range(6)
        ]:
            solution = scipy.integrate.solve_ivp(
                lambda t, x, A=A, B=B, u=u: A @ x + B * u, (0.0, period), x0, rtol=1e-12, atol=1e-14
            )
            expected = Ad[:, column] if column is not None else Bd
            np.testing.assert_allclose(solution.y[:, -1], expected, rtol=1e-8, atol=1e-11)


def test_cheap_simulator_passes_the_protocol_check():
    output = check_simulator(FlexibleAttitudeSimulator(control_rate=5.0))
    assert output.metrics["ape"] > 0


def test_protocol_check_catches_a_non_reproducible_simulator():
    from oos_drake.campaign.simulator import RunOutput

    class Drifting(FlexibleAttitudeSimulator):
        calls = [0]

        def run(self, case):
            self.calls[0] += 1
            return RunOutput({"ape": 1.0 * self.calls[0], "peak_torque": 1.0, "rms_attitude": 1.0})

    with pytest.raises(ValueError, match="not reproducible"):
        check_simulator(Drifting())
