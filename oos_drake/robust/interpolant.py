r"""Stable LTI systems that take a given complex value at one frequency (MATLAB ``wcu``'s way).

A mu lower bound gives, at the critical frequency ``omega``, a complex matrix ``Delta`` that makes
``I - M(j omega) Delta`` singular. To put it into a time-domain simulation it must become a
*stable, real* system ``Delta(s)`` with ``Delta(j omega) = Delta`` and, for an ``ultidyn`` block,
``||Delta(s)||_inf = ||Delta||`` (otherwise a smaller scaling of the realization could already
destabilize at another frequency). As MATLAB's ``wcu`` / ``ultidyn`` interpolation does, each
complex scalar ``c = g e^{j phi}`` becomes ``+-g`` times a first-order all-pass

.. math:: a_p(s) = \frac{p - s}{p + s}, \qquad \angle a_p(j\omega) = -2\arctan(\omega / p)
          \in (-\pi, 0),

with ``p > 0`` chosen so that the phase is ``phi`` (sign ``+``) or ``phi - pi`` (sign ``-``). A
matrix is written by its singular value decomposition ``Delta = sum_k sigma_k u_k v_k^H`` and
each rank-one term realized as ``sigma_k u(s) v(s)^T`` with every entry of ``u(s)``, ``v(s)`` such a
scaled all-pass: ``|u_i(j w)| = |u_i|`` at every frequency, so a rank-one ``Delta`` (the mu
power iteration's) keeps its norm on the whole axis.

With a sample period ``dt`` the section is designed at the prewarped frequency
``(2/dt) tan(omega dt / 2)`` and discretized by the bilinear transform, which maps that point
onto ``e^{j omega dt}``: the discrete system takes the value exactly at ``omega`` too.
"""

from __future__ import annotations

import control
import numpy as np
import scipy.signal

__all__ = ["lti_interpolant"]

#: Phases closer than this to 0 or pi [rad] are realized by a static gain.
STATIC_PHASE = 1e-12


def _section(c: complex, omega: float) -> tuple[np.ndarray, ...]:
    """``(A, B, C, D)`` (at most one state) of ``+-|c| a_p(s)`` with value ``c`` at ``j omega``."""
    g, phi = abs(c), float(np.angle(c))
    if g == 0.0 or abs(np.sin(phi)) < STATIC_PHASE:
        return (
            np.zeros((0, 0)),
            np.zeros((0, 1)),
            np.zeros((1, 0)),
            np.array([[np.sign(c.real) * g]]),
        )
    sign, phase = (1.0, phi) if phi < 0 else (-1.0, phi - np.pi)
    p = omega / np.tan(-phase / 2.0)
    # a_p(s) = -1 + 2 p / (s + p)
    return (
        np.array([[-p]]),
        np.array([[1.0]]),
        np.array([[2.0 * p * sign * g]]),
        np.array([[-sign * g]]),
    )


def _vector(values: np.ndarray, omega: float, column: bool):
    """Diagonal stack of sections: a column ``(n, 1)`` or row ``(1, n)`` system."""
    parts = [_section(complex(v), omega) for v in values]
    n = sum(a.shape[0] for a, *_ in parts)
    A, B, C = np.zeros((n, n)), np.zeros((n, 1 if column else len(values))), None
    Cm = np.zeros((len(values) if column else 1, n))
    D = np.zeros((len(values), 1)) if column else np.zeros((1, len(values)))
    k = 0
    for i, (a, b, c, d) in enumerate(parts):
        m = a.shape[0]
        A[k : k + m, k : k + m] = a
        if column:
            B[k : k + m, 0:1] = b
            Cm[i, k : k + m] = c[0]
            D[i, 0] = d[0, 0]
        else:
            B[k : k + m, i : i + 1] = b
            Cm[0, k : k + m] = c[0]
            D[0, i] = d[0, 0]
        k += m
    C = Cm
    return control.ss(A, B, C, D)


def lti_interpolant(value, omega: float, *, dt: float | None = None) -> control.StateSpace:
    """A stable real system ``G`` with ``G(j omega) = value`` (see the module docstring).

    Parameters
    ----------
    value : complex scalar or array_like, shape (p, q)
        Value to take at ``omega``.
    omega : float
        Frequency [rad/s], ``>= 0``; ``inf`` (or 0) needs a real ``value`` (a static gain).
    dt : float, optional
        Sample period [s] of a discrete-time result (``G(e^{j omega dt}) = value``); needs
        ``omega dt < pi``.

    Returns
    -------
    control.StateSpace
        ``p x q``; poles real and negative (inside the unit disc for ``dt``). For a rank-one
        ``value`` the peak gain over all frequencies equals ``||value||_2``; for higher ranks it
        is at most the sum of the singular values.

    Raises
    ------
    ValueError
        Non-finite value, negative frequency, a complex value at 0 or infinite frequency, or
        ``omega`` at or beyond the Nyquist frequency of ``dt``.
    """
    matrix = np.atleast_2d(np.asarray(value, dtype=complex))
    if matrix.ndim != 2 or not np.all(np.isfinite(matrix)):
        raise ValueError(f"lti_interpolant: value must be a finite scalar or matrix, got {value!r}")
    omega = float(omega)
    if not omega >= 0:
        raise ValueError(f"lti_interpolant: omega must be >= 0 rad/s, got {omega}")
    static = omega == 0.0 or np.isinf(omega)
    if static:
        if np.abs(matrix.imag).max() > 1e-9 * max(1.0, np.abs(matrix).max()):
            raise ValueError(
                f"lti_interpolant: at omega = {omega} rad/s the value must be real, got {value!r}"
            )
        return control.ss([], [], [], matrix.real, dt=0 if dt is None else dt)
    design = omega
    if dt is not None:
        if not (dt > 0 and omega * dt < np.pi):
            raise ValueError(
                f"lti_interpolant: omega = {omega:g} rad/s at or beyond the Nyquist frequency "
                f"of dt = {dt!r} s"
            )
        design = 2.0 / dt * np.tan(omega * dt / 2.0)
    U, S, Vh = np.linalg.svd(matrix)
    p, q = matrix.shape
    total = control.ss([], [], [], np.zeros((p, q)))
    for k, sigma in enumerate(S):
        if sigma <= 1e-12 * S[0]:
            break
        term = sigma * (_vector(U[:, k], design, True) * _vector(Vh[k, :], design, False))
        total = term if k == 0 else total + term
    total = control.ss(*(np.asarray(m, dtype=float) for m in (total.A, total.B, total.C, total.D)))
    if dt is None:
        return total
    if total.nstates == 0:
        return control.ss([], [], [], total.D, dt=dt)
    Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete(
        (total.A, total.B, total.C, total.D), dt, method="bilinear"
    )
    return control.ss(Ad, Bd, Cd, Dd, dt=dt)
