"""Run, resume and rerun campaigns (the engine behind ``oos campaign run|resume|rerun``).

``run_campaign`` validates the spec and builds the whole plan *before* it creates the campaign
directory, so a bad spec writes nothing. It then writes the resolved spec and the plan, and runs
the pending cases on an executor; the driver process records each result as soon as it arrives
(time series first, then the run row, each written atomically; see :mod:`.store`). ``resume``
reads the directory back and runs exactly the cases without a run row. ``rerun`` recomputes one
case from its plan row: the simulator is deterministic given (values, seed, window), so the
metrics are identical.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from tqdm import tqdm

from oos_drake.campaign import store
from oos_drake.campaign.estimators import undecided_requirements
from oos_drake.campaign.executors import RunResult, execute_case, make_executor
from oos_drake.campaign.samplers import FREQUENCY_COLUMN, make_plan, region_counts
from oos_drake.campaign.simulator import MissionWindow, RunCase, SimulatorRecipe
from oos_drake.campaign.spec import CampaignSpec, load_spec, parse_spec, spec_to_toml
from oos_drake.files import atomic_write_bytes, atomic_write_parquet, atomic_write_text


def metric_column(spec: CampaignSpec, metric: str) -> str:
    """``"ape [rad]"``: metric column name with its unit."""
    return f"{metric} [{spec.info.metric_units[metric]}]"


def case_from_plan_row(spec: CampaignSpec, row: pd.Series) -> RunCase:
    """The :class:`RunCase` of one plan row (all values physical)."""
    values = {p.name: float(row[p.column]) for p in spec.info.parameters}
    window = MissionWindow(
        float(row["window start [s]"]), float(row["window end [s]"]), str(row["window"])
    )
    frequency = float(row.get(FREQUENCY_COLUMN, math.nan))
    return RunCase(int(row["run_id"]), int(row["seed"]), values, window, frequency)


def result_row(spec: CampaignSpec, plan_row: pd.Series, result: RunResult) -> pd.DataFrame:
    """One-row table of a finished run: plan columns, metrics, pass/fail, status, wall time."""
    record = plan_row.to_dict()
    passes = []
    for metric in spec.metrics:
        record[metric_column(spec, metric)] = float(result.metrics.get(metric, math.nan))
    start, end = float(plan_row["window start [s]"]), float(plan_row["window end [s]"])
    for requirement in spec.requirements:
        value = float(result.metrics.get(requirement.metric, math.nan))
        applies = requirement.applies(start, end)
        ok = result.status == "ok" and (not applies or requirement.passes(value))
        record[requirement.column] = ok
        passes.append(ok)
    record["pass"] = result.status == "ok" and all(passes)
    record["status"] = result.status
    record["error"] = result.error
    record["wall time [s]"] = float(result.wall_time)
    record["cpu time [s]"] = float(result.cpu_time)
    record["worker"] = result.worker
    table = pd.DataFrame([record])
    for column in ("run_id", "seed", "region"):
        table[column] = table[column].astype(np.int64)
    return table


def _keep_timeseries(
    spec: CampaignSpec, row: pd.DataFrame, result: RunResult
) -> pd.DataFrame | None:
    if result.timeseries is None or spec.timeseries.keep == "none":
        return None
    if spec.timeseries.keep == "failed" and bool(row["pass"].iloc[0]):
        return None
    series = result.timeseries
    if spec.timeseries.signals:
        units = spec.info.signal_units
        wanted = ["time [s]"] + [f"{s} [{units[s]}]" for s in spec.timeseries.signals]
        series = series[[c for c in wanted if c in series.columns]]
    series = series.copy()
    series.insert(0, "run_id", np.int64(result.run_id))
    return series


def record_result(
    directory: Path, spec: CampaignSpec, plan_row: pd.Series, result: RunResult
) -> pd.DataFrame:
    """Write one finished run: time series first, then the run row (each atomically)."""
    row = result_row(spec, plan_row, result)
    series = _keep_timeseries(spec, row, result)
    if series is not None:
        atomic_write_parquet(series, store.timeseries_file(directory, result.run_id))
    atomic_write_parquet(row, store.run_file(directory, result.run_id))
    return row


@dataclass(frozen=True)
class CampaignSummary:
    """Outcome of ``run``/``resume``.

    Attributes
    ----------
    directory : Path
        The campaign directory.
    n_runs : int
        Planned runs.
    executed : int
        Runs computed by this call.
    skipped : int
        Runs already finished before this call (resume).
    status_counts : dict
        Status -> number of runs, over the whole campaign.
    n_pass : int
        Runs that passed every requirement.
    """

    directory: Path
    n_runs: int
    executed: int
    skipped: int
    status_counts: dict
    n_pass: int


@dataclass(frozen=True)
class CampaignOptions:
    """How a campaign is run (``oos campaign run``'s options, the output folder apart).

    Attributes
    ----------
    spec : Path
        Campaign spec file, or the bare name of a shipped spec (``Path("demo")``).
    worst_cases : Path or None
        ``worst_cases.parquet`` replacing the spec's (``--worst-cases``; e.g. ``oos analyze``'s).
    simulator_options : dict
        Simulator options replacing the spec's (``--simulator-option KEY=VALUE`` and
        ``--controller``, whose value is ``{"controller": "/absolute/controller.json"}``).
    workers : int
        Worker processes (``--workers``; 1 runs in this process).
    scheduler : str or None
        Where they run (``--scheduler``; see :func:`~.executors.make_executor`).
    progress : bool
        tqdm progress bar of the runs (``not --quiet``).

    Raises
    ------
    ValueError
        ``workers`` below 1, an unknown ``scheduler`` (one line naming the option).
    """

    spec: Path
    worst_cases: Path | None = None
    simulator_options: dict = field(default_factory=dict)
    workers: int = 1
    scheduler: str | None = None
    progress: bool = True

    def __post_init__(self):
        from oos_drake.processes import check_scheduler, check_workers

        check_workers(self.workers)
        check_scheduler(self.scheduler)
        object.__setattr__(self, "simulator_options", dict(self.simulator_options))


def load_campaign(directory: str | Path) -> tuple[CampaignSpec, pd.DataFrame]:
    """The resolved spec and the plan of an existing campaign directory."""
    directory = Path(directory)
    spec_path = directory / store.SPEC_FILE
    plan_path = directory / store.PLAN_FILE
    if not spec_path.is_file() or not plan_path.is_file():
        raise ValueError(
            f"{directory}: not a campaign directory (no {store.SPEC_FILE} and {store.PLAN_FILE})"
        )
    spec, plan = load_spec(spec_path), pd.read_parquet(plan_path)
    missing = [p.column for p in spec.info.parameters if p.column not in plan.columns]
    if missing:
        raise ValueError(
            f"{plan_path}: no column {missing[0]!r}: simulator {spec.simulator.name!r} declares "
            "parameters the plan does not have (it changed since the campaign was planned)"
        )
    return spec, plan


def _execute(
    directory: Path,
    spec: CampaignSpec,
    plan: pd.DataFrame,
    workers: int,
    scheduler: str | None,
    progress: bool,
) -> CampaignSummary:
    store.remove_temporaries(directory)
    for path in store.quarantine_unreadable(directory):
        print(f"unreadable file moved to {path}; its run is redone", file=sys.stderr)
    finished = store.finished_run_ids(directory)
    pending = plan[~plan["run_id"].isin(finished)]
    by_id = {int(row.run_id): row for _, row in plan.iterrows()}
    cases = [case_from_plan_row(spec, row) for _, row in pending.iterrows()]
    executed = 0
    if cases:
        executor = make_executor(workers, scheduler, spec.run_timeout)
        bar = tqdm(
            total=len(plan),
            initial=len(finished),
            unit="run",
            desc=spec.name,
            disable=not progress,
            file=sys.stderr,
            dynamic_ncols=True,
        )
        try:
            for result in executor.run(spec.simulator, cases):
                record_result(directory, spec, by_id[result.run_id], result)
                executed += 1
                bar.update(1)
                if result.status != "ok":
                    bar.write(
                        f"run {result.run_id}: {result.status}: {result.error}", file=sys.stderr
                    )
        finally:
            bar.close()
            executor.close()
    store.consolidate(directory)
    runs = store.load_runs(directory)
    if spec.estimation.until_decided and len(runs) == len(plan):
        undecided = undecided_requirements(spec, runs)
        room = spec.estimation.max_runs - len(plan)
        if undecided and room > 0:
            # add a batch, plan it on disk first (a resume then runs it), and continue
            count = min(spec.estimation.batch, room)
            batch = make_plan(spec, count, first_run_id=len(plan))
            plan = pd.concat([plan, batch], ignore_index=True)
            atomic_write_parquet(plan, directory / store.PLAN_FILE)
            print(
                f"{len(runs)} runs: undecided for {'; '.join(undecided)} against P <= "
                f"{spec.estimation.target:g}: {count} more runs planned",
                file=sys.stderr,
            )
            summary = _execute(directory, spec, plan, workers, scheduler, progress)
            return replace(summary, executed=summary.executed + executed, skipped=len(finished))
    return CampaignSummary(
        directory=directory,
        n_runs=len(plan),
        executed=executed,
        skipped=len(finished),
        status_counts={str(k): int(v) for k, v in runs["status"].value_counts().items()},
        n_pass=int(runs["pass"].sum()),
    )


def _check_new_directory(directory: Path) -> None:
    """Refuse an ``--out`` that holds a campaign or anything else (the lock file aside)."""
    if (directory / store.SPEC_FILE).exists():
        raise ValueError(
            f"{directory} already holds a campaign; continue it with "
            f"'oos campaign resume {directory}' or choose another --out"
        )
    if directory.exists() and any(p.name != store.LOCK_FILE for p in directory.iterdir()):
        raise ValueError(f"--out {directory} exists and is not empty")


def plan_campaign(
    spec_path: str | Path,
    worst_cases: str | Path | None = None,
    simulator_options: Mapping[str, Any] | None = None,
) -> tuple[CampaignSpec, pd.DataFrame]:
    """Validate the spec and build the plan; writes nothing.

    ``worst_cases`` replaces the spec's ``worst_cases`` file (e.g. the output of ``oos
    analyze``): the regions of the mu-guided sampler, and for every sampler the frequencies
    that realize the LTI perturbations (see :func:`~oos_drake.campaign.samplers.make_plan`);
    ``simulator_options`` update the spec's simulator options (e.g. a synthesized
    ``controller``). The modified spec is validated again.
    """
    spec = resolve_spec(spec_path, worst_cases, simulator_options)
    return spec, make_plan(spec)


def resolve_spec(
    spec_path: str | Path,
    worst_cases: str | Path | None = None,
    simulator_options: Mapping[str, Any] | None = None,
) -> CampaignSpec:
    """The spec with ``--worst-cases`` and ``--simulator-option`` applied, validated again."""
    if worst_cases is not None:
        worst_cases = Path(worst_cases).resolve()
        if not worst_cases.is_file():
            raise ValueError(f"--worst-cases {worst_cases}: file not found")
    spec = load_spec(spec_path, worst_cases=worst_cases)
    if simulator_options:
        options = {**spec.simulator.option_dict, **simulator_options}
        spec = replace(spec, simulator=SimulatorRecipe.create(spec.simulator.name, options))
        toml = spec_to_toml(spec, str(worst_cases) if worst_cases is not None else None)
        spec = parse_spec(toml, source=Path(spec_path))
    return spec


def _write_campaign(directory: Path, spec: CampaignSpec, plan: pd.DataFrame) -> None:
    """Create the campaign directory: worst cases, environment, plan, and the spec last."""
    _check_new_directory(directory)
    directory.mkdir(parents=True, exist_ok=True)
    worst_cases_name = None
    if spec.sampler.worst_cases is not None:
        worst_cases_name = store.WORST_CASES_FILE
        source = Path(spec.sampler.worst_cases).read_bytes()
        atomic_write_bytes(directory / worst_cases_name, lambda stream: stream.write(source))
    atomic_write_text(
        json.dumps(store.environment(), indent=2) + "\n", directory / store.ENVIRONMENT_FILE
    )
    atomic_write_parquet(plan, directory / store.PLAN_FILE)
    atomic_write_text(spec_to_toml(spec, worst_cases_name), directory / store.SPEC_FILE)


def run_campaign(
    spec_path: str | Path,
    out: str | Path,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    worst_cases: str | Path | None = None,
    simulator_options: Mapping[str, Any] | None = None,
) -> CampaignSummary:
    """Validate, plan and run a campaign into ``out`` (see the module docstring).

    The spec and the plan are checked before anything is written; the directory is locked
    while the campaign runs (a second ``run`` or ``resume`` of it is refused).
    """
    directory = Path(out)
    spec, plan = plan_campaign(spec_path, worst_cases, simulator_options)
    _check_new_directory(directory)  # before the lock file is made
    with store.campaign_lock(directory):
        _write_campaign(directory, spec, plan)  # checks again: another run may have come first
        # run from the directory's own resolved spec: what resume and rerun will see
        spec, plan = load_campaign(directory)
        if spec.sampler.kind == "mu-guided":
            counts = region_counts(plan, spec.regions)
            print("runs per region:\n" + counts.to_string(index=False), file=sys.stderr)
        return _execute(directory, spec, plan, workers, scheduler, progress)


def resume_campaign(
    directory: str | Path, workers: int = 1, scheduler: str | None = None, progress: bool = True
) -> CampaignSummary:
    """Finish a campaign: run exactly the planned cases that have no result row yet."""
    spec, plan = load_campaign(directory)
    with store.campaign_lock(Path(directory)):
        return _execute(Path(directory), spec, plan, workers, scheduler, progress)


@dataclass(frozen=True)
class RerunResult:
    """A recomputed run next to its recorded row.

    Attributes
    ----------
    recorded : pandas.Series or None
        The campaign's row for the run (None when it has not run yet).
    row : pandas.DataFrame
        The recomputed row (same columns).
    timeseries : pandas.DataFrame or None
        The recomputed time series (all signals).
    identical : bool or None
        Whether every recorded metric and the status are reproduced exactly (None if not run).
    comparison : pandas.DataFrame
        Per metric: recorded value, recomputed value, difference (empty if not run).
    environment_changes : dict
        Package -> (campaign version, current version) for the versions that differ.
    """

    recorded: pd.Series | None
    row: pd.DataFrame
    timeseries: pd.DataFrame | None
    identical: bool | None
    comparison: pd.DataFrame
    environment_changes: dict


def rerun_case(directory: str | Path, run_id: int) -> RerunResult:
    """Recompute run ``run_id`` of a campaign in this process and compare with the record."""
    directory = Path(directory)
    spec, plan = load_campaign(directory)
    matches = plan[plan["run_id"] == run_id]
    if matches.empty:
        raise ValueError(f"--case {run_id}: no such run (the plan has runs 0..{len(plan) - 1})")
    plan_row = matches.iloc[0]
    result = execute_case(spec.simulator, case_from_plan_row(spec, plan_row))
    row = result_row(spec, plan_row, result)
    recorded = None
    identical = None
    comparison = pd.DataFrame()
    path = store.run_file(directory, run_id)
    if path.is_file():
        recorded = pd.read_parquet(path).iloc[0]
        columns = [metric_column(spec, m) for m in spec.metrics]
        comparison = pd.DataFrame(
            {
                "recorded": [float(recorded[c]) for c in columns],
                "recomputed": [float(row[c].iloc[0]) for c in columns],
            },
            index=columns,
        )
        comparison["difference"] = comparison["recomputed"] - comparison["recorded"]
        same_metrics = np.array_equal(
            comparison["recorded"], comparison["recomputed"], equal_nan=True
        )
        identical = bool(same_metrics and recorded["status"] == row["status"].iloc[0])
    changes = {}
    environment_path = directory / store.ENVIRONMENT_FILE
    if environment_path.is_file():
        then = json.loads(environment_path.read_text())
        now = store.environment()
        changes = {k: (v, now.get(k)) for k, v in then.items() if now.get(k) != v}
    return RerunResult(recorded, row, result.timeseries, identical, comparison, changes)
