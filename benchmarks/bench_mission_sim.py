"""Drake mission simulation benchmark: speed, integrator choice, parallel efficiency.

Run as a script (the machine is shared: the default is short)::

    .venv/bin/python benchmarks/bench_mission_sim.py            # all parts
    .venv/bin/python benchmarks/bench_mission_sim.py --skip-full --runs 6

1. One whole 1500 s mission with all 24 flexible modes, the arm, the captured and docked target,
   the 10 Hz flight software: wall time and processor time of this process (the one-core figure
   when other jobs share the machine), as multiples of real time.
2. Integrator choice on the same 5 s window before the capture: Radau3 (the default) against the
   explicit Runge-Kutta 3 (baseline measured in the same run); the explicit integrator is limited
   by the stiff joint PDs and bushings. ``--accuracy-study`` adds the attitude error of each
   Radau3 accuracy against a 1e-7 reference.
3. Parallel efficiency ``T(1 worker) / (2 T(2 workers))`` of the campaign's local process pool with
   the Drake simulator: both pools warm (simulator built in each worker before timing), the same
   cases, interleaved repeats, best of each. By default each worker runs in its own session (see
   :func:`isolated_simulator`: Linux autogroup scheduling otherwise caps a whole pool at one
   session's share on a shared machine); ``--same-session`` measures the plain pool.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import pandas as pd

from oos_drake.campaign.drake_simulator import FACTORY_PATH
from oos_drake.campaign.executors import ProcessPoolExecutor
from oos_drake.campaign.simulator import MissionWindow, RunCase, SimulatorRecipe
from oos_drake.multibody.mission import MissionOptions
from oos_drake.multibody.mission_sim import MissionSimulation

# spawned pool workers import this module by name for the isolated factory below
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def isolated_simulator(**options):
    """Benchmark-only factory: the worker leaves its session first (``os.setsid``).

    Linux's autogroup scheduler gives each *session* one fair share of the CPUs: on a machine
    shared with other users' sessions, every worker of a pool started from one shell competes
    for that single share, so adding a worker cannot speed anything up and the measured
    efficiency says nothing about the code. A worker in its own session gets its own share,
    as it would on a dedicated machine.
    """
    try:
        os.setsid()
    except OSError:
        pass  # already a session leader
    from oos_drake.campaign.drake_simulator import make_simulator

    return make_simulator(**options)


def full_mission() -> dict:
    """Time one whole mission; return the table row."""
    simulation = MissionSimulation(MissionOptions())
    result = simulation.run({}, seed=1)
    return {
        "case": "full mission 0-1500 s, radau3, 10 Hz FSW",
        "sim [s]": simulation.duration,
        "wall [s]": result.wall_time,
        "cpu [s]": result.cpu_time,
        "x RT (wall)": simulation.duration / result.wall_time,
        "x RT (cpu)": simulation.duration / result.cpu_time,
        "steps": result.steps,
        "APE [rad]": result.metrics["ape"],
    }


def integrators(start: float = 100.0, end: float = 105.0) -> list[dict]:
    """Radau3 against RK3 on the same window."""
    rows = []
    for name in ("radau3", "runge_kutta3"):
        simulation = MissionSimulation(MissionOptions(integrator=name))
        result = simulation.run({}, seed=1, start=start, end=end, log=False)
        rows.append(
            {
                "case": f"window {start:g}-{end:g} s, {name}",
                "sim [s]": end - start,
                "wall [s]": result.wall_time,
                "cpu [s]": result.cpu_time,
                "x RT (wall)": (end - start) / result.wall_time,
                "x RT (cpu)": (end - start) / result.cpu_time,
                "steps": result.steps,
                "APE [rad]": result.metrics["ape"],
            }
        )
    return rows


def accuracy_study(start: float = 200.0, end: float = 230.0) -> None:
    """Attitude error of the default Radau3 accuracy against a 1e-7 reference (arm moving)."""
    rows, reference = [], None
    for accuracy in (1e-7, 1e-6, 1e-5, 1e-4, 1e-3):
        simulation = MissionSimulation(MissionOptions(accuracy=accuracy))
        result = simulation.run({}, seed=1, start=start, end=end)
        phi = result.timeseries[[f"phi_{a} [rad]" for a in "xyz"]].to_numpy()
        reference = phi if reference is None else reference
        rows.append(
            {
                "accuracy": accuracy,
                "max |phi - phi_ref| [rad]": np.abs(phi - reference).max(),
                "relative to peak": np.abs(phi - reference).max() / np.abs(reference).max(),
                "cpu [s]": result.cpu_time,
                "x RT (cpu)": (end - start) / result.cpu_time,
                "steps": result.steps,
            }
        )
    print(f"Radau3 accuracy on the window {start:g}-{end:g} s (reference: 1e-7)")
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.3g}".format))


def parallel_efficiency(n_runs: int, window: float, repeats: int, isolate: bool) -> float:
    """Same cases on 1 and 2 warm pool workers; print the table; return the efficiency."""
    factory = "bench_mission_sim:isolated_simulator" if isolate else FACTORY_PATH
    recipe = SimulatorRecipe.create(factory, {"control_rate": 10.0, "log_rate": 1.0})
    cases = [
        RunCase(i, 1000 + i, {"phi0_x": 1e-3 * (i % 3)}, MissionWindow(255.0, 255.0 + window))
        for i in range(n_runs)
    ]
    pools = {"pool, 1 worker": ProcessPoolExecutor(1), "pool, 2 workers": ProcessPoolExecutor(2)}
    for pool in pools.values():
        pool.start(recipe)
    timings = {label: np.inf for label in pools}
    for _ in range(repeats):
        for label, pool in pools.items():
            start = time.perf_counter()
            results = list(pool.run(recipe, cases))
            timings[label] = min(timings[label], time.perf_counter() - start)
            assert [r.status for r in results] == ["ok"] * n_runs, [r.error for r in results]
    for pool in pools.values():
        pool.close()
    rows = [
        {
            "executor": label,
            "runs": n_runs,
            "window [s]": window,
            "best wall [s]": t,
            "runs/s": n_runs / t,
        }
        for label, t in timings.items()
    ]
    efficiency = timings["pool, 1 worker"] / (2 * timings["pool, 2 workers"])
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.3f}".format))
    print(
        f"parallel efficiency 2 workers vs 1: {100 * efficiency:.0f}% (speed-up "
        f"{timings['pool, 1 worker'] / timings['pool, 2 workers']:.2f}x, best of {repeats}; "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; workers in "
        f"{'their own sessions' if isolate else 'the driver session'})"
    )
    return efficiency


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-full", action="store_true", help="skip the whole-mission run")
    parser.add_argument("--runs", type=int, default=6, help="cases of the parallel benchmark")
    parser.add_argument("--window", type=float, default=40.0, help="window of each case [s]")
    parser.add_argument("--repeats", type=int, default=2, help="interleaved repeats")
    parser.add_argument("--accuracy-study", action="store_true", help="also the accuracy table")
    parser.add_argument(
        "--same-session",
        action="store_true",
        help="keep the pool workers in the driver's session (see isolated_simulator)",
    )
    parser.add_argument("--only-parallel", action="store_true", help="only part 3")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if not args.only_parallel:
        rows = [] if args.skip_full else [full_mission()]
        rows += integrators()
        print(pd.DataFrame(rows).to_string(index=False, float_format="{:.4g}".format))
        if args.accuracy_study:
            accuracy_study()
    parallel_efficiency(args.runs, args.window, args.repeats, isolate=not args.same_session)


if __name__ == "__main__":
    main()
