"""Interconnections of LFRs: feedback, Redheffer star product, stacking, inversion.

Every function accepts LFRs, ``control.StateSpace``/``TransferFunction``, arrays and scalars as
operands and returns a new :class:`~oos_drake.lfr.core.LFR`; blocks with the same name merge.
All of them are an append of the operands followed by one static interconnection
(:func:`~oos_drake.lfr.core.close_static`).
"""

from __future__ import annotations

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
