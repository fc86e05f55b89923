"""Pieces added to a MultibodyPlant after parsing the SDF (modal residuals, floating joints:
on a plant not finalized yet), and the one way of writing physical values (inertias, modal
hinge frequencies) into a plant context.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    ForceElementIndex,
    ModelInstanceIndex,
    RevoluteSpring,
    RigidBody,
    RotationalInertia,
    RpyFloatingJoint,
    SpatialInertia,
    UnitInertia,
)

from oos_drake.multibody.appendage_sdf import MODE_JOINT, ROOT_LINK

__all__ = [
    "add_modal_residual",
    "add_floating_joint",
    "central_inertia",
    "set_central_inertia",
    "set_mode_frequency",
    "drake_spatial_inertia_to_matrix",
    "force_elements",
    "modal_hinges",
    "revolute_spring",
    "spatial_inertia_from_central",
]

RESIDUAL_BODY = "modal_residual"


def drake_spatial_inertia_to_matrix(M) -> np.ndarray:
    """Convert a Drake ``SpatialInertia`` (``[rot; trans]``) to the ``[trans; rot]`` 6x6 matrix."""
    K = M.CopyToFullMatrix6()
    perm = [3, 4, 5, 0, 1, 2]
    return K[np.ix_(perm, perm)]


def central_inertia(M) -> tuple[float, np.ndarray, np.ndarray]:
    """``(mass [kg], p_BoBcm [m], 3x3 inertia about the centre of mass [kg m^2])`` of a Drake
    ``SpatialInertia`` ``M`` about the body origin, body axes."""
    mass, com = M.get_mass(), M.get_com()
    return mass, com, M.Shift(com).CalcRotationalInertia().CopyToFullMatrix3()


def spatial_inertia_from_central(mass: float, p_BoBcm, inertia) -> SpatialInertia:
    """Drake ``SpatialInertia`` of ``mass`` [kg] with its centre of mass at ``p_BoBcm`` [m] and
    the symmetric 3x3 ``inertia`` about it [kg m^2] (body axes): the inverse of
    :func:`central_inertia`."""
    I = inertia
    rotational = RotationalInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
    return SpatialInertia.MakeFromCentralInertia(mass, p_BoBcm, rotational)


def set_central_inertia(body, plant_context, mass=None, moments=None) -> None:
    """Write a new ``mass`` [kg] and/or diagonal ``moments`` ``{axis: J [kg m^2]}`` (axis 0..2)
    of the inertia about the centre of mass (body axes) of ``body`` into ``plant_context``; the
    centre of mass, the products of inertia and what is not given keep their context values."""
    current_mass, com, inertia = central_inertia(body.CalcSpatialInertiaInBodyFrame(plant_context))
    for axis, value in (moments or {}).items():
        inertia[axis, axis] = value
    mass = current_mass if mass is None else mass
    body.SetSpatialInertiaInBodyFrame(
        plant_context, spatial_inertia_from_central(mass, com, inertia)
    )


def set_mode_frequency(spring, joint, plant_context, ratio: float, nominal=None) -> None:
    """Scale a modal hinge's frequency by ``ratio`` (same damping ratio, same participation):
    stiffness ``k0 ratio^2`` [N m/rad], damping ``d0 ratio`` [N m s/rad] of the ``spring`` on
    ``joint``, with ``nominal = (k0, d0)`` (default: the elements' default values)."""
    if nominal is None:
        nominal = (spring.default_stiffness(), joint.default_damping_vector()[0])
    stiffness, damping = nominal
    spring.SetStiffness(plant_context, stiffness * ratio**2)
    joint.SetDampingVector(plant_context, [damping * ratio])


def force_elements(plant: MultibodyPlant, kind: type) -> list:
    """The force elements of ``plant`` that are instances of ``kind`` (``RevoluteSpring``, ...)."""
    elements = (
        plant.get_force_element(ForceElementIndex(i)) for i in range(plant.num_force_elements())
    )
    return [element for element in elements if isinstance(element, kind)]


def revolute_spring(plant: MultibodyPlant, joint):
    """The ``RevoluteSpring`` on ``joint`` (the first one), None when it has none."""
    index = joint.index()
    springs = [s for s in force_elements(plant, RevoluteSpring) if s.joint().index() == index]
    return springs[0] if springs else None


def modal_hinges(plant: MultibodyPlant, model_instance: ModelInstanceIndex) -> list:
    """The mode hinges ``mode_1_hinge``, ``mode_2_hinge``, ... of a modal appendage, in order."""
    hinges = []
    while plant.HasJointNamed(MODE_JOINT.format(len(hinges) + 1), model_instance):
        hinges.append(plant.GetJointByName(MODE_JOINT.format(len(hinges) + 1), model_instance))
    return hinges


def add_modal_residual(plant: MultibodyPlant, model_instance: ModelInstanceIndex) -> RigidBody:
    """Weld to the appendage's ``root`` a body of inertia ``-sum_i M_i`` (mode bodies at q = 0).

    After this, ``root + residual + mode bodies`` has the rigid inertia that the SDF gives the
    root link (the array's ``D_P``), and the appendage's effective-mass transfer is ``M_P(s)``
    exactly. The residual is generally not a physical rigid-body inertia (negative mass): it is
    built with ``skip_validity_check=True``.

    Parameters
    ----------
    plant : MultibodyPlant
        Plant with the appendage model parsed (not finalized).
    model_instance : ModelInstanceIndex
        The appendage's model instance (links ``root``, ``mode_i``; joints ``mode_i_hinge``).

    Returns
    -------
    RigidBody
        The residual body (named ``modal_residual`` in the instance).
    """
    root = plant.GetBodyByName(ROOT_LINK, model_instance)
    total = SpatialInertia.Zero()
    hinges = modal_hinges(plant, model_instance)
    for joint in hinges:
        X_RF = joint.frame_on_parent().GetFixedPoseInBodyFrame()
        X_BM = joint.frame_on_child().GetFixedPoseInBodyFrame()
        X_RB = X_RF @ X_BM.inverse()  # joint at q = 0: M coincides with F
        M_BBo_B = joint.child_body().default_spatial_inertia()
        M_BBo_R = M_BBo_B.ReExpress(X_RB.rotation())
        M_BRo_R = M_BBo_R.Shift(-X_RB.translation())
        total += M_BRo_R
    if not hinges:
        raise ValueError(
            f"model {plant.GetModelInstanceName(model_instance)}: no joint "
            f"'{MODE_JOINT.format(1)}' found, not a modal appendage"
        )
    mass = total.get_mass()
    residual = SpatialInertia(
        mass=-mass,
        p_PScm_E=total.get_com(),
        G_SP_E=UnitInertia(*_unit_inertia_moments(total)),
        skip_validity_check=True,
    )
    body = plant.AddRigidBody(RESIDUAL_BODY, model_instance, residual)
    plant.WeldFrames(root.body_frame(), body.body_frame(), RigidTransform())
    return body


def _unit_inertia_moments(M) -> tuple[float, ...]:
    G = M.get_unit_inertia().CopyToFullMatrix3()
    return (G[0, 0], G[1, 1], G[2, 2], G[0, 1], G[0, 2], G[1, 2])


def add_floating_joint(
    plant: MultibodyPlant,
    body: RigidBody,
    X_PB: RigidTransform,
    name: str | None = None,
    parent=None,
) -> RpyFloatingJoint:
    """Give ``body`` a roll-pitch-yaw floating joint whose zero is the pose ``X_PB``.

    Parameters
    ----------
    plant : MultibodyPlant
        Plant (not finalized).
    body : RigidBody
        The floating body.
    X_PB : RigidTransform
        Pose of ``body`` in the parent frame at ``q = 0`` (a Context parameter afterwards:
        ``joint.frame_on_parent().SetPoseInParentFrame(context, X)``).
    name : str, optional
        Joint name (default ``<body>_floating``).
    parent : Frame, optional
        Parent frame (default: the world frame).

    Notes
    -----
    The parent-side frame is a fixed offset frame at ``X_PB``, so the operating point has
    ``rpy = 0`` (far from the pitch singularity) and the joint velocities are the body's angular
    and linear velocity relative to the parent, expressed in the body frame at that point. A
    quaternion joint would add two spurious near-zero eigenvalues to a linearization.
    """
    parent = plant.world_frame() if parent is None else parent
    frame = plant.AddFrame(FixedOffsetFrame(f"{body.name()}_operating_frame", parent, X_PB))
    return plant.AddJoint(
        RpyFloatingJoint(name or f"{body.name()}_floating", frame, body.body_frame())
    )
