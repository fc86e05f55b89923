"""SDF model of a cantilevered flexible appendage realized by mode bodies.

The generated model (one file per array type) holds

- link ``root`` whose frame is the attachment frame ``R_SA`` (origin ``P``), carrying the array's
  **physical rigid inertia** (mass, centre of mass ``S``, inertia at ``S``): a standalone SDF reader
  sees a valid rigid array;
- frame ``P`` (= ``root``), the docking/attachment port;
- per mode ``i``: link ``mode_i`` on revolute joint ``mode_i_hinge`` (parent ``root``) with
  ``<dynamics><spring_stiffness>`` ``k^2 w^2`` and ``<damping>`` ``2 xi w k^2``
  (Drake's parser turns them into a ``RevoluteSpring`` and joint damping).

SDF cannot hold the non-physical remainder ``-sum M_i`` (see
:mod:`oos_drake.multibody.modal_realization`):
:func:`oos_drake.multibody.plant_parts.add_modal_residual` adds it after parsing as a body
welded to ``root``, computed from the parsed mode links, so that ``root + residual + mode bodies``
has exactly the rigid inertia ``D_P`` and the effective-mass transfer ``M_P(s)``.
"""

from __future__ import annotations

import numpy as np

from oos_drake.multibody.modal_realization import realize_appendage
from oos_drake.multibody.sdf_writer import Frame, Inertial, Joint, Link, Model, Pose
from oos_drake.titop.spatial import rigid_spatial_inertia

__all__ = ["appendage_model", "MODE_LINK", "MODE_JOINT", "ROOT_LINK"]

ROOT_LINK = "root"
MODE_LINK = "mode_{}"
MODE_JOINT = "mode_{}_hinge"


def appendage_model(
    name: str,
    mass: float,
    p_PS: np.ndarray,
    I_S: np.ndarray,
    frequencies: np.ndarray,
    damping_ratios: np.ndarray,
    participations: np.ndarray,
) -> Model:
    """Return the SDF :class:`Model` of a flexible appendage.

    Parameters
    ----------
    name : str
        Model name (e.g. ``"solar_array_sa12"``).
    mass : float
        Appendage mass [kg].
    p_PS : array_like, shape (3,)
        Centre of mass ``S`` from ``P`` in ``R_SA`` [m].
    I_S : array_like, shape (3, 3)
        Inertia at ``S`` in ``R_SA`` [kg m^2].
    frequencies : array_like, shape (N,)
        Cantilever frequencies [rad/s].
    damping_ratios : array_like, shape (N,)
        Modal damping ratios [-].
    participations : array_like, shape (N, 6)
        Participation factors, rows = modes, columns ``[Tx Ty Tz Rx Ry Rz]``.
    """
    p_PS = np.asarray(p_PS, dtype=float)
    I_S = np.asarray(I_S, dtype=float)
    D_P = rigid_spatial_inertia(mass, I_S, p_PS)
    realization = realize_appendage(D_P, frequencies, damping_ratios, participations, name=name)
    links = [Link(ROOT_LINK, Inertial(mass, I_S, Pose(tuple(p_PS))))]
    joints = []
    for i, mode in enumerate(realization.modes, start=1):
        link_name = MODE_LINK.format(i)
        links.append(
            Link(
                link_name,
                Inertial(mode.mass, mode.I_Scm, Pose(tuple(mode.p_PScm - mode.p_PA))),
                Pose(tuple(mode.p_PA), relative_to=ROOT_LINK),
            )
        )
        joints.append(
            Joint(
                MODE_JOINT.format(i),
                "revolute",
                ROOT_LINK,
                link_name,
                axis=tuple(float(v) for v in mode.axis),
                damping=mode.damping,
                spring_stiffness=mode.stiffness,
                actuated=False,
            )
        )
    comment = (
        f"Flexible appendage {name}: root link = attachment frame R_SA (origin P) with the",
        "array's physical rigid inertia; one mode body per cantilever mode on a revolute",
        "joint with spring k^2 w^2 and damping 2 xi w k^2 (M_i H_i = k l_i, H_i^T M_i H_i = k^2).",
        "oos_drake.multibody adds a welded body with inertia -sum(M_i) after parsing, so that",
        "the assembly reproduces exactly",
        "M_P(s) = D_P0 + sum l_i l_i^T (2 xi w s + w^2)/(s^2 + 2 xi w s + w^2).",
        f"Root remainder D_P - sum M_i has mass {realization.residual_inertia[0, 0]:.6g} kg"
        + (" (not physical)." if not realization.residual_is_physical else "."),
    )
    return Model(
        name=name,
        comment=comment,
        links=tuple(links),
        frames=(Frame("P", ROOT_LINK),),
        joints=tuple(joints),
        canonical_link=ROOT_LINK,
    )
