"""The Drake twin of a schema-2 tree following its mission, as a campaign simulator.

Adapter between :mod:`oos_drake.multibody.tree_twin` (the tree's own Drake twin, its revolute
joints motion-driven along the timeline's joint angles, closed by the scenario's flight
software) and the campaign's :class:`~oos_drake.campaign.simulator.Simulator` protocol. Use it
in a spec with::

    scenario = "flexible_satellite"
    [simulator]
    name = "oos_drake.campaign.tree_simulator:make_simulator"
    options = { log_rate = 1.0 }

Parameters are keyed by the tree's uncertain-block names (``m_<body>``, ``Jxx_<body>``,
``w<i>_<body>``: the LFR's, so the analysis' ``worst_cases.parquet`` columns map onto them one
to one), with the ranges the scenario declares (the campaign's default dispersions); the
initial errors ``phi0_*`` [rad], ``w0_*`` [rad/s], ``noise_seed``, the normalized all-pass
scalars ``Delta_mul_*``, ``Delta_add`` and the disturbance inputs (``noise_scale``, the
sinusoid ``sine_*`` of the analysis' worst input) as for the paper's mission simulator
(:mod:`oos_drake.campaign.drake_simulator`). A run with other real-block values than the last
rebuilds the twin from the tree with those values written into its data
(:func:`~oos_drake.multibody.tree_twin.tree_with_values`, a fraction of a second); a run is a
pure function of its case. Events: the start of each mission phase (``start:<phase>``).
The option ``worst_perturbation`` realizes the analysis' worst complex blocks with their phase,
scaled by the parameter ``worst_scale``, as the paper's mission simulator does (what ``oos
campaign falsify --confirm`` runs).

A mission that captures or docks a target: the twin welds a captured target at the mated
ports through the phases that capture it, and holds a docked one on its spring-damper (a
``LinearBushingRollPitchYaw`` between the two ports, the docking studies' twin:
``build_tree_twin(..., docking=)``) whose coefficients are the run's parameters
``k_shear_<name>``, ``k_tors_<name>``, ``d_shear_<name>``, ``d_tors_<name>`` (the
spring-damper's blocks; the declared ranges, ``stiffness_percent`` and ``damping_percent``,
are their default dispersions; a coefficient without one is dispersed only by a spec, over
:data:`~oos_drake.multibody.mission_sim.BUSHING_RANGES`, as the paper's; one value per name,
so the docked phases of one spring-damper fly the same). A window that crosses a capture,
docking or release runs in segments, each on the twin of its phase, the state carried over
(:func:`~oos_drake.multibody.tree_twin.run_mission_twin`; a docked target starts on its port,
moving with it: no initial spring load). Tip-pose
waypoints are solved on the twin (:func:`~oos_drake.multibody.tree_ik.mission_timeline`: the
angles of the joint-space copy ``oos run`` writes, ``oos tree solve``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
import pandas as pd

from oos_drake.campaign.simulator import (
    Parameter,
    ParameterKind,
    RunCase,
    RunOutput,
    SimulationDiverged,
    check_options,
)

__all__ = ["TreeMissionSimulator", "make_simulator", "FACTORY_PATH", "METRIC_UNITS"]

#: Import path of the factory (usable as ``[simulator] name`` in a spec).
FACTORY_PATH = "oos_drake.campaign.tree_simulator:make_simulator"

AXES = ("x", "y", "z")

#: Metrics of a run and their units.
METRIC_UNITS = MappingProxyType(
    {
        "ape": "rad",
        "rms_attitude": "rad",
        "peak_torque": "N m",
        "peak_applied_torque": "N m",
        "max_tracking_error": "rad",
    }
)

_SIGNALS = (("phi", "rad"), ("w", "rad/s"), ("u", "N m"), ("T_rw", "N m"), ("T", "N m"),
            ("T_dist", "N m"))  # fmt: skip
_METRIC_SIGNALS = {"ape": "phi_y", "peak_torque": "u_y", "peak_applied_torque": "T_y"}

#: Options of the factory (and their defaults).
OPTIONS = {
    "scenario": None,
    "controller": None,
    "control_rate": None,
    "torque_limit": None,
    "log_rate": 1.0,
    "max_step": None,
    "joint_bandwidth": 200.0,
    "joint_damping_ratio": 0.7,
    "divergence_limit": 0.5,
    "worst_perturbation": None,
}


def tree_parameters(scenario) -> tuple[Parameter, ...]:
    """The dispersible parameters of a tree scenario's mission (see the module docstring): the
    uncertain blocks of its mission model (a mated target's included), not the scheduled
    ones (``tau_<body>``, ``delta_<PORT>``: the mission's values), and the disturbance inputs
    of the paper's mission (``noise_scale``, the sinusoid ``sine_*``:
    :func:`~oos_drake.multibody.mission_sim.disturbance_parameters`)."""
    from oos_drake.campaign.drake_simulator import campaign_parameters
    from oos_drake.multibody.mission_sim import disturbance_parameters

    params = []
    params += _spring_damper_parameters(scenario)
    for name, block in sorted(scenario.mission_model().uncertainty.items()):
        if block.quantity in ("angle", "switch"):  # scheduled along the mission
            continue
        low, high = (float(v) for v in block.range)
        params.append(
            Parameter(
                name,
                block.unit,
                float(block.nominal),
                low,
                high,
                ParameterKind.of_quantity(block.quantity),
                f"{block.quantity} {name}",
                uncertainty=(low, high),
            )
        )
    for prefix, unit, bound, what in (
        ("phi0", "rad", 0.05, "attitude error"),
        ("w0", "rad/s", 0.01, "body rate error"),
    ):
        params += [
            Parameter(
                f"{prefix}_{a}",
                unit,
                0.0,
                -bound,
                bound,
                ParameterKind.INITIAL_CONDITION,
                f"initial {what} of the controlled body ({a})",
            )
            for a in AXES
        ]
    params.append(
        Parameter(
            "noise_seed",
            "-",
            0.0,
            0.0,
            2.0**31,
            ParameterKind.SEED,
            "seed of sensor noise and disturbances (0: the run seed)",
        )
    )
    params += [
        Parameter(
            f"Delta_mul_{r}{c}",
            "-",
            0.0,
            -1.0,
            1.0,
            ParameterKind.LTI,
            f"entry {r}{c} of the multiplicative actuator all-pass perturbation",
            uncertainty=(-1.0, 1.0),
        )
        for r in AXES
        for c in AXES
    ]
    params.append(
        Parameter(
            "Delta_add",
            "-",
            0.0,
            -1.0,
            1.0,
            ParameterKind.LTI,
            "scale of the additive plant all-pass perturbation",
            uncertainty=(-1.0, 1.0),
        )
    )
    params += campaign_parameters(disturbance_parameters())
    return tuple(params)


def _spring_damper_parameters(scenario) -> list[Parameter]:
    """The coefficients of the docked phases' spring-dampers (blocks of
    :meth:`~oos_drake.scenario.tree_scenario.TreeScenario.docking_model`, the first docked
    phase declaring a name giving its nominal): declared uncertain (a percent) -> that range
    is the default dispersion; else none. Valid range: :data:`BUSHING_RANGES` (and the
    declared one)."""
    from oos_drake.multibody.mission_sim import BUSHING_RANGES
    from oos_drake.scenario.tree_model import docking_block_names

    phases = () if scenario.tree.mission is None else scenario.tree.mission.phases
    found: dict[str, Parameter] = {}
    for phase in phases:
        spring = phase.docked
        if spring is None or docking_block_names(spring)["k_shear"] in found:
            continue
        blocks = scenario.docking_model(phase.name).uncertainty
        for key, name in docking_block_names(spring).items():
            block = blocks[name]
            percent = spring.stiffness_percent if key[0] == "k" else spring.damping_percent
            low, high = BUSHING_RANGES[block.quantity]
            declared = tuple(float(v) for v in block.range) if percent > 0 else None
            if declared is not None:
                low, high = min(low, declared[0]), max(high, declared[1])
            what = "stiffness" if key[0] == "k" else "damping"
            axis = "shear" if "shear" in key else "torsional"
            found[name] = Parameter(
                name,
                block.unit,
                float(getattr(spring, key)),
                low,
                high,
                ParameterKind.STIFFNESS,
                f"{axis} {what} of spring-damper {spring.label} "
                f"({spring.port}-{spring.target_port})",
                uncertainty=declared,
            )
    return list(found.values())


class TreeMissionSimulator:
    """Campaign simulator running a tree's Drake twin along its mission.

    Parameters
    ----------
    scenario : str
        Schema-2 scenario file or shipped tree name (a spec's ``scenario`` key).
    controller : str, optional
        ``controller.json`` of ``oos synth`` (default: the baseline PD on the tree's rigid
        inertia at its file angles, ``oos_drake.control.baseline.baseline_gains``).
    control_rate, torque_limit : float, optional
        Flight-software rate [Hz] and torque bound [N m] (default: the scenario's
        ``[control]``).
    log_rate : float
        Logging rate [Hz] (the fastest rate at most this that divides the control rate).
    max_step : float, optional
        Integrator step [s] (default: one flight-software period).
    joint_bandwidth, joint_damping_ratio : float
        Joint PD of the motion-driven joints [rad/s], [-].
    divergence_limit : float
        Attitude beyond which a run is diverged [rad].
    worst_perturbation : str, optional
        The analysis' worst complex blocks realized with their phase in the flight software,
        scaled by the parameter ``worst_scale`` (0 by default: not applied): the paper's
        mission simulator's option, the same realization
        (:func:`~oos_drake.campaign.drake_simulator.worst_perturbation_option`,
        :func:`~oos_drake.multibody.flight_software.perturbation_block`).
    """

    def __init__(self, **options):
        from oos_drake.control.baseline import baseline_gains
        from oos_drake.control.components import DesignSpecification
        from oos_drake.control.interconnection import ControllerSystem, read_controller
        from oos_drake.multibody.flight_software import FlightSoftwareDesign
        from oos_drake.multibody.mission import effective_inertia, logging_rate
        from oos_drake.scenario.data import load_scenario
        from oos_drake.scenario.tree_model import docking_block_names, rigid_inertia_at_root
        from oos_drake.scenario.tree_scenario import is_tree

        check_options("tree-mission", options, set(OPTIONS))
        o = OPTIONS | options
        scenario = load_scenario(o["scenario"])
        if not is_tree(scenario):
            raise ValueError(
                f"tree-mission: scenario {scenario.name} is not a schema-2 tree "
                "(its simulator: oos_drake.campaign.drake_simulator:make_simulator)"
            )
        self.scenario, self.tree, self.timeline = scenario, scenario.tree, scenario.timeline
        if self.timeline is None:  # tip-pose waypoints: solved on the twin, as `oos run` does
            from oos_drake.multibody.tree_ik import mission_timeline

            self.timeline = mission_timeline(self.tree)
        control = scenario.control
        rate = float(o["control_rate"] or control.flight_software_rate_hz)
        J_ref = effective_inertia(rigid_inertia_at_root(self.tree))
        J_ref = 0.5 * (J_ref + J_ref.T)
        if o["controller"] is None:  # the baseline PD on the rigid inertia (file angles)
            self.controller = ControllerSystem.static(baseline_gains(J_ref))
        else:
            self.controller = read_controller(o["controller"])[1]
        self.design = FlightSoftwareDesign.create(
            self.controller,
            rate,
            spec=DesignSpecification.from_requirements(control),
            torque_limit=float(o["torque_limit"] or control.torque_limit),
            J_ref=J_ref,
        )
        self.log_rate = logging_rate(rate, float(o["log_rate"]))
        self.max_step = float(o["max_step"] or self.design.period)
        self.joint_pd = (float(o["joint_bandwidth"]), float(o["joint_damping_ratio"]))
        self.divergence_limit = float(o["divergence_limit"])
        self._parameters = tree_parameters(scenario)
        self._worst, self._perturbation_states = None, 0
        if o["worst_perturbation"] is not None:  # as the paper's mission simulator
            from oos_drake.campaign.drake_simulator import _complex_blocks, worst_scale_parameter
            from oos_drake.multibody.flight_software import perturbation_block

            self._worst = _complex_blocks(str(o["worst_perturbation"]), "tree-mission")
            block = perturbation_block(self.design, self._worst[0], **self._worst[1])
            self._perturbation_states = block.nstates
            self._parameters += (worst_scale_parameter(),)
        self._real = tuple(p.name for p in self._parameters if p.kind == ParameterKind.REAL_BLOCK)
        self._springs = {
            phase.docked.label: docking_block_names(phase.docked)
            for phase in (self.tree.mission.phases if self.tree.mission else ())
            if phase.docked is not None
        }
        self._twin_key, self._twins = None, {}

    def parameters(self) -> tuple[Parameter, ...]:
        """Dispersible parameters (uncertain blocks, initial errors, seed, LTI scalars)."""
        return self._parameters

    def metric_units(self) -> Mapping[str, str]:
        """``ape``, ``rms_attitude`` [rad], ``peak_torque``, ``peak_applied_torque`` [N m],
        ``max_tracking_error`` [rad] (joints against their trajectory)."""
        return dict(METRIC_UNITS)

    def signal_units(self) -> Mapping[str, str]:
        """Attitude, body rate and the flight software's torques, per axis."""
        return {f"{p}_{a}": unit for p, unit in _SIGNALS for a in AXES}

    def metric_signals(self) -> Mapping[str, str]:
        """Metric -> the signal the report draws it on."""
        return dict(_METRIC_SIGNALS)

    def events(self) -> Mapping[str, float]:
        """``start:<phase>`` -> the phase's start [s]."""
        phases = self.tree.mission.phases if self.tree.mission else ()
        starts = np.asarray(self.timeline.boundaries, dtype=float)[:-1]
        return {f"start:{p.name}": float(t) for p, t in zip(phases, starts, strict=False)}

    def duration(self) -> float:
        """Mission length [s]."""
        return float(self.timeline.boundaries[-1])

    def twin(self, values: Mapping[str, float], mating=None):
        """The twin with the real blocks at ``values`` [their units] and the target welded at
        ``mating`` (``(port, target port)``), or held by a docked phase's spring-damper
        (``mating`` its :class:`~oos_drake.scenario.tree_mission.Docking`: its file
        coefficients in the twin's defaults, a run sets its own), or free (None); built once
        per mating, rebuilt on a change of the real blocks' values."""
        from oos_drake.multibody.tree_twin import build_tree_twin, tree_with_values
        from oos_drake.scenario.tree_mission import Docking

        nominal = {p.name: p.nominal for p in self._parameters}
        real = {n: float(values.get(n, nominal[n])) for n in self._real}
        key = tuple(real.values())
        if key != self._twin_key:
            self._twins, self._twin_key = {}, key
        if mating not in self._twins:
            changed = {n: v for n, v in real.items() if v != nominal[n]}
            docked = isinstance(mating, Docking)
            rest = None  # a docked target's joint zero: its rest pose at the phase's start
            if docked:
                index = next(i for i, d in enumerate(self.timeline.dockings) if d is mating)
                rest = self.timeline.angles(self.timeline.boundaries[index])
            self._twins[mating] = build_tree_twin(
                tree_with_values(self.tree, changed),
                self.design,
                rest,
                log_rate=self.log_rate,
                perturbation_states=self._perturbation_states,
                timeline=self.timeline,
                joint_bandwidth=self.joint_pd[0],
                joint_damping_ratio=self.joint_pd[1],
                mating=None if docked else mating,
                docking=(mating,) if docked else (),
            )
        return self._twins[mating]

    def run(self, case: RunCase) -> RunOutput:
        """Simulate the case's window; divergence raises :class:`SimulationDiverged`."""
        from oos_drake.multibody.flight_software import NOISE_CHANNELS
        from oos_drake.multibody.mission_sim import disturbance_table
        from oos_drake.multibody.tree_twin import run_mission_twin

        values = {p.name: p.nominal for p in self._parameters} | dict(case.values)
        dynamic = None
        if self._worst is not None:
            from oos_drake.campaign.drake_simulator import WORST_SCALE, scaled_worst_block

            dynamic = scaled_worst_block(self.design, self._worst, float(values.pop(WORST_SCALE)))
        start, end = float(case.window.start), float(case.window.end)
        if not (0.0 <= start < end <= self.duration() + 1e-9):
            raise ValueError(
                f"tree-mission: window [{start}, {end}] s outside [0, {self.duration()}] s"
            )
        noise_seed = int(values["noise_seed"]) or int(case.seed)
        n = int(math.ceil((end - start) / self.design.period)) + 2
        noise = np.random.default_rng(noise_seed).standard_normal((n, NOISE_CHANNELS))
        noise = disturbance_table(values, noise, start, 1.0 / self.design.period)
        delta_mul = np.array([[values[f"Delta_mul_{r}{c}"] for c in AXES] for r in AXES])
        delta_add = float(values["Delta_add"])
        frequency = float(case.frequency)  # NaN with nonzero scalars: refused, by name
        springs = {  # {label: (k_shear, k_tors, d_shear, d_tors)}: the run's coefficients
            label: tuple(float(values[name]) for name in names.values())
            for label, names in self._springs.items()
        }
        run = run_mission_twin(
            lambda mating: self.twin(values, mating),
            self.timeline,
            end - start,
            start=start,
            springs=True,
            spring_dampers=springs,
            initial_attitude=[values[f"phi0_{a}"] for a in AXES],
            initial_rate=[values[f"w0_{a}"] for a in AXES],
            noise_table=noise,
            perturbations=(delta_mul, delta_add, frequency),
            dynamic=dynamic,
            max_step=self.max_step,
            divergence_limit=self.divergence_limit,
        )
        if run.diverged:
            raise SimulationDiverged(
                f"tree-mission: attitude beyond {self.divergence_limit} rad (or the integrator "
                f"failed) in [{start}, {end}] s"
            )
        m = run.metrics
        samples = max(float(m["samples"]), 1.0)
        metrics = {
            "ape": float(m["max_phi"].max()),
            "rms_attitude": float(np.sqrt(m["sumsq_phi"].sum() / (3.0 * samples))),
            "peak_torque": float(m["max_u"].max()),
            "peak_applied_torque": float(m["max_T"].max()),
            "max_tracking_error": run.joint_error,
        }
        columns = {"time [s]": run.times + start}
        for i, a in enumerate(AXES):
            columns[f"phi_{a} [rad]"] = run.phi[:, i]
        for i, a in enumerate(AXES):
            columns[f"w_{a} [rad/s]"] = run.rate[:, i]
        for j, (prefix, _) in enumerate(_SIGNALS[2:]):  # the torques, in N m
            for i, a in enumerate(AXES):
                columns[f"{prefix}_{a} [N m]"] = run.torques[:, 3 * j + i]
        return RunOutput(metrics=metrics, timeseries=pd.DataFrame(columns))


def make_simulator(**options) -> TreeMissionSimulator:
    """Factory for :class:`~oos_drake.campaign.simulator.SimulatorRecipe` (options as keywords)."""
    return TreeMissionSimulator(**options)
