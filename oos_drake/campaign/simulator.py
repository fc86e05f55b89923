"""The seam between the campaign machinery and a simulator.

A campaign never holds a simulator object across processes: plants, Drake diagrams and contexts are
not picklable. It holds a :class:`SimulatorRecipe` (a registered name plus plain options), and each
worker process builds the simulator once from the recipe (:func:`build_simulator`, cached per
process) and calls :meth:`Simulator.run` for every case it receives.

A simulator declares

- the dispersible parameters (:class:`Parameter`: name, unit, nominal value, physical range, kind),
- the metrics it returns and the signals it logs (name -> unit),
- the named mission events (name -> time [s]) that a campaign window can be centred on,
- the mission duration [s],

and runs one :class:`RunCase` (physical parameter values, run seed, mission window) into a
:class:`RunOutput` (metrics and an optional time-series table). A run that leaves the domain of
validity raises :class:`SimulationDiverged`; the runner records it as status ``"diverged"``.

Registering a simulator (the Drake mission simulator does this from its own package)::

    from oos_drake.campaign.simulator import register_simulator
    register_simulator("drake-mission", "oos_drake.campaign.drake_simulator:make_simulator")

The factory is named by an import path (``"module:function"``) so that a worker process that did
not import the registering module still finds it; a spec may also give the import path directly as
the simulator name.
"""

from __future__ import annotations

import enum
import importlib
import json
import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import pandas as pd


class ParameterKind(enum.StrEnum):
    """What a dispersible parameter is in the model (reported in tables, used by the samplers)."""

    #: a named real uncertain block of the LFR (mass, inertia, modal frequency, ...)
    REAL_BLOCK = "real_block"
    #: a docking / joint stiffness or damping coefficient
    STIFFNESS = "stiffness"
    #: an initial attitude or rate error
    INITIAL_CONDITION = "initial_condition"
    #: an integer seed for a noise source (dispersed with ``choice`` or ``fixed``)
    SEED = "seed"
    #: a scalar that scales a stable LTI perturbation block (Delta_add, Delta_mul)
    LTI = "lti"
    #: a parameter of the disturbance and noise inputs (a sinusoid's amplitude, frequency and
    #: direction, the scale of the random sequences)
    DISTURBANCE = "disturbance"

    @classmethod
    def of_quantity(cls, quantity: str) -> ParameterKind:
        """The kind of a parameter that stands for ``quantity``.

        ``quantity`` is an uncertain block's (:data:`oos_drake.lfr.blocks.QUANTITIES`) or
        ``"initial condition"`` / ``"seed"`` / ``"disturbance"``.
        """
        if quantity in ("stiffness", "damping"):
            return cls.STIFFNESS
        if quantity.endswith("dynamics"):
            return cls.LTI
        if quantity == "initial condition":
            return cls.INITIAL_CONDITION
        if quantity == "seed":
            return cls.SEED
        if quantity == "disturbance":
            return cls.DISTURBANCE
        return cls.REAL_BLOCK


@dataclass(frozen=True)
class Parameter:
    """One dispersible parameter of a simulator.

    Attributes
    ----------
    name : str
        Name used in specs and table columns; the uncertain block's name where there is one.
    unit : str
        Physical unit of the value (``"kg m^2"``, ``"Hz"``, ``"N m/rad"``, ``"rad"``, ``"-"``).
    nominal : float
        Value used when the campaign does not disperse the parameter [unit].
    lower, upper : float
        Physical range a dispersion must stay inside [unit]; the model is valid there.
    kind : ParameterKind
        What the parameter is (real block, stiffness, initial condition, seed, LTI).
    description : str
        One line for tables and ``--help``.
    uncertainty : tuple of float, optional
        The range the scenario declares uncertain (``nominal +- percent``, a normalized LTI
        block's ``[-1, 1]``) [unit]; None when the scenario declares none. It is the campaign's
        default dispersion (uniform over it): a spec only overrides its shape, widens it
        (``widen = true``) or replaces it (``override = true``).
    """

    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    kind: ParameterKind = ParameterKind.REAL_BLOCK
    description: str = ""
    uncertainty: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not (self.lower <= self.nominal <= self.upper):
            raise ValueError(
                f"parameter {self.name!r}: nominal {self.nominal} outside its range "
                f"[{self.lower}, {self.upper}]"
            )
        if self.uncertainty is not None:
            low, high = self.uncertainty
            if not (self.lower <= low < high <= self.upper):
                raise ValueError(
                    f"parameter {self.name!r}: declared uncertainty [{low}, {high}] outside its "
                    f"range [{self.lower}, {self.upper}]"
                )

    @property
    def column(self) -> str:
        """Table column name with the unit, e.g. ``"J_hub [kg m^2]"``."""
        return f"{self.name} [{self.unit}]"

    def clip(self, value: float) -> float | None:
        """``value`` [unit] clipped to the range, or None when it lies outside.

        A value written in decimal (2.552) may miss a computed bound (2.32 * 1.1) by round-off:
        within 1e-9 of the range's scale it counts as inside.
        """
        lo, hi = self.lower, self.upper
        slack = 1e-9 * max(abs(lo), abs(hi), hi - lo)
        return min(max(value, lo), hi) if lo - slack <= value <= hi + slack else None


@dataclass(frozen=True)
class MissionWindow:
    """The simulated part of the mission.

    Attributes
    ----------
    start, end : float
        Simulated time span [s] on the mission clock; the simulator starts from its (dispersed)
        initial conditions at ``start``.
    label : str
        Where the window comes from (``"mission"``, ``"event:capture"``, ``"region:3"``).
    """

    start: float
    end: float
    label: str = "mission"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and math.isfinite(self.end) and self.end > self.start):
            raise ValueError(f"mission window: end {self.end} s must exceed start {self.start} s")


@dataclass(frozen=True)
class RunCase:
    """Everything one run needs; reproducing a run means calling ``run`` on the same case.

    Attributes
    ----------
    run_id : int
        Index of the run in the campaign plan.
    seed : int
        Seed of the run's own random streams (sensor noise, ...), from ``SeedSequence.spawn``.
    values : Mapping[str, float]
        Physical value of every parameter of the simulator (dispersed or nominal) [unit].
    window : MissionWindow
        Simulated time span.
    frequency : float
        Critical frequency [Hz] of the analysis region the run explores (``frequency [Hz]`` of
        ``worst_cases.parquet``; may be ``inf``), NaN when none: where a simulator realizes its
        LTI perturbation blocks (parameters of kind ``lti``). See
        :func:`oos_drake.campaign.samplers.make_plan`.
    """

    run_id: int
    seed: int
    values: Mapping[str, float]
    window: MissionWindow
    frequency: float = math.nan


@dataclass(frozen=True)
class RunOutput:
    """What a simulator returns for one run.

    Attributes
    ----------
    metrics : Mapping[str, float]
        Scalar metrics, keyed as in :meth:`Simulator.metric_units` [their units].
    timeseries : pandas.DataFrame or None
        Logged signals, one row per log instant, columns named ``"signal [unit]"`` with a
        ``"time [s]"`` column; ``None`` when the simulator logs nothing.
    """

    metrics: Mapping[str, float]
    timeseries: pd.DataFrame | None = None


class SimulationDiverged(RuntimeError):
    """A run left the model's domain (state blew up, attitude lost): recorded as ``"diverged"``."""


@runtime_checkable
class Simulator(Protocol):
    """What the campaign runner needs from a simulator (built once per worker process)."""

    def parameters(self) -> tuple[Parameter, ...]:
        """Dispersible parameters, in a fixed order."""

    def metric_units(self) -> Mapping[str, str]:
        """Metric name -> unit of every metric ``run`` returns."""

    def signal_units(self) -> Mapping[str, str]:
        """Logged signal name -> unit (time-series columns are ``"name [unit]"``)."""

    def events(self) -> Mapping[str, float]:
        """Named mission events -> time [s] (windows can be centred on them)."""

    def duration(self) -> float:
        """Whole mission length [s]; the mission window is ``[0, duration]``."""

    def run(self, case: RunCase) -> RunOutput:
        """Simulate one case; raise :class:`SimulationDiverged` when the run diverges.

        The result must depend on ``case`` only (reset the context/state at the start of every
        run, draw every random number from ``case.seed``): that is what makes ``rerun``
        bit-identical and lets any worker run any case.
        """


@dataclass(frozen=True)
class SimulatorRecipe:
    """Picklable description from which a worker builds a simulator.

    Attributes
    ----------
    name : str
        Registered simulator name (:func:`register_simulator`) or an import path
        ``"package.module:factory"``.
    factory : str
        Import path of the factory, resolved from the registry when the recipe is created, so a
        freshly spawned worker that never ran the registering code still finds it.
    options : str
        Factory keyword options as canonical JSON (a string keeps the recipe hashable and frozen);
        build with :meth:`create`.
    """

    name: str
    factory: str
    options: str = "{}"

    @classmethod
    def create(cls, name: str, options: Mapping[str, Any] | None = None) -> SimulatorRecipe:
        """Recipe from a name and a plain option mapping (JSON-serializable values).

        Raises
        ------
        ValueError
            Unknown simulator name.
        """
        factory = _REGISTRY.get(name, name if ":" in name else None)
        if factory is None:
            raise ValueError(
                f"unknown simulator {name!r}; known: {', '.join(sorted(_REGISTRY))} "
                "(or give 'module:factory')"
            )
        return cls(
            name=name, factory=factory, options=json.dumps(dict(options or {}), sort_keys=True)
        )

    @property
    def option_dict(self) -> dict[str, Any]:
        """The options as a fresh dict."""
        return json.loads(self.options)


#: Built-in simulators: name -> "module:factory". Other packages add theirs with register_simulator.
_REGISTRY: dict[str, str] = {
    "flexible-attitude": "oos_drake.campaign.attitude_sim:make_simulator",
    "drake-mission": "oos_drake.campaign.drake_simulator:make_simulator",
}


def register_simulator(name: str, factory_path: str) -> None:
    """Register ``name`` -> ``"module:factory"`` (the factory takes the options as keywords)."""
    if ":" not in factory_path:
        raise ValueError(f"simulator {name!r}: factory path {factory_path!r} is not 'module:func'")
    _REGISTRY[name] = factory_path


def check_options(simulator: str, options: Mapping[str, Any], known: set[str]) -> None:
    """A factory's check of its options: ``ValueError`` naming the unknown ones and ``known``."""
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(
            f"{simulator}: unknown option(s) {', '.join(unknown)}; known: "
            f"{', '.join(sorted(known))}"
        )


#: Per-thread cache of built simulators: a simulator (a Drake context, say) is never shared by
#: two threads, and a worker process with one thread builds each recipe exactly once.
_BUILT = threading.local()


def build_simulator(recipe: SimulatorRecipe) -> Simulator:
    """The simulator a recipe describes, built once per worker thread and then reused.

    Raises
    ------
    ValueError
        Unknown simulator name, or options the factory rejects.
    """
    cache = getattr(_BUILT, "simulators", None)
    if cache is None:
        cache = _BUILT.simulators = {}
    if recipe not in cache:
        cache[recipe] = _build(recipe)
        _BUILT.builds = getattr(_BUILT, "builds", 0) + 1
    return cache[recipe]


def simulator_builds() -> int:
    """How many simulators this thread has built (1 per recipe when the cache works)."""
    return getattr(_BUILT, "builds", 0)


def _build(recipe: SimulatorRecipe) -> Simulator:
    module_name, _, attr = recipe.factory.partition(":")
    try:
        factory = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(
            f"simulator {recipe.name!r}: cannot import factory {recipe.factory!r}: {exc}"
        ) from exc
    try:
        simulator = factory(**recipe.option_dict)
    except TypeError as exc:
        raise ValueError(f"simulator {recipe.name!r}: bad options: {exc}") from exc
    if not isinstance(simulator, Simulator):
        raise ValueError(f"simulator {recipe.name!r}: factory did not return a Simulator")
    return simulator


@dataclass(frozen=True)
class SimulatorInfo:
    """Declarations of a simulator, gathered once in the driver process (picklable).

    Attributes
    ----------
    parameters : tuple of Parameter
        Dispersible parameters.
    metric_units : dict
        Metric name -> unit.
    signal_units : dict
        Logged signal name -> unit.
    metric_signals : dict
        Metric -> the signal it bounds (optional ``metric_signals()`` of the simulator; the report
        draws the requirement on that signal's plot).
    events : dict
        Event name -> mission time [s].
    duration : float
        Mission length [s].
    """

    parameters: tuple[Parameter, ...]
    metric_units: Mapping[str, str] = field(default_factory=dict)
    signal_units: Mapping[str, str] = field(default_factory=dict)
    metric_signals: Mapping[str, str] = field(default_factory=dict)
    events: Mapping[str, float] = field(default_factory=dict)
    duration: float = 0.0

    @property
    def by_name(self) -> dict[str, Parameter]:
        """Parameter name -> parameter."""
        return {p.name: p for p in self.parameters}


def describe_simulator(recipe: SimulatorRecipe) -> SimulatorInfo:
    """Build the simulator in this process and collect its declarations."""
    simulator = build_simulator(recipe)
    return SimulatorInfo(
        parameters=tuple(simulator.parameters()),
        metric_units=dict(simulator.metric_units()),
        signal_units=dict(simulator.signal_units()),
        metric_signals=dict(getattr(simulator, "metric_signals", dict)()),
        events=dict(simulator.events()),
        duration=float(simulator.duration()),
    )
