"""Benchmark: the full on-orbit-servicing LFR along the mission.

Steps timed (one process, wall clock):

1. build the mission LFR from ``paper.toml`` (TITOP blocks + assembly);
2. substitute the 330 equally spaced mission configurations (one vectorized ``usubs``) and take the
   nominal of the remaining uncertain blocks;
3. evaluate the 6x6 frequency response of the 330 models at 500 frequencies (0.01 .. 100 Hz).

Baseline measured in the same run: python-control's ``StateSpace.frequency_response`` called
model by model (on a subset, extrapolated to 330 models).

Run: ``.venv/bin/python benchmarks/bench_full_model.py [--models 330] [--frequencies 500]``
(set ``OMP_NUM_THREADS=1`` etc. for a one-core figure).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=330)
    parser.add_argument("--frequencies", type=int, default=500)
    parser.add_argument(
        "--baseline-models",
        type=int,
        default=10,
        help="models evaluated with python-control for the baseline",
    )
    args = parser.parse_args(argv)

    start = time.perf_counter()
    import control  # noqa: F401  (imported lazily by the LFR core; timed here, not in the build)

    from oos_drake.lfr import usubs
    from oos_drake.scenario.data import load_scenario
    from oos_drake.scenario.model import build_mission_model
    from oos_drake.scenario.timeline import mission_timeline

    scenario = load_scenario()
    timeline = mission_timeline(scenario)
    t_import = time.perf_counter() - start

    start = time.perf_counter()
    model = build_mission_model(scenario)
    t_build = time.perf_counter() - start

    times = np.linspace(timeline.t_start, timeline.t_end, args.models)
    start = time.perf_counter()
    values = timeline.configuration(times).parameters()
    models = usubs(model, values).nominal
    t_subs = time.perf_counter() - start

    omega = 2 * np.pi * np.logspace(-2, 2, args.frequencies)
    start = time.perf_counter()
    response = models.freqresp(omega)
    t_freq = time.perf_counter() - start
    assert response.shape == (args.models, args.frequencies, 6, 6)

    k = min(args.baseline_models, args.models)
    start = time.perf_counter()
    baseline = []
    for i in range(k):
        ss = models.model(i).to_ss()
        baseline.append(ss.frequency_response(omega).frdata)  # (6, 6, F)
    t_base = (time.perf_counter() - start) * args.models / k
    error = np.max(np.abs(np.moveaxis(np.array(baseline), -1, 1) - response[:k]))
    scale = np.max(np.abs(response[:k]))

    total = t_build + t_subs + t_freq
    print(
        f"full mission LFR: {model.nstates} states, {model.nz} Delta channels, "
        f"{args.models} configurations x {args.frequencies} frequencies x 6x6"
    )
    print(f"{'step':44s} {'time [s]':>9s}")
    print(f"{'imports (numpy, scipy, control, data)':44s} {t_import:9.2f}")
    print(f"{'build LFR (TITOP blocks + assembly)':44s} {t_build:9.2f}")
    print(f"{'usubs 330 configurations + nominal':44s} {t_subs:9.2f}")
    print(f"{'freqresp 330 x 500 x 6x6':44s} {t_freq:9.2f}")
    print(f"{'total (build + usubs + freqresp)':44s} {total:9.2f}")
    print(f"{'baseline: python-control per model (extrap.)':44s} {t_base:9.2f}")
    print(
        f"freqresp speed-up vs baseline: {t_base / t_freq:.1f}x; "
        f"max |difference| {error:.2e} (max |response| {scale:.2e})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
