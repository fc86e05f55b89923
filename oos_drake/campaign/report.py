"""Campaign report: summary tables (Parquet + printed pandas) and figures (PNG).

Probabilities of violation are estimated for the spec's dispersions by
:func:`.estimators.campaign_estimate` (exact Clopper-Pearson for Monte Carlo runs, a betting
interval for importance-weighted runs of the mu-guided sampler whose effective sample
size reaches half the runs, else the runs drawn from the dispersions alone). A run fails when it
did not finish (``failed``/``diverged``) or violates a requirement. The report states, per
requirement, "N runs, k violations: P <= p at 95 %", whether that decides against the spec's
``[estimation] target`` and how many more runs without violation would show ``P <= target``.

Files written in ``DIR/report/``:

- ``summary.parquet``: per metric: runs, weighted mean, min, quantiles, max, requirement,
  violations, estimated violation probability, its standard error, the confidence interval and its
  method, the one-sided upper bound, the decision against the target and the runs still needed;
- ``violations.parquet``: every violation with its requirement, mission phase and the time of
  the first violation (from the retained time series);
- ``status.parquet``: runs per status; ``worst_runs.parquet``: the worst runs by requirement
  margin; ``regions.parquet`` (mu-guided): runs, failures and estimate per proposal region,
  with the analysis' worst-case performance gains of the region beside the worst metric of the
  nonlinear runs drawn around it;
- ``confirmation.parquet`` (when the ``oos confirm`` table is found): the nonlinear stability
  boundary of each certified peak against mu;
- ``performance_confirmation.parquet`` (when ``oos confirm`` wrote one): the analysis'
  worst-case gains run on the twin (worst perturbation and worst input), printed with the
  worst performance ratio on the twin beside the campaign's worst run;
- ``metric_distributions.png`` (histograms of unweighted runs; for importance-weighted runs the
  weighted empirical CDF, the estimate under the dispersions, beside the runs as drawn),
  ``worst_runs.png``, ``pass_fail_vs_parameters.png``, ``regions_performance.png`` (mu-guided,
  when the worst cases carry gains) and ``stability_confirmation.png`` (with a confirmation
  table).

Like with like: mu is a stability margin, so it is compared with the stability boundary the
nonlinear twin shows (``oos confirm``: the perturbation scale ``alpha`` at which the oscillation
stops decaying, against ``1 / mu``), and the nonlinear metrics (APE, wheel command) with the
analysis' worst-case performance gains of the channels whose unit gain is their requirement
(``wcgain:<metric>`` columns of ``worst_cases.parquet``). Both sides are normalized by the
requirement, but they are not the same norm: the gain bounds a ratio of signal energies (the
worst disturbance of unit energy, H-infinity), the campaign metric is a peak over the simulated
window under the simulated noise, disturbance and initial errors. A nonlinear ratio above the
linear worst-case gain is therefore a flag to investigate, not a contradiction by itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from oos_drake.campaign import estimators, store  # noqa: E402
from oos_drake.campaign.distributions import Fixed  # noqa: E402
from oos_drake.campaign.executors import execute_case  # noqa: E402
from oos_drake.campaign.performance import (  # noqa: E402
    PERFORMANCE_CONFIRMATION_FILE,
    worst_twin_row,
    worst_twin_where,
)
from oos_drake.campaign.runner import (  # noqa: E402
    case_from_plan_row,
    load_campaign,
    metric_column,
)
from oos_drake.campaign.samplers import NOMINAL_COMPONENT, mission_phases  # noqa: E402
from oos_drake.files import atomic_write_bytes, atomic_write_parquet

#: File of ``oos confirm`` and the folder where ``oos run`` writes it (a sibling of the campaign).
CONFIRMATION_FILE = "confirmation.parquet"
CONFIRMATION_FOLDER = "confirm"
#: Columns of the confirmation table the report reads.
CONFIRMATION_COLUMNS = (
    "study",
    "subset",
    "time [s]",
    "critical frequency [Hz]",
    "mu lower [-]",
    "mu upper [-]",
    "alpha linear continuous [-]",
    "alpha linear sampled [-]",
    "alpha nonlinear [-]",
    "alpha physical max [-]",
    "oscillation frequency [Hz]",
    "status",
)


@dataclass(frozen=True)
class CampaignReport:
    """What ``write_report`` produced.

    Attributes
    ----------
    directory : Path
        ``DIR/report``.
    text : str
        The printed summary.
    figures : tuple of Path
        PNG files.
    tables : dict
        Name -> DataFrame (also written as ``<name>.parquet``).
    """

    directory: Path
    text: str
    figures: tuple[Path, ...]
    tables: dict


def _save(fig, path: Path, rect=None) -> Path:
    """Lay out ``fig`` (``tight_layout``, in ``rect`` if given), save it as PNG atomically
    (temp file + rename), close it and return ``path``."""
    fig.tight_layout(rect=rect)
    atomic_write_bytes(path, lambda stream: fig.savefig(stream, format="png", dpi=110))
    plt.close(fig)
    return path


def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """Quantile ``q`` of the weighted empirical distribution (NaNs dropped)."""
    values, weights = np.asarray(values, float), np.asarray(weights, float)
    keep = np.isfinite(values)
    values, weights = values[keep], weights[keep]
    if values.size == 0:
        return math.nan
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    index = np.searchsorted(cumulative, q * cumulative[-1])
    return float(values[order][min(index, values.size - 1)])


def weighted_ecdf(values: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted empirical CDF (self-normalized; NaNs dropped): sorted values and ``F`` [-]."""
    values, weights = np.asarray(values, float), np.asarray(weights, float)
    keep = np.isfinite(values)
    values, weights = values[keep], weights[keep]
    if values.size == 0:
        return values, values
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    return values[order], cumulative / cumulative[-1]


def _max_requirement(spec, metric: str):
    """The requirement with a positive max bound on ``metric``, or None."""
    return next(
        (r for r in spec.requirements if r.metric == metric and r.max is not None and r.max > 0),
        None,
    )


def requirement_ratio(spec, runs: pd.DataFrame) -> pd.Series:
    """Worst ``metric / bound`` over the max-requirements per run (> 1: violated; NaN: no run)."""
    ratios = []
    for requirement in spec.requirements:
        if requirement.max is not None and requirement.max > 0:
            ratios.append(runs[metric_column(spec, requirement.metric)] / requirement.max)
    if not ratios:
        return pd.Series(np.nan, index=runs.index)
    return pd.concat(ratios, axis=1).max(axis=1, skipna=False)


def _summary_table(spec, runs: pd.DataFrame) -> pd.DataFrame:
    weights = runs["weight"].to_numpy()
    rows = []
    for metric in spec.metrics:
        column = metric_column(spec, metric)
        values = runs[column].to_numpy(float)
        finite = np.isfinite(values)
        requirement = next((r for r in spec.requirements if r.metric == metric), None)
        row = {
            "metric": column,
            "runs": int(finite.sum()),
            "mean (weighted)": float(
                np.sum(weights[finite] * values[finite]) / np.sum(weights[finite])
            )
            if finite.any()
            else math.nan,
            "min": float(np.nanmin(values)) if finite.any() else math.nan,
            "p50": weighted_quantile(values, weights, 0.50),
            "p95": weighted_quantile(values, weights, 0.95),
            "p99": weighted_quantile(values, weights, 0.99),
            "max": float(np.nanmax(values)) if finite.any() else math.nan,
            "requirement": requirement.label if requirement else "",
        }
        if requirement is not None:
            violated = ~runs[requirement.column].to_numpy(bool)
            row.update(
                {"violations": int(violated.sum()), **_estimate(spec, runs, weights, violated)}
            )
        rows.append(row)
    failed = ~runs["pass"].to_numpy(bool)
    rows.append(
        {
            "metric": "any (requirement or run failure)",
            "runs": len(runs),
            "requirement": "all",
            "violations": int(failed.sum()),
            **_estimate(spec, runs, weights, failed),
        }
    )
    return pd.DataFrame(rows)


def _estimate(spec, runs, weights, events) -> dict:
    """The summary columns of one estimated probability."""
    est = estimators.campaign_estimate(spec, runs, events)
    target = spec.estimation.target
    values = weights * np.asarray(events, bool)
    n = len(values)
    decision = est.decides(target)
    # runs without violation that would show P <= target: none more once that is shown, and
    # no number at all once P > target is shown (no run count can show P <= target then)
    more = {"undecided": est.runs_to_decide(target), f"P <= {target:g}": 0}.get(decision)
    return {
        "P(violation)": est.estimate,
        "se": float(np.std(values, ddof=1) / math.sqrt(n)) if n > 1 else math.nan,
        "P 95 % low": est.low,
        "P 95 % high": est.high,
        "interval": est.method,
        "P 95 % upper (one-sided)": est.upper,
        "decision": decision,
        "more runs to show P <= target": math.nan if more is None else float(more),
    }


def probability_sentences(spec, runs: pd.DataFrame) -> str:
    """Per requirement (and for any failure): ``"N runs, k violations: P <= p at 95 %"``, the
    decision against the spec's target and the runs without violation that would show it."""
    target = spec.estimation.target
    lines = [f"probability of violation (target P <= {target:g}):"]
    events = [(r.label, ~runs[r.column].to_numpy(bool)) for r in spec.requirements]
    events.append(("any requirement or run failure", ~runs["pass"].to_numpy(bool)))
    for label, violated in events:
        est = estimators.campaign_estimate(spec, runs, violated)
        more = est.runs_to_decide(target)
        decision = est.decides(target)
        line = f"  {label}: {est.sentence()}; {decision}"
        if more and decision == "undecided":
            line += f"; {more} more runs without violation would show P <= {target:g}"
        lines.append(line)
    return "\n".join(lines)


def violations_table(directory: Path, spec, runs: pd.DataFrame) -> pd.DataFrame:
    """Every violation: run, requirement, mission phase and time of the first violation.

    The time is the first logged instant at which the signal a metric bounds (the simulator's
    ``metric_signals``) leaves the requirement's max bound in one of the requirement's phases,
    read from the run's retained time series; without one it is NaN and the phase column lists
    the phases the run's window overlaps. The metric is computed at the flight-software rate and
    the series is logged at ``log_rate``: a violation between two logged samples has no first
    logged instant, and ``peak time (logged) [s]`` (the logged sample of the largest magnitude
    within the requirement's phases) then says when it happened, to one log period. A run that
    did not finish is listed once, with its status.
    """
    phases = mission_phases(spec.info)
    rows = []
    for _, run in runs.iterrows():
        start, end = float(run["window start [s]"]), float(run["window end [s]"])
        overlapped = "+".join(
            w.label.removeprefix("phase:") for w in phases if start < w.end and end > w.start
        )
        base = {"run_id": int(run["run_id"]), "window": run["window"], "status": run["status"]}
        if run["status"] != "ok":
            rows.append(base | {"requirement": "run finished", "phase": overlapped})
            continue
        series = None
        for requirement in spec.requirements:
            if bool(run[requirement.column]):
                continue
            time, peak_time, phase = math.nan, math.nan, overlapped
            signal = spec.info.metric_signals.get(requirement.metric)
            path = store.timeseries_file(directory, int(run["run_id"]))
            if signal and requirement.max is not None and path.is_file():
                series = pd.read_parquet(path) if series is None else series
                column = f"{signal} [{spec.info.signal_units[signal]}]"
                if column in series.columns:
                    t = series["time [s]"].to_numpy(float)
                    inside = np.ones(t.size, bool)
                    if requirement.phases:
                        inside = np.zeros(t.size, bool)
                        for a, b in requirement.spans:
                            inside |= (t >= a) & (t <= b)
                    magnitude = np.abs(series[column].to_numpy())
                    beyond = np.flatnonzero(inside & (magnitude > requirement.max))
                    if inside.any():
                        peak_time = float(t[inside][np.argmax(magnitude[inside])])
                    if beyond.size:
                        time = float(t[beyond[0]])
                        phase = next(
                            w.label.removeprefix("phase:")
                            for w in phases
                            if w.start <= time <= w.end
                        )
            rows.append(
                base
                | {
                    "requirement": requirement.label,
                    "phase": phase,
                    "first violation time [s]": time,
                    "peak time (logged) [s]": peak_time,
                    metric_column(spec, requirement.metric): float(
                        run[metric_column(spec, requirement.metric)]
                    ),
                }
            )
    columns = [
        "run_id",
        "requirement",
        "phase",
        "first violation time [s]",
        "peak time (logged) [s]",
        "window",
        "status",
    ]
    table = pd.DataFrame(rows)
    if table.empty:
        return pd.DataFrame(columns=columns)
    return table[columns + [c for c in table.columns if c not in columns]]


def _gain_metrics(spec) -> list[str]:
    """Metrics with a max requirement and a worst-case gain in at least one region."""
    with_gain = {m for r in spec.regions for m in r.gains}
    return [m for m in spec.metrics if m in with_gain and _max_requirement(spec, m) is not None]


def _regions_table(spec, runs: pd.DataFrame) -> pd.DataFrame:
    """Per proposal component: runs, failures, P(fail) contribution; per region the analysis'
    predictions (mu; worst-case gain per metric) beside the worst metric / requirement of the
    nonlinear runs drawn around it."""
    metrics = _gain_metrics(spec)
    rows = [{"region": NOMINAL_COMPONENT, "configuration": "nominal dispersions"}]
    for r in spec.regions:
        row = {
            "region": r.region,
            "configuration": r.configuration,
            "time [s]": r.time,
            "frequency [Hz]": r.frequency,
            "mu lower [-]": r.mu_lower,
            "mu upper [-]": r.mu_upper,
        }
        for metric in metrics:
            low, high = r.gains.get(metric, (math.nan, math.nan))
            row[f"wcgain {metric} lower [-]"] = low
            row[f"wcgain {metric} upper [-]"] = high
        rows.append(row)
    table = pd.DataFrame(rows)
    n = len(runs)
    failed = ~runs["pass"]
    extra = {
        "failed": failed,
        "wf": runs["weight"] * failed,
        "ratio": requirement_ratio(spec, runs),
    }
    for metric in metrics:
        extra[metric] = runs[metric_column(spec, metric)] / _max_requirement(spec, metric).max
    grouped = runs.assign(**extra).groupby("region")
    table["runs"] = table["region"].map(grouped.size()).fillna(0).astype(int)
    table["failures"] = table["region"].map(grouped["failed"].sum()).fillna(0).astype(int)
    table["worst ratio (nonlinear) [-]"] = table["region"].map(grouped["ratio"].max())
    for metric in metrics:
        table[f"worst {metric} / requirement (nonlinear) [-]"] = table["region"].map(
            grouped[metric].max()
        )
    table["P(fail) contribution"] = table["region"].map(grouped["wf"].sum() / n).fillna(0.0)
    return table


def _region_label(row: pd.Series) -> str:
    """Y label of a region on three short lines, every number with its unit: id and time,
    frequency and mu, the runs drawn around it and how many failed."""
    runs = int(row["runs"])
    drawn = f"{int(row['failures'])} of {runs} runs fail" if runs else "no run drawn here"
    return (
        f"region {int(row['region'])}  (t = {row['time [s]']:.0f} s)\n"
        f"f = {row['frequency [Hz]']:.3g} Hz, mu <= {row['mu upper [-]']:.3g} [-]\n"
        f"{drawn}"
    )


def _plot_regions(spec, regions: pd.DataFrame, path: Path) -> Path | None:
    """Per region and metric: the analysis' worst-case gain against the nonlinear worst ratio
    (horizontal bars, one panel per metric that has a worst-case gain)."""
    guided = regions[regions["region"] != NOMINAL_COMPONENT]
    metrics = _gain_metrics(spec)
    if guided.empty or not metrics:
        return None
    y = np.arange(len(guided))[::-1]
    fig, axes = plt.subplots(
        1,
        len(metrics),
        figsize=(4.6 * len(metrics) + 2.8, 2.4 + 0.95 * len(guided)),
        sharey=True,
        squeeze=False,
    )
    for ax, metric in zip(axes[0], metrics, strict=True):
        low = guided[f"wcgain {metric} lower [-]"].to_numpy(float)
        high = guided[f"wcgain {metric} upper [-]"].to_numpy(float)
        nonlinear = guided[f"worst {metric} / requirement (nonlinear) [-]"].to_numpy(float)
        # an unbounded worst-case gain (mu > 1 in the region) drawn to the axis' end, labelled
        values = np.r_[low, high, nonlinear, 0.0]
        right = 1.12 * max(1.0, float(np.max(values[np.isfinite(values)])))
        unbounded = np.isinf(high)
        low, high = np.minimum(low, right), np.minimum(high, right)
        ax.barh(y + 0.2, high, height=0.38, color="lightgray", label="worst-case gain: upper")
        ax.barh(y + 0.2, low, height=0.38, color="tab:blue", label="worst-case gain: lower")
        ax.barh(
            y - 0.2,
            nonlinear,
            height=0.38,
            color="tab:orange",
            label="nonlinear runs: worst metric / requirement",
        )
        ax.axvline(1.0, color="tab:red", ls="--", lw=1, label="requirement")
        # the values at the bar ends: the bars of one region are read without a ruler
        for row_y, value, inf in zip(y + 0.2, high, unbounded, strict=True):
            if np.isfinite(value):
                label = " unbounded" if inf else f" {value:.2f}"
                ax.text(value, row_y, label, va="center", fontsize=7, color="dimgray")
        for row_y, value in zip(y - 0.2, nonlinear, strict=True):
            if np.isfinite(value):
                ax.text(value, row_y, f" {value:.2f}", va="center", fontsize=7, color="tab:orange")
        ax.set_xlim(0.0, right)
        ax.set_xlabel(f"{metric} / requirement [-]")
        ax.set_title(metric, fontsize=10)
        ax.grid(alpha=0.3, axis="x")
    labels = [_region_label(r) for _, r in guided.iterrows()]
    axes[0, 0].set_yticks(y, labels, fontsize=9, linespacing=1.3)
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, fontsize=8, loc="upper center", ncol=4, bbox_to_anchor=(0.5, 0.915))
    fig.suptitle(
        "Worst-case performance per region: analysis (H-infinity gain over the region's\n"
        "subset, an energy ratio) against the nonlinear runs drawn around it (peak in the window)",
        fontsize=10,
    )
    return _save(fig, path, rect=(0, 0, 1, 0.89))


def find_confirmation(directory: Path, confirm: str | Path | None = None) -> Path | None:
    """The ``oos confirm`` table of a campaign.

    ``confirm`` (a folder or the file) when given, else the ``oos run`` layout
    (``<out>/confirm/confirmation.parquet`` beside the campaign folder); None when there is none
    (the comparison is then left out of the report).

    Raises
    ------
    ValueError
        ``confirm`` given but no confirmation table there.
    """
    if confirm is not None:
        path = Path(confirm)
        path = path / CONFIRMATION_FILE if path.is_dir() else path
        if not path.is_file():
            raise ValueError(
                f"--confirm {confirm}: no {CONFIRMATION_FILE} (written by oos confirm)"
            )
        return path
    path = Path(directory).resolve().parent / CONFIRMATION_FOLDER / CONFIRMATION_FILE
    return path if path.is_file() else None


def find_performance_confirmation(
    directory: Path, confirm: str | Path | None = None
) -> Path | None:
    """The ``oos confirm`` performance table (``performance_confirmation.parquet``) of a
    campaign: in the ``--confirm`` folder (or beside the given file), else in the ``oos run``
    layout; None when there is none."""
    if confirm is not None:
        folder = Path(confirm) if Path(confirm).is_dir() else Path(confirm).parent
    else:
        folder = Path(directory).resolve().parent / CONFIRMATION_FOLDER
    path = folder / PERFORMANCE_CONFIRMATION_FILE
    return path if path.is_file() else None


def performance_sentences(table: pd.DataFrame, worst_ratio: float) -> str:
    """The performance confirmation against the campaign: the twin's largest requirement ratio
    under the analysis' worst case (perturbation and input) beside the analysis' bounds, and the
    campaign's worst run.

    Parameters
    ----------
    table : pandas.DataFrame
        ``performance_confirmation.parquet``.
    worst_ratio : float
        Largest requirement ratio of the campaign's runs [-] (NaN: none).
    """
    lines = [
        "worst-case performance on the twin (oos confirm; ratio to the requirement, > 1 "
        "violates it):"
    ]
    for _, row in table.iterrows():
        lines.append(
            f"  {row['channel']} {row['subset']:>14s} t = {row['time [s]']:7.1f} s "
            f"f = {row['frequency [Hz]']:.4g} Hz: analysis [{row['gain lower [-]']:.4g}, "
            f"{row['gain upper [-]']:.4g}], sampled {row['gain linear sampled [-]']:.4g}, "
            f"twin {row['gain twin [-]']:.4g} ({row['status']})"
        )
    worst = worst_twin_row(table)
    if worst is not None:
        value = float(worst["gain twin [-]"])
        lines.append(
            f"worst performance ratio on the twin: {value:.4g} ({worst_twin_where(worst)}); the "
            f"campaign's worst run: {worst_ratio:.4g}"
            + (
                " (the campaign's random disturbances stay below the worst-case input's "
                "ratio; oos campaign falsify searches for it)"
                if math.isfinite(worst_ratio) and worst_ratio < value
                else ""
            )
        )
    return "\n".join(lines)


def read_confirmation(path: Path) -> pd.DataFrame:
    """The confirmation table with mu's linear boundary as perturbation scales.

    mu certifies stability for every perturbation scaled by ``alpha < 1 / mu_upper`` and finds
    a destabilizing one at ``alpha = 1 / mu_lower``: the linear boundary lies in between.

    Raises
    ------
    ValueError
        A column of :data:`CONFIRMATION_COLUMNS` is missing.
    """
    table = store.read_table(path, CONFIRMATION_COLUMNS, str(path))
    table = table[list(CONFIRMATION_COLUMNS)].copy()
    table["alpha certified (1/mu upper) [-]"] = 1.0 / table["mu upper [-]"]
    table["alpha destabilizing (1/mu lower) [-]"] = 1.0 / table["mu lower [-]"]
    table["nonlinear / linear continuous [-]"] = (
        table["alpha nonlinear [-]"] / table["alpha linear continuous [-]"]
    )
    table["nonlinear / linear sampled [-]"] = (
        table["alpha nonlinear [-]"] / table["alpha linear sampled [-]"]
    )
    return table


def _plot_confirmation(table: pd.DataFrame, path: Path) -> Path | None:
    """Stability per certified peak: mu's interval for the linear boundary against the
    boundaries of the linear loops and of the nonlinear twin (horizontal bars)."""
    if table.empty:
        return None
    y = np.arange(len(table))[::-1]
    fig, ax = plt.subplots(figsize=(8.5, 1.8 + 0.7 * len(table)))
    low = table["alpha certified (1/mu upper) [-]"].to_numpy(float)
    high = table["alpha destabilizing (1/mu lower) [-]"].to_numpy(float)
    ax.barh(
        y,
        high - low,
        left=low,
        height=0.5,
        color="lightgray",
        edgecolor="gray",
        label="mu: [1/mu upper, 1/mu lower]",
    )
    markers = (
        ("alpha linear continuous [-]", "|", "black", "linear, continuous loop"),
        ("alpha linear sampled [-]", "|", "tab:blue", "linear, sampled-data loop"),
        ("alpha nonlinear [-]", "D", "tab:orange", "nonlinear twin (Drake)"),
        ("alpha physical max [-]", ">", "tab:red", "largest physically valid alpha"),
    )
    for column, marker, color, label in markers:
        values = table[column].to_numpy(float)
        if np.isfinite(values).any():
            ax.scatter(values, y, marker=marker, color=color, s=90, label=label, zorder=3)
    labels = [
        f"{r['study']} / {r['subset']}: t = {r['time [s]']:.0f} s\n"
        f"{r['critical frequency [Hz]']:.3g} Hz, {r['status']}"
        for _, r in table.iterrows()
    ]
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlabel("perturbation scale alpha at the stability boundary [-]")
    ax.set_title("Stability: mu's boundary against the nonlinear twin's (oos confirm)", fontsize=10)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=3)
    ax.grid(alpha=0.3, axis="x")
    return _save(fig, path)


def _worst_runs(spec, runs: pd.DataFrame, count: int) -> pd.DataFrame:
    ratio = requirement_ratio(spec, runs)
    not_ok = runs["status"] != "ok"
    key = np.where(not_ok, np.inf, ratio.fillna(-np.inf))
    order = np.argsort(-key, kind="stable")[:count]
    table = runs.iloc[order].copy()
    table.insert(1, "requirement ratio [-]", ratio.iloc[order].to_numpy())
    return table.reset_index(drop=True)


def _plot_distributions(spec, runs: pd.DataFrame, path: Path) -> Path:
    """One panel per metric: a histogram of unweighted runs, or for importance-weighted runs the
    weighted empirical CDF (the estimate under the spec's dispersions) beside the CDF of the runs
    as drawn; the requirement and its P(violation) with the confidence interval."""
    metrics = list(spec.metrics)
    columns = min(3, len(metrics))
    rows = math.ceil(len(metrics) / columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.8 * columns, 3.9 * rows), squeeze=False)
    weights = runs["weight"].to_numpy()
    weighted = not np.all(weights == 1.0)
    for ax, metric in zip(axes.flat, metrics, strict=False):
        column = metric_column(spec, metric)
        values = runs[column].to_numpy(float)
        finite = np.isfinite(values)
        if weighted:
            x, cdf = weighted_ecdf(values, weights)
            ax.step(x, cdf, where="post", color="tab:blue", label="weighted: under the dispersions")
            x, cdf = weighted_ecdf(values, np.ones_like(weights))
            ax.step(x, cdf, where="post", color="tab:gray", ls=":", label="runs as drawn")
            ax.set_ylabel("P(metric <= value) [-]")
            ax.set_ylim(0, 1.02)
        else:
            ax.hist(values[finite], bins=30, color="tab:blue", alpha=0.8, label="runs")
            ax.set_ylabel("number of runs")
        title = f"{metric}: {int(finite.sum())} finished runs"
        for requirement in spec.requirements:
            if requirement.metric != metric:
                continue
            for bound in (requirement.max, requirement.min):
                if bound is not None:
                    ax.axvline(bound, color="tab:red", linestyle="--", label="requirement")
            est = estimators.campaign_estimate(spec, runs, ~runs[requirement.column].to_numpy(bool))
            title += (
                f"\nP(violation) = {est.estimate:.2g}, 95 % [{est.low:.2g}, {est.high:.2g}]"
                f"\n({est.method})"
            )
        ax.set_xlabel(column)
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(metrics) :]:
        ax.set_visible(False)
    kind = "weighted empirical CDFs" if weighted else "histograms"
    fig.suptitle(f"Campaign {spec.name}: metric {kind} against requirements")
    return _save(fig, path)


def _series_for(directory: Path, spec, plan: pd.DataFrame, run_id: int) -> pd.DataFrame | None:
    path = store.timeseries_file(directory, run_id)
    if path.is_file():
        return pd.read_parquet(path)
    # not retained: recompute it (runs are deterministic given their plan row)
    row = plan[plan["run_id"] == run_id].iloc[0]
    return execute_case(spec.simulator, case_from_plan_row(spec, row)).timeseries


def _plot_worst(
    directory: Path, spec, plan: pd.DataFrame, worst: pd.DataFrame, path: Path
) -> Path | None:
    series = {}
    for run_id, status in zip(worst["run_id"], worst["status"], strict=True):
        data = _series_for(directory, spec, plan, int(run_id))
        if data is not None and len(data):
            series[int(run_id)] = (status, data)
    if not series:
        return None
    columns = [c for c in next(iter(series.values()))[1].columns if c not in ("run_id", "time [s]")]
    fig, axes = plt.subplots(
        len(columns), 1, figsize=(9, 2.3 * len(columns)), sharex=True, squeeze=False
    )
    bounds = {}
    metric_signals = spec.info.metric_signals
    for requirement in spec.requirements:
        signal = metric_signals.get(requirement.metric)
        if signal and requirement.max is not None:
            bounds[f"{signal} [{spec.info.signal_units[signal]}]"] = requirement
    for ax, column in zip(axes[:, 0], columns, strict=True):
        for run_id, (status, data) in series.items():
            if column in data.columns:
                ax.plot(
                    data["time [s]"],
                    data[column],
                    lw=1.0,
                    label=f"run {run_id}" + ("" if status == "ok" else f" ({status})"),
                )
        if column in bounds:
            requirement = bounds[column]
            for sign in (1, -1):
                ax.axhline(
                    sign * requirement.max,
                    color="tab:red",
                    ls="--",
                    lw=1,
                    label=f"requirement {requirement.label}" if sign > 0 else None,
                )
        ax.set_ylabel(column)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=3, loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"Campaign {spec.name}: time histories of the {len(series)} worst runs")
    return _save(fig, path)


def _plot_pass_fail(spec, runs: pd.DataFrame, path: Path) -> Path | None:
    parameters = [
        p
        for p in spec.info.parameters
        if p.name in spec.dispersions and not isinstance(spec.dispersions[p.name], Fixed)
    ]
    if not parameters:
        return None
    ratio = requirement_ratio(spec, runs)
    columns = min(3, len(parameters))
    rows = math.ceil(len(parameters) / columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.4 * columns, 3.3 * rows), squeeze=False)
    ok = runs["status"] == "ok"
    passed = runs["pass"].to_numpy(bool)
    finite_ratio = ratio[ok & np.isfinite(ratio)]
    top = float(finite_ratio.max()) * 1.15 if len(finite_ratio) else 2.0
    for ax, parameter in zip(axes.flat, parameters, strict=False):
        x = runs[parameter.column]
        ax.scatter(x[ok & passed], ratio[ok & passed], s=10, c="tab:blue", label="pass")
        ax.scatter(x[ok & ~passed], ratio[ok & ~passed], s=14, c="tab:red", label="fail")
        if (~ok).any():
            ax.scatter(
                x[~ok],
                np.full((~ok).sum(), top),
                marker="x",
                c="black",
                label="diverged/failed (plotted at top)",
            )
        ax.axhline(1.0, color="tab:red", ls="--", lw=1)
        ax.set_xlabel(parameter.column)
        ax.set_ylabel("worst metric / requirement [-]")
        if spec.dispersions[parameter.name].kind == "log-uniform":
            ax.set_xscale("log")
        else:
            ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(parameters) :]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle(
        f"Campaign {spec.name}: pass/fail against each dispersed parameter "
        "(ratio > 1 violates a requirement)"
    )
    return _save(fig, path)


def write_report(
    directory: str | Path, worst: int = 5, confirm: str | Path | None = None
) -> CampaignReport:
    """Write the tables and figures of a campaign directory into ``DIR/report``.

    Parameters
    ----------
    directory : path
        Campaign directory (finished or not: the finished runs are reported).
    worst : int
        Number of worst runs whose time histories are plotted.
    confirm : path, optional
        Folder (or file) of the ``oos confirm`` table; default: the ``oos run`` layout, see
        :func:`find_confirmation`. Without one the stability comparison is left out.
    """
    directory = Path(directory)
    spec, plan = load_campaign(directory)
    confirmation_path = find_confirmation(directory, confirm)
    confirmation = read_confirmation(confirmation_path) if confirmation_path else None
    performance_path = find_performance_confirmation(directory, confirm)
    performance = pd.read_parquet(performance_path) if performance_path else None
    runs = store.load_runs(directory)
    if runs.empty:
        raise ValueError(f"{directory}: no finished run to report")
    out = directory / store.REPORT_DIR
    out.mkdir(exist_ok=True)

    summary = _summary_table(spec, runs)
    status = runs["status"].value_counts().rename_axis("status").reset_index(name="runs")
    worst_table = _worst_runs(spec, runs, worst)
    violations = violations_table(directory, spec, runs)
    tables = {
        "summary": summary,
        "status": status,
        "worst_runs": worst_table,
        "violations": violations,
    }
    if spec.sampler.kind == "mu-guided":
        tables["regions"] = _regions_table(spec, runs)
    if confirmation is not None:
        tables["confirmation"] = confirmation
    if performance is not None:
        tables["performance_confirmation"] = performance
    else:  # a table of an earlier report whose confirmation is gone is not this report's
        (out / "performance_confirmation.parquet").unlink(missing_ok=True)
    for name, table in tables.items():
        atomic_write_parquet(table, out / f"{name}.parquet")

    figures = [
        _plot_distributions(spec, runs, out / "metric_distributions.png"),
        _plot_worst(directory, spec, plan, worst_table, out / "worst_runs.png"),
        _plot_pass_fail(spec, runs, out / "pass_fail_vs_parameters.png"),
    ]
    if "regions" in tables:
        figures.append(_plot_regions(spec, tables["regions"], out / "regions_performance.png"))
    if confirmation is not None:
        figures.append(_plot_confirmation(confirmation, out / "stability_confirmation.png"))
    figures = tuple(f for f in figures if f is not None)

    with pd.option_context(
        "display.width", 160, "display.max_columns", 20, "display.float_format", "{:.4g}".format
    ):
        parts = [
            f"campaign {spec.name}: {len(runs)}/{len(plan)} runs finished, sampler "
            f"{spec.sampler.kind}",
            summary.to_string(index=False),
            probability_sentences(spec, runs),
            status.to_string(index=False),
        ]
        if not violations.empty:
            shown = violations.head(20)
            more = f" (first 20 of {len(violations)}; all in violations.parquet)"
            parts.append(
                "violations by phase:\n"
                + violations.groupby("phase").size().rename("violations").to_string()
                + f"\nviolations{more if len(violations) > 20 else ''}:\n"
                + shown.to_string(index=False)
            )
        if "regions" in tables:
            parts.append("runs per region:\n" + tables["regions"].to_string(index=False))
            weights = runs["weight"].to_numpy()
            ess = estimators.effective_sample_size(weights)
            guided = runs["region"].to_numpy() >= 0
            guided_share = weights[guided].sum() / weights.sum()
            parts.append(
                f"importance sampling: effective sample size {ess:.1f} of {len(runs)} runs "
                f"(max weight {runs['weight'].max():.3g}); a small value means the estimates "
                "rest on few runs (widen spread or guide fewer blocks). The "
                f"{int((~guided).sum())} runs drawn from the dispersions carry "
                f"{100 * (1 - guided_share):.1f} % of the total weight, the {int(guided.sum())} "
                f"guided runs {100 * guided_share:.2g} %: a guided draw that moves many blocks "
                "near their worst-case values is improbable under the dispersions, so the guided "
                "runs search the worst cases and the probabilities rest on the others."
            )
        if confirmation is not None:
            shown = [
                "study",
                "subset",
                "time [s]",
                "critical frequency [Hz]",
                "alpha certified (1/mu upper) [-]",
                "alpha destabilizing (1/mu lower) [-]",
                "alpha nonlinear [-]",
                "nonlinear / linear continuous [-]",
                "status",
            ]
            parts.append(
                f"stability boundary, mu against the nonlinear twin ({confirmation_path}):\n"
                + confirmation[shown].to_string(index=False)
            )
        else:
            parts.append(
                "stability boundary: no oos confirm table (give --confirm DIR); mu is not "
                "compared with the campaign's performance metrics."
            )
        if performance is not None:
            ratios = requirement_ratio(spec, runs)
            parts.append(
                performance_sentences(
                    performance, float(ratios.max()) if ratios.notna().any() else math.nan
                )
            )
        if spec.window.kind == "critical":
            parts.append(
                "note: each run simulates the window around its region's critical time, so the "
                "probabilities above mix windows; read them per region (regions.parquet)."
            )
        show = ["run_id", "requirement ratio [-]", "status"] + [
            metric_column(spec, m) for m in spec.metrics
        ]
        parts.append("worst runs:\n" + worst_table[show].to_string(index=False))
    return CampaignReport(out, "\n\n".join(parts), figures, tables)
