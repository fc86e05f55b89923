"""The results folder of ``oos run`` read back: tables, records, figures, and the headline numbers.

:func:`load_run` reads what each stage wrote (a stage that did not run, or a table that is not
there, is ``None``: the report says "not run" for it); :func:`headline_numbers` picks the ten
numbers a reviewer looks at first, each with its unit and the file and column it was read from.

Folder layout read (``OUT`` = ``oos run --out``)::

    OUT/timings.json                 wall time of each stage of the last ``oos run``
    OUT/<stage>/stage.json           the stage's key and the wall time of its computation [s]
    OUT/model/*.png                  model figures
    OUT/model/blocks.parquet         the mission LFR's uncertain blocks (unit, nominal, range)
    OUT/validate/validate.txt        Drake-vs-TITOP validation table (text)
    OUT/controller/controller.json   gains, gamma, requirement met, design specification
    OUT/analysis/summary.json        scenario record (file, SHA-256), key numbers
    OUT/analysis/stability_peaks.parquet, worst_perturbations.parquet, *.png
    OUT/confirm/confirmation.parquet, performance_confirmation.parquet, *.png
    OUT/margins/margins.parquet, margins.png
    OUT/campaign-<key>/report/summary.parquet, worst_runs.parquet, regions.parquet,
                                     violations.parquet, *.png
    OUT/campaign-<key>/replay/case_<N>.html
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from oos_drake.campaign.performance import PERFORMANCE_CONFIRMATION_FILE as PERFORMANCE_FILE
from oos_drake.campaign.performance import REQUIREMENT_NAMES, worst_twin_row, worst_twin_where

#: Stage folders of ``oos run``, in the order they run.
STAGES = ("model", "validate", "controller", "analysis", "confirm", "margins")
#: Subsets of the analysis, in the order of its figures (``oos_drake.analysis.subsets``).
SUBSETS = ("total", "real", "modal", "mechanical", "additive", "multiplicative")
#: Figures shown first (file stems), in this order: the headline figure of each stage.
FIGURE_ORDER = (
    "mu_mission",
    "mu_docking",
    "performance",
    "time_check",
    "margins",
    "regions_performance",
    "metric_distributions",
    "worst_runs",
)
#: Row of the campaign summary that counts a run as failed for any reason.
ANY_FAILURE = "any (requirement or run failure)"
#: Margin columns of ``margins.parquet`` whose mission-wide minimum is a headline: column ->
#: (headline key, label, unit).
MARGIN_HEADLINES = {
    "gain margin upper [dB]": ("gain_margin", "worst gain margin (gain increase)", "dB"),
    "phase margin [deg]": ("phase_margin", "worst phase margin", "deg"),
}


@dataclass(frozen=True)
class Headline:
    """One headline number of a run.

    Attributes
    ----------
    key : str
        Identifier (``"gamma"``, ``"mu_total"``, ...), the ``data-headline`` of the HTML report.
    label : str
        What the number is, for a reader.
    value : float
        The number, in ``unit``.
    unit : str
        Its unit (``"-"`` for a dimensionless number).
    source : str
        File (relative to the results folder) and column or key it was read from.
    where : str
        Where it occurs (configuration, loop, frequency), empty when it does not apply.
    """

    key: str
    label: str
    value: float
    unit: str
    source: str
    where: str = ""


@dataclass(frozen=True)
class RunResults:
    """What an ``oos run`` results folder holds (``None``: not there).

    Attributes
    ----------
    out : pathlib.Path
        The results folder.
    timings : dict or None
        ``timings.json``.
    stage_seconds : dict
        Stage name -> wall time of the computation that produced its folder [s] (``stage.json``).
    controller : dict or None
        ``controller/controller.json``.
    analysis_summary : dict or None
        ``analysis/summary.json``.
    peaks, guaranteed, perturbations : pandas.DataFrame or None
        ``analysis/stability_peaks.parquet``, ``stability_guaranteed.parquet``,
        ``worst_perturbations.parquet``.
    confirmation : pandas.DataFrame or None
        ``confirm/confirmation.parquet``.
    performance : pandas.DataFrame or None
        ``confirm/performance_confirmation.parquet``: the analysis' worst-case gains run on
        the twin (:mod:`oos_drake.analysis.performance_twin`).
    margins : pandas.DataFrame or None
        ``margins/margins.parquet``.
    campaign : pathlib.Path or None
        The campaign folder (``campaign-<key>``).
    campaign_summary, worst_runs, regions, campaign_status : pandas.DataFrame or None
        The campaign report's ``summary``, ``worst_runs``, ``regions`` and ``status`` tables.
    violations : pandas.DataFrame or None
        The campaign report's ``violations`` table: every violation with its requirement,
        mission phase and the time of the first violation.
    campaign_environment : dict or None
        ``environment.json`` of the campaign (versions of the packages that ran it).
    blocks : pandas.DataFrame or None
        ``model/blocks.parquet``: the mission LFR's uncertain blocks (unit, nominal, range).
    validation : str or None
        ``validate/validate.txt``.
    replays : tuple of pathlib.Path
        The campaign's 3-D replays (``replay/case_N.html``).
    """

    out: Path
    timings: dict | None
    stage_seconds: dict
    controller: dict | None
    analysis_summary: dict | None
    peaks: pd.DataFrame | None
    guaranteed: pd.DataFrame | None
    perturbations: pd.DataFrame | None
    confirmation: pd.DataFrame | None
    performance: pd.DataFrame | None
    margins: pd.DataFrame | None
    campaign: Path | None
    campaign_summary: pd.DataFrame | None
    worst_runs: pd.DataFrame | None
    regions: pd.DataFrame | None
    campaign_status: pd.DataFrame | None
    violations: pd.DataFrame | None
    campaign_environment: dict | None
    blocks: pd.DataFrame | None
    validation: str | None
    replays: tuple[Path, ...]

    def figures(self, folder: str | Path) -> list[Path]:
        """The PNG figures of a stage folder (relative to :attr:`out`, or absolute): those of
        :data:`FIGURE_ORDER` first, in its order, then the others by name."""
        path = Path(folder) if Path(folder).is_absolute() else self.out / folder
        found = sorted(path.glob("*.png")) if path.is_dir() else []
        rank = {name: i for i, name in enumerate(FIGURE_ORDER)}
        return sorted(found, key=lambda p: (rank.get(p.stem, len(rank)), p.name))

    @property
    def scenario_file(self) -> Path | None:
        """The scenario file the run used (``timings.json``, else :attr:`scenario_record`)."""
        if self.timings and self.timings.get("scenario"):
            return Path(self.timings["scenario"])
        return Path(self.scenario_record["file"]) if self.scenario_record.get("file") else None

    @property
    def scenario_record(self) -> dict:
        """The scenario as the analysis (else the controller) recorded it: name, file, SHA-256."""
        for record in (self.analysis_summary, self.controller):
            if record and record.get("scenario"):
                return record["scenario"]
        return {}


def _json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _parquet(path: Path) -> pd.DataFrame | None:
    try:
        return pd.read_parquet(path)
    except (OSError, ValueError):
        return None


def find_campaign(out: str | Path) -> Path | None:
    """The campaign folder of a results folder: the newest ``campaign-*`` holding a plan."""
    folders = [p for p in Path(out).glob("campaign-*") if (p / "plan.parquet").is_file()]
    return max(folders, key=lambda p: p.stat().st_mtime) if folders else None


def load_run(out: str | Path, campaign: str | Path | None = None) -> RunResults:
    """Read the results of an ``oos run`` folder; missing stages and tables are ``None``.

    Parameters
    ----------
    out : path-like
        The ``oos run --out`` folder.
    campaign : path-like, optional
        Its campaign folder (default: :func:`find_campaign`).

    Returns
    -------
    RunResults

    Raises
    ------
    FileNotFoundError
        ``out`` is not a folder.
    """
    out = Path(out)
    if not out.is_dir():
        raise FileNotFoundError(f"results folder {out}: not found")
    campaign = Path(campaign) if campaign is not None else find_campaign(out)
    report = campaign / "report" if campaign is not None else None
    seconds = {}
    for stage in STAGES:
        stamp = _json(out / stage / "stage.json")
        if stamp and isinstance(stamp.get("seconds"), int | float):
            seconds[stage] = float(stamp["seconds"])
    validation = out / "validate" / "validate.txt"
    replays = sorted(campaign.glob("replay/case_*.html")) if campaign is not None else []
    return RunResults(
        out=out,
        timings=_json(out / "timings.json"),
        stage_seconds=seconds,
        controller=_json(out / "controller" / "controller.json"),
        analysis_summary=_json(out / "analysis" / "summary.json"),
        peaks=_parquet(out / "analysis" / "stability_peaks.parquet"),
        guaranteed=_parquet(out / "analysis" / "stability_guaranteed.parquet"),
        perturbations=_parquet(out / "analysis" / "worst_perturbations.parquet"),
        confirmation=_parquet(out / "confirm" / "confirmation.parquet"),
        performance=_parquet(out / "confirm" / PERFORMANCE_FILE),
        margins=_parquet(out / "margins" / "margins.parquet"),
        campaign=campaign,
        campaign_summary=_parquet(report / "summary.parquet") if report else None,
        worst_runs=_parquet(report / "worst_runs.parquet") if report else None,
        regions=_parquet(report / "regions.parquet") if report else None,
        campaign_status=_parquet(report / "status.parquet") if report else None,
        violations=_parquet(report / "violations.parquet") if report else None,
        campaign_environment=_json(campaign / "environment.json") if campaign else None,
        blocks=_parquet(out / "model" / "blocks.parquet"),
        validation=validation.read_text(encoding="utf-8") if validation.is_file() else None,
        replays=tuple(replays),
    )


def _finite(value) -> bool:
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def _count(value) -> str:
    """A count as an integer ("?" when it is missing)."""
    return str(int(value)) if _finite(value) else "?"


def guaranteed_mu(peaks: pd.DataFrame, subset: str, study: str = "mission") -> tuple[float, str]:
    """The peak upper bound of mu of one subset and which bound it is.

    Returns
    -------
    value : float
        ``mu upper guaranteed [-]`` (proved on the whole frequency axis) when the analysis
        computed it, else ``mu upper [-]`` (on the analyzed frequencies); NaN when the subset
        is not in the table.
    column : str
        The column it was read from.
    """
    rows = peaks[(peaks["study"] == study) & (peaks["subset"] == subset)]
    if rows.empty:
        return math.nan, ""
    row = rows.iloc[0]
    column = "mu upper guaranteed [-]"
    if column in rows.columns and _finite(row[column]):
        return float(row[column]), column
    return float(row["mu upper [-]"]), "mu upper [-]"


def headline_numbers(results: RunResults) -> list[Headline]:
    """The headline numbers of a run, each with its unit and where it was read.

    gamma of the controller; the guaranteed peak of mu of every subset of the mission study;
    the worst gain and phase margins over the mission (every loop model and configuration);
    the worst performance ratio the twin reached when driven by the analysis' worst-case
    perturbation and input (:func:`worst_performance_on_twin`); the upper end of the 95 %
    interval of the campaign's probability that a run fails. A
    number whose table is missing is left out.

    Parameters
    ----------
    results : RunResults

    Returns
    -------
    list of Headline
    """
    numbers = []
    if results.controller is not None and _finite(results.controller.get("gamma")):
        numbers.append(
            Headline(
                "gamma",
                "H-infinity performance gamma of the controller",
                float(results.controller["gamma"]),
                "-",
                "controller/controller.json: gamma",
                "requirement gamma < 1",
            )
        )
    peaks = results.peaks
    if peaks is not None and {"study", "subset", "mu upper [-]"} <= set(peaks.columns):
        present = set(peaks.loc[peaks["study"] == "mission", "subset"])
        for subset in [s for s in SUBSETS if s in present] + sorted(present - set(SUBSETS)):
            value, column = guaranteed_mu(peaks, subset)
            row = peaks[(peaks["study"] == "mission") & (peaks["subset"] == subset)].iloc[0]
            where = (
                f"t = {float(row['time [s]']):.4g} s, f = {float(row['frequency [Hz]']):.4g} Hz"
                if "time [s]" in row and "frequency [Hz]" in row
                else ""
            )
            kind = "guaranteed" if column == "mu upper guaranteed [-]" else "on the grid"
            numbers.append(
                Headline(
                    f"mu_{subset}",
                    f"peak of mu, mission, subset {subset} (upper bound, {kind})",
                    value,
                    "-",
                    f"analysis/stability_peaks.parquet: {column}",
                    where,
                )
            )
    margins = results.margins
    if margins is not None:
        for column, (key, label, unit) in MARGIN_HEADLINES.items():
            if column not in margins.columns or not margins[column].notna().any():
                continue
            row = margins.loc[margins[column].idxmin()]
            time_s = float(row.get("time [s]", math.nan))
            numbers.append(
                Headline(
                    key,
                    f"{label} over the mission",
                    float(row[column]),
                    unit,
                    f"margins/margins.parquet: min of {column}",
                    f"{row.get('loop', '?')} loop, t = {time_s:.4g} s",
                )
            )
    worst = worst_performance_on_twin(results.performance)
    if worst is not None:
        numbers.append(worst)
    summary = results.campaign_summary
    column = _p_fail_column(summary)
    if column is not None:
        rows = summary[summary["metric"] == ANY_FAILURE]
        if not rows.empty:
            row = rows.iloc[0]
            numbers.append(
                Headline(
                    "p_fail_bound",
                    f"campaign: 95 % {P_FAIL_COLUMNS[column]} of P(a run fails)",
                    float(row[column]),
                    "-",
                    f"{results.campaign.name}/report/summary.parquet: {column} ({ANY_FAILURE})",
                    f"{_count(row.get('violations'))} of {_count(row.get('runs'))} runs fail",
                )
            )
    return numbers


P_FAIL_COLUMNS = {
    "P 95 % upper (one-sided)": "upper bound (one-sided)",
    "P 95 % high": "interval's upper end (two-sided)",
}
"""The campaign summary's columns the headline reads, in order of preference, with their wording:
the one-sided bound (the one the campaign prints, ``P <= p at 95 %``), else (summaries written
before it existed) the upper end of the two-sided interval."""


def _p_fail_column(summary: pd.DataFrame | None) -> str | None:
    """The column of ``summary`` that :data:`P_FAIL_COLUMNS` prefers, or None."""
    if summary is None:
        return None
    return next((c for c in P_FAIL_COLUMNS if c in summary.columns), None)


def worst_performance_on_twin(table: pd.DataFrame | None) -> Headline | None:
    """The largest requirement ratio the Drake twin reached in ``oos confirm``'s performance
    confirmation (``gain twin [-]``: the pointing error, or the wheel command, of the twin
    driven by the worst-case perturbation and input, over its requirement; > 1 violates it),
    with the channel, the configuration, the frequency and the analysis' bounds of that gain.

    Parameters
    ----------
    table : pandas.DataFrame or None
        ``confirm/performance_confirmation.parquet``.

    Returns
    -------
    Headline or None
        None without a table or without a finished twin run.
    """
    row = worst_twin_row(table)
    if row is None:
        return None
    channel = str(row.get("channel", "?"))
    requirement = REQUIREMENT_NAMES.get(channel, "requirement")
    return Headline(
        "performance_twin",
        f"worst performance ratio on the twin ({channel} / {requirement}; > 1 violates it)",
        float(row["gain twin [-]"]),
        "-",
        f"confirm/{PERFORMANCE_FILE}: max of gain twin [-]",
        worst_twin_where(row),
    )


def format_number(value, unit: str = "-", digits: int = 4) -> str:
    """``value`` with ``digits`` significant digits and its unit (``[-]`` when dimensionless).

    >>> format_number(0.79123, "-")
    '0.7912 [-]'
    >>> format_number(6.02, "dB")
    '6.02 dB'
    """
    if isinstance(value, bool):
        return str(value)
    try:
        number = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(number):
        return "n/a"
    text = f"{number:.{digits}g}"
    return f"{text} [-]" if unit in ("-", "") else f"{text} {unit}"
