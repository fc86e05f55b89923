"""Fault injection in the campaign runner (issue 15): a run that returns NaN metrics, a run file
truncated on disk, and a second process on a campaign already in use. (A run that raises, one
that kills its worker, one over its time limit and ``kill -9`` + resume: ``test_runner.py``.)

Each fault is recorded with its reason or refused with a one-line error; the campaign completes,
``resume`` repairs what is missing, and no finished run is lost: the repaired campaign equals an
uninterrupted one, metric for metric.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pandas as pd
import pytest

from oos_drake.campaign import store
from oos_drake.campaign.runner import resume_campaign, run_campaign

from .spec_texts import BASE_SPEC

METRICS = ["ape [rad]", "peak_torque [N m]"]
#: Columns that depend only on the plan and the simulator (not on timing or worker ids).
DETERMINISTIC = ["run_id", "seed", "region", *METRICS, "status", "error", "pass"]


def _with_simulator(factory: str) -> str:
    return BASE_SPEC.replace(
        'name = "flexible-attitude"', f'name = "tests.campaign.crashing_sim:{factory}"'
    )


def _same_runs(a: pd.DataFrame, b: pd.DataFrame) -> None:
    pd.testing.assert_frame_equal(
        a[DETERMINISTIC].reset_index(drop=True), b[DETERMINISTIC].reset_index(drop=True)
    )


def test_nan_metrics_are_a_failed_run_with_its_reason(write_spec, tmp_path):
    summary = run_campaign(
        write_spec(_with_simulator("make_nan_simulator")), tmp_path / "c", progress=False
    )
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet").set_index("run_id")
    assert len(runs) == 12 and summary.executed == 12
    assert runs.loc[2, "status"] == "failed"
    assert runs.loc[2, "error"] == "NonFiniteMetric: ape = nan"
    assert not runs.loc[2, "pass"]
    assert (runs.drop(index=2)["status"] == "ok").all()
    assert summary.status_counts == {"ok": 11, "failed": 1}


@pytest.mark.parametrize("folder", [store.RUNS_DIR, store.TIMESERIES_DIR])
def test_a_truncated_run_file_is_quarantined_and_redone_by_resume(write_spec, tmp_path, folder):
    spec = write_spec()  # keeps every run's time series
    run_campaign(spec, tmp_path / "reference", progress=False)
    directory = tmp_path / "c"
    run_campaign(spec, directory, progress=False)
    victim = directory / folder / "run_000003.parquet"
    assert victim.is_file()
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) // 2])  # what a crash mid-write of a copy leaves
    other_rows = {i: store.run_file(directory, i).stat().st_mtime_ns for i in range(12) if i != 3}

    summary = resume_campaign(directory, progress=False)
    assert summary.executed == 1 and summary.skipped == 11
    assert (directory / store.QUARANTINE_DIR / folder / "run_000003.parquet").read_bytes() == (
        data[: len(data) // 2]
    )
    # finished runs were not redone; the repaired campaign equals the uninterrupted one
    assert {i: store.run_file(directory, i).stat().st_mtime_ns for i in other_rows} == other_rows
    _same_runs(
        pd.read_parquet(directory / "runs.parquet"),
        pd.read_parquet(tmp_path / "reference" / "runs.parquet"),
    )
    assert len(list((directory / store.TIMESERIES_DIR).glob("run_*.parquet"))) == 12


def _cli(*args) -> list[str]:
    return [sys.executable, "-m", "oos_drake.app.campaign", "campaign", *map(str, args)]


@pytest.fixture
def campaign_in_progress(write_spec, tmp_path):
    """A campaign run by another process, held after its first run until the test opens the
    gate (``gate.touch()``): (spec, directory, process, gate). Killed at teardown if running."""
    spec = write_spec(_with_simulator("make_gated_simulator"))
    directory = tmp_path / "c"
    gate = tmp_path / "gate"
    process = subprocess.Popen(
        _cli("run", spec, "--out", directory, "--no-progress"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "OOS_TEST_GATE": str(gate)},
    )
    try:
        deadline = time.monotonic() + 120
        while not store.finished_run_ids(directory):
            assert process.poll() is None, process.stderr.read()
            assert time.monotonic() < deadline, "the campaign did not start"
            time.sleep(0.05)
        yield spec, directory, process, gate
    finally:
        if process.poll() is None:
            process.kill()
        process.wait()


def test_a_second_process_on_a_campaign_in_use_is_refused(campaign_in_progress):
    spec, directory, first, gate = campaign_in_progress

    def files():  # (temporary files of the writes in flight come and go)
        return {p.relative_to(directory) for p in directory.rglob("*") if p.suffix != ".tmp"}

    listing = files()
    for command in (
        _cli("resume", directory, "--no-progress"),
        _cli("run", spec, "--out", directory, "--no-progress"),
    ):
        second = subprocess.run(command, capture_output=True, text=True, timeout=120)
        assert second.returncode == 2, second.stderr
        message = second.stderr.strip().splitlines()
        assert len(message) == 1, second.stderr
        assert str(directory) in message[0]
        assert "in use" in message[0] or "already holds a campaign" in message[0]
    # the refused commands wrote nothing (the first campaign only added run files)
    after = files()
    assert listing <= after
    assert all(str(p).startswith((store.RUNS_DIR, store.TIMESERIES_DIR)) for p in after - listing)
    gate.touch()
    assert first.wait(timeout=180) == 0
    runs = pd.read_parquet(directory / "runs.parquet")
    assert runs["run_id"].tolist() == list(range(12))
    assert (runs["status"] == "ok").all()


def test_the_lock_is_released_when_its_holder_is_killed(campaign_in_progress):
    """``flock`` dies with its process: a ``kill -9`` never leaves a campaign locked."""
    import signal

    _, directory, first, gate = campaign_in_progress
    with pytest.raises(ValueError, match=f"pid {first.pid}"):
        with store.campaign_lock(directory):
            pass
    os.kill(first.pid, signal.SIGKILL)
    first.wait()
    gate.touch()
    summary = resume_campaign(directory, progress=False)
    assert summary.executed + summary.skipped == 12
