"""The full mission LFR and the docking-phase LFRs against independent references."""

import numpy as np
import pytest

from oos_drake.lfr import usubs
from oos_drake.scenario.kinematics import rigid_spatial_inertia_at_G1, waypoint_ik
from oos_drake.scenario.model import (
    PAPER_OCCURRENCES,
    attitude_model,
    build_docking_model,
    build_mission_model,
    configuration_values,
    delta_block_table,
    mission_values,
)
from oos_drake.scenario.timeline import Configuration, mission_timeline


@pytest.fixture(scope="module")
def timeline(paper_scenario):
    return mission_timeline(paper_scenario)


@pytest.fixture(scope="module")
def model(timeline):
    return build_mission_model(timeline.scenario)


def sorted_roots(roots):
    """Roots ordered by rounded imaginary part, then real part (stable for repeated roots)."""
    roots = np.asarray(roots)
    return roots[np.lexsort((roots.real.round(6), roots.imag.round(6)))]


def static_gain(system):
    return system.freqresp(np.array([0.0]))[..., 0, :, :].real


def test_blocks_and_occurrences_are_the_papers(model):
    assert model.shape == (6, 6)
    assert model.nstates == 48  # 4 arrays x 6 modes x 2
    assert model.occurrences == PAPER_OCCURRENCES
    # Delta_P size: 4*2 + 4*16 + 6*16 + 12 + 12 + (3 + 1 + 1 + 1 + 4 + 4)
    assert model.nz == model.nw == 8 + 64 + 96 + 24 + 14
    table = delta_block_table(model)
    assert list(table["occurrences"]) == list(table["paper_occurrences"])


def test_low_frequency_is_inverse_rigid_inertia_at_the_six_moments(model, timeline):
    for name, moment in timeline.moments.items():
        config = moment.configuration
        gain = static_gain(usubs(model, config.parameters()).nominal)
        reference = rigid_spatial_inertia_at_G1(timeline.scenario, config)
        np.testing.assert_allclose(
            gain @ reference, np.eye(6), atol=1e-10, err_msg=f"moment {name}"
        )


def test_vectorized_substitution_matches_single_models(model, timeline):
    times = np.array([100.0, 400.0, 1300.0])
    batch = usubs(model, mission_values(times, timeline.scenario)).nominal
    assert batch.batch_shape == (3,)
    omega = np.array([0.5, 8.0])
    response = batch.freqresp(omega)
    for k, t in enumerate(times):
        single = usubs(model, timeline.configuration(t).parameters()).nominal
        np.testing.assert_allclose(response[k], single.freqresp(omega), rtol=1e-10, atol=1e-14)


def test_antiresonances_are_the_cantilevered_array_modes(model, timeline):
    # target docked at the hub: all four arrays are attached to the system
    config = timeline.moments["5"].configuration
    ss = usubs(model, config.parameters()).nominal.to_ss()
    zeros = np.linalg.eigvals(ss.A - ss.B @ np.linalg.solve(ss.D, ss.C))
    expected = []
    for mount in timeline.scenario.arrays.values():
        w = np.asarray(mount.model.omega)
        xi = np.asarray(mount.model.damping_ratios)
        expected += list(-xi * w + 1j * w * np.sqrt(1 - xi**2))
        expected += list(-xi * w - 1j * w * np.sqrt(1 - xi**2))
    np.testing.assert_allclose(sorted_roots(zeros), sorted_roots(expected), rtol=1e-7)
    # paper Fig. sigma_plot: T_ext{1} -> wdot{1} has anti-resonances (local minima) next to
    # 0.6493 Hz (target arrays) and 1.285 Hz (chaser arrays) while the target is held by the arm
    # and the chaser arrays are at theta = 0 (moment 3); SISO minima are only near the MIMO zeros
    config = timeline.moments["3"].configuration
    hz = np.linspace(0.3, 2.0, 3401)
    gain = np.abs(usubs(model, config.parameters()).nominal.freqresp(2 * np.pi * hz)[:, 3, 3])
    minima = hz[1:-1][(gain[1:-1] < gain[:-2]) & (gain[1:-1] < gain[2:])]
    for f in (0.6493, 1.2850):
        assert np.min(np.abs(minima - f)) < 0.01 * f, (f, minima)


def test_uncertain_mode_frequency_moves_the_antiresonance(model, timeline):
    config = timeline.moments["1"].configuration
    values = dict(config.parameters())
    w1 = float(timeline.scenario.array_models["SA1_2"].omega[0])
    values.update({"w1_SA1": 1.1 * w1, "w1_SA2": 1.1 * w1})
    ss = usubs(model, values).nominal.to_ss()
    zeros = np.linalg.eigvals(ss.A - ss.B @ np.linalg.solve(ss.D, ss.C))
    assert np.min(np.abs(np.abs(zeros) - 1.1 * w1)) < 1e-6 * w1


def test_attitude_model_is_double_integral(model, timeline):
    config = timeline.moments["2"].configuration
    fixed = usubs(model, config.parameters()).nominal
    phi = attitude_model(fixed)
    assert phi.shape == (3, 6)
    omega = np.array([0.3, 3.0])
    np.testing.assert_allclose(
        phi.freqresp(omega),
        fixed.freqresp(omega)[:, 3:, :] / (1j * omega[:, None, None]) ** 2,
        rtol=1e-10,
    )


def test_configuration_values_validation():
    with pytest.raises(ValueError, match="alpha must have 6 columns"):
        configuration_values(np.zeros(5), np.zeros(4), 0.0, 0.0)
    with pytest.raises(ValueError, match="delta_C1 must be in"):
        configuration_values(np.zeros(6), np.zeros(4), 2.0, 0.0)


def spring_values(sm, stiffness, damping):
    return {
        f"k_shear_{sm}": stiffness,
        f"k_tors_{sm}": stiffness,
        f"d_shear_{sm}": damping,
        f"d_tors_{sm}": damping,
    }


def test_docking_phase_7_stiff_spring_is_the_rigid_grasp(timeline):
    model7 = build_docking_model("7", timeline.scenario)
    assert {k: model7.occurrences[k] for k in ("k_shear_SM1", "d_tors_SM1")} == {
        "k_shear_SM1": 3,
        "d_tors_SM1": 3,
    }
    assert "delta_C1" not in model7.occurrences
    config = timeline.docking_phases["7"].configuration  # arm holds the target (delta_C1 = 1)
    values = {k: v for k, v in config.parameters().items() if k in model7.occurrences}
    values.update(spring_values("SM1", 1e5, 100.0))
    fixed = usubs(model7, values).nominal
    low = fixed.freqresp(np.array([1e-5]))[0].real
    reference = rigid_spatial_inertia_at_G1(timeline.scenario, config)
    np.testing.assert_allclose(low @ reference, np.eye(6), atol=1e-6)


def test_docking_phase_8_closed_loop_is_rigid_at_low_frequency(timeline):
    model8 = build_docking_model("8", timeline.scenario)
    alpha = waypoint_ik(timeline.scenario, "docked").alpha  # closes J7 = D2 while D3 = D1
    config = Configuration.from_angles(
        alpha, delta_C1=0.0, delta_C2=1.0, time=timeline.scenario.mission.second_docking_time
    )
    values = {k: v for k, v in config.parameters().items() if k in model8.occurrences}
    values.update(spring_values("SM1", 1e5, 100.0))
    values.update(spring_values("SM2", 1e5, 100.0))
    fixed = usubs(model8, values).nominal
    low = fixed.freqresp(np.array([1e-5]))[0].real
    reference = rigid_spatial_inertia_at_G1(timeline.scenario, config)
    np.testing.assert_allclose(low @ reference, np.eye(6), atol=1e-6)


def test_docking_phase_name_is_checked(paper_scenario):
    with pytest.raises(ValueError, match="phase must be '7' or '8'"):
        build_docking_model("9", paper_scenario)


def test_paper_delta_table_sizes(model, paper_scenario):
    from oos_drake.scenario.model import paper_delta_table

    table = paper_delta_table(model).set_index("sub_block")["size"]
    assert table["Delta_RA"] == 96 and table["Delta_RH2"] == 14 and table["Delta_P"] == 206
    with pytest.raises(ValueError, match="occurrences .* differ"):
        paper_delta_table(build_docking_model("7", paper_scenario))


def test_well_posed_and_stable_over_the_mission_and_the_parameter_box(model, paper_scenario):
    from oos_drake.lfr import usample

    along = usubs(model, mission_values(np.linspace(0.0, 1500.0, 61), paper_scenario)).nominal
    n = along.nstates
    assert np.linalg.eigvals(along.M[..., :n, :n]).real.max() < 0
    # every block (switches included) drawn in its range: the loops stay well posed, modes damped
    box, _ = usample(model, 20, np.random.default_rng(7))
    assert np.linalg.eigvals(box.M[..., :n, :n]).real.max() < 0
    assert np.all(np.isfinite(box.freqresp(np.array([0.0, 4.0]))))


def test_every_block_of_the_mission_and_docking_models_has_a_unit_and_quantity(paper_scenario):
    """Units and quantities are set where the blocks are created (TITOP / scenario helpers)."""
    from oos_drake.lfr.blocks import QUANTITIES
    from oos_drake.scenario.model import build_docking_model, build_mission_model, physical_blocks

    expected = {
        "m_RH2": ("kg", "mass"),
        "Jxx_RH2": ("kg m^2", "inertia"),
        "w1_SA3": ("rad/s", "modal frequency"),
        "tau_alpha2": ("-", "angle"),
        "tau_theta1": ("-", "angle"),
        "delta_C1": ("-", "switch"),
        "k_shear_SM1": ("N/m", "stiffness"),
        "k_tors_SM2": ("N m/rad", "stiffness"),
        "d_shear_SM2": ("N s/m", "damping"),
        "d_tors_SM1": ("N m s/rad", "damping"),
    }
    mission = build_mission_model(paper_scenario).uncertainty
    blocks = {**mission, **build_docking_model("8", paper_scenario).uncertainty}
    for block in blocks.values():
        assert block.unit and block.quantity in QUANTITIES, block.describe()
    for name, facts in expected.items():
        assert (blocks[name].unit, blocks[name].quantity) == facts, name
    # physical_blocks: the same specs as the models, scheduled blocks left out
    physical = physical_blocks(paper_scenario)
    assert set(physical) == {n for n, b in blocks.items() if b.quantity not in ("angle", "switch")}
    for name, block in physical.items():
        if name in mission:
            assert block == mission[name]
