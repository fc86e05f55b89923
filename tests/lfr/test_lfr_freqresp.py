"""Batched frequency response against python-control and closed forms."""

import control
import numpy as np
from lfr_helpers import assert_response_close, control_response, random_ss

from oos_drake.lfr import LFR, freqresp

OMEGA = np.logspace(-2, 2, 37)


def test_matches_control_for_random_batch():
    rng = np.random.default_rng(0)
    systems = [random_ss(rng, 6, 2, 3) for _ in range(5)]
    batch = LFR.from_ss(
        np.stack([s.A for s in systems]),
        np.stack([s.B for s in systems]),
        np.stack([s.C for s in systems]),
        np.stack([s.D for s in systems]),
    )
    resp = freqresp(batch, OMEGA)
    assert resp.shape == (5, OMEGA.size, 2, 3)
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], control_response(sys, OMEGA), rtol=1e-10)


def test_defective_matrix_uses_exact_fallback():
    # Jordan block: double pole at -1 (eigenvectors degenerate) and a double integrator
    A = np.array([[-1.0, 1.0, 0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0], [0, 0, 0, 0]])
    B = np.array([[0.0], [1.0], [0.0], [1.0]])
    C = np.array([[1.0, 0.0, 1.0, 0.0]])
    sys = LFR.from_ss(A, B, C, np.zeros((1, 1)))
    s = 1j * OMEGA
    expected = 1 / (s + 1) ** 2 + 1 / s**2
    np.testing.assert_allclose(sys.freqresp(OMEGA)[:, 0, 0], expected, rtol=1e-12)


def test_static_and_empty_cases():
    gain = LFR.from_matrix(np.array([[1.0, 2.0]]))
    np.testing.assert_allclose(
        gain.freqresp(OMEGA), np.broadcast_to([[1.0, 2.0]], (OMEGA.size, 1, 2))
    )
    sys = control.tf([1.0], [1.0, 0.4, 4.0])  # lightly damped, resonance at 2 rad/s
    lfr_sys = LFR.from_ss(*control.ssdata(control.ss(sys)))
    s = 1j * OMEGA
    np.testing.assert_allclose(
        lfr_sys.freqresp(OMEGA)[:, 0, 0], 1 / (s**2 + 0.4 * s + 4), rtol=1e-12
    )


def test_chunking_gives_same_result(monkeypatch):
    rng = np.random.default_rng(2)
    systems = [random_ss(rng, 5, 1, 1) for _ in range(9)]
    batch = LFR.from_ss(
        np.stack([s.A for s in systems]),
        np.stack([s.B for s in systems]),
        np.stack([s.C for s in systems]),
        np.stack([s.D for s in systems]),
    )
    full = freqresp(batch, OMEGA)
    import oos_drake.lfr.frequency as fr

    monkeypatch.setattr(fr, "CHUNK_ENTRIES", 1)
    np.testing.assert_allclose(fr.freqresp(batch, OMEGA), full, rtol=1e-14)
