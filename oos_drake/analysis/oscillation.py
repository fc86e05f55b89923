r"""Decay rate and frequency of the dominant oscillation of a sampled response (matrix pencil).

A free response of a linear(ized) system sampled every ``dt`` is a sum of damped exponentials
``y_k = sum_i r_i z_i^k`` with ``z_i = exp(s_i dt)``. The matrix pencil method (Hua and Sarkar,
IEEE Trans. ASSP 38(5), 1990) finds the ``z_i`` from the Hankel matrices of the samples: with the
SVD ``Y = U S V^H`` truncated to the ``m`` significant singular values and ``V_1``, ``V_2`` the
right singular vectors without their last and first row, the ``z_i`` are the eigenvalues of
``V_1^+ V_2``. Several channels (the three attitude axes) share the poles: their Hankel matrices
are stacked. The residues ``r_i`` come from a least-squares fit of the Vandermonde matrix.

The *dominant oscillation* is the pole with positive frequency (at least ``f_min``) whose
contribution is the largest at the end of the window: after the transient it is the least
damped oscillation that the initial disturbance excited, the one whose decay rate decides
whether the loop is stable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Oscillation", "dominant_oscillation", "pencil_poles"]


@dataclass(frozen=True)
class Oscillation:
    """The dominant oscillation of a response.

    Attributes
    ----------
    frequency : float
        Damped frequency [Hz].
    decay_rate : float
        Real part of the pole [1/s] (``> 0``: growing, the loop is unstable).
    amplitude : float
        Magnitude of the oscillation at the end of the window (norm over channels) [signal
        unit].
    fit_error : float
        Relative RMS error of the fitted sum of exponentials [-].
    """

    frequency: float
    decay_rate: float
    amplitude: float
    fit_error: float

    @property
    def damping_ratio(self) -> float:
        """``-sigma / |s|`` [-]."""
        omega = 2.0 * np.pi * self.frequency
        return float(-self.decay_rate / np.hypot(self.decay_rate, omega))


def pencil_poles(signal: np.ndarray, dt: float, *, rtol: float = 1e-6, max_order: int = 24):
    """Continuous poles ``s_i`` [1/s] and residues of a sampled multichannel signal.

    Parameters
    ----------
    signal : ndarray, shape (n,) or (n, channels)
        Uniformly sampled response.
    dt : float
        Sample period [s].
    rtol : float
        Singular values below ``rtol`` times the largest are noise (they set the order).
    max_order : int
        Largest number of poles.

    Returns
    -------
    poles : ndarray, complex, shape (m,)
    residues : ndarray, complex, shape (m, channels)
    fit_error : float
        Relative RMS error of the fit [-].
    """
    y = np.asarray(signal, dtype=float)
    y = y[:, None] if y.ndim == 1 else y
    n = y.shape[0]
    if n < 8 or not np.all(np.isfinite(y)):
        raise ValueError(f"matrix pencil: need at least 8 finite samples, got {n}")
    if not dt > 0:
        raise ValueError(f"matrix pencil: sample period must be > 0 s, got {dt}")
    L = n // 2
    Y = np.vstack(
        [np.lib.stride_tricks.sliding_window_view(y[:, c], L + 1) for c in range(y.shape[1])]
    )
    _, S, Vh = np.linalg.svd(Y, full_matrices=False)
    if S[0] == 0.0:
        raise ValueError("matrix pencil: the signal is identically zero")
    m = int(min(max_order, np.sum(S > rtol * S[0])))
    V = Vh[:m].conj().T  # (L + 1, m)
    z = np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:])
    vandermonde = z[None, :] ** np.arange(n)[:, None]
    residues, *_ = np.linalg.lstsq(vandermonde, y.astype(complex), rcond=None)
    error = np.linalg.norm(vandermonde @ residues - y) / max(np.linalg.norm(y), 1e-300)
    return np.log(z.astype(complex)) / dt, residues, float(error)


def dominant_oscillation(
    time,
    signal,
    *,
    f_min: float = 0.02,
    near_hz: float | None = None,
    rtol: float = 1e-6,
    max_order: int = 24,
    max_samples: int = 1500,
) -> Oscillation:
    """Frequency and decay rate of the oscillation that dominates the end of ``signal``.

    Parameters
    ----------
    time : array_like, shape (n,)
        Uniform sample times [s].
    signal : array_like, shape (n,) or (n, channels)
        Response after the transient (e.g. the attitude error [rad]).
    f_min : float
        Lowest frequency counted as an oscillation [Hz] (slower poles are drifts).
    near_hz : float, optional
        Expected frequency [Hz]: when oscillations within 25 % of it are found, the largest of
        them is returned (a slower, larger mode decaying beside a growing critical one must not
        decide the verdict); otherwise the largest of all.
    rtol, max_order
        See :func:`pencil_poles`.
    max_samples : int
        A longer signal is averaged over blocks of consecutive samples down to at most this
        many (the pencil's SVD grows with the square of the length). A block average keeps
        every pole ``s_i``: each ``r_i z_i^k`` becomes ``r_i z_i^k`` times the constant
        ``(1 + z_i + ... + z_i^(b-1)) / b``; it damps the fast modes' residues.

    Raises
    ------
    ValueError
        Non-uniform times, too few samples, or no oscillation above ``f_min``.
    """
    t = np.asarray(time, dtype=float)
    steps = np.diff(t)
    if t.ndim != 1 or t.size < 8 or np.ptp(steps) > 1e-6 * steps.mean():
        raise ValueError("dominant_oscillation: times must be uniform, at least 8 samples")
    dt = float(steps.mean())
    y = np.asarray(signal, dtype=float)
    block = -(-t.size // max_samples)  # ceil
    if block > 1:
        n = (t.size // block) * block
        t = t[:n].reshape(-1, block).mean(axis=1)
        y = y[:n].reshape(-1, block, *y.shape[1:]).mean(axis=1)
        dt *= block
    poles, residues, error = pencil_poles(y, dt, rtol=rtol, max_order=max_order)
    frequency = poles.imag / (2.0 * np.pi)
    keep = frequency >= f_min
    if not np.any(keep):
        raise ValueError(f"dominant_oscillation: no oscillation above {f_min} Hz in the signal")
    span = t[-1] - t[0]
    # a conjugate pair contributes 2 |r| e^{sigma t}: compare at the end of the window
    amplitude = 2.0 * np.linalg.norm(residues, axis=1) * np.exp(poles.real * span)
    if near_hz is not None and np.isfinite(near_hz) and near_hz > 0:
        close = keep & (np.abs(frequency / near_hz - 1.0) <= 0.25)
        keep = close if np.any(close) else keep
    index = np.flatnonzero(keep)[np.argmax(amplitude[keep])]
    return Oscillation(
        frequency=float(frequency[index]),
        decay_rate=float(poles[index].real),
        amplitude=float(amplitude[index]),
        fit_error=error,
    )
