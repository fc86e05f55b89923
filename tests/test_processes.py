"""Worker processes never outlive their parent (issue 15: ``kill -9`` of ``oos run`` during the
analysis left its two workers running), and every pool of the package is made in one place."""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "oos_drake"


def _children(pid: int) -> set[int]:
    """Process ids whose parent is ``pid`` (Linux /proc)."""
    found = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.add(int(entry.name))
    return found


def _descendants(pids: set[int]) -> set[int]:
    found, frontier = set(), set(pids)
    while frontier:
        frontier = set().union(*(_children(p) for p in frontier)) - found
        found |= frontier
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has exited (only its parent's record is left)


def _wait_for(predicate, timeout: float, period: float = 0.1):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(period)
    return predicate()


def _kill_and_check_workers(command: list[str], workers: int, *, start_timeout: float) -> None:
    """Start ``command``, wait for ``workers`` busy child processes, ``kill -9`` the parent, and
    check that every worker is gone within 10 s."""
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:

        def pool_children():
            kids = {k for k in _children(proc.pid) if _alive(k)}
            # the resource tracker of multiprocessing is a child too; the workers are the rest
            kids = {k for k in kids if b"resource_tracker" not in _cmdline(k)}
            return kids if len(kids) >= workers else None

        kids = _wait_for(pool_children, start_timeout, period=0.2)
        assert kids, f"no worker processes appeared within {start_timeout} s"
        time.sleep(1.0)  # let them get busy
        kids |= _descendants(kids)  # a Dask nanny's worker process, for instance
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        survivors = _wait_for(lambda: {k for k in kids if _alive(k)} or None, 0.0)
        gone = _wait_for(lambda: not any(_alive(k) for k in kids), 10.0)
        assert gone, f"workers {sorted(k for k in kids if _alive(k))} survived (were {survivors})"
    finally:
        if proc.poll() is None:
            proc.kill()


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


POOL_SCRIPT = """
import sys, time
from oos_drake.processes import make_executor, process_pool

def busy(seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass
    return seconds

if __name__ == "__main__":
    kind, value = sys.argv[1:3]
    if kind == "pool":  # value: the start method
        with process_pool(2, method=value) as pool:
            print(list(pool.map(busy, [120.0] * 4)))
    else:  # value: the scheduler
        with make_executor(2, value) as executor:
            print(executor.map(busy, [120.0] * 4))
"""


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_pool_workers_die_with_their_parent(tmp_path, method):
    script = tmp_path / "pool.py"
    script.write_text(POOL_SCRIPT)
    _kill_and_check_workers([sys.executable, str(script), "pool", method], 2, start_timeout=60)


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("scheduler", ["processes", "dask"])
def test_executor_workers_die_with_their_parent(tmp_path, scheduler):
    """The executors of every parallel site: the process pool, and a local Dask cluster (whose
    worker processes are Dask's, not watched by :func:`exit_with_parent`)."""
    if scheduler == "dask":
        pytest.importorskip("distributed", reason="dask.distributed is not installed")
    script = tmp_path / "executor.py"
    script.write_text(POOL_SCRIPT)
    _kill_and_check_workers(
        [sys.executable, str(script), "executor", scheduler], 2, start_timeout=120
    )


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_kill_9_of_oos_analyze_leaves_no_worker(tmp_path):
    """The real command, killed during its mu sweep (the case reported in issue 15)."""
    command = [
        sys.executable,
        "-m",
        "oos_drake.app.main",
        "analyze",
        "--out",
        str(tmp_path / "analysis"),
        "--configurations",
        "40",
        "--quiet",
    ]
    _kill_and_check_workers(command, 2, start_timeout=240)
    assert not (tmp_path / "analysis" / "stability_peaks.parquet").exists()


def test_every_process_pool_comes_from_processes_module():
    """Pools made elsewhere would not carry the parent watcher: only ``oos_drake.processes``
    starts worker processes and thread pools, and only its executors make Dask clusters and
    clients (every parallel site runs on :func:`oos_drake.processes.make_executor`)."""
    starters = {
        "ProcessPoolExecutor",
        "ThreadPoolExecutor",
        "Pool",
        "Process",
        "fork",
        "Popen",
        "LocalCluster",
        "Client",
    }
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "processes.py":
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        own = {n.name for n in ast.walk(tree) if isinstance(n, ast.ClassDef)}  # wrappers
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                func = node.func
                called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
                if called in starters - own:
                    offenders.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {called}()")
    assert not offenders, "processes started outside oos_drake/processes.py: " + "; ".join(
        offenders
    )
