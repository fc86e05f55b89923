"""The Drake twin of a tree whose mission captures and docks a target (``oos confirm`` and the
campaign on ``servicer_7dof``): the target welded where the mission model welds it.

- the twin's plant (built by ``tree_twin``: the target's own SDF welded by Drake's
  ``WeldFrames``), linearized by Drake, against the switched TITOP LFR of the mission
  (``build_mission_tree_model``, switch blocks substituted by the pipeline's ``mission_values``)
  with the uncertain blocks, the target's included, at values drawn in their ranges;
- the confirmation's twin at a captured instant against a twin built from another data path
  (``captured_tree``: the target hung on the grasp body by a fixed joint in ONE SDF);
- the campaign's dispersions against the ranges read from the TOML itself;
- the twin's joint trajectory against the timeline (three interpolations), the joints'
  tracking through a capture, and a run cut at a phase boundary against the run in one piece.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import tomli_w
from tree_documents import shipped_document

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.campaign.simulator import MissionWindow, ParameterKind, RunCase  # noqa: E402
from oos_drake.campaign.tree_simulator import make_simulator  # noqa: E402
from oos_drake.control.baseline import baseline_gains  # noqa: E402
from oos_drake.control.components import DesignSpecification  # noqa: E402
from oos_drake.lfr import usubs  # noqa: E402
from oos_drake.multibody.cross_check import VALIDATION_OMEGA, compare_systems  # noqa: E402
from oos_drake.multibody.flight_software import FlightSoftwareDesign  # noqa: E402
from oos_drake.multibody.mission import effective_inertia  # noqa: E402
from oos_drake.multibody.tree_plant import linearize_tree  # noqa: E402
from oos_drake.multibody.tree_twin import (  # noqa: E402
    build_tree_twin,
    joint_trajectory,
    mating_at,
    mating_segments,
    open_loop_twin,
    run_mission_twin,
    run_tree_twin,
    tree_with_values,
)
from oos_drake.scenario.data import load_scenario  # noqa: E402
from oos_drake.scenario.tree import captured_tree  # noqa: E402
from oos_drake.scenario.tree_model import rigid_inertia_at_root  # noqa: E402

#: servicer_7dof: stow 0-300 s, approach 300-700 s, grasp_hold 700-900 s (GRASP on T_GRASP),
#: berthed 900-1200 s (T_DOCK on DOCK, welded rigid in the mission model)
ARM_ANGLES = {"A1": 0.2, "A2": 0.9, "A3": -0.3, "A4": -1.4, "A5": 0.4, "A6": 0.8, "A7": -0.5}
TARGET_MASS_PERCENT = 10.0
TARGET_INERTIA_PERCENT = [20.0, 15.0, 25.0]


def _servicer_document(interpolation: str = "smooth") -> dict:
    """servicer_7dof, its tip waypoint replaced by fixed arm angles (no inverse kinematics
    needed), the target's mass and inertia declared uncertain."""
    document = shipped_document("servicer_7dof")
    approach = document["mission"]["phases"][1]
    del approach["tip"]
    approach["joints"].update(ARM_ANGLES)
    document["mission"]["interpolation"] = interpolation
    target = next(b for b in document["bodies"] if b["name"] == "TGT")
    target["mass_uncertainty_percent"] = TARGET_MASS_PERCENT
    target["inertia_uncertainty_percent"] = TARGET_INERTIA_PERCENT
    return document


def _write(tmp_path_factory, document, name="servicer_joints.toml"):
    path = tmp_path_factory.mktemp("mated") / name
    path.write_text(tomli_w.dumps(document))
    return path


@pytest.fixture(scope="module")
def servicer_file(tmp_path_factory):
    return _write(tmp_path_factory, _servicer_document())


@pytest.fixture(scope="module")
def servicer(servicer_file):
    return load_scenario(servicer_file)


@pytest.fixture(scope="module")
def simulator(servicer_file):
    return make_simulator(scenario=str(servicer_file))


def test_matings_follow_the_phases(servicer):
    timeline = servicer.timeline
    assert mating_at(timeline, 150.0) is None
    assert mating_at(timeline, 700.0) is None  # a boundary belongs to the phase ending there
    assert mating_at(timeline, 800.0) == ("GRASP", "T_GRASP")
    assert mating_at(timeline, 900.0) == ("GRASP", "T_GRASP")
    assert mating_at(timeline, 1050.0) == ("DOCK", "T_DOCK")
    assert mating_segments(timeline, 650.0, 950.0) == (
        (650.0, 700.0, None),
        (700.0, 900.0, ("GRASP", "T_GRASP")),
        (900.0, 950.0, ("DOCK", "T_DOCK")),
    )
    assert mating_segments(timeline, 100.0, 600.0) == ((100.0, 600.0, None),)


@pytest.mark.parametrize("time", [150.0, 500.0, 800.0, 1050.0])
def test_twin_linearized_is_the_switched_titop_lfr(servicer, time):
    """Free (stow, approach), captured (grasp_hold) and docked (berthed, welded rigid): the
    twin's plant with every uncertain block at a value drawn in its range (the target's mass
    and inertia written into the welded target's own SDF) against the mission LFR with the same
    blocks and the pipeline's switch values."""
    model = servicer.mission_model()
    blocks = {n: b for n, b in model.uncertainty.items() if b.quantity not in ("angle", "switch")}
    assert set(blocks) == {"w1_SA1", "w1_SA2", "m_TGT", "Jxx_TGT", "Jyy_TGT", "Jzz_TGT"}
    rng = np.random.default_rng(int(time))
    values = {n: float(b.to_physical(rng.uniform(-1.0, 1.0))) for n, b in blocks.items()}
    scheduled = {n: float(v[0]) for n, v in servicer.mission_values([time]).items()}
    titop = usubs(model, values | scheduled).nominal.to_ss()
    mating = mating_at(servicer.timeline, time)
    handles = open_loop_twin(tree_with_values(servicer.tree, values), mating)
    drake = linearize_tree(handles, servicer.timeline.angles(time))
    result = compare_systems(f"t = {time}", drake, titop, VALIDATION_OMEGA)
    assert result.max_relative_error <= 1e-6, result
    assert result.pole_error <= 1e-6, result
    if mating is not None:  # the target's blocks reached the welded twin
        nominal = linearize_tree(open_loop_twin(servicer.tree, mating), handles.tree.joint_angles(
            servicer.timeline.angles(time)))  # fmt: skip
        assert (
            compare_systems("nominal", nominal, titop, VALIDATION_OMEGA).max_relative_error > 1e-3
        )


def test_confirmation_twin_at_a_capture_is_the_target_hung_on_a_fixed_joint(servicer):
    """The confirmation's twin at a captured instant (``_TreeTwin``: frozen joints, the
    target welded by Drake) and a twin of ``captured_tree`` (the target one more body of the
    tree on a fixed joint at the pose of its closed form, one SDF): same attitude history;
    the free tree's twin differs (the weld reached the twin)."""
    from oos_drake.analysis.confirm import ConfirmOptions, Peak, _Twin
    from oos_drake.analysis.controller import Controller

    time = 800.0
    timeline = servicer.timeline
    angles = timeline.angles(time)
    welded = captured_tree(servicer.tree, "GRASP", "T_GRASP")
    J = effective_inertia(rigid_inertia_at_root(welded, angles))
    K = baseline_gains(0.5 * (J + J.T), 2 * np.pi * 0.02, 0.7)
    spec = DesignSpecification.from_requirements(servicer.control)
    design = FlightSoftwareDesign.create(
        K,
        servicer.control.flight_software_rate_hz,
        spec=spec,
        torque_limit=servicer.control.torque_limit,
    )
    peak = Peak("mission", "modal", time, np.nan, 1.0, 0.5, 0.5, {"w1_SA1": -1.0})
    specs = servicer.mission_model().uncertainty
    options = ConfirmOptions()
    twin = _Twin(peak, Controller(K, spec, "test", "PD"), options, servicer, 0.1, specs, design)
    confirmed = twin.twin(0.5)
    assert confirmed.mating == ("GRASP", "T_GRASP")
    run = run_tree_twin(confirmed, 30.0, initial_attitude=1e-3, max_step=design.period)
    w1 = float(specs["w1_SA1"].to_physical(-0.5))
    other = build_tree_twin(
        tree_with_values(welded, {"w1_SA1": w1}),
        design,
        angles,
        log_rate=run_log_rate(design),
    )
    reference = run_tree_twin(other, 30.0, initial_attitude=1e-3, max_step=design.period)
    np.testing.assert_allclose(run.times, reference.times)
    assert np.abs(run.phi - reference.phi).max() <= 1e-7 * np.abs(reference.phi).max()
    free = build_tree_twin(
        tree_with_values(servicer.tree, {"w1_SA1": w1}),
        design,
        angles,
        log_rate=run_log_rate(design),
    )
    loose = run_tree_twin(free, 30.0, initial_attitude=1e-3, max_step=design.period)
    assert np.abs(loose.phi - reference.phi).max() > 1e-2 * np.abs(reference.phi).max()


def run_log_rate(design) -> float:
    """The confirmation's logging rate for ``design`` (its module's choice)."""
    from oos_drake.analysis.confirm import CONFIRM_LOG_RATE_HZ
    from oos_drake.multibody.mission import logging_rate

    return logging_rate(1.0 / design.period, CONFIRM_LOG_RATE_HZ)


def test_campaign_dispersions_are_the_scenarios_ranges(simulator, servicer_file):
    """Every uncertain quantity of the file (read from the TOML here: the arrays' first modes
    in percent, the target's mass and inertia diagonal in percent) is a parameter whose default
    dispersion is its declared range; no scheduled block (joint angle, switch) is one."""
    import tomllib

    document = tomllib.loads(servicer_file.read_text())
    expected = {}
    for body in document["bodies"]:
        for mode, entry in body.get("uncertainty", {}).items():
            f = 2 * math.pi * body["frequencies_hz"][int(mode[1:]) - 1]
            p = entry["percent"] / 100.0
            expected[f"{mode}_{body['name']}"] = (f * (1 - p), f * (1 + p))
        if "mass_uncertainty_percent" in body:
            m, p = body["mass"], body["mass_uncertainty_percent"] / 100.0
            expected[f"m_{body['name']}"] = (m * (1 - p), m * (1 + p))
        for k, axis in enumerate(("Jxx", "Jyy", "Jzz")):
            if "inertia_uncertainty_percent" in body:
                j = body["inertia"][k][k]
                p = body["inertia_uncertainty_percent"][k] / 100.0
                expected[f"{axis}_{body['name']}"] = (j * (1 - p), j * (1 + p))
    params = {p.name: p for p in simulator.parameters()}
    real = {n: p for n, p in params.items() if p.kind == ParameterKind.REAL_BLOCK}
    assert set(real) == set(expected)
    assert {"m_TGT", "Jzz_TGT", "w1_SA2"} <= set(real)
    for name, (low, high) in expected.items():
        assert real[name].uncertainty == pytest.approx((low, high), rel=1e-12), name
    assert not any(n.startswith(("tau_", "delta_")) for n in params)
    assert simulator.events() == {
        "start:stow": 0.0,
        "start:approach": 300.0,
        "start:grasp_hold": 700.0,
        "start:berthed": 900.0,
    }


@pytest.mark.parametrize("interpolation", ["smooth", "linear", "quintic"])
def test_twin_trajectory_is_the_timeline(tmp_path_factory, interpolation):
    """The Drake trajectory the arm and the drives follow equals the timeline's angles (and
    their rates its finite differences) at instants all over the mission."""
    path = _write(tmp_path_factory, _servicer_document(interpolation), f"{interpolation}.toml")
    timeline = load_scenario(path).timeline
    names = timeline.joint_names
    assert {"A1", "A7", "SA1"} <= set(names)
    trajectory = joint_trajectory(timeline, names)
    h = 1e-4
    for t in np.linspace(h, timeline.duration - h, 97):
        angles = timeline.angles(t)
        np.testing.assert_allclose(
            trajectory.value(t)[:, 0], [angles[n] for n in names], rtol=0, atol=1e-12
        )
        if np.abs(np.asarray(timeline.boundaries) - t).min() < 2 * h:
            continue  # the linear interpolation's rate jumps there
        up, down = timeline.angles(t + h), timeline.angles(t - h)
        rate = [(up[n] - down[n]) / (2 * h) for n in names]
        np.testing.assert_allclose(trajectory.EvalDerivative(t, 1)[:, 0], rate, rtol=0, atol=1e-7)


def test_campaign_run_through_the_capture_tracks_the_timeline(simulator):
    """A window across the capture (700 s) runs in two segments (the free twin, then the
    target welded at the grasp port): the arm tracks its trajectory (< 1e-6 rad), the log is
    one sampled history without a repeated instant, and the weld changes the response."""
    case = RunCase(1, 5, {"phi0_y": 2e-3}, MissionWindow(690.0, 720.0))
    out = simulator.run(case)
    times = out.timeseries["time [s]"].to_numpy()
    np.testing.assert_allclose(times, np.arange(690.0, 720.0 + 0.5, 1.0 / simulator.log_rate))
    assert out.metrics["max_tracking_error"] < 1e-6
    assert set(simulator._twins) == {None, ("GRASP", "T_GRASP")}
    # the free twin alone, same noise sequence (the case's seed) and initial error
    noise = np.random.default_rng(5).standard_normal((int(30.0 / simulator.design.period) + 2, 9))
    free = run_tree_twin(
        simulator.twin({}, None),
        30.0,
        start=690.0,
        initial_attitude=[0.0, 2e-3, 0.0],
        noise_table=noise,
        perturbations=(np.zeros((3, 3)), 0.0, math.nan),
        max_step=simulator.max_step,
    )
    phi_y = out.timeseries["phi_y [rad]"].to_numpy()
    scale = np.abs(phi_y).max()
    assert np.abs(phi_y[:11] - free.phi[:11, 1]).max() <= 1e-9 * scale  # to 700 s: one twin
    assert np.abs(phi_y[-5:] - free.phi[-5:, 1]).max() > 1e-3 * scale  # then the welded one


def test_a_run_cut_at_an_instant_is_the_run_in_one_piece(simulator):
    """The state carried from one segment to the next (joints, modes, flight software): the
    same twin run over [400, 420] s at once and cut at 410 s gives the same history (to the
    integrator's Newton tolerance) and the same running metrics' sample count."""
    design = simulator.design
    twin = simulator.twin({}, None)
    kwargs = {"initial_attitude": 1e-3, "max_step": design.period, "accuracy": 1e-10}
    whole = run_tree_twin(twin, 20.0, start=400.0, **kwargs)
    first = run_tree_twin(twin, 10.0, start=400.0, **kwargs)
    second = run_tree_twin(
        twin, 10.0, start=410.0, initial_state=first.final_state, max_step=design.period,
        accuracy=1e-10,
    )  # fmt: skip
    np.testing.assert_allclose(second.times + 10.0, whole.times[-len(second.times) :])
    scale = np.abs(whole.phi).max()
    assert np.abs(second.phi - whole.phi[-len(second.times) :]).max() <= 1e-6 * scale
    assert second.metrics["samples"] == whole.metrics["samples"] == 20.0 / design.period
    joined = run_mission_twin(lambda mating: twin, simulator.timeline, 20.0, start=400.0, **kwargs)
    np.testing.assert_allclose(joined.phi, whole.phi)


@pytest.mark.slow
def test_shipped_servicer_campaign_runs_across_the_capture(tmp_path):
    """``oos campaign run`` of the shipped spec on the shipped file (tip waypoint solved by
    the simulator itself), three runs in a window across the capture: every run simulated,
    the arm on its trajectory."""
    import pandas as pd

    from oos_drake.app.main import main
    from oos_drake.campaign.tree_simulator import METRIC_UNITS
    from oos_drake.resources import package_path

    text = package_path("oos_drake.campaign", "specs", "servicer_7dof.toml").read_text()
    text = text.replace("n_runs = 48", "n_runs = 3")
    head, _, tail = text.partition("[sampler]")
    _, _, tail = tail.partition("[estimation]")
    head = head.replace(
        'scenario = "servicer_7dof"', 'scenario = "servicer_7dof"\nsampler = "monte-carlo"'
    )
    window = '[window]\nkind = "event"\nevent = "start:grasp_hold"\nbefore = 10.0\nafter = 10.0\n'
    text = head + "[estimation]" + tail
    start, end = text.index("[window]"), text.index("[dispersions]")
    spec = tmp_path / "servicer_short.toml"
    spec.write_text(text[:start] + window + "\n" + text[end:])
    out = tmp_path / "campaign"
    assert main(["campaign", "run", str(spec), "--out", str(out), "--workers", "1"]) == 0
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 3 and (runs["status"] == "ok").all()
    tracking = runs[f"max_tracking_error [{METRIC_UNITS['max_tracking_error']}]"]
    assert (tracking < 1e-6).all()


def test_every_shipped_tree_has_its_own_campaign_spec():
    """``oos run --scenario NAME`` takes ``specs/NAME.toml``: written for that very file, its
    requirements the file's pointing requirement and torque bound."""
    import tomllib

    from oos_drake.app.pipeline import _check_campaign_scenario, default_campaign
    from oos_drake.scenario.data import scenario_path
    from oos_drake.scenario.tree import shipped_trees, tree_path

    for name in shipped_trees():
        spec = default_campaign(scenario_path(name))
        assert spec.stem == name
        _check_campaign_scenario(spec, scenario_path(name))
        document = tomllib.loads(spec.read_text())
        with tree_path(name).open("rb") as stream:
            control = tomllib.load(stream)["control"]
        assert document["requirements"]["ape"]["max"] == control["pointing_requirement"]
        assert document["requirements"]["peak_torque"]["max"] == control["torque_limit"]
