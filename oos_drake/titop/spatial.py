"""Numeric 6-DOF kinematics and rigid inertia (pure numpy): closed forms behind the TITOP blocks.

Every 6-vector is ordered ``[translation; rotation]``: acceleration twist ``[a; wdot]`` and wrench
``[F; T]``, SI units. These functions are the numeric references the LFR blocks are tested against
and the constant parts the blocks are built from.

.. math::

    \\tau_{PB} = \\begin{bmatrix} I_3 & (^*\\vec{PB}) \\\\ 0 & I_3 \\end{bmatrix}, \\qquad
    \\ddot x_P = \\tau_{PB} \\ddot x_B, \\qquad W_B = \\tau_{PB}^T W_P

Examples
--------
>>> import numpy as np
>>> tau = kinematic_matrix([1.0, 0.0, 0.0])
>>> tau @ np.array([0, 0, 0, 0, 0, 1.0])   # wdot_z at B gives a_y = -1 at P = B - x
array([ 0., -1.,  0.,  0.,  0.,  1.])
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "skew",
    "kinematic_matrix",
    "frame_change_matrix",
    "rotation_matrix",
    "rigid_spatial_inertia",
    "residual_mass",
    "angle_to_tau",
    "rank2_factors",
]


def _vector3(value, what: str) -> np.ndarray:
    vector = np.asarray(value, dtype=float)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise ValueError(f"{what}: expected a finite 3-vector, got {value!r}")
    return vector


def skew(vector) -> np.ndarray:
    """Return the cross-product matrix ``(*v)`` with ``skew(v) @ u == cross(v, u)``.

    The package's one cross-product matrix (TITOP blocks, scenario kinematics, Drake modal
    bodies use it).

    Parameters
    ----------
    vector : array_like, shape (..., 3)
        Vector(s) ``v`` [any unit]; leading dimensions are a batch.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
    """
    v = np.asarray(vector, dtype=float)
    if v.shape[-1:] != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"skew: expected finite 3-vector(s), got shape {v.shape}")
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def kinematic_matrix(p_PB) -> np.ndarray:
    """Rigid kinematic model ``tau_PB`` (paper Eq. kinmodel), 6x6.

    Parameters
    ----------
    p_PB : array_like, shape (3,)
        Vector from ``P`` to ``B`` [m], in the frame the twists are expressed in.

    Returns
    -------
    numpy.ndarray, shape (6, 6)
        ``[[I3, skew(PB)], [0, I3]]``: maps the acceleration twist at ``B`` to the one at ``P``
        (``a_P = a_B + PB x wdot``); its transpose maps a wrench at ``P`` to ``B``.
    """
    tau = np.eye(6)
    tau[:3, 3:] = skew(_vector3(p_PB, "kinematic_matrix p_PB"))
    return tau


def frame_change_matrix(dcm) -> np.ndarray:
    """Return ``T = diag(DCM, DCM)`` (6x6) for a 3x3 direction cosine matrix.

    Parameters
    ----------
    dcm : array_like, shape (3, 3)
        ``DCM_{B/A}``: components in frame ``B`` of the unit vectors of frame ``A`` [-], so that
        ``v_B = DCM @ v_A``.
    """
    dcm = np.asarray(dcm, dtype=float)
    if dcm.shape != (3, 3):
        raise ValueError(f"frame_change_matrix: expected a 3x3 DCM, got shape {dcm.shape}")
    if not np.allclose(dcm @ dcm.T, np.eye(3), atol=1e-9) or np.linalg.det(dcm) < 0:
        raise ValueError("frame_change_matrix: the DCM is not a proper rotation matrix")
    frame_change = np.zeros((6, 6))
    frame_change[:3, :3] = dcm
    frame_change[3:, 3:] = dcm
    return frame_change


def _unit_axis(axis, what: str) -> np.ndarray:
    axis = _vector3(axis, what)
    norm = np.linalg.norm(axis)
    if norm < 1e-12:
        raise ValueError(f"{what}: the rotation axis is zero")
    return axis / norm


def rotation_matrix(axis, angle) -> np.ndarray:
    """Rotation matrix of angle ``angle`` about ``axis`` (Rodrigues' formula).

    Parameters
    ----------
    axis : array_like, shape (3,)
        Rotation axis (normalized here) [-].
    angle : float or array_like
        Rotation angle(s) [rad], right-handed about ``axis``.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
        ``R = I + sin(angle) N + (1 - cos(angle)) N^2`` with ``N = skew(axis)``. ``R @ v``
        rotates ``v``; ``R`` holds the rotated frame's unit vectors as columns.
    """
    n = skew(_unit_axis(axis, "rotation_matrix"))
    angle = np.asarray(angle, dtype=float)[..., None, None]
    return np.eye(3) + np.sin(angle) * n + (1.0 - np.cos(angle)) * (n @ n)


def angle_to_tau(angle):
    """Return ``tau = tan(angle / 4)`` [-] after wrapping ``angle`` [rad] to ``[-pi, pi]``.

    ``angle = pi`` maps to ``tau = 1`` (and ``-pi`` to ``-1``): both give the same rotation.
    """
    angle = np.asarray(angle, dtype=float)
    wrapped = np.remainder(angle + np.pi, 2.0 * np.pi) - np.pi
    # keep +pi as +pi (remainder sends it to -pi): same rotation, nicer value
    wrapped = np.where(np.isclose(wrapped, -np.pi) & (angle > 0), np.pi, wrapped)
    return np.tan(wrapped / 4.0)


def rank2_factors(vector) -> tuple[np.ndarray, np.ndarray]:
    """Factor ``skew(v) = U @ V.T`` with ``U``, ``V`` of shape (3, 2) (``skew`` has rank 2).

    With ``e1, e2`` orthonormal, perpendicular to ``v`` and ``e1 x e2 = v / |v|``:
    ``skew(v) = |v| (e2 e1^T - e1 e2^T)``, so ``U = |v| [e2, -e1]``, ``V = [e1, e2]`` and
    ``V.T @ U = |v| [[0, -1], [1, 0]]``.

    Parameters
    ----------
    vector : array_like, shape (3,)
        Nonzero vector ``v`` [any unit].
    """
    vector = _vector3(vector, "rank2_factors")
    norm = np.linalg.norm(vector)
    if norm < 1e-15:
        raise ValueError("rank2_factors: the vector is zero (skew has rank 0)")
    n = vector / norm
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(helper, n)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    u = norm * np.column_stack([e2, -e1])
    v = np.column_stack([e1, e2])
    return u, v


def rigid_spatial_inertia(mass, inertia_G, p_PG=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Rigid spatial inertia ``D_P = tau_GP^T diag(m I3, J_G) tau_GP`` at point ``P`` (6x6).

    The package's one spatial-inertia helper; arguments always in this order: mass, inertia at
    the centre of mass, vector from the reference point to the centre of mass.

    .. math:: D_P = \\begin{bmatrix} m I_3 & -m [p]_\\times \\\\ m [p]_\\times &
              J_G - m [p]_\\times^2 \\end{bmatrix}, \\qquad p = \\vec{PG}

    Parameters
    ----------
    mass : float
        Body mass ``m`` [kg].
    inertia_G : array_like, shape (..., 3, 3)
        Inertia tensor at the center of mass ``G`` [kg m^2].
    p_PG : array_like, shape (..., 3)
        Vector from ``P`` to ``G`` [m] (same frame as ``inertia_G``); batch dimensions of
        ``inertia_G`` and ``p_PG`` broadcast.

    Returns
    -------
    numpy.ndarray, shape (..., 6, 6)
        ``D_P`` with ``W_P = D_P xdd_P`` for the wrench applied to the body at ``P``
        ``[translation; rotation]``.
    """
    inertia_G = np.asarray(inertia_G, dtype=float)
    if inertia_G.shape[-2:] != (3, 3):
        raise ValueError(f"rigid_spatial_inertia: inertia must be 3x3, got {inertia_G.shape}")
    S = skew(p_PG)
    batch = np.broadcast_shapes(inertia_G.shape[:-2], S.shape[:-2])
    out = np.zeros(batch + (6, 6))
    out[..., :3, :3] = float(mass) * np.eye(3)
    out[..., :3, 3:] = -mass * S
    out[..., 3:, :3] = mass * S
    out[..., 3:, 3:] = inertia_G - mass * (S @ S)
    return out


def residual_mass(rigid_inertia_P, participation) -> np.ndarray:
    """Residual (cantilevered) mass ``D_P0 = D_P - L L^T`` (6x6).

    Parameters
    ----------
    rigid_inertia_P : array_like, shape (6, 6)
        Rigid spatial inertia of the appendage at its root ``P`` [kg, kg m, kg m^2].
    participation : array_like, shape (6, N)
        Modal participation factors ``L = [l_1 ... l_N]`` at ``P`` (columns = modes)
        [sqrt(kg), sqrt(kg) m].
    """
    participation = np.asarray(participation, dtype=float)
    return np.asarray(rigid_inertia_P, dtype=float) - participation @ participation.T
