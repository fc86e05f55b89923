"""Benchmark: systune vs today's static-gain synthesis on the same problem.

Run ``python benchmarks/bench_systune.py [--configurations 2] [--modes 1] [--iterations 300]``.

Both tune the static 3x6 gain ``[K_p K_d]`` of the paper's weighted interconnection
(:mod:`oos_drake.control.interconnection`) around synthetic flexible plants at nominal
parameters, from the baseline gain, one start, no worst-case search, every configuration in
the model set: :func:`oos_drake.control.synthesis.synthesize` (the modal fast path of
:mod:`~oos_drake.control.loop_response`) and :func:`oos_drake.control.systune.systune` with a
:class:`~oos_drake.control.tunable.TunableGain` and one soft
:class:`~oos_drake.control.goals.WeightedGain` from the disturbances to the errors (generic
LU solves, no modal fast path). The table gives wall and CPU time, the ratio, gamma of each
(certified norms, all models) and their relative difference.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from oos_drake.blas import single_threaded_blas
from oos_drake.control.baseline import baseline_gains, inertia_from_plant
from oos_drake.control.goals import WeightedGain
from oos_drake.control.interconnection import (
    CONTROLS,
    DISTURBANCES,
    ERRORS,
    MEASUREMENTS,
    weighted_interconnection,
)
from oos_drake.control.plants import synthetic_flexible_plants
from oos_drake.control.synthesis import SynthesisOptions, synthesize
from oos_drake.control.systune import SystuneOptions, systune
from oos_drake.control.tunable import TunableGain


def _timed(function):
    wall, cpu = time.perf_counter(), time.process_time()
    out = function()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=2)
    parser.add_argument("--modes", type=int, default=1)
    parser.add_argument("--iterations", type=int, default=300)
    args = parser.parse_args()
    plants = synthetic_flexible_plants(args.configurations, modes=args.modes, uncertain=False)
    K0 = baseline_gains(inertia_from_plant(plants.evaluate([1]))[0])
    N, P = plants.size, len(plants.parameters)
    nominal = np.broadcast_to(plants.nominal_values, (N, P))
    system = weighted_interconnection(plants.evaluate(np.arange(N), nominal)).system
    with single_threaded_blas():
        synthesis, synthesis_wall, synthesis_cpu = _timed(
            lambda: synthesize(
                plants,
                K0,
                options=SynthesisOptions(
                    restarts=0,
                    max_iterations=args.iterations,
                    worst_case_rounds=0,
                    working_set=0,
                ),
            )
        )
        tuned, tuned_wall, tuned_cpu = _timed(
            lambda: systune(
                system,
                TunableGain("K", MEASUREMENTS, CONTROLS, initial=K0),
                [WeightedGain(DISTURBANCES, ERRORS)],
                options=SystuneOptions(max_iterations=args.iterations),
            )
        )
    print(
        f"{N} configurations, {args.modes} flexible mode(s), {args.iterations} iterations, "
        f"start gamma {synthesis.gamma_start:.6g}"
    )
    print(f"{'method':12s} {'wall [s]':>9s} {'cpu [s]':>9s} {'gamma':>12s}")
    print(f"{'synthesize':12s} {synthesis_wall:9.2f} {synthesis_cpu:9.2f} {synthesis.gamma:12.8f}")
    print(f"{'systune':12s} {tuned_wall:9.2f} {tuned_cpu:9.2f} {tuned.soft:12.8f}")
    print(
        f"systune / synthesize: wall {tuned_wall / synthesis_wall:.2f}, "
        f"cpu {tuned_cpu / synthesis_cpu:.2f}; gamma relative difference "
        f"{(tuned.soft - synthesis.gamma) / synthesis.gamma:+.2e}"
    )


if __name__ == "__main__":
    main()
