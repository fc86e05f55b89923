"""``oos confirm`` of a tree's docking peaks (issue 30): the tree's twin frozen at the docking
event's configuration, the target on its floating joint held by one bushing per spring-damper
(the swept one at the peak's stiffness, the study's damping), the real parameters along the
peak's ray written into the tree's data and into the bushings.

The tree is written here (tests/tree/test_tree_docking.py's: hub, one flexible array, a rigid
target docked to the hub by a spring-damper with uncertain damping), with a low-bandwidth PD
and a worst direction normalized as the analysis saves one (``alpha = 1`` on the continuous
loop, found here by eigenvalues of the study's closed loop)."""

import dataclasses

import numpy as np
import pytest
import tomli_w
from test_tree_docking import docking_document

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.analysis.confirm import (  # noqa: E402
    AGREEMENT,
    GROWTH_TOLERANCE,
    ConfirmOptions,
    Peak,
    _continuous_abscissa,
    _peak_models,
    _Twin,
    boundary_along_ray,
    confirm_peak,
    confirm_peaks,
)
from oos_drake.analysis.controller import Controller  # noqa: E402
from oos_drake.control.baseline import baseline_gains  # noqa: E402
from oos_drake.control.components import DesignSpecification  # noqa: E402
from oos_drake.multibody.flight_software import FlightSoftwareDesign  # noqa: E402
from oos_drake.multibody.mission import effective_inertia  # noqa: E402
from oos_drake.scenario.data import load_scenario  # noqa: E402
from oos_drake.scenario.tree_model import rigid_inertia_at_root  # noqa: E402

#: Swept stiffness of the peak [N/m = N m/rad].
STIFFNESS = 3.0e3
#: The array's first mode down, the target heavier, the docking damping down: a modal worst
#: direction that also moves the target's mass and both bushing coefficients.
DIRECTION = {"w1_SA1": -1.0, "m_CLIENT": 1.0, "d_shear_DOCK": -1.0, "d_tors_DOCK": -1.0}


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """The tree, a 0.03 Hz PD on the chaser's rigid inertia at the event, and the docking
    peak along :data:`DIRECTION` normalized so that the continuous loop's boundary is at 1."""
    path = tmp_path_factory.mktemp("docking") / "docking_pair.toml"
    path.write_text(tomli_w.dumps(docking_document()))
    scenario = load_scenario(path)
    (event,) = scenario.mission.docking_phases
    angles = scenario.timeline.angles(event.time)
    J = effective_inertia(rigid_inertia_at_root(scenario.tree, angles))
    K = baseline_gains(0.5 * (J + J.T), 2 * np.pi * 0.03, 0.7)
    spec = DesignSpecification.from_requirements(scenario.control)
    controller = Controller(K, spec, "test", "test PD")
    study = f"docking-{event.name}"
    probe = Peak(study, "total", np.nan, STIFFNESS, 1.0, 0.0, 0.0, DIRECTION)
    closed, _ = _peak_models(probe, controller, scenario)
    alpha = boundary_along_ray(
        lambda a: _continuous_abscissa(closed, probe, a)[0] > GROWTH_TOLERANCE,
        4.0,
        steps=40,
        rtol=1e-7,
    )
    assert 1.0 < alpha < 4.0
    omega = _continuous_abscissa(closed, probe, alpha * (1 + 1e-6))[1]
    perturbation = {n: alpha * d for n, d in DIRECTION.items()}
    peak = Peak(study, "total", np.nan, STIFFNESS, omega, 1 / alpha, 1 / alpha, perturbation)
    return scenario, controller, closed, peak, event


def test_the_docking_twin_holds_the_target_on_the_peaks_bushing(setup):
    """At alpha = 0.5 along the ray: the twin's bushing has the peak's stiffness and the
    damping the ray gives (file value times 1 - 0.2 alpha |d|), the target's mass the ray's
    (80 kg times 1 + 0.15 alpha d), the array's drive at the event's angle, and the target at
    rest where the ports coincide (the port frames coincide at the run's start)."""
    scenario, controller, closed, peak, event = setup
    design = FlightSoftwareDesign.create(
        controller.K, scenario.control.flight_software_rate_hz, spec=controller.spec
    )
    twin = _Twin(peak, controller.K, ConfirmOptions(), scenario, np.nan, closed.uncertainty, design)
    assert twin.mating is None and twin.angles["SA1"] == pytest.approx(0.8)
    handles = twin.twin(0.5)
    context = handles.diagram.CreateDefaultContext()
    pc = handles.plant.GetMyContextFromRoot(context)
    bushing = handles.bushings["DOCK"]
    scale = 0.5 * peak.perturbation["d_shear_DOCK"]
    np.testing.assert_allclose(bushing.GetForceStiffnessConstants(pc), [STIFFNESS] * 3)
    np.testing.assert_allclose(bushing.GetTorqueStiffnessConstants(pc), [STIFFNESS] * 3)
    np.testing.assert_allclose(
        bushing.GetForceDampingConstants(pc), [150.0 * (1 + 0.2 * scale)] * 3, rtol=1e-12
    )
    np.testing.assert_allclose(
        bushing.GetTorqueDampingConstants(pc), [40.0 * (1 + 0.2 * scale)] * 3, rtol=1e-12
    )
    client = handles.plant.GetBodyByName("CLIENT")
    mass = 80.0 * (1 + 0.15 * 0.5 * peak.perturbation["m_CLIENT"])
    assert client.get_mass(pc) == pytest.approx(mass, rel=1e-12)
    # the ports coincide at the event's angle with the target's joint at zero: at rest
    pc = handles.plant.GetMyMutableContextFromRoot(context)
    handles.revolute_joints["SA1"].set_angle(pc, twin.angles["SA1"])
    dock = handles.plant.GetFrameByName("DOCK")
    ring = handles.plant.GetFrameByName("C_RING")
    X = ring.CalcPose(pc, dock)
    np.testing.assert_allclose(X.GetAsMatrix4(), np.eye(4), atol=1e-12)


def test_a_trees_docking_peak_is_confirmed_on_its_twin(setup):
    """confirm_peak end to end on the docking peak (six 40 s runs of a small twin, a few
    seconds): the continuous boundary
    at 1, the twin's boundary and oscillation frequency those of the sampled-data loop to
    :data:`AGREEMENT` (as the schema-1 docking confirmations), a decaying run below and a
    growing one above."""
    scenario, controller, _, peak, _ = setup
    options = dataclasses.replace(ConfirmOptions(), duration=40.0, settle=8.0)
    row, histories = confirm_peak(peak, controller, scenario, options)
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


def test_a_closed_loop_docking_peak_holds_the_target_on_both_spring_dampers(tmp_path):
    """The converted paper's second docking event (schema 1's phase 8: SM2 docks D1-D3 while
    SM1 holds J7-D2): the twin of its peak has two bushings on the target, SM2 at the peak's
    stiffness and the file's damping, SM1 at the file's rigid values (schema 1's
    ``docking_springs``), the arm frozen at the event's configuration (schema 1's phase-8
    angles), both pairs of port frames coinciding at rest."""
    from oos_drake.analysis.models import docking_springs, phase_configuration
    from oos_drake.scenario.tree_migration import tree_document_from_v1

    path = tmp_path / "paper_tree.toml"
    path.write_text(tomli_w.dumps(tree_document_from_v1("paper")[0]))
    converted, paper = load_scenario(path), load_scenario("paper")
    event = converted.mission.docking_phases[1]
    stiffness = 3590.7
    peak = Peak(f"docking-{event.name}", "total", np.nan, stiffness, 5.0, 0.3, 0.3, {})
    design = FlightSoftwareDesign.create(np.zeros((3, 6)), 10.0)
    twin = _Twin(peak, None, ConfirmOptions(), converted, np.nan, {}, design)
    handles = twin.twin(1.0)
    context = handles.diagram.CreateDefaultContext()
    pc = handles.plant.GetMyMutableContextFromRoot(context)
    expected = docking_springs("8", stiffness, scenario=paper)
    assert sorted(handles.bushings) == sorted(expected) == ["SM1", "SM2"]
    for name, (k, d) in expected.items():
        bushing = handles.bushings[name]
        np.testing.assert_allclose(bushing.GetForceStiffnessConstants(pc), [k] * 3)
        np.testing.assert_allclose(bushing.GetTorqueStiffnessConstants(pc), [k] * 3)
        np.testing.assert_allclose(bushing.GetForceDampingConstants(pc), [d] * 3)
        np.testing.assert_allclose(bushing.GetTorqueDampingConstants(pc), [d] * 3)
    alpha = phase_configuration("8", paper).configuration.alpha
    arm = [twin.angles[f"L{i}"] for i in range(1, 7)]
    np.testing.assert_allclose(arm, alpha, atol=1e-9)
    for name, joint in handles.revolute_joints.items():
        joint.set_angle(pc, twin.angles[name])
    for joint, angle in handles.held_joints.items():
        joint.set_angle(pc, angle)
    plant = handles.plant
    for port, target_port in (("J7", "D2"), ("D1", "D3")):
        X = plant.GetFrameByName(target_port).CalcPose(pc, plant.GetFrameByName(port))
        np.testing.assert_allclose(X.GetAsMatrix4(), np.eye(4), atol=1e-9)


def test_confirm_peaks_keeps_a_trees_docking_peaks(setup, monkeypatch):
    """``confirm_peaks`` on a tree sends its docking peaks to the twin (none left out): one
    row per peak, each with its own study."""
    import oos_drake.analysis.confirm as confirm

    scenario, controller, _, peak, _ = setup
    seen = []

    def fake(peak, controller, scenario, options):
        seen.append(peak.study)
        return {"study": peak.study, "subset": peak.subset}, confirm.pd.DataFrame()

    monkeypatch.setattr(confirm, "confirm_peak", fake)
    mission = dataclasses.replace(peak, study="mission", time=100.0, perturbation={})
    table, _ = confirm_peaks([mission, peak], controller, scenario, ConfirmOptions(), quiet=True)
    assert list(table["study"]) == ["mission", peak.study] == seen
