"""Store an LFR: MATLAB ``.mat`` (for the Robust Control Toolbox) or numpy ``.npz``, and load it.

MATLAB stores a model array as ``M(:, :, k)``: the batch dimensions come LAST; numpy puts them
first (``M[k, :, :]``). :func:`matlab_layout` and :func:`numpy_layout` convert, and every ``.mat``
file the package reads or writes goes through them, so a file from MATLAB's ``save`` reads right
and a file we write loads in MATLAB with ``M(:, :, k)`` being model ``k``. Both files hold the same
variables (see :func:`to_mat`); :func:`load_lfr` rebuilds the LFR from either. Files are written
atomically (temporary file, then rename).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.io

from oos_drake.files import atomic_write_bytes
from oos_drake.lfr.blocks import UComplex, ULTIDyn, UReal
from oos_drake.lfr.core import LFR, BlockEntry

__all__ = ["to_mat", "to_npz", "load_lfr"]


def matlab_layout(array, core_ndim: int = 2) -> np.ndarray:
    """``array`` with its leading batch dimensions moved last (numpy ``(..., r, c)`` -> MATLAB).

    Parameters
    ----------
    array : array_like
        ``(*batch, *core)`` array; the last ``core_ndim`` dimensions are the matrix.
    core_ndim : int
        Dimensions of one item (2 for a matrix).

    Examples
    --------
    >>> matlab_layout(np.zeros((5, 3, 4))).shape
    (3, 4, 5)
    """
    array = np.asarray(array)
    batch = array.ndim - core_ndim
    if batch <= 0:
        return array
    return np.moveaxis(array, tuple(range(batch)), tuple(range(core_ndim, array.ndim)))


def numpy_layout(array, core_ndim: int = 2) -> np.ndarray:
    """Inverse of :func:`matlab_layout`: MATLAB ``M(:, :, k)`` -> numpy ``M[k]``.

    Examples
    --------
    >>> numpy_layout(np.zeros((3, 4, 5))).shape
    (5, 3, 4)
    """
    array = np.asarray(array)
    batch = array.ndim - core_ndim
    if batch <= 0:
        return array
    return np.moveaxis(array, tuple(range(core_ndim, array.ndim)), tuple(range(batch)))


def read_mat(path, matrices=()) -> dict[str, np.ndarray]:
    """Variables of a ``.mat`` file; the named ``matrices`` in numpy layout (batch first).

    Parameters
    ----------
    path : str or pathlib.Path
        ``.mat`` file (MATLAB ``save``, v5 to v7.2 format, or :func:`scipy.io.savemat`).
    matrices : iterable of str
        Variables that are matrices or model arrays ``X(:, :, k, ...)``: returned as
        ``X[k, ..., :, :]``. Other variables are returned as stored.
    """
    data = scipy.io.loadmat(Path(path))
    names = set(matrices)
    return {
        k: numpy_layout(v) if k in names else np.asarray(v)
        for k, v in data.items()
        if not k.startswith("__")
    }


def write_mat(path, variables, matrices=()) -> Path:
    """Write ``variables`` to a ``.mat`` file, the named ``matrices`` in MATLAB layout.

    Parameters
    ----------
    path : str or pathlib.Path
        Output file.
    variables : dict
        Name -> array (or scalar, cell-like object array).
    matrices : iterable of str
        Variables that are matrices or numpy model arrays ``(..., r, c)``; written as
        ``(r, c, ...)`` so that MATLAB's ``X(:, :, k)`` is model ``k``.
    """
    names = set(matrices)
    data = {k: matlab_layout(v) if k in names else v for k, v in variables.items()}
    path = Path(path)
    atomic_write_bytes(
        path, lambda stream: scipy.io.savemat(stream, data, do_compression=True, oned_as="column")
    )
    return path


def to_mat(sys: LFR, path) -> None:
    """Write ``M = [A B; C D]``, the block table and the ``mussv`` BLK rows to ``path``.

    Variables: ``A, B, C, D`` (partitioned as ``docs/DESIGN.md``: ``B = [Bw Bu]``,
    ``C = [Cz; Cy]``), ``nstates, nz, nw, ny, nu``, ``blk`` (BLK rows), ``block_names`` (cell),
    ``block_kinds`` (cell: ureal/ucomplex/ultidyn), ``block_quantities`` and ``block_units``
    (cells: what each block stands for and its unit, ``''`` when not given), ``repetitions``,
    ``nominal``, ``lower``, ``upper`` (ureal ranges, NaN for other kinds), ``radius`` (ucomplex
    radius / ultidyn bound, NaN for ureal) and ``block_shape`` (``p x q`` per block). Model
    arrays put the batch dimensions LAST, as MATLAB does (``A(:, :, k)``). In MATLAB,
    ``lft(blkdiag(eye(nstates)/s, Delta), ss(A, B, C, D))`` with ``Delta`` built from the table
    rebuilds the uncertain model.

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

    write_mat(path, _variables(sys), matrices="ABCD")


def to_npz(sys: LFR, path) -> None:
    """Write the variables of :func:`to_mat` to a numpy ``.npz`` (batch dimensions first)."""
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_suffix(path.suffix + ".npz")
    data = _variables(sys)
    for key in (
        "block_names",
        "block_kinds",
        "block_quantities",
        "block_units",
        "input_names",
        "output_names",
    ):
        data[key] = np.array([str(x) for x in data[key]], dtype=str)
    atomic_write_bytes(path, lambda stream: np.savez_compressed(stream, **data))


def _variables(sys: LFR) -> dict:
    """The variables of :func:`to_mat` in numpy layout (batch dimensions first)."""
    n = sys.nstates

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
        "A": sys.M[..., :n, :n],
        "B": sys.M[..., :n, n:],
        "C": sys.M[..., n:, :n],
        "D": sys.M[..., n:, n:],
        "nstates": n,
        "nz": sys.nz,
        "nw": sys.nw,
        "ny": sys.noutputs,
        "nu": sys.ninputs,
        "blk": sys.blk.astype(float),
        "block_names": np.array([s.name for s in specs], dtype=object),
        "block_kinds": np.array([s.kind for s in specs], dtype=object),
        "block_quantities": np.array([s.quantity for s in specs], dtype=object),
        "block_units": np.array([s.unit for s in specs], dtype=object),
        "repetitions": np.array([e.reps for e in sys.block_entries], dtype=float),
        "nominal": nominal,
        "lower": np.array(lower, dtype=float),
        "upper": np.array(upper, dtype=float),
        "radius": np.array(radius, dtype=float),
        "block_shape": np.array([s.shape for s in specs], dtype=float).reshape(-1, 2),
        "input_names": np.array(list(sys.input_names or ()), dtype=object),
        "output_names": np.array(list(sys.output_names or ()), dtype=object),
    }
    return data


def load_lfr(path) -> LFR:
    """Read an LFR written by :func:`to_mat` (``.mat``) or :func:`to_npz` (``.npz``).

    Raises
    ------
    ValueError
        Unknown suffix, missing variables or an inconsistent block table (names the file).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    if path.suffix == ".mat":
        raw = read_mat(path, matrices="ABCD")

        def strings(key):
            # cells of strings; an empty string is stored as an empty array: keep its place
            cells = np.ravel(raw.get(key, np.zeros(0, dtype=object)))
            return [str(np.ravel(x)[0]) if np.size(x) else "" for x in cells]

    elif path.suffix == ".npz":
        with np.load(path) as stored:
            raw = {k: stored[k] for k in stored.files}

        def strings(key):
            return [str(x) for x in raw.get(key, [])]

    else:
        raise ValueError(
            f"{path}: expected a .mat or .npz file, got {path.suffix or 'no suffix'!r}"
        )
    names, kinds = strings("block_names"), strings("block_kinds")
    required = ("A", "B", "C", "D", "nstates", "repetitions", "nominal", "lower", "upper")
    missing = [k for k in required if k not in raw]
    if missing:
        raise ValueError(f"{path}: not an LFR file, missing variable(s) {missing}")
    A, B, C, D = (np.asarray(raw[k]) for k in "ABCD")
    n = int(np.ravel(raw["nstates"])[0])
    vector = {k: np.ravel(raw[k]) for k in ("repetitions", "nominal", "lower", "upper")}
    radius = np.ravel(raw.get("radius", np.full(len(names), np.nan)))
    shapes = np.asarray(raw.get("block_shape", np.ones((len(names), 2)))).reshape(-1, 2)
    quantities = strings("block_quantities") or [""] * len(names)
    units = strings("block_units") or [""] * len(names)
    entries = []
    for k, (name, kind) in enumerate(zip(names, kinds, strict=True)):
        facts = {"unit": units[k], "quantity": quantities[k]}
        if kind == "ureal":
            spec = UReal(
                name,
                float(np.real(vector["nominal"][k])),
                vector["lower"][k],
                vector["upper"][k],
                **facts,
            )
        elif kind == "ucomplex":
            spec = UComplex(name, complex(vector["nominal"][k]), float(radius[k]), **facts)
        elif kind == "ultidyn":
            spec = ULTIDyn(name, tuple(int(v) for v in shapes[k]), float(radius[k]), **facts)
        else:
            raise ValueError(f"{path}: block {name!r} has unknown kind {kind!r}")
        entries.append(BlockEntry(spec, int(vector["repetitions"][k])))
    M = np.concatenate([np.concatenate([A, B], axis=-1), np.concatenate([C, D], axis=-1)], axis=-2)
    inputs, outputs = strings("input_names"), strings("output_names")
    return LFR(M, n, entries, input_names=inputs or None, output_names=outputs or None)
