r"""A cheap, valid upper bound of mixed mu for screening dense grids: ``sigma_max(D M D^-1)``.

For any ``D`` that commutes with the uncertainty structure, ``mu(M) <= sigma_max(D M D^{-1})``
(the classical complex-mu D bound; it ignores that real blocks are real, so it also bounds the
mixed mu). The admissible ``D`` used here is diagonal: one positive scale per channel of a
(repeated) scalar block, one per full block (``d I``). The scales come from Osborne balancing
of the channel-norm matrix (minimizes ``||D |M| D^{-1}||_F``); the bound is the exact largest
singular value at those scales, so it is valid whatever the balancing converges to.

It costs one batched SVD per matrix (microseconds for the 26 x 26 matrices of the analysis),
against the BFGS-optimized D-G bound of :func:`oos_drake.robust.mussv` (hundreds of
iterations): the analysis screens every model and frequency with it and refines with ``mussv``
where it matters.
"""

from __future__ import annotations

import numpy as np

from oos_drake.robust.blocks import parse_blk


def scaling_groups(blk) -> np.ndarray:
    """Group index of each channel (row of ``M``) for diagonal scalings commuting with ``blk``.

    A repeated scalar block gets one group per channel (a diagonal ``D_k`` commutes with
    ``delta I_r``); a full ``p x q`` block one group (``d I``). Requires square full blocks
    ``p == q`` (true for the analysis' blocks); raises ``ValueError`` otherwise.
    """
    structure = parse_blk(blk)
    groups = []
    g = 0
    for block in structure.blocks:
        if block.rows != block.cols:
            raise ValueError(f"screening: non-square full block {block.rows}x{block.cols} "
                             "is not supported")
        if block.kind == "full":
            groups += [g] * block.rows
            g += 1
        else:
            groups += list(range(g, g + block.rows))
            g += block.rows
    return np.asarray(groups, dtype=int)


def balanced_upper_bound(M, blk, *, sweeps: int = 12) -> np.ndarray:
    """``sigma_max(D M D^-1)`` with Osborne-balanced structured ``D`` (batched).

    Parameters
    ----------
    M : array_like
        ``(..., n, n)`` complex matrices (square structure).
    blk : array_like
        MATLAB BLK rows (square full blocks).
    sweeps : int
        Balancing sweeps (Jacobi form, all groups at once).

    Returns
    -------
    numpy.ndarray
        Upper bound of mu, shape ``M.shape[:-2]``; never above ``sigma_max(M)``.
    """
    M = np.asarray(M, dtype=complex)
    batch = M.shape[:-2]
    n = M.shape[-1]
    flat = M.reshape(-1, n, n)
    groups = scaling_groups(blk)
    if groups.size != n:
        raise ValueError(f"screening: BLK covers {groups.size} channels, M is {n}x{n}")
    ng = groups.max() + 1
    onehot = np.zeros((n, ng))
    onehot[np.arange(n), groups] = 1.0
    # squared channel-norm matrix between groups: N_ij = ||M_[gi, gj]||_F^2
    A2 = np.abs(flat) ** 2
    N = np.einsum("ig,bij,jh->bgh", onehot, A2, onehot)
    N[:, np.arange(ng), np.arange(ng)] = 0.0
    logd = np.zeros((flat.shape[0], ng))
    for _ in range(sweeps):
        d2 = np.exp(2 * logd)
        # Osborne: d_g^4 = (sum_j N_jg d_j^2) / (sum_j N_gj / d_j^2)  (column mass over row mass)
        col = np.einsum("bjg,bj->bg", N, d2)
        row = np.einsum("bgj,bj->bg", N, 1.0 / d2)
        ok = (col > 0) & (row > 0)
        step = np.where(ok, 0.25 * (np.log(np.maximum(col, 1e-300)) - np.log(np.maximum(row, 1e-300))), 0.0)
        logd = 0.5 * logd + 0.5 * (step + 0.0)  # damped Jacobi update towards the balance point
        logd -= logd.mean(axis=1, keepdims=True)
        logd = np.clip(logd, -30, 30)
    d = np.exp(logd)[:, groups]
    scaled = d[:, :, None] * flat / d[:, None, :]
    bound = np.linalg.norm(scaled, ord=2, axis=(-2, -1))
    plain = np.linalg.norm(flat, ord=2, axis=(-2, -1))
    return np.minimum(bound, plain).reshape(batch)
