"""``oos confirm`` on a schema-2 tree: the tree's own Drake twin with the worst parameters
written into its data, closed by the scenario's flight software (multibody/tree_twin.py)."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.analysis.confirm import (  # noqa: E402
    AGREEMENT,
    GROWTH_TOLERANCE,
    ConfirmOptions,
    Peak,
    _continuous_abscissa,
    _Twin,
    boundary_along_ray,
    confirm_peak,
    physical_alpha_max,
    ray_values,
)
from oos_drake.analysis.controller import Controller  # noqa: E402
from oos_drake.analysis.models import mission_plants  # noqa: E402
from oos_drake.control.analysis_model import close_loop  # noqa: E402
from oos_drake.control.baseline import baseline_gains  # noqa: E402
from oos_drake.control.components import DesignSpecification  # noqa: E402
from oos_drake.lfr import usubs  # noqa: E402
from oos_drake.multibody.cross_check import VALIDATION_OMEGA, compare_systems  # noqa: E402
from oos_drake.multibody.flight_software import FlightSoftware, FlightSoftwareDesign  # noqa: E402
from oos_drake.multibody.mission import effective_inertia  # noqa: E402
from oos_drake.multibody.tree_plant import build_tree_diagram, linearize_tree  # noqa: E402
from oos_drake.multibody.tree_twin import tree_with_values  # noqa: E402
from oos_drake.scenario.data import load_scenario  # noqa: E402
from oos_drake.scenario.tree import load_tree, parse_tree  # noqa: E402
from oos_drake.scenario.tree_model import (  # noqa: E402
    build_tree_model,
    rigid_inertia_at_root,
    tree_values,
)

#: In the second observation phase (arrays at 1.2 rad), as the analysis' peak of the measured
#: flexible_satellite run (t = 1026 s).
TIME = 1100.0
#: Both arrays' first modes down: the modal direction of the measured peak.
MODAL = {"w1_SA1": -1.0, "w1_SA2": -1.0}


def _mechanical_tree():
    """flexible_satellite with an uncertain hub mass and inertia (blocks m_HUB, J.._HUB)."""
    import tomllib

    from oos_drake.scenario.tree import tree_path

    with tree_path("flexible_satellite").open("rb") as stream:
        document = tomllib.load(stream)
    hub = document["bodies"][0]
    hub["mass_uncertainty_percent"] = 10.0
    hub["inertia_uncertainty_percent"] = [15.0, 15.0, 15.0]
    return parse_tree(document)


def test_tree_twin_with_the_worst_parameters_is_the_substituted_titop_lfr():
    """Masses, inertias and mode frequencies written into the tree's data, its SDF generated
    and parsed: the Drake linearization equals the TITOP LFR of the ORIGINAL tree with the
    same blocks substituted (a second model, not the substituted tree's own LFR)."""
    tree = _mechanical_tree()
    model = build_tree_model(tree)
    blocks = {n: b for n, b in model.uncertainty.items() if not n.startswith("tau_")}
    assert set(blocks) == {"m_HUB", "Jxx_HUB", "Jyy_HUB", "Jzz_HUB", "w1_SA1", "w1_SA2"}
    normalized = {"m_HUB": -0.8, "Jxx_HUB": 0.6, "Jyy_HUB": -0.9, "Jzz_HUB": 1.0}
    normalized |= {"w1_SA1": -0.95, "w1_SA2": 0.7}
    values = {n: float(blocks[n].to_physical(d)) for n, d in normalized.items()}
    angles = {"SA1": 1.0, "SA2": 0.45}
    substituted = tree_with_values(tree, values)
    assert substituted.body("HUB").mass == pytest.approx(300.0 * (1 - 0.08))
    assert substituted.body("SA1").frequencies_hz[0] == pytest.approx(0.5 * (1 - 0.19))
    assert tree.body("SA1").frequencies_hz[0] == 0.5  # the input tree is unchanged
    drake = linearize_tree(build_tree_diagram(substituted), angles)
    titop = usubs(model, values | tree_values(tree, angles)).nominal.to_ss()
    result = compare_systems("worst", drake, titop, VALIDATION_OMEGA)
    assert result.max_relative_error <= 1e-6, result
    assert result.pole_error <= 1e-6, result
    # and the nominal tree's twin differs (the substitution reached the twin)
    nominal = linearize_tree(build_tree_diagram(tree), angles)
    assert compare_systems("nominal", nominal, titop, VALIDATION_OMEGA).max_relative_error > 1e-3


def test_geo_satellite_twin_with_every_block_substituted_is_the_substituted_lfr():
    """Four appendages, one with three uncertain modes, hub mass and inertias: every block at
    a value drawn in its range, reflector booms and array drives at other angles."""
    tree = load_tree("geo_satellite")
    model = build_tree_model(tree)
    blocks = {n: b for n, b in model.uncertainty.items() if not n.startswith("tau_")}
    assert len(blocks) == 10
    rng = np.random.default_rng(30)
    values = {n: float(b.to_physical(rng.uniform(-1.0, 1.0))) for n, b in blocks.items()}
    angles = {name: 0.5 * a + 0.2 for name, a in tree.operating_angles().items()}
    drake = linearize_tree(build_tree_diagram(tree_with_values(tree, values)), angles)
    titop = usubs(model, values | tree_values(tree, angles)).nominal.to_ss()
    result = compare_systems("geo worst", drake, titop, VALIDATION_OMEGA)
    assert result.max_relative_error <= 1e-6, result


def test_tree_with_values_names_a_bad_block():
    tree = load_tree("flexible_satellite")
    for name in ("w4_SA1", "m_SA1", "Jxx_NOPE", "k_shear_DOCK"):
        with pytest.raises(ValueError, match=f"block {name}"):
            tree_with_values(tree, {name: 1.0})
    assert tree_with_values(tree, {}) is tree


@pytest.fixture(scope="module")
def setup():
    """A PD on the tree's rigid inertia (0.03 Hz, damping 0.7: at 0.1 Hz the 0.2 Hz roll-off
    makes it unstable) and a modal worst case normalized as the analysis saves one:
    ``alpha = 1`` is the continuous loop's stability boundary along ``MODAL`` (the mu of that
    real direction is exactly ``1 / alpha``)."""
    scenario = load_scenario("flexible_satellite")
    angles = scenario.timeline.angles(TIME)
    J = effective_inertia(rigid_inertia_at_root(scenario.tree, angles))
    K = baseline_gains(0.5 * (J + J.T), 2 * np.pi * 0.03, 0.7)
    spec = DesignSpecification.from_requirements(scenario.control)
    controller = Controller(K, spec, "test", "test PD")
    plant = mission_plants([TIME], scenario).model(0)
    closed = close_loop(plant, K, spec)
    probe = Peak("mission", "modal", TIME, np.nan, 1.0, 0.0, 0.0, MODAL)
    alpha = boundary_along_ray(
        lambda a: _continuous_abscissa(closed, probe, a)[0] > GROWTH_TOLERANCE,
        4.9,
        steps=49,
        rtol=1e-7,
    )
    assert 1.0 < alpha < 4.9  # a destabilizing modal perturbation, short of zero frequency
    omega = _continuous_abscissa(closed, probe, alpha * (1 + 1e-6))[1]
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
    return scenario, controller, closed, peak, angles


def _drake_sampled_growth(scenario, controller, peak, angles, alpha):
    """Growth rate [1/s] and frequency [Hz] of the exact sampled-data loop built from the
    DRAKE linearization of the substituted tree (not the TITOP LFR the module uses): the plant
    ``T -> wdot`` integrated twice, a zero-order hold, the flight software's linear update."""
    specs = build_tree_model(scenario.tree).uncertainty
    values = ray_values(specs, dict(peak.perturbation), alpha)
    lin = linearize_tree(build_tree_diagram(tree_with_values(scenario.tree, values)), angles)
    A, B, C, D = lin.A, lin.B[:, 3:6], lin.C[3:6], lin.D[3:6, 3:6]
    n = A.shape[0]
    # states [x; w; phi]: w' = C x + D T, phi' = w (small angles)
    Aa = np.zeros((n + 6, n + 6))
    Aa[:n, :n], Aa[n : n + 3, :n], Aa[n + 3 :, n : n + 3] = A, C, np.eye(3)
    Ba = np.vstack([B, D, np.zeros((3, 3))])
    design = FlightSoftwareDesign.create(
        controller.K,
        scenario.control.flight_software_rate_hz,
        spec=controller.spec,
        torque_limit=scenario.control.torque_limit,
    )
    dt = design.period
    E = scipy.linalg.expm(np.block([[Aa, Ba], [np.zeros((3, n + 9))]]) * dt)
    Ad, Bd = E[: n + 6, : n + 6], E[: n + 6, n + 6 :]
    Cm = np.zeros((6, n + 6))
    Cm[:3, n + 3 :], Cm[3:, n : n + 3] = np.eye(3), np.eye(3)  # [phi; w]
    f = FlightSoftware(design, 6, 6, 0, 0).linear_update()
    closed = np.block([[Ad + Bd @ f.D @ Cm, Bd @ f.C], [f.B @ Cm, f.A]])
    z = np.linalg.eigvals(closed)
    k = np.argmax(np.abs(z))
    return np.log(np.abs(z[k])) / dt, abs(np.angle(z[k])) / (2 * np.pi * dt)


def test_tree_twin_verdicts_match_the_eigenvalues_of_the_drake_sampled_loop(setup):
    """Below the certified bound (alpha = 0.9: a perturbation smaller than 1 / mu) the twin
    decays; beyond the sampled-data boundary it grows at the loop's frequency. Both verdicts
    and the frequency against the eigenvalues of a closed loop built here from the Drake
    linearization with the same parameters."""
    scenario, controller, closed, peak, angles = setup
    growth_lo, _ = _drake_sampled_growth(scenario, controller, peak, angles, 0.9)
    assert growth_lo < -GROWTH_TOLERANCE
    specs = closed.uncertainty
    # the sampled boundary by eigenvalues (Drake plant), then 5 % beyond it
    alpha_s = boundary_along_ray(
        lambda a: (
            _drake_sampled_growth(scenario, controller, peak, angles, a)[0] > GROWTH_TOLERANCE
        ),
        2.0,
        steps=8,
        rtol=1e-3,
    )
    assert 0.9 < alpha_s < 1.5
    alpha_hi = 1.05 * alpha_s
    growth_hi, f_hi = _drake_sampled_growth(scenario, controller, peak, angles, alpha_hi)
    assert growth_hi > GROWTH_TOLERANCE
    limit, _ = physical_alpha_max(specs, dict(peak.perturbation), alpha_limit=4.0)
    assert alpha_hi < limit
    options = dataclasses.replace(ConfirmOptions(), duration=60.0, settle=10.0)
    design = FlightSoftwareDesign.create(
        controller.K,
        scenario.control.flight_software_rate_hz,
        spec=controller.spec,
        torque_limit=scenario.control.torque_limit,
    )
    twin = _Twin(peak, controller.K, options, scenario, f_hi, specs, design)
    stable_side = twin.run(0.9)
    unstable_side = twin.run(alpha_hi)
    assert not stable_side[0] and unstable_side[0]
    assert stable_side[1] is None or stable_side[1].decay_rate < 0
    oscillation = unstable_side[1]
    assert oscillation is not None
    assert oscillation.decay_rate == pytest.approx(growth_hi, rel=0.25)
    assert oscillation.frequency == pytest.approx(f_hi, rel=AGREEMENT)


@pytest.mark.slow
def test_a_tree_worst_case_is_confirmed_on_its_twin(setup):
    """confirm_peak end to end on flexible_satellite (six to eight 45 s runs of the tree twin):
    the continuous boundary at 1, the twin's boundary and oscillation those of the sampled-data
    loop to :data:`AGREEMENT`."""
    scenario, controller, _, peak, _ = setup
    row, histories = confirm_peak(peak, controller, scenario, ConfirmOptions())
    assert row["alpha linear continuous [-]"] == pytest.approx(1.0, abs=1e-3)
    assert row["alpha nonlinear [-]"] == pytest.approx(
        row["alpha linear sampled [-]"], rel=AGREEMENT
    )
    assert row["oscillation frequency [Hz]"] == pytest.approx(
        row["frequency linear sampled [Hz]"], rel=AGREEMENT
    )
    assert row["decay rate below [1/s]"] < 0 < row["decay rate above [1/s]"]
    assert row["status"].startswith("confirmed")
    assert set(histories["side"]) == {"stable", "unstable"}
