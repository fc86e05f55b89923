"""Kinematics: UR5 forward kinematics against the UR DH model, loop closure, mass properties."""

from __future__ import annotations

import numpy as np
import pytest
from kinematic_oracles import inertia_history  # tests/scenario is on sys.path (rootdir imports)

from oos_drake.scenario.data import load_scenario
from oos_drake.scenario.kinematics import (
    BODY_NAMES,
    IK_WAYPOINTS,
    Pose,
    arm_tip_pose,
    forward_kinematics,
    pose_error,
    rigid_spatial_inertia_at_G1,
    solve_arm_ik,
    waypoint_ik,
    waypoint_tip_pose,
)
from oos_drake.scenario.timeline import Configuration, mission_timeline
from oos_drake.titop.spatial import rotation_matrix

D1, A2, A3, D4, D5, D6 = 0.089159, 0.425, 0.39225, 0.10915, 0.09465, 0.0823


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


@pytest.fixture(scope="module")
def timeline(scenario):
    return mission_timeline(scenario)


def ur5_dh(q):
    """Standard UR5 Denavit-Hartenberg forward kinematics (UR's own base and tool frames)."""
    d = [D1, 0, 0, D4, D5, D6]
    a = [0, -A2, -A3, 0, 0, 0]
    twist = [np.pi / 2, 0, 0, np.pi / 2, -np.pi / 2, 0]
    T = np.eye(4)
    for i in range(6):
        ct, st, ca, sa = np.cos(q[i]), np.sin(q[i]), np.cos(twist[i]), np.sin(twist[i])
        T = T @ np.array(
            [
                [ct, -st * ca, st * sa, a[i] * ct],
                [st, ct * ca, -ct * sa, a[i] * st],
                [0, sa, ca, d[i]],
                [0, 0, 0, 1],
            ]
        )
    return T


def _tip_in_base(scenario, q):
    base = Pose(scenario.arm.R_G_L0, scenario.arm.p_G_J0)
    return base.inverse() @ arm_tip_pose(scenario, q)


# ---------------------------------------------------------------------------------------------
# arm forward kinematics
# ---------------------------------------------------------------------------------------------
def test_arm_matches_ur5_dh_model(scenario):
    """Same tip as UR's DH chain up to UR's base (half turn about z) and tool frame conventions."""
    Rz = np.diag([-1.0, -1.0, 1.0])
    rng = np.random.default_rng(11)
    tool = None
    for q in [np.zeros(6), *rng.uniform(-np.pi, np.pi, (20, 6))]:
        T = ur5_dh(q)
        tip = _tip_in_base(scenario, q)
        np.testing.assert_allclose(tip.p, Rz @ T[:3, 3], atol=1e-14)
        relative = (Rz @ T[:3, :3]).T @ tip.R  # constant tool-frame offset
        if tool is None:
            tool = relative
        np.testing.assert_allclose(relative, tool, atol=1e-13)


def test_arm_closed_form_poses(scenario):
    # stretched (alpha = 0): reach a2 + a3 along x_L0, lateral d4 + d6, height d1 - d5
    np.testing.assert_allclose(
        _tip_in_base(scenario, np.zeros(6)).p, [A2 + A3, D4 + D6, D1 - D5], atol=1e-15
    )
    # the paper's pictured pose alpha_{2,4} = -pi/2: upper arm and forearm along z_L0
    pictured = np.array([0, -np.pi / 2, 0, -np.pi / 2, 0, 0])
    config = Configuration.from_angles(pictured)
    poses = forward_kinematics(scenario, config)
    base = Pose(scenario.arm.R_G_L0, scenario.arm.p_G_J0).inverse()
    J = [(base @ poses.bodies[f"L{i}"]).p for i in range(7)]
    np.testing.assert_allclose(J[3] - J[2], [0, -0.1197, A2], atol=1e-15)
    np.testing.assert_allclose(J[4] - J[3], [0, 0, A3], atol=1e-15)
    np.testing.assert_allclose(
        (base @ poses.ports["J7"]).p, [0, D4 + D6, D1 + A2 + A3 + D5], atol=1e-14
    )
    # upper arm / forearm CoM 0.28 / 0.25 m along the link axis, along z_L0 in this pose
    com = base.point(poses.centers_of_mass["L2"])
    np.testing.assert_allclose(com - J[2], [0, 0, 0.28], atol=1e-15)
    np.testing.assert_allclose(
        base.point(poses.centers_of_mass["L3"]) - J[3], [0, 0, 0.25], atol=1e-15
    )


def test_arm_reach_bound(scenario):
    rng = np.random.default_rng(5)
    q = rng.uniform(-np.pi, np.pi, (500, 6))
    poses = forward_kinematics(scenario, _batch(q))
    joints = poses.joint_positions()
    bound = D1 + 0.13585 + np.hypot(A2, 0.1197) + A3 + 0.093 + D5 + D6
    assert np.all(np.linalg.norm(joints[:, 7] - joints[:, 0], axis=-1) <= bound)
    # link lengths are invariant
    np.testing.assert_allclose(
        np.linalg.norm(joints[:, 3] - joints[:, 2], axis=-1), np.hypot(A2, 0.1197)
    )
    np.testing.assert_allclose(np.linalg.norm(joints[:, 4] - joints[:, 3], axis=-1), A3)


def test_rotation_about_axis_closed_form():
    np.testing.assert_allclose(
        rotation_matrix([0, 1, 0], np.pi / 2), [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-15
    )
    R = rotation_matrix([0, 0, -1], np.array([0.3, 1.2]))
    np.testing.assert_allclose(R[1], rotation_matrix([0, 0, 1], -1.2), atol=1e-15)


def _batch(alpha, delta_C1=0.0, delta_C2=0.0):
    n = alpha.shape[0]
    return Configuration(
        time=np.zeros(n),
        alpha=alpha,
        theta=np.zeros((n, 4)),
        delta_C1=np.full(n, delta_C1),
        delta_C2=np.full(n, delta_C2),
    )


# ---------------------------------------------------------------------------------------------
# docking geometry and inverse kinematics
# ---------------------------------------------------------------------------------------------
def _stored(scenario, time):
    waypoints = scenario.mission.arm_waypoints
    return waypoints.values[list(waypoints.times).index(time)]


def test_second_docking_closes_the_loop_from_stored_angles(scenario):
    """At 880 s the stored angles put J7 on D2 while D3 sits on D1 (position and orientation)."""
    config = Configuration.from_angles(_stored(scenario, 880.0), delta_C2=1.0)
    poses = forward_kinematics(scenario, config)
    np.testing.assert_allclose(poses.ports["D3"].p, poses.ports["D1"].p, atol=1e-15)
    error = pose_error(poses.ports["J7"], poses.ports["D2"])
    assert np.linalg.norm(error) < 1e-9
    # the same target pose is obtained through the arm (delta_C1 = 1)
    via_arm = forward_kinematics(scenario, Configuration.from_angles(config.alpha, delta_C1=1.0))
    assert np.linalg.norm(pose_error(via_arm.bodies["RH2"], poses.bodies["RH2"])) < 1e-9


def test_first_docking_grasp_from_stored_angles(scenario):
    config = Configuration.from_angles(_stored(scenario, 255.0), delta_C1=1.0)
    poses = forward_kinematics(scenario, config)
    D1_pose = poses.ports["D1"]
    standoff = scenario.mission.first_docking_standoff
    expected = Pose(D1_pose.R, D1_pose.p + standoff * D1_pose.R[:, 2])
    assert np.linalg.norm(pose_error(poses.ports["D3"], expected)) < 1e-9
    np.testing.assert_allclose(np.linalg.norm(poses.ports["D3"].p - D1_pose.p), standoff, rtol=1e-9)


@pytest.mark.parametrize("label", sorted(IK_WAYPOINTS))
def test_ik_waypoints_from_stored_angles(scenario, label):
    """Every IK waypoint stored in the file puts J7 on its desired pose to < 1e-9."""
    alpha = scenario.mission.arm_waypoints.at(label)
    error = pose_error(arm_tip_pose(scenario, alpha), waypoint_tip_pose(scenario, label))
    assert np.linalg.norm(error) < 1e-9
    np.testing.assert_allclose(alpha[[0, 4, 5]], [0, np.pi / 2, 0], atol=1e-12)  # planar branch
    assert alpha[2] > 0  # elbow on the far side of the base


def test_approach_and_retreat_are_straight_out_of_the_fixture(scenario):
    """Pre-grasp/retreat tips sit grasp_approach_distance from D2 along the tool axis, same R."""
    distance = scenario.mission.grasp_approach_distance
    for backed, grasp in (("pre-grasp", "grasp"), ("retreat", "docked")):
        X_backed = waypoint_tip_pose(scenario, backed)
        X_grasp = waypoint_tip_pose(scenario, grasp)
        np.testing.assert_allclose(X_backed.R, X_grasp.R, atol=0)
        np.testing.assert_allclose(X_grasp.p - X_backed.p, distance * X_grasp.R[:, 1], atol=1e-15)


def test_arm_stays_clear_of_target_and_hub(scenario, timeline):
    """Geometry choices: the arm links never enter the target cube or the chaser's bottom face."""
    t = np.linspace(0.0, 1500.0, 601)
    poses = forward_kinematics(scenario, timeline.configuration(t))
    joints = poses.joint_positions()[:, 1:]  # J1..J7
    s = np.linspace(0.0, 1.0, 11)[:-1]
    points = joints[:, :-1, None, :] + s[:, None] * (
        joints[:, 1:, None, :] - joints[:, :-1, None, :]
    )
    points = points.reshape(len(t), -1, 3)
    target = poses.bodies["RH2"]
    local = np.einsum("nki,nij->nkj", points - target.p[:, None, :], target.R)
    half = 0.3395 - 1e-9  # target cube (the grasped tip touches its face)
    assert not np.any(np.all(np.abs(local) < half, axis=-1))
    assert joints[..., 2].max() < -0.402  # below the bottom surface of RH1


def test_docking_ik_solver_reproduces_stored_waypoints(scenario):
    for label, time in (("docked", 880.0), ("grasp", 255.0)):
        solution = waypoint_ik(scenario, label, alpha0=_stored(scenario, time) + 0.05)
        assert solution.residual < 1e-10
        np.testing.assert_allclose(solution.alpha, _stored(scenario, time), atol=1e-8)
    # the stored second-docking branch: planar arm, elbow away from the target
    np.testing.assert_allclose(_stored(scenario, 880.0)[[0, 4, 5]], [0, np.pi / 2, 0], atol=1e-12)


def test_ik_recovers_random_reachable_pose(scenario):
    rng = np.random.default_rng(3)
    q = rng.uniform(-2.5, 2.5, 6)
    target = arm_tip_pose(scenario, q)
    solution = solve_arm_ik(scenario, target, q + rng.normal(scale=0.1, size=6))
    assert solution.residual < 1e-10
    assert np.linalg.norm(pose_error(arm_tip_pose(scenario, solution.alpha), target)) < 1e-10
    unreachable = Pose(np.eye(3), np.array([5.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="out of reach"):
        solve_arm_ik(scenario, unreachable, q, extra_guesses=2)


def test_mission_ports_coincide_while_docked(scenario, timeline):
    t = np.linspace(0.0, 1500.0, 151)
    config = timeline.configuration(t)
    poses = forward_kinematics(scenario, config)
    arm_docked = config.delta_C1 == 1
    hub_docked = config.delta_C2 == 1
    grasp = pose_error(poses.ports["J7"], poses.ports["D2"])
    dock = pose_error(poses.ports["D3"], poses.ports["D1"])
    assert np.abs(grasp[arm_docked]).max() < 1e-12
    assert np.abs(dock[hub_docked]).max() < 1e-12
    # while pulled in, the target never crosses the hub's docking plane (D3 below D1 along z_D1)
    approach = np.einsum(
        "ni,i->n", poses.ports["D3"].p - poses.ports["D1"].p, poses.ports["D1"].R[0][:, 2]
    )
    assert np.all(approach >= -1e-12)
    assert set(poses.bodies) == set(BODY_NAMES)


def test_forward_kinematics_rejects_bad_switches(scenario):
    with pytest.raises(ValueError, match="cannot both be 1"):
        forward_kinematics(scenario, Configuration.from_angles(np.zeros(6), delta_C1=1, delta_C2=1))
    with pytest.raises(ValueError, match="in \\{0, 1\\}"):
        forward_kinematics(scenario, Configuration.from_angles(np.zeros(6), delta_C1=0.5))


# ---------------------------------------------------------------------------------------------
# mass properties
# ---------------------------------------------------------------------------------------------
def _equimomental_points(mass, inertia):
    """Six point masses with the body's mass, CoM and inertia tensor (needs triangle inequality)."""
    principal, axes = np.linalg.eigh(inertia)
    second_moments = (principal.sum() - 2 * principal) / 2  # s_i = (I_j + I_k - I_i) / 2
    distances = np.sqrt(3 * np.maximum(second_moments, 0) / mass)
    points = np.concatenate([axes * distances, -axes * distances], axis=1).T
    return np.full(6, mass / 6), points


def _point_mass_inertia(scenario, config):
    """Total mass, first moment and inertia at G1 from point masses: independent of D_G1 algebra."""
    poses = forward_kinematics(scenario, config)
    bodies = [("RH1", scenario.hubs["RH1"].mass, np.zeros(3), scenario.hubs["RH1"].inertia)]
    bodies += [(link.name, link.mass, link.p_J_G, link.inertia) for link in scenario.arm.links]
    bodies += [
        (n, a.model.mass, a.model.p_P_S, a.model.inertia)
        for n, a in scenario.arrays.items()
        if n in ("SA1", "SA2")
    ]
    if poses.target_connected:
        bodies += [("RH2", scenario.hubs["RH2"].mass, np.zeros(3), scenario.hubs["RH2"].inertia)]
        bodies += [
            (n, a.model.mass, a.model.p_P_S, a.model.inertia)
            for n, a in scenario.arrays.items()
            if n in ("SA3", "SA4")
        ]
    mass, first, J = 0.0, np.zeros(3), np.zeros((3, 3))
    for name, m, com, inertia in bodies:
        masses, points = _equimomental_points(m, inertia)
        world = poses.bodies[name].point(points + com)
        for mk, r in zip(masses, world, strict=True):
            mass += mk
            first += mk * r
            J += mk * (r @ r * np.eye(3) - np.outer(r, r))
    return mass, first, J


@pytest.mark.parametrize("moment", ["1", "3", "6", "7", "8"])
def test_rigid_spatial_inertia_against_point_masses(scenario, timeline, moment):
    config = timeline.named[moment].configuration
    D = rigid_spatial_inertia_at_G1(scenario, config)
    mass, first, J = _point_mass_inertia(scenario, config)
    np.testing.assert_allclose(D, D.T, atol=1e-10)
    assert np.linalg.eigvalsh(D)[0] > 0
    np.testing.assert_allclose(D[:3, :3], mass * np.eye(3), rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose([D[5, 1], D[3, 2], D[4, 0]], first, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(D[3:, 3:], J, rtol=1e-11, atol=1e-10)


def test_total_mass_closed_form(scenario, timeline):
    chaser = 188.5 + 20.9939 + 2 * 88.93
    target = 24.96 + 2 * 11.3497
    D = rigid_spatial_inertia_at_G1(
        scenario, timeline.configuration(np.array([100.0, 500.0, 1000.0]))
    )
    np.testing.assert_allclose(D[:, 0, 0], [chaser, chaser + target, chaser + target], rtol=1e-14)


def test_hub_alone_and_parallel_axis(scenario):
    """Decoupled, arm folded, arrays at 0: D_G1 - (arm + arrays) equals the hub's own D_G."""
    config = Configuration.from_angles(np.zeros(6))
    D = rigid_spatial_inertia_at_G1(scenario, config)
    # arrays at theta = 0: SA1 at P1 = [0, .4365, 0] in R_RH1, S1 = P1 + p_P_S (parallel axis)
    model = scenario.array_models["SA1_2"]
    r1 = np.array([0.0, 0.4365, 0.0]) + model.p_P_S
    r2 = np.diag([-1.0, -1.0, 1.0]) @ model.p_P_S + np.array([0.0, -0.4365, 0.0])
    J_arrays = sum(
        R @ model.inertia @ R.T + model.mass * (r @ r * np.eye(3) - np.outer(r, r))
        for R, r in ((np.eye(3), r1), (np.diag([-1.0, -1.0, 1.0]), r2))
    )
    poses = forward_kinematics(scenario, config)
    J_arm = np.zeros((3, 3))
    for link in scenario.arm.links:
        pose = poses.bodies[link.name]
        r = pose.point(link.p_J_G)
        J_arm += pose.R @ link.inertia @ pose.R.T + link.mass * (r @ r * np.eye(3) - np.outer(r, r))
    np.testing.assert_allclose(
        D[3:, 3:] - J_arrays - J_arm, scenario.hubs["RH1"].inertia, atol=1e-11
    )


def test_inertia_history(scenario):
    history = inertia_history(scenario, np.linspace(0.0, 1500.0, 301))
    entries = history.entries()
    t = history.time
    # jump at the first docking
    before = entries["Jxx"][t == 250.0][0]
    after = entries["Jxx"][t == 255.0][0]
    assert after > before + 50.0
    # paper: Jyy at G1 is bigger at docking phase 7 (255 s) than at phase 8 (880 s)
    assert entries["Jyy"][t == 255.0][0] > entries["Jyy"][t == 880.0][0] + 10.0
    # tilting about y_P1 = -y_P2 (the y_RH1 axis through P): Jyy stays constant (paper)
    tilting = t >= 1100.0
    np.testing.assert_allclose(entries["Jyy"][tilting], entries["Jyy"][tilting][0], rtol=1e-13)
    assert np.ptp(entries["Jxx"][tilting]) > 1.0
    # centre of mass moves towards the target when it is attached
    assert history.center_of_mass[t == 255.0][0][2] < history.center_of_mass[t == 250.0][0][2]
    assert set(entries) == {"Jxx", "Jyy", "Jzz", "Jxy", "Jxz", "Jyz"}


@pytest.mark.parametrize("angle", [1e-9, 0.3, 2.0, np.pi])
def test_pose_error_is_the_rotation_vector(angle):
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    actual = Pose(rotation_matrix(axis, angle), np.array([1.0, 2.0, 3.0]))
    desired = Pose(np.eye(3), np.array([1.0, 2.0, 2.5]))
    error = pose_error(actual, desired)
    np.testing.assert_allclose(error[:3], [0, 0, 0.5], atol=1e-15)
    np.testing.assert_allclose(np.abs(error[3:]), np.abs(angle * axis), rtol=1e-12, atol=1e-20)


def test_target_overrides_shift_inertia_by_the_difference(scenario, timeline):
    """Changing RH2's mass/inertia changes D_G1 by the RH2 term alone (linear in m and J)."""
    config = timeline.named["3"].configuration
    nominal = rigid_spatial_inertia_at_G1(scenario, config)
    J2 = scenario.hubs["RH2"].inertia * np.array([[1.1, 1, 1], [1, 0.9, 1], [1, 1, 1.1]])
    perturbed = rigid_spatial_inertia_at_G1(scenario, config, target_mass=27.0, target_inertia=J2)
    pose = forward_kinematics(scenario, config).bodies["RH2"]
    r = pose.p
    expected = (27.0 - 24.96) * (r @ r * np.eye(3) - np.outer(r, r)) + pose.R @ (
        J2 - scenario.hubs["RH2"].inertia
    ) @ pose.R.T
    np.testing.assert_allclose(perturbed[3:, 3:] - nominal[3:, 3:], expected, atol=1e-12)
    np.testing.assert_allclose(perturbed[0, 0] - nominal[0, 0], 27.0 - 24.96, rtol=1e-12)
    decoupled = timeline.named["1"].configuration
    np.testing.assert_array_equal(
        rigid_spatial_inertia_at_G1(scenario, decoupled, target_mass=50.0),
        rigid_spatial_inertia_at_G1(scenario, decoupled),
    )
    with pytest.raises(ValueError, match="RH2: target_mass must be > 0"):
        rigid_spatial_inertia_at_G1(scenario, config, target_mass=-1.0)
