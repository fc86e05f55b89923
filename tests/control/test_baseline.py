"""Baseline controller: the paper's formula and the closed-loop poles it places on a rigid body."""

import numpy as np
import pytest

from oos_drake.control.baseline import OMEGA_ATT, baseline_gains, inertia_from_plant
from oos_drake.control.interconnection import plant_statespace
from oos_drake.control.plants import flexible_rotational_plant

J = np.array([[300.0, 12.0, -4.0], [12.0, 410.0, 6.0], [-4.0, 6.0, 280.0]])


def test_gains_are_the_paper_formula():
    K = baseline_gains(J)
    w = 2 * np.pi * 0.01
    np.testing.assert_allclose(K[:, :3], w**2 * J, rtol=1e-15)
    np.testing.assert_allclose(K[:, 3:], 2 * 1.0 * w * J, rtol=1e-15)
    assert OMEGA_ATT == pytest.approx(0.0628318530718, rel=1e-12)


def test_rigid_loop_is_critically_damped_at_omega_att():
    # J phi'' = -K_p phi - K_d phi'  ->  phi'' + 2 w phi' + w^2 phi = 0: double poles at -w
    K = baseline_gains(J)
    A = np.block(
        [
            [np.zeros((3, 3)), np.eye(3)],
            [-np.linalg.solve(J, K[:, :3]), -np.linalg.solve(J, K[:, 3:])],
        ]
    )
    poles = np.linalg.eigvals(A)
    np.testing.assert_allclose(poles.real, -OMEGA_ATT, rtol=1e-5)
    np.testing.assert_allclose(poles.imag, 0.0, atol=1e-5)


def test_inertia_from_flexible_plant_is_total_inertia():
    L = np.array([[4.0, 1.0], [0.5, 3.0], [0.2, 0.1]])
    A, B, C, D = flexible_rotational_plant(J - L @ L.T, L, [7.0, 19.0], 0.02)
    np.testing.assert_allclose(inertia_from_plant(plant_statespace(A, B, C, D)), J, rtol=1e-10)


def test_bad_inertia_is_refused():
    with pytest.raises(ValueError, match="J_tot"):
        baseline_gains(-J)
