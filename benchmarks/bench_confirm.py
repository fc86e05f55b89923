"""``oos confirm`` benchmark: where the confirmation of one worst case spends its time.

Run as a script on an ``oos analyze`` folder (default: ``out/analysis`` of ``make run``)::

    .venv/bin/python benchmarks/bench_confirm.py [--analysis DIR] [--subset modal]

For one mission peak (default: the modal subset) it times, in one process with one BLAS thread,

1. the linear predictions: the continuous boundary (closed-loop LFR eigenvalues along the ray)
   and the sampled-data boundary (ZOH plant + discrete flight software);
2. one nonlinear run of the frozen twin as ``oos confirm`` does it (45 s simulated, Radau3 steps
   of 0.05 s), against the baseline measured in the same run: the same window with the mission's
   default steps of one control period (0.1 s), which damps the 0.8 Hz oscillation numerically
   by about 0.008 1/s (the reason for the shorter step). Wall and processor seconds, and the
   processor-time ratio.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace


def _timed(function):
    wall, cpu = time.perf_counter(), time.process_time()
    result = function()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--analysis", default="out/analysis", help="oos analyze folder")
    parser.add_argument("--subset", default="modal", help="mission subset of the peak")
    args = parser.parse_args()

    from oos_drake.blas import limit_blas_threads

    limit_blas_threads(1)
    from pathlib import Path

    import numpy as np

    from oos_drake.analysis.confirm import (
        GROWTH_TOLERANCE,
        ConfirmOptions,
        _continuous_abscissa,
        _peak_models,
        _Twin,
        boundary_along_ray,
        read_peaks,
        sampled_loop_poles,
    )
    from oos_drake.analysis.controller import load_controller
    from oos_drake.multibody.flight_software import FlightSoftware, FlightSoftwareDesign
    from oos_drake.scenario.data import load_scenario

    controller = load_controller(Path(args.analysis).parent / "controller" / "controller.json")
    (peak,) = [
        p for p in read_peaks(args.analysis) if p.study == "mission" and p.subset == args.subset
    ]
    scenario = load_scenario()
    (closed, plant_hat), wall, cpu = _timed(lambda: _peak_models(peak, controller, scenario))
    print(f"models (closed loop and plant LFR):   wall {wall:6.2f} s  cpu {cpu:6.2f} s")
    alpha_c, wall, cpu = _timed(
        lambda: boundary_along_ray(
            lambda a: _continuous_abscissa(closed, peak, a)[0] > GROWTH_TOLERANCE, 4.0
        )
    )
    print(f"continuous boundary {alpha_c:.4f}:          wall {wall:6.2f} s  cpu {cpu:6.2f} s")
    design = FlightSoftwareDesign.create(controller.K, 10.0)
    fsw = FlightSoftware(design, 6, 6, 0, 0)

    def sampled(alpha):
        z = sampled_loop_poles(plant_hat, peak, alpha, fsw)
        return np.log(np.abs(z).max()) / design.period > GROWTH_TOLERANCE

    alpha_s, wall, cpu = _timed(lambda: boundary_along_ray(sampled, 4.0))
    print(f"sampled-data boundary {alpha_s:.4f}:        wall {wall:6.2f} s  cpu {cpu:6.2f} s")

    specs = closed.uncertainty
    rows = []
    for label, step in (("baseline: 0.1 s steps", 0.1), ("oos confirm: 0.05 s steps", 0.05)):
        twin, build, _ = _timed(
            lambda step=step: _Twin(
                peak,
                controller.K,
                replace(ConfirmOptions(), max_step=step),
                scenario,
                math.nan,
                specs,
                design,
            )
        )
        (growing, oscillation, _), wall, cpu = _timed(lambda twin=twin: twin.run(alpha_s))
        rows.append((label, build, wall, cpu, oscillation))
    print("\none 45 s run of the frozen twin at the sampled-data boundary:")
    for label, build, wall, cpu, osc in rows:
        print(
            f"  {label:26s} build {build:5.2f} s  run wall {wall:6.2f} s  cpu {cpu:6.2f} s  "
            f"decay rate {osc.decay_rate:+.5f} 1/s at {osc.frequency:.4f} Hz"
        )
    print(f"  processor-time ratio (confirm / baseline): {rows[1][3] / rows[0][3]:.2f}")


if __name__ == "__main__":
    main()
