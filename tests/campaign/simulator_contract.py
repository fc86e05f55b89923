"""The simulator protocol check of the campaign tests: what the runner relies on."""

from __future__ import annotations

import math

from oos_drake.campaign.simulator import (
    MissionWindow,
    Parameter,
    RunCase,
    RunOutput,
    Simulator,
)


def check_simulator(
    simulator: Simulator, window: MissionWindow | None = None, seed: int = 1
) -> RunOutput:
    """Check that a simulator honours the protocol the campaign runner relies on.

    For a new simulator (the Drake mission, say), call this in its tests. It checks the
    declarations (unique parameter names, units, nominal values inside their ranges, events
    inside the mission), runs the nominal case twice with the same seed and once with another,
    and checks the outputs: every declared metric present and finite, time-series columns
    ``"name [unit]"`` matching the declared signals plus ``"time [s]"``, and bit-identical metrics
    for the same seed (what ``oos campaign rerun`` needs).

    Parameters
    ----------
    simulator : Simulator
        The simulator under test.
    window : MissionWindow, optional
        Window to simulate (default: the whole mission).
    seed : int
        Run seed of the nominal case.

    Returns
    -------
    RunOutput
        The nominal run's output.

    Raises
    ------
    ValueError
        The first violated expectation, in one line.
    """
    parameters = tuple(simulator.parameters())
    names = [p.name for p in parameters]
    if len(set(names)) != len(names):
        raise ValueError(f"simulator: duplicated parameter names in {names}")
    for parameter in parameters:
        if not isinstance(parameter, Parameter) or not parameter.unit:
            raise ValueError(f"simulator: parameter {parameter!r} needs a Parameter with a unit")
    duration = float(simulator.duration())
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"simulator: duration {duration} s must be positive")
    for event, time in simulator.events().items():
        if not 0 <= time <= duration:
            raise ValueError(f"simulator: event {event!r} at {time} s outside [0, {duration}] s")
    window = window or MissionWindow(0.0, duration)
    values = {p.name: p.nominal for p in parameters}
    output = simulator.run(RunCase(0, seed, values, window))
    metrics = dict(output.metrics)
    declared = dict(simulator.metric_units())
    if set(metrics) != set(declared):
        raise ValueError(
            f"simulator: metrics {sorted(metrics)} differ from declared {sorted(declared)}"
        )
    for name, value in metrics.items():
        if not math.isfinite(float(value)):
            raise ValueError(f"simulator: nominal metric {name} = {value} is not finite")
    if output.timeseries is not None:
        expected = {"time [s]"} | {f"{s} [{u}]" for s, u in simulator.signal_units().items()}
        if set(output.timeseries.columns) != expected:
            raise ValueError(
                f"simulator: time-series columns {sorted(output.timeseries.columns)} differ from "
                f"{sorted(expected)}"
            )
    again = simulator.run(RunCase(0, seed, values, window))
    if dict(again.metrics) != metrics:
        raise ValueError("simulator: two runs of the same case and seed differ (not reproducible)")
    return output
