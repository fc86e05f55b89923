"""Rigid kinematics of the OOS system in the chaser frame R_RH1 (pure numpy, no LFR code).

This module is the independent geometric reference of the scenario:

- :func:`forward_kinematics` places every body (hub RH1, arm links L0..L6, arm tip J7, arrays
  SA1..SA4, target hub RH2) and every port (D1, D2, D3) in R_RH1 at a configuration (single or
  batched). The target hangs on the arm (port D2 frame = arm tip J7 frame) when
  ``delta_C1 = 1``, sits on the hub (D3 frame = D1 frame) when ``delta_C2 = 1``, and when
  decoupled it is drawn at its first-docking pose (its free approach is not modelled).
- :func:`solve_arm_ik` solves the arm inverse kinematics (scipy least squares) for a desired
  arm-tip pose; :func:`waypoint_ik` solves any labelled IK waypoint of the mission (``"docked"``
  closes the kinematic loop of the second docking, J7 = D2 while D3 = D1; ``"grasp"`` grasps
  the target at its standoff pose; pre-grasp, retreat, ...).
- :func:`rigid_spatial_inertia_at_G1` sums the rigid spatial inertias of the connected bodies
  at G1 in R_RH1 (arrays with their full rigid ``D_P``): the low-frequency reference of the
  TITOP model, since its hub acceleration response tends to ``D_G1^-1`` at low frequency.

Examples
--------
>>> from oos_drake.scenario.kinematics import forward_kinematics, rigid_spatial_inertia_at_G1
>>> from oos_drake.scenario.timeline import mission_timeline
>>> timeline = mission_timeline()
>>> config = timeline.configuration(1200.0)
>>> poses = forward_kinematics(timeline.scenario, config)
>>> bool(abs(poses.ports["D3"].p - poses.ports["D1"].p).max() < 1e-12)
True
>>> rigid_spatial_inertia_at_G1(timeline.scenario, config).shape
(6, 6)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from oos_drake.scenario.data import Scenario
from oos_drake.scenario.timeline import Configuration
from oos_drake.titop.spatial import rigid_spatial_inertia, rotation_matrix

__all__ = [
    "BODY_NAMES",
    "IK_WAYPOINTS",
    "IKSolution",
    "Pose",
    "SystemPoses",
    "arm_tip_pose",
    "first_docking_target_pose",
    "forward_kinematics",
    "pose_error",
    "rigid_spatial_inertia_at_G1",
    "solve_arm_ik",
    "waypoint_ik",
    "waypoint_tip_pose",
]

#: Bodies placed by :func:`forward_kinematics` (body frames: RH1 at G1, Li at J_i, SAi at P_i,
#: RH2 at G2).
BODY_NAMES = (
    "RH1", "L0", "L1", "L2", "L3", "L4", "L5", "L6", "SA1", "SA2", "RH2", "SA3", "SA4",
)  # fmt: skip
_TARGET_BODIES = ("RH2", "SA3", "SA4")


@dataclass(frozen=True, eq=False)
class Pose:
    """Rigid transform ``X_AB``: orientation ``R`` (columns = B axes in A) and origin ``p`` (A->B).

    Attributes
    ----------
    R : ndarray
        Shape ``(..., 3, 3)``.
    p : ndarray
        Shape ``(..., 3)`` [m].
    """

    R: np.ndarray
    p: np.ndarray

    @classmethod
    def identity(cls, batch: tuple[int, ...] = ()) -> Pose:
        """Identity transform with optional batch shape."""
        return cls(np.broadcast_to(np.eye(3), batch + (3, 3)), np.zeros(batch + (3,)))

    def __matmul__(self, other: Pose) -> Pose:
        """Composition ``X_AC = X_AB @ X_BC``."""
        return Pose(self.R @ other.R, self.p + np.einsum("...ij,...j->...i", self.R, other.p))

    def inverse(self) -> Pose:
        """``X_BA`` from ``X_AB``."""
        R_T = np.swapaxes(self.R, -1, -2)
        return Pose(R_T, -np.einsum("...ij,...j->...i", R_T, self.p))

    def point(self, p_B: np.ndarray) -> np.ndarray:
        """Position in A of a point given in B [m]."""
        return self.p + np.einsum("...ij,...j->...i", self.R, np.asarray(p_B, dtype=float))


def pose_error(X_actual: Pose, X_desired: Pose) -> np.ndarray:
    """6-vector ``[p_actual - p_desired; rotation vector of R_desired^T R_actual]`` [m, rad].

    The rotation part is the axis-angle vector of the relative rotation, written in the
    desired frame (its norm is the rotation angle between the two frames).
    """
    from scipy.spatial.transform import Rotation

    dp = X_actual.p - X_desired.p
    R_rel = np.swapaxes(X_desired.R, -1, -2) @ X_actual.R
    rotation = Rotation.from_matrix(R_rel.reshape(-1, 3, 3)).as_rotvec()
    rotation = rotation.reshape(R_rel.shape[:-2] + (3,))
    return np.concatenate([dp, rotation], axis=-1)


# ----------------------------------------------------------------------------------------------
# forward kinematics
# ----------------------------------------------------------------------------------------------
def _arm_frames(scenario: Scenario, alpha: np.ndarray) -> tuple[list[Pose], Pose]:
    """Poses of the link frames R_L0..R_L6 (at J0..J6) and of the tip frame J7 in R_RH1."""
    arm = scenario.arm
    batch = alpha.shape[:-1]
    frame = Pose(
        np.broadcast_to(arm.R_G_L0, batch + (3, 3)), np.broadcast_to(arm.p_G_J0, batch + (3,))
    )
    frames = [frame]
    for i, link in enumerate(arm.links[1:], start=1):
        parent = arm.links[i - 1]
        joint = Pose(
            rotation_matrix(link.joint_axis, alpha[..., i - 1]),
            np.broadcast_to(parent.p_J_Jnext, batch + (3,)),
        )
        frame = frame @ joint
        frames.append(frame)
    tip = Pose(frame.R, frame.point(arm.links[-1].p_J_Jnext))
    return frames, tip


def arm_tip_pose(scenario: Scenario, alpha) -> Pose:
    """Pose of the arm tip frame J7 (``R_L6`` moved to J7) in R_RH1 for joint angles ``alpha``.

    Parameters
    ----------
    scenario : Scenario
        Scenario data.
    alpha : array_like
        Joint angles alpha_1..6 [rad], shape ``(..., 6)``.
    """
    return _arm_frames(scenario, np.asarray(alpha, dtype=float))[1]


def _hub_port(scenario: Scenario, name: str) -> Pose:
    port = scenario.ports[name]
    return Pose(port.R_G_D, port.p_G_D)


def first_docking_target_pose(scenario: Scenario) -> Pose:
    """Pose ``X_RH1_RH2`` of the target at the first docking.

    The D3 frame is the D1 frame moved by ``mission.first_docking_standoff`` along z_D1 (the
    target is parallel to its docked pose, further out along the approach axis).
    """
    X_D1 = _hub_port(scenario, "D1")
    standoff = scenario.mission.first_docking_standoff
    X_D3 = Pose(X_D1.R, X_D1.p + standoff * X_D1.R[:, 2])
    return X_D3 @ _hub_port(scenario, "D3").inverse()


def _docked_target_pose(scenario: Scenario) -> Pose:
    """``X_RH1_RH2`` with the D3 frame on the D1 frame."""
    return _hub_port(scenario, "D1") @ _hub_port(scenario, "D3").inverse()


@dataclass(frozen=True, eq=False)
class SystemPoses:
    """Poses of all bodies and ports in R_RH1 at a (possibly batched) configuration.

    Attributes
    ----------
    configuration : Configuration
        The configuration the poses belong to.
    bodies : Mapping[str, Pose]
        Body frames (see ``BODY_NAMES``): RH1 at G1 (identity), Li at J_i, SAi at P_i (tilted
        by theta_i), RH2 at G2.
    ports : Mapping[str, Pose]
        Port frames D1, D2, D3 and the arm tip J7.
    centers_of_mass : Mapping[str, ndarray]
        G1 -> centre of mass of each body in R_RH1, shape ``(..., 3)`` [m].
    target_connected : ndarray of bool
        Whether the target (RH2, SA3, SA4) is attached to the chaser, ``time.shape``.
    """

    configuration: Configuration
    bodies: Mapping[str, Pose]
    ports: Mapping[str, Pose]
    centers_of_mass: Mapping[str, np.ndarray]
    target_connected: np.ndarray

    def joint_positions(self) -> np.ndarray:
        """Positions of J0..J7 in R_RH1, shape ``(..., 8, 3)`` [m]."""
        points = [self.bodies[f"L{i}"].p for i in range(7)] + [self.ports["J7"].p]
        return np.stack(points, axis=-2)


def forward_kinematics(scenario: Scenario, configuration: Configuration) -> SystemPoses:
    """Place every body and port in R_RH1 at a configuration.

    Parameters
    ----------
    scenario : Scenario
        Scenario data.
    configuration : Configuration
        Angles and switches (single or batched); switches must be 0 or 1, not both 1.

    Returns
    -------
    SystemPoses

    Raises
    ------
    ValueError
        A switch is not 0/1, or both switches are 1.
    """
    c1 = configuration.delta_C1
    c2 = configuration.delta_C2
    if np.any((c1 != 0) & (c1 != 1)) or np.any((c2 != 0) & (c2 != 1)):
        raise ValueError("forward_kinematics needs delta_C1, delta_C2 in {0, 1}")
    if np.any((c1 == 1) & (c2 == 1)):
        raise ValueError("delta_C1 and delta_C2 cannot both be 1")
    batch = configuration.time.shape
    frames, tip = _arm_frames(scenario, configuration.alpha)
    bodies: dict[str, Pose] = {"RH1": Pose.identity(batch)}
    bodies.update({f"L{i}": frame for i, frame in enumerate(frames)})

    # target: on the arm (C1), on the hub (C2), or waiting at its first-docking pose
    via_arm = tip @ _hub_port(scenario, "D2").inverse()
    docked = _docked_target_pose(scenario)
    waiting = first_docking_target_pose(scenario)
    on_arm = (c1 == 1)[..., None]
    on_hub = (c2 == 1)[..., None]
    target_R = np.where(
        on_arm[..., None], via_arm.R, np.where(on_hub[..., None], docked.R, waiting.R)
    )
    target_p = np.where(on_arm, via_arm.p, np.where(on_hub, docked.p, waiting.p))
    bodies["RH2"] = Pose(target_R, target_p)

    for name, mount in scenario.arrays.items():
        index = int(name[2:]) - 1
        local = Pose(
            mount.R_G_P0 @ rotation_matrix(mount.axis, configuration.theta[..., index]),
            np.broadcast_to(mount.p_G_P, batch + (3,)),
        )
        bodies[name] = bodies[mount.parent] @ local

    ports = {
        name: bodies[port.body] @ Pose(port.R_G_D, port.p_G_D)
        for name, port in scenario.ports.items()
    }
    ports["J7"] = tip
    ordered = {name: bodies[name] for name in BODY_NAMES}
    centers = {name: bodies[name].point(p_com) for name, _, p_com, _ in _rigid_bodies(scenario)}
    return SystemPoses(
        configuration=configuration,
        bodies=MappingProxyType(ordered),
        ports=MappingProxyType(ports),
        centers_of_mass=MappingProxyType({name: centers[name] for name in BODY_NAMES}),
        target_connected=np.asarray((c1 == 1) | (c2 == 1)),
    )


# ----------------------------------------------------------------------------------------------
# inverse kinematics
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class IKSolution:
    """Result of :func:`solve_arm_ik`.

    Attributes
    ----------
    alpha : (6,) ndarray
        Joint angles alpha_1..6 [rad], wrapped to (-pi, pi].
    residual : float
        Norm of the 6-vector pose error [m and rad mixed: position error in m, angle in rad].
    position_error : float
        Arm-tip position error [m].
    angle_error : float
        Arm-tip orientation error [rad].
    """

    alpha: np.ndarray
    residual: float
    position_error: float
    angle_error: float


def _wrap(angle: np.ndarray) -> np.ndarray:
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def solve_arm_ik(
    scenario: Scenario,
    X_desired: Pose,
    alpha0,
    *,
    extra_guesses: int = 16,
    rng: np.random.Generator | None = None,
) -> IKSolution:
    """Joint angles that put the arm tip frame J7 on a desired pose (least squares).

    The residual is :func:`pose_error` of the tip; the Jacobian is the arm's geometric
    Jacobian (exact at the solution). Starts from ``alpha0`` and, if that does not converge,
    from ``extra_guesses`` random guesses; among converged solutions the one closest to
    ``alpha0`` is returned.

    Parameters
    ----------
    scenario : Scenario
        Scenario data.
    X_desired : Pose
        Desired ``X_RH1_J7``.
    alpha0 : array_like
        Initial guess (6,) [rad].
    extra_guesses : int
        Number of random restarts used when the first start fails.
    rng : numpy.random.Generator, optional
        Random generator for the restarts (default: seeded ``default_rng(0)``).

    Returns
    -------
    IKSolution

    Raises
    ------
    ValueError
        No start converged to a residual below 1e-10 (pose out of reach).
    """
    from scipy.optimize import least_squares  # late: keep scenario loading light

    alpha0 = np.asarray(alpha0, dtype=float)
    rng = np.random.default_rng(0) if rng is None else rng
    axes = scenario.arm.joint_axes

    def residual(alpha):
        return pose_error(arm_tip_pose(scenario, alpha), X_desired)

    def jacobian(alpha):
        frames, tip = _arm_frames(scenario, alpha)
        J = np.zeros((6, 6))
        for i in range(6):
            axis_world = frames[i + 1].R @ axes[i]
            J[:3, i] = np.cross(axis_world, tip.p - frames[i + 1].p)
            J[3:, i] = X_desired.R.T @ axis_world
        return J

    guesses = [alpha0] + [rng.uniform(-np.pi, np.pi, 6) for _ in range(extra_guesses)]
    best = None
    for guess in guesses:
        fit = least_squares(
            residual,
            guess,
            jac=jacobian,
            method="lm",
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
            max_nfev=2000,
        )
        error = residual(fit.x)
        norm = float(np.linalg.norm(error))
        if norm < 1e-10:
            alpha = _wrap(fit.x)
            distance = float(np.linalg.norm(_wrap(alpha - alpha0)))
            if best is None or distance < best[0]:
                best = (distance, alpha, error)
            if guess is alpha0:
                break
    if best is None:
        raise ValueError(
            "arm inverse kinematics: desired tip pose out of reach (no start converged)"
        )
    _, alpha, error = best
    error = residual(alpha)
    return IKSolution(
        alpha=alpha,
        residual=float(np.linalg.norm(error)),
        position_error=float(np.linalg.norm(error[:3])),
        angle_error=float(np.linalg.norm(error[3:])),
    )


#: Arm waypoints defined by inverse kinematics (label -> what the arm tip J7 does).
IK_WAYPOINTS = {
    "pre-grasp": "J7 backed out of D2 by grasp_approach_distance, target at the standoff pose",
    "grasp": "J7 on D2, target at the first-docking standoff pose",
    "docked": "J7 on D2 while D3 is on D1 (closed kinematic loop of the second docking)",
    "retreat": "J7 backed out of D2 by grasp_approach_distance, target docked at the hub",
}


def waypoint_tip_pose(scenario: Scenario, label: str) -> Pose:
    """Desired arm-tip pose ``X_RH1_J7`` of an inverse-kinematics waypoint (see ``IK_WAYPOINTS``).

    Parameters
    ----------
    scenario : Scenario
        Scenario data.
    label : str
        ``"pre-grasp"``, ``"grasp"``, ``"docked"`` or ``"retreat"``.
    """
    if label not in IK_WAYPOINTS:
        raise ValueError(f"no inverse-kinematics waypoint '{label}' (have {list(IK_WAYPOINTS)})")
    target = _docked_target_pose(scenario) if label in ("docked", "retreat") else None
    if target is None:
        target = first_docking_target_pose(scenario)
    grasp = target @ _hub_port(scenario, "D2")
    if label in ("pre-grasp", "retreat"):
        distance = scenario.mission.grasp_approach_distance
        return Pose(grasp.R, grasp.p - distance * grasp.R[:, 1])
    return grasp


def waypoint_ik(scenario: Scenario, label: str = "docked", alpha0=None) -> IKSolution:
    """Solve the inverse kinematics of a labelled arm waypoint (see ``IK_WAYPOINTS``).

    Parameters
    ----------
    scenario : Scenario
    label : str
        ``"pre-grasp"``, ``"grasp"``, ``"docked"`` (closes the loop J7 = D2, D3 = D1) or
        ``"retreat"``.
    alpha0 : array_like, optional
        Initial guess (default: the stored waypoint with that label).
    """
    X_desired = waypoint_tip_pose(scenario, label)
    if alpha0 is None:
        alpha0 = scenario.mission.arm_waypoints.at(label)
    return solve_arm_ik(scenario, X_desired, alpha0)


# ----------------------------------------------------------------------------------------------
# mass properties
# ----------------------------------------------------------------------------------------------
def _rigid_bodies(scenario: Scenario, target_mass=None, target_inertia=None):
    """(name, mass, CoM in body frame, inertia at CoM in body frame) of every rigid body."""
    chaser, target = scenario.hubs["RH1"], scenario.hubs["RH2"]
    yield "RH1", chaser.mass, np.zeros(3), chaser.inertia
    mass = target.mass if target_mass is None else float(target_mass)
    inertia = target.inertia if target_inertia is None else np.asarray(target_inertia, float)
    if not mass > 0 or inertia.shape != (3, 3):
        raise ValueError(
            f"RH2: target_mass must be > 0 and target_inertia 3x3, got {mass:g}, "
            f"shape {inertia.shape}"
        )
    yield "RH2", mass, np.zeros(3), inertia
    for link in scenario.arm.links:
        yield link.name, link.mass, link.p_J_G, link.inertia
    for name, mount in scenario.arrays.items():
        model = mount.model
        yield name, model.mass, model.p_P_S, model.inertia


def rigid_spatial_inertia_at_G1(
    scenario: Scenario,
    configuration: Configuration,
    *,
    target_mass: float | None = None,
    target_inertia: np.ndarray | None = None,
) -> np.ndarray:
    """Total rigid spatial inertia of the connected system at G1 in R_RH1.

    .. math:: D_{G_1} = \\sum_b \\tau_{G_b G_1}^T
              \\begin{bmatrix} m_b I_3 & 0 \\\\ 0 & R_b J_b R_b^T \\end{bmatrix} \\tau_{G_b G_1}

    over the chaser hub, the arm links, the chaser arrays and, when ``delta_C1`` or
    ``delta_C2`` is 1, the target hub and its arrays (arrays as rigid bodies: full ``D_P``).

    Parameters
    ----------
    scenario : Scenario
        Scenario data (nominal masses and inertias).
    configuration : Configuration
        Single or batched configuration.
    target_mass : float, optional
        Mass of RH2 [kg] replacing the nominal one (e.g. a sampled uncertain value).
    target_inertia : (3, 3) array, optional
        Inertia of RH2 at G2 in R_RH2 [kg m^2] replacing the nominal one.

    Returns
    -------
    ndarray
        Shape ``time.shape + (6, 6)`` [kg, kg m, kg m^2]; ``[F; T_G1] = D_G1 [a_G1; wdot]``.
        Each term is written in the expanded (parallel-axis) form of ``tau^T D tau``:
        ``[[m I, -m [r]x], [m [r]x, R J R^T - m [r]x^2]]`` with ``r`` = G1 -> CoM.
    """
    poses = forward_kinematics(scenario, configuration)
    batch = configuration.time.shape
    total = np.zeros(batch + (6, 6))
    connected = poses.target_connected.astype(float)
    for name, mass, _, inertia in _rigid_bodies(scenario, target_mass, target_inertia):
        pose = poses.bodies[name]
        r = poses.centers_of_mass[name]  # G1 -> CoM in R_RH1
        J = pose.R @ inertia @ np.swapaxes(pose.R, -1, -2)
        block = rigid_spatial_inertia(mass, J, r)
        weight = connected[..., None, None] if name in _TARGET_BODIES else 1.0
        total += weight * block
    return total
