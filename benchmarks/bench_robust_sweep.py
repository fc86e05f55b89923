"""Benchmark: mu sweep over a paper-sized model array (models x frequencies x subsets).

The paper analyzes 330 configurations on a dense frequency grid with the structure
Delta_tot = diag(Delta_real, Delta_add, Delta_mul): repeated real scalars (masses delta_m I3,
modal frequencies delta_w I2), a full 3x3 complex LTI block and complex scalars; M11 is about
26 x 26. This script builds a synthetic closed loop of that structure (lightly damped modes whose
frequencies drift along the model array), runs :func:`oos_drake.robust.robust_sweep` on a subset
of the models and extrapolates to 330 models x 500 frequencies.

Default mode ``peak`` (cheap bounds everywhere, full bounds where a model's peak may be, see
:func:`oos_drake.robust.robust_sweep`); ``--mode full`` gives full bounds at every frequency.
Prints wall and CPU time (CPU is the robust figure on a shared machine), the share of
tightened frequencies and the upper/lower gap at each model's peak.

Run: ``.venv/bin/python benchmarks/bench_robust_sweep.py [--models 330] [--frequencies 500]
[--jobs 2] [--mode peak|full]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from oos_drake.lfr.blocks import UComplex, ULTIDyn, UReal
from oos_drake.lfr.core import LFR

#: Paper-like BLK: 2 x [-3, 0], 4 x [-2, 0], one [3, 3] and nine [1, 0]: 26 x 26, 16 blocks.
PAPER_BLK = [[-3, 0], [-3, 0]] + [[-2, 0]] * 4 + [[3, 3]] + [[1, 0]] * 9


def paper_like_lfr(n_models: int, *, n_modes: int = 24, seed: int = 0) -> LFR:
    """Synthetic uncertain closed loop with the paper's block structure, as a model array.

    ``n_models`` configurations: modal frequencies [rad/s] between 0.3 and 60 drift by up to 30 %
    along the array, damping ratios 0.01-0.05; the Delta channels are random but fixed; the
    nominal loop is stable by construction.
    """
    rng = np.random.default_rng(seed)
    specs = [UReal("a_mass1", 100.0, 90.0, 110.0), UReal("a_mass2", 50.0, 45.0, 55.0)]
    specs += [UReal(f"b_mode{i}", 1.0, 0.8, 1.2) for i in range(1, 5)]
    specs += [ULTIDyn("c_add", (3, 3), 1.0)]
    specs += [UComplex(f"d_mul{i}", 0.0, 1.0) for i in range(1, 10)]
    reps = [3, 3, 2, 2, 2, 2, 1] + [1] * 9
    n = 2 * n_modes
    nz = nw = 26
    w0 = np.geomspace(0.3, 60.0, n_modes)
    zeta = rng.uniform(0.01, 0.05, n_modes)
    drift = 1.0 + 0.3 * np.sin(np.linspace(0, np.pi, n_models))[:, None] * rng.uniform(
        -1, 1, n_modes
    )
    wn = w0[None, :] * drift
    A = np.zeros((n_models, n, n))
    for i in range(n_modes):
        A[:, 2 * i, 2 * i + 1] = wn[:, i]
        A[:, 2 * i + 1, 2 * i] = -wn[:, i]
        A[:, 2 * i + 1, 2 * i + 1] = -2 * zeta[i] * wn[:, i]
    Bw = rng.standard_normal((n, nw)) * 0.004  # mu peaks of order one
    Cz = rng.standard_normal((nz, n)) * np.repeat(np.sqrt(zeta), 2)[None, :]
    Dzw = rng.standard_normal((nz, nw)) * 0.05
    Bu = rng.standard_normal((n, 1))
    Cy = rng.standard_normal((1, n))
    return LFR.from_parts(
        A,
        np.broadcast_to(Bw, (n_models, n, nw)),
        np.broadcast_to(Bu, (n_models, n, 1)),
        np.broadcast_to(Cz, (n_models, nz, n)),
        np.broadcast_to(Cy, (n_models, 1, n)),
        np.broadcast_to(Dzw, (n_models, nz, nw)),
        np.zeros((n_models, nz, 1)),
        np.zeros((n_models, 1, nw)),
        np.zeros((n_models, 1, 1)),
        list(zip(specs, reps, strict=True)),
    )


def _cpu_seconds() -> float:
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _load() -> float:
    import os

    return os.getloadavg()[0]


def main(argv=None):
    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import robust_sweep

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=40, help="models actually run")
    parser.add_argument("--frequencies", type=int, default=500)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument(
        "--mode", choices=("peak", "full"), default="peak", help="robust_sweep mode (see its doc)"
    )
    args = parser.parse_args(argv)
    limit_blas_threads(1)
    sys = paper_like_lfr(args.models)
    print(sys)
    assert sys.blk.tolist() == PAPER_BLK, sys.blk.tolist()
    omega = np.geomspace(0.1, 200.0, args.frequencies)
    subsets = {"total": list(sys.uncertainty)}
    t0 = time.perf_counter()
    c0 = _cpu_seconds()
    table = robust_sweep(
        sys, omega, subsets=subsets, n_jobs=args.jobs, refine_points=4, mode=args.mode
    )
    elapsed = time.perf_counter() - t0
    cpu = _cpu_seconds() - c0  # this process and its (finished) workers: robust to machine load
    n_mat = len(table)
    per_matrix = cpu / n_mat
    print(
        f"{'models x frequencies':<28}{args.models} x {args.frequencies} "
        f"(+{table.refined.sum()} refined)"
    )
    print(f"{'matrices (26 x 26)':<28}{n_mat}, mode {args.mode}")
    print(
        f"{'tightened (full bounds)':<28}{int(table.tightened.sum())} "
        f"({100 * table.tightened.mean():.1f} %)"
    )
    print(f"{'wall time [s]':<28}{elapsed:.2f} on {args.jobs} process(es), load {_load():.1f}")
    print(f"{'CPU time [s]':<28}{cpu:.2f}")
    print(f"{'CPU time per matrix [ms]':<28}{per_matrix * 1e3:.2f}")
    full = 330 * args.frequencies * (n_mat / (args.models * args.frequencies))
    print(
        f"{'extrapolated 330 models [s]':<28}{full * per_matrix / args.jobs:.0f} "
        f"on {args.jobs} cores"
    )
    gap = (table["mu upper [-]"] / np.maximum(table["mu lower [-]"], 1e-300)).median()
    print(f"{'median upper/lower':<28}{gap:.3f} (all frequencies)")
    peaks = table.groupby("model").agg(up=("mu upper [-]", "max"), lo=("mu lower [-]", "max"))
    peak_gap = peaks.up / peaks.lo
    print(
        f"{'peak upper/lower per model':<28}median {peak_gap.median():.4f}, "
        f"max {peak_gap.max():.4f} (analysis needs <= 1.05)"
    )
    print(f"{'peak mu upper':<28}{table['mu upper [-]'].max():.4f}")


if __name__ == "__main__":
    main()
