"""The Drake mission simulation as a campaign simulator (``"drake-mission"``).

Adapter between :class:`oos_drake.multibody.mission_sim.MissionSimulation` (the closed-loop
nonlinear mission in Drake) and the campaign's :class:`~oos_drake.campaign.simulator.Simulator`
protocol. The diagram is built once per worker process (the factory is cached by
:func:`~oos_drake.campaign.simulator.build_simulator`); every run starts from a fresh context, so
a run is a pure function of its case (values, seed, window) and ``rerun`` reproduces it exactly.

Use it in a spec with::

    scenario = "paper"                  # the scenario the mission is built from (required)

    [simulator]
    name = "oos_drake.campaign.drake_simulator:make_simulator"
    options = { control_rate = 10.0, log_rate = 1.0 }

Parameters are keyed by the uncertain-block names of the LFR model (``m_RH2``, ``Jxx_RH2``,
``w1_SA1``, ``k_shear_SM1``, ...), so the analysis' ``worst_cases.parquet`` columns map onto them
one to one; see :func:`oos_drake.multibody.mission_sim.mission_parameters` for the list.

The mission realizes each complex block (``Delta_add``, ``Delta_mul_*``) as a signed real
scalar times an all-pass at -90 deg: the phase of the analysis' worst complex values is lost.
The option ``worst_perturbation`` (:func:`worst_perturbation_option`: the analysis' worst
perturbation and its frequency, as ``oos confirm``'s performance table stores them) realizes
them with their phase instead, as ``oos confirm`` does (the flight software's dynamic
perturbation, :func:`~oos_drake.multibody.flight_software.perturbation_block`), scaled by the
parameter ``worst_scale`` in [0, 1] (0 by default: not applied). The falsification
(``oos campaign falsify --confirm``) uses it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields

import numpy as np

from oos_drake.campaign.simulator import (
    Parameter,
    ParameterKind,
    RunCase,
    RunOutput,
    SimulationDiverged,
    check_options,
)

__all__ = [
    "DrakeMissionSimulator",
    "FACTORY_PATH",
    "WORST_SCALE",
    "campaign_parameters",
    "make_simulator",
    "worst_perturbation_option",
]

#: Import path of the factory (usable as ``[simulator] name`` in a spec).
FACTORY_PATH = "oos_drake.campaign.drake_simulator:make_simulator"
#: Parameter scaling the realized worst perturbation (option ``worst_perturbation``) [-].
WORST_SCALE = "worst_scale"


def worst_perturbation_option(perturbation: str, frequency_hz: float) -> str:
    """The ``worst_perturbation`` option (JSON text) of a worst case: ``perturbation`` is the
    ``worst perturbation`` JSON of ``oos confirm``'s performance table (block -> normalized
    value, complex values as ``[re, im]`` pairs), ``frequency_hz`` its critical frequency [Hz]."""
    import json

    return json.dumps(
        {"frequency [Hz]": float(frequency_hz), "perturbation": json.loads(perturbation)},
        sort_keys=True,
    )


def worst_scale_parameter() -> Parameter:
    """The parameter ``worst_scale`` of a simulator given the option ``worst_perturbation``
    (this one's and the tree's, :mod:`oos_drake.campaign.tree_simulator`)."""
    return Parameter(
        WORST_SCALE,
        "-",
        0.0,
        0.0,
        1.0,
        ParameterKind.LTI,
        "scale of the analysis' worst complex perturbation realized with its phase "
        "(option worst_perturbation)",
        uncertainty=(0.0, 1.0),
    )


def scaled_worst_block(design, worst: tuple[float, dict], scale: float):
    """The flight software's dynamic perturbation for ``worst_scale = scale``: the worst complex
    blocks ``worst`` (:func:`_complex_blocks`) scaled by ``scale`` at their frequency, or None
    at 0 (the plain mission)."""
    if scale == 0.0:
        return None
    from oos_drake.multibody.flight_software import perturbation_block

    omega, blocks = worst
    return perturbation_block(design, omega, **{k: scale * v for k, v in blocks.items()})


def _complex_blocks(option: str, simulator: str = "drake-mission") -> tuple[float, dict]:
    """``(omega [rad/s], {"delta_mul": 3x3, "delta_add": 3x3})`` of a ``worst_perturbation``
    option (its complex blocks; real ones ignored); ``simulator`` names the simulator in the
    errors.

    Raises
    ------
    ValueError
        Not the JSON of :func:`worst_perturbation_option`, a bad frequency, no complex block.
    """
    import json
    import math

    from oos_drake.multibody.flight_software import complex_blocks

    try:
        data = json.loads(option)
        frequency = float(data["frequency [Hz]"])
        perturbation = {
            name: np.asarray(pairs, dtype=float)[..., 0]
            + 1j * np.asarray(pairs, dtype=float)[..., 1]
            for name, pairs in data["perturbation"].items()
        }
    except (TypeError, KeyError, IndexError, ValueError) as exc:
        raise ValueError(
            f"{simulator}: option worst_perturbation is not a worst case's JSON ({exc})"
        ) from exc
    if not (math.isfinite(frequency) and frequency > 0):
        raise ValueError(
            f"{simulator}: option worst_perturbation: frequency {frequency} Hz must be > 0"
        )
    omega = 2 * math.pi * frequency
    blocks = complex_blocks(perturbation)
    if not blocks:
        raise ValueError(f"{simulator}: option worst_perturbation has no complex block")
    return omega, blocks


_METRIC_SIGNALS = {"ape": "phi_y", "peak_torque": "u_y", "peak_applied_torque": "T_y"}


def campaign_parameters(mission_parameters) -> tuple[Parameter, ...]:
    """The mission's parameters as campaign parameters, with the uncertainty the scenario declares.

    The uncertain blocks of the scenario (masses, inertias, modal frequencies: kind
    ``real_block``) declare their range (``nominal +- percent``) and the normalized LTI blocks
    ``Delta_*`` their unit ball ``[-1, 1]``: these are the campaign's default dispersions. Docking
    coefficients, initial errors and the noise seed declare none (their ranges are the model's
    domain, not an uncertainty): a spec disperses them explicitly.

    Parameters
    ----------
    mission_parameters : sequence of MissionParameter
        :func:`oos_drake.multibody.mission_sim.mission_parameters` of the scenario.
    """
    out = []
    for p in mission_parameters:
        kind = ParameterKind.of_quantity(p.quantity)
        declared = kind in (ParameterKind.REAL_BLOCK, ParameterKind.LTI)
        out.append(
            Parameter(
                p.name,
                p.unit,
                p.nominal,
                p.lower,
                p.upper,
                kind,
                p.description,
                uncertainty=(p.lower, p.upper) if declared else None,
            )
        )
    return tuple(out)


class DrakeMissionSimulator:
    """Campaign simulator running the nonlinear Drake mission (one diagram per process).

    Parameters
    ----------
    scenario : str
        Scenario data file or shipped scenario name (a spec's ``scenario`` key). The twin is
        parsed from SDF files generated from it (the package's when they match it), and its
        ``[control]`` section gives the default ``control_rate`` (flight software rate [Hz]) and
        ``torque_limit`` [N m]; options given here override them.
    worst_perturbation : str, optional
        The analysis' worst complex blocks realized with their phase, scaled by the parameter
        ``worst_scale`` (:func:`worst_perturbation_option`, module docstring).
    **options
        Fields of :class:`oos_drake.multibody.mission.MissionOptions` (``control_rate``,
        ``log_rate``, ``controller``, ``integrator``, ...).
    """

    def __init__(self, scenario: str, worst_perturbation: str | None = None, **options):
        from oos_drake.multibody.mission import MissionOptions, make_mission_diagram
        from oos_drake.multibody.mission_sim import MissionSimulation
        from oos_drake.multibody.scenario_sdf import scenario_sdf_directory
        from oos_drake.scenario.data import load_scenario

        check_options("drake-mission", options, {f.name for f in fields(MissionOptions)})
        data = load_scenario(scenario)
        options = {
            "control_rate": data.control.flight_software_rate_hz,
            "torque_limit": data.control.torque_limit,
            **options,
        }
        sdf, self._sdf = scenario_sdf_directory(data)  # the folder lives with the simulator
        self._worst = None
        states = 0
        if worst_perturbation is not None:
            from oos_drake.control.components import DesignSpecification
            from oos_drake.multibody.flight_software import FlightSoftwareDesign, perturbation_block

            self._worst = _complex_blocks(str(worst_perturbation))
            # the state count depends on the blocks' structure only, not on the controller
            probe = FlightSoftwareDesign.create(
                np.zeros((3, 6)),
                float(options["control_rate"]),
                spec=DesignSpecification.from_requirements(data.control),
            )
            states = perturbation_block(probe, self._worst[0], **self._worst[1]).nstates
        handles = make_mission_diagram(
            MissionOptions(**options),
            scenario=data,
            sdf_directory=sdf,
            perturbation_states=states,
        )
        self.simulation = MissionSimulation(handles=handles)
        self._parameters = campaign_parameters(self.simulation.parameters)
        if self._worst is not None:
            self._parameters += (worst_scale_parameter(),)

    def parameters(self) -> tuple[Parameter, ...]:
        """Dispersible parameters (uncertain blocks, dockings, initial errors, seed, LTI)."""
        return self._parameters

    def metric_units(self) -> Mapping[str, str]:
        """``ape``, ``rms_attitude`` [rad], torques [N m], bushing forces [N], tracking [rad]."""
        from oos_drake.multibody.mission_sim import METRIC_UNITS

        return dict(METRIC_UNITS)

    def signal_units(self) -> Mapping[str, str]:
        """Logged signals (attitude, rate, torques, bushing wrenches, modal coordinates)."""
        from oos_drake.multibody.mission_sim import SIGNAL_UNITS

        return dict(SIGNAL_UNITS)

    def metric_signals(self) -> Mapping[str, str]:
        """Metric -> the signal the report draws it on."""
        return dict(_METRIC_SIGNALS)

    def events(self) -> Mapping[str, float]:
        """``capture`` (255 s), ``docking`` (880 s), ``tilt`` (1100 s)."""
        return dict(self.simulation.events)

    def duration(self) -> float:
        """Mission length [s] (1500)."""
        return self.simulation.duration

    def run(self, case: RunCase) -> RunOutput:
        """Simulate the case's window; divergence raises :class:`SimulationDiverged`."""
        from oos_drake.multibody.mission_sim import MissionDiverged

        values = dict(case.values)
        on_start = None
        if self._worst is not None:
            fsw = self.simulation.handles.flight_software
            block = scaled_worst_block(fsw.design, self._worst, float(values.pop(WORST_SCALE)))

            def on_start(context):
                fsw.set_dynamic_perturbation(fsw.GetMyMutableContextFromRoot(context), block)

        try:
            result = self.simulation.run(
                values,
                seed=case.seed,
                start=case.window.start,
                end=case.window.end,
                perturbation_frequency_hz=case.frequency,
                on_start=on_start,
            )
        except MissionDiverged as exc:
            raise SimulationDiverged(str(exc)) from exc
        return RunOutput(metrics=dict(result.metrics), timeseries=result.timeseries)


def make_simulator(**options) -> DrakeMissionSimulator:
    """Factory for :class:`~oos_drake.campaign.simulator.SimulatorRecipe` (options as keywords).

    Raises
    ------
    ValueError
        No ``scenario`` option: the spec names none (its top-level ``scenario`` key).
    """
    if "scenario" not in options:
        raise ValueError(
            'drake-mission: the spec names no scenario; add the top-level key scenario = "paper" '
            "(or another scenario file)"
        )
    return DrakeMissionSimulator(**options)
