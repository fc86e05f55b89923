"""Dask executor: a small local cluster gives the same runs as the in-process executor."""

from __future__ import annotations

import pandas as pd
import pytest

pytest.importorskip("dask.distributed")

from oos_drake.campaign.executors import DaskExecutor, InlineExecutor  # noqa: E402
from oos_drake.campaign.runner import case_from_plan_row, run_campaign  # noqa: E402
from oos_drake.campaign.samplers import make_plan  # noqa: E402
from oos_drake.campaign.spec import load_spec  # noqa: E402


def test_dask_local_cluster_threads_matches_inline(write_spec):
    spec = load_spec(write_spec())
    plan = make_plan(spec)
    cases = [case_from_plan_row(spec, row) for _, row in plan.iterrows()]
    executor = DaskExecutor(None, workers=2, processes=False)
    try:
        executor.start(spec.simulator)
        dask_results = {r.run_id: r for r in executor.run(spec.simulator, cases)}
    finally:
        executor.close()
    inline = {r.run_id: r for r in InlineExecutor().run(spec.simulator, cases)}
    assert sorted(dask_results) == list(range(spec.n_runs))
    # each worker thread built its own simulator exactly once
    assert {r.simulator_builds for r in dask_results.values()} == {1}
    for run_id, result in inline.items():
        assert dask_results[run_id].status == result.status == "ok"
        assert dask_results[run_id].metrics == result.metrics


def test_campaign_on_a_dask_scheduler_address(write_spec, tmp_path):
    """``--scheduler ADDRESS``: a separate cluster of 2 worker processes, reached by address."""
    from dask.distributed import LocalCluster

    spec = write_spec()
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        run_campaign(spec, tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False)
    run_campaign(spec, tmp_path / "inline", workers=1, progress=False)
    dask = pd.read_parquet(tmp_path / "dask" / "runs.parquet")
    inline = pd.read_parquet(tmp_path / "inline" / "runs.parquet")
    pd.testing.assert_frame_equal(
        dask.drop(columns=["wall time [s]", "cpu time [s]", "worker"]),
        inline.drop(columns=["wall time [s]", "cpu time [s]", "worker"]),
    )
