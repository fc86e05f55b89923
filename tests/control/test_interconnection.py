"""The weighted interconnection against the same diagram built independently with python-control."""

import control
import numpy as np
import pytest

from oos_drake.control.baseline import baseline_gains
from oos_drake.control.interconnection import (
    DISTURBANCES,
    ERRORS,
    plant_statespace,
    weighted_interconnection,
)
from oos_drake.control.plants import flexible_rotational_plant

J = np.array([[120.0, 5.0, 0.0], [5.0, 150.0, -3.0], [0.0, -3.0, 100.0]])
L = np.array([[3.0, 0.5], [0.2, 2.5], [0.4, -0.3]])


def reference_closed_loop(plant: control.StateSpace, K):
    """Fig. controldesign with python-control's interconnect (independent of our connect)."""
    I3 = np.eye(3)
    sig = lambda name: [f"{name}[{i}]" for i in range(3)]  # noqa: E731
    P = control.ss(plant.A, plant.B, plant.C, plant.D, inputs=sig("T"), outputs=sig("wdot"))
    s = control.tf("s")
    integ1 = control.ss(control.tf(1, [1, 0]) * I3, inputs=sig("wdot"), outputs=sig("w"))
    integ2 = control.ss(control.tf(1, [1, 0]) * I3, inputs=sig("w"), outputs=sig("phi"))
    w8, w200 = 2 * np.pi * 8, 2 * np.pi * 200
    sst = control.ss(1 / (s / w8 + 1) * I3, inputs=sig("phi"), outputs=sig("phi_m"))
    gyro = control.ss(1 / (s / w200 + 1) * I3, inputs=sig("w"), outputs=sig("w_m"))
    rw = control.ss(
        w200**2 / (s**2 + 1.4 * w200 * s + w200**2) * I3, inputs=sig("u"), outputs=sig("T_rw")
    )
    import scipy.signal

    b, a = scipy.signal.butter(4, 2 * np.pi * 0.7, analog=True)
    ro = control.ss(control.tf(b, a) * I3, inputs=sig("u_K"), outputs=sig("u"))
    wext = control.ss(
        control.tf([1], [2.236, 0.2236]) * np.diag([0.002577, 0.009685, 0.01239]),
        inputs=sig("d_ext"),
        outputs=sig("T_dist"),
    )
    sum_T = control.summing_junction(inputs=["T_rw", "T_dist"], output="T", dimension=3)
    ctrl = control.ss(
        [], [], [], np.asarray(K), inputs=sig("y_att") + sig("y_rate"), outputs=sig("u_K")
    )
    meas_att = control.ss(
        [],
        [],
        [],
        np.hstack([-I3, -1.5343e-5 * I3]),
        inputs=sig("phi_m") + sig("n_sst"),
        outputs=sig("y_att"),
    )
    meas_rate = control.ss(
        [],
        [],
        [],
        np.hstack([-I3, -9.1987e-4 * I3]),
        inputs=sig("w_m") + sig("n_gyro"),
        outputs=sig("y_rate"),
    )
    e_p = control.ss([], [], [], I3 / 0.0079, inputs=sig("phi"), outputs=sig("e_p"))
    e_u = control.ss([], [], [], 0.5 * I3, inputs=sig("u"), outputs=sig("e_u"))
    return control.interconnect(
        [P, integ1, integ2, sst, gyro, rw, ro, wext, sum_T, ctrl, meas_att, meas_rate, e_p, e_u],
        inputs=sig("d_ext") + sig("n_sst") + sig("n_gyro"),
        outputs=sig("e_p") + sig("e_u"),
    )


def test_closed_loop_matches_python_control_interconnect():
    A, B, C, D = flexible_rotational_plant(J - L @ L.T, L, [8.0, 20.0], 0.01)
    plant = plant_statespace(A, B, C, D)
    K = baseline_gains(J) * np.array([20, 20, 20, 4, 4, 4])
    K[0, 4] = 3.0  # a cross-axis gain
    mine = weighted_interconnection(plant).close(K)
    ref = reference_closed_loop(control.ss(A, B, C, D), K)
    omega = np.array([0.0, 0.01, 0.3, 2.0, 8.0, 30.0, 500.0])
    H_ref = np.moveaxis(ref(1j * omega), -1, 0)
    np.testing.assert_allclose(mine.freqresp(omega), H_ref, rtol=1e-8, atol=1e-12)
    assert mine.inputs == DISTURBANCES and mine.outputs == ERRORS


def test_batched_plants_give_batched_interconnection():
    A, B, C, D = flexible_rotational_plant(np.stack([J, 2 * J]) - L @ L.T, L, [8.0, 20.0], 0.01)
    W = weighted_interconnection(plant_statespace(A, B, C, D))
    assert W.system.batch_shape == (2,)
    single = weighted_interconnection(plant_statespace(A[1], B[1], C[1], D[1]))
    np.testing.assert_allclose(W.system.A[1], single.system.A)


def test_wrong_gain_shape_is_refused():
    A, B, C, D = flexible_rotational_plant(J - L @ L.T, L, [8.0, 20.0], 0.01)
    W = weighted_interconnection(plant_statespace(A, B, C, D))
    with pytest.raises(ValueError, match="3x6"):
        W.close(np.zeros((3, 3)))
