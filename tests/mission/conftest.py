"""Shared fixtures of the mission tests: one mission diagram per test session (build ~0.3 s)."""

import pytest

pytest.importorskip("pydrake")


@pytest.fixture(scope="session")
def mission():
    """The default :class:`MissionSimulation` (baseline controller, 10 Hz, 1 Hz logging)."""
    from oos_drake.multibody.mission_sim import MissionSimulation

    return MissionSimulation()


@pytest.fixture(scope="session")
def mission_10hz_log():
    """A :class:`MissionSimulation` logging at the control rate (default integrator settings)."""
    from oos_drake.multibody.mission import MissionOptions
    from oos_drake.multibody.mission_sim import MissionSimulation

    return MissionSimulation(MissionOptions(log_rate=10.0))
