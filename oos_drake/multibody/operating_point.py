"""Place the Drake twin at a mission configuration and linearize it there.

A configuration (``oos_drake.scenario.timeline.Configuration``: arm angles ``alpha``, array
angles ``theta``, switches ``delta_C1``, ``delta_C2``) fixes

- the connection kind (:func:`oos_drake.multibody.scenario_plant.connection_for`), hence which
  cached diagram is used;
- the angles of the motion-driven joints, set and **locked** in the context (zero relative
  acceleration: the exact linear model of a prescribed motion);
- the target's operating pose when it floats: J7 = D2 with spring-dampers (the grasp), the
  docked pose D3 = D1 when it is free (it is then decoupled from the hub anyway).

:func:`linearize_at` returns a ``control.StateSpace`` from the wrench ``[F; T]`` at G1 to
``[a_G1; wdot; w; rpy]`` in ``R_RH1`` whose states are the plant's ``[q; v]`` without the locked
joints' coordinates (they are constant).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from oos_drake.multibody.linearization import linearize_hub, structural_prune
from oos_drake.multibody.scenario_plant import (
    ScenarioDiagram,
    connection_for,
    set_spring_damper,
)

__all__ = [
    "OperatingPoint",
    "operating_point",
    "set_operating_point",
    "linearize_at",
    "acceleration_response",
]


@dataclass(frozen=True)
class OperatingPoint:
    """Joint angles, connection and spring-damper settings of one linearization.

    Attributes
    ----------
    alpha : tuple of float
        Arm angles ``alpha_1..6`` [rad].
    theta : tuple of float
        Array drive angles ``theta_1..4`` [rad].
    connection : str
        ``"free"``, ``"arm"``, ``"hub"`` or ``"spring_damper"``.
    spring_dampers : tuple of (str, float, float, float, float)
        ``(name, k_shear, k_tors, d_shear, d_tors)`` per bushing [N/m, N m/rad, N s/m,
        N m s/rad]; bushings not listed have zero stiffness and damping (open).
    label : str
        Name for tables (e.g. ``"moment 3"``).
    """

    alpha: tuple[float, ...]
    theta: tuple[float, ...]
    connection: str
    spring_dampers: tuple[tuple[str, float, float, float, float], ...] = ()
    label: str = ""


def operating_point(configuration, spring_dampers=None, label: str = "") -> OperatingPoint:
    """Build an :class:`OperatingPoint` from a scenario ``Configuration``.

    Parameters
    ----------
    configuration : oos_drake.scenario.timeline.Configuration
        A single (non-batch) configuration.
    spring_dampers : Mapping[str, (float, float)], optional
        ``{"SM1": (k, d), ...}`` -- uses spring-damper docking (both shear and torsion);
        bushings not listed are open. ``None``: rigid connections from ``delta_C1, delta_C2``.
    """
    alpha, theta = np.asarray(configuration.alpha), np.asarray(configuration.theta)
    if alpha.shape != (6,) or theta.shape != (4,):
        raise ValueError(
            f"operating_point needs one configuration (alpha (6,), theta (4,)), got alpha "
            f"{alpha.shape} and theta {theta.shape}; index a batch first"
        )
    if not (np.all(np.isfinite(alpha)) and np.all(np.isfinite(theta))):
        raise ValueError(f"operating_point: non-finite angles alpha={alpha}, theta={theta}")
    alpha = tuple(float(v) for v in alpha)
    theta = tuple(float(v) for v in theta)
    if spring_dampers:
        settings = tuple(
            (name, float(k), float(k), float(d), float(d))
            for name, (k, d) in sorted(dict(spring_dampers).items())
        )
        return OperatingPoint(alpha, theta, "spring_damper", settings, label)
    connection = connection_for(float(configuration.delta_C1), float(configuration.delta_C2))
    return OperatingPoint(alpha, theta, connection, (), label)


def set_operating_point(handles: ScenarioDiagram, context, point: OperatingPoint) -> None:
    """Write ``point`` into a root ``context`` of ``handles.diagram`` (no rebuild).

    Sets and locks the arm and drive joints, zeroes every other position and velocity, places
    the floating target and sets the bushing parameters.
    """
    if point.connection != handles.connection:
        raise ValueError(
            f"operating point needs a {point.connection!r} diagram, got {handles.connection!r}"
        )
    plant = handles.plant
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositionsAndVelocities(plant_context, np.zeros(plant.num_multibody_states()))
    angles = np.concatenate([point.alpha, point.theta])
    for joint, angle in zip(handles.prescribed_joints, angles, strict=True):
        joint.Unlock(plant_context)
        joint.set_angle(plant_context, angle)
        joint.Lock(plant_context)
    if handles.target_operating_frame is not None:
        frames = handles.frames
        if handles.connection == "spring_damper":
            # grasp: D2 on J7 (SM1 at rest); SM2 at rest too when the IK closes the loop
            X_WJ7 = frames["J7"].CalcPoseInWorld(plant_context)
            X_GD2 = frames["D2"].GetFixedPoseInBodyFrame()
            X_WG2 = X_WJ7 @ X_GD2.inverse()
        else:
            X_WD1 = frames["D1"].CalcPoseInWorld(plant_context)
            X_WG2 = X_WD1 @ frames["D3"].GetFixedPoseInBodyFrame().inverse()
        # the chaser sits at the world origin (its joint at q = 0), so X_G1G2 = X_WG2
        handles.target_operating_frame.SetPoseInParentFrame(plant_context, X_WG2)
    for name in handles.bushings:
        set_spring_damper(handles, context, name, 0.0, 0.0)
    for name, k_shear, k_tors, d_shear, d_tors in point.spring_dampers:
        set_spring_damper(handles, context, name, (k_shear, k_tors), (d_shear, d_tors))


def _locked_state_indices(handles: ScenarioDiagram) -> np.ndarray:
    nq = handles.plant.num_positions()
    indices = []
    for joint in handles.prescribed_joints:
        indices.append(joint.position_start())
        indices.append(nq + joint.velocity_start())
    return np.array(sorted(indices), dtype=int)


def linearize_at(
    point: OperatingPoint, handles: ScenarioDiagram, context=None
) -> control.StateSpace:
    """Linearize the twin at ``point``: wrench at G1 -> ``[a; wdot; w; rpy]`` in ``R_RH1``.

    Parameters
    ----------
    point : OperatingPoint
        Where to linearize.
    handles : ScenarioDiagram
        The twin with ``point.connection``
        (:func:`~oos_drake.multibody.scenario_plant.twin_diagram`).
    context : Context, optional
        Root context to reuse (default: a new one).

    Returns
    -------
    control.StateSpace
        Inputs ``Fx Fy Fz Tx Ty Tz`` [N, N m]; outputs ``ax ay az`` [m/s^2], ``wdot_*``
        [rad/s^2], ``w*`` [rad/s], ``roll pitch yaw`` [rad]. Rows 0:6 are the 6x6
        acceleration response.
    """
    if context is None:
        context = handles.diagram.CreateDefaultContext()
    set_operating_point(handles, context, point)
    full = linearize_hub(handles.diagram, context, handles.ports)
    keep = np.setdiff1d(np.arange(full.nstates), _locked_state_indices(handles))
    return control.ss(
        full.A[np.ix_(keep, keep)],
        full.B[keep, :],
        full.C[:, keep],
        full.D,
        inputs=full.input_labels,
        outputs=full.output_labels,
    )


def acceleration_response(system: control.StateSpace, prune: bool = True) -> control.StateSpace:
    """The 6x6 part ``[F; T] -> [a_G1; wdot]`` of a :func:`linearize_at` result.

    With ``prune`` (default) the states that cannot reach these outputs are removed
    structurally: the chaser's rigid-body coordinates and a free target's states. The result is
    then the minimal realization (48 states with rigid connections, 60 with spring-dampers).
    """
    return structural_prune(system[0:6, :]) if prune else system[0:6, :]
