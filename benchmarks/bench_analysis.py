"""Benchmark of the analysis' mu sweep: cold grid vs continuation grid vs certified sweep.

Run: ``.venv/bin/python benchmarks/bench_analysis.py [--models 40] [--first 40] [--jobs 1]``

On ``--models`` consecutive mission configurations of the paper's 330 (starting at index
``--first``; the default slice holds the first docking at 255 s), synthesized controller if
``--controller`` is given (else the baseline PD), total uncertainty set, common 12/decade grid:

* ``cold grid``: every point from Osborne balancing, 30 BFGS iterations (the session-1 sweep);
* ``continuation grid``: the first model converged, every next one started from its
  predecessor's scalings (15 iterations), spikes re-solved from frequency neighbours;
* ``certified sweep``: the continuation grid plus spike resolution and the certified peak.

For each: wall and CPU time (this process and its workers), the largest upper bound and the
number of "spikes" (upper bound above 1.03 x the certified lower bound: points that would
need tightening). Timings on a shared machine are noisy: read the ratios of the same run.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=40)
    parser.add_argument("--first", type=int, default=40)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--controller", default=None, help="controller.json (default: baseline)")
    args = parser.parse_args()

    from oos_drake.analysis.cli import _controller
    from oos_drake.analysis.models import mission_closed_loop, mission_times
    from oos_drake.analysis.stability import SweepOptions, certified_sweep, mu_sweep
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.blas import limit_blas_threads

    limit_blas_threads(1)
    controller = _controller(args.controller)
    times = mission_times(330)[args.first : args.first + args.models]
    arr = mission_closed_loop(controller, times).system
    total = {"total": uncertainty_subsets(arr.uncertainty)["total"]}
    omega = 2 * np.pi * np.geomspace(0.005, 5.0, 37)

    runs = []
    for name, fn in (
        (
            "cold grid (30 it, session 1)",
            lambda: mu_sweep(
                arr,
                omega,
                total,
                times=times,
                options=SweepOptions(n_jobs=args.jobs, continuation_iterations=0),
                progress=False,
            ),
        ),
        (
            "continuation grid",
            lambda: mu_sweep(
                arr,
                omega,
                total,
                times=times,
                options=SweepOptions(n_jobs=args.jobs),
                progress=False,
            ),
        ),
        (
            "certified sweep (grid + spikes + peak)",
            lambda: certified_sweep(
                arr,
                omega,
                total,
                times=times,
                options=SweepOptions(n_jobs=args.jobs),
                progress=False,
            ),
        ),
    ):
        w0, c0 = time.perf_counter(), _cpu()
        out = fn()
        runs.append((name, out, time.perf_counter() - w0, _cpu() - c0))
    cert = runs[-1][1].certificates["total"]
    lower = cert.mu_lower
    print(
        f"{args.models} configurations from t = {times[0]:.0f} s, {controller.label} controller; "
        f"certified mu in [{lower:.4f}, {cert.mu_upper:.4f}] (gap {100 * cert.gap:.2f} %) at "
        f"t = {cert.time:.0f} s, {cert.frequency:.3f} Hz"
    )
    print(
        f"{'method':40s} {'wall [s]':>9s} {'CPU [s]':>9s} {'points':>7s} {'max upper':>10s} "
        f"{'spikes':>7s}"
    )
    for name, out, wall, cpu in runs:
        table = out if hasattr(out, "columns") else out.table
        spikes = int(np.sum(table["mu_upper"].to_numpy() > 1.03 * lower))
        print(
            f"{name:40s} {wall:9.1f} {cpu:9.1f} {len(table):7d} "
            f"{table['mu_upper'].max():10.4f} {spikes:7d}"
        )
    cold, cont = runs[0], runs[1]
    print(f"continuation vs cold grid: CPU ratio {cold[3] / max(cont[3], 1e-9):.2f}x")


if __name__ == "__main__":
    main()
