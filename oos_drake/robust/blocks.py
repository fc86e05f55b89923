"""Block structures of the structured singular value, in MATLAB's BLK format.

A block structure is a list of rows ``[r, c]``:

* ``[-r, 0]``: repeated real scalar ``delta I_r`` (``delta`` real),
* ``[r, 0]``: repeated complex scalar ``delta I_r``,
* ``[r, c]`` with ``c > 0``: full complex ``r x c`` block (``[1, 1]`` is a complex scalar).

``Delta = blkdiag(Delta_1, ..., Delta_k)`` is ``sum(r) x sum(c)`` and the matrix ``M`` it closes
the loop with is ``sum(c) x sum(r)``, so that ``M Delta`` is square (MATLAB's convention).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Kinds of blocks.
REAL, COMPLEX_REPEATED, FULL = "real", "complex", "full"


@dataclass(frozen=True)
class Block:
    """One uncertainty block.

    Attributes
    ----------
    kind : str
        ``"real"`` (repeated real scalar), ``"complex"`` (repeated complex scalar) or ``"full"``.
    rows : int
        Rows of the block (size of its slice of the ``Delta`` output, i.e. of ``M``'s input).
    cols : int
        Columns of the block (size of its slice of ``M``'s output).
    row_offset : int
        First row of the block in ``Delta`` (first column of it in ``M``).
    col_offset : int
        First column of the block in ``Delta`` (first row of it in ``M``).
    """

    kind: str
    rows: int
    cols: int
    row_offset: int
    col_offset: int

    @property
    def repeated(self) -> bool:
        """True for scalar blocks ``delta I`` (real or complex)."""
        return self.kind != FULL

    @property
    def r_slice(self) -> slice:
        """Slice of the block in the ``Delta``-row (``M``-column) space."""
        return slice(self.row_offset, self.row_offset + self.rows)

    @property
    def c_slice(self) -> slice:
        """Slice of the block in the ``Delta``-column (``M``-row) space."""
        return slice(self.col_offset, self.col_offset + self.cols)


@dataclass(frozen=True)
class BlockStructure:
    """A parsed BLK description.

    Attributes
    ----------
    blocks : tuple of Block
        The blocks in order.
    n_rows : int
        ``sum(r)``: rows of ``Delta``, columns of ``M``.
    n_cols : int
        ``sum(c)``: columns of ``Delta``, rows of ``M``.
    blk : numpy.ndarray
        The BLK rows as given (integer array ``(k, 2)``).
    """

    blocks: tuple
    n_rows: int
    n_cols: int
    blk: np.ndarray

    @property
    def has_real(self) -> bool:
        """True if at least one block is real."""
        return any(b.kind == REAL for b in self.blocks)

    @property
    def m_shape(self) -> tuple[int, int]:
        """Shape ``(sum(c), sum(r))`` that ``M`` must have."""
        return (self.n_cols, self.n_rows)

    def assemble(self, values) -> np.ndarray:
        """Build ``Delta`` from per-block values (scalars for repeated blocks, matrices otherwise).

        Parameters
        ----------
        values : sequence
            One entry per block: a scalar (possibly batched, shape ``(...)``) for repeated
            blocks, an ``(..., r, c)`` array for full blocks.

        Returns
        -------
        numpy.ndarray
            ``(..., sum(r), sum(c))`` complex block-diagonal ``Delta``.
        """
        if len(values) != len(self.blocks):
            raise ValueError(
                f"assemble: expected {len(self.blocks)} block values, got {len(values)}"
            )
        batch = ()
        for block, value in zip(self.blocks, values, strict=True):
            value = np.asarray(value)
            batch = np.broadcast_shapes(batch, value.shape if block.repeated else value.shape[:-2])
        delta = np.zeros(batch + (self.n_rows, self.n_cols), dtype=complex)
        for block, value in zip(self.blocks, values, strict=True):
            value = np.asarray(value)
            if block.repeated:
                eye = np.eye(block.rows)
                delta[..., block.r_slice, block.c_slice] = value[..., None, None] * eye
            else:
                delta[..., block.r_slice, block.c_slice] = value
        return delta

    def split(self, delta: np.ndarray) -> list:
        """Per-block values of a block-diagonal ``Delta`` (inverse of :meth:`assemble`)."""
        out = []
        for block in self.blocks:
            sub = delta[..., block.r_slice, block.c_slice]
            if block.repeated:
                value = sub[..., 0, 0]
                out.append(value.real.copy() if block.kind == REAL else value.copy())
            else:
                out.append(sub.copy())
        return out

    def block_norms(self, delta: np.ndarray) -> np.ndarray:
        """Largest singular value of each block of ``Delta``: ``(..., k)``."""
        return np.stack(
            [
                np.linalg.norm(delta[..., b.r_slice, b.c_slice], ord=2, axis=(-2, -1))
                if b.kind == FULL
                else np.max(
                    np.abs(np.diagonal(delta[..., b.r_slice, b.c_slice], 0, -2, -1)), axis=-1
                )
                for b in self.blocks
            ],
            axis=-1,
        )


def parse_blk(blk) -> BlockStructure:
    """Parse and validate a MATLAB BLK description.

    Parameters
    ----------
    blk : array_like of int, shape (k, 2)
        Rows ``[-r, 0]`` (repeated real scalar), ``[r, 0]`` (repeated complex scalar) or
        ``[r, c]`` (full complex ``r x c``). A single row may be given as ``[r, c]``.

    Returns
    -------
    BlockStructure

    Raises
    ------
    ValueError
        If a row is malformed (non-integer, zero size, negative columns, real full block).
    """
    if isinstance(blk, BlockStructure):
        return blk
    arr = np.asarray(blk)
    if arr.ndim == 1 and arr.size == 2:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise ValueError(f"blk: expected rows [r, c] (shape (k, 2)), got shape {arr.shape}")
    if not np.all(np.isfinite(arr.astype(float))) or np.any(arr != np.round(arr)):
        raise ValueError(f"blk: entries must be integers, got {arr.tolist()}")
    arr = arr.astype(int)
    blocks = []
    n_rows = n_cols = 0
    for i, (r, c) in enumerate(arr):
        if r == 0:
            raise ValueError(f"blk row {i}: block size 0 in {[int(r), int(c)]}")
        if c < 0:
            raise ValueError(f"blk row {i}: negative column count in {[int(r), int(c)]}")
        if r < 0 and c != 0:
            raise ValueError(
                f"blk row {i}: real blocks must be repeated scalars [-r, 0], got {[int(r), int(c)]}"
            )
        kind = FULL if c else (REAL if r < 0 else COMPLEX_REPEATED)
        rows, cols = (int(r), int(c)) if c else (abs(int(r)), abs(int(r)))
        blocks.append(Block(kind, rows, cols, n_rows, n_cols))
        n_rows, n_cols = n_rows + rows, n_cols + cols
    return BlockStructure(tuple(blocks), n_rows, n_cols, arr)


def check_matrix(M, structure: BlockStructure) -> np.ndarray:
    """Return ``M`` as a complex array after checking its shape and finiteness.

    Raises
    ------
    ValueError
        If ``M`` is not ``(..., sum(c), sum(r))`` or holds NaN/Inf.
    """
    M = np.asarray(M)
    if M.ndim < 2:
        raise ValueError(
            f"M: expected a matrix (..., {structure.n_cols}, {structure.n_rows}), "
            f"got shape {M.shape}"
        )
    if M.shape[-2:] != structure.m_shape:
        raise ValueError(
            f"M: shape {M.shape[-2:]} does not match blk (needs sum(c) x sum(r) = "
            f"{structure.n_cols} x {structure.n_rows})"
        )
    if not np.issubdtype(M.dtype, np.number):
        raise ValueError(f"M: expected a numeric array, got dtype {M.dtype}")
    M = M.astype(complex)
    if not np.all(np.isfinite(M)):
        bad = np.argwhere(~np.isfinite(M))[0]
        raise ValueError(f"M: non-finite entry at index {tuple(int(i) for i in bad)}")
    return M
