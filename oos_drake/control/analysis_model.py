"""The uncertain closed loop of the paper's analysis (section 4) as an LFR.

``M_unc = F_u(M, diag(Delta_real, Delta_add, Delta_mul))`` with ``M = F_l(P_tot, K)``: the
weighted interconnection of Fig. controldesign closed by the static gain, around the plant

.. math::

    \\hat P = P\\,(I_3 + W_{mul,L} \\Delta_{mul,L} + W_{mul,R} \\Delta_{mul,R})
    + W_{add} \\Delta_{add}

(paper Eqs. for Delta_add and Delta_mul): ``Delta_add`` a full 3x3 ``ultidyn`` scaled by
``W_add = -75 dB``; ``Delta_mul`` nine scalar ``ultidyn`` blocks, ``mul_xx, mul_yy, mul_zz``
(weight 4e-2) on the diagonal and ``mul_xy, ...`` (weight 4e-3) off it. The real uncertainty
``Delta_real`` of the plant LFR stays in. Inputs ``d`` (9) and outputs ``e`` (6) keep the names
of :mod:`oos_drake.control.interconnection`.
"""

from __future__ import annotations

import numpy as np

from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import (
    CONTROLS,
    DISTURBANCES,
    ERRORS,
    MEASUREMENTS,
    diagram_parts,
)
from oos_drake.control.statespace import BatchedStateSpace, channel_names, connect

AXES = "xyz"


def multiplicative_uncertainty(spec: DesignSpecification | None = None):
    """``I3 + W_mul,L Delta_mul,L + W_mul,R Delta_mul,R`` as a 3x3 static LFR (9 ultidyn blocks)."""
    from oos_drake.lfr import LFR, ultidyn

    spec = spec or DesignSpecification()
    total = LFR.from_matrix(np.eye(3))
    for i in range(3):
        for j in range(3):
            weight = spec.multiplicative_diagonal if i == j else spec.multiplicative_off_diagonal
            E = np.zeros((3, 1))
            E[i, 0] = 1.0
            F = np.zeros((1, 3))
            F[0, j] = 1.0
            delta = ultidyn(
                f"mul_{AXES[i]}{AXES[j]}",
                (1, 1),
                bound=1.0,
                unit="-",
                quantity="multiplicative dynamics",
            )
            total = total + LFR.from_matrix(weight * E) * delta * LFR.from_matrix(F)
    return total


def uncertain_plant(plant, spec: DesignSpecification | None = None):
    """``P_hat = P (I + W_mul Delta_mul) + W_add Delta_add`` (an LFR, 3x3 ``T -> wdot``).

    Parameters
    ----------
    plant : oos_drake.lfr.LFR or BatchedStateSpace
        The 3x3 plant (possibly with ``Delta_real`` blocks and batch dimensions).
    """
    from oos_drake.lfr import LFR, as_lfr, ultidyn

    spec = spec or DesignSpecification()
    if isinstance(plant, BatchedStateSpace):
        plant = LFR.from_ss(plant.A, plant.B, plant.C, plant.D)
    plant = as_lfr(plant)
    if plant.shape != (3, 3):
        raise ValueError(f"uncertain_plant: plant must be 3x3 (T -> wdot), got {plant.shape}")
    additive = spec.additive_weight * ultidyn(
        "Delta_add", (3, 3), bound=1.0, unit="-", quantity="additive dynamics"
    )
    return plant * multiplicative_uncertainty(spec) + additive


def closed_loop_lfr(plant, K, spec: DesignSpecification | None = None, *, analysis=True):
    """The closed loop ``d -> e`` with its uncertain blocks, as an LFR (for mu analysis).

    Parameters
    ----------
    plant : oos_drake.lfr.LFR or BatchedStateSpace
        3x3 plant ``T -> wdot`` (``Delta_real`` blocks and batch dimensions allowed).
    K : array_like, shape (3, 6)
        Static gain ``[K_p, K_d]`` [N m/rad, N m s/rad].
    spec : DesignSpecification, optional
    analysis : bool
        Add ``Delta_add`` and ``Delta_mul`` (default) or keep only the plant's blocks.

    Returns
    -------
    oos_drake.lfr.LFR
        ``M_unc``: inputs ``DISTURBANCES``, outputs ``ERRORS``.
    """
    from oos_drake.lfr import LFR, as_lfr

    spec = spec or DesignSpecification()
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 6):
        raise ValueError(f"controller gain K must be 3x6, got shape {K.shape}")
    if isinstance(plant, BatchedStateSpace):
        plant = LFR.from_ss(plant.A, plant.B, plant.C, plant.D)
    P = uncertain_plant(plant, spec) if analysis else as_lfr(plant)
    nz, nw = P.nz, P.nw
    z_names, w_names = channel_names("z_delta", nz), channel_names("w_delta", nw)
    augmented = BatchedStateSpace(
        P.A,
        np.concatenate([P.Bw, P.Bu], axis=-1),
        np.concatenate([P.Cz, P.Cy], axis=-2),
        np.concatenate(
            [np.concatenate([P.Dzw, P.Dzu], axis=-1), np.concatenate([P.Dyw, P.Dyu], axis=-1)],
            axis=-2,
        ),
        w_names + channel_names("T", 3),
        z_names + channel_names("wdot", 3),
    )
    G = connect(
        [augmented, *diagram_parts(spec)],
        w_names + DISTURBANCES + CONTROLS,
        z_names + ERRORS + MEASUREMENTS,
    )
    # close u_K = K y (the loop u_K -> y is strictly proper)
    nin, nout = nw + 9, nz + 6
    Bu, Cy = G.B[..., :, nin:], G.C[..., nout:, :]
    Dyw, Dzu = G.D[..., nout:, :nin], G.D[..., :nout, nin:]
    if np.any(G.D[..., nout:, nin:] != 0):
        raise ValueError("closed_loop_lfr: the loop u_K -> y must be strictly proper")
    A = G.A + Bu @ K @ Cy
    B = G.B[..., :, :nin] + Bu @ K @ Dyw
    C = G.C[..., :nout, :] + Dzu @ K @ Cy
    D = G.D[..., :nout, :nin] + Dzu @ K @ Dyw
    return LFR.from_parts(
        A,
        B[..., :, :nw],
        B[..., :, nw:],
        C[..., :nz, :],
        C[..., nz:, :],
        D[..., :nz, :nw],
        D[..., :nz, nw:],
        D[..., nz:, :nw],
        D[..., nz:, nw:],
        [(entry.spec, entry.reps) for entry in P.block_entries],
        input_names=list(DISTURBANCES),
        output_names=list(ERRORS),
    )
