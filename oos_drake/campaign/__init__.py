"""oos_drake.campaign: Monte Carlo campaigns, from a TOML spec to pandas tables and figures.

Flow: ``spec`` (validated TOML) -> ``samplers`` (plan: values, seeds, weights, windows) ->
``executors`` (in-process, process pool, Dask) running a ``simulator`` per worker -> ``store``
(crash-safe per-run Parquet files, ``runs.parquet``) -> ``estimators`` (P(violation) with
intervals that hold: Clopper-Pearson, stratified by phase, defensive importance sampling) ->
``report`` (tables, figures). Falsification (``falsify``: an optimizer over the dispersion box
looking for the worst nonlinear run) uses the same simulators and executors but keeps its runs
apart from the estimation runs.

Plugging in a simulator (e.g. the Drake mission): implement the :class:`Simulator` protocol,
expose a factory ``make_simulator(**options)``, and register it::

    register_simulator("drake-mission", "oos_drake.campaign.drake_simulator:make_simulator")

(or name the factory path directly in the spec: ``[simulator] name = "pkg.module:factory"``),
and check it in its tests with ``tests/campaign/simulator_contract.py:check_simulator``
(declarations, metrics, time-series columns, reproducibility for a given seed).
Dispersions are keyed by the parameter (uncertain block) names the simulator declares, so a
misspelled or absent block is an error before any run, not a silently ignored dispersion.
"""

from oos_drake.campaign.simulator import (
    MissionWindow,
    Parameter,
    ParameterKind,
    RunCase,
    RunOutput,
    SimulationDiverged,
    Simulator,
    SimulatorRecipe,
    build_simulator,
    register_simulator,
)

__all__ = [
    "MissionWindow",
    "Parameter",
    "ParameterKind",
    "RunCase",
    "RunOutput",
    "SimulationDiverged",
    "Simulator",
    "SimulatorRecipe",
    "build_simulator",
    "register_simulator",
]
