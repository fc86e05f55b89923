"""Baseline for the mu benchmarks: the D-G upper bound as an LMI solved with cvxpy (bisection).

This is what a Python user writes today without a dedicated tool: for a trial ``beta``, find
``D_k >= I`` (Hermitian ``r x r`` for repeated scalars, ``d_k >= 1`` for full blocks) and Hermitian
``G_k`` on the real blocks with ``M^* D_l M + j (G M - M^* G^*) - beta^2 D_r <= 0``; bisect on beta.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from oos_drake.robust.blocks import REAL, parse_blk


def cvxpy_dg_upper_bound(M, blk, *, rtol: float = 1e-4, solver: str = "CLARABEL"):
    """Return ``(beta, n_solves)``: the LMI D-G upper bound of mu by bisection.

    Parameters
    ----------
    M : array (c, r)
    blk : MATLAB BLK rows
    rtol : float
        Relative width of the final bisection interval.
    solver : str
        cvxpy solver name.
    """
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
