"""Drake mission simulation benchmark: speed, integrator choice, parallel efficiency.

Run as a script (the machine is shared: the default is short)::

    .venv/bin/python benchmarks/bench_mission_sim.py            # all parts
    .venv/bin/python benchmarks/bench_mission_sim.py --skip-full --runs 6

1. One whole 1500 s mission with all 24 flexible modes, the arm, the captured and docked target,
   the 10 Hz flight software: wall time and processor time of this process (the one-core figure
   when other jobs share the machine), as multiples of real time.
2. Integrator choice on the same 10 s window before the capture: Radau3 (the default) against the
   explicit Runge-Kutta 3 (baseline measured in the same run); the explicit integrator is limited
   by the stiff joint PDs and bushings.
3. Parallel efficiency ``T(1 worker) / (2 T(2 workers))`` of the campaign's local process pool with
   the Drake simulator: both pools warm (simulator built in each worker before timing), the same
   cases, interleaved repeats, best of each.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pandas as pd

from oos_drake.campaign.drake_simulator import FACTORY_PATH
from oos_drake.campaign.executors import ProcessPoolExecutor
from oos_drake.campaign.simulator import MissionWindow, RunCase, SimulatorRecipe
from oos_drake.multibody.mission import MissionOptions
from oos_drake.multibody.mission_sim import MissionSimulation


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


def parallel_efficiency(n_runs: int, window: float, repeats: int) -> float:
    """Same cases on 1 and 2 warm pool workers; print the table; return the efficiency."""
    recipe = SimulatorRecipe.create(FACTORY_PATH, {"control_rate": 10.0, "log_rate": 1.0})
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
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
    )
    return efficiency


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-full", action="store_true", help="skip the whole-mission run")
    parser.add_argument("--runs", type=int, default=6, help="cases of the parallel benchmark")
    parser.add_argument("--window", type=float, default=40.0, help="window of each case [s]")
    parser.add_argument("--repeats", type=int, default=2, help="interleaved repeats")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    rows = [] if args.skip_full else [full_mission()]
    rows += integrators()
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.4g}".format))
    parallel_efficiency(args.runs, args.window, args.repeats)


if __name__ == "__main__":
    main()
