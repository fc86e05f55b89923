"""Shared fixtures of the mission tests: one mission diagram per test session (build ~0.3 s)."""

import pytest

pytest.importorskip("pydrake")


@pytest.fixture(scope="session")
def mission(paper_scenario):
    """The paper's :class:`MissionSimulation` (baseline controller, 10 Hz, 1 Hz logging)."""
    from oos_drake.multibody.mission import make_mission_diagram
    from oos_drake.multibody.mission_sim import MissionSimulation

    return MissionSimulation(make_mission_diagram(scenario=paper_scenario))


@pytest.fixture(scope="session")
def mission_10hz_log(paper_scenario):
    """A :class:`MissionSimulation` logging at the control rate (default integrator settings)."""
    from oos_drake.multibody.mission import MissionOptions, make_mission_diagram
    from oos_drake.multibody.mission_sim import MissionSimulation

    options = MissionOptions(log_rate=10.0)
    return MissionSimulation(make_mission_diagram(options, scenario=paper_scenario))
