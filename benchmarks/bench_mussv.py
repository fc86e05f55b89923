"""Benchmark: mussv on the paper-sized structure vs an LMI D-G upper bound written with cvxpy.

Structure: 2 x [-3, 0] (masses), 4 x [-2, 0] (modal frequencies), one full [3, 3] (additive LTI),
nine [1, 0] (multiplicative complex scalars): M is 26 x 26, 16 blocks. Matrices are frequency
responses of a synthetic closed loop with that structure (see ``bench_robust_sweep.py``).

Baseline (what a Python user writes today): for a trial beta, find ``D_k >= I`` and Hermitian
``G_k`` with ``M^* D_l M + j (G M - M^* G^*) - beta^2 D_r <= 0`` with cvxpy (Clarabel), bisect on
beta. Both are timed in the same run, on one BLAS thread.

Prints wall and CPU time per matrix for both bounds and each bound (CPU is the robust figure on
a shared machine), eigen-decompositions per matrix, the speed-up over cvxpy and the relative
difference of the values (same run), the upper/lower gap and the certificate checks;
``--frontier`` adds the time vs accuracy of the upper bound for several iteration budgets.

Run: ``.venv/bin/python benchmarks/bench_mussv.py [--matrices 200] [--lmi 3] [--frontier]``
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


def _clock() -> tuple[float, float]:
    """(wall, CPU) time of this process [s]: the machine is shared, the CPU time is the robust
    figure; the wall time is what a user sees on an idle machine."""
    return time.perf_counter(), time.process_time()


def _since(t0, n=1) -> tuple[float, float]:
    """(wall, CPU) seconds per item since ``t0 = _clock()``."""
    w, c = _clock()
    return (w - t0[0]) / n, (c - t0[1]) / n


def _count_evaluations(run) -> int:
    """Matrix evaluations (one Hermitian eigen-decomposition each) of the upper bound in ``run``."""
    from oos_drake.robust import mu_upper

    count = [0]
    original = mu_upper._Objective.__call__

    def counting(self, x, idx, t, need_grad=True):
        count[0] += len(idx)
        return original(self, x, idx, t, need_grad)

    mu_upper._Objective.__call__ = counting
    try:
        run()
    finally:
        mu_upper._Objective.__call__ = original
    return count[0]


def main(argv=None):
    import warnings

    from bench_robust_sweep import PAPER_BLK, paper_like_lfr

    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import mussv
    from oos_drake.robust.lfr_analysis import delta_channel_response
    from oos_drake.robust.mu import (
        UPPER_ITERATIONS,
        UPPER_PATIENCE,
        UPPER_TEMPERATURES,
        UPPER_TOL,
        _lower_bound,
    )
    from oos_drake.robust.mu_upper import mu_upper_bound

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--matrices", type=int, default=200)
    parser.add_argument("--lmi", type=int, default=3, help="matrices solved by the cvxpy baseline")
    parser.add_argument(
        "--frontier",
        action="store_true",
        help="also print time vs accuracy of the upper bound for several iteration budgets",
    )
    args = parser.parse_args(argv)
    limit_blas_threads(1)
    warnings.filterwarnings("ignore")
    lfr = paper_like_lfr(1)
    omega = np.geomspace(0.1, 200.0, args.matrices)
    M = delta_channel_response(lfr.A[0], lfr.Bw[0], lfr.Cz[0], lfr.Dzw[0], omega)
    s = parse_blk(PAPER_BLK)
    n = len(M)

    def upper(Ms):  # the upper bound exactly as mussv runs it (defaults)
        return mu_upper_bound(
            Ms,
            s,
            max_iter=UPPER_ITERATIONS,
            tol=UPPER_TOL,
            temperatures=UPPER_TEMPERATURES,
            patience=UPPER_PATIENCE,
        )

    mussv(M[:4], PAPER_BLK)  # warm-up (imports, caches)
    t0 = _clock()
    res = mussv(M, PAPER_BLK)
    t_both = _since(t0, n)
    t0 = _clock()
    up = upper(M)
    t_up = _since(t0, n)
    evals = _count_evaluations(lambda: upper(M)) / n
    t0 = _clock()
    _lower_bound(M, s, up, restarts=4, iters=60, rng=np.random.default_rng(0), restart_gap=1.02)
    t_lo = _since(t0, n)

    pick = np.linspace(0, n - 1, args.lmi).round().astype(int)
    pick = np.unique(np.r_[pick, np.argmax(res.upper)])[: max(args.lmi, 1)]
    lmi_vals, lmi_times = [], []
    for k in pick:
        t0 = _clock()
        beta, _ = cvxpy_dg_upper_bound(M[k], PAPER_BLK)
        lmi_times.append(_since(t0))
        lmi_vals.append(beta)
    ours_1 = []
    for k in pick:  # single-matrix calls, no batching advantage
        t0 = _clock()
        ub = upper(M[k : k + 1]).upper[0]
        ours_1.append((_since(t0), ub))
    lmi_t = np.mean(lmi_times, axis=0)
    one_t = np.mean([o[0] for o in ours_1], axis=0)
    rel = np.array([o[1] for o in ours_1]) / np.array(lmi_vals) - 1
    rel_batch = res.upper[pick] / np.array(lmi_vals) - 1
    gap = res.upper / np.maximum(res.lower, 1e-300)
    chk = res.check(M)
    print(
        f"structure: {len(PAPER_BLK)} blocks, M {s.n_cols} x {s.n_rows}; batch of {n} "
        f"frequency-response matrices, 1 BLAS thread, load average {os.getloadavg()[0]:.1f}"
    )
    print(f"{'time per matrix [ms]':36}{'wall':>10}{'CPU':>10}")
    for name, t in (
        ("mussv, both bounds (batched)", t_both),
        ("  upper bound only (batched)", t_up),
        ("  lower bound only (batched)", t_lo),
        ("  upper bound, single-matrix call", one_t),
        ("cvxpy LMI D-G bound (bisection)", lmi_t),
    ):
        print(f"{name:36}{t[0] * 1e3:10.2f}{t[1] * 1e3:10.2f}")
    print(f"eigen-decompositions per matrix (upper bound): {evals:.1f}")
    print(
        f"speed-up of the upper bound vs cvxpy (CPU, same run): batched {lmi_t[1] / t_up[1]:.0f}x, "
        f"single call {lmi_t[1] / one_t[1]:.0f}x (target >= 50x)"
    )
    print(
        f"upper bound vs cvxpy value: max rel. diff {np.max(np.abs(rel)):.2e} single, "
        f"{np.max(np.abs(rel_batch)):.2e} batched (target <= 1e-2); "
        f"(ours - lmi)/lmi = {np.array2string(rel_batch, precision=4)}"
    )
    print(
        f"upper/lower gap: median {np.median(gap):.4f}, max {np.max(gap):.4f}; "
        f"at the peak {gap[np.argmax(res.upper)]:.4f}; lower = 0 at {(res.lower == 0).sum()} of {n}"
    )
    print(
        f"certificates: max LMI eig {np.max(chk['lmi_max_eig']):.1e} (<= 0), "
        f"max sigma_min(I - M delta) {np.nanmax(chk['singularity']):.1e}"
    )
    if args.frontier:
        ref = mu_upper_bound(
            M, s, max_iter=600, tol=1e-12, temperatures=(30.0, 300.0, 3000.0, 30000.0)
        ).upper
        print("upper bound: iterations -> CPU ms/matrix, eigen-decompositions, excess over a")
        print("fully converged D-G bound (600 iterations, 4 stages): median / max")
        for iters in (0, 10, 20, 30, 40, 60, 80, UPPER_ITERATIONS):

            def run(iters=iters):
                return mu_upper_bound(
                    M,
                    s,
                    max_iter=iters,
                    tol=UPPER_TOL,
                    temperatures=UPPER_TEMPERATURES,
                    patience=UPPER_PATIENCE,
                ).upper

            t0 = _clock()
            u = run()
            t = _since(t0, n)
            ev = _count_evaluations(run) / n
            ex = u / ref - 1
            print(
                f"  {iters:3d} it: {t[1] * 1e3:6.2f} ms, {ev:5.1f} eig, "
                f"{np.median(ex):.2e} / {np.max(ex):.2e}"
            )


if __name__ == "__main__":
    main()
