"""Benchmark of the analysis' mu sweep against the robust package's sweep, same run, same models.

Run: ``.venv/bin/python benchmarks/bench_analysis.py [--models 6] [--ppd 8]``

Prints, for a small mission model array (baseline controller, total uncertainty set):

* wall time and per-matrix time of :func:`oos_drake.analysis.stability.mu_sweep` (batched D-G
  upper bound, power-iteration lower bound, one refinement) and of the baseline
  :func:`oos_drake.robust.robust_sweep` (mussv with its default accuracy) on the SAME grid;
* the peak upper bound each finds (lower is better: both are valid bounds);
* the certified lower bound of the direct destabilizing search vs mussv's lower bound at the peak.

Timings on the shared machine are noisy: read the ratio, measured in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=4)
    parser.add_argument("--ppd", type=int, default=8, help="grid points per decade")
    args = parser.parse_args()

    from oos_drake.analysis.cli import _controller
    from oos_drake.analysis.destabilizing import destabilizing_perturbation
    from oos_drake.analysis.models import mission_closed_loop
    from oos_drake.analysis.stability import SweepOptions, mu_sweep
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import mussv, robust_sweep
    from oos_drake.robust.lfr_analysis import block_map, delta_channel_response

    limit_blas_threads(1)
    controller = _controller(None)
    times = np.linspace(255.0, 1400.0, args.models)
    arr = mission_closed_loop(controller, times).system
    total = {"total": uncertainty_subsets(arr.uncertainty)["total"]}
    omega = 2 * np.pi * np.geomspace(0.005, 5.0, int(3 * args.ppd) + 1)

    t0 = time.perf_counter()
    ours = mu_sweep(
        arr,
        omega,
        total,
        times=times,
        options=SweepOptions(n_jobs=1, pole_points=0),
        progress=False,
    )
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    base = robust_sweep(arr, omega, subsets=total, times=times, n_jobs=1, refine_points=3)
    t_base = time.perf_counter() - t0

    k = int(ours["mu_upper"].idxmax())
    model = int(ours.at[k, "model"])
    w_peak = 2 * np.pi * float(ours.at[k, "frequency [Hz]"])
    one = arr.model(model)
    bmap = block_map(one)
    A, Bw, Cz, Dzw = (np.asarray(x) for x in (one.A, one.Bw, one.Cz, one.Dzw))
    t0 = time.perf_counter()
    direct = destabilizing_perturbation(A, Bw, Cz, Dzw, bmap.blk, [w_peak / 2, w_peak * 2])
    t_direct = time.perf_counter() - t0
    local = w_peak * np.geomspace(0.8, 1.25, 21)
    t0 = time.perf_counter()
    ref = mussv(delta_channel_response(A, Bw, Cz, Dzw, local), bmap.blk)
    t_mussv = time.perf_counter() - t0

    print(f"{'method':44s} {'wall [s]':>9s} {'matrices':>9s} {'ms/matrix':>10s} {'peak':>8s}")
    for name, table, t in (
        ("analysis.mu_sweep (batched, 30 it + refine)", ours, t_ours),
        ("robust.robust_sweep (mussv defaults)", base, t_base),
    ):
        print(
            f"{name:44s} {t:9.2f} {len(table):9d} {1e3 * t / len(table):10.2f} "
            f"{table['mu_upper'].max():8.4f}"
        )
    print(f"speed-up per matrix: {(t_base / len(base)) / (t_ours / len(ours)):.1f}x")
    print(f"{'lower bound at the peak model':44s} {'wall [s]':>9s} {'mu_lower':>10s}")
    print(f"{'direct destabilizing search':44s} {t_direct:9.2f} {direct.mu_lower:10.4f}")
    print(
        f"{'mussv power iteration (21 local points)':44s} {t_mussv:9.2f} "
        f"{float(np.max(ref.lower)):10.4f}"
    )


if __name__ == "__main__":
    main()
