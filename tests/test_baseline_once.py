"""The paper's baseline controller is derived once (``control.baseline.scenario_baseline_gains``):
the analysis and the Drake mission get the same gain, and it is the paper's closed form on the
rigid coupled inertia at the first docking (a second, independent computation of ``J_tot``)."""

import numpy as np
import pytest

from oos_drake.analysis.controller import scenario_controller
from oos_drake.control.baseline import scenario_baseline_gains
from oos_drake.scenario.kinematics import rigid_spatial_inertia_at_G1
from oos_drake.scenario.timeline import mission_timeline


def _rigid_inertia_at_first_docking(scenario) -> np.ndarray:
    """``J_tot``: the Schur complement of the rigid spatial inertia at G1 (torque -> wdot of a
    free body), summed body by body by the kinematics, not by the LFR."""
    t = float(scenario.mission.first_docking_time)
    D = rigid_spatial_inertia_at_G1(scenario, mission_timeline(scenario).configuration(t))
    J = D[3:, 3:] - D[3:, :3] @ np.linalg.solve(D[:3, :3], D[:3, 3:])
    return 0.5 * (J + J.T)


def test_baseline_is_the_closed_form_on_the_rigid_inertia(paper_scenario):
    K = scenario_baseline_gains(paper_scenario)
    J = _rigid_inertia_at_first_docking(paper_scenario)
    w, xi = 2 * np.pi * 0.01, 1.0  # paper section 3.1: 0.01 Hz, critically damped
    np.testing.assert_allclose(K[:, :3], w**2 * J, rtol=1e-10, atol=1e-12 * w**2 * abs(J).max())
    np.testing.assert_allclose(K[:, 3:], 2 * xi * w * J, rtol=1e-10, atol=1e-12 * w * abs(J).max())


def test_analysis_and_mission_get_the_same_baseline(paper_scenario):
    pytest.importorskip("pydrake")
    from oos_drake.multibody.mission import mission_controller

    analysis = scenario_controller(None, paper_scenario)
    mission = mission_controller(None, paper_scenario)
    assert analysis.label == "baseline"
    np.testing.assert_array_equal(analysis.K, mission.K)
    np.testing.assert_array_equal(analysis.K, scenario_baseline_gains(paper_scenario))
