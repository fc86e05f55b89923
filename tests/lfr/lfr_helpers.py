"""Shared helpers for the LFR tests: random systems and response comparison."""

from __future__ import annotations

import control
import numpy as np


def random_ss(rng: np.random.Generator, n: int, ny: int, nu: int, *, d_scale: float = 0.3):
    """Random stable continuous-time ``control.StateSpace`` (eigenvalues in Re < -0.1)."""
    A = rng.standard_normal((n, n))
    shift = np.max(np.linalg.eigvals(A).real) + 0.1 + rng.uniform(0.0, 1.0) if n else 0.0
    A = A - shift * np.eye(n)
    B = rng.standard_normal((n, nu))
    C = rng.standard_normal((ny, n))
    D = d_scale * rng.standard_normal((ny, nu))
    return control.ss(A, B, C, D)


def control_response(sys, omega) -> np.ndarray:
    """python-control frequency response as an ``(F, ny, nu)`` array (independent path)."""
    sys = control.ss(sys)
    resp = control.frequency_response(sys, omega, squeeze=False)
    return np.moveaxis(np.asarray(resp.complex), -1, 0)


def assert_response_close(actual, expected, rtol=1e-9):
    """Per-frequency norm-wise relative agreement."""
    actual = np.asarray(actual)
    expected = np.asarray(expected)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    err = np.linalg.norm((actual - expected).reshape(actual.shape[0], -1), axis=1)
    ref = np.linalg.norm(expected.reshape(expected.shape[0], -1), axis=1)
    worst = np.max(err / np.maximum(ref, 1e-300))
    assert worst <= rtol, f"relative error {worst:.3g} > {rtol:.1g}"
