"""Kinematics, frame changes and the tan(theta/4) rotation LFR against independent closed forms."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from oos_drake.lfr import usubs
from oos_drake.titop import (
    angle_parameter,
    kinematic_model,
    revolute_connection,
    rotation_dcm,
    rotation_frame_change,
    rotation_matrix_lfr,
)
from oos_drake.titop.spatial import (
    angle_to_tau,
    kinematic_matrix,
    rank2_factors,
    rigid_spatial_inertia,
    rotation_matrix,
    skew,
)

RNG = np.random.default_rng(20240601)


def static_gain(system):
    """Static matrix of a certain LFR (batch dims kept)."""
    return system.freqresp(np.array([0.0]))[..., 0, :, :].real


def test_kinematic_matrix_transports_twists_and_wrenches():
    p_PB = np.array([0.3, -1.2, 0.7])
    a_B, wdot = RNG.normal(size=3), RNG.normal(size=3)
    twist_P = kinematic_matrix(p_PB) @ np.concatenate([a_B, wdot])
    # a_P = a_B + wdot x BP = a_B + wdot x (-PB)
    np.testing.assert_allclose(twist_P[:3], a_B + np.cross(wdot, -p_PB), atol=1e-14)
    np.testing.assert_allclose(twist_P[3:], wdot, atol=0)
    force, torque = RNG.normal(size=3), RNG.normal(size=3)
    wrench_B = kinematic_matrix(p_PB).T @ np.concatenate([force, torque])
    # moment at B of a force at P: T_B = T_P + BP x F
    np.testing.assert_allclose(wrench_B[3:], torque + np.cross(-p_PB, force), atol=1e-14)


def test_rigid_spatial_inertia_is_parallel_axis_theorem():
    mass, p_PG = 12.0, np.array([0.4, 1.1, -0.2])
    inertia_G = np.array([[3.0, 0.1, 0.0], [0.1, 2.0, -0.2], [0.0, -0.2, 4.0]])
    d_P = rigid_spatial_inertia(mass, inertia_G, p_PG)
    steiner = inertia_G + mass * (p_PG @ p_PG * np.eye(3) - np.outer(p_PG, p_PG))
    np.testing.assert_allclose(d_P[3:, 3:], steiner, atol=1e-13)
    np.testing.assert_allclose(d_P[:3, :3], mass * np.eye(3))
    # first moment: m * skew(PG)^T (torque at P from acceleration of P)
    np.testing.assert_allclose(d_P[:3, 3:], mass * skew(p_PG).T, atol=1e-13)


@pytest.mark.parametrize("vector", [[0, 0, 1.0], [1.0, 0, 0], [0.3, -0.4, 2.0], [0, 1e-3, 0]])
def test_rank2_factors(vector):
    u, v = rank2_factors(vector)
    np.testing.assert_allclose(u @ v.T, skew(vector), atol=1e-15)


def test_angle_tau_maps():
    angles = np.linspace(-np.pi, np.pi, 9)
    np.testing.assert_allclose(4 * np.arctan(angle_to_tau(angles)), angles, atol=1e-14)
    np.testing.assert_allclose(angle_to_tau([np.pi, 3 * np.pi / 2]), [1.0, np.tan(-np.pi / 8)])


@pytest.mark.parametrize("axis", [[0, 1.0, 0], [0, 0, -1.0], [0.2, -0.5, 0.9]])
def test_rotation_lfr_equals_rotation_matrix_on_full_range(axis):
    tau = angle_parameter("tau_test")
    rotation = rotation_matrix_lfr(tau, axis)
    assert rotation.occurrences == {"tau_test": 4}
    angles = np.linspace(-np.pi, np.pi, 73)
    values = static_gain(usubs(rotation, {"tau_test": angle_to_tau(angles)}))
    unit = np.asarray(axis) / np.linalg.norm(axis)
    expected = Rotation.from_rotvec(angles[:, None] * unit).as_matrix()  # independent (scipy)
    np.testing.assert_allclose(values, expected, atol=1e-12)
    np.testing.assert_allclose(rotation_matrix(axis, angles), expected, atol=1e-12)


def test_dcm_and_frame_change_occurrences_and_values():
    tau = angle_parameter("tau_theta1")
    axis = [0.0, 1.0, 0.0]
    dcm = rotation_dcm(tau, axis)
    frame = rotation_frame_change(tau, axis)
    frame_t = rotation_frame_change(tau, axis, transpose=True)
    assert dcm.occurrences == {"tau_theta1": 4}
    assert frame.occurrences == {"tau_theta1": 8}
    assert frame_t.occurrences == {"tau_theta1": 8}
    theta = np.array([-2.5, 0.3, np.pi])
    values = {"tau_theta1": angle_to_tau(theta)}
    r = Rotation.from_rotvec(theta[:, None] * np.array(axis)).as_matrix()
    np.testing.assert_allclose(static_gain(usubs(dcm, values)), np.swapaxes(r, -1, -2), atol=1e-12)
    t = static_gain(usubs(frame, values))
    np.testing.assert_allclose(t[:, :3, :3], np.swapaxes(r, -1, -2), atol=1e-12)
    np.testing.assert_allclose(t[:, 3:, 3:], np.swapaxes(r, -1, -2), atol=1e-12)
    np.testing.assert_allclose(t[:, :3, 3:], 0.0, atol=1e-15)
    np.testing.assert_allclose(
        static_gain(usubs(frame_t, values)), np.swapaxes(t, -1, -2), atol=1e-12
    )


def test_revolute_connection_has_16_occurrences_and_is_t_and_t_transpose():
    tau = angle_parameter("tau_alpha3")
    fixed = Rotation.from_rotvec([0.0, 0.0, np.pi / 2]).as_matrix()
    joint = revolute_connection(tau, [0.0, 1.0, 0.0], dcm_fixed=fixed)
    assert joint.occurrences == {"tau_alpha3": 16}
    alpha = 1.1
    matrix = static_gain(usubs(joint, {"tau_alpha3": np.tan(alpha / 4)}))
    dcm = Rotation.from_rotvec([0.0, alpha, 0.0]).as_matrix().T @ fixed
    t = np.kron(np.eye(2), dcm)
    np.testing.assert_allclose(matrix[:6, :6], t, atol=1e-12)
    np.testing.assert_allclose(matrix[6:, 6:], t.T, atol=1e-12)
    np.testing.assert_allclose(matrix[:6, 6:], 0.0, atol=1e-15)


def test_kinematic_model_with_switched_position():
    from oos_drake.titop import connection_parameter
    from oos_drake.titop.kinematics import kinematic_model_transposed

    d1, d2 = connection_parameter("delta_C1"), connection_parameter("delta_C2")
    v1, v2 = np.array([0.3395, 0.0, 0.0]), np.array([0.0, 0.0, 0.3395])
    tau = kinematic_model(np.zeros(3), [(d1, v1), (d2, v2)])
    tau_t = kinematic_model_transposed(np.zeros(3), [(d1, v1), (d2, v2)])
    assert tau.occurrences == {"delta_C1": 2, "delta_C2": 2}
    assert tau_t.occurrences == {"delta_C1": 2, "delta_C2": 2}
    for c1, c2 in [(1.0, 0.0), (0.0, 1.0), (0.0, 0.0), (0.3, 0.6)]:
        values = {"delta_C1": c1, "delta_C2": c2}
        expected = kinematic_matrix(c1 * v1 + c2 * v2)
        np.testing.assert_allclose(static_gain(usubs(tau, values)), expected, atol=1e-14)
        np.testing.assert_allclose(static_gain(usubs(tau_t, values)), expected.T, atol=1e-14)


def test_bad_inputs_raise_value_errors():
    with pytest.raises(ValueError, match="rotation axis is zero"):
        rotation_matrix([0, 0, 0], 1.0)
    with pytest.raises(ValueError, match="3-vector"):
        kinematic_matrix([1.0, 2.0])
    with pytest.raises(ValueError, match="tau must be a 1x1 LFR"):
        rotation_matrix_lfr(0.3, [0, 0, 1])
    with pytest.raises(ValueError, match="not a valid name"):
        angle_parameter("tau theta")


def test_skew_and_spatial_inertia_are_batched_like_their_single_forms():
    """Batched ``skew``/``rigid_spatial_inertia`` equal the per-item results (parallel axes)."""
    rng = np.random.default_rng(21)
    p = rng.normal(size=(4, 3))
    A = rng.normal(size=(4, 3, 3))
    J = A @ np.swapaxes(A, -1, -2) + np.eye(3)
    S = skew(p)
    D = rigid_spatial_inertia(1.7, J, p)
    assert S.shape == (4, 3, 3) and D.shape == (4, 6, 6)
    u = rng.normal(size=3)
    for k in range(4):
        np.testing.assert_allclose(S[k] @ u, np.cross(p[k], u), atol=1e-14)
        np.testing.assert_allclose(D[k], rigid_spatial_inertia(1.7, J[k], p[k]), atol=1e-13)
        parallel = J[k] + 1.7 * (p[k] @ p[k] * np.eye(3) - np.outer(p[k], p[k]))
        np.testing.assert_allclose(D[k, 3:, 3:], parallel, rtol=1e-13)
    with pytest.raises(ValueError, match="skew"):
        skew([1.0, np.nan, 0.0])
