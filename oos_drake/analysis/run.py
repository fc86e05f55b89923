"""The whole worst-case analysis (paper section 4): :func:`compute_analysis` returns an
:class:`~oos_drake.analysis.results.AnalysisResult` (no file written),
:func:`~oos_drake.analysis.writers.write_analysis` writes it, :func:`run_analysis` does both.

Files written in ``out_dir`` (Parquet tables are tidy, units in column names):

``mu_mission.parquet``          mu bounds: subset x configuration x frequency (Fig. muanalysis)
``stability_peaks.parquet``     certified peak per subset: time, frequency, bounds, gap, margin; the
                                peak's interval is ``[mu lower [-], mu upper [-]]``: the best
                                certified lower bound found (grid, refinement, searches) and the
                                whole-axis guaranteed bound (``mu upper scope``: "whole axis";
                                with --grid-only the analyzed points' bound, "analyzed points");
                                the grid's largest upper bound is ``mu upper grid [-]``;
                                ``guarantee fell back``: a cover did not close at the first
                                level (``--guarantee-tight``) and was done again from
                                ``(1 + target gap)`` x the lower bound
``stability_guaranteed.parquet`` per study, subset and analyzed configuration: the peak of mu
                                proved on the whole frequency axis beside the largest lower and
                                upper bounds on the analyzed frequencies, ``cover fell back``
                                (not with ``--grid-only``)
``worst_perturbations.parquet`` destabilizing perturbation of every peak, per block (physical)
``peak_perturbations.npz``      the same perturbations whole and normalized (complex blocks too)
``performance.parquet``         worst-case gains of d -> e_p, d -> e_u per subset (Fig. performance)
``docking_<7|8>.parquet``       mu (Delta_tot), stiffness x frequency (Fig. mu_analysis_SM)
``sensitivity.parquet``         which block moves the worst-case mu most (Fig. unc_sensitivity)
``time_check.parquet``          APE / torque of the perturbed closed loops vs the requirements
``time_signals.parquet``        the simulated signals
``worst_cases.parquet``         critical regions for the mu-guided campaign (campaign schema)
``open_loop_effects.parquet``   sampled open-loop gains per uncertainty set (Fig. unc_sensitivity)
``summary.json``                controller, key numbers, paper values, timings
``*.png``                       the figures
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from oos_drake.analysis.controller import Controller
from oos_drake.analysis.results import PAPER, AnalysisResult, Certificate  # noqa: F401 (PAPER)
from oos_drake.analysis.stability import TIGHT_GAP, SweepOptions
from oos_drake.analysis.tightening import TightenOptions
from oos_drake.blas import with_single_threaded_blas


@dataclass(frozen=True)
class AnalysisOptions:
    """What the analysis computes and how finely.

    Attributes
    ----------
    configurations : int
        Equally spaced mission configurations (paper: 330).
    frequency_range_hz : tuple of float
        Span of the common frequency grid [Hz].
    points_per_decade : int
        Density of the common logarithmic grid.
    sweep : SweepOptions
        Accuracy and parallelism of the mu sweeps.
    docking_phases : tuple of str
        Docking phases studied (schema 1: ``"7"``, ``"8"``; a tree: its docking events,
        ``scenario.mission.docking_phases``); checked against the scenario's before any work.
    docking_points : int
        Stiffness values per phase (paper: 300).
    stiffness_range : tuple of float
        Swept stiffness span [N/m or N m/rad] (paper: 0.1 .. 1e5, log spaced).
    performance_models : int
        Equally spaced configurations of the worst-case gain study (the critical one and those
        of every certified peak, the campaign regions, are added).
    performance_points : int
        Frequencies of the worst-case gain study.
    certify_iterations : int
        BFGS iterations of the upper bound at the critical frequency of each certificate
        (the sensitivity study uses half).
    open_loop_samples : int
        Samples per uncertainty set of the open-loop figure (0: skip).
    tighten : TightenOptions
        Target gap of the certified peaks and effort of the spike resolution
        (:mod:`oos_drake.analysis.tightening`).
    spike_budget : float
        Wall-clock budget of the spike resolution of the whole analysis [s] (all studies and
        subsets; each subset also keeps ``tighten.time_budget``). With the grid sweeps, it
        bounds the run time whatever the controller; where it cuts the resolution short, the
        peaks table says so (``budget exhausted``, ``spike stop``).
    sensitivity : bool
        Compute the sensitivity table.
    sensitivity_iterations : int
        BFGS iterations of its upper bounds.
    time_check : bool
        Run the time-domain check.
    time_check_duration : float
        Simulated time [s].
    guarantee : bool
        Prove each analyzed configuration's mu peak on the whole frequency axis
        (:func:`~oos_drake.analysis.stability.axis_guarantee`, from the level
        ``(1 + tighten.target_gap)`` times the certified lower bound; timed as ``guarantee`` in
        each study's timing detail, beside the grid-only ``grid`` and ``tighten+certify``).
        On by default (``oos analyze --grid-only`` turns it off; cost: docs/ANALYSIS-RESULTS.md).
        Without it the upper bounds hold on the analyzed frequencies only (``oos confirm``
        found one broken between them, docs/CLAIMS.md A11).
    guarantee_tight : float
        Relative margin [-] of the guarantee's first level above the largest bound found
        (``tight`` of :func:`~oos_drake.analysis.stability.axis_guarantee`, default
        :data:`~oos_drake.analysis.stability.TIGHT_GAP`: 0.015, 1.5 %); a configuration whose
        cover does not close there is covered again from ``(1 + tighten.target_gap)`` times
        the certified lower bound (``guarantee fell back`` in the peaks table).
    progress : bool
        tqdm progress bars.
    plant : str
        Source of the uncertain plants: ``"lfr"`` (the TITOP LFR, substituted) or ``"drake"``
        (LFRs extracted from the Drake twin by ``ulinearize``, same blocks).
    """

    configurations: int = 330
    frequency_range_hz: tuple = (0.005, 5.0)
    points_per_decade: int = 12
    sweep: SweepOptions = field(default_factory=SweepOptions)
    docking_phases: tuple = ("7", "8")
    docking_points: int = 300
    stiffness_range: tuple = (0.1, 1.0e5)
    performance_models: int = 6
    performance_points: int = 24
    certify_iterations: int = 1000
    tighten: TightenOptions = field(default_factory=TightenOptions)
    spike_budget: float = 240.0
    open_loop_samples: int = 20
    sensitivity: bool = True
    sensitivity_iterations: int = 150
    time_check: bool = True
    time_check_duration: float = 600.0
    guarantee: bool = True
    guarantee_tight: float = TIGHT_GAP
    progress: bool = True
    plant: str = "lfr"

    def __post_init__(self):
        # checked here, before any work: a bad option must not cost a mission sweep
        lo, hi = self.frequency_range_hz
        if not 0 < lo < hi:
            raise ValueError(
                f"frequency_range_hz must be 0 < low < high, got {self.frequency_range_hz}"
            )
        for name in ("configurations", "points_per_decade", "docking_points"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        k_lo, k_hi = self.stiffness_range
        if not 0 < k_lo <= k_hi:
            raise ValueError(f"stiffness_range must be 0 < low <= high, got {self.stiffness_range}")
        if not (np.isfinite(self.guarantee_tight) and self.guarantee_tight >= 0):
            raise ValueError(
                "guarantee_tight must be a finite relative margin >= 0 [-], got "
                f"{self.guarantee_tight}"
            )
        from oos_drake.analysis.models import PLANT_SOURCES

        if self.plant not in PLANT_SOURCES:
            raise ValueError(f"plant must be one of {PLANT_SOURCES}, got {self.plant!r}")

    def grid(self) -> np.ndarray:
        """Common frequency grid [rad/s]."""
        lo, hi = self.frequency_range_hz
        n = max(int(round(self.points_per_decade * np.log10(hi / lo))) + 1, 3)
        return 2 * np.pi * np.geomspace(lo, hi, n)


def _certify(array, study, subsets, *, configuration_label):
    """Peak table rows and destabilizing perturbations from a :class:`StudyResult`."""
    from oos_drake.analysis.worst_cases import physical_values

    sys = array.system
    rows, perturbation_rows, certificates = [], [], {}
    for name, cert in study.certificates.items():
        report = study.reports[name]
        model = cert.model
        lower, upper_grid = cert.mu_lower, cert.mu_upper
        upper, upper_scope = peak_upper(cert, study.guarantees.get(name))
        rows.append(
            {
                "study": array.study,
                "subset": name,
                "model": model,
                array.label: float(array.values[model]),
                "frequency [Hz]": cert.frequency,
                "mu lower [-]": lower,
                "mu upper [-]": upper,
                "mu upper scope": upper_scope,
                "mu upper at critical [-]": cert.mu_upper_critical,
                "mu upper grid [-]": upper_grid,
                "gap [%]": 100.0 * (upper - lower) / upper if upper > 0 else 0.0,
                "gap at critical [%]": 100.0 * cert.gap_critical,
                "margin [-]": 1.0 / upper if upper > 0 else np.inf,
                "peak model": cert.peak_model,
                f"peak {array.label}": float(array.values[cert.peak_model]),
                "peak frequency [Hz]": cert.peak_frequency,
                "lower source": cert.source,
                "spike rounds": report.rounds,
                "spikes left": cert.spikes_left,
                "spikes converged": report.converged,
                "refinement points": report.points_added,
                "searched models": len(report.searched_models),
                "spike stop": report.stop,
                "budget exhausted": bool(report.budget_exhausted),
                "spike time [s]": round(report.seconds, 2),
                "spike work [point-iterations]": float(report.work),
                "configuration": configuration_label(model),
                **_guarantee_columns(study.guarantees.get(name), lower, len(array.values)),
            }
        )
        normalized = cert.worst_case_normalized
        certificates[name] = Certificate(
            int(model), float(cert.frequency), lower, upper, normalized
        )
        one = sys.model(model) if sys.batch_shape else sys
        specs = one.uncertainty
        phys_unit = physical_values(one, normalized, lower)
        for bname, value in normalized.items():
            arr = np.atleast_2d(np.asarray(value, dtype=complex))
            kind = specs[bname].kind
            destab = (
                float(specs[bname].to_physical(float(arr[0, 0].real)))
                if kind == "ureal"
                else float(np.linalg.norm(arr, ord=2)) * specs[bname].bound
            )
            perturbation_rows.append(
                {
                    "study": array.study,
                    "subset": name,
                    "block": bname,
                    "kind": kind,
                    "unit": specs[bname].unit,
                    "normalized norm [-]": float(np.linalg.norm(arr, ord=2)),
                    "normalized real [-]": float(arr[0, 0].real),
                    "normalized imag [-]": float(arr[0, 0].imag),
                    "destabilizing value [unit]": destab,
                    "in set value [unit]": phys_unit.get(bname, np.nan),
                }
            )
    return pd.DataFrame(rows), pd.DataFrame(perturbation_rows), certificates


def peak_upper(cert, guarantee) -> tuple[float, str]:
    """The upper end of a peak's interval and what it covers.

    The whole-axis guaranteed bound when the subset has one (every analyzed configuration,
    every frequency in ``[0, inf)``), else the largest upper bound on the analyzed points.
    Never below the certified lower bound (both are certificates; round-off only).

    Parameters
    ----------
    cert : PeakCertificate
        The subset's certified peak (``mu_lower``: the best lower bound of the grid, the
        refinements and the searches; ``mu_upper``: the largest upper bound of the grid).
    guarantee : AxisGuarantee or None
        The subset's whole-axis guarantee.

    Returns
    -------
    (float, str)
        The bound [-] and its scope (``"whole axis"`` or ``"analyzed points"``).
    """
    if guarantee is not None and np.isfinite(guarantee.mu_upper):
        return max(float(guarantee.mu_upper), float(cert.mu_lower)), "whole axis"
    return max(float(cert.mu_upper), float(cert.mu_lower)), "analyzed points"


def _guarantee_columns(guarantee, lower, n_configurations) -> dict:
    """Peak-table columns of an :class:`~oos_drake.analysis.stability.AxisGuarantee`."""
    if guarantee is None:
        return {}
    up = guarantee.mu_upper
    return {
        "mu upper guaranteed [-]": up,
        "gap guaranteed [%]": 100.0 * (up - lower) / up if up > 0 else 0.0,
        "margin guaranteed [-]": 1.0 / up if up > 0 else np.inf,
        "guarantee slack [%]": 100.0 * guarantee.slack,
        "guarantee points": int(guarantee.points.sum()),
        "guarantee solved points": int(guarantee.solved.sum()),
        "guarantee raised configurations": guarantee.raised,
        "guarantee failures": len(guarantee.failures),
        "guarantee fell back": bool(np.any(guarantee.fell_back)),
        "guarantee time [s]": round(guarantee.seconds, 2),
        "guarantee scope": (
            f"every frequency in [0, inf) at each of the {n_configurations} analyzed "
            "configurations; configurations between them are sampled, not covered"
        ),
    }


def guaranteed_table(study: str, result, label: str, values) -> pd.DataFrame:
    """Per subset and analyzed configuration of a :class:`StudyResult`: the whole-axis
    guaranteed peak of mu beside the largest bounds on the analyzed frequencies."""
    frames = []
    for name, g in result.guarantees.items():
        frames.append(
            pd.DataFrame(
                {
                    "study": study,
                    "subset": name,
                    "model": g.models,
                    label: np.asarray(values, dtype=float)[g.models],
                    "mu upper guaranteed [-]": g.levels,
                    "mu upper on grid [-]": g.grid_upper,
                    "mu lower on grid [-]": g.grid_lower,
                    "cover points": g.points,
                    "cover solved points": g.solved,
                    "level raised": g.levels > g.floor * (1 + 1e-12),
                    "cover fell back": np.asarray(g.fell_back, dtype=bool),
                }
            )
        )
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _moment_label(times, scenario):
    from oos_drake.scenario.timeline import mission_timeline

    try:
        named = mission_timeline(scenario).moments
        moments = sorted((m.time, k) for k, m in named.items())
    except Exception:  # noqa: BLE001 - labels are cosmetic
        moments = []

    def label(model):
        t = float(times[model])
        if not moments:
            return f"mission t={t:.0f}s"
        tm, name = min(moments, key=lambda m: abs(m[0] - t))
        return f"mission t={t:.0f}s (near moment {name} at {tm:.0f}s)"

    return label


def run_analysis(
    controller: Controller,
    out_dir,
    options: AnalysisOptions | None = None,
    *,
    scenario,
    log=print,
) -> dict:
    """Compute the worst-case analysis and write every table and figure in ``out_dir``.

    :func:`compute_analysis` then :func:`~oos_drake.analysis.writers.write_analysis`.

    Parameters
    ----------
    controller : Controller
        From :func:`~oos_drake.analysis.controller.load_controller` (or the labeled baseline).
    out_dir : str or Path
        Output directory (created).
    options : AnalysisOptions, optional
    scenario : Scenario
        The analyzed scenario (its models, timeline and record in ``summary.json``).
    log : callable
        Progress messages.

    Returns
    -------
    dict
        The summary written to ``summary.json`` (key numbers, paths, timings).
    """
    from oos_drake.analysis.writers import write_analysis

    result = compute_analysis(controller, options, scenario=scenario, log=log)
    return write_analysis(result, out_dir, log=log)


@with_single_threaded_blas  # restored on return: callers keep their BLAS threads
def compute_analysis(
    controller: Controller,
    options: AnalysisOptions | None = None,
    *,
    scenario,
    log=print,
) -> AnalysisResult:
    """Compute the worst-case analysis (paper section 4); nothing is written.

    Parameters
    ----------
    controller : Controller
        From :func:`~oos_drake.analysis.controller.load_controller` (or the labeled baseline).
    options : AnalysisOptions, optional
    scenario : Scenario
        The analyzed scenario (its models and timeline).
    log : callable
        Progress messages.

    Returns
    -------
    AnalysisResult
        Tables, certificates, worst-case regions, key numbers and timings [s].
    """
    from oos_drake.analysis.models import mission_closed_loop, mission_times
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.analysis.worst_cases import block_parameters
    from oos_drake.processes import make_executor

    options = options or AnalysisOptions()
    known = [str(p.name) for p in scenario.mission.docking_phases]
    unknown = [p for p in options.docking_phases if str(p) not in known]
    if unknown:
        listed = ", ".join(known) or "none"
        raise ValueError(f"--docking: unknown docking phase {unknown[0]!r} (phases: {listed})")
    timings = {}
    clock = _time.perf_counter()
    t_start = clock

    def lap(name):
        nonlocal clock
        now = _time.perf_counter()
        timings[name] = round(now - clock, 2)
        log(f"  [{name}: {now - clock:.1f} s]")
        clock = now

    omega = options.grid()
    # ------------------------------------------------------------------ mission stability
    times = mission_times(options.configurations, scenario)
    if options.plant == "drake":  # one ulinearize per configuration: on spawned workers
        with make_executor(
            options.sweep.n_jobs, options.sweep.scheduler, method="spawn"
        ) as extraction:
            mission = mission_closed_loop(
                controller, times, scenario, source="drake", executor=extraction
            )
    else:
        mission = mission_closed_loop(controller, times, scenario, source=options.plant)
    subsets = uncertainty_subsets(mission.system.uncertainty)
    abscissa = np.linalg.eigvals(np.asarray(mission.system.A)).real.max(axis=-1)
    lap("build mission models")
    log(
        f"mission: {times.size} configurations, {omega.size} grid frequencies, "
        f"subsets {list(subsets)}; nominal loops stable: {int((abscissa < 0).sum())}/{times.size}"
    )
    study = _Studies(options, omega)
    result = study(mission.system, subsets, times, "mu mission")
    lap("mu sweep mission (grid + certified peaks)")
    timings["mu mission detail"] = {k: round(v, 2) for k, v in result.timings.items()}
    label = _moment_label(times, scenario)
    peaks, perturbations, certs = _certify(mission, result, subsets, configuration_label=label)
    peak_tables = {"mission": peaks}
    perturbation_tables = [perturbations]
    guaranteed_tables = [guaranteed_table("mission", result, "time [s]", times)]
    certificates = {"mission": certs}
    # ------------------------------------------------------------------ docking
    docking_sweeps, docking_peaks = {}, {}
    stiffness = np.geomspace(*options.stiffness_range, options.docking_points)
    for phase in options.docking_phases:
        study_name = f"docking-{phase}"
        dres, tables, certificates[study_name] = _docking_study(
            controller, scenario, phase, stiffness, study, options
        )
        docking_sweeps[phase], peak_tables[study_name] = tables[0], tables[1]
        guaranteed_tables.append(tables[2])
        perturbation_tables.append(tables[3])
        docking_peaks[phase] = _docking_peak(tables[1].iloc[0])
        timings[f"docking {phase} detail"] = {k: round(v, 2) for k, v in dres.timings.items()}
        lap(f"docking phase {phase}")
    # ------------------------------------------------------------------ performance
    perf, perf_deltas, perf_models = _performance(mission, times, subsets, certs, peaks, options)
    lap("worst-case performance")
    regions = _regions(mission, times, subsets, certs, peaks, perf, label)
    # ------------------------------------------------------------------ sensitivity
    sens = None
    if options.sensitivity:
        sens = _sensitivity(mission, result.table, certs, options)
        lap("sensitivity")
    # ------------------------------------------------------------------ time-domain check
    tsum, signals = pd.DataFrame(), None
    if options.time_check:
        tsum, signals = _time_check(
            mission, controller, times, certs, perf, perf_deltas, perf_models, options
        )
        lap("time-domain check")
    # ------------------------------------------------------------------ open-loop effects
    effects, effects_title = None, ""
    if options.open_loop_samples > 0:
        effects, effects_title = _open_loop(controller, scenario, options)
        lap("open-loop effects")
    return AnalysisResult(
        controller=controller,
        scenario=scenario,
        options=options,
        grid_hz=omega / (2 * np.pi),
        mission=result.table,
        docking=docking_sweeps,
        peak_tables=peak_tables,
        guaranteed_tables=tuple(guaranteed_tables),
        perturbation_tables=tuple(perturbation_tables),
        certificates=certificates,
        performance=perf,
        regions=tuple(regions),
        parameters=tuple(block_parameters(mission.system)),
        docking_peaks=docking_peaks,
        configurations=int(times.size),
        nominal_stable_models=int((abscissa < 0).sum()),
        sensitivity=sens,
        time_check=tsum,
        time_signals=signals,
        open_loop=effects,
        open_loop_title=effects_title,
        timings=timings,
        spike_seconds=study.spike_seconds,
        seconds=_time.perf_counter() - t_start,
    )


class _Studies:
    """The analysis' certified sweeps, sharing one spike-resolution budget
    (:attr:`AnalysisOptions.spike_budget`) in the order they run."""

    def __init__(self, options: AnalysisOptions, omega: np.ndarray):
        self.options = options
        self.omega = omega
        self.spike_seconds = 0.0

    def __call__(self, system, sets, grid, description):
        """mu bounds on the common grid, spikes resolved, a certified peak per subset."""
        from oos_drake.analysis.stability import certified_sweep

        options = self.options
        res = certified_sweep(
            system,
            self.omega,
            sets,
            times=grid,
            options=options.sweep,
            tighten=options.tighten,
            critical_iterations=options.certify_iterations,
            progress=options.progress,
            description=description,
            time_budget=max(options.spike_budget - self.spike_seconds, 1e-3),
            guarantee=options.guarantee,
            guarantee_gap=options.tighten.target_gap,
            guarantee_tight=options.guarantee_tight,
        )
        self.spike_seconds += sum(r.seconds for r in res.reports.values())
        return res


def _docking_study(controller, scenario, phase, stiffness, study, options):
    """The certified sweep of the total set over the stiffness of docking ``phase``:
    ``(study result, (sweep, peaks, guaranteed, perturbations) tables, {"total": cert})``."""
    from oos_drake.analysis.models import docking_closed_loop
    from oos_drake.analysis.subsets import uncertainty_subsets

    arr = docking_closed_loop(controller, phase, stiffness, scenario=scenario, source=options.plant)
    tot = {"total": uncertainty_subsets(arr.system.uncertainty)["total"]}
    dres = study(arr.system, tot, stiffness, f"mu docking {phase}")
    sweep = dres.table.rename(columns={"time [s]": "stiffness [N/m or N m/rad]"})
    peaks, perturbations, certs = _certify(
        arr,
        dres,
        tot,
        configuration_label=lambda m: f"docking-{phase} k={stiffness[m]:.3g}",
    )
    guaranteed = guaranteed_table(f"docking-{phase}", dres, "stiffness [N/m or N m/rad]", stiffness)
    return dres, (sweep, peaks, guaranteed, perturbations), {"total": certs["total"]}


def _docking_peak(row) -> dict:
    """``summary.json``'s numbers of a docking phase's peak (its peak table's row)."""
    return {
        "stiffness": float(row["stiffness [N/m or N m/rad]"]),
        "gap [%]": float(row["gap [%]"]),
        "mu_upper_grid": float(row["mu upper grid [-]"]),
        "frequency [Hz]": float(row["frequency [Hz]"]),
        "mu_lower": float(row["mu lower [-]"]),
        "mu_upper": float(row["mu upper [-]"]),
        "mu_upper_scope": str(row["mu upper scope"]),
        "peak_stiffness": float(row["peak stiffness [N/m or N m/rad]"]),
        "peak frequency [Hz]": float(row["peak frequency [Hz]"]),
        "spikes left": int(row["spikes left"]),
        "spike stop": str(row["spike stop"]),
        "budget exhausted": bool(row["budget exhausted"]),
        "mu_upper_guaranteed": float(row.get("mu upper guaranteed [-]", np.nan)),
        "guarantee_fell_back": bool(row.get("guarantee fell back", False)),
    }


def _performance(mission, times, subsets, certs, peaks, options):
    """Worst-case gains at the critical configuration, every region's (for the campaign's
    like-for-like comparison) and equally spaced ones: ``(table, deltas, models)``."""
    from oos_drake.analysis.performance import worst_case_gains

    crit_model = certs["total"].model
    region_models = [certs[name].model for name in peaks["subset"]]
    spread = np.linspace(0, times.size - 1, max(options.performance_models - 1, 1)).round()
    models = np.unique(np.concatenate([[crit_model], region_models, spread.astype(int)]))
    lo_hz, hi_hz = options.frequency_range_hz
    w_perf = (
        2 * np.pi * np.geomspace(max(lo_hz, 0.005), min(hi_hz, 3.0), options.performance_points)
    )
    w_perf = np.unique(np.concatenate([w_perf, [2 * np.pi * certs["total"].frequency_hz]]))
    perf, perf_deltas = worst_case_gains(
        mission.system,
        models,
        w_perf,
        subsets,
        times=times,
        n_jobs=options.sweep.n_jobs,
        scheduler=options.sweep.scheduler,
        progress=options.progress,
    )
    return perf, perf_deltas, models


def _regions(mission, times, subsets, certs, peaks, perf, label) -> list:
    """The critical regions of the mu-guided campaign, one per subset's certified peak."""
    from oos_drake.analysis.performance import peak_gains
    from oos_drake.analysis.worst_cases import physical_values
    from oos_drake.campaign.worst_cases import WorstCaseRegion

    regions = []
    for index, subset in enumerate(peaks["subset"]):
        c = certs[subset]
        regions.append(
            WorstCaseRegion(
                index,
                label(c.model),
                max(float(times[c.model]), 0.0),
                float(c.frequency_hz),
                float(c.mu_upper),
                float(min(c.mu_lower, c.mu_upper)),
                ",".join(subsets[subset]),
                physical_values(mission.system, c.normalized, c.mu_lower),
                peak_gains(perf, subset, int(c.model)),
            )
        )
    return regions


def _sensitivity(mission, sweep, certs, options) -> pd.DataFrame:
    """Which block moves the worst-case mu most, at the critical configuration."""
    from oos_drake.analysis.sensitivity import mu_sensitivity

    crit_model = certs["total"].model
    part = sweep[(sweep["subset"] == "total") & (sweep["model"] == crit_model)]
    top = part.nlargest(6, "mu upper [-]")["frequency [Hz]"].to_numpy()
    w_crit = 2 * np.pi * certs["total"].frequency_hz
    w_s = np.unique(np.concatenate([2 * np.pi * top, w_crit * np.geomspace(0.97, 1.03, 3)]))
    return mu_sensitivity(
        mission.system, crit_model, w_s, iterations=options.sensitivity_iterations
    )


def _time_check(mission, controller, times, certs, perf, perf_deltas, models, options):
    """The nominal, worst-stability and worst-APE loops at the critical configuration
    simulated: ``(summary table, signals)``."""
    from oos_drake.analysis.time_check import check_case

    rows, signals = [], []
    crit = certs["total"]
    crit_model = crit.model
    one = mission.system.model(crit_model)
    w_c = 2 * np.pi * crit.frequency_hz
    cases = [
        ("nominal", {}, 1.0, w_c),
        ("worst stability (unit size)", crit.normalized, crit.mu_lower, w_c),
    ]
    pk = perf[
        (perf["channel"] == "e_p") & (perf["subset"] == "total") & (perf["model"] == crit_model)
    ]
    if len(pk):
        j = int(np.argmax(pk["gain lower [-]"].to_numpy()))
        wj = 2 * np.pi * float(pk["frequency [Hz]"].iloc[j])
        k_model = int(np.flatnonzero(models == crit_model)[0])
        dl = perf_deltas[("e_p", "total")][k_model, j]
        from oos_drake.robust.blocks import parse_blk
        from oos_drake.robust.lfr_analysis import block_map, normalized_worst_case

        bmap = block_map(one)
        norm_p = normalized_worst_case(bmap, parse_blk(bmap.blk), dl)
        cases.append(("worst APE gain (unit size)", norm_p, 1.0, wj))
    for case, values, scale, w in cases:
        scaled = {k: v * scale for k, v in values.items()}  # unit size: inside the set
        row, sig = check_case(
            one,
            scaled,
            w,
            controller.spec,
            case=case,
            study="mission",
            model=crit_model,
            time=float(times[crit_model]),
            scale=scale,
            duration=options.time_check_duration,
        )
        rows.append(row)
        signals.append(sig)
    return pd.DataFrame(rows), pd.concat(signals, ignore_index=True)


def _open_loop(controller, scenario, options) -> tuple[pd.DataFrame, str]:
    """Sampled open-loop gains per uncertainty set at moment 2, and their description."""
    from oos_drake.analysis.models import mission_plants
    from oos_drake.analysis.open_loop import uncertainty_effects
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.control.analysis_model import uncertain_plant
    from oos_drake.scenario.timeline import mission_timeline

    t_moment = float(mission_timeline(scenario).moments["2"].time)
    plant = mission_plants([t_moment], scenario, source=options.plant).model(0)
    p_hat = uncertain_plant(plant, controller.spec)
    effects = uncertainty_effects(
        p_hat,
        uncertainty_subsets(p_hat.uncertainty),
        2 * np.pi * np.geomspace(0.05, 20.0, 300),
        samples=options.open_loop_samples,
        rng=np.random.default_rng(0),
    )
    title = (
        f"T_ext,G1{{1}} -> wdot{{1}} at moment 2 (t = {t_moment:g} s): samples of "
        "each uncertainty set"
    )
    return effects, title
