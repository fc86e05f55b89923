r"""Stability margins of the attitude loop broken at the actuator input.

The loop ``L`` (3x3) is broken at the reaction wheels' input ``u`` with negative feedback
(``u = -L u``). Two kinds of margins, the ones a GNC reviewer reads first:

**Loop at a time** (MATLAB ``loopmargin`` / ``allmargin`` on each channel, the other two loops
closed): channel ``i`` sees the scalar loop

.. math:: l_i = \frac{1}{[(I + L)^{-1}]_{ii}} - 1,

whose gain margins (the gain factors at the phase crossovers ``angle(l_i) = -180 deg``: upper
``> 0 dB``, lower ``< 0 dB``), phase margin (``180 deg + angle(l_i)`` at ``|l_i| = 1``) and delay
margin (phase margin [rad] over the crossover frequency [rad/s]: the smallest extra time delay
that destabilizes, in seconds also for a sampled loop) are computed on a frequency grid,
crossings refined by bisection on the exact response.

**Disk margins**, balanced (skew ``sigma = 0``), as MATLAB's ``diskmargin`` and
RobustAndOptimalControl.jl's ``diskmargin`` (Seiler, Packard and Gahinet, "An introduction to
disk margins", IEEE Control Systems Magazine 40(5), 2020, Eqs. (9)-(12) and the multiloop
section): the loop tolerates every gain ``f = (1 + delta/2) / (1 - delta/2)`` with complex
``|delta| < alpha`` inserted in the loop, with

.. math::

    \alpha_{max} = \frac{1}{\|S - I/2\|_\infty} = \frac{2}{\|S - T\|_\infty}
    \quad (\text{SISO}, \ S = (1 + l)^{-1},\ T = l S),

i.e. the simultaneous gain and phase variation inside the disk: gain in
``[(2 - alpha)/(2 + alpha), (2 + alpha)/(2 - alpha)]``, phase ``+-2 atan(alpha / 2)``. Loop at a
time uses ``l_i``; the **multiloop** disk margin (independent ``f_i`` in every channel at once) is

.. math:: \alpha_{mm} = 1 / \sup_\omega \mu_\Delta\big((I + L)^{-1} - I/2\big),
          \quad \Delta = \mathrm{diag}(\delta_1, \delta_2, \delta_3) \text{ complex},

computed from an Osborne-balanced upper bound of ``mu`` on the whole grid and
:func:`oos_drake.robust.mussv` at the grid points where that bound is largest and at the two
largest peaks refined between grid points: the margin it reports (``1 / mu_upper``) holds on
the grid and at the refined peaks (not proven between grid points);
``multiloop_disk_max`` (``1 / mu_lower``) is a perturbation size that does destabilize.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["Margins", "loop_at_a_time", "margins", "disk_gain_phase"]

#: Bisection steps refining a crossing (2^-30 of a grid cell).
_BISECTIONS = 30
#: Grid points where the multiloop mu is computed with ``mussv``.
_MU_POINTS = 6


@dataclass(frozen=True)
class Margins:
    """Margins of a 3-channel loop broken at the actuator input (see the module docstring).

    Attributes (per channel, shape (3,), unless said otherwise)
    ----------
    gain_upper_db : ndarray
        Smallest gain increase that destabilizes [dB] (``inf``: no phase crossover with
        ``|l| < 1``).
    gain_upper_hz : ndarray
        Its phase-crossover frequency [Hz].
    gain_lower_db : ndarray
        Smallest gain decrease that destabilizes [dB] (negative; ``-inf``: none on the grid).
    phase_deg : ndarray
        Phase margin [deg] (smallest over the gain crossovers; ``inf``: no crossover).
    crossover_hz : ndarray
        Gain-crossover frequency of that phase margin [Hz].
    delay_s : ndarray
        Delay margin [s] (smallest ``PM / omega_c`` over the crossovers).
    disk : ndarray
        Loop-at-a-time balanced disk margin ``alpha`` [-].
    disk_hz : ndarray
        Frequency where it is attained [Hz].
    multiloop_disk : float
        Multiloop balanced disk margin from ``mu`` upper bounds [-] (holds on the grid).
    multiloop_disk_max : float
        ``1 / mu_lower`` [-]: the multiloop margin is at most this.
    multiloop_hz : float
        Frequency of the multiloop peak [Hz].
    """

    gain_upper_db: np.ndarray
    gain_upper_hz: np.ndarray
    gain_lower_db: np.ndarray
    phase_deg: np.ndarray
    crossover_hz: np.ndarray
    delay_s: np.ndarray
    disk: np.ndarray
    disk_hz: np.ndarray
    multiloop_disk: float
    multiloop_disk_max: float
    multiloop_hz: float


def disk_gain_phase(alpha) -> tuple[np.ndarray, np.ndarray]:
    """Gain [dB] and phase [deg] margins implied by a balanced disk margin ``alpha``.

    ``(2 + alpha)/(2 - alpha)`` as a gain (``inf`` for ``alpha >= 2``) and ``2 atan(alpha/2)``.
    """
    alpha = np.asarray(alpha, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(alpha < 2, 20 * np.log10((2 + alpha) / (2 - alpha)), np.inf)
    return gain, np.degrees(2 * np.arctan(alpha / 2))


def loop_at_a_time(L) -> np.ndarray:
    """Scalar loops ``l_i = 1 / [(I + L)^{-1}]_ii - 1`` (..., 3) of ``L`` (..., 3, 3)."""
    L = np.asarray(L)
    S = np.linalg.inv(np.eye(L.shape[-1]) + L)
    return 1.0 / np.diagonal(S, axis1=-2, axis2=-1) - 1.0


def _bisect(f, lo, hi, value_lo):
    """Refine a sign change of the real vectorized function ``f`` between ``lo`` and ``hi``
    (arrays, log-spaced bisection)."""
    lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
    sign_lo = np.sign(value_lo)
    for _ in range(_BISECTIONS):
        mid = np.sqrt(lo * hi)
        right = np.sign(f(mid)) == sign_lo
        lo, hi = np.where(right, mid, lo), np.where(right, hi, mid)
    return np.sqrt(lo * hi)


def _channel(loop: Callable, omega: np.ndarray, l_grid: np.ndarray, i: int) -> dict:
    """Classical margins of channel ``i`` (keyed by :class:`Margins` field) from its grid values
    and the exact loop."""

    def l_of(w):
        return loop_at_a_time(loop(np.atleast_1d(w)))[:, i]

    out = {
        "gain_upper_db": np.inf,
        "gain_upper_hz": np.nan,
        "gain_lower_db": -np.inf,
        "phase_deg": np.inf,
        "crossover_hz": np.nan,
        "delay_s": np.inf,
    }
    li = l_grid[:, i]
    # phase crossovers: Im(l) changes sign where Re(l) < 0
    im = li.imag
    k = np.flatnonzero((np.sign(im[:-1]) != np.sign(im[1:])) & (li.real[:-1] + li.real[1:] < 0))
    if k.size:
        w = _bisect(lambda x: l_of(x).imag, omega[k], omega[k + 1], im[k])
        lw = l_of(w)
        keep = lw.real < 0
        gain = -20 * np.log10(np.abs(lw[keep]))  # factor that brings |l| to 1
        w = w[keep]
        up, down = gain > 0, gain < 0
        if up.any():
            j = np.argmin(np.where(up, gain, np.inf))
            out["gain_upper_db"], out["gain_upper_hz"] = float(gain[j]), w[j] / (2 * np.pi)
        if down.any():
            out["gain_lower_db"] = float(np.max(gain[down]))
    # Nyquist point of a sampled loop (omega = pi / T): l is real there
    if abs(li[-1].imag) < 1e-9 * max(abs(li[-1]), 1e-300) and li[-1].real < 0:
        g = -20 * np.log10(abs(li[-1].real))
        if 0 < g < out["gain_upper_db"]:
            out["gain_upper_db"], out["gain_upper_hz"] = g, omega[-1] / (2 * np.pi)
    # gain crossovers: log|l| changes sign
    mag = np.log(np.abs(li))
    k = np.flatnonzero(np.sign(mag[:-1]) != np.sign(mag[1:]))
    if k.size:
        w = _bisect(lambda x: np.log(np.abs(l_of(x))), omega[k], omega[k + 1], mag[k])
        pm = np.degrees(np.angle(-l_of(w)))  # 180 deg + angle(l), wrapped to (-180, 180]
        j = int(np.argmin(pm))
        out["phase_deg"], out["crossover_hz"] = float(pm[j]), w[j] / (2 * np.pi)
        positive = pm > 0
        if positive.any():
            out["delay_s"] = float(np.min(np.radians(pm[positive]) / w[positive]))
        else:
            out["delay_s"] = 0.0
    return out


def _golden_max(f, lo, hi, iterations=30):
    """Maximum of the scalar function ``f`` on ``[lo, hi]`` (golden section, log scale)."""
    a, b = np.log(lo), np.log(hi)
    r = (np.sqrt(5) - 1) / 2
    c, d = b - r * (b - a), a + r * (b - a)
    fc, fd = f(np.exp(c)), f(np.exp(d))
    for _ in range(iterations):
        if fc > fd:
            b, d, fd = d, c, fc
            c = b - r * (b - a)
            fc = f(np.exp(c))
        else:
            a, c, fc = c, d, fd
            d = a + r * (b - a)
            fd = f(np.exp(d))
    return (np.exp(c), fc) if fc > fd else (np.exp(d), fd)


def _osborne_upper(M, iterations=12) -> np.ndarray:
    """``sigma_max(D M D^-1)`` with Osborne-balanced diagonal ``D``: a valid upper bound of mu
    for complex scalar blocks, batched over the leading dimension."""
    B = np.array(M, dtype=complex)
    n = B.shape[-1]
    off = ~np.eye(n, dtype=bool)
    for _ in range(iterations):
        for i in range(n):
            row = np.sum(np.abs(B[:, i, :]) ** 2 * off[i], axis=-1)
            col = np.sum(np.abs(B[:, :, i]) ** 2 * off[:, i], axis=-1)
            d = np.where((row > 0) & (col > 0), (col / np.where(row > 0, row, 1)) ** 0.25, 1.0)
            B[:, i, :] *= d[:, None]
            B[:, :, i] /= d[:, None]
    return np.linalg.norm(B, 2, axis=(-2, -1))


def margins(loop: Callable[[np.ndarray], np.ndarray], omega) -> Margins:
    """Loop-at-a-time and disk margins of ``loop`` (see the module docstring).

    Parameters
    ----------
    loop : callable
        ``loop(omega)`` -> ``L(j omega)`` (F, 3, 3), broken at the actuator input, negative
        feedback; for a sampled loop ``L(e^{j omega T})``.
    omega : array_like
        Increasing grid [rad/s] (for a sampled loop, up to ``pi / T``); dense enough to see every
        crossing (crossings are then refined on ``loop`` itself).

    Returns
    -------
    Margins
    """
    from oos_drake.robust import mussv

    omega = np.asarray(omega, dtype=float)
    if omega.ndim != 1 or omega.size < 3 or np.any(np.diff(omega) <= 0) or omega[0] <= 0:
        raise ValueError("margins: omega must be an increasing grid of > 2 positive frequencies")
    L = loop(omega)
    n = L.shape[-1]
    lgrid = loop_at_a_time(L)
    channels = [_channel(loop, omega, lgrid, i) for i in range(n)]
    # loop-at-a-time disk margins: 2 / max |(1 - l) / (1 + l)|, peak refined
    disk, disk_hz = np.empty(n), np.empty(n)
    for i in range(n):
        peak = np.abs((1 - lgrid[:, i]) / (1 + lgrid[:, i]))
        j = int(np.argmax(peak))
        lo, hi = omega[max(j - 1, 0)], omega[min(j + 1, omega.size - 1)]

        def value(w, i=i):
            li = loop_at_a_time(loop(np.atleast_1d(w)))[0, i]
            return abs((1 - li) / (1 + li))

        w_best, v_best = _golden_max(value, lo, hi)
        if v_best < peak[j]:
            w_best, v_best = omega[j], peak[j]
        disk[i], disk_hz[i] = 2.0 / v_best, w_best / (2 * np.pi)
    # multiloop: mu of S - I/2 with complex scalar blocks
    eye = np.eye(n)
    Mgrid = np.linalg.inv(eye + L) - eye / 2
    upper = _osborne_upper(Mgrid)
    top = np.argsort(upper)[::-1][:_MU_POINTS]
    # refine the two largest peaks between their grid neighbours (on the Osborne bound)
    refined = []
    for k in top[:2]:
        lo, hi = omega[max(k - 1, 0)], omega[min(k + 1, omega.size - 1)]
        w_peak, _ = _golden_max(
            lambda w: float(
                _osborne_upper(np.linalg.inv(eye + loop(np.atleast_1d(w))) - eye / 2)[0]
            ),
            lo,
            hi,
        )
        refined.append(w_peak)
    refined = np.array(refined)
    points = np.concatenate([Mgrid[top], np.linalg.inv(eye + loop(refined)) - eye / 2])
    frequencies = np.concatenate([omega[top], refined])
    res = mussv(points, [[1, 1]] * n)
    mu_up = np.minimum(_osborne_upper(points), np.asarray(res.upper))
    upper_all = upper.copy()
    upper_all[top] = mu_up[: top.size]
    mu_upper = float(max(np.max(upper_all), np.max(mu_up)))
    j = int(np.argmax(np.asarray(res.lower)))
    mu_lower = float(np.asarray(res.lower)[j])
    return Margins(
        **{key: np.array([c[key] for c in channels]) for key in channels[0]},
        disk=disk,
        disk_hz=disk_hz,
        multiloop_disk=1.0 / mu_upper if mu_upper > 0 else np.inf,
        multiloop_disk_max=1.0 / mu_lower if mu_lower > 0 else np.inf,
        multiloop_hz=float(frequencies[j] / (2 * np.pi)),
    )
