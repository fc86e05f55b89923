"""Benchmark: batched hinfnorm vs slycot's AB13DD (Fortran, one model per call), same run.

Models: lightly damped modal systems (damping 0.005-0.05) like the flexible spacecraft's, plus
a random stable feedthrough-free part; the batch shares its size.

Run: ``.venv/bin/python benchmarks/bench_hinfnorm.py [--models 50] [--states 40]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def modal_models(n_models, n_states, n_in=3, n_out=3, seed=0):
    """Batch ``(A, B, C, D)`` of stable modal models with lightly damped modes."""
    rng = np.random.default_rng(seed)
    n_modes = n_states // 2
    A = np.zeros((n_models, n_states, n_states))
    for k in range(n_models):
        wn = np.geomspace(0.5, 50.0, n_modes) * rng.uniform(0.8, 1.2, n_modes)
        zeta = rng.uniform(0.005, 0.05, n_modes)
        for i in range(n_modes):
            A[k, 2 * i, 2 * i + 1] = wn[i]
            A[k, 2 * i + 1, 2 * i] = -wn[i]
            A[k, 2 * i + 1, 2 * i + 1] = -2 * zeta[i] * wn[i]
    B = rng.standard_normal((n_models, n_states, n_in))
    C = rng.standard_normal((n_models, n_out, n_states))
    D = 0.1 * rng.standard_normal((n_models, n_out, n_in))
    return A, B, C, D


def main(argv=None):
    import slycot

    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import hinfnorm

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=50)
    parser.add_argument("--states", type=int, default=40)
    args = parser.parse_args(argv)
    limit_blas_threads(1)
    A, B, C, D = modal_models(args.models, args.states)
    hinfnorm((A[:2], B[:2], C[:2], D[:2]))  # warm-up
    t0 = time.perf_counter()
    res = hinfnorm((A, B, C, D))
    t_ours = (time.perf_counter() - t0) / args.models
    n, m, p = args.states, B.shape[-1], C.shape[-2]
    ref = np.empty(args.models)
    t0 = time.perf_counter()
    for k in range(args.models):
        ref[k] = slycot.ab13dd("C", "I", "N", "D", n, m, p, A[k], np.eye(n), B[k], C[k], D[k])[0]
    t_ref = (time.perf_counter() - t0) / args.models
    rel = np.abs(res.norm / ref - 1)
    print(f"{args.models} models, {n} states, {m} inputs, {p} outputs, 1 BLAS thread")
    print(f"{'':30}{'time/model [ms]':>16}")
    print(f"{'hinfnorm (batched)':30}{t_ours * 1e3:16.2f}")
    print(f"{'slycot ab13dd (loop)':30}{t_ref * 1e3:16.2f}")
    print(f"ratio ab13dd/ours: {t_ref / t_ours:.2f}; max relative difference {rel.max():.2e}")


if __name__ == "__main__":
    main()
