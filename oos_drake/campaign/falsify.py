r"""Falsification: search the dispersion box for the nonlinear run that comes closest to (or
beyond) a requirement.

Estimation runs (``oos campaign run``) draw from the dispersions to estimate probabilities;
falsification runs (``oos campaign falsify``) are chosen by an optimizer to find worst cases.
The two are kept apart: a falsification writes its own folder and its own table
(``falsification.parquet``), never a campaign's ``runs.parquet``.

The search maximizes the requirement ratio of a run,

.. math::

    r(x) = \max_j \frac{m_j(x)}{\bar m_j}

over the max-requirements ``m_j <= \bar m_j`` of the spec (``r > 1``: violated; a run that
diverges or fails counts as :data:`FAILED_RATIO`), over the box of every dispersed parameter:
uniform and log-uniform laws span their support (log-uniform in log coordinates), a normal law
``mean +- 3 std`` within its support, a choice law its values (snapped to the nearest). Initial
conditions and disturbance parameters are searched when the spec disperses them. Every run uses
the same seed (common random numbers: the search compares parameters, not noise realizations);
the window is the spec's (for a ``critical`` window: the window and frequency of the analysis'
peak region, the largest ``mu_upper``).

Optimizer: scipy's differential evolution (``best1bin``, deferred updating: one generation is one
batch of runs on the campaign's executor, process pool or Dask) over the unit cube of the box
widened by :data:`EDGE_MARGIN` and clipped back (faces and vertices are reachable). Its first
generation holds the analysis' worst cases (the regions' perturbations, other parameters at their
nominal values, all clipped to the box) and the nominal point, filled up by a Latin hypercube.

Local search (``search="local"``, ``oos campaign falsify --search local``): differential evolution
over some 37 dimensions does not climb past its seeds in a few generations (heavy_target: 90
runs, generation bests 1.168, 1.154, 1.142, the first the seed). The local search climbs from
the best starting point instead: its first batch is the starting points alone (the worst cases
and the nominal point, no fill-up), then projected gradient ascent in the unit cube
(:func:`local_search`): one batch of central differences, two runs a coordinate (step
:data:`LOCAL_STEP`, one-sided of second order on a face: a forward difference reads the
curvature as a slope where the start is near a maximum, as the analysis' worst input is), then
one batch of a line search along the gradient divided by each coordinate's curvature (a
diagonal Newton direction; the curvature at least the largest over :data:`CURVATURE_SPAN`),
normalized, at :data:`LINE_STEPS` times a trust radius (first :data:`LOCAL_RADIUS`; doubled
when the longest step was best, halved when the shortest was, quartered without progress, the
direction then kept). The best point of the two batches becomes the centre when it improves on
it. A gradient costs two runs per dimension: the search pays for it only on a smooth objective
(common random numbers make it deterministic) started near a worst case (from the regions alone
differential evolution explores better: docs/ANALYSIS-RESULTS.md); a failed run,
:data:`FAILED_RATIO`, is a finding and becomes the centre like any other.

Started from the worst input: given ``oos confirm``'s performance table (``--confirm``), whose
rows store the analysis' worst cases as simulator values (``worst values``: the worst
perturbation, and the worst input as a sinusoid of unit amplitude, its frequency and complex
direction, see :mod:`oos_drake.analysis.performance_twin`), the first generation starts with
them (largest certified lower bound first, before the regions' perturbations), and the search
box gains the sinusoid's parameters the spec does not disperse: its frequency within a factor
:data:`SINE_FREQUENCY_FACTOR` of the worst case's (log coordinates) and its direction (real and
imaginary parts in ``[-1, 1]``, normalized by the simulator); its amplitude and the scale of
the random noise stay at the worst case's (1 and 0: the analysis' unit input alone) unless the
spec disperses them. The LTI blocks are then realized at the worst case's frequency and a
``critical`` window is centred on its time. On a Drake mission (the paper's or a tree's) the
first worst case's complex blocks are realized with their phase
(:func:`realize_worst_perturbation`: the mission's own realization, a signed scalar times an
all-pass, loses it), scaled by the searched ``worst_scale`` in [0, 1]; the scalar LTI
parameters it replaces stay at 0.
``--window START,END`` replaces the spec's window (a sinusoid needs time to build up its
steady state).

Resume: every evaluated point is written atomically as soon as its run finishes
(``points/point_NNNNNN.parquet``). The search is deterministic given its seed and the values it
sees, so a resumed search replays the optimizer, takes the recorded values of the points already
run (checking that each is the same point) and runs only the new ones: no finished run is lost, and
a larger ``--budget`` continues the same search.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from tqdm import tqdm

from oos_drake.campaign.distributions import Choice, Fixed, LogUniform, TruncatedNormal
from oos_drake.campaign.drake_simulator import FACTORY_PATH, WORST_SCALE
from oos_drake.campaign.executors import make_executor
from oos_drake.campaign.runner import metric_column, resolve_spec
from oos_drake.campaign.samplers import run_seeds
from oos_drake.campaign.simulator import MissionWindow, ParameterKind, RunCase
from oos_drake.campaign.spec import CampaignSpec, spec_to_toml
from oos_drake.campaign.tree_simulator import FACTORY_PATH as TREE_FACTORY_PATH
from oos_drake.files import atomic_write_parquet, atomic_write_text

#: Requirement ratio given to a run that diverged or failed (the optimizer's objective) [-].
FAILED_RATIO = 1.0e3
#: The optimizer searches the unit cube widened by this margin on each side and the points are
#: clipped back to the box: worst cases often lie on the box's faces and vertices, which
#: differential evolution (re-drawing out-of-bounds trials at random) would otherwise rarely reach.
EDGE_MARGIN = 0.1
#: Files of a falsification folder.
SPEC_FILE = "spec.toml"
SETTINGS_FILE = "falsify.json"
POINTS_DIR = "points"
TABLE_FILE = "falsification.parquet"
COMPARISON_FILE = "comparison.parquet"
RATIO_COLUMN = "requirement ratio [-]"
#: The sinusoid's frequency is searched within ``[f / factor, f * factor]`` of the worst case's.
SINE_FREQUENCY_FACTOR = 2.0
#: Started from a performance worst case, half of the first generation's fill-up is drawn
#: around it (normal, this standard deviation in unit-cube coordinates), half over the box.
SEED_SPREAD = 0.1
#: Searches of :func:`falsify` (``--search``): differential evolution, local gradient ascent.
SEARCHES = ("evolution", "local")
#: Local search: finite-difference step in unit-cube coordinates [-].
LOCAL_STEP = 0.01
#: Local search: first trust radius of the line search in unit-cube coordinates [-].
LOCAL_RADIUS = 0.05
#: Local search: the line search's steps, in trust radii [-].
LINE_STEPS = (0.25, 0.5, 1.0, 2.0, 4.0)
#: Local search: the line's direction divides each gradient coordinate by its curvature, at
#: least the largest curvature over this factor [-].
CURVATURE_SPAN = 100.0
#: Local search: it stops (converged) when the finite-difference step falls below this [-].
SMALLEST_STEP = 1.0e-4
#: Column of the performance table: the twin run's largest centred axis over the requirement.
PEAK_RATIO = "peak ratio twin [-]"
#: Column of the performance table holding the worst case as simulator values (JSON).
WORST_VALUES_COLUMN = "worst values"
#: The same perturbation with the input that is worst for a single axis (JSON).
AXIS_VALUES_COLUMN = "worst values, largest axis"


@dataclass(frozen=True)
class SearchBox:
    """The searched parameters and their bounds.

    Attributes
    ----------
    names : tuple of str
        Searched parameter names (the spec's dispersed, non-fixed parameters).
    low, high : numpy.ndarray
        Bounds [unit of each parameter].
    log : numpy.ndarray of bool
        Searched in log coordinates (log-uniform laws).
    choices : tuple
        Per parameter: the allowed values of a choice law, else None.
    """

    names: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray
    log: np.ndarray
    choices: tuple

    @classmethod
    def of_spec(cls, spec: CampaignSpec, extra=(), exclude=()) -> SearchBox:
        """The box of the spec's dispersions (see the module docstring) but ``exclude`` and the
        ``extra`` dimensions ``(name, low, high, log)``."""
        names, low, high, log, choices = [], [], [], [], []
        for name, lo, hi, logarithmic in extra:
            names.append(name)
            low.append(lo)
            high.append(hi)
            log.append(logarithmic)
            choices.append(None)
        for name, law in spec.dispersions.items():
            if isinstance(law, Fixed) or name in exclude:
                continue
            lo, hi = law.support
            if isinstance(law, TruncatedNormal):
                lo, hi = max(lo, law.mean - 3 * law.std), min(hi, law.mean + 3 * law.std)
            if not hi > lo:
                continue
            names.append(name)
            low.append(lo)
            high.append(hi)
            log.append(isinstance(law, LogUniform))
            choices.append(np.array(law.values, float) if isinstance(law, Choice) else None)
        if not names:
            raise ValueError(f"spec {spec.name}: no dispersed parameter to search")
        return cls(tuple(names), np.array(low), np.array(high), np.array(log), tuple(choices))

    @property
    def _log_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the log-searched parameters (1 and e elsewhere: no division by 0)."""
        return np.where(self.log, self.low, 1.0), np.where(self.log, self.high, math.e)

    def to_physical(self, u: np.ndarray) -> np.ndarray:
        """Unit-cube coordinates ``u`` -> physical values (choices snapped)."""
        u = np.clip(np.asarray(u, float), 0.0, 1.0)
        linear = self.low + u * (self.high - self.low)
        low, high = self._log_bounds
        logarithmic = np.exp(np.log(low) + u * np.log(high / low))
        x = np.where(self.log, logarithmic, linear)
        for j, values in enumerate(self.choices):
            if values is not None:
                x[..., j] = values[np.argmin(np.abs(values - x[..., j, None]), axis=-1)]
        return x

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        """Physical values -> unit-cube coordinates (clipped to the box)."""
        x = np.clip(np.asarray(x, float), self.low, self.high)
        linear = (x - self.low) / (self.high - self.low)
        low, high = self._log_bounds
        logarithmic = np.log(np.where(self.log, x, 1.0) / low) / np.log(high / low)
        return np.where(self.log, logarithmic, linear)


def requirement_ratio(spec: CampaignSpec, status: str, metrics: dict) -> float:
    """``max_j metric_j / bound_j`` over the max-requirements; :data:`FAILED_RATIO` for a run
    that did not finish."""
    if status != "ok":
        return FAILED_RATIO
    ratios = [
        float(metrics[r.metric]) / r.max
        for r in spec.requirements
        if r.max is not None and r.max > 0
    ]
    return max(ratios)


def _window_and_frequency(spec: CampaignSpec, seed: pd.Series | None = None, window=None):
    """The window every search run simulates and the frequency of its LTI perturbations: the
    worst case ``seed``'s (a performance row) or the peak region's; ``window`` ``(start,
    end)`` [s] replaces the spec's."""
    frequency, centre = math.nan, None
    peak = max(spec.regions, key=lambda r: r.mu_upper) if spec.regions else None
    if seed is not None:
        frequency, centre = float(seed["frequency [Hz]"]), float(seed["time [s]"])
    elif peak is not None:
        frequency, centre = peak.frequency, peak.time
    if window is not None:
        return MissionWindow(float(window[0]), float(window[1]), "falsify"), frequency
    if spec.window.kind == "critical":
        return spec.window.resolve(spec.info, centre), frequency
    return spec.window.resolve(spec.info), frequency


def performance_seeds(spec: CampaignSpec, performance: pd.DataFrame | None) -> list[dict]:
    """The performance table's worst cases for the spec's max-requirements, as simulator
    values (``worst values``, then the same perturbation with the input that is worst for one
    axis, ``worst values, largest axis``: a peak requirement bounds each axis), largest
    certified lower bound first; each dict also holds the row under ``"row"``. Empty without a
    table or without that column."""
    from oos_drake.campaign.performance import REQUIREMENT_METRICS

    if performance is None or WORST_VALUES_COLUMN not in performance.columns:
        return []
    metrics = {r.metric for r in spec.requirements if r.max is not None and r.max > 0}
    rows = performance[performance["channel"].map(REQUIREMENT_METRICS).isin(metrics)]
    rows = rows[rows[WORST_VALUES_COLUMN].notna()]
    rows = rows.sort_values("gain lower [-]", ascending=False, kind="stable")
    known = spec.info.by_name
    seeds = []
    for _, row in rows.iterrows():
        for column in (WORST_VALUES_COLUMN, AXIS_VALUES_COLUMN):
            if not isinstance(row.get(column), str):
                continue  # a table written before the largest-axis input
            values = json.loads(row[column])
            seeds.append({k: float(v) for k, v in values.items() if k in known} | {"row": row})
    return seeds


def realize_worst_perturbation(spec, spec_path, worst_cases, simulator_options, seeds):
    """The spec whose Drake mission realizes the first seed's complex blocks with their phase.

    The mission realizes a complex block as a signed real scalar times an all-pass (the phase of
    the analysis' worst value is lost: on heavy_target the seed's run reaches 1.026 of the
    pointing requirement that way, 1.138 with the phase). The seed's row (``worst
    perturbation``, ``frequency [Hz]``) becomes the simulator option ``worst_perturbation``
    (:func:`~oos_drake.campaign.drake_simulator.worst_perturbation_option`), its scale
    ``worst_scale`` a searched parameter (1 at the seed); the scalar blocks it realizes are
    fixed at 0 and left out of the search (the perturbation stays in the analysis' unit ball).

    Returns
    -------
    spec : CampaignSpec
        The spec with the option (``spec`` itself when the row has no complex block).
    seeds : list of dict
        The seeds, the first with ``worst_scale = 1``.
    realized : list of str
        The scalar blocks the realization replaces (fixed at 0).
    """
    from oos_drake.campaign.drake_simulator import worst_perturbation_option

    row = seeds[0]["row"]
    perturbation = row.get("worst perturbation")
    if not isinstance(perturbation, str):
        return spec, seeds, []
    by_name = spec.info.by_name
    realized = sorted(
        n for n in json.loads(perturbation) if n in by_name and by_name[n].kind == ParameterKind.LTI
    )
    if not realized:
        return spec, seeds, []
    option = worst_perturbation_option(perturbation, float(row["frequency [Hz]"]))
    spec = resolve_spec(
        spec_path, worst_cases, {**(simulator_options or {}), "worst_perturbation": option}
    )
    same = [s for s in seeds if s["row"] is row]  # the first row's seeds (both inputs)
    realized_seeds = [
        {k: v for k, v in s.items() if k not in realized} | {WORST_SCALE: 1.0} for s in same
    ]
    return spec, [*realized_seeds, *seeds[len(same) :]], realized


def disturbance_dimensions(spec: CampaignSpec, seed: dict) -> tuple[list, dict]:
    """Search dimensions ``(name, low, high, log)`` and fixed values of the sinusoidal input
    the spec does not disperse (module docstring), around the worst case ``seed``."""
    dimensions, fixed = [], {}
    for name, value in seed.items():
        if name == "row" or name in spec.dispersions:
            continue
        parameter = spec.info.by_name[name]
        if parameter.kind != ParameterKind.DISTURBANCE:
            continue
        if name == "sine_frequency":
            low = max(parameter.lower, value / SINE_FREQUENCY_FACTOR)
            high = min(parameter.upper, value * SINE_FREQUENCY_FACTOR)
            dimensions.append((name, low, high, True))
        elif name.startswith(("sine_re_", "sine_im_")):
            dimensions.append((name, parameter.lower, parameter.upper, False))
        else:  # amplitude, noise scale: the worst case's
            fixed[name] = value
    return dimensions, fixed


def starting_points(spec: CampaignSpec, box: SearchBox, seeds=()) -> np.ndarray:
    """Unit-cube points of the analysis' worst cases (the performance ``seeds`` first, then the
    regions by decreasing ``mu_upper``) and the nominal point; parameters a worst case does not
    give stay at their nominal values, the input (parameters of kind ``disturbance``) and the
    scale of the realized worst perturbation (``worst_scale``) at the first seed's (a region
    carries neither: it is then driven by the worst ones)."""
    nominal = np.array([spec.info.by_name[n].nominal for n in box.names])
    if seeds:
        for j, name in enumerate(box.names):
            kind = spec.info.by_name[name].kind
            if (kind == ParameterKind.DISTURBANCE or name == WORST_SCALE) and name in seeds[0]:
                nominal[j] = seeds[0][name]
    points = []
    for seed in seeds:
        x = nominal.copy()
        for j, name in enumerate(box.names):
            if name in seed:
                x[j] = seed[name]
        points.append(box.to_unit(x))
    for region in sorted(spec.regions, key=lambda r: -r.mu_upper):
        x = nominal.copy()
        for j, name in enumerate(box.names):
            if name in region.perturbation:
                x[j] = region.perturbation[name]
        points.append(box.to_unit(x))
    points.append(box.to_unit(nominal))
    _, first = np.unique(np.array(points), axis=0, return_index=True)
    return np.array(points)[np.sort(first)]  # duplicates dropped, order kept


def local_search(evaluate, starts: np.ndarray) -> tuple[np.ndarray, float]:
    """Projected gradient ascent with a line search in the unit cube (module docstring).

    Parameters
    ----------
    evaluate : callable
        ``evaluate(points) -> ratios``: runs a batch of unit-cube points (rows) and returns their
        requirement ratios [-]; it stops the search by raising (the budget is spent).
    starts : numpy.ndarray
        The starting points (rows), run as the first batch; the search climbs from the best.

    Returns
    -------
    centre : numpy.ndarray
        The best point found (unit cube).
    value : float
        Its ratio [-]; returned when the step fell below :data:`SMALLEST_STEP` (converged).
    """
    values = np.asarray(evaluate(starts), float)
    best = int(np.argmax(values))
    centre, value = np.array(starts[best], float), float(values[best])
    radius, step, direction = LOCAL_RADIUS, LOCAL_STEP, None
    line = np.array(LINE_STEPS)
    while step >= SMALLEST_STEP:
        pool, pool_values = [], []
        if direction is None:
            up = np.where(centre + step <= 1.0, step, -2.0 * step)  # on a face: one-sided
            down = np.where(centre - step >= 0.0, -step, 2.0 * step)
            points = np.vstack([centre + np.diag(up), centre + np.diag(down)])
            differences = np.asarray(evaluate(points), float)
            gradient, curvature = _derivatives(
                value, up, differences[: len(up)], down, differences[len(up) :]
            )
            outward = ((centre >= 1.0) & (gradient > 0)) | ((centre <= 0.0) & (gradient < 0))
            gradient[outward] = 0.0  # projected: the box's faces hold
            pool, pool_values = list(points), list(differences)
            norm = float(np.linalg.norm(gradient))
            if not norm > 0.0 or not np.isfinite(norm):
                step /= 2.0  # flat at this resolution: a finer difference
                continue
            # each coordinate scaled by its curvature (a diagonal Newton step's direction),
            # within a factor CURVATURE_SPAN of the largest: a flat coordinate stays bounded
            curvature = np.abs(curvature)
            scale = np.maximum(curvature, curvature.max() / CURVATURE_SPAN)
            direction = gradient / scale if np.all(scale > 0) else gradient
            direction = direction / float(np.linalg.norm(direction))
        trials = np.clip(centre + radius * line[:, None] * direction, 0.0, 1.0)
        found = np.asarray(evaluate(trials), float)
        pool, pool_values = [*pool, *trials], [*pool_values, *found]
        best = int(np.argmax(pool_values))
        if pool_values[best] > value:
            centre, value = np.array(pool[best]), float(pool_values[best])
            along = best - (len(pool) - len(trials))  # index in the line, < 0: a difference
            radius *= 2.0 if along == len(line) - 1 else 0.5 if along == 0 else 1.0
            direction = None
        else:
            radius /= 4.0  # the same gradient, shorter steps
            if radius * line[0] < step:
                step, radius, direction = step / 2.0, max(radius, step), None
    return centre, value


def _derivatives(value, h1, f1, h2, f2) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives at 0 of the parabola through ``(0, value)``, ``(h1, f1)``,
    ``(h2, f2)`` (per coordinate; ``h1 = -h2``: the central differences, unbiased at a maximum
    where a forward difference reads the curvature as a slope)."""
    a, b, c = 1.0 / (h1 * h2), 1.0 / (h1 * (h1 - h2)), 1.0 / (h2 * (h2 - h1))
    first = -value * (h1 + h2) * a - f1 * h2 * b - f2 * h1 * c
    return first, 2.0 * (value * a + f1 * b + f2 * c)


def population_size(dimension: int) -> int:
    """Points per generation: ``3 d`` within [8, 30]."""
    return int(min(max(3 * dimension, 8), 30))


@dataclass(frozen=True)
class FalsificationResult:
    """What a falsification found.

    Attributes
    ----------
    directory : Path
        Its folder.
    table : pandas.DataFrame
        Every evaluated point (``falsification.parquet``).
    best : pandas.Series
        The row of the largest requirement ratio.
    evaluated : int
        Points run by this call.
    reused : int
        Points taken from an earlier (interrupted) call.
    comparison : pandas.DataFrame
        Per max-requirement metric: the worst ratio metric / requirement the search found beside
        the analysis' worst-case gain bounds (largest over the regions; NaN without gains), both
        normalized by the requirement (``comparison.parquet``).
    search : str
        The optimizer (:data:`SEARCHES`).
    """

    directory: Path
    table: pd.DataFrame
    best: pd.Series
    evaluated: int
    reused: int
    comparison: pd.DataFrame
    search: str = "evolution"

    def sentence(self) -> str:
        """One line: the worst run found and its parameters."""
        best = self.best
        verdict = "VIOLATES" if best[RATIO_COLUMN] > 1 else "meets"
        generations = int(self.table["generation"].max()) + 1 if len(self.table) else 0
        unit = "generation" if self.search == "evolution" else "batch"
        plural = "" if generations == 1 else "es" if unit == "batch" else "s"
        climbed = ""
        if self.search == "local" and len(self.table):
            starts = self.table.loc[self.table["generation"] == 0, RATIO_COLUMN].max()
            climbed = f" (local search; best starting point {starts:.4g})"
        lines = [
            f"falsification: {len(self.table)} runs in {generations} {unit}{plural}"
            + (" (the first only: the starting points)" if generations == 1 else climbed)
            + "; worst requirement ratio "
            f"{best[RATIO_COLUMN]:.4g} (point {int(best['point_id'])}, {best['status']}): "
            f"{verdict} the requirements"
        ]
        for _, row in self.comparison.iterrows():
            line = f"  {row['metric']}: worst found {row['worst found / requirement [-]']:.4g}"
            if np.isfinite(row["wcgain upper [-]"]):
                line += (
                    f" of the requirement; the analysis' worst-case gain lies in "
                    f"[{row['wcgain lower [-]']:.4g}, {row['wcgain upper [-]']:.4g}] "
                    f"(region {int(row['region'])})"
                )
            if np.isfinite(row.get("performance upper [-]", math.nan)):
                line += (
                    f"; certified worst-case gain [{row['performance lower [-]']:.4g}, "
                    f"{row['performance upper [-]']:.4g}], twin with the worst perturbation "
                    f"and input {row['twin worst input / requirement [-]']:.4g}"
                )
                axis = row.get("twin worst input, largest axis / requirement [-]", math.nan)
                if np.isfinite(axis):
                    line += f" (its largest axis, what a peak metric sees: {axis:.4g})"
            lines.append(line)
        return "\n".join(lines)


class _BudgetSpent(Exception):
    """The run budget is used up (stops the optimizer)."""


class _Evaluator:
    """The optimizer's batch map: replays recorded points, runs the new ones on the executor."""

    def __init__(self, directory, spec, box, budget, executor, progress, seed, where, fixed):
        self.directory, self.spec, self.box, self.budget = directory, spec, box, budget
        self.executor = executor
        self.window, self.frequency = where
        self.fixed = dict(fixed)
        self.seed = seed
        self.recorded = _read_points(directory)
        self.next_id = 0
        self.generation = 0
        self.evaluated = 0
        self.reused = 0
        self.bar = tqdm(
            total=budget,
            unit="run",
            desc=f"falsify {spec.name}",
            disable=not progress,
            file=sys.stderr,
            dynamic_ncols=True,
        )

    def __call__(self, _function, population) -> list[float]:
        population = np.atleast_2d(np.asarray(list(population), float))
        ids = np.arange(self.next_id, self.next_id + len(population))
        self.next_id += len(population)
        ratios = np.full(len(population), np.nan)
        new = []
        for i, (point_id, u) in enumerate(zip(ids, population, strict=True)):
            row = self.recorded.get(int(point_id))
            if row is not None:
                if not np.allclose(row["u"], u, rtol=0, atol=1e-12):
                    raise ValueError(
                        f"{self.directory}: point {point_id} differs from the recorded one: the "
                        "folder holds another search (other spec, seed or worst cases)"
                    )
                ratios[i] = row["ratio"]
                self.reused += 1
                self.bar.update(1)
            elif point_id < self.budget:
                new.append((i, int(point_id), u))
        cases = {}
        for i, point_id, u in new:
            values = {p.name: float(p.nominal) for p in self.spec.info.parameters}
            for name, law in self.spec.dispersions.items():
                if isinstance(law, Fixed):
                    values[name] = float(law.value)
            values.update(self.fixed)
            values.update(zip(self.box.names, self.box.to_physical(u).tolist(), strict=True))
            cases[point_id] = (
                i,
                u,
                RunCase(point_id, self.seed, values, self.window, self.frequency),
            )
        if cases:
            for result in self.executor.run(self.spec.simulator, [c[2] for c in cases.values()]):
                i, u, case = cases[result.run_id]
                ratio = requirement_ratio(self.spec, result.status, result.metrics)
                self._record(case, u, result, ratio)
                ratios[i] = ratio
                self.evaluated += 1
                self.bar.update(1)
                if result.status != "ok":
                    self.bar.write(f"point {result.run_id}: {result.status}: {result.error}")
        self.generation += 1
        if np.isnan(ratios).any():  # points beyond the budget were not run
            raise _BudgetSpent
        return (-ratios).tolist()

    def _record(self, case, u, result, ratio) -> None:
        spec = self.spec
        record = {
            "point_id": np.int64(case.run_id),
            "generation": np.int64(self.generation),
            "seed": np.int64(case.seed),
            "window start [s]": case.window.start,
            "window end [s]": case.window.end,
            "frequency [Hz]": case.frequency,
        }
        for parameter in spec.info.parameters:
            record[parameter.column] = float(case.values[parameter.name])
        for metric in spec.metrics:
            record[metric_column(spec, metric)] = float(result.metrics.get(metric, math.nan))
        record[RATIO_COLUMN] = ratio
        record["status"] = result.status
        record["error"] = result.error
        record["wall time [s]"] = float(result.wall_time)
        record["unit coordinates"] = json.dumps([float(v) for v in u])
        path = Path(self.directory) / POINTS_DIR / f"point_{case.run_id:06d}.parquet"
        atomic_write_parquet(pd.DataFrame([record]), path)


def _read_points(directory: Path) -> dict[int, dict]:
    """Recorded points: id -> unit coordinates and ratio (unreadable leftovers are redone)."""
    folder = Path(directory) / POINTS_DIR
    out = {}
    for leftover in folder.glob(".point_*.tmp") if folder.is_dir() else ():
        leftover.unlink()  # a write interrupted by a kill: its point is run again
    for path in sorted(folder.glob("point_*.parquet")) if folder.is_dir() else ():
        try:
            row = pd.read_parquet(path).iloc[0]
        except Exception:  # noqa: BLE001 - a torn file from a kill: the point is run again
            path.unlink()
            continue
        out[int(row["point_id"])] = {
            "u": np.array(json.loads(row["unit coordinates"])),
            "ratio": float(row[RATIO_COLUMN]),
        }
    return out


def read_table(directory: str | Path) -> pd.DataFrame:
    """Every evaluated point of a falsification folder, by ``point_id``."""
    folder = Path(directory) / POINTS_DIR
    paths = sorted(folder.glob("point_*.parquet")) if folder.is_dir() else []
    if not paths:
        return pd.DataFrame()
    table = pd.concat([pd.read_parquet(p) for p in paths], ignore_index=True)
    return table.sort_values("point_id").reset_index(drop=True)


def _prepare_directory(directory: Path, spec: CampaignSpec, settings: dict) -> None:
    """Create the folder, or check that it holds this same search (then it is resumed)."""
    text = spec_to_toml(spec, str(spec.sampler.worst_cases) if spec.sampler.worst_cases else None)
    spec_path, settings_path = directory / SPEC_FILE, directory / SETTINGS_FILE
    if spec_path.is_file():
        same = spec_path.read_text() == text and settings_path.is_file()
        old = json.loads(settings_path.read_text()) if same else {}
        if not same or {k: v for k, v in old.items() if k != "budget"} != {
            k: v for k, v in settings.items() if k != "budget"
        }:
            raise ValueError(
                f"--out {directory} holds another falsification (other spec or settings); "
                "choose another --out"
            )
        return
    if directory.exists() and any(directory.iterdir()):
        raise ValueError(f"--out {directory} exists and is not empty")
    directory.mkdir(parents=True, exist_ok=True)
    atomic_write_text(json.dumps(settings, indent=2) + "\n", settings_path)
    atomic_write_text(text, spec_path)


def falsify(
    spec_path: str | Path,
    out: str | Path,
    budget: int = 200,
    workers: int = 1,
    scheduler: str | None = None,
    worst_cases: str | Path | None = None,
    progress: bool = True,
    simulator_options: Mapping[str, Any] | None = None,
    confirm: str | Path | None = None,
    window: tuple[float, float] | None = None,
    search: str = "evolution",
) -> FalsificationResult:
    """Search the spec's dispersion box for the largest requirement ratio (module docstring).

    Parameters
    ----------
    spec_path : path
        Campaign spec (or the name of a shipped one).
    out : path
        Folder of the search; an existing folder of the same search is resumed.
    budget : int
        Largest number of runs (including those of an earlier, interrupted call).
    workers, scheduler
        Executor of the runs (as ``oos campaign run``).
    worst_cases : path, optional
        The analysis' ``worst_cases.parquet``: its regions start the search.
    progress : bool
        Show a progress bar.
    simulator_options : dict, optional
        Update the spec's simulator options (``--simulator-option``, e.g. a ``controller``).
    confirm : path, optional
        ``oos confirm`` folder (or its ``performance_confirmation.parquet``): the comparison
        then also gives, per requirement, the analysis' certified worst-case gain and the twin
        run with the worst perturbation and the worst input (:func:`linear_comparison`); its
        worst cases (``worst values``) start the search, which then also searches the
        sinusoidal input (module docstring).
    window : (float, float), optional
        Simulated window ``(start, end)`` [s] of every run instead of the spec's.
    search : {"evolution", "local"}
        Differential evolution, or the local search from the best starting point
        (:func:`local_search`, module docstring).

    Raises
    ------
    ValueError
        Bad spec, no max-requirement, a folder holding another search, a budget < 1, a bad
        window, an unknown search.
    """
    from scipy.optimize import differential_evolution

    if budget < 1:
        raise ValueError(f"--budget {budget}: need at least 1 run")
    if search not in SEARCHES:
        raise ValueError(f"--search {search}: expected one of {', '.join(SEARCHES)}")
    performance = _performance_table(confirm)
    spec = resolve_spec(spec_path, worst_cases, simulator_options)
    if not any(r.max is not None and r.max > 0 for r in spec.requirements):
        raise ValueError(f"spec {spec.name}: falsification needs a requirement with a max bound")
    seeds = performance_seeds(spec, performance)
    realized = []
    if seeds and spec.simulator.factory in (FACTORY_PATH, TREE_FACTORY_PATH):
        spec, seeds, realized = realize_worst_perturbation(
            spec, spec_path, worst_cases, simulator_options, seeds
        )
    dimensions, fixed = disturbance_dimensions(spec, seeds[0]) if seeds else ([], {})
    fixed |= dict.fromkeys(realized, 0.0)
    box = SearchBox.of_spec(spec, dimensions, exclude=realized)
    if realized and WORST_SCALE not in box.names:  # not dispersed: the worst case's, whole
        fixed[WORST_SCALE] = 1.0
    if window is not None and not (0.0 <= window[0] < window[1] <= spec.info.duration):
        raise ValueError(
            f"--window {window[0]:g},{window[1]:g}: need 0 <= start < end <= "
            f"{spec.info.duration:g} s"
        )
    where = _window_and_frequency(spec, seeds[0]["row"] if seeds else None, window)
    frequency = where[1]
    lti = [n for n in box.names if spec.info.by_name[n].kind == ParameterKind.LTI]
    if lti and math.isnan(frequency):
        raise ValueError(
            f"falsify {spec.name}: LTI perturbations ({', '.join(lti)}) need the analysis' "
            "worst_cases.parquet for their frequency (--worst-cases FILE)"
        )
    size = population_size(len(box.names))
    run_seed, _ = run_seeds(spec.random_seed, 1)
    settings = {"seed": spec.random_seed, "population": size, "budget": budget}
    if window is not None:
        settings["window [s]"] = [float(window[0]), float(window[1])]
    if seeds:
        settings["worst values"] = [{k: v for k, v in s.items() if k != "row"} for s in seeds]
    if realized:
        settings["realized with their phase"] = realized
    if search != "evolution":  # (a folder written before the option holds an evolution)
        settings["search"] = search
    directory = Path(out)
    _prepare_directory(directory, spec, settings)

    starts = starting_points(spec, box, seeds)
    starts = starts if search == "local" else starts[:size]
    rng = np.random.default_rng(np.random.SeedSequence([spec.random_seed, 0xFA15]))
    fill = size - len(starts) if search == "evolution" else 0
    if fill > 0:
        from scipy.stats import qmc

        cloud = fill // 2 if seeds else 0  # around the first worst case (module docstring)
        around = np.clip(
            starts[0] + SEED_SPREAD * rng.standard_normal((cloud, len(box.names))), 0, 1
        )
        spread = qmc.LatinHypercube(len(box.names), rng=rng).random(fill - cloud)
        starts = np.vstack([starts, around, spread])
    executor = make_executor(workers, scheduler, spec.run_timeout)
    evaluator = _Evaluator(
        directory, spec, box, budget, executor, progress, int(run_seed[0]), where, fixed
    )
    try:
        if search == "local":
            local_search(lambda points: -np.array(evaluator(None, points)), starts)
        else:
            differential_evolution(
                lambda u: 0.0,  # never called: the batch map evaluates
                bounds=[(-EDGE_MARGIN, 1.0 + EDGE_MARGIN)] * len(box.names),
                init=starts,
                maxiter=max(1, math.ceil(budget / size)),
                popsize=size,
                tol=0.0,
                atol=0.0,
                polish=False,
                updating="deferred",
                workers=evaluator,
                rng=rng,
            )
    except _BudgetSpent:
        pass
    except RuntimeError as exc:  # scipy wraps the batch map's refusal: give it back as is
        if isinstance(exc.__cause__, ValueError):
            raise exc.__cause__ from None
        raise
    finally:
        evaluator.bar.close()
        executor.close()
    table = read_table(directory)
    table = table[table["point_id"] < budget].reset_index(drop=True)
    atomic_write_parquet(table, directory / TABLE_FILE)
    best = table.loc[table[RATIO_COLUMN].idxmax()]
    comparison = linear_comparison(spec, table, performance)
    atomic_write_parquet(comparison, directory / COMPARISON_FILE)
    return FalsificationResult(
        directory, table, best, evaluator.evaluated, evaluator.reused, comparison, search
    )


def _performance_table(confirm: str | Path | None) -> pd.DataFrame | None:
    """``oos confirm``'s performance table (a folder or the file), None when not given.

    Raises
    ------
    ValueError
        ``confirm`` given but no table there.
    """
    from oos_drake.campaign.performance import PERFORMANCE_CONFIRMATION_FILE

    if confirm is None:
        return None
    path = Path(confirm)
    path = path / PERFORMANCE_CONFIRMATION_FILE if path.is_dir() else path
    if not path.is_file():
        raise ValueError(
            f"--confirm {confirm}: no {PERFORMANCE_CONFIRMATION_FILE} (written by oos confirm)"
        )
    return pd.read_parquet(path)


def _performance_columns(performance: pd.DataFrame | None, metric: str) -> dict:
    """The performance confirmation of the channel whose unit gain is ``metric``'s requirement:
    the largest certified interval of the analysis (row of the largest lower bound) and the
    largest ratio of the twin run with the worst perturbation and the worst input (NaN without
    a table, a channel or a twin run)."""
    from oos_drake.campaign.performance import REQUIREMENT_METRICS

    out = {
        "performance lower [-]": math.nan,
        "performance upper [-]": math.nan,
        "twin worst input / requirement [-]": math.nan,
        "twin worst input, largest axis / requirement [-]": math.nan,
    }
    channels = [c for c, m in REQUIREMENT_METRICS.items() if m == metric]
    if performance is None or not channels:
        return out
    rows = performance[performance["channel"].isin(channels)]
    lower = pd.to_numeric(rows["gain lower [-]"], errors="coerce")
    if lower.notna().any():
        row = rows.loc[lower.idxmax()]
        out["performance lower [-]"] = float(row["gain lower [-]"])
        out["performance upper [-]"] = float(row["gain upper [-]"])
    twin = pd.to_numeric(rows["gain twin [-]"], errors="coerce")
    if twin.notna().any():
        out["twin worst input / requirement [-]"] = float(twin.max())
    if PEAK_RATIO in rows.columns:  # a peak metric bounds each axis: the gain is their 2-norm
        peak = pd.to_numeric(rows[PEAK_RATIO], errors="coerce")
        if peak.notna().any():
            out["twin worst input, largest axis / requirement [-]"] = float(peak.max())
    return out


def linear_comparison(
    spec: CampaignSpec, table: pd.DataFrame, performance: pd.DataFrame | None = None
) -> pd.DataFrame:
    """Per max-requirement metric: worst metric / requirement among the finished points, the
    largest worst-case gain bounds of the analysis' regions for it (NaN without gains) and,
    given ``oos confirm``'s performance table, the analysis' certified worst-case gain of its
    channel and the twin's ratio under the worst perturbation and input
    (:func:`_performance_columns`)."""
    rows = []
    ok = table["status"] == "ok"
    for requirement in spec.requirements:
        if requirement.max is None or requirement.max <= 0:
            continue
        ratio = table.loc[ok, metric_column(spec, requirement.metric)] / requirement.max
        with_gain = [r for r in spec.regions if requirement.metric in r.gains]
        region = max(with_gain, key=lambda r: r.gains[requirement.metric][1], default=None)
        low, high = region.gains[requirement.metric] if region else (math.nan, math.nan)
        rows.append(
            {
                "metric": requirement.metric,
                "worst found / requirement [-]": float(ratio.max()) if len(ratio) else math.nan,
                "wcgain lower [-]": float(low),
                "wcgain upper [-]": float(high),
                "region": region.region if region else -1,
            }
            | _performance_columns(performance, requirement.metric)
        )
    return pd.DataFrame(rows)
