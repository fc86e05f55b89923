"""Benchmark: plants of the synthesis' worst-case search, Drake twin (old and new) vs TITOP LFR.

For ``--configurations`` mission configurations, each at ``--points`` random values of the real
parameters (a worst-case search round evaluates a few configurations at tens of points each),
the 3x3 plants ``T -> wdot`` from:

- **Drake, relinearized** (the ``--plant drake`` path before issue 18's synthesis half): the
  values written into the twin's Context and one linearization per point;
- **Drake, extracted LFR** (now): one ``ulinearize`` extraction per configuration (timed
  separately), then the values substituted into it, as the TITOP path does;
- **TITOP LFR**: the scheduled LFR with the values substituted (``--plant lfr``).

All three are timed in the same run; their frequency responses are compared (largest relative
error) so the timings are for equivalent models. Run::

    PYTHONPATH=. python benchmarks/bench_synthesis_plants.py [--configurations 4 --points 40]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=4, help="mission configurations")
    parser.add_argument("--points", type=int, default=40, help="parameter points per configuration")
    args = parser.parse_args(argv)

    from oos_drake.app.synth import mission_times, scenario_plants, source_plants
    from oos_drake.control.interconnection import plant_statespace
    from oos_drake.control.plants import _pad
    from oos_drake.multibody.synthesis_plants import (
        PADDING_POLE,
        DrakePlantSource,
        rotational_plant,
    )

    n = 9  # the array: free target, arm-held, docked, tilted arrays among them
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario("paper")
    source = DrakePlantSource(mission_times(n, scenario), scenario)
    drake = source_plants(source, PADDING_POLE)
    titop = scenario_plants(n, scenario)
    order = drake.nominal().A.shape[-1]
    configs = np.linspace(0, n - 1, args.configurations).round().astype(int)
    lower, upper = drake.bounds
    rng = np.random.default_rng(0)
    values = lower + (upper - lower) * rng.random((configs.size, args.points, lower.size))
    index = np.repeat(configs, args.points)
    flat = values.reshape(-1, lower.size)
    names = [p.name for p in drake.parameters]

    wall = time.perf_counter()
    relinearized = [
        _pad(
            *rotational_plant(source.configurations[i], scenario, dict(zip(names, v, strict=True))),
            order,
            PADDING_POLE,
        )
        for i, v in zip(index, flat, strict=True)
    ]
    t_relinearized = time.perf_counter() - wall

    wall = time.perf_counter()
    for i in configs:
        source.lfr(i)
    t_extract = time.perf_counter() - wall
    wall = time.perf_counter()
    extracted = drake.evaluate(index, flat)
    t_substitute = time.perf_counter() - wall

    wall = time.perf_counter()
    reference = titop.evaluate(index, flat)
    t_titop = time.perf_counter() - wall

    omega = np.logspace(-2, 2, 200)
    H_ref = reference.freqresp(omega)
    scale = np.abs(H_ref).max(axis=(1, 2, 3))
    err_extracted = (np.abs(extracted.freqresp(omega) - H_ref).max(axis=(1, 2, 3)) / scale).max()
    A, B, C, D = (np.stack([m[k] for m in relinearized]) for k in range(4))
    H_relin = plant_statespace(A, B, C, D).freqresp(omega)
    err_relinearized = (np.abs(H_relin - H_ref).max(axis=(1, 2, 3)) / scale).max()

    models = index.size
    print(
        f"{models} plants ({configs.size} configurations x {args.points} points); "
        "machine load affects all rows alike"
    )
    print(f"{'method':<34} {'time [s]':>9} {'per plant [ms]':>15} {'vs TITOP':>9} {'error':>9}")
    rows = [
        ("Drake, relinearized per point", t_relinearized, err_relinearized),
        ("Drake, extraction (per config)", t_extract, np.nan),
        ("Drake, substitution in the LFRs", t_substitute, err_extracted),
        ("Drake, extraction + substitution", t_extract + t_substitute, err_extracted),
        ("TITOP LFR substitution", t_titop, 0.0),
    ]
    for label, seconds, error in rows:
        print(
            f"{label:<34} {seconds:9.3f} {1e3 * seconds / models:15.3f} "
            f"{seconds / t_titop:9.1f} {error:9.1e}"
        )
    print(
        f"one extraction: {t_extract / configs.size:.3f} s = "
        f"{t_extract / configs.size / (t_relinearized / models):.0f} relinearizations"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
