"""Partial inversion of an LFR's input/output channels (MATLAB/TITOP ``invio``).

For a square LFR with inputs ``u = [u1; u2]`` and outputs ``y = [y1; y2]`` the channels ``2``
are inverted: the new system maps ``[u1; y2]`` to ``[y1; u2]`` (channels keep their positions).
With ``y2 = C2 x + D21 u1 + D22 u2`` (``x`` = states and uncertain-block channels alike):

.. math::

    u_2 = D_{22}^{-1} (y_2 - C_2 x - D_{21} u_1)

substituted everywhere. The uncertain blocks and their occurrences are unchanged, which is how an
inverse dynamic model (acceleration out) becomes a direct model (wrench out) at one port.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from oos_drake.lfr import LFR

__all__ = ["invert_channels"]


def invert_channels(system: LFR, channels: Sequence[int]) -> LFR:
    """Swap the input and output of ``channels`` of a square LFR (partial inversion).

    Parameters
    ----------
    system : LFR
        Square system (``ninputs == noutputs``), possibly a model array.
    channels : sequence of int
        Indices of the channels to invert (same index for the input and the output).

    Returns
    -------
    LFR
        Same states and blocks; input ``k`` in ``channels`` is now the former output ``k`` and
        output ``k`` the former input ``k``.

    Raises
    ------
    ValueError
        Non-square system, bad channel indices, or a singular feedthrough ``D22``.
    """
    ny, nu = system.shape
    if ny != nu:
        raise ValueError(f"invert_channels: system must be square, got shape {system.shape}")
    channels = np.unique(np.asarray(channels, dtype=int))
    if channels.size == 0 or channels.min() < 0 or channels.max() >= nu:
        raise ValueError(f"invert_channels: channel indices {channels.tolist()} out of 0..{nu - 1}")
    n_rows = system.nstates + system.nz
    n_cols = system.nstates + system.nw
    matrix = np.array(system.M)
    rows_2 = n_rows + channels  # outputs y2
    cols_2 = n_cols + channels  # inputs u2
    other_rows = np.setdiff1d(np.arange(matrix.shape[-2]), rows_2)
    other_cols = np.setdiff1d(np.arange(matrix.shape[-1]), cols_2)
    d22 = matrix[..., rows_2[:, None], cols_2[None, :]]
    cond = np.linalg.cond(d22)
    if not np.all(np.isfinite(cond)) or np.any(cond > 1e13):
        raise ValueError(
            f"invert_channels: feedthrough of channels {channels.tolist()} is singular "
            f"(condition number {np.max(cond):.3g})"
        )
    d22_inv = np.linalg.inv(d22)
    c2 = matrix[..., rows_2[:, None], other_cols[None, :]]  # y2 <- everything else
    b2 = matrix[..., other_rows[:, None], cols_2[None, :]]  # everything else <- u2
    result = np.array(matrix)
    rest = matrix[..., other_rows[:, None], other_cols[None, :]]
    result[..., other_rows[:, None], other_cols[None, :]] = rest - b2 @ d22_inv @ c2
    result[..., other_rows[:, None], cols_2[None, :]] = b2 @ d22_inv
    result[..., rows_2[:, None], other_cols[None, :]] = -d22_inv @ c2
    result[..., rows_2[:, None], cols_2[None, :]] = d22_inv
    return LFR(result, system.nstates, system.block_entries)
