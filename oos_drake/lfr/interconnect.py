"""Interconnections of LFRs: feedback, Redheffer star product, stacking, inversion, connect.

Every function accepts LFRs, ``control.StateSpace``/``TransferFunction``, arrays and scalars as
operands and returns a new :class:`~oos_drake.lfr.core.LFR`; blocks with the same name merge.
All of them are an append of the operands followed by one static interconnection
(:func:`~oos_drake.lfr.core.close_static`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np

from oos_drake.lfr.core import LFR, append_systems, as_lfr, close_static, inverse


def feedback(sys1, sys2=1, sign: int = -1) -> LFR:
    """Feedback loop ``y = sys1 (u + sign * sys2 y)`` (negative feedback by default).

    Parameters
    ----------
    sys1 : LFR or convertible
        Forward path, shape ``(ny, nu)``.
    sys2 : LFR or convertible
        Feedback path, shape ``(nu, ny)`` (1x1 operands expand to ``sys2 * I``).
    sign : {-1, 1}
        Feedback sign.

    Raises
    ------
    ValueError
        On dimension mismatch or an ill-posed algebraic loop.
    """
    sys1, sys2 = as_lfr(sys1), as_lfr(sys2)
    ny, nu = sys1.shape
    if sys2.shape != (nu, ny):
        if sys2.shape == (1, 1) and ny == nu:
            sys2 = append_systems([sys2] * nu) if nu > 1 else sys2
        else:
            raise ValueError(f"feedback: sys2 has shape {sys2.shape}, expected {(nu, ny)}")
    if sign not in (-1, 1):
        raise ValueError(f"feedback: sign must be -1 or 1, got {sign!r}")
    G = append_systems([sys1, sys2])
    K = np.zeros((nu + ny, ny + nu))
    K[:nu, ny:] = sign * np.eye(nu)
    K[nu:, :ny] = np.eye(ny)
    E = np.vstack([np.eye(nu), np.zeros((ny, nu))])
    F = np.hstack([np.eye(ny), np.zeros((ny, nu))])
    return close_static(
        G, K, E, F, np.zeros((ny, nu)), input_names=sys1.input_names, output_names=sys1.output_names
    )


def lft(upper, lower, nu: int | None = None, ny: int | None = None) -> LFR:
    """Redheffer star product of ``upper`` and ``lower`` (MATLAB ``lft(sys1, sys2, nu, ny)``).

    The last ``nu`` outputs of ``upper`` drive the first ``nu`` inputs of ``lower``; the first
    ``ny`` outputs of ``lower`` drive the last ``ny`` inputs of ``upper``. The result has inputs
    ``[upper's free inputs; lower's free inputs]`` and outputs ``[upper's free outputs; lower's
    free outputs]``.

    Without ``nu``/``ny``: if ``lower`` is smaller than ``upper`` it is closed completely (lower
    LFT, e.g. a controller ``K`` closing a plant ``P``: ``lft(P, K)``); if ``upper`` is the smaller
    one it is closed completely (upper LFT ``lft(Delta, M)``).
    """
    upper, lower = as_lfr(upper), as_lfr(lower)
    p1, m1 = upper.shape
    p2, m2 = lower.shape
    if nu is None and ny is None:
        if m2 <= p1 and p2 <= m1 and (p2 < m1 or m2 < p1 or (p1, m1) == (m2, p2)):
            nu, ny = m2, p2  # lower LFT: lower closed completely
        elif p1 <= m2 and m1 <= p2:
            nu, ny = p1, m1  # upper LFT: upper closed completely
        else:
            raise ValueError(
                f"lft: cannot infer the loop sizes for shapes {upper.shape} and "
                f"{lower.shape}; pass nu and ny"
            )
    elif nu is None or ny is None:
        raise ValueError("lft: give both nu and ny, or neither")
    nu, ny = int(nu), int(ny)
    if not (0 <= nu <= min(p1, m2) and 0 <= ny <= min(m1, p2)):
        raise ValueError(f"lft: nu={nu}, ny={ny} do not fit shapes {upper.shape} and {lower.shape}")
    G = append_systems([upper, lower])
    # external inputs of G: [u1a (m1-ny), u1b (ny), u2a (nu), u2b (m2-nu)]
    # external outputs of G: [y1a (p1-nu), y1b (nu), y2a (ny), y2b (p2-ny)]
    K = np.zeros((m1 + m2, p1 + p2))
    K[m1 - ny : m1, p1 : p1 + ny] = np.eye(ny)  # u1b = y2a
    K[m1 : m1 + nu, p1 - nu : p1] = np.eye(nu)  # u2a = y1b
    free_in = np.concatenate([np.arange(m1 - ny), m1 + nu + np.arange(m2 - nu)])
    free_out = np.concatenate([np.arange(p1 - nu), p1 + ny + np.arange(p2 - ny)])
    E = np.zeros((m1 + m2, free_in.size))
    E[free_in, np.arange(free_in.size)] = 1.0
    F = np.zeros((free_out.size, p1 + p2))
    F[np.arange(free_out.size), free_out] = 1.0
    in_names = _pick(G.input_names, free_in)
    out_names = _pick(G.output_names, free_out)
    return close_static(
        G,
        K,
        E,
        F,
        np.zeros((free_out.size, free_in.size)),
        input_names=in_names,
        output_names=out_names,
    )


def _pick(names, index):
    return None if names is None else [names[i] for i in index]


def append(*systems) -> LFR:
    """Block-diagonal append: inputs and outputs of all systems stacked (MATLAB ``append``)."""
    return append_systems(list(systems))


def hstack(systems: Sequence) -> LFR:
    """``[sys1, sys2, ...]``: inputs stacked, outputs added (MATLAB horizontal concatenation)."""
    return _concatenate(systems, horizontal=True)


def vstack(systems: Sequence) -> LFR:
    """``[sys1; sys2; ...]``: shared inputs, outputs stacked (MATLAB vertical concatenation)."""
    return _concatenate(systems, horizontal=False)


def _concatenate(systems: Sequence, *, horizontal: bool) -> LFR:
    """``hstack`` (the systems' outputs added) or ``vstack`` (their inputs shared)."""
    what, shared = ("hstack", "outputs") if horizontal else ("vstack", "inputs")
    systems = [as_lfr(s) for s in systems]
    if not systems:
        raise ValueError(f"{what}: no systems given")
    size = systems[0].noutputs if horizontal else systems[0].ninputs
    for k, sys in enumerate(systems):
        got = sys.noutputs if horizontal else sys.ninputs
        if got != size:
            raise ValueError(f"{what}: system {k} has {got} {shared}, expected {size}")
    if len(systems) == 1:
        return systems[0]
    G = append_systems(systems)
    m, p = G.ninputs, G.noutputs
    K = np.zeros((m, p))
    if horizontal:
        E, F, H = np.eye(m), np.hstack([np.eye(size)] * len(systems)), np.zeros((size, m))
        names = {"input_names": G.input_names, "output_names": systems[0].output_names}
    else:
        E, F, H = np.vstack([np.eye(size)] * len(systems)), np.eye(p), np.zeros((p, size))
        names = {"input_names": systems[0].input_names, "output_names": G.output_names}
    return close_static(G, K, E, F, H, **names)


def inv(sys) -> LFR:
    """Inverse of a square LFR with invertible feedthrough (``ValueError`` otherwise)."""
    return inverse(as_lfr(sys))


def sumblk(expression: str, width: int = 1) -> LFR:
    """Summing junction with named signals, e.g. ``sumblk("e = r - y")`` (MATLAB ``sumblk``).

    Parameters
    ----------
    expression : str
        ``"out = [+-]in1 [+-] in2 ..."``.
    width : int
        Vector width; names then expand to ``name[0], ..., name[width-1]``.
    """
    match = re.fullmatch(r"\s*([\w.\[\]]+)\s*=\s*(.+)", expression)
    if not match:
        raise ValueError(f"sumblk: cannot parse {expression!r} (expected 'out = a + b - c')")
    output, rhs = match.group(1), match.group(2).replace(" ", "")
    terms = re.findall(r"([+-]?)([\w.\[\]]+)", rhs)
    if not terms or "".join(s + t for s, t in terms) != rhs.lstrip("+"):
        if "".join(s + t for s, t in terms) != rhs:
            raise ValueError(f"sumblk: cannot parse right-hand side {rhs!r}")
    signs = [-1.0 if s == "-" else 1.0 for s, _ in terms]
    names = [t for _, t in terms]
    D = np.hstack([sign * np.eye(width) for sign in signs])

    def expand(name):
        return [name] if width == 1 else [f"{name}[{k}]" for k in range(width)]

    in_names = [n for name in names for n in expand(name)]
    return LFR.from_matrix(D, input_names=in_names, output_names=expand(output))


def _expand_signal(name: str, available: Sequence[str]) -> list[str]:
    if name in available:
        return [name]
    vector = [f"{name}[{k}]" for k in range(len(available))]
    found = [v for v in vector if v in available]
    return found


def connect(systems: Sequence, inputs: Sequence[str], outputs: Sequence[str]) -> LFR:
    """Interconnect named systems MATLAB-style.

    Each system needs ``input_names`` and ``output_names`` (see :meth:`LFR.with_names` and
    :func:`sumblk`). A signal ``X`` is the sum of every block output named ``X`` plus, if
    ``X`` is in
    ``inputs``, the external input ``X``. Every block input named ``X`` receives signal ``X``; every
    external output named ``X`` reads it. A vector name ``u`` stands for ``u[0], u[1], ...``.

    Parameters
    ----------
    systems : sequence of LFR
        Blocks with named inputs and outputs.
    inputs, outputs : sequence of str
        External input and output signal names, in order.

    Raises
    ------
    ValueError
        When a block input has no source, an external name is unknown, or the loop is ill-posed.
    """
    systems = [as_lfr(s) for s in systems]
    for k, sys in enumerate(systems):
        if sys.input_names is None and sys.ninputs or sys.output_names is None and sys.noutputs:
            raise ValueError(
                f"connect: system {k} ({sys!r}) has unnamed inputs or outputs; "
                "use .with_names(inputs=..., outputs=...)"
            )
        names = (sys.input_names or ()) + (sys.output_names or ())
        if None in names:
            raise ValueError(f"connect: system {k} has partly unnamed inputs or outputs")
    if isinstance(inputs, str):
        inputs = [inputs]
    if isinstance(outputs, str):
        outputs = [outputs]
    G = append_systems(systems)
    in_names = list(G.input_names or ())
    out_names = list(G.output_names or ())
    signals = set(in_names) | set(out_names)
    ext_in = []
    for name in inputs:
        found = _expand_signal(name, sorted(signals))
        if not found:
            raise ValueError(f"connect: external input {name!r} is not a signal of any system")
        ext_in.extend(found)
    ext_out = []
    for name in outputs:
        found = _expand_signal(name, sorted(signals | set(ext_in)))
        if not found:
            raise ValueError(f"connect: external output {name!r} is not a signal of any system")
        ext_out.extend(found)
    sources = set(out_names) | set(ext_in)
    for name in in_names:
        if name not in sources:
            raise ValueError(
                f"connect: block input {name!r} is driven by no block output and is "
                "not an external input"
            )
    out_arr = np.array(out_names, dtype=object)
    in_arr = np.array(in_names, dtype=object)
    K = (
        (in_arr[:, None] == out_arr[None, :]).astype(float)
        if in_names and out_names
        else np.zeros((len(in_names), len(out_names)))
    )
    E = np.array([[1.0 if a == b else 0.0 for b in ext_in] for a in in_names]).reshape(
        len(in_names), len(ext_in)
    )
    F = np.array([[1.0 if a == b else 0.0 for b in out_names] for a in ext_out]).reshape(
        len(ext_out), len(out_names)
    )
    H = np.array([[1.0 if a == b else 0.0 for b in ext_in] for a in ext_out]).reshape(
        len(ext_out), len(ext_in)
    )
    # an external output reading a signal that is also fed back must see the closed loop value
    return close_static(G, K, E, F, H, input_names=ext_in, output_names=ext_out)
