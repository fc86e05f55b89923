"""Export an LFR to a MATLAB ``.mat`` file for cross-checking with the Robust Control Toolbox."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.io

from oos_drake.lfr.core import LFR


def to_mat(sys: LFR, path) -> None:
    """Write ``M = [A B; C D]``, the block table and the ``mussv`` BLK rows to ``path``.

    Variables: ``A, B, C, D`` (partitioned as ``docs/DESIGN.md``: ``B = [Bw Bu]``,
    ``C = [Cz; Cy]``), ``nstates, nz, nw, ny, nu``, ``blk`` (BLK rows), ``block_names`` (cell),
    ``block_kinds`` (cell), ``repetitions``, ``nominal``, ``lower``, ``upper`` (ureal ranges,
    NaN for
    other kinds), ``radius`` (ucomplex radius / ultidyn bound, NaN for ureal) and ``block_shape``
    (``p x q`` per block). Model arrays put the batch dimensions LAST, as MATLAB does
    (``A(:, :, k)``). In MATLAB, ``lft(blkdiag(eye(nstates)/s, Delta), ss(A, B, C, D))`` with
    ``Delta`` built from the table rebuilds the uncertain model.

    Parameters
    ----------
    sys : LFR
        Model or model array.
    path : str or pathlib.Path
        Output file (``.mat`` appended if missing).
    """
    path = Path(path)
    if path.suffix != ".mat":
        path = path.with_suffix(path.suffix + ".mat")
    n = sys.nstates

    def last(x):
        x = np.asarray(x)
        return (
            np.moveaxis(x, tuple(range(x.ndim - 2)), tuple(range(2, x.ndim))) if x.ndim > 2 else x
        )

    specs = [entry.spec for entry in sys.block_entries]
    lower = [s.range[0] if s.kind == "ureal" else np.nan for s in specs]
    upper = [s.range[1] if s.kind == "ureal" else np.nan for s in specs]
    radius = [
        getattr(s, "radius", getattr(s, "bound", np.nan)) if s.kind != "ureal" else np.nan
        for s in specs
    ]
    nominal = np.array([s.nominal for s in specs], dtype=complex) if specs else np.zeros(0)
    if np.all(nominal.imag == 0):
        nominal = nominal.real
    data = {
        "A": last(sys.M[..., :n, :n]),
        "B": last(sys.M[..., :n, n:]),
        "C": last(sys.M[..., n:, :n]),
        "D": last(sys.M[..., n:, n:]),
        "nstates": n,
        "nz": sys.nz,
        "nw": sys.nw,
        "ny": sys.noutputs,
        "nu": sys.ninputs,
        "blk": sys.blk.astype(float),
        "block_names": np.array([s.name for s in specs], dtype=object),
        "block_kinds": np.array([s.kind for s in specs], dtype=object),
        "repetitions": np.array([e.reps for e in sys.block_entries], dtype=float),
        "nominal": nominal,
        "lower": np.array(lower, dtype=float),
        "upper": np.array(upper, dtype=float),
        "radius": np.array(radius, dtype=float),
        "block_shape": np.array([s.shape for s in specs], dtype=float).reshape(-1, 2),
    }
    scipy.io.savemat(path, data, do_compression=True, oned_as="column")
