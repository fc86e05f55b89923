"""The immutable LFR object: an upper LFT of a state-space model and named uncertain blocks.

Storage is one constant matrix ``M`` (possibly with leading batch dimensions) partitioned as::

    [ xdot ]   [ A   Bw  Bu  ] [ x ]
    [  z   ] = [ Cz  Dzw Dzu ] [ w ]        w = Delta z,  Delta = blkdiag(Delta_1, ..., Delta_k)
    [  y   ]   [ Cy  Dyw Dyu ] [ u ]

so that the whole system is ``Fu(M, blkdiag(I/s, Delta))``. The internal channels (states, then the
occurrences of each block in name order) all behave alike for the algebra: every interconnection
is an ``append`` of the operands followed by closing a static interconnection matrix on the external
channels (:func:`close_static`). Block occurrences of the same name are merged and kept contiguous.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from oos_drake.lfr.blocks import Block, merge_facts, same_block


@dataclass(frozen=True)
class BlockEntry:
    """One block of an LFR: its spec and its occurrences (``Delta_i = I_reps (x) delta``)."""

    spec: Block
    reps: int

    @property
    def nz(self) -> int:
        """Rows of ``z`` feeding this block (``reps * q``)."""
        return self.reps * self.spec.shape[1]

    @property
    def nw(self) -> int:
        """Rows of ``w`` produced by this block (``reps * p``)."""
        return self.reps * self.spec.shape[0]


def _freeze(array: np.ndarray) -> np.ndarray:
    array = np.array(array, copy=True)
    array.flags.writeable = False
    return array


def _names(names, count: int, label: str):
    if names is None:
        return None
    if isinstance(names, str):
        names = [names] if count == 1 else [f"{names}[{k}]" for k in range(count)]
    names = tuple(None if n is None else str(n) for n in names)
    if len(names) != count:
        raise ValueError(f"{label}: {len(names)} names given for {count} channels")
    if all(n is None for n in names):
        return None
    return names


class LFR:
    """Uncertain continuous-time linear system ``Fu(M, blkdiag(I/s, Delta))``.

    Build one with :func:`~oos_drake.lfr.ureal` (and friends), :meth:`from_ss`,
    :meth:`from_matrix` or :func:`~oos_drake.lfr.as_lfr`, and combine them with ``*`` (series,
    ``sys * other`` is ``sys`` after ``other``), ``+``, ``-``, gains,
    :func:`~oos_drake.lfr.feedback`, :func:`~oos_drake.lfr.lft`, ...
    The object is immutable; every operation returns a new LFR.

    Matrices may carry leading batch dimensions (a *model array*: all models share the block
    structure); ``sys.batch_shape`` gives them and ``sys.model(k)`` picks one model.

    Examples
    --------
    >>> import control
    >>> from oos_drake.lfr import ureal, usubs
    >>> m = ureal("m", 2.0, percent=10)          # mass [kg]
    >>> plant = (1 / m) * control.tf(1, [1, 0, 0])
    >>> plant.occurrences
    {'m': 1}
    >>> usubs(plant, {"m": 2.1}).nstates
    2
    """

    __slots__ = ("_M", "_n", "_blocks", "_input_names", "_output_names", "_cache")
    __array_ufunc__ = None  # numpy_array * lfr defers to LFR.__rmul__

    def __init__(
        self,
        M,
        nstates: int,
        blocks: Sequence[BlockEntry] = (),
        *,
        input_names=None,
        output_names=None,
    ):
        M = np.asarray(M)
        if M.ndim < 2:
            raise ValueError(f"LFR matrix M must be at least 2-D, got shape {M.shape}")
        if not (np.issubdtype(M.dtype, np.floating) or np.issubdtype(M.dtype, np.complexfloating)):
            M = M.astype(float)
        blocks = tuple(blocks)
        names = [entry.spec.name for entry in blocks]
        if names != sorted(names) or len(set(names)) != len(names):
            raise ValueError(f"LFR blocks must be unique and sorted by name, got {names}")
        if any(entry.reps < 1 for entry in blocks):
            raise ValueError("LFR block repetitions must be >= 1")
        nz = sum(entry.nz for entry in blocks)
        nw = sum(entry.nw for entry in blocks)
        nstates = int(nstates)
        rows, cols = M.shape[-2:]
        if nstates < 0 or rows < nstates + nz or cols < nstates + nw:
            raise ValueError(
                f"LFR matrix M of shape {M.shape} is too small for {nstates} states, "
                f"{nz} z and {nw} w channels"
            )
        object.__setattr__(self, "_M", _freeze(M))
        object.__setattr__(self, "_n", nstates)
        object.__setattr__(self, "_blocks", blocks)
        object.__setattr__(self, "_input_names", _names(input_names, cols - nstates - nw, "inputs"))
        object.__setattr__(
            self, "_output_names", _names(output_names, rows - nstates - nz, "outputs")
        )
        object.__setattr__(self, "_cache", {})

    def __setattr__(self, name, value):
        raise AttributeError("LFR objects are immutable")

    def __reduce__(self):
        return (
            _rebuild,
            (np.array(self._M), self._n, self._blocks, self._input_names, self._output_names),
        )

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_ss(cls, A, B, C, D, *, input_names=None, output_names=None) -> LFR:
        """Certain state-space model ``xdot = A x + B u, y = C x + D u`` (arrays may be batched).

        Parameters
        ----------
        A, B, C, D : array_like
            State-space matrices, shapes ``(..., n, n)``, ``(..., n, nu)``, ``(..., ny, n)``,
            ``(..., ny, nu)``.
        """
        A, B, C, D = (np.asarray(x) for x in (A, B, C, D))
        D = np.atleast_2d(D)
        n = A.shape[-1] if A.size else 0
        if A.size == 0:
            ny, nu = D.shape[-2:]
            A = np.zeros(D.shape[:-2] + (0, 0))
            B = np.zeros(D.shape[:-2] + (0, nu))
            C = np.zeros(D.shape[:-2] + (ny, 0))
        if A.shape[-2:] != (n, n):
            raise ValueError(f"from_ss: A must be square, got shape {A.shape}")
        ny, nu = D.shape[-2:]
        B = B.reshape(B.shape[:-2] + (n, nu)) if B.size == n * nu and B.ndim < 2 else B
        if B.shape[-2:] != (n, nu):
            raise ValueError(f"from_ss: B has shape {B.shape}, expected (..., {n}, {nu})")
        if C.shape[-2:] != (ny, n):
            raise ValueError(f"from_ss: C has shape {C.shape}, expected (..., {ny}, {n})")
        batch = np.broadcast_shapes(A.shape[:-2], B.shape[:-2], C.shape[:-2], D.shape[:-2])
        dtype = np.result_type(A, B, C, D, float)
        M = np.zeros(batch + (n + ny, n + nu), dtype=dtype)
        M[..., :n, :n] = A
        M[..., :n, n:] = B
        M[..., n:, :n] = C
        M[..., n:, n:] = D
        return cls(M, n, (), input_names=input_names, output_names=output_names)

    @classmethod
    def from_matrix(cls, D, *, input_names=None, output_names=None) -> LFR:
        """Static gain ``y = D u`` (scalars become 1x1; leading batch dimensions allowed)."""
        D = np.asarray(D)
        if D.ndim == 0:
            D = D.reshape(1, 1)
        elif D.ndim == 1:
            D = D.reshape(1, -1)
        return cls(D, 0, (), input_names=input_names, output_names=output_names)

    @classmethod
    def from_parts(cls, A, Bw, Bu, Cz, Cy, Dzw, Dzu, Dyw, Dyu, blocks, **names) -> LFR:
        """Assemble an LFR from the nine partitions and a block list ``[(spec, reps), ...]``."""
        top = np.concatenate([np.asarray(A), np.asarray(Bw), np.asarray(Bu)], axis=-1)
        mid = np.concatenate([np.asarray(Cz), np.asarray(Dzw), np.asarray(Dzu)], axis=-1)
        bot = np.concatenate([np.asarray(Cy), np.asarray(Dyw), np.asarray(Dyu)], axis=-1)
        entries = sorted(
            (BlockEntry(spec, int(reps)) for spec, reps in blocks),
            key=lambda entry: entry.spec.name,
        )
        return cls(
            np.concatenate([top, mid, bot], axis=-2), np.asarray(A).shape[-1], entries, **names
        )

    # ------------------------------------------------------------------ sizes and partitions
    @property
    def M(self) -> np.ndarray:
        """The full constant matrix (read-only), shape ``(..., n+nz+ny, n+nw+nu)``."""
        return self._M

    @property
    def nstates(self) -> int:
        return self._n

    @property
    def nz(self) -> int:
        """Number of ``z`` channels (inputs of Delta)."""
        return sum(entry.nz for entry in self._blocks)

    @property
    def nw(self) -> int:
        """Number of ``w`` channels (outputs of Delta)."""
        return sum(entry.nw for entry in self._blocks)

    @property
    def noutputs(self) -> int:
        return self._M.shape[-2] - self._n - self.nz

    @property
    def ninputs(self) -> int:
        return self._M.shape[-1] - self._n - self.nw

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nu)``."""
        return (self.noutputs, self.ninputs)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading batch dimensions (``()`` for a single model)."""
        return self._M.shape[:-2]

    @property
    def nmodels(self) -> int:
        return int(np.prod(self.batch_shape, dtype=int))

    @property
    def input_names(self):
        return self._input_names

    @property
    def output_names(self):
        return self._output_names

    @property
    def block_entries(self) -> tuple[BlockEntry, ...]:
        """Blocks in channel order (sorted by name) with their repetitions."""
        return self._blocks

    def _row_slices(self):
        n, nz = self._n, self.nz
        return slice(0, n), slice(n, n + nz), slice(n + nz, None)

    def _col_slices(self):
        n, nw = self._n, self.nw
        return slice(0, n), slice(n, n + nw), slice(n + nw, None)

    def _part(self, row: int, col: int) -> np.ndarray:
        return self._M[..., self._row_slices()[row], self._col_slices()[col]]

    A = property(lambda self: self._part(0, 0), doc="State matrix ``A``.")
    Bw = property(lambda self: self._part(0, 1), doc="``Bw`` (states from Delta outputs).")
    Bu = property(lambda self: self._part(0, 2), doc="``Bu`` (states from inputs).")
    Cz = property(lambda self: self._part(1, 0), doc="``Cz``.")
    Dzw = property(lambda self: self._part(1, 1), doc="``Dzw`` (= M11 of mussv for static LFRs).")
    Dzu = property(lambda self: self._part(1, 2), doc="``Dzu``.")
    Cy = property(lambda self: self._part(2, 0), doc="``Cy``.")
    Dyw = property(lambda self: self._part(2, 1), doc="``Dyw``.")
    Dyu = property(lambda self: self._part(2, 2), doc="``Dyu`` (nominal feedthrough).")

    @property
    def B(self) -> np.ndarray:
        """``[Bw, Bu]``."""
        return self._M[..., : self._n, self._n :]

    @property
    def C(self) -> np.ndarray:
        """``[Cz; Cy]``."""
        return self._M[..., self._n :, : self._n]

    @property
    def D(self) -> np.ndarray:
        """``[[Dzw, Dzu], [Dyw, Dyu]]``."""
        return self._M[..., self._n :, self._n :]

    # ------------------------------------------------------------------ block information
    @property
    def uncertainty(self) -> dict:
        """Block name -> block spec (:class:`~oos_drake.lfr.blocks.UReal`, ...), in name order."""
        return {entry.spec.name: entry.spec for entry in self._blocks}

    @property
    def occurrences(self) -> dict:
        """Block name -> number of occurrences."""
        return {entry.spec.name: entry.reps for entry in self._blocks}

    @property
    def blocks(self):
        """``pandas.DataFrame``, one row per block: name, kind, repetitions, nominal, range, ...

        Columns ``name, kind, repetitions, nominal, range, radius, shape, quantity, unit``
        (``kind``: ureal/ucomplex/ultidyn; ``radius``: ucomplex radius or ultidyn bound;
        ``shape``: ``(p, q)`` of one occurrence; ``quantity``/``unit``: what the block stands
        for).
        """
        import pandas as pd

        rows = []
        for entry in self._blocks:
            spec = entry.spec
            rows.append(
                {
                    "name": spec.name,
                    "kind": spec.kind,
                    "repetitions": entry.reps,
                    "nominal": spec.nominal,
                    "range": spec.range,
                    "radius": getattr(spec, "radius", getattr(spec, "bound", None)),
                    "shape": spec.shape,
                    "quantity": spec.quantity,
                    "unit": spec.unit,
                }
            )
        columns = [
            "name",
            "kind",
            "repetitions",
            "nominal",
            "range",
            "radius",
            "shape",
            "quantity",
            "unit",
        ]
        return pd.DataFrame(rows, columns=columns)

    @property
    def blk(self) -> np.ndarray:
        """MATLAB ``mussv`` BLK rows, one row per block (ureal ``[-r, 0]``, ucomplex ``[r, 0]``,
        ultidyn ``[p, q]`` repeated ``r`` times since repeated full blocks have no BLK row)."""
        rows = []
        for entry in self._blocks:
            if entry.spec.kind == "ureal":
                rows.append([-entry.reps, 0])
            elif entry.spec.kind == "ucomplex":
                rows.append([entry.reps, 0])
            else:
                rows.extend([list(entry.spec.shape)] * entry.reps)
        return np.array(rows, dtype=int).reshape(-1, 2)

    def channel_slices(self) -> dict:
        """Block name -> ``(z_slice, w_slice)``: rows of ``z`` and columns of ``w`` (0-based within
        the Delta channels) that belong to the block."""
        out, z0, w0 = {}, 0, 0
        for entry in self._blocks:
            out[entry.spec.name] = (slice(z0, z0 + entry.nz), slice(w0, w0 + entry.nw))
            z0 += entry.nz
            w0 += entry.nw
        return out

    # ------------------------------------------------------------------ misc
    def __repr__(self) -> str:
        batch = f", batch {self.batch_shape}" if self.batch_shape else ""
        blocks = ", ".join(f"{e.spec.name}:{e.spec.kind}x{e.reps}" for e in self._blocks) or "none"
        return (
            f"LFR({self.noutputs} outputs, {self.ninputs} inputs, {self._n} states{batch}; "
            f"blocks: {blocks})"
        )

    def model(self, index) -> LFR:
        """Model ``index`` of a model array (``sys.model(k)``; tuples for several batch dims)."""
        if not self.batch_shape:
            raise ValueError("model(): this LFR is not a model array (batch_shape is ())")
        index = index if isinstance(index, tuple) else (index,)
        if len(index) > len(self.batch_shape):
            raise ValueError(
                f"model(): index {index} has more entries than batch_shape {self.batch_shape}"
            )
        return self._replace(self._M[index])

    def _replace(self, M, nstates=None, blocks=None, **names) -> LFR:
        return LFR(
            M,
            self._n if nstates is None else nstates,
            self._blocks if blocks is None else blocks,
            input_names=names.get("input_names", self._input_names),
            output_names=names.get("output_names", self._output_names),
        )

    def with_names(self, *, inputs=None, outputs=None) -> LFR:
        """Copy with input and/or output signal names.

        A single string ``"u"`` for a ``k``-channel port expands to ``u[0], ..., u[k-1]``.
        """
        return LFR(
            self._M,
            self._n,
            self._blocks,
            input_names=self._input_names if inputs is None else inputs,
            output_names=self._output_names if outputs is None else outputs,
        )

    @property
    def is_certain(self) -> bool:
        """True when no uncertain block remains."""
        return not self._blocks

    # ------------------------------------------------------------------ operators
    def __neg__(self) -> LFR:
        M = np.array(self._M)
        M[..., self._n + self.nz :, :] *= -1
        return self._replace(M)

    def __pos__(self) -> LFR:
        return self

    def __mul__(self, other) -> LFR:
        if _is_scalar(other):
            M = np.array(self._M, dtype=np.result_type(self._M, other))
            M[..., self._n + self.nz :, :] *= other
            return self._replace(M)
        other = _operand(other)
        return NotImplemented if other is None else series(other, self)

    def __rmul__(self, other) -> LFR:
        if _is_scalar(other):
            return self.__mul__(other)
        other = _operand(other)
        return NotImplemented if other is None else series(self, other)

    __matmul__ = __mul__
    __rmatmul__ = __rmul__

    def __add__(self, other) -> LFR:
        other = _operand(other)
        return NotImplemented if other is None else parallel(self, other, 1.0)

    def __radd__(self, other) -> LFR:
        other = _operand(other)
        return NotImplemented if other is None else parallel(other, self, 1.0)

    def __sub__(self, other) -> LFR:
        other = _operand(other)
        return NotImplemented if other is None else parallel(self, other, -1.0)

    def __rsub__(self, other) -> LFR:
        other = _operand(other)
        return NotImplemented if other is None else parallel(other, self, -1.0)

    def __truediv__(self, other) -> LFR:
        if _is_scalar(other):
            return self.__mul__(1.0 / other)
        other = _operand(other)
        return NotImplemented if other is None else self * inverse(other)

    def __rtruediv__(self, other) -> LFR:
        other = _operand(other)
        return NotImplemented if other is None else other * inverse(self)

    def __pow__(self, power) -> LFR:
        if not isinstance(power, numbers.Integral):
            raise ValueError(f"LFR power must be an integer, got {power!r}")
        if self.noutputs != self.ninputs:
            raise ValueError(f"LFR power needs a square system, got shape {self.shape}")
        if power < 0:
            return inverse(self) ** (-power)
        result = LFR.from_matrix(np.eye(self.noutputs))
        for _ in range(int(power)):
            result = result * self
        return result

    def __getitem__(self, key) -> LFR:
        if not isinstance(key, tuple) or len(key) != 2:
            raise ValueError("LFR indexing needs sys[outputs, inputs]")
        rows = _index_list(key[0], self.noutputs, "output")
        cols = _index_list(key[1], self.ninputs, "input")
        n, nz, nw = self._n, self.nz, self.nw
        row_idx = np.concatenate([np.arange(n + nz), n + nz + rows])
        col_idx = np.concatenate([np.arange(n + nw), n + nw + cols])
        M = self._M[..., row_idx[:, None], col_idx[None, :]]
        return LFR(
            M,
            n,
            self._blocks,
            input_names=None if self._input_names is None else [self._input_names[c] for c in cols],
            output_names=None
            if self._output_names is None
            else [self._output_names[r] for r in rows],
        )

    # ------------------------------------------------------------------ analysis entry points
    @property
    def nominal(self) -> LFR:
        """The nominal model (every block at ``delta = 0``), an LFR without blocks."""
        from oos_drake.lfr.substitution import nominal

        return nominal(self)

    def usubs(self, values, **kwargs):
        """See :func:`oos_drake.lfr.usubs`."""
        from oos_drake.lfr.substitution import usubs

        return usubs(self, values, **kwargs)

    def freqresp(self, omega) -> np.ndarray:
        """See :func:`oos_drake.lfr.freqresp`."""
        from oos_drake.lfr.frequency import freqresp

        return freqresp(self, omega)

    def to_ss(self):
        """``control.StateSpace`` of a certain, single (non-batched) LFR."""
        import control

        if self._blocks:
            names = ", ".join(self.occurrences)
            raise ValueError(
                f"to_ss: LFR still has uncertain blocks ({names}); use usubs() or .nominal first"
            )
        if self.batch_shape:
            raise ValueError(
                f"to_ss: LFR is a model array of shape {self.batch_shape}; pick one with .model(k)"
            )
        n = self._n
        M = self._M
        kwargs = {}
        if self._input_names is not None and None not in self._input_names:
            kwargs["inputs"] = list(self._input_names)
        if self._output_names is not None and None not in self._output_names:
            kwargs["outputs"] = list(self._output_names)
        return control.ss(M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:], **kwargs)

    def reduce(self, tol: float | None = None) -> LFR:
        """See :func:`oos_drake.lfr.reduction.reduce_lfr`."""
        from oos_drake.lfr.reduction import reduce_lfr

        return reduce_lfr(self, tol=tol)

    def to_mat(self, path) -> None:
        """See :func:`oos_drake.lfr.matfile.to_mat`."""
        from oos_drake.lfr.matfile import to_mat

        to_mat(self, path)

    def to_npz(self, path) -> None:
        """See :func:`oos_drake.lfr.matfile.to_npz` (read back with ``load_lfr``)."""
        from oos_drake.lfr.matfile import to_npz

        to_npz(self, path)


def _rebuild(M, n, blocks, input_names, output_names):
    return LFR(M, n, blocks, input_names=input_names, output_names=output_names)


def _is_scalar(value) -> bool:
    return isinstance(value, numbers.Number) or (
        isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "biufc"
    )


def _index_list(key, size: int, label: str) -> np.ndarray:
    if isinstance(key, slice):
        return np.arange(size)[key]
    arr = np.asarray(key)
    if arr.dtype == bool:
        if arr.shape != (size,):
            raise ValueError(f"LFR {label} mask has shape {arr.shape}, expected ({size},)")
        return np.flatnonzero(arr)
    arr = np.atleast_1d(arr).astype(int)
    if arr.ndim != 1 or np.any(arr >= size) or np.any(arr < -size):
        raise ValueError(f"LFR {label} index {key!r} out of range for {size} {label}s")
    return np.where(arr < 0, arr + size, arr)


# ====================================================================== conversion
def as_lfr(value) -> LFR:
    """Convert ``value`` to an :class:`LFR`.

    Parameters
    ----------
    value : LFR, control.StateSpace, control.TransferFunction, array_like or scalar
        Continuous-time systems only; transfer functions must be proper. Arrays with more than two
        dimensions are batched static gains.

    Raises
    ------
    TypeError
        For objects that are not systems or numbers (so operators can return ``NotImplemented``).
    ValueError
        For discrete-time or improper systems.
    """
    if isinstance(value, LFR):
        return value
    import control

    if isinstance(value, control.TransferFunction):
        if not value.isctime(strict=False):
            raise ValueError(
                f"as_lfr: discrete-time transfer function (dt={value.dt}) not supported"
            )
        for i in range(value.noutputs):
            for j in range(value.ninputs):
                num = np.trim_zeros(np.atleast_1d(value.num_array[i, j]), "f")
                den = np.trim_zeros(np.atleast_1d(value.den_array[i, j]), "f")
                if len(num) > len(den):
                    raise ValueError(
                        f"as_lfr: improper transfer function entry ({i}, {j}); "
                        "LFRs need proper systems"
                    )
        value = control.ss(value)
    if isinstance(value, control.StateSpace):
        if not value.isctime(strict=False):
            raise ValueError(f"as_lfr: discrete-time system (dt={value.dt}) not supported")
        return LFR.from_ss(value.A, value.B, value.C, value.D)
    if isinstance(value, numbers.Number | np.ndarray | list | tuple):
        arr = np.asarray(value)
        if arr.dtype.kind not in "biufc":
            raise TypeError(f"as_lfr: cannot convert array of dtype {arr.dtype}")
        return LFR.from_matrix(arr)
    raise TypeError(f"as_lfr: cannot convert {type(value).__name__} to an LFR")


def _operand(value) -> LFR | None:
    """The other operand of an LFR operator as an LFR; None when it is no system or number."""
    try:
        return as_lfr(value)
    except TypeError:
        return None


# ====================================================================== primitives
def _merge_blocks(systems: Sequence[LFR]):
    """Merged block table and, per system, the z-row / w-column offsets of its occurrences."""
    specs: dict[str, Block] = {}
    counts: dict[str, int] = {}
    for sys in systems:
        for entry in sys.block_entries:
            name = entry.spec.name
            if name in specs:
                if not same_block(specs[name], entry.spec):
                    raise ValueError(
                        f"uncertain block {name!r} is defined twice differently: "
                        f"{specs[name].describe()} vs {entry.spec.describe()}"
                    )
                specs[name] = merge_facts(specs[name], entry.spec)
            else:
                specs[name] = entry.spec
            counts[name] = counts.get(name, 0) + entry.reps
    names = sorted(specs)
    merged = tuple(BlockEntry(specs[name], counts[name]) for name in names)
    # next free z row / w column of each block in the merged vectors
    used_z, used_w, z0, w0 = {}, {}, 0, 0
    for entry in merged:
        used_z[entry.spec.name], used_w[entry.spec.name] = z0, w0
        z0 += entry.nz
        w0 += entry.nw
    z_maps, w_maps = [], []
    for sys in systems:
        zmap, wmap = [], []
        for entry in sys.block_entries:
            name = entry.spec.name
            zmap.append(np.arange(used_z[name], used_z[name] + entry.nz))
            wmap.append(np.arange(used_w[name], used_w[name] + entry.nw))
            used_z[name] += entry.nz
            used_w[name] += entry.nw
        z_maps.append(np.concatenate(zmap) if zmap else np.zeros(0, int))
        w_maps.append(np.concatenate(wmap) if wmap else np.zeros(0, int))
    return merged, z_maps, w_maps, z0, w0


def _concat_names(systems, attr):
    names = [getattr(s, attr) for s in systems]
    if all(n is None for n in names):
        return None
    out = []
    for sys, n in zip(systems, names, strict=True):
        count = sys.ninputs if attr == "_input_names" else sys.noutputs
        out.extend([None] * count if n is None else n)
    return out


def append_systems(systems: Sequence[LFR]) -> LFR:
    """Block-diagonal append of LFRs (inputs and outputs stacked), blocks merged by name."""
    systems = [as_lfr(s) for s in systems]
    if not systems:
        raise ValueError("append: no systems given")
    if len(systems) == 1:
        return systems[0]
    merged, z_maps, w_maps, nz, nw = _merge_blocks(systems)
    n = sum(s.nstates for s in systems)
    ny = sum(s.noutputs for s in systems)
    nu = sum(s.ninputs for s in systems)
    batch = np.broadcast_shapes(*(s.batch_shape for s in systems))
    dtype = np.result_type(*(s.M for s in systems))
    M = np.zeros(batch + (n + nz + ny, n + nw + nu), dtype=dtype)
    x0 = y0 = u0 = 0
    for sys, zmap, wmap in zip(systems, z_maps, w_maps, strict=True):
        rows = np.concatenate(
            [x0 + np.arange(sys.nstates), n + zmap, n + nz + y0 + np.arange(sys.noutputs)]
        )
        cols = np.concatenate(
            [x0 + np.arange(sys.nstates), n + wmap, n + nw + u0 + np.arange(sys.ninputs)]
        )
        M[..., rows[:, None], cols[None, :]] = sys.M
        x0 += sys.nstates
        y0 += sys.noutputs
        u0 += sys.ninputs
    return LFR(
        M,
        n,
        merged,
        input_names=_concat_names(systems, "_input_names"),
        output_names=_concat_names(systems, "_output_names"),
    )


def quarters(sys: LFR) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(M11, M12, M21, M22)`` of ``sys.M``: internal rows and columns (states and uncertain
    channels) first, external (outputs, inputs) second."""
    rows, cols = sys.nstates + sys.nz, sys.nstates + sys.nw
    M = sys.M
    return M[..., :rows, :cols], M[..., :rows, cols:], M[..., rows:, :cols], M[..., rows:, cols:]


def join_quarters(M11, M12, M21, M22) -> np.ndarray:
    """``[[M11, M12], [M21, M22]]`` with the batch dimensions broadcast (inverse of
    :func:`quarters`)."""
    batch = np.broadcast_shapes(*(m.shape[:-2] for m in (M11, M12, M21, M22)))
    rows = [
        np.concatenate([np.broadcast_to(m, batch + m.shape[-2:]) for m in pair], axis=-1)
        for pair in ((M11, M12), (M21, M22))
    ]
    return np.concatenate(rows, axis=-2)


def close_static(G: LFR, K, E, F, H, *, input_names=None, output_names=None) -> LFR:
    """Close a static interconnection around the external channels of ``G``.

    With ``G``'s inputs ``u_a`` and outputs ``y_a``, new external input ``v`` and output ``o``::

        u_a = K y_a + E v,      o = F y_a + H v

    Raises ``ValueError`` when the algebraic loop is ill-posed (``I - Dyu K`` singular).
    """
    K, E, F, H = (
        np.asarray(x, dtype=float) if np.isrealobj(x) else np.asarray(x) for x in (K, E, F, H)
    )
    M11, M12, M21, M22 = quarters(G)
    p_a, m_a = M22.shape[-2:]
    if K.shape != (m_a, p_a) or E.shape[0] != m_a or F.shape[1] != p_a:
        raise ValueError(
            f"close_static: interconnection sizes do not match system shape {(p_a, m_a)}"
        )
    if np.any(K):
        loop = np.eye(p_a) - M22 @ K
        _check_well_posed(loop)
        S_M21 = np.linalg.solve(loop, M21)  # S M21
        S_M22E = np.linalg.solve(loop, M22 @ E)  # S M22 E
        KS_M21 = K @ S_M21
        new11 = M11 + M12 @ KS_M21
        new12 = M12 @ (K @ S_M22E + E)
        new21 = F @ S_M21
        new22 = F @ S_M22E + H
    else:
        new11 = M11
        new12 = M12 @ E
        new21 = F @ M21
        new22 = F @ M22 @ E + H
    return LFR(
        join_quarters(new11, new12, new21, new22),
        G.nstates,
        G.block_entries,
        input_names=input_names,
        output_names=output_names,
    )


def _check_well_posed(loop: np.ndarray) -> None:
    cond = np.linalg.cond(loop) if loop.shape[-1] else np.array(1.0)
    if not np.all(np.isfinite(cond)) or np.any(cond > 1e13):
        raise ValueError(
            "interconnection is not well-posed: the algebraic loop matrix I - D1*D2 is singular "
            f"(condition number {np.max(cond):.3g})"
        )


def _siso_expand(sys: LFR, rows: int, cols: int) -> LFR:
    """A 1x1 system acting on ``rows x cols`` like MATLAB scalar expansion: ``ones*sys``
    (one copy) for addition."""
    return close_static(
        sys, np.zeros((1, 1)), np.ones((1, cols)), np.ones((rows, 1)), np.zeros((rows, cols))
    )


def _diag_expand(sys: LFR, count: int) -> LFR:
    """``sys * I_count`` for a 1x1 system (``count`` copies, like MATLAB ``m*eye(k)``)."""
    return append_systems([sys] * count)


def series(first: LFR, second: LFR) -> LFR:
    """``second * first``: the output of ``first`` drives ``second`` (python-control order)."""
    first, second = as_lfr(first), as_lfr(second)
    if first.noutputs != second.ninputs:
        if first.shape == (1, 1):
            first = _diag_expand(first, second.ninputs)
        elif second.shape == (1, 1):
            second = _diag_expand(second, first.noutputs)
    if first.noutputs != second.ninputs:
        raise ValueError(
            f"series connection: {first.noutputs} outputs cannot drive {second.ninputs} inputs"
        )
    if first.is_certain and first.nstates == 0 and not first.batch_shape and second.ninputs:
        # static gain on the input side: cheap right multiplication
        return _scale_inputs(second, first.M, first.input_names)
    if second.is_certain and second.nstates == 0 and not second.batch_shape and first.noutputs:
        return _scale_outputs(first, second.M, second.output_names)
    G = append_systems([first, second])
    p1, m1 = first.shape
    p2, m2 = second.shape
    K = np.zeros((m1 + m2, p1 + p2))
    K[m1:, :p1] = np.eye(p1)
    E = np.vstack([np.eye(m1), np.zeros((m2, m1))])
    F = np.hstack([np.zeros((p2, p1)), np.eye(p2)])
    return close_static(
        G,
        K,
        E,
        F,
        np.zeros((p2, m1)),
        input_names=first.input_names,
        output_names=second.output_names,
    )


def _scale_inputs(sys: LFR, gain: np.ndarray, input_names) -> LFR:
    n_int_c = sys.nstates + sys.nw
    M = np.concatenate([sys.M[..., :n_int_c], sys.M[..., n_int_c:] @ gain], axis=-1)
    return LFR(
        M, sys.nstates, sys.block_entries, input_names=input_names, output_names=sys.output_names
    )


def _scale_outputs(sys: LFR, gain: np.ndarray, output_names) -> LFR:
    n_int_r = sys.nstates + sys.nz
    M = np.concatenate([sys.M[..., :n_int_r, :], gain @ sys.M[..., n_int_r:, :]], axis=-2)
    return LFR(
        M, sys.nstates, sys.block_entries, input_names=sys.input_names, output_names=output_names
    )


def parallel(first: LFR, second: LFR, sign: float = 1.0) -> LFR:
    """``first + sign * second`` (same inputs, outputs added); 1x1 operands expand MATLAB-style."""
    first, second = as_lfr(first), as_lfr(second)
    if first.shape != second.shape:
        if first.shape == (1, 1):
            first = _siso_expand(first, *second.shape)
        elif second.shape == (1, 1):
            second = _siso_expand(second, *first.shape)
        else:
            raise ValueError(f"parallel connection: shapes {first.shape} and {second.shape} differ")
    G = append_systems([first, second])
    p, m = first.shape
    K = np.zeros((2 * m, 2 * p))
    E = np.vstack([np.eye(m), np.eye(m)])
    F = np.hstack([np.eye(p), sign * np.eye(p)])
    return close_static(
        G,
        K,
        E,
        F,
        np.zeros((p, m)),
        input_names=first.input_names or second.input_names,
        output_names=first.output_names or second.output_names,
    )


def inverse(sys: LFR) -> LFR:
    """Inverse system ``sys^-1`` of a square LFR with invertible feedthrough ``Dyu``."""
    sys = as_lfr(sys)
    ny, nu = sys.shape
    if ny != nu:
        raise ValueError(f"inv: system must be square, got shape {sys.shape}")
    M11, M12, M21, M22 = quarters(sys)
    cond = np.linalg.cond(M22) if ny else np.array(1.0)
    if not np.all(np.isfinite(cond)) or np.any(cond > 1e13):
        raise ValueError(f"inv: feedthrough Dyu is singular (condition number {np.max(cond):.3g})")
    Di = np.linalg.inv(M22)
    Di_M21 = Di @ M21
    return LFR(
        join_quarters(M11 - M12 @ Di_M21, M12 @ Di, -Di_M21, Di),
        sys.nstates,
        sys.block_entries,
        input_names=sys.output_names,
        output_names=sys.input_names,
    )
