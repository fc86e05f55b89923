"""The Apkarian-Noll gradient of the peak gain against central finite differences."""

import numpy as np
import pytest

from oos_drake.control.baseline import baseline_gains
from oos_drake.control.interconnection import plant_statespace, weighted_interconnection
from oos_drake.control.objective import evaluate, peak_gradients
from oos_drake.control.plants import flexible_rotational_plant

J = np.array([[150.0, 6.0, 0.0], [6.0, 190.0, -2.0], [0.0, -2.0, 130.0]])
L = np.array([[3.0, 0.5], [0.2, 2.5], [0.4, -0.3]])


@pytest.fixture(scope="module")
def problem():
    A, B, C, D = flexible_rotational_plant(
        np.stack([J, 1.4 * J]) - L @ L.T, L, np.array([[9.0, 25.0], [8.0, 22.0]]), 0.01
    )
    W = weighted_interconnection(plant_statespace(A, B, C, D))
    K = baseline_gains(J) * np.array([12, 12, 12, 3, 3, 3])
    K = K + 0.05 * np.abs(K).mean() * np.random.default_rng(0).normal(size=K.shape)
    return W, K


def test_gradient_matches_finite_differences(problem):
    W, K = problem
    ev = evaluate(W, K, focus=None)
    assert np.isfinite(ev.gamma)
    rng = np.random.default_rng(1)
    scale = np.abs(K).mean()
    for _ in range(3):
        direction = rng.normal(size=K.shape) * scale
        h = 1e-6
        fd = (
            evaluate(W, K + h * direction, focus=None).gamma
            - evaluate(W, K - h * direction, focus=None).gamma
        ) / (2 * h)
        assert np.sum(ev.gradient * direction) == pytest.approx(fd, rel=1e-4, abs=1e-9 * scale)


def test_gradient_at_fixed_frequency_matches_finite_differences(problem):
    W, K = problem
    omega = np.array([0.05, 0.7, 3.0])
    index = np.array([0, 1, 1])
    s0, grads = peak_gradients(W, K, index, omega)
    E = np.zeros((3, 6))
    E[1, 4] = 1.0
    h = 1e-5
    sp, _ = peak_gradients(W, K + h * E, index, omega)
    sm, _ = peak_gradients(W, K - h * E, index, omega)
    np.testing.assert_allclose(grads[:, 1, 4], (sp - sm) / (2 * h), rtol=1e-5)
