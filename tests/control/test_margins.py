"""Loop-at-a-time and disk margins against closed forms, python-control and brute force."""

import control
import numpy as np
import pytest

from oos_drake.control.margins import disk_gain_phase, loop_at_a_time, margins


def _diag_loop(systems):
    """``L = diag(l_1, l_2, l_3)`` from SISO python-control systems (continuous)."""

    def loop(omega):
        omega = np.atleast_1d(omega)
        out = np.zeros((omega.size, 3, 3), dtype=complex)
        for i, sys in enumerate(systems):
            out[:, i, i] = sys(1j * omega) if sys.isctime() else sys(np.exp(1j * omega * sys.dt))
        return out

    return loop


def test_siso_margins_against_closed_forms_and_python_control():
    """``l = k / (s + 1)^3``: phase crossover at sqrt(3) rad/s with ``|l| = k / 8``."""
    s = control.tf("s")
    gains = (2.0, 4.0, 1.5)
    systems = [k / (s + 1) ** 3 for k in gains]
    omega = np.geomspace(1e-3, 1e2, 800)
    m = margins(_diag_loop(systems), omega)
    for i, k in enumerate(gains):
        np.testing.assert_allclose(m.gain_upper_db[i], 20 * np.log10(8 / k), atol=1e-6)
        np.testing.assert_allclose(m.gain_upper_hz[i] * 2 * np.pi, np.sqrt(3), rtol=1e-7)
        wc = np.sqrt(k ** (2 / 3) - 1)  # |l(j wc)| = 1
        pm = 180 - 3 * np.degrees(np.arctan(wc))
        np.testing.assert_allclose(m.crossover_hz[i] * 2 * np.pi, wc, rtol=1e-7)
        np.testing.assert_allclose(m.phase_deg[i], pm, atol=1e-6)
        np.testing.assert_allclose(m.delay_s[i], np.radians(pm) / wc, rtol=1e-6)
        gm, pm_pc, _, wpc, wgc, _ = control.stability_margins(systems[i])
        np.testing.assert_allclose(m.gain_upper_db[i], 20 * np.log10(gm), atol=1e-5)
        np.testing.assert_allclose(m.phase_deg[i], pm_pc, atol=1e-5)
        # disk margin: python-control's balanced disk margin as a second method
        dm, _, _ = control.disk_margins(systems[i], np.geomspace(0.5, 3.0, 4000))
        np.testing.assert_allclose(m.disk[i], dm, rtol=1e-4)
    # decoupled channels: the multiloop margin is the smallest loop-at-a-time margin
    np.testing.assert_allclose(m.multiloop_disk, m.disk.min(), rtol=1e-4)


def test_discrete_loop_margins_against_python_control():
    """A sampled loop (ZOH double integrator with a discrete PD) up to the Nyquist frequency."""
    T = 0.1
    plant = control.c2d(control.tf([1.0], [1.0, 0.0, 0.0]), T, "zoh")
    z = control.tf([1.0, 0.0], [1.0], T)
    systems = [k * plant * (1.0 + 4.0 * (z - 1) / (z + 0.2)) for k in (0.05, 0.1, 0.2)]
    omega = np.geomspace(1e-3, np.pi / T, 3000)
    m = margins(_diag_loop(systems), omega)
    for i, sys in enumerate(systems):
        gm, pm, _, _, wgc, _ = control.stability_margins(sys)
        np.testing.assert_allclose(m.phase_deg[i], pm, atol=1e-4)
        np.testing.assert_allclose(m.crossover_hz[i] * 2 * np.pi, wgc, rtol=1e-5)
        if np.isfinite(gm):
            np.testing.assert_allclose(m.gain_upper_db[i], 20 * np.log10(gm), atol=1e-4)


def _complex_gain_unstable(A, B, C, D, F) -> bool:
    """Closed loop ``u = -F y`` of ``(A, B, C, D)`` with a (complex) gain matrix ``F``."""
    n = D.shape[0]
    feed = np.linalg.solve(np.eye(n) + F @ D, F)
    return bool(np.max(np.linalg.eigvals(A - B @ feed @ C).real) >= 0)


def test_siso_disk_margin_against_brute_force_over_the_disk():
    """Sweep the gain ``f = (1 + d/2)/(1 - d/2)`` over complex ``|d| <= r``: every ``f`` is
    stabilizing for ``r`` just below ``alpha``, some ``f`` is not just above it."""
    s = control.tf("s")
    sys = control.ss(3.0 * (s + 0.5) / (s * (s + 1) * (s + 2)))
    systems = [control.tf(sys)] * 3
    m = margins(_diag_loop(systems), np.geomspace(1e-3, 1e2, 1500))
    alpha = m.disk[0]
    A, B, C, D = (np.asarray(x, dtype=complex) for x in (sys.A, sys.B, sys.C, sys.D))

    def any_unstable(r):
        radii = np.linspace(0, r, 12)[1:]
        angles = np.linspace(0, 2 * np.pi, 721)
        for rr in radii:
            d = rr * np.exp(1j * angles)
            for f in (1 + d / 2) / (1 - d / 2):
                if _complex_gain_unstable(A, B, C, D, np.array([[f]])):
                    return True
        return False

    assert not any_unstable(0.99 * alpha)
    assert any_unstable(1.01 * alpha)
    gain_db, phase_deg = disk_gain_phase(alpha)
    assert gain_db == pytest.approx(20 * np.log10((2 + alpha) / (2 - alpha)))
    assert phase_deg == pytest.approx(np.degrees(2 * np.arctan(alpha / 2)))


def test_multiloop_disk_margin_against_brute_force():
    """A coupled 3x3 loop: independent disk gains in each channel, with equal magnitudes (the
    worst case of complex scalar mu) swept over a grid of phases."""
    rng = np.random.default_rng(3)
    n = 4
    A = -np.diag([0.5, 1.0, 2.0, 3.0])  # stable open loop, coupled through B and C
    B = rng.normal(size=(n, 3))
    C = rng.normal(size=(3, n))
    D = np.zeros((3, 3))
    sys = control.ss(A, B, C, D)
    scale = 1.0  # largest power of 1/2 that leaves the nominal closed loop stable
    for _ in range(30):
        if not _complex_gain_unstable(A, scale * B, C, D, np.eye(3)):
            break
        scale *= 0.5
    assert not _complex_gain_unstable(A, scale * B, C, D, np.eye(3))

    def loop(omega):
        omega = np.atleast_1d(omega)
        X = np.linalg.solve(
            1j * omega[:, None, None] * np.eye(n) - A, np.broadcast_to(B, (omega.size, n, 3))
        )
        return scale * (C @ X)

    m = margins(loop, np.geomspace(1e-3, 1e3, 3000))
    assert m.multiloop_disk <= m.disk.min() * (1 + 1e-9)
    assert m.multiloop_disk <= m.multiloop_disk_max * (1 + 1e-9)
    phases = np.linspace(0, 2 * np.pi, 37)[:-1]
    Ac, Bc, Cc, Dc = A.astype(complex), scale * B.astype(complex), C.astype(complex), D

    def any_unstable(r):
        for p1 in phases:
            for p2 in phases:
                for p3 in phases[::2]:
                    d = r * np.exp(1j * np.array([p1, p2, p3]))
                    F = np.diag((1 + d / 2) / (1 - d / 2))
                    if _complex_gain_unstable(Ac, Bc, Cc, Dc, F):
                        return True
        return False

    assert not any_unstable(0.97 * m.multiloop_disk)
    assert any_unstable(1.03 * m.multiloop_disk_max)
    assert sys.nstates == n


def test_loop_at_a_time_closes_the_other_channels():
    L = np.array([[[0.5, 0.2, 0.0], [0.1, 2.0, 0.3], [0.0, -0.4, 1.0]]], dtype=complex)
    l1 = loop_at_a_time(L)[0, 0]
    rest = L[0, 1:, 1:]
    expected = L[0, 0, 0] - L[0, 0, 1:] @ np.linalg.solve(np.eye(2) + rest, L[0, 1:, 0])
    assert l1 == pytest.approx(expected)


def test_bad_grid():
    with pytest.raises(ValueError, match="omega"):
        margins(lambda w: np.zeros((np.size(w), 3, 3)), np.array([1.0, 0.5, 2.0]))
