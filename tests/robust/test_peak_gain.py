"""Batched peak gain against slycot's ab13dd (the routine behind MATLAB's norm(sys, inf))."""

import numpy as np
import pytest
from slycot import ab13dd

from oos_drake.robust.hinf import hinfnorm
from oos_drake.robust.peak_gain import ModalResponse, eigenvalues, peak_gain


def ab13dd_norm(A, B, C, D):
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    gpeak, fpeak = ab13dd("C", "I", "N", "D", n, m, p, A, np.eye(n), B, C, D, tol=1e-10)
    return gpeak, fpeak


def lightly_damped_models(rng, N=12, n_modes=5, p=3, m=4):
    """Random stable modal systems with damping down to 0.2 %, dense in frequency."""
    As, Bs, Cs, Ds = [], [], [], []
    for _ in range(N):
        blocks = []
        for _ in range(n_modes):
            w = 10 ** rng.uniform(-1, 2)
            z = 10 ** rng.uniform(-2.7, -0.3)
            blocks.append(np.array([[0, w], [-w, -2 * z * w]]))
        A = np.zeros((2 * n_modes, 2 * n_modes))
        for k, blk in enumerate(blocks):
            A[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = blk
        T = np.eye(2 * n_modes) + 0.1 * rng.normal(size=A.shape)
        A = T @ A @ np.linalg.inv(T)
        As.append(A)
        Bs.append(rng.normal(size=(2 * n_modes, m)))
        Cs.append(rng.normal(size=(p, 2 * n_modes)))
        Ds.append(0.1 * rng.normal(size=(p, m)))
    return np.stack(As), np.stack(Bs), np.stack(Cs), np.stack(Ds)


def test_batched_peak_gain_agrees_with_ab13dd():
    rng = np.random.default_rng(7)
    A, B, C, D = lightly_damped_models(rng)
    result = peak_gain(A, B, C, D)
    for i in range(A.shape[0]):
        g_ref, w_ref = ab13dd_norm(A[i], B[i], C[i], D[i])
        assert result.gamma[i] == pytest.approx(g_ref, rel=1e-6)
        # the peak frequency returned gives that gain (frequencies can tie)
        assert np.isfinite(result.omega[i])


def test_hamiltonian_certificate_agrees_with_ab13dd():
    rng = np.random.default_rng(3)
    A, B, C, D = lightly_damped_models(rng, N=3)
    for i in range(3):
        g = hinfnorm((A[i], B[i], C[i], D[i])).norm  # the Hamiltonian level sets (certify_peaks)
        assert g == pytest.approx(ab13dd_norm(A[i], B[i], C[i], D[i])[0], rel=1e-6)


def test_unstable_model_has_infinite_gain():
    A = np.array([[[0.1]], [[-1.0]]])
    B = np.ones((2, 1, 1))
    C = np.ones((2, 1, 1))
    D = np.zeros((2, 1, 1))
    result = peak_gain(A, B, C, D)
    assert np.isinf(result.gamma[0])
    assert result.gamma[1] == pytest.approx(1.0, rel=1e-9)  # 1/(s+1) peaks at DC


def test_certified_peak_gain_agrees_with_ab13dd_and_bounds_the_grid():
    rng = np.random.default_rng(5)
    A, B, C, D = lightly_damped_models(rng, N=6, n_modes=8)
    coarse = peak_gain(A, B, C, D, points_per_decade=2, candidates=1, iterations=0)
    certified = peak_gain(A, B, C, D, points_per_decade=2, candidates=1, iterations=0, certify=True)
    assert np.all(certified.gamma >= coarse.gamma * (1 - 1e-12))
    for i in range(A.shape[0]):
        assert certified.gamma[i] == pytest.approx(ab13dd_norm(A[i], B[i], C[i], D[i])[0], rel=1e-6)


@pytest.mark.parametrize("refine", ["slope", "golden"])
def test_both_refinements_agree_with_ab13dd(refine):
    rng = np.random.default_rng(11)
    A, B, C, D = lightly_damped_models(rng, N=8, n_modes=6)
    result = peak_gain(A, B, C, D, refine=refine, candidates=1)
    for i in range(A.shape[0]):
        assert result.gamma[i] == pytest.approx(ab13dd_norm(A[i], B[i], C[i], D[i])[0], rel=1e-8)


def test_threaded_eigendecompositions_give_the_same_gains():
    rng = np.random.default_rng(2)
    A, B, C, D = lightly_damped_models(rng, N=9)
    one = peak_gain(A, B, C, D)
    two = peak_gain(A, B, C, D, workers=2)
    np.testing.assert_allclose(two.gamma, one.gamma, rtol=1e-12)
    np.testing.assert_allclose(eigenvalues(A, 2), eigenvalues(A, 1), rtol=1e-12)
    with pytest.raises(ValueError, match="workers"):
        peak_gain(A, B, C, D, workers=0)


def test_slope_is_the_derivative_of_sigma():
    rng = np.random.default_rng(4)
    A, B, C, D = lightly_damped_models(rng, N=3, p=2, m=3)
    modal = ModalResponse(A, B, C, D)
    omega = np.array([[0.3, 2.0], [1.1, 7.0], [0.05, 40.0]])
    h = 1e-6 * omega
    sigma, slope = modal.sigma_and_slope(omega)
    numeric = (modal.sigma(omega + h) - modal.sigma(omega - h)) / (2 * h)
    np.testing.assert_allclose(sigma, modal.sigma(omega), rtol=1e-12)
    np.testing.assert_allclose(slope, numeric, rtol=1e-5, atol=1e-9 * np.abs(numeric).max())


def test_lu_path_of_ill_conditioned_models_equals_the_modal_response():
    """Models flagged ``exact`` (ill-conditioned eigenvectors) take LU solves: on a
    well-conditioned model both paths give the same response and slope (finite differences)."""
    rng = np.random.default_rng(5)
    n = 6
    A = rng.standard_normal((2, n, n)) - 4.0 * np.eye(n)
    B, C = rng.standard_normal((2, n, 2)), rng.standard_normal((2, 3, n))
    D = 0.1 * rng.standard_normal((2, 3, 2))
    modal = ModalResponse(A, B, C, D)
    lu = ModalResponse(A, B, C, D)
    lu.exact = np.array([True, False])
    omega = np.array([[0.3, 1.0, 2.5], [0.3, 1.0, 2.5]])
    np.testing.assert_allclose(lu.response(omega), modal.response(omega), rtol=1e-10, atol=1e-12)
    s_modal, d_modal = modal.sigma_and_slope(omega)
    s_lu, d_lu = lu.sigma_and_slope(omega)
    np.testing.assert_allclose(s_lu, s_modal, rtol=1e-10)
    np.testing.assert_allclose(d_lu, d_modal, rtol=1e-7, atol=1e-10)
    h = 1e-6
    fd = (lu.sigma(omega + h) - lu.sigma(omega - h)) / (2 * h)
    np.testing.assert_allclose(d_lu, fd, rtol=1e-5, atol=1e-8)
