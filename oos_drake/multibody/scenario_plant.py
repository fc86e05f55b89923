"""Factory of the scenario's Drake twin: MultibodyPlant from the SDF files plus Drake-only parts.

``build_scenario_diagram(connection)`` parses ``oos_scenario.sdf`` of
:data:`~oos_drake.multibody.scenario_sdf.SDF_DIRECTORY` (after validating every SDF file it
includes), then

- adds the modal residual bodies of the four arrays (exact ``M_P(s)``, see
  :mod:`oos_drake.multibody.modal_realization`);
- gives the chaser hub RH1 a roll-pitch-yaw floating joint whose zero is the world frame
  (``R_RH1`` is the reference frame of the linear models) and, unless it is clamped, the target
  hub RH2 a roll-pitch-yaw 6-DOF joint *relative to RH1* whose zero is a frame fixed in RH1
  with a *Context parameter* pose (a context is placed at any operating point without
  rebuilding; no force depends on the chaser's own pose, so the global rigid-body motion is
  exactly RH1's coordinates);
- connects the target according to ``connection``:

  ==================  ======================================================================
  ``"free"``          ``delta_C1 = delta_C2 = 0``: target free-floating, not connected
  ``"arm"``           ``delta_C1 = 1``: D2 welded to the arm tip J7 (clamped)
  ``"hub"``           ``delta_C2 = 1``: D3 welded to D1 (clamped)
  ``"spring_damper"`` target free-floating, ``LinearBushingRollPitchYaw`` SM1 (frames J7, D2)
                      and SM2 (D1, D3) whose stiffness and damping are Context parameters
  ==================  ======================================================================

- no gravity; continuous plant (time step 0) so that ``Linearize``/Taylor work directly.

The arm joints ``alpha_1..6`` and the array drives ``theta_SA1..4`` stay revolute joints: the
same diagram runs nonlinear simulations. For a linearization they are *motion-driven* (zero
relative acceleration): :func:`oos_drake.multibody.operating_point.set_operating_point` sets
their angles and locks them in the context, and
:func:`oos_drake.multibody.operating_point.linearize_at` drops their (constant) states.
Diagrams, plants and contexts are not picklable: build one per process.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import LinearBushingRollPitchYaw
from pydrake.systems.framework import Diagram, DiagramBuilder

from oos_drake.multibody.linearization import HubPorts, add_hub_io
from oos_drake.multibody.plant_parts import add_floating_joint, add_modal_residual
from oos_drake.multibody.scenario_sdf import (
    ARM_MODEL,
    ASSEMBLY_FILE,
    ASSEMBLY_MODEL,
    SDF_DIRECTORY,
    SDF_PACKAGE,
    arm_joint_name,
    drive_joint_name,
    scenario_sdf_directory,
)
from oos_drake.multibody.sdf_validation import validate_sdf_tree

__all__ = [
    "CONNECTIONS",
    "ScenarioDiagram",
    "add_docking_bushings",
    "add_scenario_plant",
    "build_scenario_diagram",
    "cached_scenario_diagram",
    "connection_for",
    "prescribed_joints",
    "set_bushing",
    "set_spring_damper",
    "twin_diagram",
]

CONNECTIONS = ("free", "arm", "hub", "spring_damper")
ARRAYS = ("SA1", "SA2", "SA3", "SA4")
CHASER, TARGET = "RH1", "RH2"
#: Port and mount frames the twin needs, and the SDF file that must define each.
REQUIRED_FRAMES = MappingProxyType(
    {
        "D1": "hub_RH1.sdf",
        "J0": "hub_RH1.sdf",
        "P1": "hub_RH1.sdf",
        "P2": "hub_RH1.sdf",
        "D2": "hub_RH2.sdf",
        "D3": "hub_RH2.sdf",
        "P3": "hub_RH2.sdf",
        "P4": "hub_RH2.sdf",
        "J7": "arm_ur5.sdf",
    }
)


@dataclass(frozen=True, eq=False)
class ScenarioDiagram:
    """Handles of a built scenario diagram (not picklable).

    Attributes
    ----------
    diagram : Diagram
        Plant + wrench-input/hub-output maps; exported ports ``W_ext_G1`` and ``y_G1``.
    plant : MultibodyPlant
        The plant (system name ``plant``).
    connection : str
        One of :data:`CONNECTIONS`.
    ports : HubPorts
        Exported port names.
    hub_joint : RpyFloatingJoint
        RH1's floating joint (zero = world frame).
    target_joint : RpyFloatingJoint or None
        RH2's floating joint (``None`` when clamped).
    target_operating_frame : FixedOffsetFrame or None
        Parent frame of ``target_joint`` (fixed in RH1); its pose ``X_G1_F`` is a Context
        parameter.
    arm_joints : tuple of RevoluteJoint
        ``alpha_1..alpha_6``.
    drive_joints : tuple of RevoluteJoint
        ``theta_SA1..theta_SA4``.
    bushings : Mapping[str, LinearBushingRollPitchYaw]
        ``{"SM1": ..., "SM2": ...}`` for ``"spring_damper"``, else empty.
    frames : Mapping[str, Frame]
        Port frames ``D1, D2, D3, J7`` and hub frames ``G1, G2``.
    """

    diagram: Diagram
    plant: MultibodyPlant
    connection: str
    ports: HubPorts
    hub_joint: object
    target_joint: object
    target_operating_frame: object
    arm_joints: tuple
    drive_joints: tuple
    bushings: Mapping[str, LinearBushingRollPitchYaw] = field(default_factory=dict)
    frames: Mapping[str, object] = field(default_factory=dict)

    @property
    def prescribed_joints(self) -> tuple:
        """Motion-driven joints (arm and array drives), locked at a linearization point."""
        return self.arm_joints + self.drive_joints


def connection_for(delta_C1: float, delta_C2: float, spring_dampers: tuple[str, ...] = ()) -> str:
    """Return the connection kind of a configuration (switches in {0, 1}).

    Raises
    ------
    ValueError
        If both switches are 1 (the paper's LFR excludes it) or a switch is not 0 or 1.
    """
    if spring_dampers:
        return "spring_damper"
    c1, c2 = float(delta_C1), float(delta_C2)
    if c1 not in (0.0, 1.0) or c2 not in (0.0, 1.0):
        raise ValueError(f"connection switches must be 0 or 1, got delta_C1={c1}, delta_C2={c2}")
    if c1 and c2:
        raise ValueError("delta_C1 = delta_C2 = 1 is not a configuration of the scenario")
    return "arm" if c1 else ("hub" if c2 else "free")


def add_scenario_plant(builder: DiagramBuilder, sdf_directory: str | Path):
    """Parse the scenario's SDF assembly into a continuous plant in ``builder`` (not finalized).

    The plant (system ``plant``, zero gravity vector) gets the arrays' modal residuals and the
    chaser's floating joint ``RH1_floating`` (zero = world frame), in that order.

    Returns
    -------
    plant : MultibodyPlant
        The plant.
    instance : callable
        Model instance of an assembly part by name (``"RH1"``, ``"SA3"``, ``ARM_MODEL``).
    frames : dict of str to Frame
        Hub frames ``G1``, ``G2`` and port frames ``D1``, ``D2``, ``D3``, ``J7``.
    hub_joint : RpyFloatingJoint
        The chaser's floating joint.
    """
    plant = builder.AddNamedSystem("plant", MultibodyPlant(time_step=0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    parser = Parser(plant)
    parser.package_map().Add(SDF_PACKAGE, str(sdf_directory))
    parser.AddModels(str(Path(sdf_directory) / ASSEMBLY_FILE))

    def instance(name: str):
        return plant.GetModelInstanceByName(f"{ASSEMBLY_MODEL}::{name}")

    for array in ARRAYS:
        add_modal_residual(plant, instance(array))
    chaser = plant.GetBodyByName(CHASER, instance(CHASER))
    target = plant.GetBodyByName(TARGET, instance(TARGET))
    frames = {
        "G1": chaser.body_frame(),
        "G2": target.body_frame(),
        "D1": plant.GetFrameByName("D1", instance(CHASER)),
        "D2": plant.GetFrameByName("D2", instance(TARGET)),
        "D3": plant.GetFrameByName("D3", instance(TARGET)),
        "J7": plant.GetFrameByName("J7", instance(ARM_MODEL)),
    }
    hub_joint = add_floating_joint(plant, chaser, RigidTransform(), name="RH1_floating")
    return plant, instance, frames, hub_joint


def add_docking_bushings(
    plant: MultibodyPlant, frames: Mapping, stiffness: float = 0.0, damping: float = 0.0
) -> dict[str, LinearBushingRollPitchYaw]:
    """The docking spring-dampers ``SM1`` (J7 - D2) and ``SM2`` (D1 - D3) as bushings with
    ``stiffness`` [N/m = N m/rad] and ``damping`` [N s/m = N m s/rad] on every axis."""
    k, d = [stiffness] * 3, [damping] * 3
    return {
        name: plant.AddForceElement(LinearBushingRollPitchYaw(frames[a], frames[c], k, d, k, d))
        for name, (a, c) in {"SM1": ("J7", "D2"), "SM2": ("D1", "D3")}.items()
    }


def prescribed_joints(plant: MultibodyPlant, instance) -> tuple[tuple, tuple]:
    """``(arm joints alpha_1..6, array drive joints theta_SA1..4)`` of a finalized
    :func:`add_scenario_plant` plant."""
    arm = instance(ARM_MODEL)
    return (
        tuple(plant.GetJointByName(arm_joint_name(i), arm) for i in range(1, 7)),
        tuple(plant.GetJointByName(drive_joint_name(a), instance(a)) for a in ARRAYS),
    )


def build_scenario_diagram(
    connection: str = "spring_damper",
    *,
    sdf_directory: str | Path = SDF_DIRECTORY,
    spring_damper: tuple[float, float] = (0.0, 0.0),
) -> ScenarioDiagram:
    """Build the scenario diagram from the SDF files.

    Parameters
    ----------
    connection : str
        One of :data:`CONNECTIONS`.
    sdf_directory : str or Path
        Directory with ``oos_scenario.sdf`` and the files it includes.
    spring_damper : (float, float)
        Default ``(stiffness, damping)`` of both bushings [N/m = N m/rad, N s/m = N m s/rad];
        change them per context with :func:`set_spring_damper`.

    Raises
    ------
    ValueError
        Unknown connection, or an SDF file with an invalid inertia or a missing port frame
        (message names the file and the element).
    """
    if connection not in CONNECTIONS:
        raise ValueError(f"connection must be one of {CONNECTIONS}, got {connection!r}")
    sdf_directory = Path(sdf_directory)
    assembly = sdf_directory / ASSEMBLY_FILE
    validate_sdf_tree(assembly, required_frames=REQUIRED_FRAMES)

    builder = DiagramBuilder()
    plant, instance, frames, hub_joint = add_scenario_plant(builder, sdf_directory)
    target = frames["G2"].body()
    target_joint = target_frame = None
    bushings = {}
    if connection == "arm":
        plant.WeldFrames(frames["J7"], frames["D2"], RigidTransform())
    elif connection == "hub":
        plant.WeldFrames(frames["D1"], frames["D3"], RigidTransform())
    else:
        # relative to the chaser: forces then do not depend on the chaser's pose, so the global
        # rigid-body motion is exactly the chaser's own (q, v) and drops out structurally
        target_joint = add_floating_joint(
            plant, target, RigidTransform(), name="RH2_floating", parent=frames["G1"]
        )
        target_frame = target_joint.frame_on_parent()
    if connection == "spring_damper":
        bushings = add_docking_bushings(plant, frames, *(float(v) for v in spring_damper))
    plant.Finalize()
    ports = add_hub_io(builder, plant, hub_joint)
    diagram = builder.Build()
    diagram.set_name(f"oos_scenario_{connection}")
    arm_joints, drive_joints = prescribed_joints(plant, instance)
    return ScenarioDiagram(
        diagram=diagram,
        plant=plant,
        connection=connection,
        ports=ports,
        hub_joint=hub_joint,
        target_joint=target_joint,
        target_operating_frame=target_frame,
        arm_joints=arm_joints,
        drive_joints=drive_joints,
        bushings=MappingProxyType(bushings),
        frames=MappingProxyType(frames),
    )


@functools.lru_cache(maxsize=8)
def cached_scenario_diagram(
    connection: str, sdf_directory: str = str(SDF_DIRECTORY)
) -> ScenarioDiagram:
    """One :func:`build_scenario_diagram` per connection kind and process (contexts are cheap)."""
    return build_scenario_diagram(connection, sdf_directory=sdf_directory)


def twin_diagram(scenario, connection: str) -> ScenarioDiagram:
    """The Drake twin of ``scenario`` with ``connection`` (cached per process): parsed from the
    scenario's own SDF files (:func:`~oos_drake.multibody.scenario_sdf.scenario_sdf_directory`).

    Parameters
    ----------
    scenario : oos_drake.scenario.data.Scenario
    connection : {"free", "arm", "hub", "spring_damper"}
    """
    directory, _ = scenario_sdf_directory(scenario)
    return cached_scenario_diagram(connection, str(directory))


def set_spring_damper(
    handles: ScenarioDiagram,
    context,
    name: str,
    stiffness: float | tuple[float, float],
    damping: float | tuple[float, float],
) -> None:
    """Set a docking bushing's stiffness and damping in ``context`` (no rebuild).

    Parameters
    ----------
    handles : ScenarioDiagram
        A ``"spring_damper"`` diagram.
    context : Context
        Root (diagram) context.
    name : str
        ``"SM1"`` (J7 - D2) or ``"SM2"`` (D1 - D3).
    stiffness : float or (float, float)
        ``k`` or ``(k_shear, k_tors)`` [N/m, N m/rad], >= 0.
    damping : float or (float, float)
        ``d`` or ``(d_shear, d_tors)`` [N s/m, N m s/rad], >= 0.
    """
    if name not in handles.bushings:
        raise ValueError(
            f"no spring-damper {name!r} in a {handles.connection!r} diagram "
            f"(available: {sorted(handles.bushings)})"
        )
    k_shear, k_tors = np.broadcast_to(np.asarray(stiffness, dtype=float), (2,))
    d_shear, d_tors = np.broadcast_to(np.asarray(damping, dtype=float), (2,))
    for label, value in (("stiffness", (k_shear, k_tors)), ("damping", (d_shear, d_tors))):
        if not np.all(np.isfinite(value)) or min(value) < 0:
            raise ValueError(f"{name}: {label} must be finite and >= 0, got {value}")
    plant_context = handles.plant.GetMyMutableContextFromRoot(context)
    set_bushing(handles.bushings[name], plant_context, (k_shear, k_tors, d_shear, d_tors))


def set_bushing(bushing: LinearBushingRollPitchYaw, plant_context, setting) -> None:
    """Write ``setting = (k_shear, k_tors, d_shear, d_tors)`` [N/m, N m/rad, N s/m, N m s/rad]
    on every axis of ``bushing`` in a plant context (not checked: see :func:`set_spring_damper`)."""
    k_shear, k_tors, d_shear, d_tors = setting
    bushing.SetForceStiffnessConstants(plant_context, [k_shear] * 3)
    bushing.SetTorqueStiffnessConstants(plant_context, [k_tors] * 3)
    bushing.SetForceDampingConstants(plant_context, [d_shear] * 3)
    bushing.SetTorqueDampingConstants(plant_context, [d_tors] * 3)
