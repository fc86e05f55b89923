"""The Drake twin's LFR extractions at mission times: one after the other vs on the executor.

``oos analyze --plant drake`` extracts one LFR per mission configuration
(:func:`oos_drake.multibody.mission_lfr.twin_mission_plants`, one ``ulinearize`` each). This
times that for ``--configurations`` equally spaced times on the executor of ``--workers`` and
``--scheduler`` (spawned worker processes: Drake) and one after the other in this process, in
the same run (both cold: the pool first, so the serial run builds its own cached diagrams),
prints the wall and CPU times and their ratio, and checks that the two model arrays are
identical (every matrix entry, blocks and names).

Run: ``PYTHONPATH=. python benchmarks/bench_extraction.py [--configurations 8] [--workers 2]
[--scheduler dask]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from oos_drake.analysis.models import mission_times
from oos_drake.multibody.mission_lfr import twin_mission_plants
from oos_drake.processes import SCHEDULER_HELP, make_executor
from oos_drake.scenario.data import load_scenario


def timed(function):
    wall, cpu = time.perf_counter(), time.process_time()
    result = function()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=8)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--scheduler", default=None, help=SCHEDULER_HELP)
    args = parser.parse_args()
    scenario = load_scenario()
    times = mission_times(args.configurations, scenario)

    def on_executor():
        with make_executor(args.workers, args.scheduler, method="spawn") as executor:
            return twin_mission_plants(times, scenario, executor=executor)

    parallel, p_wall, p_cpu = timed(on_executor)
    serial, s_wall, s_cpu = timed(lambda: twin_mission_plants(times, scenario))
    same = (
        np.array_equal(np.asarray(parallel.M), np.asarray(serial.M))
        and parallel.block_entries == serial.block_entries
        and parallel.input_names == serial.input_names
        and parallel.output_names == serial.output_names
    )
    print(f"{times.size} extractions, {args.workers} workers, scheduler {args.scheduler}")
    print(f"{'':<12} {'wall [s]':>9} {'CPU here [s]':>13}")
    print(f"{'serial':<12} {s_wall:>9.1f} {s_cpu:>13.1f}")
    print(f"{'executor':<12} {p_wall:>9.1f} {p_cpu:>13.1f}")
    print(f"wall-time speed-up: {s_wall / p_wall:.2f}x; model arrays identical: {same}")


if __name__ == "__main__":
    main()
