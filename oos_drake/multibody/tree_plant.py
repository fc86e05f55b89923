"""The Drake twin of a spacecraft tree, its linearization and its check against the TITOP LFR.

:func:`build_tree_diagram` parses the tree's SDF folder (:mod:`oos_drake.multibody.tree_sdf`)
into a continuous plant without gravity, adds the appendages' modal residual bodies and a
roll-pitch-yaw floating joint on the controlled (root) body whose zero is the world frame, and
wraps the plant with the hub wrench input and hub outputs at the root's centre of mass
(:func:`oos_drake.multibody.linearization.add_hub_io`). The revolute joints stay joints: a
linearization sets them at their angles and locks them (motion-driven, zero relative
acceleration), as the TITOP model's scheduled blocks ``tau_<body>`` assume.

:func:`check_tree` compares the twin's 6x6 response ``[F; T] -> [a; wdot]`` at ``G`` with the
TITOP LFR's nominal (frequency response, poles and zeros of the minimal realizations, with
:func:`oos_drake.multibody.cross_check.compare_systems`). Neither model uses the other.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import control
import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import LinearBushingRollPitchYaw
from pydrake.systems.framework import Diagram, DiagramBuilder

from oos_drake.lfr import usubs
from oos_drake.multibody.cross_check import VALIDATION_OMEGA, CaseResult, compare_systems
from oos_drake.multibody.linearization import (
    HubPorts,
    add_hub_io,
    linearize_hub,
    structural_prune,
)
from oos_drake.multibody.plant_parts import add_floating_joint, add_modal_residual
from oos_drake.multibody.sdf_validation import validate_sdf_tree
from oos_drake.multibody.tree_sdf import (
    TREE_ASSEMBLY_FILE,
    TREE_ASSEMBLY_MODEL,
    TREE_SDF_PACKAGE,
    joint_name,
    write_tree_sdf,
)
from oos_drake.scenario.tree import SpacecraftTree, captured_tree, docked_tree
from oos_drake.scenario.tree_model import build_tree_model, tree_values

__all__ = [
    "TreeDiagram",
    "build_tree_diagram",
    "build_captured_diagram",
    "build_docked_diagram",
    "add_docked_target",
    "docked_target_pose",
    "linearize_tree",
    "check_tree",
]


@dataclass(frozen=True, eq=False)
class TreeDiagram:
    """Handles of a built tree diagram (not picklable).

    Attributes
    ----------
    diagram : Diagram
        Plant + hub wrench input ``W_ext_G1`` and output ``y_G1`` (at the root's centre of mass).
    plant : MultibodyPlant
        The plant (system ``plant``).
    tree : SpacecraftTree
        The tree it was built from.
    ports : HubPorts
        Exported port names.
    hub_joint : RpyFloatingJoint
        The root's floating joint (zero = world frame).
    revolute_joints : Mapping[str, RevoluteJoint]
        Joint of each body on a revolute joint, by body name.
    sdf_directory : Path
        Folder of the SDF files parsed.
    """

    diagram: Diagram
    plant: MultibodyPlant
    tree: SpacecraftTree
    ports: HubPorts
    hub_joint: object
    revolute_joints: Mapping[str, object] = field(default_factory=dict)
    sdf_directory: Path | None = None


def build_tree_diagram(
    tree: SpacecraftTree, sdf_directory: str | Path | None = None
) -> TreeDiagram:
    """Build the Drake twin of ``tree``.

    Parameters
    ----------
    tree : SpacecraftTree
        Validated tree.
    sdf_directory : str or Path, optional
        Folder holding the tree's SDF files (``spacecraft.sdf`` and the appendages); default:
        generated from ``tree`` into a temporary folder (removed once parsed).

    Raises
    ------
    ValueError
        An SDF file with an invalid inertia (message names the file and the link).
    """
    if sdf_directory is None:
        with tempfile.TemporaryDirectory(prefix="oos-tree-sdf-") as folder:
            write_tree_sdf(tree, folder)
            handles = build_tree_diagram(tree, folder)
        return handles
    return _build(tree, Path(sdf_directory))


def _parse_tree_sdf(plant, tree: SpacecraftTree, sdf_directory: Path, prefix: str = ""):
    """Parse one tree's SDF folder into ``plant`` (model names under ``prefix::`` if given);
    add the modal residual bodies of its appendages; return its assembly model instance."""
    assembly = sdf_directory / TREE_ASSEMBLY_FILE
    validate_sdf_tree(assembly, required_frames=tuple(tree.ports))
    parser = Parser(plant, model_name_prefix=prefix)
    parser.package_map().Add(TREE_SDF_PACKAGE, str(sdf_directory))
    parser.AddModels(str(assembly))
    scope = f"{prefix}::" if prefix else ""
    top = plant.GetModelInstanceByName(f"{scope}{TREE_ASSEMBLY_MODEL}")
    for body in tree.bodies:
        if body.kind == "flexible":
            add_modal_residual(
                plant,
                plant.GetModelInstanceByName(f"{scope}{TREE_ASSEMBLY_MODEL}::{body.name}"),
            )
    return top


def _build(
    tree: SpacecraftTree,
    sdf_directory: Path,
    *,
    target: SpacecraftTree | None = None,
    target_directory: Path | None = None,
    weld: tuple[str, str] | None = None,
    docking=None,
    also: tuple = (),
    X_W_target: RigidTransform | None = None,
    model_tree: SpacecraftTree | None = None,
) -> TreeDiagram:
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("plant", MultibodyPlant(time_step=0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    top = _parse_tree_sdf(plant, tree, sdf_directory)
    if target is not None:
        # the target: its own model (its SDF folder)
        target_top = _parse_tree_sdf(plant, target, target_directory, prefix=target.name)
        if docking is None:  # welded port to port (Drake's WeldFrames)
            port, target_port = weld
            plant.WeldFrames(
                plant.GetFrameByName(port, top), plant.GetFrameByName(target_port, target_top)
            )
        else:  # free, held by a bushing between the ports, at rest at X_W_target
            add_docked_target(plant, tree, top, target, target_top, X_W_target, (docking, *also))
    root = plant.GetBodyByName(tree.root, top)
    hub_joint = add_floating_joint(plant, root, RigidTransform(), name=f"{tree.root}_floating")
    plant.Finalize()
    ports = add_hub_io(builder, plant, hub_joint)
    diagram = builder.Build()
    model_tree = tree if model_tree is None else model_tree
    diagram.set_name(f"tree_{model_tree.name}")
    # a joint belongs to its child's model instance (nested for appendages); names are unique
    revolute = {name: plant.GetJointByName(joint_name(name)) for name in model_tree.revolute_bodies}
    return TreeDiagram(
        diagram=diagram,
        plant=plant,
        tree=model_tree,
        ports=ports,
        hub_joint=hub_joint,
        revolute_joints=MappingProxyType(revolute),
        sdf_directory=sdf_directory,
    )


def add_docked_target(plant, tree, top, target, target_top, X_W_target, springs) -> dict:
    """Hold a parsed target by spring-dampers: its root on a roll-pitch-yaw floating joint
    relative to the chaser's root whose zero is ``X_W_target`` (the rest pose with the chaser's
    root at the world frame), one ``LinearBushingRollPitchYaw`` per spring-damper of
    ``springs`` between its two port frames (shear and torsion coefficients of each, equal
    on the three axes).

    On a floating joint relative to the chaser's root, as the paper's twin (scenario_plant):
    the bushing force then does not depend on the root's pose, so the global rigid-body motion
    is exactly the root's own ``(q, v)`` and drops out structurally. Relative to the world, the
    common motion of the two bodies stays in a linearization as near-cancelling states
    (~1e-3 rad/s) that a minimal realization cannot remove reliably.

    Parameters
    ----------
    plant : MultibodyPlant
        Not finalized, holding the tree (model ``top``) and the target (model ``target_top``).
    tree, target : SpacecraftTree
    top, target_top : ModelInstanceIndex
    X_W_target : RigidTransform
        Rest pose of the target's root frame in the chaser's root frame [m].
    springs : sequence of Docking
        The spring-dampers (their ``k_shear`` [N/m], ``k_tors`` [N m/rad], ``d_shear``
        [N s/m], ``d_tors`` [N m s/rad] as they are).

    Returns
    -------
    dict
        ``{label: LinearBushingRollPitchYaw}`` by spring-damper label.
    """
    add_floating_joint(
        plant,
        plant.GetBodyByName(target.root, target_top),
        X_W_target,
        name=f"{target.root}_floating",
        parent=plant.GetBodyByName(tree.root, top).body_frame(),
    )
    bushings = {}
    for spring in springs:
        k = [spring.k_shear] * 3, [spring.k_tors] * 3
        d = [spring.d_shear] * 3, [spring.d_tors] * 3
        bushings[spring.label] = plant.AddForceElement(
            LinearBushingRollPitchYaw(
                plant.GetFrameByName(spring.port, top),
                plant.GetFrameByName(spring.target_port, target_top),
                k[1], d[1], k[0], d[0],
            )
        )  # fmt: skip
    return bushings


def docked_target_pose(
    tree: SpacecraftTree, docking, angles: Mapping[str, float] | None = None
) -> RigidTransform:
    """Rest pose of the target held by ``docking`` relative to the chaser's root (the world
    frame at rest): the ports coinciding, axes aligned, the tree's joints at ``angles`` [rad]
    (default: the file's) and the target's at its file angles; Drake's forward kinematics of
    the tree's twin and of the target's."""
    target = next(t for t in tree.targets.values() if docking.target_port in t.ports)
    chosen = tree.joint_angles(angles)
    X_W_D = _port_pose_in_world(build_tree_diagram(tree), docking.port, chosen)
    X_T_D = _port_pose_in_world(build_tree_diagram(target), docking.target_port, {})
    return X_W_D @ X_T_D.inverse()


def build_captured_diagram(tree: SpacecraftTree, port: str, target_port: str) -> TreeDiagram:
    """The Drake twin of ``tree`` with a target captured: the tree's SDF and the target's own
    SDF (each generated from its file data) parsed as two models, the ports welded by Drake
    (``WeldFrames``, ports coinciding, axes aligned).

    The handles' ``tree`` is :func:`oos_drake.scenario.tree.captured_tree` (for the joint
    names); the weld pose itself is Drake's, computed from the two SDF frames, not from it.

    Parameters
    ----------
    tree : SpacecraftTree
        The tree with its ``targets``.
    port, target_port : str
        Port of the tree and port of a target welded together.
    """
    model_tree = captured_tree(tree, port, target_port)  # KeyError on unknown ports
    target = next(t for t in tree.targets.values() if target_port in t.ports)
    with tempfile.TemporaryDirectory(prefix="oos-tree-sdf-") as folder:
        chaser_directory, target_directory = Path(folder) / "tree", Path(folder) / "target"
        write_tree_sdf(tree, chaser_directory)
        write_tree_sdf(target, target_directory)
        return _build(
            tree,
            chaser_directory,
            target=target,
            target_directory=target_directory,
            weld=(port, target_port),
            model_tree=model_tree,
        )


def build_docked_diagram(
    tree: SpacecraftTree,
    docking,
    angles: Mapping[str, float] | None = None,
    also: tuple = (),
) -> TreeDiagram:
    """The Drake twin of ``tree`` with a target held by a spring-damper: the tree's SDF and the
    target's own SDF parsed as two models, the target on its own floating joint, a
    ``LinearBushingRollPitchYaw`` between the two port frames (stiffness and damping of
    ``docking``, nominal).

    The target's rest pose (ports coinciding, axes aligned, at the joint ``angles`` [rad]) is
    found by Drake's forward kinematics of the tree's twin and of the target's; the handles'
    ``tree`` is :func:`oos_drake.scenario.tree.docked_tree` (for the joint names).

    ``also``: more spring-dampers holding the same target (one more bushing each, between its
    port frames; a closed loop: at ``angles`` their ports are expected to coincide too, as in
    a docking event's configuration, else the bushing is preloaded).
    """
    model_tree = docked_tree(tree, docking, tuple(also))  # KeyError on unknown ports
    target = next(t for t in tree.targets.values() if docking.target_port in t.ports)
    X_W_target = docked_target_pose(tree, docking, angles)
    with tempfile.TemporaryDirectory(prefix="oos-tree-sdf-") as folder:
        chaser_directory, target_directory = Path(folder) / "tree", Path(folder) / "target"
        write_tree_sdf(tree, chaser_directory)
        write_tree_sdf(target, target_directory)
        return _build(
            tree,
            chaser_directory,
            target=target,
            target_directory=target_directory,
            docking=docking,
            also=tuple(also),
            X_W_target=X_W_target,
            model_tree=model_tree,
        )


def _port_pose_in_world(handles: TreeDiagram, port: str, angles) -> RigidTransform:
    """Pose of a port frame in the world (the root's centre-of-mass frame at rest), Drake FK;
    ``angles`` [rad] by body over the file's (a target's drives included)."""
    plant = handles.plant
    context = plant.CreateDefaultContext()
    chosen = handles.tree.joint_angles(angles)
    for name, joint in handles.revolute_joints.items():
        joint.set_angle(context, float(chosen[name]))
    frame = plant.GetFrameByName(port, plant.GetModelInstanceByName(TREE_ASSEMBLY_MODEL))
    return frame.CalcPoseInWorld(context)


def linearize_tree(
    handles: TreeDiagram, angles: Mapping[str, float] | None = None
) -> control.StateSpace:
    """Linearize the twin with its revolute joints locked at ``angles``.

    Parameters
    ----------
    handles : TreeDiagram
        From :func:`build_tree_diagram`.
    angles : Mapping[str, float], optional
        Joint angle [rad] by body; default: the file's operating angles.

    Returns
    -------
    control.StateSpace
        6x6 ``[F; T] at G -> [a; wdot] at G`` in the root's axes [N, N m -> m/s^2, rad/s^2],
        states structurally pruned (the root's rigid-body coordinates and the locked joints'
        coordinates removed): the minimal realization up to numerical cancellation.
    """
    chosen = handles.tree.joint_angles(angles)
    plant = handles.plant
    context = handles.diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositionsAndVelocities(plant_context, np.zeros(plant.num_multibody_states()))
    locked = []
    nq = plant.num_positions()
    for name, joint in handles.revolute_joints.items():
        joint.set_angle(plant_context, chosen[name])
        joint.Lock(plant_context)
        locked += [joint.position_start(), nq + joint.velocity_start()]
    full = linearize_hub(handles.diagram, context, handles.ports)
    keep = np.setdiff1d(np.arange(full.nstates), np.array(locked, dtype=int))
    reduced = control.ss(
        full.A[np.ix_(keep, keep)],
        full.B[keep, :],
        full.C[:6, keep],
        full.D[:6, :],
        inputs=full.input_labels,
        outputs=full.output_labels[:6],
    )
    return structural_prune(reduced)


def check_tree(
    tree: SpacecraftTree,
    angles: Mapping[str, float] | None = None,
    *,
    handles: TreeDiagram | None = None,
    omega: np.ndarray | None = None,
    response_tolerance: float = 1e-6,
    root_tolerance: float = 1e-4,
) -> CaseResult:
    """TITOP LFR (nominal) vs the Drake twin of the same tree at the given joint angles.

    Parameters
    ----------
    tree : SpacecraftTree
        The tree.
    angles : Mapping[str, float], optional
        Joint angles [rad] by body (default: the file's).
    handles : TreeDiagram, optional
        A built twin (default: built from ``tree``).
    omega : ndarray, optional
        Frequencies [rad/s] (default: 400 from 0.01 to 100 Hz).
    response_tolerance, root_tolerance : float
        Pass thresholds (relative) of
        :func:`oos_drake.multibody.cross_check.compare_systems`.

    Returns
    -------
    CaseResult
        Max relative response error, pole and zero errors, minimal orders, verdict.
    """
    handles = build_tree_diagram(tree) if handles is None else handles
    drake = linearize_tree(handles, angles)
    titop = usubs(build_tree_model(tree), tree_values(tree, dict(angles or {}))).nominal.to_ss()
    return compare_systems(
        f"{tree.name}",
        drake,
        titop,
        VALIDATION_OMEGA if omega is None else omega,
        response_tolerance=response_tolerance,
        root_tolerance=root_tolerance,
    )
