"""TITOP building blocks that return LFRs with named parameters (imports ``oos_drake.lfr`` only).

Two-Input Two-Output Port (TITOP) models of substructures (Alazard, Sanfedino et al.): each block
maps the acceleration twist received from its parent and the wrenches received from its children
to the wrench it applies to its parent and the twists it imposes on its children. 6-DOF vectors are
ordered ``[translation; rotation]``, SI units.

Modules
-------
spatial      numeric closed forms: skew, tau_PB, DCMs, rigid spatial inertia, residual mass
parameters   block naming convention and parameter constructors (tau, delta_C, relative ureals)
kinematics   kinematic model tau_PB and frame change T = diag(DCM, DCM) as LFRs
rotation     rotation about an axis by tau = tan(theta/4) (4 occurrences per DCM)
rigid_body   multi-port rigid body (inverse model), inverted port (direct model), rigid link
appendage    cantilevered flexible appendage one-port M_P(s)
connection   fixed / revolute connections, switches delta_C I12, spring-dampers
assembly     connect blocks by named port signals into one LFR
inversion    partial inversion of channels (invio): inverse model -> direct model at a port
"""

from oos_drake.titop.appendage import flexible_appendage
from oos_drake.titop.assembly import Component, assemble
from oos_drake.titop.connection import (
    fixed_connection,
    revolute_connection,
    revolute_frame_changes,
    spring_damper,
    spring_damper_parameters,
)
from oos_drake.titop.inversion import invert_channels
from oos_drake.titop.kinematics import frame_change, kinematic_model, repeat
from oos_drake.titop.parameters import angle_parameter, connection_parameter, relative_parameter
from oos_drake.titop.rigid_body import (
    rigid_body_direct,
    rigid_body_inverse,
    rigid_link,
    spatial_inertia_lfr,
    uncertain_inertia,
    uncertain_mass,
)
from oos_drake.titop.rotation import rotation_dcm, rotation_frame_change, rotation_matrix_lfr

__all__ = [
    "Component",
    "angle_parameter",
    "assemble",
    "connection_parameter",
    "fixed_connection",
    "flexible_appendage",
    "frame_change",
    "invert_channels",
    "kinematic_model",
    "relative_parameter",
    "repeat",
    "revolute_connection",
    "revolute_frame_changes",
    "rigid_body_direct",
    "rigid_body_inverse",
    "rigid_link",
    "rotation_dcm",
    "rotation_frame_change",
    "rotation_matrix_lfr",
    "spatial_inertia_lfr",
    "spring_damper",
    "spring_damper_parameters",
    "uncertain_inertia",
    "uncertain_mass",
]
