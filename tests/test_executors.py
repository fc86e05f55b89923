"""The generic executors (:mod:`oos_drake.processes`): one interface for every parallel site.

Serial, process pool and Dask give the same results: the interface itself (order, exceptions,
worker initializers), a small mu sweep (:func:`oos_drake.robust.robust_sweep`) and a small
certified analysis sweep (:func:`oos_drake.analysis.stability.certified_sweep`) compared
number for number, with the chunks of work fixed so that only the executor changes.
"""

from __future__ import annotations

import importlib.util
import os

import control
import numpy as np
import pandas as pd
import pytest

from oos_drake.processes import (
    DaskExecutor,
    PoolExecutor,
    SerialExecutor,
    ThreadExecutor,
    make_executor,
    scheduler_address,
)

HAS_DASK = importlib.util.find_spec("distributed") is not None
needs_dask = pytest.mark.skipif(
    not HAS_DASK, reason='dask.distributed is not installed (pip install "dask[distributed]")'
)

_STATE: dict = {}


def _remember(value) -> None:
    _STATE["value"] = value


def _scaled(x):
    """Uses the state that the initializer left in the worker, and says which process ran it."""
    return x * _STATE["value"], os.getpid()


def _fails(x):
    raise ValueError(f"bad task {x}")


def _check_interface(executor) -> set[int]:
    values = list(range(7))
    mapped = executor.map(_scaled, values)
    assert [m[0] for m in mapped] == [3 * v for v in values]  # ordered, initializer ran
    futures = [executor.submit(_scaled, v) for v in values]
    assert sorted(f.result()[0] for f in executor.as_completed(futures)) == [3 * v for v in values]
    with pytest.raises(ValueError, match="bad task 5"):
        executor.submit(_fails, 5).result()
    assert executor.map(_scaled, []) == []
    return {m[1] for m in mapped}


def test_thread_executor_runs_here_with_one_blas_thread():
    """The fine-grain kind (``make_executor(n, "threads")``): same interface, tasks in threads
    of this process, each with one OpenBLAS thread (checked where OpenBLAS is found)."""
    from oos_drake.blas import _global_pair, _libraries

    with make_executor(2, "threads", initializer=_remember, initargs=(3,)) as threads:
        assert isinstance(threads, ThreadExecutor) and threads.workers == 2
        assert _check_interface(threads) == {os.getpid()}
        getters = [pair[1] for pair in map(_global_pair, _libraries()) if pair is not None]
        inside = threads.submit(lambda: [get() for get in getters]).result()
        assert all(n == 1 for n in inside)
    assert isinstance(make_executor(1, "threads"), SerialExecutor)


def test_serial_executor_runs_here_and_pool_in_workers():
    with make_executor(1, initializer=_remember, initargs=(3,)) as serial:
        assert isinstance(serial, SerialExecutor)
        assert _check_interface(serial) == {os.getpid()}
    with make_executor(2, "processes", initializer=_remember, initargs=(3,)) as pool:
        assert isinstance(pool, PoolExecutor) and pool.workers == 2
        pids = _check_interface(pool)
        assert os.getpid() not in pids and len(pids) <= 2


def test_bad_scheduler_and_workers_are_one_line_errors():
    with pytest.raises(ValueError, match="--workers 0"):
        make_executor(0)
    with pytest.raises(ValueError, match="--scheduler 'dsak'"):
        make_executor(2, "dsak")
    assert scheduler_address("dask") is None and scheduler_address("local") is None
    assert scheduler_address("tcp://10.0.0.1:8786") == "tcp://10.0.0.1:8786"


def test_dask_missing_is_a_one_line_error(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import fails as if absent
    with pytest.raises(ValueError, match=r"--scheduler dask needs Dask: pip install") as error:
        make_executor(2, "dask")
    assert "\n" not in str(error.value)


def test_cli_rejects_a_bad_scheduler_with_status_2(tmp_path, capsys):
    from oos_drake.app.main import main

    for command in (
        ["analyze"],
        ["study", "--vary", "hubs.RH2.mass=1:2:2"],
        ["run"],
        ["synth"],
        ["confirm", "--analysis", str(tmp_path)],
    ):
        with pytest.raises(SystemExit) as exit_:
            main([*command, "--out", str(tmp_path / "a"), "--scheduler", "dsak"])
        assert exit_.value.code == 2
        assert "--scheduler 'dsak'" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()


def test_synth_rejects_zero_workers_with_status_2(tmp_path, capsys):
    """Before any model is built: one line naming the option."""
    from oos_drake.app.main import main

    status = main(["synth", "--plant", "synthetic", "--out", str(tmp_path / "a"), "--workers", "0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "--workers 0" in err[0]
    assert not (tmp_path / "a").exists()


def _sweep_array():
    """k g / ((s+1)(s+2)(s+3)) in unit feedback, complex k = 40 +- 10, four gains g.

    Closed form: ``mu(omega) = |10 g G / (1 + 40 g G)|``, ``G = 1 / ((s+1)(s+2)(s+3))``.
    """
    from oos_drake.lfr import feedback, ucomplex, ureal, usubs

    k = ucomplex("k", 40.0, 10.0)
    g = ureal("g", 1.0, range=(0.5, 1.5))
    loop = feedback(k * g * control.tf(1, [1, 6, 11, 6]), 1)
    return usubs(loop, {"g": GAINS})


GAINS = np.array([0.9, 1.0, 1.1, 1.2])


def _closed_form(model, hz):
    s = 2j * np.pi * np.asarray(hz)
    G = 1.0 / ((s + 1) * (s + 2) * (s + 3))
    g = GAINS[np.asarray(model)]
    return np.abs(10 * g * G / (1 + 40 * g * G))


def _robust_sweep(workers, scheduler):
    from oos_drake.robust import robust_sweep

    omega = np.geomspace(0.5, 10.0, 24)
    return robust_sweep(
        _sweep_array(),
        omega,
        subsets={"k": ["k"]},
        n_jobs=workers,
        scheduler=scheduler,
        chunk_size=2,
        guaranteed=False,
    )


def _analysis(workers, scheduler):
    from oos_drake.analysis.stability import SweepOptions, certified_sweep

    options = SweepOptions(
        n_jobs=workers,
        scheduler=scheduler,
        chunk_size=2,
        converge_passes=1,
        converge_iterations=60,
    )
    omega = 2 * np.pi * np.geomspace(0.05, 5.0, 25)
    res = certified_sweep(_sweep_array(), omega, {"k": ["k"]}, options=options, progress=False)
    cert = res.certificates["k"]
    return res.table, (cert.model, cert.frequency, cert.mu_lower, cert.mu_upper)


def test_mu_sweep_serial_and_pool_agree():
    serial = _robust_sweep(1, None)
    pool = _robust_sweep(2, None)
    pd.testing.assert_frame_equal(serial, pool)
    # and the sweep is a real one: its bounds bracket the closed form at every point
    lower, upper = serial["mu lower [-]"], serial["mu upper [-]"]
    exact = _closed_form(serial["model"], serial["frequency [Hz]"])
    assert np.all(lower <= exact * (1 + 1e-6))
    assert np.all(upper >= exact * (1 - 1e-6))
    assert np.all(upper[serial["tightened"]] <= exact[serial["tightened"]] * 1.01)


def test_analysis_sweep_serial_and_pool_agree():
    serial_table, serial_cert = _analysis(1, None)
    pool_table, pool_cert = _analysis(2, None)
    assert serial_cert == pool_cert
    pd.testing.assert_frame_equal(serial_table, pool_table)


@pytest.mark.slow
@needs_dask
def test_dask_local_cluster_gives_the_pool_results():
    """Interface, mu sweep and analysis on a local Dask cluster of 2 worker processes."""
    with make_executor(2, "dask", initializer=_remember, initargs=(3,)) as dask:
        assert isinstance(dask, DaskExecutor) and dask.workers == 2
        assert os.getpid() not in _check_interface(dask)
    pd.testing.assert_frame_equal(_robust_sweep(2, "dask"), _robust_sweep(2, None))
    dask_table, dask_cert = _analysis(2, "dask")
    pool_table, pool_cert = _analysis(2, None)
    assert dask_cert == pool_cert
    pd.testing.assert_frame_equal(dask_table, pool_table)
