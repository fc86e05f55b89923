"""The uncertain analysis closed loop against plants perturbed by hand."""

import numpy as np
import pytest

from oos_drake.control.analysis_model import closed_loop_lfr
from oos_drake.control.baseline import baseline_gains
from oos_drake.control.interconnection import plant_statespace, weighted_interconnection
from oos_drake.control.plants import flexible_rotational_plant
from oos_drake.lfr import usubs

J = np.array([[120.0, 5.0, 0.0], [5.0, 150.0, -3.0], [0.0, -3.0, 100.0]])
L = np.array([[3.0, 0.5], [0.2, 2.5], [0.4, -0.3]])
OMEGA = np.array([0.0, 0.05, 0.4, 3.0, 40.0])


@pytest.fixture(scope="module")
def setup():
    A, B, C, D = flexible_rotational_plant(J - L @ L.T, L, [8.0, 20.0], 0.01)
    K = baseline_gains(J) * np.array([20, 20, 20, 4, 4, 4])
    return (A, B, C, D), K, closed_loop_lfr(plant_statespace(A, B, C, D), K)


def zeros_for(M):
    return {name: np.zeros(spec.shape) for name, spec in M.uncertainty.items()}


def test_blocks_are_the_paper_analysis_uncertainties(setup):
    _, _, M = setup
    assert M.uncertainty["Delta_add"].shape == (3, 3)
    names = {n for n in M.uncertainty if n.startswith("mul_")}
    assert names == {f"mul_{a}{b}" for a in "xyz" for b in "xyz"}


def test_nominal_equals_the_synthesis_closed_loop(setup):
    (A, B, C, D), K, M = setup
    nominal = usubs(M, zeros_for(M), normalized=True)
    ref = weighted_interconnection(plant_statespace(A, B, C, D)).close(K)
    np.testing.assert_allclose(nominal.freqresp(OMEGA), ref.freqresp(OMEGA), atol=1e-10)


def test_static_uncertainty_values_equal_perturbed_plants(setup):
    (A, B, C, D), K, M = setup
    rng = np.random.default_rng(2)
    delta_add = rng.uniform(-1, 1, (3, 3)) / 3
    values = zeros_for(M)
    values["Delta_add"] = delta_add
    values["mul_xy"] = np.array([[0.7]])
    values["mul_zz"] = np.array([[-0.5]])
    perturbed = usubs(M, values, normalized=True)
    # by hand: P_hat = P (I + W_mul E) + W_add Delta_add
    E = np.zeros((3, 3))
    E[0, 1] = 4e-3 * 0.7
    E[2, 2] = 4e-2 * -0.5
    W_add = 10 ** (-75 / 20)
    P_hat = plant_statespace(A, B @ (np.eye(3) + E), C, D @ (np.eye(3) + E) + W_add * delta_add)
    ref = weighted_interconnection(P_hat).close(K)
    np.testing.assert_allclose(perturbed.freqresp(OMEGA), ref.freqresp(OMEGA), atol=1e-10)
