"""Parameter study (``oos study``): the certified robustness margin against one scenario value.

"How heavy a target can this controller take?" ``run_study`` sets one number of the scenario
file (a dotted path, ``hubs.RH2.mass``) to each value of a sweep, rebuilds the scenario (validated
like a file: :func:`oos_drake.scenario.data.load_scenario` with ``overrides``), optionally
re-synthesizes the controller on it, and re-runs the worst-case mu analysis
(:func:`oos_drake.analysis.run.run_analysis`). The values run in parallel on
:func:`oos_drake.processes.make_executor` (``--scheduler``: local processes or Dask; one analysis
per worker, one BLAS thread each).

The margin of a value is the robust stability margin ``1 / mu`` of its worst study (the mission
and the docking phases, subset ``total``): ``margin_lower = 1 / mu_upper`` is certified (no
perturbation inside ``margin_lower`` times the uncertainty set destabilizes the loop at the
analyzed configurations and grid frequencies) and ``margin_upper = 1 / mu_lower`` is attained
(a perturbation that large is found that destabilizes it). The margin reaches 1 between the
values where ``margin_lower`` and ``margin_upper`` cross 1 (:func:`margin_crossing`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from oos_drake.analysis.run import AnalysisOptions
from oos_drake.control.synthesis import SynthesisOptions

#: Units of scenario fields by their last key (the comments of the scenario file say the same).
FIELD_UNITS = {
    "mass": "kg",
    "inertia": "kg m^2",
    "stiffness_sweep": "N/m",
    "damping": "N s/m",
    "rigid_stiffness": "N/m",
    "rigid_damping": "N s/m",
    "pointing_requirement": "rad",
    "torque_limit": "N m",
    "star_tracker_noise": "rad",
    "gyro_noise": "rad/s",
    "disturbance_gains": "N m",
    "additive_weight_db": "dB",
    "first_docking_standoff": "m",
    "grasp_approach_distance": "m",
}


def field_unit(path: str) -> str:
    """Unit of the scenario number at dotted ``path`` (``"-"`` when it has none)."""
    keys = [k for k in path.split(".") if not k.isdigit()]
    last = keys[-1]
    if last.endswith("_hz"):
        return "Hz"
    if last.endswith("_percent"):
        return "%"
    if last.startswith(("p_", "t_")) or last.endswith("_time") or last == "times":
        return "m" if last.startswith("p_") else "s"
    return FIELD_UNITS.get(last, "-")


@dataclass(frozen=True)
class Sweep:
    """One swept scenario value: ``path`` set to each of ``values``.

    Attributes
    ----------
    path : str
        Dotted path of a number in the scenario file (``hubs.RH2.mass``).
    values : tuple of float
        Values in the unit of the file (:func:`field_unit`).
    """

    path: str
    values: tuple[float, ...]

    @classmethod
    def parse(cls, text: str) -> Sweep:
        """``PATH=start:stop:n`` (``n`` equally spaced values, ends included).

        Raises
        ------
        ValueError
            One line naming the bad part (``--vary``).
        """
        path, sep, span = text.partition("=")
        parts = span.split(":")
        if not sep or not path or len(parts) != 3:
            raise ValueError(f"--vary {text!r}: expected PATH=start:stop:n")
        try:
            start, stop = float(parts[0]), float(parts[1])
            count = int(parts[2])
        except ValueError:
            raise ValueError(
                f"--vary {text!r}: start and stop must be numbers and n an integer"
            ) from None
        if not (np.isfinite(start) and np.isfinite(stop)):
            raise ValueError(f"--vary {text!r}: start and stop must be finite")
        if count < 2 or start == stop:
            raise ValueError(f"--vary {text!r}: need n >= 2 values and start != stop")
        return cls(path.strip(), tuple(float(v) for v in np.linspace(start, stop, count)))

    @property
    def column(self) -> str:
        """Table column of the swept value: ``"hubs.RH2.mass [kg]"``."""
        return f"{self.path} [{field_unit(self.path)}]"


@dataclass(frozen=True)
class StudyOptions:
    """What each value of a study runs.

    Attributes
    ----------
    controller : str or None
        ``controller.json`` analyzed at every value (None: the baseline PD tuned on each value's
        scenario), or the start of the synthesis with ``synthesize``.
    synthesize : bool
        Re-synthesize the controller on each value's scenario (``oos synth`` defaults but
        ``synthesis_configurations`` configurations).
    synthesis_configurations : int
        Mission configurations of each synthesis.
    synthesis : SynthesisOptions
        Options of each synthesis (``oos synth``'s defaults, one worker).
    analysis : AnalysisOptions
        Options of each analysis (``sweep.n_jobs`` is forced to 1: the values run in parallel).
    workers : int
        Values analyzed at the same time (worker processes).
    scheduler : str or None
        Where they run (``--scheduler``, :func:`oos_drake.processes.make_executor`): None for
        the local process pool (one worker: in this process), ``"dask"`` for a local Dask
        cluster, or an address.
    """

    controller: str | None = None
    synthesize: bool = False
    synthesis_configurations: int = 40
    synthesis: SynthesisOptions = field(default_factory=lambda: SynthesisOptions(workers=1))
    analysis: AnalysisOptions = field(
        default_factory=lambda: AnalysisOptions(
            configurations=40,
            docking_points=40,
            sensitivity=False,
            time_check=False,
            open_loop_samples=0,
            progress=False,
            guarantee=False,  # many analyses: grid-only (the guarantee's cost: ANALYSIS-RESULTS)
        )
    )
    workers: int = 2
    scheduler: str | None = None


def _run_point(scenario_file: str, path: str, value: float, options: StudyOptions, folder: str):
    """One value: scenario variant -> (synthesis) -> analysis in ``folder``; one table row."""
    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.run import run_analysis
    from oos_drake.scenario.data import load_scenario

    start = time.perf_counter()
    scenario = load_scenario(scenario_file, {path: value})
    folder = Path(folder)
    gamma = np.nan
    controller_file = options.controller
    if options.synthesize:
        gamma, controller_file = _synthesize(scenario, options, folder / "controller")
    controller = scenario_controller(controller_file, scenario)
    sweep = replace(options.analysis.sweep, n_jobs=1, scheduler=None)
    summary = run_analysis(
        controller,
        folder / "analysis",
        replace(options.analysis, sweep=sweep, progress=False),
        scenario=scenario,
        log=lambda message: None,
    )
    studies = {"mission": summary["mission"]}
    studies.update({f"docking-{k}": v for k, v in summary["docking"].items()})
    upper = {k: v.get("mu_peak_upper", v.get("mu_upper")) for k, v in studies.items()}
    lower = {k: v.get("mu_peak_lower", v.get("mu_lower")) for k, v in studies.items()}
    worst = max(upper, key=upper.get)
    mission = summary["mission"]
    row = {
        "mu upper [-]": upper[worst],
        "mu lower [-]": max(lower.values()),
        "margin lower [-]": 1.0 / upper[worst],
        "margin upper [-]": 1.0 / max(lower.values()),
        "worst study": worst,
        "mission mu upper [-]": upper["mission"],
        "mission mu lower [-]": lower["mission"],
        "mission peak time [s]": mission["peak_time_s"],
        "mission peak frequency [Hz]": mission["peak_frequency_hz"],
        "nominal stable models [-]": mission["nominal_stable_models"],
        "pointing worst gain upper [-]": summary["performance"]["e_p_peak_gain_upper"],
        "gamma [-]": gamma,
        "controller": controller.label,
        "wall time [s]": time.perf_counter() - start,
    }
    for name in studies:
        if name != "mission":
            row[f"{name} mu upper [-]"] = upper[name]
    return row


def _synthesize(scenario, options: StudyOptions, folder: Path) -> tuple[float, str]:
    """``oos synth`` on ``scenario`` (from ``options.controller`` or the baseline)."""
    from oos_drake.analysis.controller import load_controller
    from oos_drake.control.baseline import baseline_for
    from oos_drake.control.components import DesignSpecification
    from oos_drake.control.plants import scenario_plants
    from oos_drake.control.report import write_synthesis
    from oos_drake.control.synthesis import synthesize
    from oos_drake.scenario.data import scenario_record

    plants = scenario_plants(options.synthesis_configurations, scenario)
    K0 = baseline_for(plants, scenario.mission.first_docking_time)
    if options.controller:
        K0 = load_controller(options.controller).K
    result = synthesize(
        plants,
        K0,
        spec=DesignSpecification.from_requirements(scenario.control),
        options=options.synthesis,
    )
    paths = write_synthesis(
        folder, result, plants, options.synthesis, scenario_record=scenario_record(scenario)
    )
    return float(result.gamma), str(paths["controller"])


def run_study(
    scenario_file, sweep: Sweep, out_dir, options: StudyOptions | None = None, progress=True
) -> pd.DataFrame:
    """Run the study into ``out_dir``: ``study.parquet``/``.csv``, ``study.png``,
    ``summary.json`` and one ``points/<i>`` folder per value (its analysis, its controller).

    Every value's scenario is validated before any work starts (a bad path or value is a
    one-line ``ValueError`` naming the path).

    Returns
    -------
    pandas.DataFrame
        One row per value (``name [unit]`` columns).
    """
    from tqdm import tqdm

    from oos_drake.processes import make_executor
    from oos_drake.scenario.data import load_scenario, scenario_path, scenario_record

    options = options or StudyOptions()
    scenario_file = str(scenario_path(scenario_file))
    for value in sweep.values:  # validation of every value before any work
        load_scenario(scenario_file, {sweep.path: value})
    if options.controller:
        from oos_drake.analysis.controller import load_controller

        load_controller(options.controller)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    rows: dict[int, dict] = {}
    workers = max(1, min(options.workers, len(sweep.values)))
    with make_executor(workers, options.scheduler) as executor:
        futures = {
            executor.submit(
                _run_point, scenario_file, sweep.path, value, options, str(out / "points" / f"{i}")
            ): i
            for i, value in enumerate(sweep.values)
        }
        bar = tqdm(total=len(futures), desc=f"study {sweep.path}", disable=not progress)
        for future in executor.as_completed(futures):
            i = futures[future]
            rows[i] = {sweep.column: sweep.values[i], **future.result()}
            bar.update()
        bar.close()
    table = pd.DataFrame([rows[i] for i in range(len(sweep.values))])
    table.to_parquet(out / "study.parquet", index=False)
    table.to_csv(out / "study.csv", index=False)
    study_figure(table, sweep, out / "study.png")
    crossing = margin_crossing(table, sweep.column)
    summary = {
        "scenario": scenario_record(load_scenario(scenario_file)),
        "vary": {"path": sweep.path, "unit": field_unit(sweep.path), "values": sweep.values},
        "controller": options.controller or "baseline PD per value",
        "synthesize": options.synthesize,
        "margin_reaches_1": crossing,
        "wall_time_s": time.perf_counter() - start,
        "files": ["study.parquet", "study.csv", "study.png", "points"],
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    return table


def margin_crossing(table: pd.DataFrame, column: str) -> dict:
    """Where the margin bounds cross 1, linearly interpolated between swept values.

    Returns
    -------
    dict
        ``certified`` (``margin_lower`` = 1: below it, up to the first crossing, margin >= 1 is
        certified) and ``attained`` (``margin_upper`` = 1: beyond it a destabilizing perturbation
        inside the uncertainty set is found); None when the bound does not cross 1 in the sweep.
    """
    x = table[column].to_numpy(dtype=float)
    result = {}
    for key, name in (("certified", "margin lower [-]"), ("attained", "margin upper [-]")):
        y = table[name].to_numpy(dtype=float) - 1.0
        result[key] = None
        for k in range(len(x) - 1):
            if y[k] == 0 or y[k] * y[k + 1] < 0:
                t = 0.0 if y[k] == 0 else y[k] / (y[k] - y[k + 1])
                result[key] = float(x[k] + t * (x[k + 1] - x[k]))
                break
    return result


def study_figure(table: pd.DataFrame, sweep: Sweep, path) -> Path:
    """The certified margin band ``[1/mu_upper, 1/mu_lower]`` against the swept value."""
    from oos_drake.analysis.figures import pyplot, save_figure

    plt = pyplot()

    x = table[sweep.column].to_numpy(dtype=float)
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.fill_between(
        x,
        table["margin lower [-]"],
        table["margin upper [-]"],
        alpha=0.25,
        label="margin between its bounds",
    )
    ax.plot(x, table["margin lower [-]"], "o-", label="certified lower bound 1/mu_upper")
    ax.plot(x, table["margin upper [-]"], "s--", label="attained upper bound 1/mu_lower")
    ax.axhline(1.0, color="k", lw=0.8, label="margin 1 (uncertainty set just covered)")
    ax.set_xlabel(sweep.column)
    ax.set_ylabel("robust stability margin 1/mu [-]")
    ax.set_title(f"Robust stability margin against {sweep.path}")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)
