"""Rotation about a fixed axis by an angle parameterized by ``tau = tan(theta / 4)`` (minimal LFR).

.. math::

    R(\\theta) = \\left[(I - \\tau N)^{-1} (I + \\tau N)\\right]^2, \\qquad
    N = (^*n) = U V^T, \\qquad \\tau = \\tan(\\theta / 4) \\in [-1, 1]

Each Cayley factor is ``I + 2 U tau (I - tau V^T U)^{-1} V^T`` (``tau I2``), so ``tau`` occurs
4 times per DCM, 8 times per ``T = diag(DCM, DCM)`` and 16 times per connection (``T`` and ``T^T``),
the paper's counts (Dubanchet's parameterization). ``I - tau V^T U`` is invertible for every real
``tau`` (the eigenvalues of ``V^T U`` are ``+-i``), so the LFR is well posed on the whole range.
"""

from __future__ import annotations

import numpy as np

from oos_drake.lfr import LFR, append, as_lfr, feedback
from oos_drake.titop.kinematics import repeat
from oos_drake.titop.spatial import rank2_factors

__all__ = ["cayley_factor", "rotation_matrix_lfr", "rotation_dcm", "rotation_frame_change"]


def _check_tau(tau) -> LFR:
    if not isinstance(tau, LFR) or tau.shape != (1, 1):
        raise ValueError("rotation: tau must be a 1x1 LFR (e.g. angle_parameter('tau_theta1'))")
    return tau


def cayley_factor(tau: LFR, axis) -> LFR:
    """Cayley factor ``(I - tau N)^{-1} (I + tau N)``: rotation by ``2 atan(tau)`` about ``axis``.

    Parameters
    ----------
    tau : LFR (1x1)
        Scalar parameter (2 occurrences).
    axis : array_like, shape (3,)
        Rotation axis (normalized here) [-].
    """
    axis = np.asarray(axis, dtype=float)
    u, v = rank2_factors(axis / np.linalg.norm(axis))
    gain = v.T @ u
    loop = feedback(repeat(_check_tau(tau), 2), as_lfr(gain), sign=+1)  # tau (I - tau V^T U)^-1
    return as_lfr(np.eye(3)) + (2.0 * u) @ loop @ v.T


def rotation_matrix_lfr(tau: LFR, axis) -> LFR:
    """Rotation matrix ``R(theta)`` about ``axis`` as a 3x3 LFR in ``tau = tan(theta/4)`` (4 occ.).

    ``R @ v`` rotates ``v`` by ``theta`` (right-handed about ``axis``); it equals
    :func:`oos_drake.titop.spatial.rotation_matrix`.
    """
    factor = cayley_factor(tau, axis)
    return factor @ cayley_factor(tau, axis)


def rotation_dcm(tau: LFR, axis) -> LFR:
    """``DCM_{B/A}`` of a frame ``B`` obtained by turning ``A`` by ``theta`` about ``axis``.

    ``v_B = DCM_{B/A} v_A = R(theta)^T v_A = R(-theta) v_A`` (3x3 LFR, 4 occurrences of ``tau``).

    Parameters
    ----------
    tau : LFR (1x1)
        ``tan(theta / 4)`` block.
    axis : array_like, shape (3,)
        Rotation axis, components in ``A`` (and ``B``) [-].
    """
    # R(theta)^T = R(-theta): the same tau block about -axis (no gain on tau, same occurrences)
    return rotation_matrix_lfr(tau, -np.asarray(axis, dtype=float))


def rotation_frame_change(tau: LFR, axis, *, transpose: bool = False) -> LFR:
    """Frame change ``T_theta = diag(DCM, DCM)`` (6x6, 8 occurrences of ``tau``).

    Parameters
    ----------
    tau : LFR (1x1)
        ``tan(theta / 4)`` block.
    axis : array_like, shape (3,)
        Rotation axis [-].
    transpose : bool
        Return ``T_theta^T`` (maps wrenches back from the rotated frame), also 8 occurrences.
    """
    dcm = rotation_matrix_lfr(tau, axis) if transpose else rotation_dcm(tau, axis)
    return append(dcm, dcm)
