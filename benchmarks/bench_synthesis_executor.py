"""The synthesis with its restarts on the executor vs one after the other, same run, same gains.

``oos synth`` runs the independent optimizer runs of a round (start point and random restarts
of round 0: three runs with the defaults) as tasks of ``make_executor(--workers, --scheduler)``
(:func:`oos_drake.control.synthesis.synthesize` with ``executor=``); before, they ran one after
the other in this process, each on ``--workers`` threads for its eigendecompositions. This runs
both on the same plant array, alternating (``--pairs`` pairs, the order swapped every pair, so a
load change on a shared machine hits both), and prints per run the wall time, the CPU time of
this process and of the finished worker processes, and the wall-time ratio; it checks that the
gains, gamma and every table are identical.

Run: ``PYTHONPATH=. python benchmarks/bench_synthesis_executor.py [--configurations 200]
[--workers 2] [--scheduler dask] [--pairs 1]`` (200 configurations: the controller stage of
``make run``; 40: its ``--quick`` stage).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_analysis import _cpu  # CPU of this process and its finished workers

from oos_drake.app.synth import baseline_for, make_plants
from oos_drake.control.components import DesignSpecification
from oos_drake.control.synthesis import SynthesisOptions, synthesize
from oos_drake.processes import SCHEDULER_HELP, make_executor
from oos_drake.scenario.data import load_scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--scheduler", default=None, help=SCHEDULER_HELP)
    parser.add_argument("--pairs", type=int, default=1)
    args = parser.parse_args()
    scenario = load_scenario()
    spec = DesignSpecification.from_requirements(scenario.control)
    plants = make_plants("lfr", args.configurations, scenario)
    K0 = baseline_for(plants, scenario.mission.first_docking_time)
    options = SynthesisOptions(workers=args.workers)

    def run(kind):
        wall, cpu = time.perf_counter(), _cpu()
        if kind == "serial":
            result = synthesize(plants, K0, spec=spec, options=options)
        else:
            with make_executor(args.workers, args.scheduler) as executor:
                result = synthesize(plants, K0, spec=spec, options=options, executor=executor)
        return result, time.perf_counter() - wall, _cpu() - cpu

    print(
        f"{args.configurations} configurations, {options.restarts} restarts, "
        f"--workers {args.workers}, scheduler {args.scheduler or 'processes'}"
    )
    print(f"{'pair':>4} {'run':<9} {'wall [s]':>9} {'CPU [s]':>8} {'gamma':>20}")
    results, ratios = {}, []
    for pair in range(args.pairs):
        walls = {}
        for kind in ("serial", "executor") if pair % 2 == 0 else ("executor", "serial"):
            result, wall, cpu = run(kind)
            results.setdefault(kind, result)
            walls[kind] = wall
            print(f"{pair:>4} {kind:<9} {wall:>9.1f} {cpu:>8.1f} {result.gamma!r:>20}")
        ratios.append(walls["serial"] / walls["executor"])
    a, b = results["serial"], results["executor"]
    same = (
        np.array_equal(a.K, b.K)
        and a.gamma == b.gamma
        and all(getattr(a, t).equals(getattr(b, t)) for t in ("runs", "models", "worst_cases"))
    )
    print(f"wall-time speed-up per pair: {', '.join(f'{r:.2f}x' for r in ratios)}")
    print(f"identical K, gamma and tables: {same}")


if __name__ == "__main__":
    main()
