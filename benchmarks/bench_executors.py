"""Benchmark: per-task overhead of the executors (:func:`oos_drake.processes.make_executor`).

Every parallel site of the package runs on one executor interface; this measures what the
interface costs against the raw ``concurrent.futures`` pool it wraps (the baseline, measured in
the same run), and what Dask's local cluster costs per task:

- ``empty``: a task that returns at once (the per-task overhead alone: submit, pickle, result);
- ``mu``: mu upper bounds of a batch of 16 random 8 x 8 complex matrices (a small real task).

Start-up (pool or cluster creation) is timed apart from the tasks. Prints seconds per task and
ratios to the raw pool. On a shared machine, compare ratios of one run only.

Run: ``.venv/bin/python benchmarks/bench_executors.py [--tasks 400] [--workers 2] [--no-dask]``
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import numpy as np

from oos_drake.processes import make_executor, process_pool


def empty(i: int) -> int:
    return i


def mu_batch(seed: int) -> float:
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu_upper import mu_upper_bound

    rng = np.random.default_rng(seed)
    M = rng.normal(size=(16, 8, 8)) + 1j * rng.normal(size=(16, 8, 8))
    structure = parse_blk(np.array([[2, 0], [2, 0], [1, 0], [1, 0], [2, 2]]))
    return float(mu_upper_bound(M, structure, max_iter=20).upper.max())


def _time_tasks(run, fn, n) -> float:
    run(fn, range(min(n, 8)))  # warm the workers (imports, compiled kernels)
    start = time.perf_counter()
    out = run(fn, range(n))
    elapsed = time.perf_counter() - start
    assert len(out) == n
    return elapsed / n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", type=int, default=400, help="empty tasks per executor")
    parser.add_argument("--mu-tasks", type=int, default=40, help="mu tasks per executor")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-dask", action="store_true", help="skip the Dask local cluster")
    args = parser.parse_args()
    kinds = ["raw pool", "serial", "processes"]
    if not args.no_dask and importlib.util.find_spec("distributed") is not None:
        kinds.append("dask")
    rows = {}
    for kind in kinds:
        start = time.perf_counter()
        if kind == "raw pool":
            executor = process_pool(args.workers)

            def run(fn, items, pool=executor):
                return list(pool.map(fn, items))
        else:
            workers = 1 if kind == "serial" else args.workers
            executor = make_executor(workers, None if kind != "dask" else "dask")
            run = executor.map
        startup = time.perf_counter() - start
        try:
            rows[kind] = (
                startup,
                _time_tasks(run, empty, args.tasks),
                _time_tasks(run, mu_batch, args.mu_tasks),
            )
        finally:
            executor.shutdown()
    base = rows["raw pool"]
    print(f"{args.workers} workers, {args.tasks} empty tasks, {args.mu_tasks} mu tasks")
    print(
        f"{'executor':>10s} {'start [s]':>10s} {'empty [ms/task]':>16s} {'ratio':>7s} "
        f"{'mu [ms/task]':>13s} {'ratio':>7s}"
    )
    for kind, (startup, e, m) in rows.items():
        print(
            f"{kind:>10s} {startup:10.2f} {1e3 * e:16.3f} {e / base[1]:7.2f} "
            f"{1e3 * m:13.2f} {m / base[2]:7.2f}"
        )


if __name__ == "__main__":
    main()
