"""Benchmark: mussv on the paper-sized structure vs an LMI D-G upper bound written with cvxpy.

Structure: 2 x [-3, 0] (masses), 4 x [-2, 0] (modal frequencies), one full [3, 3] (additive LTI),
nine [1, 0] (multiplicative complex scalars): M is 26 x 26, 16 blocks. Matrices are frequency
responses of a synthetic closed loop with that structure (see ``bench_robust_sweep.py``).

Baseline (what a Python user writes today): for a trial beta, find ``D_k >= I`` and Hermitian
``G_k`` with ``M^* D_l M + j (G M - M^* G^*) - beta^2 D_r <= 0`` with cvxpy (Clarabel), bisect on
beta. Both are timed in the same run, on one BLAS thread.

Run: ``.venv/bin/python benchmarks/bench_mussv.py [--matrices 200] [--lmi 3]``
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from oos_drake.robust.blocks import REAL, parse_blk


def cvxpy_dg_upper_bound(M, blk, *, rtol: float = 1e-4, solver: str = "CLARABEL"):
    """Return ``(beta, n_solves)``: the LMI D-G upper bound of mu by bisection on beta."""
    import cvxpy as cp

    s = parse_blk(blk)
    M = np.asarray(M, dtype=complex)
    c, r = s.m_shape
    beta2 = cp.Parameter(nonneg=True)
    cons = []
    quad = 0
    right = 0
    gterm = 0
    for b in s.blocks:
        Mk = M[b.c_slice, :]  # rows of M feeding this block
        Er = np.zeros((r, b.rows))
        Er[b.r_slice, :] = np.eye(b.rows)
        if b.repeated:
            Dk = cp.Variable((b.rows, b.rows), hermitian=True)
            cons.append(Dk >> np.eye(b.rows))
            quad = quad + Mk.conj().T @ Dk @ Mk
            right = right + Er @ Dk @ Er.T
            if b.kind == REAL:
                Gk = cp.Variable((b.rows, b.rows), hermitian=True)
                GM = Er @ Gk @ Mk
                gterm = gterm + 1j * (GM - GM.H)
        else:
            dk = cp.Variable(nonneg=True)
            cons.append(dk >= 1)
            quad = quad + dk * (Mk.conj().T @ Mk)
            right = right + dk * (Er @ Er.T)
    lmi = quad + gterm - beta2 * right
    lmi = (lmi + lmi.H) / 2
    prob = cp.Problem(cp.Minimize(0), cons + [lmi << 0])
    lo, hi = 0.0, float(np.linalg.norm(M, 2)) * (1 + 1e-9)
    n_solves = 0
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        beta2.value = mid**2
        try:
            prob.solve(solver=solver)
            feasible = prob.status in ("optimal", "optimal_inaccurate")
        except cp.error.SolverError:
            feasible = False
        n_solves += 1
        if feasible:
            hi = mid
        else:
            lo = mid
    return hi, n_solves


def _clock() -> float:
    """CPU time of this process [s]: the machine is shared, wall time would measure the others."""
    return time.process_time()


def main(argv=None):
    import warnings

    from bench_robust_sweep import PAPER_BLK, paper_like_lfr

    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import mussv
    from oos_drake.robust.lfr_analysis import delta_channel_response
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--matrices", type=int, default=200)
    parser.add_argument("--lmi", type=int, default=3, help="matrices solved by the cvxpy baseline")
    args = parser.parse_args(argv)
    limit_blas_threads(1)
    warnings.filterwarnings("ignore")
    lfr = paper_like_lfr(1)
    omega = np.geomspace(0.1, 200.0, args.matrices)
    M = delta_channel_response(lfr.A[0], lfr.Bw[0], lfr.Cz[0], lfr.Dzw[0], omega)
    s = parse_blk(PAPER_BLK)

    mussv(M[:4], PAPER_BLK)  # warm-up (imports, caches)
    t0 = _clock()
    res = mussv(M, PAPER_BLK)
    t_both = (_clock() - t0) / len(M)
    t0 = _clock()
    up = mu_upper_bound(M, s, max_iter=80)
    t_up = (_clock() - t0) / len(M)
    t0 = _clock()
    mu_lower_bound(M, s, start_inputs=up.worst_input)
    t_lo = (_clock() - t0) / len(M)

    pick = np.linspace(0, len(M) - 1, args.lmi).round().astype(int)
    pick = np.unique(np.r_[pick, np.argmax(res.upper)])[: max(args.lmi, 1)]
    lmi_vals, lmi_times = [], []
    for k in pick:
        t0 = _clock()
        beta, _ = cvxpy_dg_upper_bound(M[k], PAPER_BLK)
        lmi_times.append(_clock() - t0)
        lmi_vals.append(beta)
    ours_1 = []
    for k in pick:  # single-matrix calls, no batching advantage
        t0 = _clock()
        ub = mu_upper_bound(M[k : k + 1], s, max_iter=80).upper[0]
        ours_1.append((_clock() - t0, ub))
    rel = np.array([o[1] for o in ours_1]) / np.array(lmi_vals) - 1
    gap = res.upper / np.maximum(res.lower, 1e-300)
    chk = res.check(M)
    print(
        f"structure: {len(PAPER_BLK)} blocks, M {s.n_cols} x {s.n_rows}; batch of {len(M)} "
        f"frequency-response matrices, 1 BLAS thread, load average {os.getloadavg()[0]:.1f}"
    )
    print(f"{'':36}{'CPU time/matrix [ms]':>22}")
    print(f"{'mussv, both bounds (batched)':36}{t_both * 1e3:22.2f}")
    print(f"{'  upper bound only (batched)':36}{t_up * 1e3:22.2f}")
    print(f"{'  lower bound only (batched)':36}{t_lo * 1e3:22.2f}")
    print(f"{'  upper bound, single-matrix call':36}{np.mean([o[0] for o in ours_1]) * 1e3:22.2f}")
    print(f"{'cvxpy LMI D-G bound (bisection)':36}{np.mean(lmi_times) * 1e3:22.2f}")
    print(
        f"speed-up of the upper bound vs cvxpy: batched {np.mean(lmi_times) / t_up:.0f}x, "
        f"single call {np.mean(lmi_times) / np.mean([o[0] for o in ours_1]):.0f}x"
    )
    print(
        f"upper bound vs cvxpy value: max rel. diff {np.max(np.abs(rel)):.2e} "
        f"(ours - lmi)/lmi = {np.array2string(rel, precision=4)}"
    )
    print(
        f"upper/lower gap: median {np.median(gap):.4f}, max {np.max(gap):.4f}; "
        f"lower = 0 at {(res.lower == 0).sum()} of {len(M)}"
    )
    print(
        f"certificates: max LMI eig {np.max(chk['lmi_max_eig']):.1e} (<= 0), "
        f"max sigma_min(I - M delta) {np.nanmax(chk['singularity']):.1e}"
    )


if __name__ == "__main__":
    main()
