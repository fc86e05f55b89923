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
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields

from oos_drake.campaign.simulator import (
    Parameter,
    ParameterKind,
    RunCase,
    RunOutput,
    SimulationDiverged,
    check_options,
)

__all__ = ["DrakeMissionSimulator", "campaign_parameters", "make_simulator", "FACTORY_PATH"]

#: Import path of the factory (usable as ``[simulator] name`` in a spec).
FACTORY_PATH = "oos_drake.campaign.drake_simulator:make_simulator"

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
    **options
        Fields of :class:`oos_drake.multibody.mission.MissionOptions` (``control_rate``,
        ``log_rate``, ``controller``, ``integrator``, ...).
    """

    def __init__(self, scenario: str, **options):
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
        handles = make_mission_diagram(MissionOptions(**options), scenario=data, sdf_directory=sdf)
        self.simulation = MissionSimulation(handles=handles)
        self._parameters = campaign_parameters(self.simulation.parameters)

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

        try:
            result = self.simulation.run(
                dict(case.values),
                seed=case.seed,
                start=case.window.start,
                end=case.window.end,
                perturbation_frequency_hz=case.frequency,
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
