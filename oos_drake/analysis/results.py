"""What the worst-case analysis computes, as one frozen object (no file, no figure).

:func:`~oos_drake.analysis.run.compute_analysis` returns an :class:`AnalysisResult`;
:func:`~oos_drake.analysis.writers.write_analysis` writes it (the Parquet tables, the
perturbations, ``worst_cases.parquet``, the figures of :mod:`oos_drake.analysis.figures` and
``summary.json``); the ``oos run`` pipeline and ``oos analyze`` pass it on.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd

#: The paper's published numbers (section 4), written to the summary under ``"paper"`` for the
#: comparison only: none of them is a default or an input of our analysis or campaign (its
#: 0.55 Hz mission peak frequency is not listed: it used to stand in for ours in the campaign).
PAPER = {
    "mission_mu_peak": 0.79,
    "mission_peak_time_s": 275.0,
    "mission_margin_percent": 26.0,
    "docking7_mu_peak": 1.04,
    "docking7_peak_stiffness": 2.5e3,
    "docking7_peak_frequency_hz": 0.58,
    "performance_ep_peak_frequency_hz": 0.08,
}


@dataclass(frozen=True)
class Certificate:
    """The certified peak of one study and subset, whole (for re-checks and the campaign).

    Attributes
    ----------
    model : int
        Index of the critical configuration in the study's model array.
    frequency_hz : float
        Critical frequency [Hz].
    mu_lower, mu_upper : float
        The peak's interval [-] (``mu_upper`` of its scope, see ``run.peak_upper``).
    normalized : dict
        Block name -> normalized destabilizing value (float of a ``ureal``, complex matrix of
        an ``ultidyn``), of size ``mu_lower`` (unit size: ``1 / mu_lower``-scaled to the set).
    """

    model: int
    frequency_hz: float
    mu_lower: float
    mu_upper: float
    normalized: dict


@dataclass(frozen=True)
class AnalysisResult:
    """The whole worst-case analysis of one controller on one scenario (paper section 4).

    Tables are tidy, units in column names (their meaning: :mod:`oos_drake.analysis.run`).

    Attributes
    ----------
    controller : Controller
        The analyzed controller.
    scenario : Scenario
        The analyzed scenario.
    options : AnalysisOptions
        What was computed and how finely.
    grid_hz : numpy.ndarray
        The common frequency grid [Hz].
    mission : pandas.DataFrame
        mu bounds of the mission: subset x configuration x frequency (``mu_mission``).
    docking : dict of str to pandas.DataFrame
        Phase -> mu bounds of the total set, stiffness x frequency (``docking_<phase>``).
    peak_tables : dict of str to pandas.DataFrame
        Study (``"mission"``, ``"docking-7"``, ...) -> certified peak per subset.
    guaranteed_tables : tuple of pandas.DataFrame
        Per study, the whole-axis guaranteed peaks (empty frames without the guarantee).
    perturbation_tables : tuple of pandas.DataFrame
        Per study, the destabilizing perturbation of every peak, per block (physical).
    certificates : dict
        Study -> subset -> :class:`Certificate`.
    performance : pandas.DataFrame
        Worst-case gains of ``d -> e_p``, ``d -> e_u`` per subset.
    regions : tuple of WorstCaseRegion
        The critical regions of the mu-guided campaign (``worst_cases.parquet``).
    parameters : tuple of Parameter
        The blocks' physical parameters (the schema of ``worst_cases.parquet``).
    docking_peaks : dict
        Phase -> the docking peak's key numbers (``summary.json``'s ``"docking"``).
    configurations : int
        Analyzed mission configurations.
    nominal_stable_models : int
        Mission configurations whose nominal loop is stable.
    sensitivity : pandas.DataFrame or None
        Which block moves the worst-case mu most (None: not computed).
    time_check : pandas.DataFrame
        APE / torque of the perturbed closed loops (empty: not computed).
    time_signals : pandas.DataFrame or None
        The simulated signals of the time check.
    open_loop : pandas.DataFrame or None
        Sampled open-loop gains per uncertainty set.
    open_loop_title : str
        What the open-loop samples are (the figure's title).
    timings : dict
        Stage name -> wall time [s] (and per-study details), in the order run.
    spike_seconds : float
        Wall time of the spike resolution of all studies [s].
    seconds : float
        Wall time of the whole computation [s].
    """

    controller: object
    scenario: object
    options: object
    grid_hz: np.ndarray
    mission: pd.DataFrame
    docking: dict
    peak_tables: dict
    guaranteed_tables: tuple
    perturbation_tables: tuple
    certificates: dict
    performance: pd.DataFrame
    regions: tuple
    parameters: tuple
    docking_peaks: dict
    configurations: int
    nominal_stable_models: int
    sensitivity: pd.DataFrame | None = None
    time_check: pd.DataFrame = field(default_factory=pd.DataFrame)
    time_signals: pd.DataFrame | None = None
    open_loop: pd.DataFrame | None = None
    open_loop_title: str = ""
    timings: dict = field(default_factory=dict)
    spike_seconds: float = 0.0
    seconds: float = 0.0

    @property
    def peaks(self) -> pd.DataFrame:
        """Certified peak per study and subset (``stability_peaks``)."""
        return pd.concat(list(self.peak_tables.values()), ignore_index=True)

    @property
    def mission_peaks(self) -> pd.DataFrame:
        """Certified peak per subset of the mission."""
        return self.peak_tables["mission"]

    def tables(self) -> dict[str, pd.DataFrame]:
        """Every table of the analysis, by file stem, in the order they are written.

        ``worst_cases`` is the campaign's schema
        (:func:`~oos_drake.campaign.worst_cases.worst_cases_table` of :attr:`regions`); the
        whole perturbations (``peak_perturbations.npz``, from :attr:`certificates`) are not a
        table.
        """
        from oos_drake.campaign.worst_cases import worst_cases_table

        tables = {"mu_mission": self.mission}
        tables.update({f"docking_{phase}": sweep for phase, sweep in self.docking.items()})
        tables["stability_peaks"] = self.peaks
        guaranteed = [t for t in self.guaranteed_tables if not t.empty]
        if guaranteed:
            tables["stability_guaranteed"] = pd.concat(guaranteed, ignore_index=True)
        tables["worst_perturbations"] = pd.concat(list(self.perturbation_tables), ignore_index=True)
        tables["performance"] = self.performance
        if self.sensitivity is not None:
            tables["sensitivity"] = self.sensitivity
        if self.time_signals is not None:
            tables["time_check"] = self.time_check
            tables["time_signals"] = self.time_signals
        if self.open_loop is not None:
            tables["open_loop_effects"] = self.open_loop
        tables["worst_cases"] = worst_cases_table(self.regions, self.parameters)
        return tables

    def summary(self) -> dict:
        """The key numbers of ``summary.json`` (all but its ``"files"``): scenario, controller,
        loop, mission peak, subsets, docking, performance, time check, the paper's values,
        options and timings [s]."""
        from oos_drake.scenario.data import scenario_record

        controller = self.controller
        spec = controller.spec
        peaks = self.mission_peaks
        tot = peaks[peaks["subset"] == "total"].iloc[0]
        perf = self.performance
        ep = perf[perf["channel"] == "e_p"]
        ep_peak = ep.loc[ep["gain upper [-]"].idxmax()]
        return {
            "scenario": scenario_record(self.scenario),
            "controller": {
                "label": controller.label,
                "source": controller.source,
                "gamma": controller.gamma,
                "structure": controller.structure,
                **({"K": controller.K.tolist()} if controller.is_static else {}),
                "state_space": controller.system.record(),
            },
            "loop": {
                "sampled": spec.sampled,
                "sample_rate_hz": spec.flight_software_rate_hz,
                "delay_s": spec.computation_delay_s,
                "hold_order": spec.hold_order,
            },
            "mission": {
                "configurations": int(self.configurations),
                "grid_frequencies": int(self.grid_hz.size),
                "nominal_stable_models": int(self.nominal_stable_models),
                "mu_peak_upper": float(tot["mu upper [-]"]),
                "mu_peak_upper_scope": str(tot["mu upper scope"]),
                "mu_peak_upper_grid": float(tot["mu upper grid [-]"]),
                "mu_peak_upper_refined": float(tot["mu upper grid [-]"]),
                "mu_peak_lower": float(tot["mu lower [-]"]),
                "mu_upper_at_critical": float(tot["mu upper at critical [-]"]),
                "gap_percent": float(tot["gap [%]"]),
                "gap_at_critical_percent": float(tot["gap at critical [%]"]),
                "peak_time_s": float(tot["time [s]"]),
                "peak_frequency_hz": float(tot["frequency [Hz]"]),
                "upper_peak_time_s": float(tot["peak time [s]"]),
                "upper_peak_frequency_hz": float(tot["peak frequency [Hz]"]),
                "stability_margin": float(tot["margin [-]"]),
                "spikes_left": int(tot["spikes left"]),
                "spike_stop": str(tot["spike stop"]),
                "budget_exhausted": bool(tot["budget exhausted"]),
                "guarantee_fell_back": bool(tot.get("guarantee fell back", False)),
            },
            "subsets": peaks.drop(columns=["study"]).to_dict(orient="records"),
            "docking": self.docking_peaks,
            "performance": {
                "e_p_peak_gain_upper": float(ep_peak["gain upper [-]"]),
                "e_p_peak_frequency_hz": float(ep_peak["frequency [Hz]"]),
                "e_u_peak_gain_upper": float(
                    perf.loc[perf["channel"] == "e_u", "gain upper [-]"].max()
                ),
            },
            "time_check": self.time_check.to_dict(orient="records"),
            "paper": PAPER,
            "options": asdict(self.options),
            "timings_s": dict(self.timings),
        }
