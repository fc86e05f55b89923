"""The Drake twin of a spacecraft tree closed by its flight software (``oos confirm`` on a tree).

:func:`tree_with_values` writes physical values of a tree's uncertain blocks (``m_<body>``,
``Jxx_<body>``, ``Jyy_<body>``, ``Jzz_<body>``, ``w<i>_<body>``) into the tree's data, so the
SDF files generated from it (:func:`oos_drake.multibody.tree_sdf.write_tree_sdf`) carry them:
the twin of the substituted tree is the twin "with those parameters", built from the same
data path as the nominal one. Its linearization equals the TITOP LFR of the original tree with
the same blocks substituted (``tests/tree/test_tree_confirm.py``).

:func:`build_tree_twin` parses that SDF into a continuous ``MultibodyPlant`` (no gravity), the
controlled body on the roll-pitch-yaw floating joint whose zero is the world frame (its angles
are the attitude error), and closes it with the
:class:`~oos_drake.multibody.flight_software.FlightSoftware` (the scenario's sensors,
controller, roll-off, wheels, torque bound, at its flight-software rate), whose held torque is
the generalized force of the floating joint's rotation. The revolute joints are **frozen** at
the given angles (Drake joint locking, in the run's context): the configuration of one instant
of the mission, as the analysis' frozen models see it; or **motion-driven** along the mission's
timeline (``timeline=``: a stiff joint PD on a Drake trajectory equal to the timeline's
interpolation, the campaign's twin). C++ loggers record the plant state and the flight
software's torques.

A mission that captures or docks a target: the twin of an instant welds the target where the
mission model (:func:`~oos_drake.scenario.tree_model.build_mission_tree_model`) welds it
(``mating=``, :func:`mating_at`: the target's own SDF parsed as a second model and welded port
to port by Drake's ``WeldFrames``, through a captured phase and a docked one alike; a free
target is in neither). The twin of a docking study (``docking=``) holds the target on
spring-dampers instead: its own floating joint relative to the controlled body, one
``LinearBushingRollPitchYaw`` per spring-damper, at rest where the ports coincide
(:func:`~oos_drake.multibody.tree_plant.add_docked_target`, as
:func:`~oos_drake.multibody.tree_plant.build_docked_diagram`); the mission's twin of a docked
phase is that twin too (:func:`phase_mating`: the campaign flies a docked phase on its
spring-damper, the run's coefficients set in the bushings' Context parameters as the paper's
mission twin does). :func:`open_loop_twin` is the same plant with the wrench input and hub
output of the validation, for checks against the TITOP LFR
(``tests/tree/test_tree_mated_twin.py``, ``tests/tree/test_tree_docked_mission.py``).

:func:`run_tree_twin` integrates one run from a small attitude error (or driven by a noise
table, or from the :class:`TwinState` a previous run ended in) and reports whether the attitude
left the model's domain. :func:`run_mission_twin` runs a window that crosses a capture, a
docking or a release in segments (:func:`mating_segments`), each on the twin of its phase, the
chaser's state and the flight software's carried over: the mission model's instantaneous switch
(the target welded at rest relative to its port, or on its spring-damper with its port on the
tree's and moving with it: no spring load; no contact impulse).
"""

from __future__ import annotations

import dataclasses
import re
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, LogVectorOutput, MatrixGain, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from oos_drake.multibody.flight_software import FlightSoftware, FlightSoftwareDesign
from oos_drake.multibody.plant_parts import add_floating_joint
from oos_drake.multibody.tree_plant import _parse_tree_sdf
from oos_drake.multibody.tree_sdf import joint_name, write_tree_sdf
from oos_drake.scenario.tree import SpacecraftTree

__all__ = [
    "TreeTwin",
    "TreeRun",
    "TwinState",
    "build_tree_twin",
    "joint_trajectory",
    "mating_at",
    "mating_segments",
    "open_loop_twin",
    "phase_mating",
    "run_mission_twin",
    "run_tree_twin",
    "tree_with_values",
]

_MODE = re.compile(r"^w(\d+)_(.+)$")
_INERTIA = {"Jxx": 0, "Jyy": 1, "Jzz": 2}


def tree_with_values(tree: SpacecraftTree, values: Mapping[str, float]) -> SpacecraftTree:
    """The tree with physical values of its uncertain blocks written into its bodies' data.

    Parameters
    ----------
    tree : SpacecraftTree
        The tree (its free targets' bodies included: a mission model's ``m_<target>``, ...).
    values : Mapping[str, float]
        Physical value by block name: ``m_<body>`` mass [kg] (rigid body), ``Jxx_<body>``,
        ``Jyy_<body>``, ``Jzz_<body>`` diagonal of the inertia at the centre of mass [kg m^2]
        (products of inertia kept, as the LFR's blocks), ``w<i>_<body>`` frequency of mode
        ``i`` (1-based) of a flexible body [rad/s] (written as Hz; the participation rows are
        kept, as the LFR's block).

    Returns
    -------
    SpacecraftTree
        A new tree (the input is not changed); the same tree for empty ``values``.

    Raises
    ------
    ValueError
        A block name that is none of these, or names no body (or mode) of the tree or of its
        targets.
    """
    bodies = {b.name: b for b in tree.bodies}
    for target in tree.targets.values():
        bodies.update({b.name: b for b in target.bodies})
    changes: dict[str, dict] = {}
    for name, value in values.items():
        value = float(value)
        mode = _MODE.match(name)
        prefix, _, body = name.partition("_")
        if mode is not None and mode.group(2) in bodies:
            body, index = mode.group(2), int(mode.group(1)) - 1
            data = bodies[body]
            if data.kind != "flexible" or not 0 <= index < len(data.frequencies_hz):
                raise ValueError(f"block {name}: {body} has no mode {index + 1}")
            hz = changes.setdefault(body, {}).setdefault(
                "frequencies_hz", np.array(data.frequencies_hz, dtype=float)
            )
            hz[index] = value / (2.0 * np.pi)
        elif prefix == "m" and body in bodies and bodies[body].kind == "rigid":
            changes.setdefault(body, {})["mass"] = value
        elif prefix in _INERTIA and body in bodies and bodies[body].kind == "rigid":
            inertia = changes.setdefault(body, {}).setdefault(
                "inertia", np.array(bodies[body].inertia, dtype=float)
            )
            k = _INERTIA[prefix]
            inertia[k, k] = value
        else:
            raise ValueError(
                f"block {name}: not a mass, inertia or mode-frequency block of tree {tree.name}"
            )
    if not changes:
        return tree
    return _replace_bodies(tree, changes)


def _replace_bodies(tree: SpacecraftTree, changes: Mapping[str, dict]) -> SpacecraftTree:
    new = tuple(
        dataclasses.replace(b, **changes[b.name]) if b.name in changes else b for b in tree.bodies
    )
    targets = {name: _replace_bodies(t, changes) for name, t in tree.targets.items()}
    return dataclasses.replace(tree, bodies=new, targets=MappingProxyType(targets))


def mating_at(timeline, time: float) -> tuple[str, str] | None:
    """The ports mated at mission ``time`` [s]: ``(port, target port)`` of the phase's capture
    or docking (both welded rigid, as in the mission model
    :func:`~oos_drake.scenario.tree_model.build_mission_tree_model`; at a boundary: the phase
    ending there), or None (every target free)."""
    docked = timeline.docked_at(time)
    return timeline.captured_at(time) if docked is None else tuple(docked.connection)


def phase_mating(timeline, time: float):
    """The mating at mission ``time`` [s] as the mission twin flies it: the phase's
    :class:`~oos_drake.scenario.tree_mission.Docking` in a docked phase (the target on its
    spring-damper), else :func:`mating_at` (a capture's ``(port, target port)``, welded, or
    None); at a boundary: the phase ending there."""
    docked = timeline.docked_at(time)
    return timeline.captured_at(time) if docked is None else docked


def mating_segments(
    timeline, start: float, end: float, *, springs: bool = False
) -> tuple[tuple[float, float, object], ...]:
    """``[start, end]`` [s] cut where the mating changes: ``(t0, t1, mating)`` in time order,
    ``mating`` as :func:`mating_at` over ``(t0, t1]`` (``springs``: as :func:`phase_mating`,
    a docked phase's spring-damper; a cut also between two docked phases with their own
    spring-dampers at the same ports)."""
    at = phase_mating if springs else mating_at
    cuts = [float(start)]
    for b in np.asarray(timeline.boundaries, dtype=float)[1:-1]:
        if start < b < end and at(timeline, b) != at(
            timeline, min(b + 1e-6 * max(timeline.duration, 1.0), end)
        ):
            cuts.append(float(b))
    cuts.append(float(end))
    pairs = zip(cuts[:-1], cuts[1:], strict=True)
    return tuple((t0, t1, at(timeline, 0.5 * (t0 + t1))) for t0, t1 in pairs)


@dataclass(frozen=True, eq=False)
class TreeTwin:
    """Handles of a tree twin closed by its flight software (not picklable).

    Attributes
    ----------
    diagram : Diagram
        Plant, flight software and loggers.
    plant : MultibodyPlant
    flight_software : FlightSoftware
    hub_joint : RpyFloatingJoint
        The controlled body's floating joint (zero = world frame).
    angles : Mapping[str, float]
        Frozen revolute joint angles [rad] by body.
    revolute_joints : Mapping[str, RevoluteJoint]
        By body name.
    state_logger, torque_logger : VectorLogSink
        Plant state and the flight software's ``log`` output ``[u; T_rw; T; T_dist]`` [N m].
    tree : SpacecraftTree
        The (substituted) tree it was built from.
    trajectory : PiecewisePolynomial or None
        The joint angles the revolute joints follow (rows: ``revolute_joints`` in order)
        [rad]; None: frozen at ``angles``.
    mating : tuple of str or None
        ``(port, target port)`` welded, or None.
    held_joints : Mapping[Joint, float]
        The welded or docked target's revolute joints and their file angles [rad] (locked in
        a run).
    bushings : Mapping[str, LinearBushingRollPitchYaw]
        The docked target's spring-dampers by label (empty without ``docking``).
    docked_target : tuple or None
        ``(floating joint, port frame, target port frame)`` of the docked target (its
        floating joint relative to the controlled body, the first spring-damper's two port
        frames), or None without ``docking``: where :func:`run_tree_twin` places the target
        when a run does not carry its state.
    """

    diagram: Diagram
    plant: MultibodyPlant
    flight_software: FlightSoftware
    hub_joint: object
    angles: Mapping[str, float]
    revolute_joints: Mapping[str, object]
    state_logger: object
    torque_logger: object
    tree: SpacecraftTree
    trajectory: PiecewisePolynomial | None = None
    mating: tuple[str, str] | None = None
    held_joints: Mapping[object, float] = dataclasses.field(default_factory=dict)
    bushings: Mapping[str, object] = dataclasses.field(default_factory=dict)
    docked_target: tuple | None = None


def build_tree_twin(
    tree: SpacecraftTree,
    design: FlightSoftwareDesign,
    angles: Mapping[str, float] | None = None,
    *,
    log_rate: float = 10.0,
    perturbation_states: int = 0,
    timeline=None,
    joint_bandwidth: float = 200.0,
    joint_damping_ratio: float = 0.7,
    mating: tuple[str, str] | None = None,
    docking: tuple = (),
) -> TreeTwin:
    """Build the closed-loop twin of ``tree`` (its SDF generated into a temporary folder).

    Parameters
    ----------
    tree : SpacecraftTree
        The tree (substituted with :func:`tree_with_values` for worst-case parameters).
    design : FlightSoftwareDesign
        The flight software (rate, components, controller, torque bound).
    angles : Mapping[str, float], optional
        Revolute joint angles [rad] by body, frozen for the whole run (default: the file's);
        with ``timeline``, only where a docked target's floating joint has its zero (the rest
        pose at those angles).
    log_rate : float
        Logging rate [Hz] (should divide the flight-software rate).
    perturbation_states : int
        States of the flight software's dynamic perturbation block
        (:func:`~oos_drake.multibody.flight_software.perturbation_block`).
    timeline : Timeline, optional
        The mission's joint angles (:class:`~oos_drake.scenario.tree_mission.Timeline`): the
        revolute joints are then motion-driven along it (a stiff joint-space PD on each joint's
        inertia at the file's angles, built from C++ primitives, as the paper's mission twin).
        Default: frozen at ``angles``.
    joint_bandwidth : float
        Joint PD bandwidth [rad/s] (motion-driven joints).
    joint_damping_ratio : float
        Joint PD damping ratio [-].
    mating : tuple of str, optional
        ``(port, target port)``: the target owning ``target port`` (one of ``tree.targets``)
        parsed from its own SDF and welded to the tree port to port (Drake's ``WeldFrames``),
        as the mission model welds a captured or docked target (:func:`mating_at`); its own
        revolute joints held at their file angles. Default: every target free, not in the
        twin (as in the model).
    docking : tuple of Docking, optional
        Spring-dampers holding one target (a docking study's twin): the target parsed from its
        own SDF on a floating joint relative to the controlled body, at rest where the ports
        coincide at ``angles``, one ``LinearBushingRollPitchYaw`` per spring-damper with its
        coefficients as given (:func:`~oos_drake.multibody.tree_plant.add_docked_target`);
        its own revolute joints held at their file angles. Not with ``mating``.
    """
    chosen = tree.joint_angles(angles)
    builder = DiagramBuilder()
    plant, hub_joint, held, bushings, docked = _add_twin_plant(
        builder, tree, mating, docking, chosen
    )
    fsw = builder.AddNamedSystem(
        "flight_software",
        FlightSoftware(
            design,
            plant.num_positions(),
            plant.num_velocities(),
            hub_joint.position_start(),
            hub_joint.velocity_start(),
            perturbation_states=perturbation_states,
        ),
    )
    builder.Connect(plant.get_state_output_port(), fsw.get_input_port(0))
    revolute = {name: plant.GetJointByName(joint_name(name)) for name in tree.revolute_bodies}
    trajectory = None
    if timeline is None or not revolute:
        builder.Connect(
            fsw.GetOutputPort("generalized_force"),
            plant.get_applied_generalized_force_input_port(),
        )
    else:
        trajectory = joint_trajectory(timeline, tuple(revolute))
        forces = _add_joint_drives(
            builder, plant, revolute, trajectory, joint_bandwidth, joint_damping_ratio,
            tree.joint_angles(None),
        )  # fmt: skip
        builder.Connect(fsw.GetOutputPort("generalized_force"), forces.get_input_port(2))
    period = 1.0 / float(log_rate)
    state_logger = LogVectorOutput(plant.get_state_output_port(), builder, period)
    torque_logger = LogVectorOutput(fsw.GetOutputPort("log"), builder, period)
    diagram = builder.Build()
    diagram.set_name(f"tree_twin_{tree.name}")
    return TreeTwin(
        diagram=diagram,
        plant=plant,
        flight_software=fsw,
        hub_joint=hub_joint,
        angles=chosen,
        revolute_joints=revolute,
        state_logger=state_logger,
        torque_logger=torque_logger,
        tree=tree,
        trajectory=trajectory,
        mating=None if mating is None else tuple(mating),
        held_joints=held,
        bushings=MappingProxyType(bushings),
        docked_target=docked,
    )


def _add_twin_plant(builder, tree: SpacecraftTree, mating, docking=(), angles=None):
    """The continuous plant of the twin (no gravity), the controlled body on its floating
    joint; with ``mating = (port, target port)`` the target's own SDF parsed as a second model
    and welded port to port (Drake's ``WeldFrames``: ports coinciding, axes aligned); with
    ``docking`` (spring-dampers on one target) the target parsed the same way and held by one
    bushing per spring-damper, at rest where the ports coincide at the tree's joint ``angles``
    [rad] (:func:`~oos_drake.multibody.tree_plant.add_docked_target`). The target's revolute
    joints are returned with their file angles (held locked). Returns
    ``(plant, hub_joint, held, bushings, docked)``, ``docked`` the docked target's
    ``(floating joint, port frame, target port frame)`` or None."""
    from oos_drake.multibody.tree_plant import add_docked_target, docked_target_pose

    plant = builder.AddNamedSystem("plant", MultibodyPlant(time_step=0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    held, bushings, docked = {}, {}, None
    docking = tuple(docking)
    if mating is not None and docking:
        raise ValueError("tree twin: a target is either welded (mating) or docked, not both")
    with tempfile.TemporaryDirectory(prefix="oos-tree-twin-") as folder:
        write_tree_sdf(tree, Path(folder) / "tree")
        top = _parse_tree_sdf(plant, tree, Path(folder) / "tree")
        pairs = [mating] if mating is not None else [s.connection for s in docking]
        target = None
        for port, target_port in pairs:
            if port not in tree.ports:
                raise ValueError(f"tree twin: no port {port!r} on tree {tree.name}")
            owner = [t for t in tree.targets.values() if target_port in t.ports]
            if not owner:
                raise ValueError(f"tree twin: no target port {target_port!r} on tree {tree.name}")
            if target is not None and owner[0] is not target:
                raise ValueError(
                    f"tree twin: docking {port}-{target_port} holds another target than "
                    f"{target.name}"
                )
            target = owner[0]
        if target is not None:
            write_tree_sdf(target, Path(folder) / "target")
            target_top = _parse_tree_sdf(plant, target, Path(folder) / "target", prefix=target.name)
            if mating is not None:
                port, target_port = mating
                plant.WeldFrames(
                    plant.GetFrameByName(port, top),
                    plant.GetFrameByName(target_port, target_top),
                )
            else:
                X_W_target = docked_target_pose(tree, docking[0], angles)
                bushings = add_docked_target(
                    plant, tree, top, target, target_top, X_W_target, docking
                )
                docked = (
                    plant.GetJointByName(f"{target.root}_floating", target_top),
                    plant.GetFrameByName(docking[0].port, top),
                    plant.GetFrameByName(docking[0].target_port, target_top),
                )
            held = {
                plant.GetJointByName(joint_name(body)): float(angle)
                for body, angle in target.operating_angles().items()
            }
    hub_joint = add_floating_joint(
        plant, plant.GetBodyByName(tree.root, top), RigidTransform(), name=f"{tree.root}_floating"
    )
    plant.Finalize()
    return plant, hub_joint, held, bushings, docked


def open_loop_twin(
    tree: SpacecraftTree,
    mating: tuple[str, str] | None = None,
    *,
    docking: tuple = (),
    angles: Mapping[str, float] | None = None,
):
    """The twin's plant (built as :func:`build_tree_twin` builds it, target welded at
    ``mating`` or held by the spring-dampers ``docking`` at rest at the joint ``angles``
    [rad]) with the wrench input and hub output of
    :func:`~oos_drake.multibody.tree_plant.linearize_tree` instead of the flight software: the
    open-loop ``[F; T]_G -> [a; wdot]_G`` of the twin, for checks against the TITOP LFR.

    Returns
    -------
    TreeDiagram
        Handles for :func:`~oos_drake.multibody.tree_plant.linearize_tree`: its ``tree`` is
        ``tree``, or with a ``mating`` :func:`~oos_drake.scenario.tree.captured_tree`, with a
        ``docking`` :func:`~oos_drake.scenario.tree.docked_tree` (the mated target's revolute
        joints among the handles' joints, so that ``linearize_tree`` locks them too: at their
        file angles unless given).

    Raises
    ------
    ValueError
        An unknown port.
    """
    from oos_drake.multibody.linearization import add_hub_io
    from oos_drake.multibody.tree_plant import TreeDiagram
    from oos_drake.scenario.tree import captured_tree, docked_tree

    builder = DiagramBuilder()
    docking = tuple(docking)
    chosen = tree.joint_angles(angles)
    plant, hub_joint, _, _, _ = _add_twin_plant(builder, tree, mating, docking, chosen)
    ports = add_hub_io(builder, plant, hub_joint)
    diagram = builder.Build()
    model_tree = tree
    if mating is not None:
        model_tree = captured_tree(tree, *mating)
    elif docking:
        model_tree = docked_tree(tree, docking[0], docking[1:])
    revolute = {name: plant.GetJointByName(joint_name(name)) for name in model_tree.revolute_bodies}
    return TreeDiagram(
        diagram=diagram,
        plant=plant,
        tree=model_tree,
        ports=ports,
        hub_joint=hub_joint,
        revolute_joints=MappingProxyType(revolute),
    )


def joint_trajectory(timeline, bodies) -> PiecewisePolynomial:
    """The timeline's joint angles of ``bodies`` as a Drake trajectory [rad] (exact: the
    ``"smooth"`` interpolation is the cubic Hermite with zero rates at the waypoints, the
    ``"linear"`` one the first-order hold, the ``"quintic"`` one the quintic with zero rates
    and accelerations at the waypoints)."""
    index = [timeline.joint_names.index(b) for b in bodies]
    breaks = np.asarray(timeline.boundaries, dtype=float)
    samples = np.asarray(timeline.waypoints, dtype=float)[:, index].T
    if breaks.size < 2:  # a mission of one instant: hold it
        breaks = np.array([0.0, 1.0])
        samples = np.hstack([samples, samples])
    if timeline.interpolation == "linear":
        return PiecewisePolynomial.FirstOrderHold(breaks, samples)
    if timeline.interpolation == "quintic":
        from oos_drake.multibody.mission import quintic_piecewise_polynomial
        from oos_drake.scenario.timeline import QuinticTrajectory

        return quintic_piecewise_polynomial(QuinticTrajectory(breaks, samples.T))
    return PiecewisePolynomial.CubicHermite(breaks, samples, np.zeros_like(samples))


def _add_joint_drives(builder, plant, revolute, trajectory, bandwidth, damping, angles):
    """``tau = kp (q_ref - q) + kd (v_ref - v)`` on each joint of ``revolute`` (by body; kp,
    kd on the joint's own inertia at ``angles`` [rad]) from C++ primitives; returns the
    3-input adder of the generalized forces (inputs 0, 1: the PD terms; 2: free for the flight
    software)."""
    nq, nv = plant.num_positions(), plant.num_velocities()
    context = plant.CreateDefaultContext()
    for name, joint in revolute.items():
        joint.set_angle(context, float(angles[name]))
    M = plant.CalcMassMatrix(context)
    joints = list(revolute.values())
    n = len(joints)
    K_state = np.zeros((nv, nq + nv))
    K_ref = np.zeros((nv, 2 * n))
    for i, joint in enumerate(joints):
        qi, vi = joint.position_start(), joint.velocity_start()
        kp, kd = bandwidth**2 * M[vi, vi], 2.0 * damping * bandwidth * M[vi, vi]
        K_state[vi, qi], K_state[vi, nq + vi] = -kp, -kd
        K_ref[vi, i], K_ref[vi, n + i] = kp, kd
    source = builder.AddNamedSystem(
        "joint_trajectory", TrajectorySource(trajectory, output_derivative_order=1)
    )
    state_gain = builder.AddNamedSystem("joint_pd_state", MatrixGain(K_state))
    ref_gain = builder.AddNamedSystem("joint_pd_reference", MatrixGain(K_ref))
    builder.Connect(plant.get_state_output_port(), state_gain.get_input_port())
    builder.Connect(source.get_output_port(), ref_gain.get_input_port())
    forces = builder.AddNamedSystem("generalized_forces", Adder(3, nv))
    builder.Connect(state_gain.get_output_port(), forces.get_input_port(0))
    builder.Connect(ref_gain.get_output_port(), forces.get_input_port(1))
    builder.Connect(forces.get_output_port(), plant.get_applied_generalized_force_input_port())
    return forces


@dataclass(frozen=True)
class TreeRun:
    """One run of the tree twin.

    Attributes
    ----------
    diverged : bool
        The attitude left ``divergence_limit`` (or the state became non-finite, or the
        integrator failed).
    times : ndarray, shape (n,)
        Log times [s] from the run's start.
    phi : ndarray, shape (n, 3)
        Controlled body's roll-pitch-yaw attitude [rad].
    rate : ndarray, shape (n, 3)
        Controlled body's angular rate in its own axes [rad/s].
    torques : ndarray, shape (n, 12)
        ``[u; T_rw; T; T_dist]`` of the flight software [N m].
    metrics : Mapping[str, ndarray]
        The flight software's running metrics at the end
        (:meth:`~oos_drake.multibody.flight_software.FlightSoftware.metrics`).
    joint_error : float
        Largest deviation of a motion-driven joint from its trajectory at the log instants
        [rad] (0 for frozen joints).
    """

    diverged: bool
    times: np.ndarray
    phi: np.ndarray
    rate: np.ndarray
    torques: np.ndarray
    metrics: Mapping[str, np.ndarray]
    joint_error: float = 0.0
    final_state: TwinState | None = None


@dataclass(frozen=True)
class TwinState:
    """The state of a twin at one instant, portable to a twin with other welds.

    Attributes
    ----------
    time : float
        Mission time [s].
    joints : Mapping[tuple[str, str], tuple[ndarray, ndarray]]
        Positions and velocities of every joint with degrees of freedom, keyed by
        ``(model instance name, joint name)`` (so a twin whose target is welded or free finds
        the chaser's joints: the floating joint, the revolute joints, the appendages' modal
        coordinates).
    flight_software : ndarray
        The flight software's discrete state (filters, held torque, metrics, sample counter,
        dynamic perturbation).
    docked : tuple or None
        A docked target's ``(joint key, (port, target port), X_RM, V_RM_R)``: its pose and
        spatial velocity relative to the controlled body's frame R (the joint's own zero is
        its twin's rest pose, another twin's may differ), or None.
    """

    time: float
    joints: Mapping[tuple[str, str], tuple[np.ndarray, np.ndarray]]
    flight_software: np.ndarray
    docked: tuple | None = None


def _dof_joints(plant):
    from pydrake.multibody.tree import JointIndex

    for i in range(plant.num_joints()):
        joint = plant.get_joint(JointIndex(i))
        if joint.num_positions() + joint.num_velocities():
            yield (plant.GetModelInstanceName(joint.model_instance()), joint.name()), joint


def _capture_state(twin: TreeTwin, context) -> TwinState:
    plant_context = twin.plant.GetMyContextFromRoot(context)
    q, v = twin.plant.GetPositions(plant_context), twin.plant.GetVelocities(plant_context)
    joints = {
        key: (
            q[j.position_start() : j.position_start() + j.num_positions()].copy(),
            v[j.velocity_start() : j.velocity_start() + j.num_velocities()].copy(),
        )
        for key, j in _dof_joints(twin.plant)
    }
    fsw_context = twin.flight_software.GetMyContextFromRoot(context)
    docked = None
    if twin.docked_target is not None:
        joint, port, target_port = twin.docked_target
        R = joint.frame_on_parent().body().body_frame()
        M = joint.frame_on_child()
        docked = (
            _docked_key(twin),
            (port.name(), target_port.name()),
            M.CalcPose(plant_context, R),
            M.CalcSpatialVelocity(plant_context, R, R),
        )
    return TwinState(
        float(context.get_time()),
        MappingProxyType(joints),
        np.array(fsw_context.get_discrete_state(0).get_value()),
        docked,
    )


def _docked_key(twin: TreeTwin) -> tuple[str, str]:
    joint = twin.docked_target[0]
    return (twin.plant.GetModelInstanceName(joint.model_instance()), joint.name())


def _restore_state(twin: TreeTwin, context, state: TwinState) -> None:
    """Write ``state`` into ``context``: the joints found by key (others keep their default
    state: a target welded anew has no degrees of freedom if rigid, its modes start at rest).
    A docked target: held at the same ports in ``state``, its pose and velocity relative to
    the controlled body carried over (the spring-damper's deflection continues); else placed
    on its port (:func:`_place_docked_target`)."""
    plant_context = twin.plant.GetMyMutableContextFromRoot(context)
    q, v = twin.plant.GetPositions(plant_context), twin.plant.GetVelocities(plant_context)
    for key, j in _dof_joints(twin.plant):
        if key in state.joints:
            qj, vj = state.joints[key]
            q[j.position_start() : j.position_start() + j.num_positions()] = qj
            v[j.velocity_start() : j.velocity_start() + j.num_velocities()] = vj
    twin.plant.SetPositions(plant_context, q)
    twin.plant.SetVelocities(plant_context, v)
    fsw_context = twin.flight_software.GetMyMutableContextFromRoot(context)
    fsw_context.get_mutable_discrete_state(0).SetFromVector(state.flight_software)
    if twin.docked_target is None:
        return
    joint, port, target_port = twin.docked_target
    carried = state.docked
    if carried is None or carried[:2] != (_docked_key(twin), (port.name(), target_port.name())):
        _place_docked_target(twin, plant_context)
        return
    X_RM, V_RM_R = carried[2:]
    X_RF = joint.frame_on_parent().GetFixedPoseInBodyFrame()
    joint.SetPose(plant_context, X_RF.inverse() @ X_RM)
    R_FR = X_RF.rotation().inverse().matrix()  # F is fixed in R: M's velocity in F is in R's
    joint.set_angular_velocity(plant_context, R_FR @ V_RM_R.rotational())
    joint.set_translational_velocity(plant_context, R_FR @ V_RM_R.translational())


def _place_docked_target(twin: TreeTwin, plant_context) -> None:
    """Put the docked target's port frame Q on the tree's port frame P and move it rigidly
    with P: the target's floating joint (parent frame F on the controlled body) at
    ``X_FM = X_FP X_QM`` with the spatial velocity of P in F shifted to M's origin."""
    joint, port, target_port = twin.docked_target
    F = joint.frame_on_parent()
    X_FP = port.CalcPose(plant_context, F)
    X_MQ = target_port.GetFixedPoseInBodyFrame()
    X_FM = X_FP @ X_MQ.inverse()
    joint.SetPose(plant_context, X_FM)
    V_FP_F = port.CalcSpatialVelocity(plant_context, F, F)
    V_FM_F = V_FP_F.Shift(X_FM.translation() - X_FP.translation())
    joint.set_angular_velocity(plant_context, V_FM_F.rotational())
    joint.set_translational_velocity(plant_context, V_FM_F.translational())


def run_tree_twin(
    twin: TreeTwin,
    duration: float,
    *,
    start: float = 0.0,
    initial_attitude=0.0,
    initial_rate=0.0,
    noise_table: np.ndarray | None = None,
    dynamic=None,
    perturbations: tuple | None = None,
    max_step: float = 0.05,
    accuracy: float | None = None,
    divergence_limit: float = 0.5,
    check_interval: float = 1.0,
    initial_state: TwinState | None = None,
    spring_dampers: Mapping[str, tuple] | None = None,
) -> TreeRun:
    """Integrate the twin for ``duration`` [s] from mission time ``start`` [s].

    Frozen joints (no ``timeline`` at the build): locked at their angles, error-controlled
    third-order Runge-Kutta (accuracy 1e-8 by default) with steps of at most ``max_step``.
    Motion-driven joints: started on their trajectory at ``start`` (angle and rate), Radau3
    in fixed steps of ``max_step`` (the stiff joint PDs; accuracy 1e-7 by default, the
    Newton tolerance of the paper's mission twin).

    Parameters
    ----------
    twin : TreeTwin
    duration : float
        Simulated time [s].
    start : float
        Mission time of the run's start [s] (the joints' trajectory time).
    initial_attitude : float or array_like (3,)
        Initial roll, pitch and yaw error of the controlled body [rad].
    initial_rate : float or array_like (3,)
        Initial body rate of the controlled body, its axes [rad/s].
    noise_table : ndarray, shape (n, 9), optional
        Unit ``[n_sst; n_gyro; d_ext]`` per flight-software sample (default: none).
    dynamic : DiscreteBlock, optional
        The flight software's dynamic perturbation of the run.
    perturbations : tuple, optional
        ``(delta_mul (3x3), delta_add, frequency_hz)`` of the flight software's all-pass LTI
        perturbations (:meth:`FlightSoftware.set_perturbations`).
    max_step : float
        Longest integrator step [s].
    accuracy : float, optional
        Integrator target accuracy [-].
    divergence_limit : float
        Attitude [rad] beyond which the run stops as diverged.
    check_interval : float
        Simulated time between divergence checks [s].
    initial_state : TwinState, optional
        Start from this state (a previous run's ``final_state``, at ``start``) instead of the
        initial errors; the motion-driven joints keep their state from it.
    spring_dampers : Mapping[str, tuple], optional
        ``{label: (k_shear, k_tors, d_shear, d_tors)}`` [N/m, N m/rad, N s/m, N m s/rad]:
        the coefficients of the twin's bushings of those labels in this run (Context
        parameters, as the paper's mission twin:
        :func:`~oos_drake.multibody.scenario_plant.set_bushing`); labels the twin does not
        have are ignored (a segment without them); default: the coefficients it was built with.

    Notes
    -----
    A docked target (``docking`` at the build) whose state the run does not carry (no
    ``initial_state``, or one where the target was welded, free or docked at other ports)
    starts with its port frame on the tree's port and moving with it (rigidly, at that
    instant): no initial spring load, the mission model's instantaneous switch. Docked at the
    same ports in ``initial_state`` (another docked phase of the same spring-damper): its
    pose and velocity relative to the controlled body carried over.
    """
    from pydrake.math import RollPitchYaw

    context = twin.diagram.CreateDefaultContext()
    context.SetTime(float(start))
    plant_context = twin.plant.GetMyMutableContextFromRoot(context)
    driven = twin.trajectory is not None
    for i, (name, joint) in enumerate(twin.revolute_joints.items()):
        if driven:
            joint.set_angle(plant_context, float(twin.trajectory.value(start)[i, 0]))
            joint.set_angular_rate(
                plant_context, float(twin.trajectory.EvalDerivative(start, 1)[i, 0])
            )
        else:
            joint.set_angle(plant_context, float(twin.angles[name]))
            joint.Lock(plant_context)
    for joint, angle in twin.held_joints.items():
        joint.set_angle(plant_context, angle)
        joint.Lock(plant_context)
    phi0 = np.broadcast_to(np.asarray(initial_attitude, dtype=float), (3,)).copy()
    w0_B = np.broadcast_to(np.asarray(initial_rate, dtype=float), (3,)).copy()
    twin.hub_joint.set_angles(plant_context, phi0)
    R_WB = RollPitchYaw(phi0).ToRotationMatrix().matrix()
    twin.hub_joint.set_angular_velocity(plant_context, R_WB @ w0_B)
    fsw = twin.flight_software
    fsw_context = fsw.GetMyMutableContextFromRoot(context)
    fsw.set_noise(fsw_context, np.zeros((1, 9)) if noise_table is None else noise_table)
    fsw.set_dynamic_perturbation(fsw_context, dynamic)
    if perturbations is not None:
        fsw.set_perturbations(fsw_context, *perturbations)
    if initial_state is None:
        # sensor filters start at their steady state for the initial measurement
        state = fsw_context.get_mutable_discrete_state(0).get_mutable_value()
        slices, d = fsw.state_slices, fsw.design
        for block, name, u in ((d.star_tracker, "star_tracker", phi0), (d.gyro, "gyro", w0_B)):
            state[slices[name]] = np.linalg.solve(np.eye(block.nstates) - block.A, block.B @ u)
    else:
        _restore_state(twin, context, initial_state)
    if spring_dampers:
        from oos_drake.multibody.scenario_plant import set_bushing

        for label, bushing in twin.bushings.items():
            if label in spring_dampers:
                set_bushing(bushing, plant_context, tuple(float(x) for x in spring_dampers[label]))
    if initial_state is None and twin.docked_target is not None:
        _place_docked_target(twin, plant_context)
    simulator = Simulator(twin.diagram, context)
    ResetIntegratorFromFlags(simulator, "radau3" if driven else "runge_kutta3", max_step)
    integrator = simulator.get_mutable_integrator()
    integrator.set_target_accuracy(accuracy or (1e-7 if driven else 1e-8))
    integrator.set_maximum_step_size(max_step)
    integrator.set_fixed_step_mode(driven)
    simulator.Initialize()
    diverged = False
    end = float(start) + float(duration)
    stops = np.arange(float(start) + check_interval, end, check_interval)
    for stop in [*stops, end]:
        try:
            simulator.AdvanceTo(float(stop))
        except RuntimeError:
            diverged = True
            break
        max_phi = fsw.metrics(fsw_context)["max_phi"]
        if not np.all(np.isfinite(max_phi)) or max_phi.max() > divergence_limit:
            diverged = True
            break
    states = twin.state_logger.FindLog(context)
    torques = twin.torque_logger.FindLog(context)
    nq = twin.plant.num_positions()
    q, v = twin.hub_joint.position_start(), nq + twin.hub_joint.velocity_start()
    n = min(states.num_samples(), torques.num_samples())
    x = np.asarray(states.data()[:, :n])
    times = np.asarray(states.sample_times()[:n])
    phi = x[q : q + 3].T
    rate = np.empty_like(phi)
    for k in range(n):
        R = RollPitchYaw(phi[k]).ToRotationMatrix().matrix()
        rate[k] = R.T @ x[v : v + 3, k]
    joint_error = 0.0
    if driven and n:
        reference = np.column_stack([twin.trajectory.value(t)[:, 0] for t in times])
        actual = np.array([x[j.position_start()] for j in twin.revolute_joints.values()])
        joint_error = float(np.abs(actual - reference).max())
    return TreeRun(
        diverged=diverged,
        times=times - float(start),
        phi=phi,
        rate=rate,
        torques=np.asarray(torques.data()[:, :n]).T,
        metrics=fsw.metrics(fsw_context),
        joint_error=joint_error,
        final_state=_capture_state(twin, context),
    )


def run_mission_twin(
    twin_for,
    timeline,
    duration: float,
    *,
    start: float = 0.0,
    springs: bool = False,
    initial_state: TwinState | None = None,
    **options,
):
    """Integrate a tree's twin along its mission for ``duration`` [s] from ``start`` [s],
    switching the welded (or docked) target where the mission's phases mate or release it.

    The window is cut where the mated ports change (:func:`mating_segments`); each segment
    runs on ``twin_for(mating)`` (a motion-driven twin built with that ``mating``), started
    from the previous segment's final state (:class:`TwinState`: the chaser's joints and the
    flight software carried over, the target welded rigidly at rest relative to its port or
    released: the switch of the mission model, no contact impulse).

    Parameters
    ----------
    twin_for : callable
        ``mating (tuple or None) -> TreeTwin``; with ``springs``, a docked phase's mating is
        its :class:`~oos_drake.scenario.tree_mission.Docking` (:func:`phase_mating`: the
        twin built with ``docking=``).
    timeline : Timeline
        The mission's timeline (its captures and dockings).
    duration, start : float
        Window [s].
    springs : bool
        Docked phases on their spring-dampers (:func:`phase_mating`); default: welded as
        the mission model (:func:`mating_at`).
    initial_state : TwinState, optional
        The first segment's start (a previous run's ``final_state`` at ``start``).
    **options
        Of :func:`run_tree_twin` (``initial_attitude``, ``noise_table``, ...), the same for
        every segment.

    Returns
    -------
    TreeRun
        The segments' logs joined (times from ``start``), the metrics at the end, the largest
        joint error.
    """
    start = float(start)
    parts, state = [], initial_state
    for t0, t1, mating in mating_segments(
        timeline, start, start + float(duration), springs=springs
    ):
        run = run_tree_twin(twin_for(mating), t1 - t0, start=t0, initial_state=state, **options)
        parts.append((t0, run))
        state = run.final_state
        if run.diverged:
            break
    if len(parts) == 1:
        return parts[0][1]
    times, keep, last = [], [], -np.inf
    for t0, run in parts:
        absolute = run.times + t0
        mask = absolute > last + 1e-9
        times.append(absolute[mask] - start)
        keep.append((run, mask))
        if absolute.size:
            last = max(last, float(absolute[-1]))
    final = parts[-1][1]
    return TreeRun(
        diverged=final.diverged,
        times=np.concatenate(times),
        phi=np.concatenate([r.phi[m] for r, m in keep]),
        rate=np.concatenate([r.rate[m] for r, m in keep]),
        torques=np.concatenate([r.torques[m] for r, m in keep]),
        metrics=final.metrics,
        joint_error=max(r.joint_error for _, r in parts),
        final_state=final.final_state,
    )
