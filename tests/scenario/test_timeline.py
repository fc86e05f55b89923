"""Mission timeline: quintic segments, connection switches, named configurations, tau helpers."""

from __future__ import annotations

import numpy as np
import pytest

from oos_drake.scenario.data import Waypoints
from oos_drake.scenario.timeline import (
    ALPHA_PARAMETERS,
    THETA_PARAMETERS,
    Configuration,
    QuinticTrajectory,
    mission_timeline,
)


@pytest.fixture(scope="module")
def timeline(paper_scenario):
    return mission_timeline(paper_scenario)


def test_quintic_hits_waypoints_with_zero_rate_and_acceleration(timeline):
    for trajectory in (timeline.arm, timeline.arrays):
        t = trajectory.times
        np.testing.assert_allclose(trajectory(t), trajectory.values, atol=1e-15)
        np.testing.assert_allclose(trajectory(t, 1), 0.0, atol=1e-15)
        np.testing.assert_allclose(trajectory(t, 2), 0.0, atol=1e-15)


def test_quintic_closed_form_midpoint():
    """At the middle of a segment: mean value, peak rate 15/8 dq/h, zero acceleration."""
    trajectory = QuinticTrajectory(np.array([10.0, 30.0]), np.array([[1.0, -2.0], [3.0, 2.0]]))
    np.testing.assert_allclose(trajectory(20.0), [2.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(trajectory(20.0, 1), [15 / 8 * 2 / 20, 15 / 8 * 4 / 20], rtol=1e-14)
    np.testing.assert_allclose(trajectory(20.0, 2), [0.0, 0.0], atol=1e-15)
    # quarter point: s(1/4) = 10/64 - 15/256 + 6/1024 = 53/512
    np.testing.assert_allclose(trajectory(15.0)[0], 1.0 + 2.0 * 53 / 512, rtol=1e-14)


def test_quintic_derivatives_match_finite_differences(timeline):
    t = np.linspace(1.0, 1499.0, 97)
    h = 1e-3
    for trajectory in (timeline.arm, timeline.arrays):
        rate = (trajectory(t + h) - trajectory(t - h)) / (2 * h)
        accel = (trajectory(t + h, 1) - trajectory(t - h, 1)) / (2 * h)
        np.testing.assert_allclose(trajectory(t, 1), rate, atol=1e-9)
        np.testing.assert_allclose(trajectory(t, 2), accel, atol=1e-9)


def test_quintic_stays_between_waypoints(timeline):
    t = np.linspace(timeline.t_start, timeline.t_end, 3001)
    q = timeline.arm(t)
    k = np.clip(
        np.searchsorted(timeline.arm.times, t, side="right") - 1, 0, len(timeline.arm.times) - 2
    )
    lo = np.minimum(timeline.arm.values[k], timeline.arm.values[k + 1])
    hi = np.maximum(timeline.arm.values[k], timeline.arm.values[k + 1])
    assert np.all(q >= lo - 1e-15) and np.all(q <= hi + 1e-15)


def test_connection_switches_follow_docking(timeline):
    t = np.array([0.0, 254.999, 255.0, 500.0, 879.999, 880.0, 1200.0, 1500.0])
    c1, c2 = timeline.switches(t)
    np.testing.assert_array_equal(c1, [0, 0, 1, 1, 1, 0, 0, 0])
    np.testing.assert_array_equal(c2, [0, 0, 0, 0, 0, 1, 1, 1])


def test_array_angles(timeline):
    t = np.linspace(0.0, 1500.0, 301)
    config = timeline.configuration(t)
    theta = config.theta
    np.testing.assert_array_equal(theta[t <= 1100.0, :2], 0.0)
    np.testing.assert_array_equal(theta[:, 2:], 0.0)  # target arrays fixed
    np.testing.assert_allclose(theta[:, 1], -theta[:, 0], atol=0)  # co-rotating about y_RH1
    np.testing.assert_allclose(theta[-1, :2], [np.pi, -np.pi], atol=1e-15)  # half a revolution
    assert np.all(np.diff(theta[:, 0]) >= 0)


def test_vectorized_equals_scalar(timeline):
    t = np.array([3.0, 255.0, 611.5, 1333.3])
    batch = timeline.configuration(t)
    rates = timeline.rates(t)
    assert batch.alpha.shape == (4, 6) and batch.theta.shape == (4, 4) and len(batch) == 4
    for i, ti in enumerate(t):
        single = timeline.configuration(ti)
        assert single.alpha.shape == (6,) and single.delta_C1.shape == ()
        np.testing.assert_array_equal(single.alpha, batch.alpha[i])
        np.testing.assert_array_equal(single.theta, batch[i].theta)
        assert float(single.delta_C2) == batch.delta_C2[i]
        np.testing.assert_array_equal(timeline.rates(ti).alpha_ddot, rates.alpha_ddot[i])


def test_sample_and_parameters(timeline):
    samples = timeline.sample(330)
    assert samples.alpha.shape == (330, 6)
    np.testing.assert_allclose(samples.time[[0, -1]], [0.0, 1500.0])
    params = samples.parameters()
    assert set(params) == {*ALPHA_PARAMETERS, *THETA_PARAMETERS, "delta_C1", "delta_C2"}
    np.testing.assert_allclose(params["tau_alpha2"], np.tan(samples.alpha[:, 1] / 4), rtol=1e-15)
    for name in (*ALPHA_PARAMETERS, *THETA_PARAMETERS):
        assert params[name].shape == (330,) and np.all(np.abs(params[name]) <= 1 + 1e-15)
    np.testing.assert_allclose(params["tau_theta1"][-1], 1.0, rtol=1e-15)  # theta = pi


def test_named_configurations(timeline):
    named = timeline.named
    assert list(named) == ["1", "2", "3", "4", "5", "6", "7", "8"]
    switches = {
        n: (float(c.configuration.delta_C1), float(c.configuration.delta_C2))
        for n, c in named.items()
    }
    assert switches["1"] == (0.0, 0.0)
    assert switches["2"] == switches["3"] == switches["4"] == (1.0, 0.0)
    assert switches["5"] == switches["6"] == (0.0, 1.0)
    assert named["1"].time < 255.0 < named["2"].time < named["3"].time < named["4"].time < 880.0
    for name in ("5", "6"):  # arrays tilting: strictly between 0 and half a turn
        theta1 = float(named[name].configuration.theta[0])
        assert 0.05 < theta1 < np.pi - 0.05
        assert named[name].time > 1100.0
    assert named["7"].kind == "docking phase" and named["7"].time == 255.0
    assert named["7"].spring_dampers == ("SM1",)
    assert named["8"].time == 880.0 and named["8"].spring_dampers == ("SM1", "SM2")
    assert named["1"].kind == "moment" and named["1"].spring_dampers == ()
    # the docking-phase angles are the waypoints
    waypoints = timeline.scenario.mission.arm_waypoints
    np.testing.assert_array_equal(named["8"].configuration.alpha, waypoints.at("docked"))
    np.testing.assert_array_equal(named["7"].configuration.alpha, waypoints.at("grasp"))


def test_out_of_range_inputs(timeline):
    with pytest.raises(ValueError, match=r"time -1 s outside the mission \[0, 1500\] s"):
        timeline.configuration(-1.0)
    with pytest.raises(ValueError, match="time 1600 s outside"):
        timeline.rates([10.0, 1600.0])
    with pytest.raises(ValueError, match="outside"):
        timeline.arm(np.nan)
    with pytest.raises(ValueError, match=r"^Configuration.alpha: angle 4 rad outside \[-pi, pi\]$"):
        Configuration.from_angles([0, 0, 4.0, 0, 0, 0])
    with pytest.raises(ValueError, match="alpha must have shape"):
        Configuration.from_angles([0, 0, 0])
    with pytest.raises(ValueError, match="delta_C1 must be in"):
        Configuration.from_angles(np.zeros(6), delta_C1=2.0)
    with pytest.raises(ValueError, match="derivative must be"):
        timeline.arm(1.0, 3)


def test_waypoints_from_data_type():
    trajectory = QuinticTrajectory.from_waypoints(
        Waypoints(times=np.array([0.0, 1.0]), values=np.array([[0.0], [1.0]]))
    )
    assert trajectory(0.5).shape == (1,) and trajectory(0.5)[0] == pytest.approx(0.5)
