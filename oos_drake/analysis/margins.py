"""Classical and disk margins over the mission, for the continuous and the sampled-data loop.

For each mission configuration (nominal plant, the configuration substituted) three loops are
broken at the reaction wheels' input (:mod:`oos_drake.control.margins`):

- ``continuous``: the paper's continuous loop;
- ``sampled``: the EXACT sampled-data loop of the flight software
  (:func:`oos_drake.control.sampled.sampled_loop`: zero-order-hold plant, Tustin sensors and
  filters, the controller at the flight software's rate -- a dynamic one discretized exactly,
  zero-order hold, or as tuned when discrete -- responses at ``z = e^{j omega T}`` up to the
  Nyquist frequency);
- ``sampled model``: the continuous loop with the rational hold model that ``--sampled`` puts
  in the mu analysis (:func:`oos_drake.control.components.sample_hold`): its distance to
  ``sampled`` is the model's error.

Any controller structure runs (the static gain ``[K_p, K_d]``, a PID, a state space:
:class:`~oos_drake.analysis.controller.Controller`); the continuous loops use its continuous
form. The study also measures, along rays of the analysis' worst real-parameter perturbations, where
the exact sampled loop and the two continuous models lose stability (:func:`ray_boundaries`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from oos_drake.analysis.controller import Controller
from oos_drake.control.loop_response import LoopResponse
from oos_drake.control.margins import disk_gain_phase, margins
from oos_drake.control.sampled import continuous_poles, sampled_loop, spectral_abscissa

#: The loops of the study, in table order.
LOOPS = ("continuous", "sampled model", "sampled")
#: Grid points per study (log spaced, plus the plant's lightly damped mode frequencies).
GRID_POINTS = 1200
#: Lowest grid frequency [Hz].
F_MIN_HZ = 1e-3
#: Highest grid frequency of the continuous loops [Hz] (the sampled loop stops at Nyquist).
F_MAX_HZ = 20.0


#: Columns of the worst margins over the mission in ``summary.json`` (``"worst"``).
WORST_COLUMNS = (
    "gain margin upper [dB]",
    "phase margin [deg]",
    "delay margin [s]",
    "disk margin [-]",
    "multiloop disk margin [-]",
)


@dataclasses.dataclass(frozen=True)
class MarginsResult:
    """The margins stage of one controller on one scenario (:func:`compute_margins`): what
    ``oos margins`` writes, as one frozen object (no file, no figure).

    Attributes
    ----------
    controller : Controller
        The controller whose loops are broken.
    scenario : Scenario
        The scenario of the plants.
    options : MarginsOptions
        What was computed.
    times_s : numpy.ndarray
        The mission times [s].
    margins : pandas.DataFrame
        One row per time, loop and channel (:func:`mission_margins`).
    ray_boundaries : pandas.DataFrame or None
        Stability boundaries of the three loops along the analysis' rays
        (:func:`ray_boundaries`; None without ``options.analysis`` or without rays).
    seconds : float
        Wall time of the computation [s].
    """

    controller: Controller
    scenario: object
    options: MarginsOptions
    times_s: np.ndarray
    margins: pd.DataFrame
    ray_boundaries: pd.DataFrame | None
    seconds: float

    def tables(self) -> dict[str, pd.DataFrame]:
        """File stem -> table: ``margins`` and, with rays, ``ray_boundaries``."""
        tables = {"margins": self.margins}
        if self.ray_boundaries is not None:
            tables["ray_boundaries"] = self.ray_boundaries
        return tables

    def worst(self) -> dict[str, dict[str, float]]:
        """Loop -> the smallest value over the mission of each of :data:`WORST_COLUMNS`."""
        table = self.margins
        columns = list(WORST_COLUMNS)
        return {loop: table.loc[table["loop"] == loop, columns].min().to_dict() for loop in LOOPS}

    def summary(self) -> dict:
        """The record of ``summary.json``: scenario, controller, sampled loop, configurations,
        worst margins per loop, the ray boundaries (with rays) and the wall time [s]."""
        spec = self.controller.spec
        record = {
            "scenario": str(self.scenario.source),
            "controller": {"label": self.controller.label, "source": self.controller.source},
            "loop": {
                "sample_rate_hz": spec.flight_software_rate_hz,
                "delay_s": spec.computation_delay_s,
                "hold_order": spec.hold_order,
            },
            "configurations": int(self.times_s.size),
            "worst": self.worst(),
        }
        if self.ray_boundaries is not None:
            record["rays"] = self.ray_boundaries.to_dict(orient="records")
        record["time_s"] = round(self.seconds, 2)
        return record


def _grid(f_max_hz: float, plant_poles) -> np.ndarray:
    """Log grid [rad/s] with the frequencies of the plant's modes (and +-0.2 % around them)."""
    omega = 2 * np.pi * np.geomspace(F_MIN_HZ, f_max_hz, GRID_POINTS)
    modes = np.abs(np.imag(plant_poles))
    modes = modes[(modes > omega[0]) & (modes < omega[-1])]
    extra = np.concatenate([modes, modes * 0.998, modes * 1.002])
    return np.unique(np.concatenate([omega, extra[extra < omega[-1]]]))


def _rows(result, time_s: float, loop: str) -> list[dict]:
    gain, phase = disk_gain_phase(result.disk)
    rows = []
    for i, axis in enumerate("xyz"):
        rows.append(
            {
                "time [s]": time_s,
                "loop": loop,
                "channel": f"u_{axis}",
                "gain margin upper [dB]": result.gain_upper_db[i],
                "phase crossover [Hz]": result.gain_upper_hz[i],
                "gain margin lower [dB]": result.gain_lower_db[i],
                "phase margin [deg]": result.phase_deg[i],
                "gain crossover [Hz]": result.crossover_hz[i],
                "delay margin [s]": result.delay_s[i],
                "disk margin [-]": result.disk[i],
                "disk gain margin [dB]": gain[i],
                "disk phase margin [deg]": phase[i],
                "disk frequency [Hz]": result.disk_hz[i],
                "multiloop disk margin [-]": result.multiloop_disk,
                "multiloop disk margin, destabilizing [-]": result.multiloop_disk_max,
                "multiloop frequency [Hz]": result.multiloop_hz,
            }
        )
    return rows


def nominal_plants(times, scenario):
    """Nominal rotational plants ``T -> wdot`` at mission ``times`` [s]: a certain LFR model
    array, one model per time."""
    from oos_drake.analysis.models import mission_plants
    from oos_drake.control.analysis_model import rotational_channels

    P = rotational_channels(mission_plants(times, scenario).nominal)
    if not P.batch_shape:
        P = P.model(np.zeros(np.size(times), dtype=int))
    return P


def mission_margins(
    controller: Controller, times, scenario, *, progress: bool = False
) -> pd.DataFrame:
    """Margins of the three loops (:data:`LOOPS`) at each mission time.

    Parameters
    ----------
    controller : Controller
        Controller and design specification (its ``flight_software_rate_hz`` and
        ``computation_delay_s`` define the sampled loops; its ``sampled`` flag is ignored).
    times : array_like
        Mission times [s].
    scenario : Scenario
    progress : bool
        tqdm progress bar.

    Returns
    -------
    pandas.DataFrame
        One row per time, loop and channel (columns ``name [unit]``, see :func:`_rows`).
    """
    from tqdm import tqdm

    times = np.atleast_1d(np.asarray(times, dtype=float))
    plants = nominal_plants(times, scenario)
    specs = {
        "continuous": dataclasses.replace(controller.spec, sampled=False),
        "sampled model": dataclasses.replace(controller.spec, sampled=True),
    }
    responses = {name: LoopResponse(plants, spec) for name, spec in specs.items()}
    system = controller.system
    nyquist_hz = controller.spec.flight_software_rate_hz / 2
    rows = []
    for k in tqdm(range(times.size), disable=not progress, desc="margins", unit="config"):
        poles = np.linalg.eigvals(plants.A[k])
        for name, response in responses.items():

            def loop(w, response=response, k=k):
                return response.loop_gain(system, np.atleast_1d(w)[None, :], [k])[0]

            rows += _rows(margins(loop, _grid(F_MAX_HZ, poles)), times[k], name)
        exact = sampled_loop(plants.model(k), system, controller.spec)
        grid = _grid(nyquist_hz, poles)
        grid[-1] = 2 * np.pi * nyquist_hz
        rows += _rows(margins(exact.loop_gain, grid), times[k], "sampled")
    return pd.DataFrame(rows)


def ray_boundaries(
    controller: Controller, perturbations: dict, scenario, *, scale_max: float = 6.0
) -> pd.DataFrame:
    """Stability boundary along rays of real-parameter perturbations, three loops compared.

    For each ray (a mission time and normalized values of ``ureal`` blocks of the scenario
    model; the other blocks nominal) the plant ``P(s * delta)`` is built for a scale ``s`` and
    the smallest ``s`` in ``(0, scale_max]`` where the loop is unstable is found by bisection:
    closed-loop eigenvalues ``|z| >= 1`` for the exact sampled loop, ``Re >= 0`` for the
    continuous models.

    Parameters
    ----------
    controller : Controller
    perturbations : dict
        ``name -> (time [s], {block: normalized value})``.
    scale_max : float
        Largest scale searched [-].

    Returns
    -------
    pandas.DataFrame
        ``ray``, ``time [s]``, ``boundary <loop> [-]`` for each loop, the relative errors of the
        two models against the exact loop, and the frequency [Hz] of the pole that crosses.
    """
    from oos_drake.control.analysis_model import rotational_channels
    from oos_drake.lfr import usubs
    from oos_drake.scenario.model import build_mission_model, mission_values

    model = build_mission_model(scenario)
    spec_c = dataclasses.replace(controller.spec, sampled=False)
    spec_s = dataclasses.replace(controller.spec, sampled=True)
    system = controller.system
    pole_sets = {
        "continuous": lambda p: continuous_poles(p, system, spec_c),
        "sampled model": lambda p: continuous_poles(p, system, spec_s),
        "sampled": lambda p: sampled_loop(p, system, controller.spec).poles(),
    }
    rows = []
    for name, (time_s, values) in perturbations.items():
        configured = usubs(model, mission_values([time_s], scenario)).model(0)
        unknown = set(values) - set(configured.uncertainty)
        if unknown:
            raise ValueError(f"ray {name}: blocks {sorted(unknown)} are not in the mission model")

        def plant(scale, configured=configured, values=values):
            sub = {k: scale * v for k, v in values.items()}
            P = rotational_channels(usubs(configured, sub, normalized=True)).nominal
            return (P.A, P.B, P.C, P.D)

        row = {"ray": name, "time [s]": time_s}
        for loop_name, poles_of in pole_sets.items():
            scale = _boundary(lambda s, f=poles_of: spectral_abscissa(f(plant(s))), scale_max)
            row[f"boundary {loop_name} [-]"] = scale
            frequency = np.nan
            if np.isfinite(scale):
                poles = poles_of(plant(scale))
                frequency = abs(poles[np.argmax(poles.real)].imag) / (2 * np.pi)
            row[f"crossing frequency {loop_name} [Hz]"] = frequency
        exact = row["boundary sampled [-]"]
        for loop_name in ("continuous", "sampled model"):
            row[f"error {loop_name} [%]"] = 100 * (row[f"boundary {loop_name} [-]"] / exact - 1)
        rows.append(row)
    return pd.DataFrame(rows)


def analysis_rays(analysis_dir, scenario) -> dict:
    """Rays of the mission's worst real-parameter perturbations of an ``oos analyze`` folder.

    Reads its certified peaks (:func:`~oos_drake.analysis.confirm.read_peaks`: normalized
    values) and keeps the mission subsets whose perturbation has only blocks of the scenario
    model (``ureal``) and a finite critical frequency; each ray is the perturbation divided by
    its largest entry, so the scale is the normalized size (mu's boundary is ``1 / mu`` on it).

    Parameters
    ----------
    analysis_dir : path
        Output folder of ``oos analyze``.

    Returns
    -------
    dict
        Subset -> ``(time [s], {block: normalized value})``, subsets in alphabetical order.
    """
    from oos_drake.analysis.confirm import read_peaks
    from oos_drake.scenario.model import build_mission_model

    real_blocks = build_mission_model(scenario).uncertainty  # the plant's ureal blocks
    rays = {}
    for peak in sorted(read_peaks(analysis_dir), key=lambda p: p.subset):
        blocks = peak.perturbation
        if peak.study != "mission" or not np.isfinite(peak.omega):
            continue
        if not blocks or not set(blocks) <= set(real_blocks):
            continue
        values = {k: float(np.real(np.ravel(v)[0])) for k, v in blocks.items()}
        size = max(abs(v) for v in values.values())
        if size > 0:
            rays[peak.subset] = (peak.time, {k: v / size for k, v in values.items()})
    return rays


def _boundary(abscissa, scale_max: float) -> float:
    """Smallest scale in ``[0, scale_max]`` with ``abscissa(scale) >= 0`` (a scan of 60 steps,
    then bisection to a relative ``1e-12``: :func:`~oos_drake.analysis.confirm.
    boundary_along_ray`); ``inf`` when there is none."""
    from oos_drake.analysis.confirm import boundary_along_ray

    if abscissa(0.0) >= 0:
        return 0.0
    return boundary_along_ray(lambda s: abscissa(s) >= 0, scale_max, steps=60, rtol=1e-12)


@dataclasses.dataclass(frozen=True)
class MarginsOptions:
    """What the margins stage computes (``oos margins``' options, the controller apart).

    Attributes
    ----------
    configurations : int
        Equally spaced mission configurations (``--configurations``).
    analysis : Path or None
        An ``oos analyze`` folder: also the stability boundaries along its worst
        real-parameter perturbations (``--analysis``; :func:`analysis_rays`).
    progress : bool
        tqdm progress bar (``not --quiet``).
    """

    configurations: int = 60
    analysis: Path | None = None
    progress: bool = True

    def __post_init__(self):
        if self.configurations < 1:
            raise ValueError(f"--configurations must be >= 1, got {self.configurations}")
        if self.analysis is not None:
            object.__setattr__(self, "analysis", Path(self.analysis))


def compute_margins(controller: Controller, scenario, options: MarginsOptions) -> MarginsResult:
    """The margins stage: :func:`mission_margins` at ``options.configurations`` mission times
    and, with ``options.analysis``, :func:`ray_boundaries` along its rays; nothing written
    (:func:`~oos_drake.analysis.writers.write_margins` writes the result).

    Parameters
    ----------
    controller : Controller
        Controller and design specification (rate and delay of the sampled loops).
    scenario : Scenario
        The scenario of the plants (and of the analysis' rays).
    options : MarginsOptions

    Returns
    -------
    MarginsResult
    """
    import time

    from oos_drake.analysis.models import mission_times

    rays = analysis_rays(options.analysis, scenario) if options.analysis is not None else {}
    times = mission_times(options.configurations, scenario)
    start = time.perf_counter()
    table = mission_margins(controller, times, scenario, progress=options.progress)
    boundaries = ray_boundaries(controller, rays, scenario) if rays else None
    return MarginsResult(
        controller=controller,
        scenario=scenario,
        options=options,
        times_s=np.asarray(times, dtype=float),
        margins=table,
        ray_boundaries=boundaries,
        seconds=time.perf_counter() - start,
    )
