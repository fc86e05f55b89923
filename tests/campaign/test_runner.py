"""Runner reliability: failing/diverging runs recorded, kill -9 + resume, rerun reproducibility."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from oos_drake.campaign import store
from oos_drake.campaign.attitude_sim import FlexibleAttitudeSimulator
from oos_drake.campaign.executors import ProcessPoolExecutor
from oos_drake.campaign.runner import (
    case_from_plan_row,
    rerun_case,
    resume_campaign,
    run_campaign,
)
from oos_drake.campaign.samplers import make_plan
from oos_drake.campaign.spec import load_spec

from . import crashing_sim
from .spec_texts import BASE_SPEC

METRICS = ["ape [rad]", "peak_torque [N m]"]


def _oos(*args, **kwargs):
    return [sys.executable, "-m", "oos_drake.app.campaign", "campaign", *map(str, args)]


def test_diverging_run_is_recorded_and_the_campaign_goes_on(write_spec, tmp_path):
    # omega0 = 0.1 rad/s against a 3 N m torque limit: the hub needs at least
    # J w^2 / (2 u_max) = 600 * 0.01 / 6 = 1 rad to stop, beyond the 0.5 rad divergence limit
    text = BASE_SPEC.replace(
        "[requirements]",
        'omega0 = { distribution = "choice", values = [0.0, 0.1] }\n\n[requirements]',
    )
    summary = run_campaign(write_spec(text), tmp_path / "c", progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    assert runs["run_id"].tolist() == list(range(12)) and summary.executed == 12
    diverging = runs["omega0 [rad/s]"] == 0.1
    assert 0 < diverging.sum() < 12
    assert (runs.loc[diverging, "status"] == "diverged").all()
    assert runs.loc[diverging, "error"].str.contains("divergence limit").all()
    assert runs.loc[diverging, METRICS].isna().all().all()
    assert not runs.loc[diverging, "pass"].any()
    assert (runs.loc[~diverging, "status"] == "ok").all()
    assert runs.loc[~diverging, METRICS].notna().all().all()
    assert summary.status_counts == {
        "diverged": int(diverging.sum()),
        "ok": int((~diverging).sum()),
    }


def test_failing_run_is_recorded_with_its_error(write_spec, tmp_path, monkeypatch):
    original = FlexibleAttitudeSimulator.run

    def flaky(self, case):
        if case.run_id == 3:
            raise RuntimeError("solver exploded")
        return original(self, case)

    monkeypatch.setattr(FlexibleAttitudeSimulator, "run", flaky)
    run_campaign(write_spec(), tmp_path / "c", progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet").set_index("run_id")
    assert runs.loc[3, "status"] == "failed"
    assert runs.loc[3, "error"].startswith("RuntimeError: solver exploded")
    assert (runs.drop(index=3)["status"] == "ok").all() and len(runs) == 12


def test_rerun_reproduces_metrics_exactly(write_spec, tmp_path):
    run_campaign(write_spec(), tmp_path / "c", progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    for run_id in (0, 5, 11):
        result = rerun_case(tmp_path / "c", run_id)
        assert result.identical is True
        recorded = runs[runs["run_id"] == run_id].iloc[0]
        for column in METRICS:
            assert result.row[column].iloc[0] == recorded[column]  # bit-identical
        stored = pd.read_parquet(store.timeseries_file(tmp_path / "c", run_id))
        np.testing.assert_array_equal(
            stored["theta_hub [rad]"], result.timeseries["theta_hub [rad]"]
        )
    cli = subprocess.run(
        _oos("rerun", tmp_path / "c", "--case", 4), capture_output=True, text=True, timeout=120
    )
    assert cli.returncode == 0, cli.stderr
    assert "reproduced exactly" in cli.stdout
    with pytest.raises(ValueError, match="--case 12: no such run"):
        rerun_case(tmp_path / "c", 12)


def _live_group_members(group: int) -> set[int]:
    """Pids of the process group that are alive (zombies excluded)."""
    members = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == group and fields[0] != "Z":
            members.add(int(stat.parent.name))
    return members


@pytest.mark.parametrize("workers", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_kill_9_then_resume_loses_and_repeats_nothing(write_spec, tmp_path, workers):
    n_runs = 30
    # ~30 ms per run so that the kill lands mid-campaign
    text = BASE_SPEC.replace("n_runs = 12", f"n_runs = {n_runs}").replace(
        "control_rate = 5.0", "control_rate = 40.0"
    )
    spec = write_spec(text)
    killed = tmp_path / "killed"
    process = subprocess.Popen(
        _oos("run", spec, "--out", killed, "--workers", workers, "--quiet"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + 90
    try:
        while len(store.finished_run_ids(killed)) < 6:
            assert process.poll() is None, "campaign ended before it could be killed"
            assert time.monotonic() < deadline, "campaign did not start"
            time.sleep(0.02)
        os.kill(process.pid, signal.SIGKILL)  # the driver only
        process.wait()
        # pool workers notice that their driver died and exit by themselves
        while _live_group_members(process.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _live_group_members(process.pid), "orphan worker processes"
    finally:
        if _live_group_members(process.pid):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    done_before = store.finished_run_ids(killed)
    assert 6 <= len(done_before) < n_runs
    assert not (killed / "runs.parquet").exists()
    mtimes = {i: store.run_file(killed, i).stat().st_mtime_ns for i in done_before}
    # a half-written leftover of an interrupted write must be ignored and cleaned up
    (killed / "runs" / ".run_000029.parquet.abc.tmp").write_bytes(b"PAR1 truncated")

    result = subprocess.run(
        _oos("resume", killed, "--workers", workers, "--quiet"),
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert result.returncode == 0, result.stderr
    assert f"{n_runs - len(done_before)} run now, {len(done_before)} already done" in result.stdout
    assert not list((killed / "runs").glob("*.tmp"))
    # finished runs were not redone
    assert {i: store.run_file(killed, i).stat().st_mtime_ns for i in done_before} == mtimes

    reference = tmp_path / "reference"
    run_campaign(spec, reference, progress=False)
    resumed = pd.read_parquet(killed / "runs.parquet")
    uninterrupted = pd.read_parquet(reference / "runs.parquet")
    assert resumed["run_id"].tolist() == list(range(n_runs))  # each run exactly once
    # bit for bit: every column but the timing and worker ones
    machine = ["wall time [s]", "cpu time [s]", "worker"]
    pd.testing.assert_frame_equal(
        resumed.drop(columns=machine), uninterrupted.drop(columns=machine), check_exact=True
    )
    assert len(list((killed / "timeseries").glob("run_*.parquet"))) == n_runs


def test_process_pool_matches_in_process_results(write_spec, tmp_path):
    spec = write_spec()
    run_campaign(spec, tmp_path / "pool", workers=2, progress=False)
    run_campaign(spec, tmp_path / "inline", workers=1, progress=False)
    pool = pd.read_parquet(tmp_path / "pool" / "runs.parquet")
    inline = pd.read_parquet(tmp_path / "inline" / "runs.parquet")
    pd.testing.assert_frame_equal(
        pool.drop(columns=["wall time [s]", "cpu time [s]", "worker"]),
        inline.drop(columns=["wall time [s]", "cpu time [s]", "worker"]),
    )
    here = f"{socket.gethostname()}:{os.getpid()}"
    assert set(inline["worker"]) == {here}
    assert 1 <= pool["worker"].nunique() <= 2 and here not in set(pool["worker"])


@pytest.mark.slow  # (the Dask thread test checks the same cache, quickly)
def test_pool_builds_the_simulator_once_per_worker_process(write_spec):
    spec = load_spec(write_spec())
    cases = [case_from_plan_row(spec, row) for _, row in make_plan(spec).iterrows()]
    executor = ProcessPoolExecutor(2)
    try:
        results = list(executor.run(spec.simulator, cases))
    finally:
        executor.close()
    assert sorted(r.run_id for r in results) == list(range(12))
    assert {r.simulator_builds for r in results} == {1}
    assert 1 <= len({r.worker for r in results}) <= 2  # (a loaded machine may favour one)


def test_resume_of_a_finished_campaign_runs_nothing(write_spec, tmp_path):
    run_campaign(write_spec(), tmp_path / "c", progress=False)
    summary = resume_campaign(tmp_path / "c", progress=False)
    assert summary.executed == 0 and summary.skipped == 12


def load_timeseries(directory: Path, run_ids=None) -> pd.DataFrame:
    """Retained time series of ``run_ids`` (default: all kept), stacked, with a ``run_id`` column.

    Runs whose time series was not kept are skipped (``oos campaign rerun`` recomputes them).
    """
    folder = Path(directory) / store.TIMESERIES_DIR
    if run_ids is None:
        files = sorted(folder.glob("run_*.parquet")) if folder.is_dir() else []
    else:
        files = [store.timeseries_file(directory, int(i)) for i in run_ids]
        files = [f for f in files if f.is_file()]
    if not files:
        return pd.DataFrame()
    return pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)


def test_only_failed_runs_keep_their_selected_signals(write_spec, tmp_path):
    text = BASE_SPEC.replace('keep = "all"', 'keep = "failed"').replace(
        "[requirements]",
        'omega0 = { distribution = "uniform", low = -0.008, high = 0.008 }\n\n[requirements]',
    )
    run_campaign(write_spec(text), tmp_path / "c", progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    failing = set(runs.loc[~runs["pass"], "run_id"])
    assert 0 < len(failing) < len(runs)
    kept = {int(p.stem.removeprefix("run_")) for p in (tmp_path / "c" / "timeseries").iterdir()}
    assert kept == failing
    series = pd.read_parquet(store.timeseries_file(tmp_path / "c", min(failing)))
    assert list(series.columns) == ["run_id", "time [s]", "theta_hub [rad]", "torque_command [N m]"]
    stacked = load_timeseries(tmp_path / "c")
    assert set(stacked["run_id"]) == failing
    assert load_timeseries(tmp_path / "c", [min(failing)]).equals(series)
    # the APE metric is the peak of the retained attitude signal
    ape = runs.set_index("run_id").loc[min(failing), "ape [rad]"]
    assert series["theta_hub [rad]"].abs().max() == ape


def test_a_run_that_kills_its_worker_is_recorded_and_the_others_complete(write_spec, tmp_path):
    text = BASE_SPEC.replace(
        'name = "flexible-attitude"', f'name = "{crashing_sim.__name__}:make_simulator"'
    )
    spec = write_spec(text)
    run_campaign(spec, tmp_path / "c", workers=2, progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    assert runs["run_id"].tolist() == list(range(12))
    crashing = runs["run_id"] == 5
    assert (runs.loc[crashing, "status"] == "failed").all()
    assert runs.loc[crashing, "error"].str.startswith("WorkerDied").all()
    assert (runs.loc[~crashing, "status"] == "ok").all()
    # the surviving runs are exactly those of the ordinary simulator
    reference = BASE_SPEC
    run_campaign(write_spec(reference, name="ref"), tmp_path / "ref", progress=False)
    ref = pd.read_parquet(tmp_path / "ref" / "runs.parquet")
    for column in METRICS:
        assert runs.loc[~crashing, column].tolist() == ref.loc[~crashing, column].tolist()


def test_a_run_over_the_timeout_is_stopped_and_recorded(write_spec, tmp_path):
    text = BASE_SPEC.replace(
        'name = "flexible-attitude"', f'name = "{crashing_sim.__name__}:make_hanging_simulator"'
    ).replace("random_seed = 7", "random_seed = 7\nrun_timeout = 2.0")
    run_campaign(write_spec(text), tmp_path / "c", workers=1, progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet").set_index("run_id")
    assert runs.loc[4, "status"] == "failed"
    assert runs.loc[4, "error"].startswith("Timeout: the run exceeded 2 s")
    assert (runs.drop(index=4)["status"] == "ok").all() and len(runs) == 12
    assert "run_timeout = 2.0" in (tmp_path / "c" / "spec.toml").read_text()


@pytest.mark.parametrize("workers", [1, 2])
def test_runs_report_processor_time_and_use_one_blas_thread(workers):
    """Processor time counts the busy part of a run, not its sleep; the run sees one OpenBLAS
    thread, in the calling process (inline) and in a pool worker."""
    from oos_drake.campaign.executors import InlineExecutor
    from oos_drake.campaign.simulator import MissionWindow, RunCase, SimulatorRecipe

    recipe = SimulatorRecipe.create("tests.campaign.crashing_sim:make_probe_simulator", {})
    executor = InlineExecutor() if workers == 1 else ProcessPoolExecutor(1)
    try:
        executor.start(recipe)
        (result,) = executor.run(recipe, [RunCase(0, 1, {}, MissionWindow(0.0, 1.0))])
    finally:
        executor.close()
    assert result.status == "ok", result.error
    # the 0.2 s busy loop is counted, the 0.3 s sleep is not (whatever the machine's load)
    assert result.cpu_time >= 0.2, result.cpu_time
    assert result.wall_time - result.cpu_time >= 0.29, (result.wall_time, result.cpu_time)
    if result.metrics["blas_threads"] >= 0:  # an OpenBLAS with a thread getter is loaded
        assert result.metrics["blas_threads"] == 1
