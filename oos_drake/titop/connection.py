"""Connections between substructures: fixed and rotating frame changes, switches, spring-dampers.

All connection blocks act on the 12 channels of a port pair: the acceleration twist going from
parent to child and the wrench coming back from child to parent:

``inputs = [xdd (parent frame, 6); W (child frame, 6)]``,
``outputs = [xdd (child frame, 6); W (parent frame, 6)]``.

* Revolute joint, motion driven (arm and array drives follow a prescribed trajectory): relative
  acceleration zero at the linearization point, i.e. a cantilever through ``T(theta)``:
  ``xdd_child = T xdd_parent``, ``W_parent = T^T W_child`` with ``T = T_theta T_0`` (16 occurrences
  of ``tau``; the constant ``T_0`` adds none).
* Connection switch ``delta_C`` in ``{0, 1}`` multiplies the 12 channels (``delta_C I12``).
* Spring-damper ``SM`` between points ``C`` and ``P`` (paper Eq. springmasseq).
"""

from __future__ import annotations

import numpy as np

from oos_drake.lfr import LFR, append, as_lfr, hstack
from oos_drake.titop.kinematics import repeat
from oos_drake.titop.parameters import check_name
from oos_drake.titop.rotation import rotation_frame_change
from oos_drake.titop.spatial import frame_change_matrix

__all__ = [
    "fixed_connection",
    "revolute_connection",
    "revolute_frame_changes",
    "spring_damper",
    "spring_damper_parameters",
]


def fixed_connection(dcm_child_parent) -> LFR:
    """Rigid connection with a constant frame change (12 x 12 static LFR, no parameter).

    Parameters
    ----------
    dcm_child_parent : array_like (3, 3)
        ``DCM_{child/parent}``: ``v_child = DCM v_parent`` [-].
    """
    t = frame_change_matrix(dcm_child_parent)
    matrix = np.zeros((12, 12))
    matrix[:6, :6] = t
    matrix[6:, 6:] = t.T
    return as_lfr(matrix)


def revolute_connection(tau: LFR, axis, dcm_fixed=None) -> LFR:
    """Motion-driven revolute joint: ``T = T_theta T_0`` forward, ``T^T`` back (16 occurrences).

    Parameters
    ----------
    tau : LFR (1x1)
        ``tan(theta/4)`` block (e.g. ``angle_parameter("tau_alpha3")``).
    axis : array_like (3,)
        Joint axis in the intermediate frame ``T_0`` leads to (= the child frame, which turns
        about it) [-].
    dcm_fixed : array_like (3, 3), optional
        Constant ``DCM_{child0/parent}`` before the rotation (identity if None).

    Returns
    -------
    LFR
        12 x 12 static: ``[xdd_child; W_parent] = [[T, 0], [0, T^T]] [xdd_parent; W_child]``.
    """
    return append(*revolute_frame_changes(tau, axis, dcm_fixed))


def revolute_frame_changes(tau: LFR, axis, dcm_fixed=None) -> tuple[LFR, LFR]:
    """The two halves of :func:`revolute_connection`: ``T = T_theta T_0`` and ``T^T``.

    A one-port hanging on the joint (an appendage ``W = -M_P(s) xdd_P`` in the child frame) is
    seen from the parent as ``T^T (-M_P(s)) T``: ``backward @ system @ forward``.

    Parameters
    ----------
    tau, axis, dcm_fixed
        As :func:`revolute_connection`.

    Returns
    -------
    forward, backward : LFR (6x6)
        ``xdd_child = forward xdd_parent``, ``W_parent = backward W_child`` (8 occurrences of
        ``tau`` each).
    """
    t0 = frame_change_matrix(np.eye(3) if dcm_fixed is None else dcm_fixed)
    forward = rotation_frame_change(tau, axis) @ t0
    backward = t0.T @ rotation_frame_change(tau, axis, transpose=True)
    return forward, backward


def spring_damper_parameters(
    name: str,
    stiffness: tuple[float, float] = (1.0e5, 1.0e5),
    damping: tuple[float, float] = (100.0, 100.0),
    stiffness_range: tuple[float, float] = (0.0, 2.0e5),
    damping_range: tuple[float, float] = (0.0, 200.0),
) -> dict[str, LFR]:
    """The four blocks ``k_shear_<name>``, ``k_tors_<name>``, ``d_shear_<name>``, ``d_tors_<name>``.

    Parameters
    ----------
    name : str
        Spring-damper name, e.g. ``"SM1"``.
    stiffness : (float, float)
        Nominal shear [N/m] and torsional [N m/rad] stiffness.
    damping : (float, float)
        Nominal shear [N s/m] and torsional [N m s/rad] damping.
    stiffness_range, damping_range : (float, float)
        Physical ranges of the blocks (stiffness sweeps use values inside them).
    """
    from oos_drake.lfr import ureal

    check_name(name, "spring-damper name")
    blocks = {}
    for label, nominal, value_range, unit, quantity in (
        ("k_shear", stiffness[0], stiffness_range, "N/m", "stiffness"),
        ("k_tors", stiffness[1], stiffness_range, "N m/rad", "stiffness"),
        ("d_shear", damping[0], damping_range, "N s/m", "damping"),
        ("d_tors", damping[1], damping_range, "N m s/rad", "damping"),
    ):
        blocks[label] = ureal(
            f"{label}_{name}",
            float(nominal),
            range=tuple(value_range),
            unit=unit,
            quantity=quantity,
        )
    return blocks


def spring_damper(
    k_shear,
    k_tors,
    d_shear,
    d_tors,
) -> LFR:
    """Massless 6-DOF spring-damper between points ``C`` and ``P`` (paper Eq. springmasseq).

    .. math::

        W_C = -(K \\delta x + D \\delta \\dot x), \\quad W_P = -W_C, \\quad
        \\delta \\ddot x = \\ddot x_C - \\ddot x_P,

    ``K = diag(k_shear I3, k_tors I3)``, ``D = diag(d_shear I3, d_tors I3)``.

    Parameters
    ----------
    k_shear, k_tors : float or LFR (1x1)
        Shear [N/m] and torsional [N m/rad] stiffness (3 occurrences each if uncertain).
    d_shear, d_tors : float or LFR (1x1)
        Shear [N s/m] and torsional [N m s/rad] damping (3 occurrences each if uncertain).

    Returns
    -------
    LFR
        Inputs ``[xdd_C; xdd_P]`` (12), outputs ``[W_C; W_P]`` (12, wrenches the spring-damper
        applies to the bodies at ``C`` and ``P``), 12 states ``[dx; dx_dot]``, all in the frame
        ``R_SM`` of the spring-damper.
    """
    for label, value in (
        ("k_shear", k_shear),
        ("k_tors", k_tors),
        ("d_shear", d_shear),
        ("d_tors", d_tors),
    ):
        if isinstance(value, LFR):
            if value.shape != (1, 1):
                raise ValueError(f"spring_damper: {label} must be a 1x1 LFR or a float")
        elif not float(value) >= 0:
            raise ValueError(f"spring_damper: {label} must be >= 0, got {value}")
    # relative motion: dx' = v, v' = a_C - a_P; output [dx; v]
    a_matrix = np.block([[np.zeros((6, 6)), np.eye(6)], [np.zeros((6, 6)), np.zeros((6, 6))]])
    b_matrix = np.block([[np.zeros((6, 6)), np.zeros((6, 6))], [np.eye(6), -np.eye(6)]])
    relative = LFR.from_ss(a_matrix, b_matrix, np.eye(12), np.zeros((12, 12)))
    stiffness = append(repeat(k_shear, 3), repeat(k_tors, 3))
    damping = append(repeat(d_shear, 3), repeat(d_tors, 3))
    force = hstack([stiffness, damping])  # K dx + D v (6)
    spread = as_lfr(np.vstack([-np.eye(6), np.eye(6)]))
    return spread @ force @ relative
