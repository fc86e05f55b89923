"""Cantilevered flexible appendage (one-port), SDT's *One-port flexible body*.

Effective mass model at the root ``P`` (paper Eq. sadynmodel), ``N`` cantilevered modes
``(w_i, xi_i, l_i)``:

.. math::

    M_P(s) = D_{P0} + \\sum_i l_i l_i^T
    \\frac{2 \\xi_i w_i s + w_i^2}{s^2 + 2 \\xi_i w_i s + w_i^2},
    \\qquad D_{P0} = D_P - \\sum_i l_i l_i^T

The block outputs the wrench the appendage applies to its parent, ``W = -M_P(s) xdd_P``.
Per mode, the state ``z = [w eta; eta_dot]`` gives the realization

.. math::

    \\dot z_1 = w z_2, \\quad \\dot z_2 = -w (z_1 + 2 \\xi z_2) - l^T a, \\quad
    W = -D_{P0} a + l\\, w (z_1 + 2 \\xi z_2)

where ``w`` enters exactly twice: an uncertain frequency is ``w I2``
(paper: ``Delta_w = delta I2``).
Checks: ``M_P(0) = D_P`` and ``M_P(inf) = D_P0``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from oos_drake.lfr import LFR, append, as_lfr, feedback
from oos_drake.titop.kinematics import repeat
from oos_drake.titop.spatial import residual_mass

__all__ = ["flexible_appendage", "check_appendage_data"]


def check_appendage_data(rigid_inertia_P, participation, frequencies, damping, name="appendage"):
    """Validate appendage data and return numpy arrays ``(D_P, L, w, xi)``.

    Parameters
    ----------
    rigid_inertia_P : array_like (6, 6)
        Rigid spatial inertia of the appendage at ``P`` [kg, kg m, kg m^2].
    participation : array_like (6, N)
        Participation factors, one COLUMN per mode (``L = [l_1 ... l_N]``) [sqrt(kg), sqrt(kg) m].
    frequencies : array_like (N,)
        Cantilevered mode frequencies [rad/s], > 0.
    damping : float or array_like (N,)
        Modal damping ratios [-], >= 0.
    name : str
        Used in error messages.

    Raises
    ------
    ValueError
        Bad shapes, non-positive frequency, negative damping, or residual mass ``D_P0`` not
        positive semi-definite (e.g. participation matrix read with rows and columns swapped).
    """
    d_P = np.asarray(rigid_inertia_P, dtype=float)
    participation = np.asarray(participation, dtype=float)
    if d_P.shape != (6, 6) or not np.allclose(d_P, d_P.T, atol=1e-9):
        raise ValueError(f"{name}: rigid inertia D_P must be a symmetric 6x6 matrix")
    if participation.ndim != 2 or participation.shape[0] != 6:
        raise ValueError(
            f"{name}: participation must be 6 x N (one column per mode), got {participation.shape}"
        )
    n_modes = participation.shape[1]
    frequencies = np.asarray(frequencies, dtype=float).reshape(-1)
    if frequencies.shape != (n_modes,) or not np.all(frequencies > 0):
        raise ValueError(f"{name}: need {n_modes} mode frequencies > 0 rad/s, got {frequencies}")
    damping = np.broadcast_to(np.asarray(damping, dtype=float), (n_modes,)).copy()
    if not np.all(damping >= 0):
        raise ValueError(f"{name}: damping ratios must be >= 0, got {damping}")
    residual = residual_mass(d_P, participation)
    min_eig = np.min(np.linalg.eigvalsh(0.5 * (residual + residual.T)))
    if min_eig < -1e-9 * max(1.0, np.max(np.abs(d_P))):
        raise ValueError(
            f"{name}: residual mass D_P0 = D_P - L L^T is not positive semi-definite "
            f"(min eigenvalue {min_eig:.4g}); are the participation factors one column per mode?"
        )
    return d_P, participation, frequencies, damping


def _mode_plant(li: np.ndarray, xi: float) -> LFR:
    # inputs [p1, p2, a(6)], outputs [q1, q2, W(6)], p = w q (the frequency loop)
    a_matrix = np.zeros((2, 2))
    b_matrix = np.zeros((2, 8))
    b_matrix[0, 0] = 1.0  # z1' = p1
    b_matrix[1, 1] = -1.0  # z2' = -p2 - l^T a
    b_matrix[1, 2:] = -li
    c_matrix = np.zeros((8, 2))
    c_matrix[0, 1] = 1.0  # q1 = z2
    c_matrix[1, 0] = 1.0  # q2 = z1 + 2 xi z2
    c_matrix[1, 1] = 2.0 * xi
    d_matrix = np.zeros((8, 8))
    d_matrix[2:, 1] = li  # W += l p2
    return LFR.from_ss(a_matrix, b_matrix, c_matrix, d_matrix)


def _close_frequency_loop(plant: LFR, frequency) -> LFR:
    """Close ``p = w q`` (``w I2``) on the mode plant and return the map a -> W."""
    loop = append(repeat(frequency, 2), as_lfr(np.zeros((6, 6))))
    closed = feedback(plant, loop, sign=+1)  # plant inputs += loop @ outputs
    return closed[2:, 2:]


def flexible_appendage(
    rigid_inertia_P,
    participation,
    frequencies: Sequence[float],
    damping,
    *,
    uncertain_frequencies: dict | None = None,
    name: str = "appendage",
) -> LFR:
    """Cantilevered flexible appendage one-port: ``W_{A/parent,P} = -M_P(s) xdd_P``.

    Parameters
    ----------
    rigid_inertia_P : array_like (6, 6)
        Rigid spatial inertia ``D_P`` at the root ``P`` in the appendage frame.
    participation : array_like (6, N)
        Participation factors, one column per mode [sqrt(kg), sqrt(kg) m].
    frequencies : sequence of float
        Cantilevered mode frequencies [rad/s].
    damping : float or sequence of float
        Modal damping ratios [-].
    uncertain_frequencies : dict {mode index: LFR (1x1)}, optional
        Uncertain frequency blocks [rad/s] replacing ``frequencies[i]`` (2 occurrences each), e.g.
        ``{0: ureal("w1_SA1", w1, percent=20)}``.
    name : str
        Used in error messages.

    Returns
    -------
    LFR
        6 inputs ``xdd_P`` [m/s^2; rad/s^2], 6 outputs ``W`` [N; N m], ``2 N`` states.
    """
    d_P, participation, w, xi = check_appendage_data(
        rigid_inertia_P, participation, frequencies, damping, name
    )
    uncertain_frequencies = dict(uncertain_frequencies or {})
    for index, block in uncertain_frequencies.items():
        if not 0 <= int(index) < w.size:
            raise ValueError(f"{name}: uncertain mode index {index} out of range 0..{w.size - 1}")
        if not isinstance(block, LFR) or block.shape != (1, 1):
            raise ValueError(f"{name}: uncertain frequency of mode {index} must be a 1x1 LFR")
    residual = residual_mass(d_P, participation)

    known = [i for i in range(w.size) if i not in uncertain_frequencies]
    n = len(known)
    # certain modes: one state-space block, z_i' = w z2, z2' = -w z1 - 2 xi w z2 - l^T a
    a_matrix = np.zeros((2 * n, 2 * n))
    b_matrix = np.zeros((2 * n, 6))
    c_matrix = np.zeros((6, 2 * n))
    for k, i in enumerate(known):
        li = participation[:, i]
        a_matrix[2 * k, 2 * k + 1] = w[i]
        a_matrix[2 * k + 1, 2 * k] = -w[i]
        a_matrix[2 * k + 1, 2 * k + 1] = -2 * xi[i] * w[i]
        b_matrix[2 * k + 1] = -li
        c_matrix[:, 2 * k] = w[i] * li
        c_matrix[:, 2 * k + 1] = 2 * xi[i] * w[i] * li
    model = LFR.from_ss(a_matrix, b_matrix, c_matrix, -residual)
    for index in sorted(uncertain_frequencies):
        li = participation[:, int(index)]
        model = model + _close_frequency_loop(
            _mode_plant(li, xi[int(index)]), uncertain_frequencies[index]
        )
    return model
