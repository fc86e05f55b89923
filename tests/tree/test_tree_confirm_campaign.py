"""The campaign simulator of a schema-2 tree (campaign/tree_simulator.py): the tree's Drake
twin with its revolute joints motion-driven along the mission's timeline."""

import math
import tomllib

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.campaign.simulator import (  # noqa: E402
    MissionWindow,
    ParameterKind,
    RunCase,
    Simulator,
)
from oos_drake.campaign.tree_simulator import make_simulator  # noqa: E402
from oos_drake.multibody.tree_twin import (  # noqa: E402
    build_tree_twin,
    joint_trajectory,
    run_tree_twin,
)
from oos_drake.scenario.tree import tree_path  # noqa: E402


@pytest.fixture(scope="module")
def simulator():
    return make_simulator(scenario="flexible_satellite")


def test_dispersions_are_the_scenarios_declared_ranges(simulator):
    """Each uncertain quantity of the file (read here from the TOML itself) is a parameter whose
    default dispersion is its declared range; the LTI scalars [-1, 1]; initial errors none."""
    assert isinstance(simulator, Simulator)
    with tree_path("flexible_satellite").open("rb") as stream:
        document = tomllib.load(stream)
    expected = {}
    for body in document["bodies"]:
        for mode, entry in body.get("uncertainty", {}).items():
            f = body["frequencies_hz"][int(mode[1:]) - 1]
            p = entry["percent"] / 100.0
            expected[f"{mode}_{body['name']}"] = (
                2 * math.pi * f * (1 - p),
                2 * math.pi * f * (1 + p),
            )
    params = {p.name: p for p in simulator.parameters()}
    real = {n: p for n, p in params.items() if p.kind == ParameterKind.REAL_BLOCK}
    assert set(real) == set(expected) == {"w1_SA1", "w1_SA2"}
    for name, (low, high) in expected.items():
        assert real[name].uncertainty == pytest.approx((low, high), rel=1e-12)
        assert real[name].unit == "rad/s"
    lti = [p for p in params.values() if p.kind == ParameterKind.LTI]
    assert len(lti) == 10 and all(p.uncertainty == (-1.0, 1.0) for p in lti)
    assert params["phi0_x"].uncertainty is None
    assert simulator.duration() == pytest.approx(1600.0)
    assert simulator.events() == {
        "start:observation": 0.0,
        "start:array_slew": 600.0,
        "start:observation_2": 1000.0,
    }


def test_joint_trajectory_is_the_timelines_angles(simulator):
    timeline = simulator.timeline
    trajectory = joint_trajectory(timeline, ("SA1", "SA2"))
    for t in np.linspace(0.0, 1600.0, 57):
        angles = timeline.angles(t)
        np.testing.assert_allclose(
            trajectory.value(t)[:, 0], [angles["SA1"], angles["SA2"]], rtol=0, atol=1e-12
        )


def test_driven_joints_follow_the_slew_and_a_held_phase_equals_the_frozen_twin(simulator):
    """During the slew the drives track the timeline (1e-6 rad); over a held phase the driven
    twin and the frozen twin (joints locked, another integrator) give the same attitude."""
    design, timeline = simulator.design, simulator.timeline
    driven = build_tree_twin(simulator.tree, design, timeline=timeline, log_rate=1.0)
    run = run_tree_twin(driven, 100.0, start=750.0, initial_attitude=1e-3, max_step=design.period)
    assert not run.diverged and run.joint_error < 1e-6
    held = run_tree_twin(driven, 60.0, start=1100.0, initial_attitude=1e-3, max_step=0.1)
    frozen = build_tree_twin(simulator.tree, design, timeline.angles(1100.0), log_rate=1.0)
    reference = run_tree_twin(frozen, 60.0, initial_attitude=1e-3, max_step=0.05)
    np.testing.assert_allclose(held.times, reference.times)
    scale = np.abs(reference.phi).max()
    assert np.abs(held.phi - reference.phi).max() <= 1e-4 * scale


def test_a_campaign_run_is_a_pure_function_of_its_case(simulator):
    """Same case twice (with the twin rebuilt in between for other values): identical metrics;
    dispersed real blocks reach the twin (another result)."""
    case = RunCase(3, 11, {"phi0_y": 2e-3, "w1_SA1": 2.6}, MissionWindow(590.0, 650.0))
    first = simulator.run(case)
    other = simulator.run(RunCase(4, 11, {"phi0_y": 2e-3}, MissionWindow(590.0, 650.0)))
    again = simulator.run(case)
    assert first.metrics == again.metrics
    assert first.metrics["ape"] != other.metrics["ape"]
    assert first.metrics["max_tracking_error"] < 1e-6
    assert set(first.metrics) == set(simulator.metric_units())
    columns = {f"{n} [{u}]" for n, u in simulator.signal_units().items()} | {"time [s]"}
    assert set(first.timeseries.columns) == columns
    assert first.timeseries["time [s]"].iloc[0] == pytest.approx(590.0)
