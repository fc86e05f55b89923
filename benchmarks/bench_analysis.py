"""Benchmark of the analysis' mu sweep: cold grid vs continuation grid vs certified sweep.

Run: ``.venv/bin/python benchmarks/bench_analysis.py [--models 40] [--first 40] [--jobs 1]``

On ``--models`` consecutive mission configurations of the paper's 330 (starting at index
``--first``; the default slice holds the first docking at 255 s), synthesized controller if
``--controller`` is given (else the baseline PD), uncertainty subsets ``--subsets`` (default:
the total set), common 12/decade grid:

* ``cold grid``: every point from Osborne balancing, 30 BFGS iterations (the session-1 sweep);
* ``continuation grid``: the first model converged, every next one started from its
  predecessor's scalings (15 iterations), spikes re-solved from frequency neighbours;
* ``certified sweep``: the continuation grid plus spike resolution and the certified peak.

For each: wall and CPU time (this process and its workers), the largest upper bound and the
number of "spikes" (upper bound above 1.03 x the certified lower bound: points that would
need tightening), then per subset what the spike resolution did (rounds, spikes left, why it
stopped, whether a budget cut it short, seconds). Timings on a shared machine are noisy: read
the ratios of the same run.

``--subsets total,real,modal`` with the baseline controller is the case that used to explode
(a flat real-parameter ridge whose converged D-G bound stays 3-4 % above the exact mu).
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
    parser.add_argument("--subsets", default="total", help="comma-separated uncertainty subsets")
    args = parser.parse_args()

    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.models import mission_closed_loop, mission_times
    from oos_drake.analysis.stability import SweepOptions, certified_sweep, mu_sweep
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.blas import limit_blas_threads

    limit_blas_threads(1)
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario("paper")
    controller = scenario_controller(args.controller, scenario)
    times = mission_times(330, scenario)[args.first : args.first + args.models]
    arr = mission_closed_loop(controller, times, scenario).system
    named = uncertainty_subsets(arr.uncertainty)
    total = {k: named[k] for k in args.subsets.split(",") if k}
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
    first = next(iter(total))
    cert = runs[-1][1].certificates[first]
    lower = cert.mu_lower
    print(
        f"{args.models} configurations from t = {times[0]:.0f} s, {controller.label} controller; "
        f"{first}: certified mu in [{lower:.4f}, {cert.mu_upper:.4f}] "
        f"(gap {100 * cert.gap:.2f} %) at "
        f"t = {cert.time:.0f} s, {cert.frequency:.3f} Hz"
    )
    print(
        f"{'method':40s} {'wall [s]':>9s} {'CPU [s]':>9s} {'points':>7s} {'max upper':>10s} "
        f"{'spikes':>7s}"
    )
    for name, out, wall, cpu in runs:
        table = out if hasattr(out, "columns") else out.table
        table = table[table["subset"] == first]
        spikes = int(np.sum(table["mu upper [-]"].to_numpy() > 1.03 * lower))
        print(
            f"{name:40s} {wall:9.1f} {cpu:9.1f} {len(table):7d} "
            f"{table['mu upper [-]'].max():10.4f} {spikes:7d}"
        )
    cold, cont = runs[0], runs[1]
    print(f"continuation vs cold grid: CPU ratio {cold[3] / max(cont[3], 1e-9):.2f}x")
    study = runs[-1][1]
    stages = {k: round(v, 1) for k, v in study.timings.items()}
    print(f"certified sweep stages [s, wall]: {stages}")
    print(
        f"{'subset':15s} {'mu_lower':>9s} {'mu_upper':>9s} {'gap [%]':>8s} {'rounds':>6s} "
        f"{'left':>6s} {'searches':>8s} {'stop':>12s} {'budget out':>10s} {'seconds':>8s}"
    )
    for name, c in study.certificates.items():
        r = study.reports[name]
        print(
            f"{name:15s} {c.mu_lower:9.4f} {c.mu_upper:9.4f} {100 * c.gap:8.2f} {r.rounds:6d} "
            f"{r.points_left:6d} {len(r.searched_models):8d} {r.stop:>12s} "
            f"{'yes' if r.budget_exhausted else 'no':>10s} {r.seconds:8.1f}"
        )


if __name__ == "__main__":
    main()
