"""Batched continuous-time state-space models with named channels, and a MATLAB-style ``connect``.

A :class:`BatchedStateSpace` holds ``A, B, C, D`` with optional leading batch dimensions
``(..., rows, cols)`` (a model array: every model has the same sizes). Channels are named, so
interconnections are written by signal name, like MATLAB's ``connect``. The weighted synthesis
interconnection of the paper (Fig. controldesign) is assembled with it when no uncertain block is
left in the plant; :mod:`oos_drake.control.interconnection` uses it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


def channel_names(name: str, size: int) -> tuple[str, ...]:
    """Return the channel names ``name[0] ... name[size-1]`` of a vector signal.

    Parameters
    ----------
    name : str
        Signal name, e.g. ``"phi"``.
    size : int
        Number of channels.

    Returns
    -------
    tuple of str
    """
    return tuple(f"{name}[{i}]" for i in range(size))


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class BatchedStateSpace:
    """A (possibly batched) continuous-time LTI model ``xdot = A x + B u, y = C x + D u``.

    Parameters
    ----------
    A, B, C, D : numpy.ndarray
        State-space matrices, shapes ``(..., n, n)``, ``(..., n, m)``, ``(..., p, n)``,
        ``(..., p, m)``; leading batch dimensions must agree (or broadcast).
    inputs, outputs : tuple of str
        Channel names (``m`` and ``p`` of them).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    def __post_init__(self):
        A, B, C, D = (np.asarray(M, dtype=float) for M in (self.A, self.B, self.C, self.D))
        n, m, p = A.shape[-1], D.shape[-1], D.shape[-2]
        if A.shape[-2] != n or B.shape[-2:] != (n, m) or C.shape[-2:] != (p, n):
            raise ValueError(
                f"BatchedStateSpace: inconsistent shapes "
                f"A{A.shape} B{B.shape} C{C.shape} D{D.shape}"
            )
        if len(self.inputs) != m or len(self.outputs) != p:
            raise ValueError(
                f"BatchedStateSpace: {len(self.inputs)} input names for {m} inputs or "
                f"{len(self.outputs)} output names for {p} outputs"
            )
        batch = np.broadcast_shapes(A.shape[:-2], B.shape[:-2], C.shape[:-2], D.shape[:-2])
        for field, M in zip("ABCD", (A, B, C, D), strict=True):
            object.__setattr__(self, field, _readonly(np.broadcast_to(M, batch + M.shape[-2:])))
        object.__setattr__(self, "inputs", tuple(self.inputs))
        object.__setattr__(self, "outputs", tuple(self.outputs))

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading batch dimensions (``()`` for a single model)."""
        return self.A.shape[:-2]

    @property
    def nstates(self) -> int:
        """Number of states."""
        return self.A.shape[-1]

    @classmethod
    def static(cls, D, inputs, outputs) -> BatchedStateSpace:
        """Return a static gain ``y = D u`` (no states)."""
        D = np.asarray(D, dtype=float)
        batch = D.shape[:-2]
        p, m = D.shape[-2:]
        return cls(
            np.zeros(batch + (0, 0)),
            np.zeros(batch + (0, m)),
            np.zeros(batch + (p, 0)),
            D,
            inputs,
            outputs,
        )

    def take(self, index) -> BatchedStateSpace:
        """Return the models ``index`` of the first batch dimension (int, slice or array)."""
        return BatchedStateSpace(
            self.A[index], self.B[index], self.C[index], self.D[index], self.inputs, self.outputs
        )

    def freqresp(self, omega) -> np.ndarray:
        """Return the frequency response, shape ``(..., F, p, m)``, at ``omega`` [rad/s].

        Uses one LU solve per model and frequency (exact, for checks and small grids).
        """
        omega = np.atleast_1d(np.asarray(omega, dtype=float))
        n = self.nstates
        s = 1j * omega[:, None, None]
        A = self.A[..., None, :, :]
        if n == 0:
            return np.broadcast_to(
                self.D[..., None, :, :], self.batch_shape + (omega.size,) + self.D.shape[-2:]
            ).astype(complex)
        X = np.linalg.solve(s * np.eye(n) - A, self.B[..., None, :, :].astype(complex))
        return self.C[..., None, :, :] @ X + self.D[..., None, :, :]


def append(systems: Sequence[BatchedStateSpace]) -> BatchedStateSpace:
    """Return the block-diagonal union of ``systems`` (states, inputs and outputs concatenated)."""
    batch = np.broadcast_shapes(*(sys.batch_shape for sys in systems))
    n = sum(sys.nstates for sys in systems)
    m = sum(len(sys.inputs) for sys in systems)
    p = sum(len(sys.outputs) for sys in systems)
    A = np.zeros(batch + (n, n))
    B = np.zeros(batch + (n, m))
    C = np.zeros(batch + (p, n))
    D = np.zeros(batch + (p, m))
    i = j = k = 0
    for sys in systems:
        ni, mi, pi = sys.nstates, len(sys.inputs), len(sys.outputs)
        A[..., i : i + ni, i : i + ni] = sys.A
        B[..., i : i + ni, j : j + mi] = sys.B
        C[..., k : k + pi, i : i + ni] = sys.C
        D[..., k : k + pi, j : j + mi] = sys.D
        i, j, k = i + ni, j + mi, k + pi
    inputs = sum((sys.inputs for sys in systems), ())
    outputs = sum((sys.outputs for sys in systems), ())
    return BatchedStateSpace(A, B, C, D, inputs, outputs)


def connect(
    systems: Sequence[BatchedStateSpace], inputs: Sequence[str], outputs: Sequence[str]
) -> BatchedStateSpace:
    """Interconnect named systems, like MATLAB's ``connect(sys1, ..., inputs, outputs)``.

    Every component input channel named ``s`` is driven by the signal ``s``: the component
    output of that name, or the external input of that name. Sums are written with
    :func:`sum_block`. Each signal must be produced by exactly one component output (or be an
    external input); external inputs that are also component inputs feed them directly.

    Parameters
    ----------
    systems : sequence of BatchedStateSpace
        Components (batch dimensions broadcast).
    inputs : sequence of str
        External input channel names, in order.
    outputs : sequence of str
        Output channel names (component outputs or external inputs), in order.

    Returns
    -------
    BatchedStateSpace
        The interconnection from ``inputs`` to ``outputs``.
    """
    big = append(systems)
    producers: dict[str, int] = {}
    for row, name in enumerate(big.outputs):
        if name in producers:
            raise ValueError(f"connect: signal {name!r} is produced by two components")
        producers[name] = row
    external = {name: col for col, name in enumerate(inputs)}
    if len(external) != len(inputs):
        raise ValueError("connect: duplicate external input name")
    m_int, p_int, m_ext = len(big.inputs), len(big.outputs), len(inputs)
    Q = np.zeros((m_int, p_int))  # internal input <- component outputs
    R = np.zeros((m_int, m_ext))  # internal input <- external inputs
    for col, name in enumerate(big.inputs):
        if name in producers:
            Q[col, producers[name]] = 1.0
        elif name in external:
            R[col, external[name]] = 1.0
        else:
            raise ValueError(f"connect: component input {name!r} is driven by no signal")
    # y = C x + D (Q y + R u)  ->  y = (I - D Q)^-1 (C x + D R u)
    L = np.linalg.inv(np.eye(p_int) - big.D @ Q)
    Cy = L @ big.C
    Dy = L @ big.D @ R
    A = big.A + big.B @ Q @ Cy
    B = big.B @ (Q @ Dy + R)
    C_rows, D_rows = [], []
    batch = big.batch_shape
    for name in outputs:
        if name in producers:
            C_rows.append(Cy[..., producers[name], :])
            D_rows.append(Dy[..., producers[name], :])
        elif name in external:
            C_rows.append(np.zeros(batch + (big.nstates,)))
            D_rows.append(np.broadcast_to(np.eye(m_ext)[external[name]], batch + (m_ext,)))
        else:
            raise ValueError(f"connect: output {name!r} is no signal of the interconnection")
    C = np.stack(C_rows, axis=-2)
    D = np.stack(D_rows, axis=-2)
    return BatchedStateSpace(A, B, C, D, tuple(inputs), tuple(outputs))


def sum_block(output: Sequence[str], terms: Sequence[Sequence[str]], signs: Sequence[float]):
    """Return the static summing junction ``output = sum_k signs[k] * terms[k]`` (vector signals).

    Parameters
    ----------
    output : sequence of str
        Output channel names (length ``q``).
    terms : sequence of sequence of str
        Input signals, each a sequence of ``q`` channel names.
    signs : sequence of float
        One sign (or gain) per term.
    """
    q = len(output)
    if any(len(term) != q for term in terms) or len(signs) != len(terms):
        raise ValueError("sum_block: every term must have as many channels as the output")
    D = np.hstack([sign * np.eye(q) for sign in signs])
    return BatchedStateSpace.static(D, sum((tuple(t) for t in terms), ()), tuple(output))
