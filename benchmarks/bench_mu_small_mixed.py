"""Benchmark: mussv's lower bound on small mixed structures against brute force (issue 29 item 2).

Two real scalars and one complex scalar (``BLK = [[-1, 0], [-1, 0], [1, 0]]``) on 3 x 3
matrices, four per seed, real and complex: ``mussv`` with and without the search over the real
parameters (``mixed_search``, :func:`oos_drake.robust.worst_search.mixed_real_search`), in the
same run, against mu found by brute force (zoomed grids of the two real parameters, the complex
one in closed form: ``tests/robust/test_mu_brute_force.py``). Prints the CPU per ``mussv`` call
(four matrices) of both, the fraction of lower bounds within 1 % of the brute-force mu, the
number of zeros, the worst and largest ratios, and the cases still more than 1 % short.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_mu_small_mixed.py [--seeds 0 200]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "robust"))

from test_mu_brute_force import BLK, _brute_force_mu_zoomed  # noqa: E402

from oos_drake.robust import mussv  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs=2, default=(0, 200), metavar=("FIRST", "END"))
    args = parser.parse_args(argv)
    rows = []
    cpu = {False: 0.0, True: 0.0}
    calls = 0
    for seed in range(*args.seeds):
        for real in (True, False):
            rng = np.random.default_rng(seed)
            M = rng.standard_normal((4, 3, 3))
            if not real:
                M = M + 1j * rng.standard_normal((4, 3, 3))
            res = {}
            for search in (False, True):
                t0 = time.process_time()
                res[search] = mussv(M, BLK, mixed_search=search)
                cpu[search] += time.process_time() - t0
            calls += 1
            check = res[True].check(M)
            assert np.all(check["singularity"] <= 1e-7)
            assert np.all(np.abs(check["delta_norm_error"]) <= 1e-9)
            for k in range(len(M)):
                mu, _ = _brute_force_mu_zoomed(M[k], 1e3 / res[True].upper[k])
                rows.append((seed, real, k, mu, res[False].lower[k], res[True].lower[k]))
    a = np.array([r[3:] for r in rows])
    print(f"{len(rows)} matrices, BLK {BLK}")
    print(
        f"CPU per mussv call (4 matrices): power iteration alone {cpu[False] / calls * 1e3:.2f} ms,"
        f" with mixed_real_search {cpu[True] / calls * 1e3:.2f} ms"
        f" (ratio {cpu[True] / cpu[False]:.1f})"
    )
    for name, col in (("power iteration alone", 1), ("with mixed_real_search", 2)):
        q = a[:, col] / a[:, 0]
        print(
            f"{name}: within 1 % of brute force {np.mean(q >= 0.99):.4f}, zeros "
            f"{int(np.sum(a[:, col] == 0))}, worst ratio {q.min():.4f}, largest {q.max():.5f}"
        )
    q = a[:, 2] / a[:, 0]
    for r, x in zip(rows, q, strict=True):
        if x < 0.99:
            print(f"  short: seed {r[0]} real {r[1]} matrix {r[2]}: {r[5]:.6g} vs {r[3]:.6g}")


if __name__ == "__main__":
    main()
