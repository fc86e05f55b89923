r"""The D-G upper bound of mixed mu solved as an LMI (cvxpy + Clarabel), for a few matrices.

.. math::

    \mu_\Delta(M) \le \beta \iff \exists D = D^* \succ 0,\ G = G^*:\quad
    M^* D M + j (G M - M^* G) - \beta^2 D \preceq 0

(Fan, Tits & Doyle 1991) with ``D`` commuting with the structure (a full Hermitian block per
repeated scalar, ``d I`` per full block) and ``G`` non-zero on the real blocks only. ``beta`` is
found by bisection on the feasibility of the LMI. The BFGS bound of :mod:`oos_drake.robust`
handles thousands of matrices at once but is not always converged; this one is exact up to the
solver's tolerance and is used on the few frequencies that decide the peak. The result is
re-checked by :func:`oos_drake.robust.mu_upper.lmi_residual` (a certificate independent of the
solver: largest eigenvalue of the LMI at the returned scalings).
"""

from __future__ import annotations

import numpy as np

from oos_drake.robust.blocks import REAL, parse_blk


def _structure_vars(structure, cp):
    """cvxpy D (Hermitian, block diagonal) and G (Hermitian on real blocks) for square blocks."""
    n = structure.n_rows
    D_blocks, G_blocks = [], []
    for block in structure.blocks:
        if block.rows != block.cols:
            raise ValueError("lmi_upper_bound: only square full blocks are supported")
        k = block.rows
        if block.kind == "full":
            d = cp.Variable(nonneg=True)
            D_blocks.append(d * np.eye(k))
            G_blocks.append(np.zeros((k, k)))
        else:
            D_blocks.append(cp.Variable((k, k), hermitian=True))
            if block.kind == REAL:
                G_blocks.append(cp.Variable((k, k), hermitian=True))
            else:
                G_blocks.append(np.zeros((k, k)))
    return cp.bmat(_blkdiag(D_blocks, cp)), cp.bmat(_blkdiag(G_blocks, cp)), n


def _blkdiag(blocks, cp):
    sizes = [b.shape[0] if hasattr(b, "shape") and b.shape else 1 for b in blocks]
    rows = []
    for i, bi in enumerate(blocks):
        row = []
        for j in range(len(blocks)):
            row.append(bi if i == j else np.zeros((sizes[i], sizes[j])))
        rows.append(row)
    return rows


def lmi_upper_bound(M, blk, *, beta_hi: float | None = None, rtol: float = 2e-3,
                    max_bisections: int = 30):
    """Certified D-G upper bound of mu for ONE matrix (bisection on the LMI).

    Parameters
    ----------
    M : array_like
        ``(n, n)`` complex matrix (square structure).
    blk : array_like
        MATLAB BLK rows.
    beta_hi : float, optional
        A known upper bound (e.g. the BFGS one); default ``sigma_max(M)``.
    rtol : float
        Relative width of the final bracket.
    max_bisections : int
        Cap on the LMI solves.

    Returns
    -------
    float
        Upper bound ``beta`` (verified by the eigenvalue check at the solver's scalings; if no
        check passes, ``beta_hi``).
    """
    import cvxpy as cp

    from oos_drake.robust.mu_upper import lmi_residual

    M = np.asarray(M, dtype=complex)
    structure = parse_blk(blk)
    n = M.shape[0]
    hi = float(beta_hi) if beta_hi is not None else float(np.linalg.norm(M, 2))
    hi = max(hi, 1e-12)
    lo = 0.0
    D, G, _ = _structure_vars(structure, cp)
    beta2 = cp.Parameter(nonneg=True)
    t = cp.Variable()
    Mh = M.conj().T
    lmi = Mh @ D @ M + 1j * (G @ M - Mh @ G) - beta2 * D
    lmi = 0.5 * (lmi + lmi.H)
    cons = [lmi << t * np.eye(n), D >> np.eye(n), D << 1e6 * np.eye(n)]
    problem = cp.Problem(cp.Minimize(t), cons)
    best = None
    for _ in range(max_bisections):
        if hi - lo <= rtol * hi:
            break
        mid = 0.5 * (lo + hi) if lo > 0 else 0.6 * hi
        beta2.value = mid**2
        try:
            problem.solve(solver=cp.CLARABEL)
        except cp.error.SolverError:
            lo = mid
            continue
        if problem.status in ("optimal", "optimal_inaccurate") and t.value is not None \
                and t.value < 0:
            Dv, Gv = np.asarray(D.value), np.asarray(G.value) if hasattr(G, "value") and \
                G.value is not None else np.zeros((n, n))
            # independent check: largest eigenvalue of the LMI at these scalings
            res = lmi_residual(M[None], np.array([mid]), Dv[None], Dv[None], Gv[None])
            if float(np.asarray(res).ravel()[0]) <= 1e-9:
                hi, best = mid, (Dv, Gv)
                continue
        lo = mid
    return hi
