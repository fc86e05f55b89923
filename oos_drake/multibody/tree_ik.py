"""Inverse kinematics on a spacecraft tree's Drake twin: place a port at a pose.

:func:`solve_port_pose` moves the revolute joints on the path from the root to the port's body
(an arm chain of any length) so that the port frame reaches a pose given in the root's
centre-of-mass frame; every other coordinate (the root's floating joint, other drives, the mode
hinges) stays at the operating point. It is a least-squares problem on Drake's
``InverseKinematics`` (position and orientation costs, joint limits of the tree file as bounds),
restarted from seeded random guesses until the residual is within tolerance; a pose out of
reach raises a one-line error with the residual.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from pydrake.math import RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import Solve

from oos_drake.multibody.tree_plant import TreeDiagram, build_tree_diagram
from oos_drake.multibody.tree_sdf import TREE_ASSEMBLY_MODEL
from oos_drake.scenario.data import ScenarioError
from oos_drake.scenario.tree_mission import IkSolution, Timeline, TipWaypoint, build_timeline

__all__ = [
    "IkSolution",
    "chain_to_port",
    "solve_port_pose",
    "port_pose_drake",
    "mission_timeline",
]


def chain_to_port(tree, port: str) -> tuple[str, ...]:
    """Bodies on revolute joints between the root and ``port``'s body, root side first."""
    if port not in tree.ports:
        raise ScenarioError(f"ports.{port}", f"no such port (ports: {', '.join(tree.ports)})")
    return tree.revolute_chain(tree.ports[port].body)


def _port_frame(handles: TreeDiagram, port: str):
    plant = handles.plant
    return plant.GetFrameByName(port, plant.GetModelInstanceByName(TREE_ASSEMBLY_MODEL))


def _operating_positions(handles: TreeDiagram, angles: Mapping[str, float]) -> np.ndarray:
    plant = handles.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, np.zeros(plant.num_positions()))
    for name, joint in handles.revolute_joints.items():
        joint.set_angle(context, float(angles[name]))
    return plant.GetPositions(context)


def port_pose_drake(
    handles: TreeDiagram, port: str, angles: Mapping[str, float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(R_G_D, p_G_D)`` of ``port`` by Drake's forward kinematics, root at its operating pose
    (its centre-of-mass frame is the world frame) [-, m]."""
    chosen = handles.tree.joint_angles(angles)
    plant = handles.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, _operating_positions(handles, chosen))
    X = _port_frame(handles, port).CalcPoseInWorld(context)
    return X.rotation().matrix(), X.translation()


def _errors(R, p, R_target, p_target) -> tuple[float, float]:
    """Position error [m] and rotation angle from target to actual axes [rad] (accurate when
    small: ``atan2(sin, cos)`` from the skew and trace parts)."""
    E = R_target.T @ R
    sin = 0.5 * np.linalg.norm([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
    cos = (np.trace(E) - 1.0) / 2.0
    return float(np.linalg.norm(p - p_target)), float(np.arctan2(sin, cos))


def solve_port_pose(
    handles: TreeDiagram,
    port: str,
    R_target,
    p_target,
    *,
    initial: Mapping[str, float] | None = None,
    tolerance: float = 1e-6,
    restarts: int = 8,
    seed: int = 0,
) -> IkSolution:
    """Joint angles of the chain to ``port`` that put it at ``(R_target, p_target)``.

    Parameters
    ----------
    handles : TreeDiagram
        The tree's twin (:func:`oos_drake.multibody.tree_plant.build_tree_diagram`).
    port : str
        Port to place (e.g. an arm's tip port).
    R_target : array_like (3, 3)
        Target port axes in the root's axes [-].
    p_target : array_like (3,)
        Target port position from the root's centre of mass, root axes [m].
    initial : Mapping[str, float], optional
        First guess [rad] by body (default: the file's angles); joints off the chain stay at the
        file's angles.
    tolerance : float
        Largest accepted position [m] and orientation [rad] residual.
    restarts : int
        Random first guesses (within the joint limits) tried after the given one.
    seed : int
        Seed of those guesses (``numpy.random.default_rng``).

    Raises
    ------
    ScenarioError
        ``ports.<port>: inverse kinematics misses the pose by ... m, ... rad`` when no guess
        reaches it (out of reach or beyond the joint limits).
    """
    tree = handles.tree
    chain = chain_to_port(tree, port)
    if not chain:
        raise ScenarioError(f"ports.{port}", "no revolute joint between the root and this port")
    R_target = np.asarray(R_target, dtype=float)
    p_target = np.asarray(p_target, dtype=float)
    plant = handles.plant
    angles = tree.joint_angles(initial)
    q_operating = _operating_positions(handles, angles)
    free = {name: handles.revolute_joints[name].position_start() for name in chain}
    frame = _port_frame(handles, port)
    rng = np.random.default_rng(seed)
    limits = {name: (tree.body(name).joint.lower, tree.body(name).joint.upper) for name in chain}
    best = None
    for attempt in range(restarts + 1):
        ik = InverseKinematics(plant, with_joint_limits=False)
        q = ik.q()
        prog = ik.get_mutable_prog()
        for index in range(plant.num_positions()):
            if index not in free.values():
                prog.AddBoundingBoxConstraint(q_operating[index], q_operating[index], q[index])
        guess = q_operating.copy()
        for name, index in free.items():
            low, high = limits[name]
            prog.AddBoundingBoxConstraint(low, high, q[index])
            if attempt:
                guess[index] = rng.uniform(low, high)
        # weights: SNOPT stops on a relative optimality tolerance; large weights -> small residual
        ik.AddPositionCost(plant.world_frame(), p_target, frame, np.zeros(3), 1e4 * np.eye(3))
        ik.AddOrientationCost(
            plant.world_frame(), RotationMatrix(R_target), frame, RotationMatrix(), 1e4
        )
        prog.SetInitialGuess(q, guess)
        result = Solve(prog)
        values = result.GetSolution(q)
        # bounds hold to the solver's feasibility tolerance: clip onto the limits
        solution = {
            name: float(np.clip(values[index], *limits[name])) for name, index in free.items()
        }
        R, p = port_pose_drake(handles, port, {**angles, **solution})
        position_error, orientation_error = _errors(R, p, R_target, p_target)
        candidate = IkSolution(port, solution, position_error, orientation_error)
        if best is None or max(position_error, orientation_error) < max(
            best.position_error, best.orientation_error
        ):
            best = candidate
        if max(position_error, orientation_error) <= tolerance:
            return candidate
    raise ScenarioError(
        f"ports.{port}",
        f"inverse kinematics misses the pose by {best.position_error:.3g} m and "
        f"{best.orientation_error:.3g} rad after {restarts + 1} guesses (out of reach?)",
    )


def mission_timeline(
    tree, handles: TreeDiagram | None = None, *, tolerance: float = 1e-6
) -> Timeline:
    """The timeline of ``tree``'s mission, its tip-pose waypoints solved on its Drake twin.

    Each tip waypoint is solved once, by :func:`solve_port_pose` from the angles the previous
    phases left (so consecutive waypoints stay on one branch of the arm's solutions).

    Parameters
    ----------
    tree : SpacecraftTree
        The tree (with or without ``[mission]``).
    handles : TreeDiagram, optional
        Its twin (default: built from ``tree`` when a tip waypoint needs it).
    tolerance : float
        Largest accepted position [m] and orientation [rad] residual of a tip waypoint.

    Raises
    ------
    ScenarioError
        ``mission.<phase>.tip: inverse kinematics misses the pose by ... m and ... rad ...``.
    """
    if tree.mission is None or not tree.mission.has_tip_waypoints:
        return build_timeline(tree)
    handles = build_tree_diagram(tree) if handles is None else handles

    def solve(phase: str, tip: TipWaypoint, angles) -> IkSolution:
        try:
            return solve_port_pose(
                handles, tip.port, tip.R_G_D, tip.p_G_D, initial=angles, tolerance=tolerance
            )
        except ScenarioError as error:
            raise ScenarioError(f"mission.{phase}.tip", error.detail) from None

    return build_timeline(tree, solve)
