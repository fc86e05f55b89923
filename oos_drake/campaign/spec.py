"""Campaign specs: TOML files, validated before any run starts.

The specs shipped with the package (the top-level ``campaigns/``, linked into the package as
``oos_drake/campaign/specs``: ``demo``, ``demo_mu``, ``paper``, ``paper_mc``, ``paper_phases``,
``heavy_target``) can be named
without a path: ``oos campaign run demo``.

A spec names a simulator, disperses some of its parameters, chooses a sampler, a number of runs, a
seed and a mission window, and states the requirements each run is checked against::

    name = "demo"
    n_runs = 64
    random_seed = 20261121
    sampler = "latin-hypercube"              # or a [sampler] table (mu-guided)
    metrics = ["ape", "peak_torque"]        # default: every metric of the simulator
    run_timeout = 600.0                      # [s] per run (optional; local process pool)

    [simulator]
    name = "flexible-attitude"
    options = { control_rate = 10.0 }

    [window]                                 # default: the whole mission
    kind = "event"                           # "mission" | "event" | "critical" (mu-guided)
    event = "capture"
    before = 10.0                            # [s]
    after = 90.0                             # [s]

    [dispersions]
    J_hub = { distribution = "uniform", low = 300.0, high = 700.0 }

    [requirements]
    ape = { max = 0.0079, phases = ["capture-end"] }   # [rad], only after the capture
    peak_torque = { max = 2.0 }              # [N m]

    [timeseries]
    keep = "all"                             # "all" | "failed" | "none"
    signals = ["theta_hub", "torque_command"]

    [estimation]                             # optional
    target = 0.01                            # show P(violation) <= 1 %
    confidence = 0.95
    until_decided = true                     # add batches until the intervals decide
    max_runs = 2000                          # ... or this many runs are spent
    batch = 100

Uncertainty is declared once, by the scenario: every simulator parameter with a declared
uncertainty (:attr:`~oos_drake.campaign.simulator.Parameter.uncertainty`: an uncertain block's
``nominal +- percent``, a normalized LTI block's ``[-1, 1]``) is dispersed uniformly over it
without a line in ``[dispersions]``. A line there only overrides: a shape over the same range
(``{ distribution = "normal", mean = ..., std = ... }``: ``low``/``high`` default to the declared
range), a wider range (``widen = true``) or anything else (``override = true``); a range that
contradicts the scenario without saying so is refused, naming the parameter. Samplers:
``monte-carlo``, ``latin-hypercube``, ``phase-stratified`` (the whole mission, runs per phase in
proportion to its duration) and ``mu-guided``; ``[requirements]`` may name the mission phases
they apply to (``phases = ["capture-end"]``), and ``[estimation]`` sets the probability target.

Errors are one-line ``ValueError`` s naming the file and the key. :func:`load_spec` builds the
simulator once (in the calling process) to check parameter names, ranges, metrics and events.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import tomli_w

from oos_drake.campaign.distributions import (
    Distribution,
    Uniform,
    finite_number,
    parse_distribution,
)
from oos_drake.campaign.samplers import mission_phases
from oos_drake.campaign.simulator import (
    MissionWindow,
    Parameter,
    ParameterKind,
    SimulatorInfo,
    SimulatorRecipe,
    describe_simulator,
)
from oos_drake.campaign.worst_cases import WorstCaseRegion, read_worst_cases
from oos_drake.resources import package_path

SAMPLERS = ("monte-carlo", "latin-hypercube", "phase-stratified", "mu-guided")
WINDOW_KINDS = ("mission", "event", "critical")
KEEP_TIMESERIES = ("all", "failed", "none")
REGION_WEIGHTINGS = ("mu_upper", "uniform")


@dataclass(frozen=True)
class SamplerSpec:
    """How the dispersed values are drawn."""

    #: "monte-carlo" (i.i.d.), "latin-hypercube" (stratified marginals), "phase-stratified" (the
    #: whole mission's phases, runs in proportion to their durations) or "mu-guided"
    kind: str = "monte-carlo"
    #: path of the analysis' worst_cases.parquet (relative paths: to the spec file); required
    #: by mu-guided (its regions); for every sampler it gives the frequencies that realize LTI
    #: perturbation blocks (see samplers.make_plan). Also given by ``--worst-cases``.
    worst_cases: Path | None = None
    #: mu-guided: share of runs drawn from the nominal dispersions (bounds the weights by 1/share)
    defensive_fraction: float = 0.2
    #: mu-guided: proposal std around a worst case / dispersion width (support or 6 std) [-]
    spread: float = 0.1
    #: mu-guided: how runs are shared between regions: "mu_upper" (proportional) or "uniform"
    region_weighting: str = "mu_upper"
    #: mu-guided: smallest effective sample size of the plan's weights, as a share of the runs;
    #: the plan raises the defensive fraction (guided share / 1.5 per step) until it holds, so
    #: the importance-sampling estimate stays usable (0: no check; the report then rests on the
    #: defensive draws)
    min_ess_fraction: float = 0.5


@dataclass(frozen=True)
class WindowSpec:
    """Which part of the mission each run simulates."""

    #: "mission" (whole), "event" (around a named event), "critical" (around the run's region
    #: time; failure probabilities are then conditional on each region's window, see the report)
    kind: str = "mission"
    #: event name for kind "event" (one of the simulator's events)
    event: str | None = None
    #: simulated time before the event / critical time [s]
    before: float = 0.0
    #: simulated time after the event / critical time [s]
    after: float = 0.0

    def resolve(self, info: SimulatorInfo, centre: float | None = None) -> MissionWindow:
        """Concrete window; ``centre`` [s] is the region time for kind ``"critical"``."""
        if self.kind == "mission":
            return MissionWindow(0.0, info.duration, "mission")
        if self.kind == "event":
            centre, label = info.events[self.event], f"event:{self.event}"
        else:
            label = "critical"
        start = max(0.0, centre - self.before)
        end = min(info.duration, centre + self.after)
        return MissionWindow(start, end, label)


@dataclass(frozen=True)
class Requirement:
    """A bound a metric must satisfy for the run to pass."""

    #: metric name (one of the spec's metrics)
    metric: str
    #: upper bound [metric unit], or None
    max: float | None = None
    #: lower bound [metric unit], or None
    min: float | None = None
    #: unit of the metric (filled from the simulator)
    unit: str = ""
    #: mission phases during which the requirement applies (names of
    #: :func:`~oos_drake.campaign.samplers.mission_phases` without "phase:", e.g.
    #: "start-capture"); empty: the whole mission
    phases: tuple[str, ...] = ()
    #: the phases' time spans [s] (filled from the simulator's events, not part of the TOML)
    spans: tuple[tuple[float, float], ...] = field(default=(), compare=False, repr=False)

    def passes(self, value: float) -> bool:
        """True when ``value`` is finite and within the bounds."""
        if not math.isfinite(value):
            return False
        return (self.max is None or value <= self.max) and (self.min is None or value >= self.min)

    def applies(self, start: float, end: float) -> bool:
        """Whether a run simulating ``[start, end]`` [s] is checked: its window overlaps one of
        the requirement's phases (always, without phases)."""
        return not self.phases or any(start < b and end > a for a, b in self.spans)

    @property
    def label(self) -> str:
        """Human-readable bound, e.g. ``"ape <= 0.0079 rad"``."""
        parts = []
        if self.min is not None:
            parts.append(f"{self.metric} >= {self.min:g} {self.unit}")
        if self.max is not None:
            parts.append(f"{self.metric} <= {self.max:g} {self.unit}")
        return " and ".join(parts).strip()

    @property
    def column(self) -> str:
        """Pass/fail column name in ``runs.parquet``."""
        return f"pass_{self.metric}"


@dataclass(frozen=True)
class TimeseriesSpec:
    """Which time series are kept on disk."""

    #: "all" runs, only "failed" runs (status not ok or a requirement violated), or "none"
    keep: str = "all"
    #: signal names to keep (empty: every signal the simulator logs)
    signals: tuple[str, ...] = ()


@dataclass(frozen=True)
class EstimationSpec:
    """What the probability estimates must show (``[estimation]``)."""

    #: probability of violation to demonstrate: the report says whether the upper bound is below
    #: it and how many runs without violation would show it [-]
    target: float = 0.01
    #: confidence level of every interval [-]
    confidence: float = 0.95
    #: keep adding batches of runs until every requirement's interval decides against the target
    #: (upper bound below it, or lower bound above it) or max_runs are spent
    until_decided: bool = False
    #: budget of runs when until_decided (default: n_runs, i.e. no extension)
    max_runs: int | None = None
    #: runs per added batch when until_decided (default: n_runs)
    batch: int | None = None


@dataclass(frozen=True)
class CampaignSpec:
    """A validated campaign spec (see the module docstring for the TOML form)."""

    #: campaign name (used in report titles)
    name: str
    #: free text
    description: str
    #: number of runs (> 0)
    n_runs: int
    #: root seed: per-run seeds are SeedSequence(random_seed).spawn(n_runs)
    random_seed: int
    #: sampler settings
    sampler: SamplerSpec
    #: picklable simulator recipe (name + options)
    simulator: SimulatorRecipe
    #: simulated window
    window: WindowSpec
    #: dispersed parameter name -> distribution (physical units), in simulator parameter order
    dispersions: Mapping[str, Distribution]
    #: metrics recorded (simulator metric names)
    metrics: tuple[str, ...]
    #: requirements checked per run
    requirements: tuple[Requirement, ...]
    #: retained time series
    timeseries: TimeseriesSpec
    #: wall-clock limit of one run [s] (None: no limit); an overdue run is stopped, "failed"
    run_timeout: float | None = None
    #: probability target, confidence and run-until-decided budget
    estimation: EstimationSpec = EstimationSpec()
    #: simulator declarations gathered at load time (not part of the TOML)
    info: SimulatorInfo = field(compare=False, repr=False, default=None)
    #: the regions read from worst_cases (not part of the TOML)
    regions: tuple[WorstCaseRegion, ...] = field(compare=False, repr=False, default=())


def _keys(table_class) -> set[str]:
    """The keys of a spec table: the fields of the dataclass it becomes."""
    return {f.name for f in fields(table_class)}


#: Top-level keys: the fields of CampaignSpec that come from the TOML, and the scenario.
_TOP_KEYS = (_keys(CampaignSpec) - {"info", "regions"}) | {"scenario"}


def spec_scenario(value: Any, spec_path: str | Path) -> Path:
    """The scenario file a spec's ``scenario`` key names (None: the paper's).

    A path is resolved against the spec's folder; a bare name may also be a shipped scenario
    (``"heavy_target"``).
    """
    from oos_drake.scenario.data import scenario_path

    if value is None:
        return scenario_path(None)
    if not isinstance(value, str):
        raise _fail(f"spec {spec_path}", f"scenario = {value!r} must be a file name")
    relative = Path(spec_path).parent / value
    return relative.resolve() if relative.is_file() else scenario_path(value)


#: Keys of a dispersion that accept a law contradicting the scenario's declared uncertainty.
OVERRIDE_KEYS = ("widen", "override")


def _matches(law: Distribution, parameter: Parameter) -> str:
    """How a law's support compares with the declared uncertainty: "same", "wider" or "other"."""
    declared_low, declared_high = parameter.uncertainty
    low, high = law.support
    tolerance = 1e-6 * max(abs(declared_low), abs(declared_high), declared_high - declared_low)
    if abs(low - declared_low) <= tolerance and abs(high - declared_high) <= tolerance:
        return "same"
    if low <= declared_low + tolerance and high >= declared_high - tolerance:
        return "wider"
    return "other"


def declared_dispersion(where: str, table: Any, parameter: Parameter) -> Distribution:
    """A spec's dispersion of ``parameter``, checked against the uncertainty the scenario declares.

    For a parameter the scenario declares uncertain (:attr:`Parameter.uncertainty`), a law
    without ``low``/``high`` (uniform, log-uniform, normal) spans the declared range: the spec
    overrides the shape only. A law over the same range is accepted; a wider one needs
    ``widen = true``; any other (narrower, shifted, fixed, choice) needs ``override = true``.

    Raises
    ------
    ValueError
        One line naming the parameter: a law contradicting the declared range without the
        key that says so, an override key on a parameter the scenario does not declare
        uncertain, or any error of :func:`parse_distribution`.
    """
    if not isinstance(table, Mapping):
        return parse_distribution(where, table, parameter)
    table = dict(table)
    flags = {}
    for key in OVERRIDE_KEYS:
        if key in table:
            flags[key] = table.pop(key)
            if not isinstance(flags[key], bool):
                raise ValueError(f"{where}: {key} = {flags[key]!r} must be true or false")
    if parameter.uncertainty is None:
        if flags:
            raise ValueError(
                f"{where}: {', '.join(flags)} only apply to a parameter the scenario declares "
                "uncertain; this one has no declared uncertainty"
            )
        return parse_distribution(where, table, parameter)
    declared_low, declared_high = parameter.uncertainty
    if table.get("distribution") in ("uniform", "log-uniform", "normal"):
        table.setdefault("low", declared_low)
        table.setdefault("high", declared_high)
    law = parse_distribution(where, table, parameter)
    match = _matches(law, parameter)
    unit = parameter.unit
    declared = f"the scenario's uncertainty [{declared_low:.7g}, {declared_high:.7g}] {unit}"
    low, high = law.support
    if match == "wider" and not (flags.get("widen") or flags.get("override")):
        raise ValueError(
            f"{where}: [{low:.7g}, {high:.7g}] {unit} is wider than {declared}: say widen = true, "
            "or drop low/high to use the scenario's range"
        )
    if match == "other" and not flags.get("override"):
        raise ValueError(
            f"{where}: [{low:.7g}, {high:.7g}] {unit} contradicts {declared}: drop low/high "
            "to use the scenario's range, or say override = true"
        )
    return law


def _dispersion_entry(spec: CampaignSpec, name: str) -> dict[str, Any]:
    """A dispersion's TOML table, with ``override = true`` where it departs from the scenario."""
    entry = spec.dispersions[name].to_dict()
    parameter = spec.info.by_name[name]
    if parameter.uncertainty is not None and _matches(spec.dispersions[name], parameter) != "same":
        entry["override"] = True
    return entry


def _fail(where: str, message: str) -> ValueError:
    return ValueError(f"{where}: {message}")


def _check_keys(where: str, table: Any, allowed: set[str]) -> Mapping[str, Any]:
    if not isinstance(table, Mapping):
        raise _fail(where, "expected a table")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise _fail(
            where, f"unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}"
        )
    return table


def _positive_float(where: str, key: str, value: Any, allow_zero: bool = False) -> float:
    finite_number(where, key, value)
    if value < 0 or (value == 0 and not allow_zero):
        raise _fail(where, f"{key} = {value!r} must be {'>= 0' if allow_zero else '> 0'}")
    return float(value)


#: Folder of the campaign specs shipped with the package.
SPEC_DIRECTORY = package_path("oos_drake.campaign", "specs")


def packaged_spec_names() -> list[str]:
    """Names of the specs shipped in :data:`SPEC_DIRECTORY` (``["demo", ...]``)."""
    return sorted(p.stem for p in SPEC_DIRECTORY.glob("*.toml"))


def load_spec(path: str | Path, worst_cases: str | Path | None = None) -> CampaignSpec:
    """Read and validate a campaign spec file.

    ``path`` may also be the bare name of a shipped spec (``"demo"``, see
    :func:`packaged_spec_names`) when no such file exists in the working directory.
    ``worst_cases`` replaces the spec's ``[sampler] worst_cases`` (``--worst-cases``).

    Raises
    ------
    ValueError
        On any problem, with a one-line message naming the file and the key.
    """
    path = Path(path)
    if not path.is_file() and path.parent == Path():
        shipped = SPEC_DIRECTORY / path.with_suffix(".toml").name
        path = shipped if shipped.is_file() else path
    if not path.is_file():
        raise ValueError(
            f"spec {path}: file not found (shipped specs: {', '.join(packaged_spec_names())})"
        )
    return parse_spec(path.read_text(encoding="utf-8"), source=path, worst_cases=worst_cases)


def parse_spec(text: str, source: Path, worst_cases: str | Path | None = None) -> CampaignSpec:
    """Validate spec ``text``; relative paths are resolved against ``source``'s folder;
    ``worst_cases`` replaces the spec's ``[sampler] worst_cases``."""
    where = f"spec {source}"
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _fail(where, f"TOML syntax error: {exc}") from exc
    _check_keys(where, raw, _TOP_KEYS)
    for key in ("n_runs", "random_seed", "simulator"):
        if key not in raw:
            raise _fail(where, f"missing required key {key!r}")

    n_runs = raw["n_runs"]
    if isinstance(n_runs, bool) or not isinstance(n_runs, int) or n_runs <= 0:
        raise _fail(where, f"n_runs = {n_runs!r} must be a positive integer")
    seed = raw["random_seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise _fail(where, f"random_seed = {seed!r} must be a non-negative integer")
    run_timeout = raw.get("run_timeout")
    if run_timeout is not None:
        run_timeout = _positive_float(where, "run_timeout", run_timeout)
    name = raw.get("name", source.stem)
    description = raw.get("description", "")
    if not isinstance(name, str) or not isinstance(description, str):
        raise _fail(where, "name and description must be strings")

    # simulator -------------------------------------------------------------------------------
    simulator_table = _check_keys(f"{where}: [simulator]", raw["simulator"], {"name", "options"})
    simulator_name = simulator_table.get("name")
    if not isinstance(simulator_name, str):
        raise _fail(f"{where}: [simulator]", "missing name")
    options = simulator_table.get("options", {})
    if not isinstance(options, Mapping):
        raise _fail(f"{where}: [simulator]", "options must be a table")
    if "scenario" in raw:
        # the simulator builds its model from this scenario file (an absolute path, so the
        # resolved copy of the spec in the campaign folder names the same file)
        if "scenario" in options:
            raise _fail(where, "give the scenario once: top-level `scenario` or simulator option")
        try:
            scenario = spec_scenario(raw["scenario"], source)
        except ValueError as exc:
            raise _fail(where, str(exc)) from exc
        options = {**options, "scenario": str(scenario)}
    try:
        recipe = SimulatorRecipe.create(simulator_name, options)
    except ValueError as exc:
        raise _fail(f"{where}: [simulator]", str(exc)) from exc
    except TypeError as exc:
        raise _fail(f"{where}: [simulator]", f"options are not plain values: {exc}") from exc
    try:
        info = describe_simulator(recipe)
    except ValueError as exc:
        raise _fail(f"{where}: [simulator]", str(exc)) from exc
    parameters = info.by_name

    # sampler ---------------------------------------------------------------------------------
    sampler_raw = raw.get("sampler", "monte-carlo")
    if isinstance(sampler_raw, str):
        sampler_raw = {"kind": sampler_raw}
    sw = f"{where}: [sampler]"
    sampler_raw = _check_keys(sw, sampler_raw, _keys(SamplerSpec))
    kind = sampler_raw.get("kind", SamplerSpec.kind)
    if kind not in SAMPLERS:
        raise _fail(sw, f"unknown sampler {kind!r}; use one of {', '.join(SAMPLERS)}")
    if kind != "mu-guided":
        extra = sorted(set(sampler_raw) - {"kind", "worst_cases"})
        if extra:
            raise _fail(sw, f"{', '.join(extra)} only apply to the mu-guided sampler")
    worst_cases_path = None
    regions: tuple[WorstCaseRegion, ...] = ()
    defensive = sampler_raw.get("defensive_fraction", SamplerSpec.defensive_fraction)
    spread = sampler_raw.get("spread", SamplerSpec.spread)
    weighting = sampler_raw.get("region_weighting", SamplerSpec.region_weighting)
    if worst_cases is not None:
        worst_cases_path = Path(worst_cases).resolve()
    elif "worst_cases" in sampler_raw:
        if not isinstance(sampler_raw["worst_cases"], str):
            raise _fail(sw, 'worst_cases must be a path: "path/to/worst_cases.parquet"')
        worst_cases_path = Path(sampler_raw["worst_cases"])
        if not worst_cases_path.is_absolute():
            worst_cases_path = (source.parent / worst_cases_path).resolve()
    if worst_cases_path is not None:
        if not worst_cases_path.is_file():
            raise _fail(
                sw, f"worst_cases file {worst_cases_path} not found (written by oos analyze)"
            )
        regions = read_worst_cases(worst_cases_path, info.parameters)
    elif kind == "mu-guided":
        raise _fail(
            sw,
            "mu-guided needs the analysis' worst_cases.parquet (written by oos analyze): "
            "give --worst-cases FILE or worst_cases = FILE",
        )
    if kind == "mu-guided":
        defensive = _positive_float(sw, "defensive_fraction", defensive)
        if not defensive < 1:
            raise _fail(sw, f"defensive_fraction = {defensive} must be in (0, 1)")
        spread = _positive_float(sw, "spread", spread)
        if weighting not in REGION_WEIGHTINGS:
            raise _fail(sw, f"region_weighting {weighting!r} not in {', '.join(REGION_WEIGHTINGS)}")
    min_ess = sampler_raw.get("min_ess_fraction", SamplerSpec.min_ess_fraction)
    min_ess = _positive_float(sw, "min_ess_fraction", min_ess, allow_zero=True)
    if not min_ess < 1:
        raise _fail(sw, f"min_ess_fraction = {min_ess} must be in [0, 1)")
    sampler = SamplerSpec(
        kind, worst_cases_path, float(defensive), float(spread), weighting, float(min_ess)
    )

    # window ----------------------------------------------------------------------------------
    ww = f"{where}: [window]"
    window_raw = _check_keys(ww, raw.get("window", {"kind": "mission"}), _keys(WindowSpec))
    window_kind = window_raw.get("kind", "mission")
    if window_kind not in WINDOW_KINDS:
        raise _fail(
            ww, f"unknown window kind {window_kind!r}; use one of {', '.join(WINDOW_KINDS)}"
        )
    if window_kind == "mission":
        extra = sorted(set(window_raw) - {"kind"})
        if extra:
            raise _fail(ww, f"{', '.join(extra)} do not apply to the whole-mission window")
        window = WindowSpec("mission")
    else:
        before = _positive_float(ww, "before", window_raw.get("before", 0.0), allow_zero=True)
        after = _positive_float(ww, "after", window_raw.get("after", 0.0), allow_zero=True)
        if before + after <= 0:
            raise _fail(ww, "before + after must be > 0 s")
        event = window_raw.get("event")
        if window_kind == "event":
            if event not in info.events:
                raise _fail(ww, f"unknown event {event!r}; known: {', '.join(info.events)}")
        else:
            if kind != "mu-guided":
                raise _fail(ww, 'kind = "critical" needs the mu-guided sampler')
            if event is not None:
                raise _fail(ww, 'event does not apply to kind = "critical"')
        window = WindowSpec(window_kind, event, before, after)
    if kind == "phase-stratified" and window.kind != "mission":
        raise _fail(ww, "the phase-stratified sampler simulates every phase: no [window]")

    # dispersions -----------------------------------------------------------------------------
    dispersions_raw = raw.get("dispersions", {})
    if not isinstance(dispersions_raw, Mapping):
        raise _fail(where, "[dispersions] must be a table")
    for parameter_name in dispersions_raw:
        if parameter_name not in parameters:
            raise _fail(
                f"{where}: dispersions.{parameter_name}",
                f"unknown parameter; known: {', '.join(parameters)}",
            )
    dispersions = {}
    for p in info.parameters:
        if p.name in dispersions_raw:
            entry = dispersions_raw[p.name]
            dispersions[p.name] = declared_dispersion(f"{where}: dispersions.{p.name}", entry, p)
        elif p.uncertainty is not None and (p.kind != ParameterKind.LTI or regions):
            # the scenario's uncertainty, declared once (an LTI block needs the critical
            # frequency of a worst-case region to be realized: dispersed only with regions)
            dispersions[p.name] = Uniform(*p.uncertainty)
    if kind == "mu-guided":
        guided = {n for r in regions for n in r.perturbation}
        if not guided & set(dispersions):
            raise _fail(sw, "no worst-case block of the worst_cases file is dispersed")

    # metrics and requirements ----------------------------------------------------------------
    metrics = raw.get("metrics", list(info.metric_units))
    if not isinstance(metrics, list) or not metrics or not all(isinstance(m, str) for m in metrics):
        raise _fail(where, "metrics must be a non-empty list of metric names")
    for metric in metrics:
        if metric not in info.metric_units:
            raise _fail(where, f"unknown metric {metric!r}; known: {', '.join(info.metric_units)}")
    requirements = []
    requirements_raw = raw.get("requirements", {})
    if not isinstance(requirements_raw, Mapping):
        raise _fail(where, "[requirements] must be a table")
    for metric, bounds in requirements_raw.items():
        rw = f"{where}: requirements.{metric}"
        if metric not in metrics:
            raise _fail(rw, f"not one of the recorded metrics {', '.join(metrics)}")
        bounds = dict(_check_keys(rw, bounds, {"max", "min", "phases"}))
        phases = bounds.pop("phases", [])
        if not bounds:
            raise _fail(rw, "give max and/or min")
        known = {w.label.removeprefix("phase:"): w for w in mission_phases(info)}
        if not isinstance(phases, list) or not all(isinstance(p, str) for p in phases):
            raise _fail(rw, "phases must be a list of phase names")
        for phase in phases:
            if phase not in known:
                raise _fail(rw, f"unknown phase {phase!r}; known: {', '.join(known)}")
        spans = tuple((known[p].start, known[p].end) for p in phases)
        values = {key: finite_number(rw, key, value) for key, value in bounds.items()}
        if "max" in values and "min" in values and values["min"] > values["max"]:
            raise _fail(rw, f"min {values['min']} exceeds max {values['max']}")
        requirements.append(
            Requirement(
                metric,
                values.get("max"),
                values.get("min"),
                info.metric_units[metric],
                tuple(phases),
                spans,
            )
        )

    # estimation ------------------------------------------------------------------------------
    ew = f"{where}: [estimation]"
    est_raw = _check_keys(ew, raw.get("estimation", {}), _keys(EstimationSpec))
    target = finite_number(ew, "target", est_raw.get("target", EstimationSpec.target))
    confidence = finite_number(
        ew, "confidence", est_raw.get("confidence", EstimationSpec.confidence)
    )
    for key, value in (("target", target), ("confidence", confidence)):
        if not 0 < value < 1:
            raise _fail(ew, f"{key} = {value:g} must be in (0, 1)")
    until_decided = est_raw.get("until_decided", False)
    if not isinstance(until_decided, bool):
        raise _fail(ew, f"until_decided = {until_decided!r} must be true or false")
    counts = {}
    for key in ("max_runs", "batch"):
        value = est_raw.get(key, n_runs)
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise _fail(ew, f"{key} = {value!r} must be a positive integer")
        counts[key] = value
    if counts["max_runs"] < n_runs:
        raise _fail(ew, f"max_runs = {counts['max_runs']} is below n_runs = {n_runs}")
    estimation = EstimationSpec(target, confidence, until_decided, **counts)

    # time series -----------------------------------------------------------------------------
    tw = f"{where}: [timeseries]"
    ts_raw = _check_keys(tw, raw.get("timeseries", {}), _keys(TimeseriesSpec))
    keep = ts_raw.get("keep", TimeseriesSpec.keep)
    if keep not in KEEP_TIMESERIES:
        raise _fail(tw, f"keep = {keep!r} not in {', '.join(KEEP_TIMESERIES)}")
    signals = ts_raw.get("signals", [])
    if not isinstance(signals, list) or not all(isinstance(s, str) for s in signals):
        raise _fail(tw, "signals must be a list of signal names")
    for signal in signals:
        if signal not in info.signal_units:
            raise _fail(tw, f"unknown signal {signal!r}; known: {', '.join(info.signal_units)}")

    return CampaignSpec(
        name=name,
        description=description,
        n_runs=int(n_runs),
        random_seed=int(seed),
        sampler=sampler,
        simulator=recipe,
        window=window,
        dispersions=dispersions,
        metrics=tuple(metrics),
        requirements=tuple(requirements),
        timeseries=TimeseriesSpec(keep, tuple(signals)),
        run_timeout=run_timeout,
        estimation=estimation,
        info=info,
        regions=regions,
    )


# --- writing the resolved spec -----------------------------------------------------------------
def spec_to_toml(spec: CampaignSpec, worst_cases_name: str | None = None) -> str:
    """The resolved spec as TOML (every default written out); reading it back gives ``spec``.

    Parameters
    ----------
    worst_cases_name : str, optional
        Path written for ``worst_cases`` (the campaign directory's copy).
    """
    document: dict[str, Any] = {
        "name": spec.name,
        "description": spec.description,
        "n_runs": spec.n_runs,
        "random_seed": spec.random_seed,
        "metrics": list(spec.metrics),
    }
    if spec.run_timeout:
        document["run_timeout"] = spec.run_timeout
    sampler: dict[str, Any] = {"kind": spec.sampler.kind}
    if spec.sampler.worst_cases is not None:
        sampler["worst_cases"] = worst_cases_name or str(spec.sampler.worst_cases)
    if spec.sampler.kind == "mu-guided":
        sampler |= {
            "defensive_fraction": spec.sampler.defensive_fraction,
            "spread": spec.sampler.spread,
            "region_weighting": spec.sampler.region_weighting,
            "min_ess_fraction": spec.sampler.min_ess_fraction,
        }
    window: dict[str, Any] = {"kind": spec.window.kind}
    if spec.window.kind != "mission":
        if spec.window.event is not None:
            window["event"] = spec.window.event
        window |= {"before": spec.window.before, "after": spec.window.after}
    document |= {
        "sampler": sampler,
        "simulator": {"name": spec.simulator.name, "options": spec.simulator.option_dict},
        "window": window,
        "dispersions": {name: _dispersion_entry(spec, name) for name in spec.dispersions},
        "requirements": {
            r.metric: {k: getattr(r, k) for k in ("max", "min") if getattr(r, k) is not None}
            | ({"phases": list(r.phases)} if r.phases else {})
            for r in spec.requirements
        },
        "timeseries": {"keep": spec.timeseries.keep, "signals": list(spec.timeseries.signals)},
        "estimation": {k: v for k, v in vars(spec.estimation).items() if v is not None},
    }
    header = "# Resolved campaign spec written by oos campaign run (every default filled in).\n"
    return header + tomli_w.dumps(document)
