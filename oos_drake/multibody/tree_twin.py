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
of the mission, as the analysis' frozen models see it. C++ loggers record the plant state and
the flight software's torques.

:func:`run_tree_twin` integrates one run from a small attitude error (or driven by a noise
table) and reports whether the attitude left the model's domain.

Unlike the paper's mission twin (:mod:`oos_drake.multibody.mission`), nothing moves along the
timeline here: the twin of a tree follows no joint trajectory yet.
"""

from __future__ import annotations

import dataclasses
import re
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

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
    "build_tree_twin",
    "joint_trajectory",
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
        The tree.
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
        A block name that is none of these, or names no body (or mode) of the tree.
    """
    bodies = {b.name: b for b in tree.bodies}
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
    new = tuple(
        dataclasses.replace(b, **changes[b.name]) if b.name in changes else b for b in tree.bodies
    )
    return dataclasses.replace(tree, bodies=new)


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
) -> TreeTwin:
    """Build the closed-loop twin of ``tree`` (its SDF generated into a temporary folder).

    Parameters
    ----------
    tree : SpacecraftTree
        The tree (substituted with :func:`tree_with_values` for worst-case parameters).
    design : FlightSoftwareDesign
        The flight software (rate, components, controller, torque bound).
    angles : Mapping[str, float], optional
        Revolute joint angles [rad] by body, frozen for the whole run (default: the file's).
    log_rate : float
        Logging rate [Hz] (should divide the flight-software rate).
    perturbation_states : int
        States of the flight software's dynamic perturbation block
        (:func:`~oos_drake.multibody.flight_software.perturbation_block`).
    timeline : Timeline, optional
        The mission's joint angles (:class:`~oos_drake.scenario.tree_mission.Timeline`): the
        revolute joints are then motion-driven along it (a stiff joint-space PD on each joint's
        inertia, built from C++ primitives, as the paper's mission twin), and ``angles`` is
        ignored. Default: frozen at ``angles``.
    joint_bandwidth : float
        Joint PD bandwidth [rad/s] (motion-driven joints).
    joint_damping_ratio : float
        Joint PD damping ratio [-].
    """
    chosen = tree.joint_angles(angles)
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("plant", MultibodyPlant(time_step=0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    with tempfile.TemporaryDirectory(prefix="oos-tree-twin-") as folder:
        write_tree_sdf(tree, folder)
        top = _parse_tree_sdf(plant, tree, Path(folder))
    hub_joint = add_floating_joint(
        plant, plant.GetBodyByName(tree.root, top), RigidTransform(), name=f"{tree.root}_floating"
    )
    plant.Finalize()
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
            builder, plant, revolute, trajectory, joint_bandwidth, joint_damping_ratio, chosen,
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
    )


def joint_trajectory(timeline, bodies) -> PiecewisePolynomial:
    """The timeline's joint angles of ``bodies`` as a Drake trajectory [rad] (exact: the
    ``"smooth"`` interpolation is the cubic Hermite with zero rates at the waypoints, the
    ``"linear"`` one the first-order hold)."""
    index = [timeline.joint_names.index(b) for b in bodies]
    breaks = np.asarray(timeline.boundaries, dtype=float)
    samples = np.asarray(timeline.waypoints, dtype=float)[:, index].T
    if breaks.size < 2:  # a mission of one instant: hold it
        breaks = np.array([0.0, 1.0])
        samples = np.hstack([samples, samples])
    if timeline.interpolation == "linear":
        return PiecewisePolynomial.FirstOrderHold(breaks, samples)
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
    # sensor filters start at their steady state for the initial measurement
    state = fsw_context.get_mutable_discrete_state(0).get_mutable_value()
    slices, d = fsw.state_slices, fsw.design
    for block, name, u in ((d.star_tracker, "star_tracker", phi0), (d.gyro, "gyro", w0_B)):
        state[slices[name]] = np.linalg.solve(np.eye(block.nstates) - block.A, block.B @ u)
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
    )
