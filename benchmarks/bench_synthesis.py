"""Benchmark: batched gamma evaluation vs 200 calls of slycot ab13dd, and synthesis wall time.

Run ``python benchmarks/bench_synthesis.py [--plant synthetic|lfr] [--models 200]
[--synthesis]``. The baseline (ab13dd, the routine behind MATLAB's ``norm(sys, inf)`` and
python-control's ``hinfnorm``) is measured in the same run on the same closed loops; the table
shows both times, their ratio and the largest relative difference of the norms. Both run with
one OpenBLAS thread (see :mod:`oos_drake.blas`).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from slycot import ab13dd

from oos_drake.blas import single_threaded_blas
from oos_drake.control.cli import baseline_for, make_plants
from oos_drake.control.interconnection import weighted_interconnection
from oos_drake.control.peak_gain import peak_gain
from oos_drake.control.synthesis import SynthesisOptions, synthesize


def ab13dd_all(M):
    out = np.empty(M.A.shape[0])
    for i in range(M.A.shape[0]):
        A, B, C, D = M.A[i], M.B[i], M.C[i], M.D[i]
        n, m, p = A.shape[0], B.shape[1], C.shape[0]
        out[i] = ab13dd("C", "I", "N", "D", n, m, p, A, np.eye(n), B, C, D, tol=1e-10)[0]
    return out


def best_of(fn, repeats):
    times, result = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t)
    return min(times), result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--plant", default="synthetic", choices=["synthetic", "lfr"])
    parser.add_argument("--models", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--synthesis", action="store_true", help="also time a full synthesis")
    args = parser.parse_args(argv)

    plants = make_plants(args.plant, args.models)
    K0 = baseline_for(plants)
    nominal = plants.nominal()
    W = weighted_interconnection(nominal)
    K = K0 * np.array([20, 20, 20, 4, 4, 4])  # a stabilizing, non-trivial gain
    M = W.close(K)
    t_batch, ours = best_of(lambda: peak_gain(M.A, M.B, M.C, M.D).gamma, args.repeats)
    t_focus, _ = best_of(lambda: peak_gain(M.A, M.B, M.C, M.D, focus=0.2).gamma, args.repeats)
    t_cert, certified = best_of(
        lambda: peak_gain(M.A, M.B, M.C, M.D, certify=True).gamma, args.repeats
    )
    with single_threaded_blas():  # same BLAS setting as the synthesis for the baseline
        t_ref, ref = best_of(lambda: ab13dd_all(M), args.repeats)
    finite = np.isfinite(ref) & np.isfinite(ours)
    rel = np.max(np.abs(ours[finite] - ref[finite]) / ref[finite]) if finite.any() else np.nan
    print(f"plant={args.plant} models={M.A.shape[0]} closed-loop states={M.A.shape[-1]}")
    print(f"{'method':44s} {'time [s]':>10s} {'speed-up':>9s}")
    print(f"{'ab13dd, one call per model (baseline)':44s} {t_ref:10.3f} {1.0:9.2f}")
    print(f"{'batched peak_gain, all models refined':44s} {t_batch:10.3f} {t_ref / t_batch:9.2f}")
    print(
        f"{'batched peak_gain, objective mode (focus)':44s} {t_focus:10.3f} {t_ref / t_focus:9.2f}"
    )
    print(
        f"{'batched peak_gain + Hamiltonian certificate':44s} {t_cert:10.3f} {t_ref / t_cert:9.2f}"
    )
    rel_cert = np.max(np.abs(certified[finite] - ref[finite]) / ref[finite])
    print(
        f"max relative difference of the norms vs ab13dd: grid {rel:.2e}, certified {rel_cert:.2e}"
    )
    if args.synthesis:
        options = SynthesisOptions()
        t = time.perf_counter()
        result = synthesize(plants, K0, options=options)
        wall = time.perf_counter() - t
        print(
            f"synthesis: gamma {result.gamma_start:.4g} -> {result.gamma:.4g}, "
            f"{len(result.models)} models in the final set, wall time {wall:.1f} s"
        )


if __name__ == "__main__":
    main()
