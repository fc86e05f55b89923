r"""The uncertain closed loop of the analysis (paper Fig. controldesign with Delta_add, Delta_mul).

One implementation for the analysis (:mod:`oos_drake.analysis`) and the control package's users.

Around the rotational plant ``P(Delta_real)`` (``T_ext,G1 -> wdot``, 3x3, a channel of the
scenario LFR) the analysis adds

.. math::

    \hat P = (P + W_{add} \Delta_{add})
             \,(I_3 + W_{mul_L} \Delta_{mul_L} + W_{mul_R} \Delta_{mul_R}),

with ``Delta_add`` a full 3x3 ``ultidyn`` (``W_add = -75 dB``: it covers unknown inverse inertia
[(rad/s^2)/(N m)]) and ``Delta_mul`` nine scalar ``ultidyn`` blocks (diagonal ``W_mul_L = 4e-2``,
off-diagonal ``W_mul_R = 4e-3``: actuator gain, phase and misalignment). The weighted
interconnection (sensors, reaction wheels, roll-off, weights) of :mod:`oos_drake.control` is
closed with the controller (the static gain ``K``, or a dynamic
:class:`~oos_drake.control.interconnection.ControllerSystem`, its states then states of the
LFR) and with ``\hat P`` by two star products, giving the LFR

.. math:: \hat{\mathscr M}_{unc} = F_u(\mathscr M, \Delta_{tot}) : d = [d_{ext}; n_{sst}; n_{gyro}]
          \to e = [e_p; e_u],

with ``e_p = phi / W_p`` (pointing error over the APE requirement) and ``e_u = W_u u`` (torque
over its 2 N m bound), batched over the plant's configurations.
"""

from __future__ import annotations

import numpy as np

from oos_drake.control import components as comp
from oos_drake.control.interconnection import (
    CONTROLS,
    DISTURBANCES,
    ERRORS,
    MEASUREMENTS,
    PLANT_INPUTS,
    PLANT_OUTPUTS,
    as_controller,
    diagram_parts,
)
from oos_drake.control.statespace import connect
from oos_drake.lfr import LFR, as_lfr, lft, ultidyn

#: Name of the full 3x3 additive LTI block.
ADDITIVE_BLOCK = "Delta_add"
#: Axis labels of the multiplicative scalars ``Delta_mul_<ij>``.
_AXES = "xyz"
#: The nine multiplicative LTI scalars, diagonal (``W_mul_L``) first.
MULTIPLICATIVE_BLOCKS = tuple(f"Delta_mul_{a}{a}" for a in _AXES) + tuple(
    f"Delta_mul_{a}{b}" for a in _AXES for b in _AXES if a != b
)


def rotational_channels(model: LFR) -> LFR:
    """``T_ext,G1 -> wdot`` (3x3) of a scenario LFR ``W_ext,G1 (6) -> [a; wdot] (6)``."""
    model = as_lfr(model)
    if model.shape == (3, 3):
        return model
    if model.shape != (6, 6):
        raise ValueError(
            f"plant must be 3x3 (T -> wdot) or 6x6 (wrench -> twist), got {model.shape}"
        )
    return model[3:6, 3:6]


def uncertain_plant(
    plant: LFR,
    spec: comp.DesignSpecification | None = None,
    *,
    additive: bool = True,
    multiplicative: bool = True,
) -> LFR:
    """``P_hat = (P + W_add Delta_add)(I + W_mul Delta_mul)`` (3x3, blocks added by name).

    Parameters
    ----------
    plant : LFR
        ``T -> wdot`` (3x3) or the 6x6 scenario model, possibly a model array.
    spec : DesignSpecification, optional
        ``additive_weight_db``, ``multiplicative_diagonal``, ``multiplicative_off_diagonal``.
    additive, multiplicative : bool
        Include ``Delta_add`` / ``Delta_mul``.
    """
    spec = spec or comp.DesignSpecification()
    P = rotational_channels(plant)
    if additive:
        P = P + spec.additive_weight * ultidyn(
            ADDITIVE_BLOCK, (3, 3), unit="-", quantity="additive dynamics"
        )
    if multiplicative:
        factor = as_lfr(np.eye(3))
        eye = np.eye(3)
        for name in MULTIPLICATIVE_BLOCKS:
            i, j = _AXES.index(name[-2]), _AXES.index(name[-1])
            weight = spec.multiplicative_diagonal if i == j else spec.multiplicative_off_diagonal
            delta = ultidyn(name, (1, 1), unit="-", quantity="multiplicative dynamics")
            factor = factor + (weight * eye[:, [i]]) @ delta @ eye[[j], :]
        P = P @ factor
    return P


def weighted_interconnection_open(spec: comp.DesignSpecification | None = None) -> LFR:
    """The certain part of Fig. controldesign with the plant cut out.

    Returns
    -------
    LFR
        Inputs ``[d (9); wdot (3); u_K (3)]``, outputs ``[e (6); T (3); y (6)]`` (the same
        components and signs as :func:`oos_drake.control.interconnection.weighted_interconnection`).
    """
    spec = spec or comp.DesignSpecification()
    parts = diagram_parts(spec)
    inputs = DISTURBANCES + PLANT_OUTPUTS + CONTROLS
    outputs = ERRORS + PLANT_INPUTS + MEASUREMENTS
    H = connect(parts, inputs, outputs)
    return LFR.from_ss(H.A, H.B, H.C, H.D, input_names=list(inputs), output_names=list(outputs))


def close_loop(
    plant: LFR,
    K,
    spec: comp.DesignSpecification | None = None,
    *,
    additive: bool = True,
    multiplicative: bool = True,
) -> LFR:
    """Uncertain closed loop ``d (9) -> e (6)`` with ``Delta_tot`` (batched like ``plant``).

    Parameters
    ----------
    plant : LFR
        Scenario model (6x6) or its rotational channels (3x3) with the configuration already
        substituted (the remaining blocks are ``Delta_real``); a model array is allowed.
    K : array_like, shape (3, 6), or ControllerSystem
        ``[K_p, K_d]`` [N m/rad, N m s/rad], or a linear controller ``y -> u_K`` (a discrete
        one by its continuous form, :meth:`~oos_drake.control.interconnection.
        ControllerSystem.continuous`).
    spec : DesignSpecification, optional
        Weights and components (paper values by default).
    additive, multiplicative : bool
        Include ``Delta_add`` / ``Delta_mul``.

    Returns
    -------
    LFR
        Inputs ``d_ext[0..2], n_sst[0..2], n_gyro[0..2]``, outputs ``e_p[0..2], e_u[0..2]``.
    """
    try:
        controller = as_controller(K).continuous()
    except ValueError as exc:
        raise ValueError(f"close_loop: {exc}") from exc
    spec = spec or comp.DesignSpecification()
    H = weighted_interconnection_open(spec)
    if controller.is_static:
        C = as_lfr(controller.D)
    else:
        C = LFR.from_ss(controller.A, controller.B, controller.C, controller.D)
    HK = lft(H, C, 6, 3)  # y -> C -> u_K: [d; wdot] -> [e; T]
    P_hat = uncertain_plant(plant, spec, additive=additive, multiplicative=multiplicative)
    closed = lft(HK, P_hat, 3, 3)  # T -> P_hat -> wdot
    return closed.with_names(inputs=list(DISTURBANCES), outputs=list(ERRORS))
