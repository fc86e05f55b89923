"""Benchmark: the package's H-infinity norm paths on the same models, against slycot's AB13DD.

Compares, on one batch of lightly damped modal models (``bench_hinfnorm.modal_models``, the
flexible spacecraft's kind of dynamics):

* ``hinfnorm``: the MATLAB-named front end (certified upper bound); since the consolidation it
  runs ``peak_gain`` and the Hamiltonian test; before it (run with ``PYTHONPATH`` of an older
  checkout) it was a separate batched Boyd-Balakrishnan / Bruinsma-Steinbuch level-set loop,
* ``peak_gain``: modal-form grid plus peak refinement (the synthesis' sampler; a lower bound,
  not certified),
* ``peak_gain(certify=True)``: the same, then the Hamiltonian test per model,

with slycot's AB13DD (Fortran, one model per call) as the independent reference and the time
baseline measured in the same run. Prints time per model, ratio to AB13DD and the largest
relative difference to AB13DD.

``--closed-loops FILE`` adds the synthesis' closed loops (``closed_loop.npz`` of ``oos synth`` /
``make run``: 204 models of 81 states for the paper) as a third model set.

Run: ``.venv/bin/python benchmarks/bench_hinf_paths.py [--models 50] [--states 40 80]
[--closed-loops out/controller/closed_loop.npz]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_hinfnorm import modal_models


def _timed(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None):
    import slycot

    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import hinfnorm

    try:
        from oos_drake.robust.peak_gain import peak_gain
    except ImportError:  # before the consolidation (PYTHONPATH of an older checkout)
        from oos_drake.control.peak_gain import peak_gain

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=50)
    parser.add_argument("--states", type=int, nargs="+", default=[40, 80])
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--closed-loops", default=None, help="closed_loop.npz of oos synth")
    args = parser.parse_args(argv)
    limit_blas_threads(1)
    print(f"{args.models} models per size, 1 BLAS thread, best of {args.repeat}")
    if args.closed_loops:
        print(f"last set: the closed loops of {args.closed_loops}")
    print(f"{'states':>6} {'path':34}{'ms/model':>10}{'vs ab13dd':>11}{'max rel diff':>14}")
    sets = [modal_models(args.models, n) for n in args.states]
    if args.closed_loops:
        with np.load(args.closed_loops) as data:
            sets.append(tuple(np.asarray(data[k], dtype=float) for k in "ABCD"))
    for A, B, C, D in sets:
        n, m, p = A.shape[-1], B.shape[-1], C.shape[-2]

        def ab13dd(A=A, B=B, C=C, D=D, n=n, m=m, p=p):
            return np.array(
                [
                    slycot.ab13dd("C", "I", "N", "D", n, m, p, A[k], np.eye(n), B[k], C[k], D[k])[0]
                    for k in range(A.shape[0])
                ]
            )

        paths = {
            "slycot ab13dd (reference, loop)": ab13dd,
            "hinfnorm": lambda A=A, B=B, C=C, D=D: hinfnorm((A, B, C, D)).norm,
            "peak_gain": lambda A=A, B=B, C=C, D=D: peak_gain(A, B, C, D).gamma,
            "peak_gain(certify=True)": lambda A=A, B=B, C=C, D=D: (
                peak_gain(A, B, C, D, certify=True).gamma
            ),
        }
        hinfnorm((A[:2], B[:2], C[:2], D[:2]))  # warm-up
        peak_gain(A[:2], B[:2], C[:2], D[:2])
        ref_time, ref = _timed(ab13dd, args.repeat)
        for name, fn in paths.items():
            t, g = (ref_time, ref) if name.startswith("slycot") else _timed(fn, args.repeat)
            rel = np.max(np.abs(np.asarray(g) / ref - 1.0))
            print(f"{n:6d} {name:34}{1e3 * t / A.shape[0]:10.2f}{t / ref_time:11.2f}{rel:14.2e}")


if __name__ == "__main__":
    main()
