"""Batched peak gain against slycot's ab13dd (the routine behind MATLAB's norm(sys, inf))."""

import numpy as np
import pytest
from slycot import ab13dd

from oos_drake.control.peak_gain import hinfnorm_hamiltonian, peak_gain


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
        g, _ = hinfnorm_hamiltonian(A[i], B[i], C[i], D[i])
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
