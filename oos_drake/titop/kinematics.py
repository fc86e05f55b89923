"""Kinematic model ``tau_PB`` and frame change ``T = diag(DCM, DCM)`` as LFR blocks.

The position ``PB`` may depend linearly on scalar parameters (e.g. connection switches):
``PB = p0 + sum_k delta_k v_k``. Since ``skew(v_k)`` has rank 2, each ``delta_k`` occurs twice
in ``tau_PB`` (paper section 2, RH2 shared port: ``delta_C1 I2`` and ``delta_C2 I2`` per tau).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from oos_drake.lfr import LFR, append, as_lfr, hstack, vstack
from oos_drake.titop.spatial import frame_change_matrix, kinematic_matrix, rank2_factors, skew

__all__ = [
    "repeat",
    "kinematic_model",
    "kinematic_model_transposed",
    "frame_change",
    "uncertain_skew",
]


def repeat(value, count: int) -> LFR:
    """Return ``value * I_count`` as an LFR; a 1x1 LFR block then occurs ``count`` times.

    Parameters
    ----------
    value : LFR (1x1) or float
        Scalar (uncertain or not).
    count : int
        Size of the identity.
    """
    if isinstance(value, LFR):
        if value.shape != (1, 1):
            raise ValueError(f"repeat: expected a 1x1 LFR, got shape {value.shape}")
        return append(*([value] * count))
    return as_lfr(float(value) * np.eye(count))


def uncertain_skew(p0, terms: Sequence[tuple[LFR, Sequence[float]]] = ()) -> LFR:
    """Return ``skew(p0 + sum_k delta_k v_k)`` (3x3 LFR), ``delta_k I2`` per nonzero ``v_k``.

    Parameters
    ----------
    p0 : array_like, shape (3,)
        Constant part of the vector [m].
    terms : sequence of (LFR, array_like)
        Pairs ``(delta_k, v_k)``: a 1x1 LFR scalar and a 3-vector [m].
    """
    result = as_lfr(skew(p0))
    for delta, vector in terms:
        vector = np.asarray(vector, dtype=float)
        if np.linalg.norm(vector) < 1e-15:
            continue  # skew(0) = 0: no occurrence
        u, v = rank2_factors(vector)
        result = result + u @ repeat(delta, 2) @ v.T
    return result


def kinematic_model(p_PB, terms: Sequence[tuple[LFR, Sequence[float]]] = ()) -> LFR:
    """Kinematic model ``tau_PB = [[I3, skew(PB)], [0, I3]]`` (6x6 static LFR).

    Parameters
    ----------
    p_PB : array_like, shape (3,)
        Constant part of the vector from ``P`` to ``B`` [m].
    terms : sequence of (LFR, array_like), optional
        Parameter-dependent parts ``(delta_k, v_k)`` of ``PB`` (2 occurrences of each delta_k).

    Returns
    -------
    LFR
        ``xdd_P = tau_PB xdd_B``; its transpose maps wrenches from ``P`` to ``B``.

    Examples
    --------
    >>> kinematic_model([0.0, 0.4365, 0.0]).shape
    (6, 6)
    """
    if not terms:
        return as_lfr(kinematic_matrix(p_PB))
    s = uncertain_skew(p_PB, terms)
    upper = hstack([as_lfr(np.eye(3)), s])
    lower = as_lfr(np.hstack([np.zeros((3, 3)), np.eye(3)]))
    return vstack([upper, lower])


def kinematic_model_transposed(p_PB, terms: Sequence[tuple[LFR, Sequence[float]]] = ()) -> LFR:
    """``tau_PB^T = [[I3, 0], [skew(PB)^T, I3]]`` (6x6 LFR, same occurrences as ``tau_PB``).

    Parameters are those of :func:`kinematic_model`; maps a wrench at ``P`` to ``B``.
    """
    if not terms:
        return as_lfr(kinematic_matrix(p_PB).T)
    s = uncertain_skew(p_PB, terms)
    upper = as_lfr(np.hstack([np.eye(3), np.zeros((3, 3))]))
    lower = hstack([-1.0 * s, as_lfr(np.eye(3))])  # skew^T = -skew
    return vstack([upper, lower])


def frame_change(dcm) -> LFR:
    """Constant frame change ``T_{B/A} = diag(DCM_{B/A}, DCM_{B/A})`` (6x6 static LFR).

    Parameters
    ----------
    dcm : array_like, shape (3, 3)
        ``DCM_{B/A}`` with ``v_B = DCM_{B/A} v_A`` [-].
    """
    return as_lfr(frame_change_matrix(dcm))
