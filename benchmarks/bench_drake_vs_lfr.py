"""Benchmark: linear models at the 330 mission configurations, Drake twin vs LFR substitution.

For the same ``n`` equally spaced mission configurations (paper: 330):

- **Drake, rebuild**: per configuration, build the diagram from the SDF files (parse, modal
  residuals, connection) and linearize it (``FirstOrderTaylorApproximation``);
- **Drake, cached**: one diagram per connection kind (3 builds), then per configuration set the
  context (angles, locks, target pose) and linearize;
- **LFR**: build the mission LFR once (TITOP blocks) and substitute the scheduled parameters for all
  configurations in one vectorized ``usubs`` call (the LFR approach's model array).

Every method yields the 6x6 hub acceleration model at each configuration; a few are compared at
the end (same frequency response) so the timings are for equivalent results. Run::

    .venv/bin/python benchmarks/bench_drake_vs_lfr.py            # n = 330
    .venv/bin/python benchmarks/bench_drake_vs_lfr.py --n 40     # quick
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=330, help="number of mission configurations")
    parser.add_argument(
        "--rebuild-n",
        type=int,
        default=None,
        help="configurations for the rebuild variant (default: all n)",
    )
    args = parser.parse_args(argv)

    from oos_drake.lfr import usubs
    from oos_drake.multibody.operating_point import (
        acceleration_response,
        linearize_at,
        operating_point,
    )
    from oos_drake.multibody.scenario_plant import build_scenario_diagram
    from oos_drake.scenario.data import load_scenario
    from oos_drake.scenario.model import build_mission_model, configuration_values
    from oos_drake.scenario.timeline import mission_timeline

    scenario = load_scenario()
    timeline = mission_timeline(scenario)
    batch = timeline.sample(args.n)
    points = [operating_point(batch[i]) for i in range(args.n)]
    n_rebuild = args.n if args.rebuild_n is None else min(args.rebuild_n, args.n)

    # --- Drake, rebuild per configuration --------------------------------------------------
    start = time.perf_counter()
    for point in points[:n_rebuild]:
        handles = build_scenario_diagram(point.connection)
        acceleration_response(linearize_at(point, handles))
    drake_rebuild = (time.perf_counter() - start) * args.n / n_rebuild

    # --- Drake, one diagram per connection kind ---------------------------------------------
    start = time.perf_counter()
    diagrams, contexts = {}, {}
    drake_models = []
    for point in points:
        if point.connection not in diagrams:
            diagrams[point.connection] = build_scenario_diagram(point.connection)
            contexts[point.connection] = diagrams[point.connection].diagram.CreateDefaultContext()
        handles = diagrams[point.connection]
        drake_models.append(
            acceleration_response(linearize_at(point, handles, contexts[point.connection]))
        )
    drake_cached = time.perf_counter() - start

    # --- LFR: build once, substitute all configurations -------------------------------------
    start = time.perf_counter()
    model = build_mission_model(scenario)
    lfr_build = time.perf_counter() - start
    start = time.perf_counter()
    values = configuration_values(batch.alpha, batch.theta, batch.delta_C1, batch.delta_C2)
    values = {k: v for k, v in values.items() if k in model.uncertainty}
    substituted = usubs(model, values).nominal
    lfr_substitution = time.perf_counter() - start

    # --- same results? (a few configurations) -----------------------------------------------
    omega = 2 * np.pi * np.logspace(-2, 2, 100)
    errors = []
    titop_response = substituted.freqresp(omega)  # (n, F, 6, 6)
    for i in np.linspace(0, args.n - 1, 5).astype(int):
        drake = np.moveaxis(drake_models[i](1j * omega), -1, 0)
        reference = titop_response[i]
        errors.append(
            np.linalg.norm(drake - reference, 2, axis=(1, 2)).max()
            / np.linalg.norm(reference, 2, axis=(1, 2)).max()
        )

    rows = [
        ("Drake: build + linearize per configuration", drake_rebuild),
        ("Drake: 3 cached diagrams, linearize per configuration", drake_cached),
        ("LFR: build mission model once", lfr_build),
        ("LFR: substitute all configurations (usubs)", lfr_substitution),
        ("LFR: build + substitute", lfr_build + lfr_substitution),
    ]
    print(f"{args.n} mission configurations (t = {timeline.t_start:g} .. {timeline.t_end:g} s)")
    if n_rebuild < args.n:
        print(f"(rebuild variant timed on {n_rebuild} configurations and scaled to {args.n})")
    print(f"{'method':<56} {'time [s]':>9} {'per config [ms]':>16}")
    for label, seconds in rows:
        print(f"{label:<56} {seconds:9.3f} {1e3 * seconds / args.n:16.3f}")
    lfr_total = lfr_build + lfr_substitution
    print(f"ratio Drake rebuild / LFR build+substitute: {drake_rebuild / lfr_total:8.1f}")
    print(f"ratio Drake cached  / LFR build+substitute: {drake_cached / lfr_total:8.1f}")
    print(f"ratio Drake cached  / LFR substitute only : {drake_cached / lfr_substitution:8.1f}")
    print(f"max relative response difference Drake vs LFR (5 configurations): {max(errors):.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
