"""``oos confirm`` against the Drake twin: the flight software's linear map, the sampled-data
loop against the continuous one, and one worst case confirmed end to end (slow)."""

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from pydrake.systems.analysis import Simulator  # noqa: E402

from oos_drake.analysis.confirm import (  # noqa: E402
    AGREEMENT,
    GROWTH_TOLERANCE,
    ConfirmOptions,
    Peak,
    _continuous_abscissa,
    boundary_along_ray,
    confirm_peak,
    sampled_loop_poles,
)
from oos_drake.analysis.controller import Controller  # noqa: E402
from oos_drake.analysis.models import mission_plants  # noqa: E402
from oos_drake.control.analysis_model import close_loop, uncertain_plant  # noqa: E402
from oos_drake.control.baseline import baseline_gains  # noqa: E402
from oos_drake.control.components import DesignSpecification  # noqa: E402
from oos_drake.multibody.flight_software import (  # noqa: E402
    FlightSoftware,
    FlightSoftwareDesign,
    perturbation_block,
    rpy_to_rotation,
)
from oos_drake.multibody.mission import effective_inertia  # noqa: E402
from oos_drake.scenario.data import load_scenario  # noqa: E402
from oos_drake.scenario.kinematics import rigid_spatial_inertia_at_G1  # noqa: E402
from oos_drake.scenario.timeline import mission_timeline  # noqa: E402

#: A configuration with the arrays tilting (frozen there) and the chaser arrays' first modes
#: pulled apart (SA1, SA4 down, SA2, SA3 up): the analysis' modal worst-case direction.
TIME = 1418.0
MODAL = {"w1_SA1": -1.0, "w1_SA2": 1.0, "w1_SA3": 1.0, "w1_SA4": -1.0}


@pytest.fixture(scope="module")
def setup():
    """A PD on the coupled inertia at ``TIME`` (0.1 Hz, damping 0.7) and the plant there."""
    scenario = load_scenario()
    configuration = mission_timeline(scenario).configuration(TIME)
    J = effective_inertia(rigid_spatial_inertia_at_G1(scenario, configuration))
    K = baseline_gains(0.5 * (J + J.T), 2 * np.pi * 0.1, 0.7)
    controller = Controller(K, DesignSpecification(), "test", "test PD")
    plant = mission_plants([TIME], scenario).model(0)
    closed = close_loop(plant, K, controller.spec)
    probe = Peak("mission", "modal", TIME, np.nan, 1.0, 0.0, 0.0, MODAL)

    def unstable(alpha):
        return _continuous_abscissa(closed, probe, alpha)[0] > GROWTH_TOLERANCE

    alpha = boundary_along_ray(unstable, 4.0, steps=40, rtol=1e-6)
    assert 1.0 < alpha < 4.0  # a physical destabilizing modal perturbation exists
    omega = _continuous_abscissa(closed, probe, alpha * (1 + 1e-6))[1]
    # the worst case as the analysis would save it: normalized so that alpha = 1 is critical
    peak = Peak(
        "mission",
        "modal",
        TIME,
        np.nan,
        omega,
        1 / alpha,
        1 / alpha,
        {n: alpha * d for n, d in MODAL.items()},
    )
    return controller, plant, peak


def _random_complex_blocks(rng):
    """A full-rank ``Delta_mul`` and a rank-one ``Delta_add`` (the mu power iteration's)."""
    mul = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
    u, v = rng.standard_normal((2, 3)) + 1j * rng.standard_normal((2, 3))
    return mul, np.outer(u, v)


@pytest.mark.parametrize("dynamic", [False, True])
def test_flight_software_linear_map_is_the_update_drake_runs(dynamic):
    rng = np.random.default_rng(1)
    design = FlightSoftwareDesign.create(rng.standard_normal((3, 6)), 10.0)
    block = None
    if dynamic:
        mul, add = _random_complex_blocks(rng)
        block = perturbation_block(design, 5.0, delta_mul=mul, delta_add=add)
    fsw = FlightSoftware(design, 6, 6, 0, 0, perturbation_states=block.nstates if block else 0)
    linear = fsw.linear_update(dynamic=block)
    rpy, w_B = 1e-3 * rng.standard_normal(3), 1e-3 * rng.standard_normal(3)
    context = fsw.CreateDefaultContext()
    fsw.set_dynamic_perturbation(context, block)
    fsw.get_input_port(0).FixValue(
        context, np.concatenate([rpy, np.zeros(3), rpy_to_rotation(*rpy) @ w_B, np.zeros(3)])
    )
    simulator = Simulator(fsw, context)
    x = np.zeros(linear.A.shape[0])
    y = np.concatenate([rpy, w_B])
    for k in range(8):
        simulator.AdvanceTo((k + 0.5) * design.period)
        T_drake = fsw.GetOutputPort("log").Eval(context)[6:9]
        T_linear = linear.C @ x + linear.D @ y
        np.testing.assert_allclose(T_drake, T_linear, rtol=1e-10, atol=1e-15)
        x = linear.A @ x + linear.B @ y


def _response(block, z, rows):
    """Frequency response of rows of a DiscreteBlock at ``z``."""
    n = block.A.shape[0]
    return block.C[rows] @ np.linalg.solve(z * np.eye(n) - block.A, block.B) + block.D[rows]


def test_realized_complex_blocks_take_the_worst_value_at_the_critical_frequency():
    """The multiplicative part is the worst matrix at ``e^{j omega dt}``; the additive part is
    the exact sampled response of the continuous acceleration ``W_add Delta_add(s)`` integrated
    twice under a held torque (checked against an ODE solver), whose continuous interpolant
    takes the worst matrix at ``j omega``; the block is stable but for the two integrators."""
    from scipy.integrate import solve_ivp

    from oos_drake.robust.interpolant import lti_interpolant

    rng = np.random.default_rng(7)
    design = FlightSoftwareDesign.create(rng.standard_normal((3, 6)), 10.0)
    mul, add = _random_complex_blocks(rng)
    omega = 2 * np.pi * 0.8
    block = perturbation_block(design, omega, delta_mul=mul, delta_add=add)
    z = np.exp(1j * omega * design.period)
    dT = _response(block, z, slice(0, 3))
    np.testing.assert_allclose(dT, design.W_mul * mul, rtol=1e-9, atol=1e-12)
    poles = np.linalg.eigvals(block.A)
    at_one = np.abs(poles - 1.0) < 1e-6
    assert np.count_nonzero(at_one) == 6 and np.all(np.abs(poles[~at_one]) < 1.0)
    # the additive part: a held torque T_m = T_rw (no Delta_mul) through the continuous
    # double-integrated acceleration W_add Delta_add(s) T_m, solved as an ODE
    only_add = perturbation_block(design, omega, delta_add=add)
    G = lti_interpolant(design.W_add * add, omega)
    np.testing.assert_allclose(np.asarray(G(1j * omega)), design.W_add * add, rtol=1e-9, atol=1e-15)
    A, B, C, D = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (G.A, G.B, G.C, G.D))
    n = A.shape[0]
    torques = rng.standard_normal((12, 3))
    state = np.zeros(n + 6)  # [x_G; w_a; phi_a]
    x = np.zeros(only_add.nstates)
    for k, T_m in enumerate(torques):
        measured = only_add.C[3:] @ x
        np.testing.assert_allclose(measured, np.concatenate([state[n + 3 :], state[n : n + 3]]),
                                   rtol=1e-7, atol=1e-14)  # fmt: skip
        x = only_add.A @ x + only_add.B @ T_m

        def rhs(t, s, T_m=T_m):
            return np.concatenate([A @ s[:n] + B @ T_m, C @ s[:n] + D @ T_m, s[n : n + 3]])

        state = solve_ivp(rhs, (0, design.period), state, rtol=1e-11, atol=1e-16).y[:, -1]
        assert k < 2 or np.abs(measured).max() > 0


def test_sampled_data_loop_tends_to_the_continuous_loop_as_the_rate_grows(setup):
    controller, plant, peak = setup
    plant_hat = uncertain_plant(plant, controller.spec)
    found = {}
    for rate in (10.0, 1000.0):
        design = FlightSoftwareDesign.create(controller.K, rate)
        fsw = FlightSoftware(design, 6, 6, 0, 0)

        def unstable(alpha, fsw=fsw, period=design.period):
            z = sampled_loop_poles(plant_hat, peak, alpha, fsw)
            return np.log(np.abs(z).max()) / period > GROWTH_TOLERANCE

        alpha = boundary_along_ray(unstable, 2.0, steps=40, rtol=1e-6)
        z = sampled_loop_poles(plant_hat, peak, alpha * (1 + 1e-6), fsw)
        frequency = abs(np.angle(z[np.argmax(np.abs(z))])) / design.period
        found[rate] = (alpha, frequency)
    assert found[1000.0][0] == pytest.approx(1.0, abs=2e-3)
    assert found[1000.0][1] == pytest.approx(peak.omega, rel=2e-3)
    assert abs(found[10.0][0] - 1.0) > 5e-3  # the 10 Hz loop is a different loop


def test_the_twins_measured_additive_perturbation_closes_the_analysis_sampled_loop(setup):
    """The twin's realization (``Delta_add`` on the measurements, ``Delta_mul`` in the flight
    software) against the analysis' uncertain plant ``(P + W_add Delta_add(s))(I + ...)``
    behind the hold (the LFR's own construction): the same closed-loop poles, plus the
    realization's six unobservable integrator modes at ``z = 1``."""
    controller, plant, _ = setup
    rng = np.random.default_rng(3)
    mul, add = _random_complex_blocks(rng)
    omega = 2 * np.pi * 0.8
    perturbation = {"Delta_add": 2.0 * add} | {
        f"Delta_mul_{a}{b}": np.array([[mul[i, j]]]) for i, a in enumerate("xyz")
        for j, b in enumerate("xyz")
    }  # fmt: skip
    peak = Peak("mission", "total", TIME, np.nan, omega, 1.0, 1.0, perturbation)
    plant_hat = uncertain_plant(plant, controller.spec)
    design = FlightSoftwareDesign.create(controller.K, 10.0)
    software = FlightSoftware(design, 6, 6, 0, 0)
    mul_block = perturbation_block(design, omega, delta_mul=mul)
    expected = sampled_loop_poles(plant_hat, peak, 1.0, software, mul_block)
    # the twin: the real plant behind the hold, every complex block in the flight software
    block = perturbation_block(design, omega, delta_mul=mul, delta_add=2.0 * add)
    twin_peak = Peak("mission", "real", TIME, np.nan, omega, 1.0, 1.0, {})
    fsw = software.linear_update(dynamic=block)
    assert fsw.A.shape[0] == software.linear_update().A.shape[0] + block.nstates
    twin = sampled_loop_poles(
        uncertain_plant(plant, controller.spec, additive=False, multiplicative=False),
        twin_peak,
        1.0,
        _WithDynamic(software, block),
    )
    at_one = np.abs(twin - 1.0) < 1e-5
    assert np.count_nonzero(at_one) >= 6
    rest = np.sort_complex(twin[np.argsort(np.abs(twin - 1.0))[6:]])
    np.testing.assert_allclose(rest, np.sort_complex(expected), rtol=0, atol=1e-7)


class _WithDynamic:
    """A flight software whose linear update always carries ``block``."""

    def __init__(self, software, block):
        self.software, self.block, self.design = software, block, software.design

    def linear_update(self, dynamic=None):
        assert dynamic is None
        return self.software.linear_update(dynamic=self.block)


@pytest.mark.slow
def test_a_worst_case_is_confirmed_on_the_nonlinear_twin(setup):
    """Six to eight 45 s runs of the frozen mission: 77 s measured on the shared, loaded
    development machine (load average 15), the heavier part of it the runs."""
    controller, _, peak = setup
    row, histories = confirm_peak(peak, controller, load_scenario("paper"), ConfirmOptions())
    _assert_confirmed(row, histories)


def _assert_confirmed(row, histories):
    """The continuous boundary at 1; the Drake boundary and oscillation frequency those of the
    sampled-data loop to :data:`AGREEMENT`, with a decaying and a growing run around it."""
    assert row["alpha linear continuous [-]"] == pytest.approx(1.0, abs=1e-3)
    assert np.isfinite(row["alpha nonlinear [-]"])
    assert row["alpha nonlinear [-]"] == pytest.approx(
        row["alpha linear sampled [-]"], rel=AGREEMENT
    )
    assert row["oscillation frequency [Hz]"] == pytest.approx(
        row["frequency linear sampled [Hz]"], rel=AGREEMENT
    )
    assert row["decay rate below [1/s]"] < 0 < row["decay rate above [1/s]"]
    assert set(histories["side"]) == {"stable", "unstable"}


@pytest.mark.slow
def test_a_complex_block_worst_case_is_confirmed_on_the_nonlinear_twin(setup):
    """``Delta_add`` and ``Delta_mul`` (phase -90 deg) on the PD loop, realized on the twin
    (no real parameter): the Drake boundary against the sampled-data loop's. The interpolation
    frequency is moved twice to the continuous crossing (as a mu worst case sits there), the
    perturbation normalized to ``alpha = 1``. Six to eight 45 s runs: 42 s measured on the
    shared, loaded development machine (load average 12)."""
    controller, plant, _ = setup
    closed = close_loop(plant, controller.K, controller.spec)
    e_xx = np.zeros((3, 3))
    e_xx[0, 0] = 1.0
    direction = {"Delta_add": -10j * e_xx} | {
        f"Delta_mul_{a}{a}": np.array([[-10j]]) for a in "xyz"
    }
    omega = 2 * np.pi * 0.1
    for iteration in range(3):
        probe = Peak("mission", "total", TIME, np.nan, omega, 0.0, 0.0, direction)
        alpha = boundary_along_ray(
            lambda a, p=probe: _continuous_abscissa(closed, p, a)[0] > GROWTH_TOLERANCE,
            4.0,
            steps=40,
            rtol=1e-6,
        )
        assert 0.1 < alpha < 4.0
        crossing = _continuous_abscissa(closed, probe, alpha * (1 + 1e-6))[1]
        if iteration < 2:
            omega = crossing
    scaled = {n: alpha * v for n, v in direction.items()}
    peak = Peak("mission", "total", TIME, np.nan, omega, 1 / alpha, 1 / alpha, scaled)
    row, histories = confirm_peak(peak, controller, load_scenario("paper"), ConfirmOptions())
    assert row["nonlinear runs"] >= 3
    _assert_confirmed(row, histories)


def test_confirmation_windows_hold_one_connection_state(paper_scenario):
    from oos_drake.analysis.confirm import _mission_window
    from oos_drake.multibody.mission import make_mission_diagram
    from oos_drake.multibody.mission_sim import MissionSimulation

    sim = MissionSimulation(make_mission_diagram(scenario=paper_scenario))
    ramps = sim.schedule(sim.resolve(None)).ramp_intervals()
    for t in np.linspace(0.0, sim.duration, 61):
        start = _mission_window(sim, t, 45.0)
        assert 0.0 <= start and start + 45.0 <= sim.duration
        assert not any(start < b and a < start + 45.0 for a, b in ramps), (t, start)
        inside = [b for a, b in ramps if a <= t < b]
        if inside:  # a peak inside a ramp: simulated with the connection made
            assert start == inside[0] + 0.5


def test_a_docking_peak_runs_at_its_phase_with_the_peaks_stiffness():
    """The twin of a docking-8 peak: arm and arrays at the phase's configuration, SM2 at the
    peak's stiffness and the study's damping, SM1 at the rigid connection, held over the run."""
    from oos_drake.analysis.confirm import _Twin
    from oos_drake.analysis.models import phase_configuration

    scenario = load_scenario()
    stiffness = 3590.7
    peak = Peak("docking-8", "total", np.nan, stiffness, 5.0, 0.3, 0.3, {})
    K = np.zeros((3, 6))
    twin = _Twin(peak, K, ConfirmOptions(), scenario, np.nan, {}, None)
    docking = scenario.docking
    assert twin.start == 880.0
    holder = {}
    twin.sim.run(
        {},
        0,
        twin.start,
        twin.start + 1.0,
        log=False,
        noise_table=np.zeros((1, 9)),
        on_start=lambda context: holder.setdefault("context", context),
        bushings=twin.bushings,
    )
    h = twin.sim.handles
    pc = h.plant.GetMyContextFromRoot(holder["context"])
    expected = {
        "SM1": (docking.rigid_stiffness, docking.rigid_damping),
        "SM2": (stiffness, docking.damping),
    }
    for name, (k, d) in expected.items():
        bushing = h.bushings[name]
        np.testing.assert_allclose(bushing.GetForceStiffnessConstants(pc), [k] * 3)
        np.testing.assert_allclose(bushing.GetTorqueStiffnessConstants(pc), [k] * 3)
        np.testing.assert_allclose(bushing.GetForceDampingConstants(pc), [d] * 3)
        np.testing.assert_allclose(bushing.GetTorqueDampingConstants(pc), [d] * 3)
    alpha = phase_configuration("8", scenario).configuration.alpha
    angles = [joint.get_angle(pc) for joint in h.arm_joints]
    np.testing.assert_allclose(angles, alpha, atol=1e-6)
    # bad settings: one line naming the culprit
    with pytest.raises(ValueError, match="unknown bushing.*SM3"):
        twin.sim.run({}, 0, 880.0, 881.0, log=False, bushings={"SM3": (1.0, 1.0, 0.0, 0.0)})
    with pytest.raises(ValueError, match="bushing SM2 settings"):
        twin.sim.run({}, 0, 880.0, 881.0, log=False, bushings={"SM2": (-1.0, 1.0, 0.0, 0.0)})
    with pytest.raises(ValueError, match="must not contain the capture"):
        twin.sim.run({}, 0, 250.0, 260.0, log=False, bushings=twin.bushings)


def test_dynamic_perturbation_of_the_wrong_size_is_refused():
    design = FlightSoftwareDesign.create(np.zeros((3, 6)), 10.0)
    block = perturbation_block(design, 5.0, delta_mul=np.full((3, 3), 1j))
    fsw = FlightSoftware(design, 6, 6, 0, 0, perturbation_states=block.nstates + 1)
    with pytest.raises(ValueError, match=f"must be a {block.nstates + 1}-state 3 -> 9 block"):
        fsw.set_dynamic_perturbation(fsw.CreateDefaultContext(), block)
    with pytest.raises(ValueError, match="Delta_mul and Delta_add must be 3x3"):
        perturbation_block(design, 5.0, delta_add=np.ones((2, 2)))


@pytest.mark.parametrize("limit", [0.0, -1.0, float("nan")])
def test_confirm_rejects_a_search_limit_that_is_not_positive(limit):
    """``oos confirm --alpha-limit``: a limit <= 0 or NaN is one line naming the option."""
    with pytest.raises(ValueError, match="alpha_limit"):
        ConfirmOptions(alpha_limit=limit)
