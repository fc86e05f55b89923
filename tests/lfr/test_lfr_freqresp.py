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


def test_integrator_tail_paths_match_direct_solve():
    """Rigid-body-like outputs (integrator chains) with stable, slow and defective cores."""
    import oos_drake.lfr.frequency as fr

    rng = np.random.default_rng(5)
    cores = [
        random_ss(rng, 4, 2, 2).A - 5.0 * np.eye(4),  # |poles| >= 5: partial fractions
        np.array([[-1e-4, 1.0], [0.0, -2.0]]),  # slow pole: augmented path
        np.array([[-1.0, 1.0], [0.0, -1.0]]),  # defective core: clustered path
    ]
    for A11 in cores:
        m = A11.shape[0]
        n = m + 3
        A = np.zeros((n, n))
        A[:m, :m] = A11
        A[m:, :m] = rng.standard_normal((3, m))
        A[m + 1, m] = 1.0
        A[m + 2, m + 1] = 1.0  # chain of three integrators
        B = rng.standard_normal((n, 2))
        C = rng.standard_normal((2, n))
        D = rng.standard_normal((2, 2))
        sys = LFR.from_ss(A, B, C, D)
        core, tail, q = fr._integrator_tail(A[None])
        assert tail.size == 3 and q == 3
        if A11.shape[0] == 4:  # this core takes the partial-fraction path
            assert (OMEGA.max() / np.abs(np.linalg.eigvals(A11)).min()) ** q < 1e6
        expected = fr._direct_response(A, B, C, D, 1j * OMEGA)
        np.testing.assert_allclose(sys.freqresp(OMEGA), expected, rtol=1e-9, atol=1e-12)


def test_clustered_path_for_defective_eigenvalues_inside_the_spectrum(monkeypatch):
    import oos_drake.lfr.frequency as fr

    rng = np.random.default_rng(8)
    R = random_ss(rng, 4, 1, 1).A
    A = np.zeros((6, 6))
    A[:2, :2] = [[-0.5, 1.0], [0.0, -0.5]]  # Jordan block (defective)
    A[2:, 2:] = R
    A[:2, 2:] = rng.standard_normal((2, 4))
    A[2:, :2] = 0.0  # keep the Jordan block exact
    T = np.linalg.qr(rng.standard_normal((6, 6)))[0]  # hide the structure from the pattern
    A = T @ A @ T.T
    B = rng.standard_normal((6, 2))
    C = rng.standard_normal((3, 6))
    D = np.zeros((3, 2))
    core, tail, _ = fr._integrator_tail(A[None])
    assert tail.size == 0
    lam, V = np.linalg.eig(A)
    X = np.linalg.solve(V, fr._probes(6))
    kappa = np.sqrt(6) * np.max(np.abs(X), axis=1) * np.linalg.norm(V, axis=0)
    assert 0 < np.sum(kappa > fr.EIG_COND_LIMIT) < 6  # a proper cluster is flagged
    expected = fr._direct_response(A, B, C, D, 1j * OMEGA)

    def no_fallback(*args, **kwargs):
        raise AssertionError("the clustered path should handle this model")

    monkeypatch.setattr(fr, "_direct_response", no_fallback)
    sys = LFR.from_ss(np.stack([A, A]), B, C, D)
    np.testing.assert_allclose(sys.freqresp(OMEGA), np.stack([expected, expected]), rtol=1e-9)
