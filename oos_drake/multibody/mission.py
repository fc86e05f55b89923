"""Factory of the closed-loop mission diagram: the Drake twin following the mission timeline.

``make_mission_diagram(options)`` builds, from the same SDF files and modal residuals as
:func:`oos_drake.multibody.scenario_plant.build_scenario_diagram`,

- a **continuous** MultibodyPlant (no gravity): chaser hub RH1 on a roll-pitch-yaw floating joint
  whose zero is the world frame (its angles are the attitude error, the reference being zero),
  target hub RH2 on its own roll-pitch-yaw floating joint in the world, the four arrays with their
  exact modal realizations, docking bushings SM1 (J7 - D2) and SM2 (D1 - D3) whose stiffness and
  damping are Context parameters (open by default);
- **motion-driven** arm joints ``alpha_1..6`` and array drives ``theta_SA1..4``: each tracks its
  fifth-order trajectory (:class:`~pydrake.systems.primitives.TrajectorySource` of the exact
  quintic segments) through a stiff joint-space PD (``omega_joint = 200 rad/s`` by default on the
  joint's inertia), built from C++ primitives only (``MatrixGain``, ``Adder``) so that no Python
  runs inside the integrator; the tracking error is ~1e-9 rad and the hub feels the reactions of
  the joint torques;
- the :class:`~oos_drake.multibody.flight_software.FlightSoftware` (periodic discrete update at
  ``control_rate``) whose held hub torque is added to the joint torques;
- C++ loggers (``VectorLogSink``) of the plant state and of the flight software's torques at
  ``log_rate``.

The stiff parts (joint PDs, bushings up to 1e5 N/m on the 0.19 kg wrist, modes up to 28 Hz) make
the continuous system stiff: :mod:`oos_drake.multibody.mission_sim` integrates it with Radau3
(L-stable) in fixed steps of one flight-software period (a quarter period while a docking
stiffness ramps) and a tight Newton tolerance (see ``MissionOptions.accuracy``).

Where the processor time goes (``benchmarks/bench_mission_sim.py --profile``, whole mission,
about 17 s on one core, i.e. 11 ms per simulated second): 73 % in the MultibodyPlant's time
derivatives (about 44 us per evaluation: the articulated-body algorithm over 42 bodies, 24 of
them modal; ~18 evaluations per step: ~7 Newton-Raphson iterations of Radau3's two stages and
~3.5 of the implicit-trapezoid error estimate, which Drake computes in fixed-step mode too, with
Jacobians reused over hundreds of steps), 24 % in the integrator's own linear algebra and the
simulator's event handling, 3 % in the Python flight software. Gravity is disabled per model
instance (the field is zero in orbit) so its element costs nothing.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    LinearBushingRollPitchYaw,
    ModelInstanceIndex,
    RevoluteSpring,
)
from pydrake.polynomial import Polynomial
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import (
    Adder,
    LogVectorOutput,
    MatrixGain,
    Multiplexer,
    TrajectorySource,
)
from pydrake.trajectories import PiecewisePolynomial

from oos_drake.control.baseline import scenario_baseline_gains
from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import ControllerSystem, as_controller, read_controller
from oos_drake.multibody.flight_software import FlightSoftware, FlightSoftwareDesign
from oos_drake.multibody.plant_parts import add_floating_joint, force_elements, modal_hinges
from oos_drake.multibody.scenario_plant import (
    ARRAYS,
    add_docking_bushings,
    add_scenario_plant,
    prescribed_joints,
)
from oos_drake.multibody.scenario_sdf import scenario_sdf_directory
from oos_drake.scenario.data import Scenario
from oos_drake.scenario.kinematics import rigid_spatial_inertia_at_G1
from oos_drake.scenario.timeline import MissionTimeline, QuinticTrajectory, mission_timeline

__all__ = [
    "ARRAYS",
    "IMPLICIT_INTEGRATORS",
    "MissionDiagram",
    "MissionOptions",
    "effective_inertia",
    "mission_controller",
    "logging_rate",
    "make_mission_diagram",
    "quintic_piecewise_polynomial",
]


def logging_rate(control_rate: float, wanted: float) -> float:
    """The fastest logging rate [Hz] at most ``wanted`` that divides ``control_rate``.

    .. math:: f_{log} = f_c / \\lceil f_c / f_{wanted} \\rceil

    (``control_rate`` itself when ``wanted >= control_rate``): every logged sample falls on a
    flight-software instant, for any flight-software rate.

    Parameters
    ----------
    control_rate : float
        Flight-software rate [Hz], > 0.
    wanted : float
        Desired logging rate [Hz], > 0.

    Examples
    --------
    >>> logging_rate(10.0, 10.0), logging_rate(5.0, 10.0), logging_rate(7.0, 2.0)
    (10.0, 5.0, 1.75)
    """
    control_rate, wanted = float(control_rate), float(wanted)
    for name, value in (("control_rate", control_rate), ("wanted", wanted)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"logging_rate: {name} must be > 0 Hz, got {value}")
    return control_rate / max(1, math.ceil(control_rate / wanted - 1e-9))


#: Drake integrators (``ResetIntegratorFromFlags`` names) that are stable on the stiff mission.
IMPLICIT_INTEGRATORS = frozenset({"radau1", "radau3", "implicit_euler", "velocity_implicit_euler"})


@dataclass(frozen=True)
class MissionOptions:
    """Options of the mission diagram and simulation (plain values: picklable, JSON-able).

    Attributes
    ----------
    control_rate : float or None
        Flight-software sample rate [Hz]; ``None`` (default): the scenario's
        ``[control] flight_software_rate_hz`` (set by :meth:`resolved`, which
        :func:`make_mission_diagram` calls).
    log_rate : float or None
        Logging rate of the time series [Hz] (must divide ``control_rate``: the loggers sample
        the held torque at control instants); ``None`` (default): about 1 Hz, the fastest rate
        <= 1 Hz that divides ``control_rate`` (:func:`logging_rate`).
    controller : str or None
        Path of a synthesis ``controller.json`` (any structure: the static gains ``K_p``,
        ``K_d``, a PID, a state space; :func:`mission_controller`); ``None``: the paper's
        baseline tuned on the coupled inertia at the first docking.
    torque_limit : float
        Reaction-wheel torque limit [N m].
    joint_bandwidth : float
        Natural frequency of the motion-driving joint PDs [rad/s].
    joint_damping_ratio : float
        Damping ratio of the joint PDs [-].
    arm_min_inertia : float
        Lower bound of the inertia used to size an arm joint's PD [kg m^2] (the wrist alone is
        light; the gains must hold the captured target).
    ramp_duration : float
        Duration of each docking stiffness ramp [s].
    ramp_steps : int
        Piecewise-constant steps of a ramp (log-spaced stiffness).
    ramp_start_stiffness : float
        First stiffness of a ramp [N/m, N m/rad] (paper: 0.1).
    ramp_substeps : int
        Integrator steps per control period while a docking stiffness ramps (the bushing
        stiffness jumps at every ramp step; finer steps there cost little, the ramps are short).
    integrator : str
        Drake integrator name (``"radau3"``, ``"implicit_euler"``, ``"runge_kutta3"``, ...).
    max_step : float or None
        Longest integrator step [s]; ``None``: one control period (a reference solution takes a
        fraction of it).
    error_control : bool or None
        ``False``: fixed steps of one flight-software period (shorter only where an event or a
        failed Newton iteration needs it); ``True``: error-controlled steps of at most one
        period. ``None`` (default): fixed for the implicit integrators, error-controlled for
        the explicit ones (which the stiff joint PDs and bushings would make unstable).
    accuracy : float
        Integrator accuracy [-]. Drake's implicit integrators use it as the Newton-Raphson
        convergence tolerance of every step (and, with error control, as the target of the
        error estimate); the error norm is absolute for states below 1, so it is about the
        attitude error per step [rad]. With fixed Radau3 steps of one 10 Hz period the Newton
        tolerance, not the step, bounds the attitude error away from the dockings. Against a
        converged reference (fixed steps of 25 ms, 6 ms in the ramps, tolerance 1e-9), the
        default (fixed steps, 1e-7, ``ramp_substeps`` 4) is within 0.08 % of the peak attitude
        on an arm-motion window (400-440 s), 0.03 % at the capture ramp (250-275 s) and 1.4 % at
        the second docking (870-900 s: the SM2 and SM1 ramps excite the 1e5 N/m bushings at
        ~100 Hz; ``ramp_substeps`` 16 gives 0.08 %); session 1's error-controlled 1e-5 was
        7.4 %, 0.03 % and 3.5 % off on the same windows at about the same cost
        (``benchmarks/bench_mission_sim.py --accuracy-study``).
    divergence_limit : float
        Hub attitude beyond which a run is declared diverged [rad].
    check_interval : float
        Simulated time between divergence checks [s].
    """

    control_rate: float | None = None
    log_rate: float | None = None
    controller: str | None = None
    torque_limit: float = 2.0
    joint_bandwidth: float = 200.0
    joint_damping_ratio: float = 0.7
    arm_min_inertia: float = 1.0
    ramp_duration: float = 2.0
    ramp_steps: int = 10
    ramp_start_stiffness: float = 0.1
    ramp_substeps: int = 4
    integrator: str = "radau3"
    max_step: float | None = None
    error_control: bool | None = None
    accuracy: float = 1e-7
    divergence_limit: float = 0.5
    check_interval: float = 50.0

    def __post_init__(self):
        positive = [
            name for name in ("control_rate", "log_rate") if getattr(self, name) is not None
        ]
        positive += [
            "torque_limit",
            "joint_bandwidth",
            "joint_damping_ratio",
            "ramp_duration",
            "ramp_start_stiffness",
            "accuracy",
            "divergence_limit",
            "check_interval",
        ]
        if self.max_step is not None:
            positive.append("max_step")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise ValueError(f"mission option {name} must be a positive number, got {value!r}")
        if self.control_rate is not None and self.log_rate is not None:
            ratio = self.control_rate / self.log_rate
            if abs(ratio - round(ratio)) > 1e-9:
                raise ValueError(
                    f"mission option log_rate {self.log_rate} Hz must divide control_rate "
                    f"{self.control_rate} Hz (e.g. log_rate = "
                    f"{logging_rate(self.control_rate, self.log_rate):g})"
                )
        if not (isinstance(self.ramp_substeps, int) and self.ramp_substeps >= 1):
            raise ValueError(
                f"mission option ramp_substeps must be an integer >= 1, got {self.ramp_substeps!r}"
            )
        if int(self.ramp_steps) < 1:
            raise ValueError(f"mission option ramp_steps must be >= 1, got {self.ramp_steps}")
        if self.error_control not in (None, True, False):
            raise ValueError(
                f"mission option error_control must be true, false or unset, got "
                f"{self.error_control!r}"
            )

    def resolved(self, scenario: Scenario) -> MissionOptions:
        """These options with the rates set: ``control_rate`` from the scenario's flight
        software when unset, ``log_rate`` the fastest rate <= 1 Hz that divides it when unset."""
        control_rate = (
            scenario.control.flight_software_rate_hz
            if self.control_rate is None
            else self.control_rate
        )
        log_rate = logging_rate(control_rate, 1.0) if self.log_rate is None else self.log_rate
        return dataclasses.replace(self, control_rate=float(control_rate), log_rate=log_rate)

    @property
    def step(self) -> float:
        """Integrator step outside the docking ramps [s]: ``max_step``, at most one period."""
        period = 1.0 / self.control_rate
        return period if self.max_step is None else min(float(self.max_step), period)

    @property
    def fixed_step(self) -> bool:
        """Whether the integrator takes fixed steps of one control period (see the class doc)."""
        if self.error_control is None:
            return self.integrator in IMPLICIT_INTEGRATORS
        return not self.error_control


@dataclass(frozen=True, eq=False)
class MissionDiagram:
    """Handles of a built mission diagram (not picklable: build one per process).

    Attributes
    ----------
    diagram : Diagram
    plant : MultibodyPlant
    flight_software : FlightSoftware
    options : MissionOptions
    scenario : Scenario
    timeline : MissionTimeline
    controller : ControllerSystem
        Controller in use (``y -> u_K``; the static gain ``[K_p, K_d]`` has no states).
    hub_joint, target_joint : RpyFloatingJoint
    arm_joints, drive_joints : tuple of RevoluteJoint
    mode_joints : Mapping[str, tuple of RevoluteJoint]
        Array name -> its 6 mode hinges (the modal coordinates, scaled).
    mode_springs : Mapping[str, tuple of RevoluteSpring]
        Array name -> the springs of its mode hinges.
    bushings : Mapping[str, LinearBushingRollPitchYaw]
        ``{"SM1": J7 - D2, "SM2": D1 - D3}``.
    frames : Mapping[str, Frame]
        ``G1, G2, D1, D2, D3, J7``.
    target_body : RigidBody
    state_logger, torque_logger : VectorLogSink
    """

    diagram: Diagram
    plant: MultibodyPlant
    flight_software: FlightSoftware
    options: MissionOptions
    scenario: Scenario
    timeline: MissionTimeline
    controller: ControllerSystem
    hub_joint: object
    target_joint: object
    arm_joints: tuple
    drive_joints: tuple
    mode_joints: Mapping[str, tuple] = field(default_factory=dict)
    mode_springs: Mapping[str, tuple] = field(default_factory=dict)
    bushings: Mapping[str, LinearBushingRollPitchYaw] = field(default_factory=dict)
    frames: Mapping[str, object] = field(default_factory=dict)
    target_body: object = None
    state_logger: object = None
    torque_logger: object = None

    @property
    def K(self) -> np.ndarray:
        """The static gain ``[K_p, K_d]`` (3x6) in use (ValueError for a dynamic controller)."""
        return self.controller.K


def quintic_piecewise_polynomial(trajectory: QuinticTrajectory) -> PiecewisePolynomial:
    """The exact Drake ``PiecewisePolynomial`` of a :class:`QuinticTrajectory`.

    Segment ``k``: ``q_k + (q_{k+1} - q_k) (10 u^3 - 15 u^4 + 6 u^5)``, ``u = (t - t_k)/h_k``;
    Drake evaluates each segment's polynomial in ``t - t_k``.
    """
    times = np.asarray(trajectory.times, dtype=float)
    values = np.asarray(trajectory.values, dtype=float)
    polynomials = []
    for k in range(len(times) - 1):
        h = times[k + 1] - times[k]
        shape = np.array([0.0, 0.0, 0.0, 10.0 / h**3, -15.0 / h**4, 6.0 / h**5])
        matrix = np.empty((values.shape[1], 1), dtype=object)
        for i in range(values.shape[1]):
            coefficients = shape * (values[k + 1, i] - values[k, i])
            coefficients[0] = values[k, i]
            matrix[i, 0] = Polynomial(coefficients)
        polynomials.append(matrix)
    return PiecewisePolynomial(polynomials, list(times))


def effective_inertia(D_G1: np.ndarray) -> np.ndarray:
    """Rotational inertia seen by a torque on a free body: the Schur complement of ``D_G1``.

    ``J = D_rr - D_rt D_tt^-1 D_tr`` [kg m^2] (the inverse of the static gain torque -> wdot).
    """
    D = np.asarray(D_G1, dtype=float)
    return D[3:, 3:] - D[3:, :3] @ np.linalg.solve(D[:3, :3], D[:3, 3:])


def mission_controller(path: str | Path | None, scenario: Scenario) -> ControllerSystem:
    """The controller of the mission: a synthesis ``controller.json`` or the baseline gain.

    Parameters
    ----------
    path : str, Path or None
        ``controller.json`` written by ``oos synth`` (any structure, read by
        :func:`oos_drake.control.interconnection.read_controller`); ``None``: the paper's baseline
        (``omega = 2 pi 0.01 rad/s``, ``xi = 1``) tuned at the first docking,
        :func:`oos_drake.control.baseline.scenario_baseline_gains` (the analysis' baseline).
    scenario : Scenario
        The scenario of the baseline (unused with a file).

    Raises
    ------
    ValueError
        Missing file or malformed controller (the message names the file and the field).
    """
    if path is None:
        return ControllerSystem.static(scenario_baseline_gains(scenario))
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"controller file {path} not found")
    return read_controller(path)[1]


def _add_plant(builder: DiagramBuilder, sdf_directory: Path):
    plant, instance, frames, hub_joint = add_scenario_plant(builder, sdf_directory)
    target = frames["G2"].body()
    target_joint = add_floating_joint(plant, target, RigidTransform(), name="RH2_floating")
    bushings = add_docking_bushings(plant, frames)
    # no gravity in orbit: the gravity vector is zero, and disabling the element per model
    # instance also skips computing its (zero) generalized forces at every derivative evaluation
    for index in range(plant.num_model_instances()):
        plant.set_gravity_enabled(ModelInstanceIndex(index), False)
    plant.Finalize()
    arm_joints, drive_joints = prescribed_joints(plant, instance)
    mode_joints, mode_springs = {}, {}
    by_joint = {s.joint().index(): s for s in force_elements(plant, RevoluteSpring)}
    for array in ARRAYS:
        mode_joints[array] = tuple(modal_hinges(plant, instance(array)))
        mode_springs[array] = tuple(by_joint[j.index()] for j in mode_joints[array])
    return dict(
        plant=plant,
        hub_joint=hub_joint,
        target_joint=target_joint,
        arm_joints=arm_joints,
        drive_joints=drive_joints,
        mode_joints=MappingProxyType(mode_joints),
        mode_springs=MappingProxyType(mode_springs),
        bushings=MappingProxyType(bushings),
        frames=MappingProxyType(frames),
        target_body=target,
    )


def make_mission_diagram(
    options: MissionOptions | None = None,
    *,
    scenario: Scenario,
    K=None,
    sdf_directory: str | Path | None = None,
    timeline: MissionTimeline | None = None,
    perturbation_states: int = 0,
) -> MissionDiagram:
    """Build the closed-loop mission diagram (see the module docstring).

    Parameters
    ----------
    options : MissionOptions, optional
        Rates, controller file, joint PD, integrator settings (default: ``MissionOptions()``;
        unset rates come from the scenario: :meth:`MissionOptions.resolved`).
    scenario : Scenario
        Scenario data (trajectories, inertias, flight software).
    K : array_like, shape (3, 6), or ControllerSystem, optional
        Controller (gain ``[K_p, K_d]`` or a linear controller ``y -> u_K``) overriding
        ``options.controller``.
    sdf_directory : str or Path, optional
        Directory of ``oos_scenario.sdf`` (default: the scenario's own twin,
        :func:`~oos_drake.multibody.scenario_sdf.scenario_sdf_directory`).
    timeline : MissionTimeline, optional
        Trajectories the arm and array drives follow (default: the scenario's mission;
        ``mission_timeline(scenario).frozen(t)`` holds them at time ``t``). The joint PDs and
        the additive perturbation's inertia are sized on the scenario's own timeline either way.
    perturbation_states : int
        States of the flight software's dynamic perturbation block (the analysis' complex
        blocks realized at a peak's frequency: ``oos confirm``); 0: none.

    Returns
    -------
    MissionDiagram
    """
    options = (options or MissionOptions()).resolved(scenario)
    if sdf_directory is None:
        sdf_directory, _ = scenario_sdf_directory(scenario)
    mission = mission_timeline(scenario)
    timeline = mission if timeline is None else timeline
    controller = mission_controller(options.controller, scenario) if K is None else as_controller(K)
    builder = DiagramBuilder()
    parts = _add_plant(builder, Path(sdf_directory))
    plant = parts["plant"]
    nq, nv = plant.num_positions(), plant.num_velocities()

    # motion-driven joints: r = [alpha(6), alpha_dot(6), theta_12(2), theta_12_dot(2)]
    arm_source = builder.AddNamedSystem(
        "arm_trajectory",
        TrajectorySource(quintic_piecewise_polynomial(timeline.arm), output_derivative_order=1),
    )
    array_source = builder.AddNamedSystem(
        "array_trajectory",
        TrajectorySource(quintic_piecewise_polynomial(timeline.arrays), output_derivative_order=1),
    )
    reference = builder.AddNamedSystem("joint_reference", Multiplexer([12, 4]))
    builder.Connect(arm_source.get_output_port(), reference.get_input_port(0))
    builder.Connect(array_source.get_output_port(), reference.get_input_port(1))

    sizing_context = plant.CreateDefaultContext()
    grasp = mission.configuration(float(scenario.mission.first_docking_time))
    for joint, angle in zip(parts["arm_joints"], grasp.alpha, strict=True):
        joint.set_angle(sizing_context, angle)
    M = plant.CalcMassMatrix(sizing_context)
    K_state = np.zeros((nv, nq + nv))
    K_ref = np.zeros((nv, 16))
    w, zeta = options.joint_bandwidth, options.joint_damping_ratio
    for i, joint in enumerate(parts["arm_joints"] + parts["drive_joints"]):
        qi, vi = joint.position_start(), joint.velocity_start()
        inertia = M[vi, vi]
        if i < 6:
            inertia = max(inertia, options.arm_min_inertia)
        kp, kd = w**2 * inertia, 2.0 * zeta * w * inertia
        K_state[vi, qi], K_state[vi, nq + vi] = -kp, -kd
        if i < 6:
            K_ref[vi, i], K_ref[vi, 6 + i] = kp, kd
        elif i < 8:  # chaser arrays follow theta_1,2; target arrays held at their fixed angle
            K_ref[vi, 12 + i - 6], K_ref[vi, 14 + i - 6] = kp, kd
    joint_state_gain = builder.AddNamedSystem("joint_pd_state", MatrixGain(K_state))
    joint_ref_gain = builder.AddNamedSystem("joint_pd_reference", MatrixGain(K_ref))
    builder.Connect(plant.get_state_output_port(), joint_state_gain.get_input_port())
    builder.Connect(reference.get_output_port(), joint_ref_gain.get_input_port())

    J_ref = effective_inertia(rigid_spatial_inertia_at_G1(scenario, grasp))
    design = FlightSoftwareDesign.create(
        controller,
        options.control_rate,
        spec=DesignSpecification.from_requirements(scenario.control),
        torque_limit=options.torque_limit,
        J_ref=J_ref,
    )
    fsw = builder.AddNamedSystem(
        "flight_software",
        FlightSoftware(
            design,
            nq,
            nv,
            parts["hub_joint"].position_start(),
            parts["hub_joint"].velocity_start(),
            perturbation_states=perturbation_states,
        ),
    )
    builder.Connect(plant.get_state_output_port(), fsw.get_input_port(0))
    forces = builder.AddNamedSystem("generalized_forces", Adder(3, nv))
    builder.Connect(joint_state_gain.get_output_port(), forces.get_input_port(0))
    builder.Connect(joint_ref_gain.get_output_port(), forces.get_input_port(1))
    builder.Connect(fsw.GetOutputPort("generalized_force"), forces.get_input_port(2))
    builder.Connect(forces.get_output_port(), plant.get_applied_generalized_force_input_port())

    period = 1.0 / options.log_rate
    state_logger = LogVectorOutput(plant.get_state_output_port(), builder, period)
    state_logger.set_name("state_logger")
    torque_logger = LogVectorOutput(fsw.GetOutputPort("log"), builder, period)
    torque_logger.set_name("torque_logger")
    diagram = builder.Build()
    diagram.set_name("oos_mission")
    return MissionDiagram(
        diagram=diagram,
        flight_software=fsw,
        options=options,
        scenario=scenario,
        timeline=timeline,
        controller=controller,
        state_logger=state_logger,
        torque_logger=torque_logger,
        **parts,
    )
