"""hinfnorm against slycot's AB13DD and closed forms."""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from oos_drake.robust import hinfnorm

slycot = pytest.importorskip("slycot")


def _ab13dd(A, B, C, D):
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    return slycot.ab13dd("C", "I", "N", "D", n, m, p, A, np.eye(n), B, C, D)


def test_random_stable_models_match_ab13dd():
    rng = np.random.default_rng(0)
    for k in range(8):
        n, m, p = 6 + k % 3, 3, 2
        A = rng.standard_normal((n, n))
        A -= (np.max(np.linalg.eigvals(A).real) + 0.05 + k * 0.1) * np.eye(n)  # lightly stable
        B, C = rng.standard_normal((n, m)), rng.standard_normal((p, n))
        D = rng.standard_normal((p, m)) * (k % 2)
        ref, fpeak = _ab13dd(A, B, C, D)
        sys = control.ss(A, B, C, D)
        res = hinfnorm(sys)
        assert_allclose(res.norm, ref, rtol=1e-7)
        assert res.upper >= ref * (1 - 1e-12)


def test_batch_matches_per_model():
    rng = np.random.default_rng(1)
    n, m, p, N = 5, 2, 2, 6
    A = rng.standard_normal((N, n, n)) - 6 * np.eye(n)
    B = rng.standard_normal((N, n, m))
    C = rng.standard_normal((N, p, n))
    D = 0.1 * rng.standard_normal((N, p, m))
    res = hinfnorm((A, B, C, D))
    assert res.norm.shape == (N,)
    for k in range(N):
        assert_allclose(res.norm[k], _ab13dd(A[k], B[k], C[k], D[k])[0], rtol=1e-7)


def test_lightly_damped_mode_peak_and_frequency():
    wn, zeta = 3.0, 0.01  # peak of wn^2/(s^2 + 2 zeta wn s + wn^2): 1/(2 zeta sqrt(1 - zeta^2))
    A = np.array([[0.0, 1.0], [-(wn**2), -2 * zeta * wn]])
    B = np.array([[0.0], [wn**2]])
    C = np.array([[1.0, 0.0]])
    res = hinfnorm((A, B, C, np.zeros((1, 1))))
    assert_allclose(res.norm, 1 / (2 * zeta * np.sqrt(1 - zeta**2)), rtol=1e-8)
    assert_allclose(res.peak_frequency, wn * np.sqrt(1 - 2 * zeta**2), rtol=1e-6)


def test_lfr_model_array_input():
    from oos_drake.lfr import feedback, ureal, usubs

    k = ureal("k", 2.0, plusminus=1.0)
    arr = usubs(feedback(k * control.tf(1, [1, 3, 2]), 1), {"k": np.array([1.0, 2.0, 3.0])})
    ref = [
        hinfnorm(control.ss(control.feedback(kk * control.tf(1, [1, 3, 2]), 1))).norm
        for kk in (1.0, 2.0, 3.0)
    ]
    assert_allclose(hinfnorm(arr).norm, ref, rtol=1e-8)


def test_unstable_is_infinite_and_bad_input_raises():
    res = hinfnorm((np.array([[1.0]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1))))
    assert np.isinf(res.norm)
    with pytest.raises(ValueError, match="non-finite"):
        hinfnorm((np.array([[np.nan]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1))))
    with pytest.raises(ValueError, match="shapes"):
        hinfnorm((-np.eye(2), np.ones((3, 1)), np.ones((1, 2)), np.zeros((1, 1))))
    with pytest.raises(ValueError, match="continuous-time"):
        hinfnorm(control.ss(0.5, 1, 1, 0, dt=0.1))
