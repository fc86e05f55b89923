"""Exact structured reduction of an LFR: remove unreachable/unobservable states and Delta channels.

An LFR is the n-D system ``eta = M11 xi + M12 u``, ``y = M21 xi + M22 u`` closed by ``xi =
blkdiag(I/s, delta_1 I_r1, ..., delta_k I_rk) eta``. For a subspace ``V = V_0 (+) ... (+) V_k``
that follows the channel groups (states, then each scalar block), contains ``Im M12`` and is
invariant (``M11 V`` inside ``V`` group by group), every signal ``eta`` stays in ``V``, and because
each group is a scalar times the identity, ``xi`` stays in ``V`` too. Projecting onto orthonormal
bases ``T_i`` of the ``V_i`` therefore gives the same input-output map for EVERY value of the
parameters, with ``dim V_i`` occurrences of block ``i`` (the structured, n-D Kalman reduction; the
reachable subspace is the smallest such ``V``). The dual step removes unobservable channels. Full
``ultidyn`` blocks are kept as they are (a projection would not preserve their structure).

This is exact (up to the rank tolerance) and typically recovers the minimal occurrence counts of
LFRs built by the algebra, e.g. ``m + m`` -> one occurrence, ``m * (u v^T)`` -> one occurrence.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from oos_drake.lfr.core import LFR, BlockEntry, join_quarters, quarters


def _groups(sys: LFR):
    """Per group: (eta rows, xi cols, reducible, entry) with the states as group 0."""
    n, slices = sys.nstates, sys.channel_slices()
    groups = [(np.arange(n), np.arange(n), True, None)]
    for entry in sys.block_entries:
        z, w = slices[entry.spec.name]
        rows, cols = n + np.arange(z.start, z.stop), n + np.arange(w.start, w.stop)
        groups.append((rows, cols, entry.spec.kind != "ultidyn", entry))
    return groups


def _orth(matrix: np.ndarray, tol: float) -> np.ndarray:
    if matrix.shape[1] == 0 or matrix.shape[0] == 0:
        return np.zeros((matrix.shape[0], 0), dtype=matrix.dtype)
    U, s, _ = np.linalg.svd(matrix, full_matrices=False)
    return U[:, s > tol]


def _flat_columns(block: np.ndarray) -> np.ndarray:
    """Stack a batched ``(..., r, c)`` array side by side into ``(r, batch * c)``."""
    if block.ndim == 2:
        return block
    block = block.reshape((int(np.prod(block.shape[:-2])),) + block.shape[-2:])
    return np.concatenate(list(block), axis=1) if block.shape[0] > 1 else block[0]


def _reachable(M: np.ndarray, n_int_r: int, n_int_c: int, groups, tol: float):
    """Orthonormal bases (in eta coordinates) of the structured reachable subspace."""
    M11 = M[..., :n_int_r, :n_int_c]
    M12 = M[..., :n_int_r, n_int_c:]
    bases = []
    for rows, _cols, reducible, _ in groups:
        if reducible:
            bases.append(_orth(_flat_columns(M12[..., rows, :]), tol))
        else:
            bases.append(np.eye(rows.size, dtype=M.dtype))
    for _ in range(n_int_r + 1):
        # image of the current subspace through xi -> M11 xi
        pieces = []
        for (_, cols, reducible, _), basis in zip(groups, bases, strict=True):
            if not reducible:
                pieces.append(M11[..., :, cols])  # full block: all of its w channels
            elif basis.shape[1]:
                pieces.append(M11[..., :, cols] @ basis)
        if not pieces:
            break
        image = np.concatenate(pieces, axis=-1)
        grown = False
        for k, (rows, _cols, reducible, _) in enumerate(groups):
            if not reducible:
                continue
            candidate = np.concatenate([bases[k], _flat_columns(image[..., rows, :])], axis=1)
            new = _orth(candidate, tol)
            if new.shape[1] > bases[k].shape[1]:
                bases[k] = new
                grown = True
        if not grown:
            break
    return bases


def _project(sys: LFR, bases) -> LFR:
    """Restrict ``sys`` to the reachable bases: ``eta = T eta_r``, ``xi = T xi_r``."""
    groups = _groups(sys)
    n_int_r, n_int_c = sys.nstates + sys.nz, sys.nstates + sys.nw
    M = sys.M
    left_blocks, right_blocks = [], []
    for (rows, cols, reducible, _), basis in zip(groups, bases, strict=True):
        if reducible:
            left_blocks.append((rows, basis))
            right_blocks.append((cols, basis))
        else:
            left_blocks.append((rows, np.eye(rows.size)))
            right_blocks.append((cols, np.eye(cols.size)))
    k_r = sum(b.shape[1] for _, b in left_blocks)
    k_c = sum(b.shape[1] for _, b in right_blocks)
    dtype = np.result_type(M, *(b for _, b in left_blocks))
    T_left = np.zeros((n_int_r, k_r), dtype=dtype)  # eta = T_left eta'
    T_right = np.zeros((n_int_c, k_c), dtype=dtype)  # xi = T_right xi'
    r0 = c0 = 0
    for (rows, bl), (cols, br) in zip(left_blocks, right_blocks, strict=True):
        T_left[rows, r0 : r0 + bl.shape[1]] = bl
        T_right[cols, c0 : c0 + br.shape[1]] = br
        r0 += bl.shape[1]
        c0 += br.shape[1]
    M11, M12, M21, M22 = quarters(sys)
    TlH = T_left.conj().T
    new_M = join_quarters(TlH @ M11 @ T_right, TlH @ M12, M21 @ T_right, M22)
    n_new = bases[0].shape[1]
    entries = []
    for (_, _, reducible, entry), basis in zip(groups[1:], bases[1:], strict=True):
        reps = basis.shape[1] if reducible else entry.reps
        if reps:
            entries.append(BlockEntry(entry.spec, reps))
    if np.isrealobj(M) and np.iscomplexobj(new_M):
        new_M = new_M.real
    return LFR(new_M, n_new, entries, input_names=sys.input_names, output_names=sys.output_names)


def _transpose(sys: LFR) -> LFR:
    """Dual LFR ``M^H`` (roles of eta/xi and of u/y swapped; ultidyn shapes transposed)."""
    from oos_drake.lfr.blocks import ULTIDyn

    entries = []
    for entry in sys.block_entries:
        spec = entry.spec
        if isinstance(spec, ULTIDyn):
            spec = dataclasses.replace(spec, io_shape=spec.io_shape[::-1])
        entries.append(BlockEntry(spec, entry.reps))
    MH = np.conj(np.swapaxes(sys.M, -1, -2))
    return LFR(MH, sys.nstates, entries, input_names=sys.output_names, output_names=sys.input_names)


def _reduce_reachable(sys: LFR, tol: float) -> LFR:
    groups = _groups(sys)
    bases = _reachable(sys.M, sys.nstates + sys.nz, sys.nstates + sys.nw, groups, tol)
    return _project(sys, bases)


def reduce_lfr(sys: LFR, tol: float | None = None) -> LFR:
    """Structurally reduced LFR with the same input-output map for all parameter values.

    Parameters
    ----------
    sys : LFR
        Model or model array (the reduction is common to all models of the array).
    tol : float, optional
        Absolute singular-value threshold for the subspace ranks; default
        ``1e-10 * max(1, ||M||_F)``.

    Returns
    -------
    LFR
        Fewer (or equal) states and block occurrences; same blocks except those that no longer
        influence the input-output map.
    """
    if tol is None:
        tol = 1e-10 * max(
            1.0, float(np.linalg.norm(sys.M.reshape(-1))) / max(1, sys.nmodels) ** 0.5
        )
    current = sys
    for _ in range(4):
        size_before = (current.nstates, current.nz, current.nw)
        current = _reduce_reachable(current, tol)
        current = _transpose(_reduce_reachable(_transpose(current), tol))
        if (current.nstates, current.nz, current.nw) == size_before:
            break
    return current
