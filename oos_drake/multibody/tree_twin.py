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
from pydrake.systems.primitives import LogVectorOutput

from oos_drake.multibody.flight_software import FlightSoftware, FlightSoftwareDesign
from oos_drake.multibody.plant_parts import add_floating_joint
from oos_drake.multibody.tree_plant import _parse_tree_sdf
from oos_drake.multibody.tree_sdf import joint_name, write_tree_sdf
from oos_drake.scenario.tree import SpacecraftTree

__all__ = ["TreeTwin", "TreeRun", "build_tree_twin", "run_tree_twin", "tree_with_values"]

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


def build_tree_twin(
    tree: SpacecraftTree,
    design: FlightSoftwareDesign,
    angles: Mapping[str, float] | None = None,
    *,
    log_rate: float = 10.0,
    perturbation_states: int = 0,
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
    builder.Connect(
        fsw.GetOutputPort("generalized_force"), plant.get_applied_generalized_force_input_port()
    )
    period = 1.0 / float(log_rate)
    state_logger = LogVectorOutput(plant.get_state_output_port(), builder, period)
    torque_logger = LogVectorOutput(fsw.GetOutputPort("log"), builder, period)
    diagram = builder.Build()
    diagram.set_name(f"tree_twin_{tree.name}")
    revolute = {name: plant.GetJointByName(joint_name(name)) for name in tree.revolute_bodies}
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
    )


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
    torques : ndarray, shape (n, 12)
        ``[u; T_rw; T; T_dist]`` of the flight software [N m].
    """

    diverged: bool
    times: np.ndarray
    phi: np.ndarray
    torques: np.ndarray


def run_tree_twin(
    twin: TreeTwin,
    duration: float,
    *,
    initial_attitude: float = 0.0,
    noise_table: np.ndarray | None = None,
    dynamic=None,
    max_step: float = 0.05,
    accuracy: float = 1e-8,
    divergence_limit: float = 0.5,
    check_interval: float = 1.0,
) -> TreeRun:
    """Integrate the twin for ``duration`` [s] from rest with the joints frozen.

    Parameters
    ----------
    twin : TreeTwin
    duration : float
        Simulated time [s].
    initial_attitude : float
        Initial roll, pitch and yaw error of the controlled body [rad].
    noise_table : ndarray, shape (n, 9), optional
        Unit ``[n_sst; n_gyro; d_ext]`` per flight-software sample (default: none).
    dynamic : DiscreteBlock, optional
        The flight software's dynamic perturbation of the run.
    max_step : float
        Longest integrator step [s] (error-controlled third-order Runge-Kutta).
    accuracy : float
        Integrator target accuracy [-].
    divergence_limit : float
        Attitude [rad] beyond which the run stops as diverged.
    check_interval : float
        Simulated time between divergence checks [s].
    """
    context = twin.diagram.CreateDefaultContext()
    plant_context = twin.plant.GetMyMutableContextFromRoot(context)
    for name, joint in twin.revolute_joints.items():
        joint.set_angle(plant_context, float(twin.angles[name]))
        joint.Lock(plant_context)
    twin.hub_joint.set_angles(plant_context, np.full(3, float(initial_attitude)))
    fsw = twin.flight_software
    fsw_context = fsw.GetMyMutableContextFromRoot(context)
    fsw.set_noise(fsw_context, np.zeros((1, 9)) if noise_table is None else noise_table)
    fsw.set_dynamic_perturbation(fsw_context, dynamic)
    simulator = Simulator(twin.diagram, context)
    ResetIntegratorFromFlags(simulator, "runge_kutta3", max_step)
    integrator = simulator.get_mutable_integrator()
    integrator.set_target_accuracy(accuracy)
    integrator.set_maximum_step_size(max_step)
    simulator.Initialize()
    diverged = False
    for stop in [*np.arange(check_interval, duration, check_interval), duration]:
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
    q = twin.hub_joint.position_start()
    n = min(states.num_samples(), torques.num_samples())
    return TreeRun(
        diverged=diverged,
        times=np.asarray(states.sample_times()[:n]),
        phi=np.asarray(states.data()[q : q + 3, :n]).T,
        torques=np.asarray(torques.data()[:, :n]).T,
    )
