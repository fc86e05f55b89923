"""The weighted synthesis interconnection of the paper's Fig. controldesign.

Signals (three channels each, named ``name[0..2]``)::

    d = [d_ext; n_sst; n_gyro]   normalized disturbances (9 inputs)
    u_K                          controller output [N m] (3 inputs)
    e = [e_p; e_u]               weighted errors: e_p = phi / W_p, e_u = W_u u (6 outputs)
    y = [y_att; y_rate]          measured errors (reference 0): -(SST phi + W_n,sst n_sst) [rad],
                                 -(GYRO w + W_n,gyro n_gyro) [rad/s] (6 outputs)

    u    = F_ro u_K                     (Butterworth roll-off on the command)
    T    = H RW u + W_n,ext d_ext       (reaction wheels, external disturbance) -> plant input;
                                        H = 1, or the flight software's sample-and-hold
                                        (``components.sample_hold``) when ``spec.sampled``
    wdot = P T                          (plant channels T_ext,G1 -> wdot, 3x3)
    w    = wdot / s,  phi = w / s

The controller is ``u_K = K y`` with the static 3x6 gain ``K = [K_p, K_d]``, which equals the
paper's ``u = K_att [phi_ref - phi; w_ref - w]``. The closed loop ``M = F_l(P_tot, K)`` maps
``d -> e``; the synthesis goal is ``||M||_inf < 1`` (Eq. controlreq).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from oos_drake.control import components as comp
from oos_drake.control.loop_response import LoopResponse
from oos_drake.control.statespace import BatchedStateSpace, channel_names, connect, sum_block

DISTURBANCES = channel_names("d_ext", 3) + channel_names("n_sst", 3) + channel_names("n_gyro", 3)
CONTROLS = channel_names("u_K", 3)
ERRORS = channel_names("e_p", 3) + channel_names("e_u", 3)
MEASUREMENTS = channel_names("y_att", 3) + channel_names("y_rate", 3)
PLANT_INPUTS = channel_names("T", 3)
PLANT_OUTPUTS = channel_names("wdot", 3)


@dataclass(frozen=True)
class WeightedInterconnection:
    """The open-loop weighted interconnection ``P_tot`` (batched over plant models).

    Parameters
    ----------
    system : BatchedStateSpace
        ``[e; y] = P_tot [d; u_K]``, inputs ``DISTURBANCES + CONTROLS``, outputs
        ``ERRORS + MEASUREMENTS``.
    spec : DesignSpecification
        The weights and component data used.
    plant : BatchedStateSpace, optional
        The plant array it was built around (enables :attr:`loop`).
    """

    system: BatchedStateSpace
    spec: comp.DesignSpecification
    plant: BatchedStateSpace | None = None

    @functools.cached_property
    def loop(self):
        """:class:`~oos_drake.control.loop_response.LoopResponse` of the plant array, or None.

        Closed-loop responses from the plant's modal form (computed once, reused for every
        gain); ``None`` for a single model or when the plant is unknown.
        """
        if self.plant is None or self.plant.A.ndim != 3:
            return None
        return LoopResponse(self.plant, self.spec)

    def __post_init__(self):
        sys = self.system
        if sys.inputs != DISTURBANCES + CONTROLS or sys.outputs != ERRORS + MEASUREMENTS:
            raise ValueError("WeightedInterconnection: channels are not [d; u_K] -> [e; y]")
        if np.any(sys.D[..., 6:, 9:] != 0):
            raise ValueError("WeightedInterconnection: the loop u_K -> y must be strictly proper")

    def partitions(self):
        """Return ``(A, B1, B2, C1, C2, D11, D12, D21)`` (batched), ``D22 = 0``."""
        s = self.system
        return (
            s.A,
            s.B[..., :, :9],
            s.B[..., :, 9:],
            s.C[..., :6, :],
            s.C[..., 6:, :],
            s.D[..., :6, :9],
            s.D[..., :6, 9:],
            s.D[..., 6:, :9],
        )

    def close(self, K) -> BatchedStateSpace:
        """Return the closed loop ``M = F_l(P_tot, K)`` from ``d`` to ``e``.

        Parameters
        ----------
        K : array_like, shape (3, 6) or (..., 3, 6)
            Static gain ``[K_p, K_d]``: ``K_p`` [N m/rad], ``K_d`` [N m s/rad].
        """
        K = np.asarray(K, dtype=float)
        if K.shape[-2:] != (3, 6):
            raise ValueError(f"controller gain K must be 3x6, got shape {K.shape}")
        A, B1, B2, C1, C2, D11, D12, D21 = self.partitions()
        B2K = B2 @ K
        D12K = D12 @ K
        return BatchedStateSpace(
            A + B2K @ C2, B1 + B2K @ D21, C1 + D12K @ C2, D11 + D12K @ D21, DISTURBANCES, ERRORS
        )


def plant_statespace(A, B, C, D) -> BatchedStateSpace:
    """Wrap batched plant matrices ``T -> wdot`` (3 inputs [N m], 3 outputs [rad/s^2])."""
    D = np.asarray(D, dtype=float)
    if D.shape[-2:] != (3, 3):
        raise ValueError(f"plant must be 3x3 (T_ext -> wdot), got D of shape {D.shape}")
    return BatchedStateSpace(A, B, C, D, PLANT_INPUTS, PLANT_OUTPUTS)


def weighted_interconnection(
    plant: BatchedStateSpace, spec: comp.DesignSpecification | None = None
) -> WeightedInterconnection:
    """Assemble the paper's weighted interconnection around a (batched) 3x3 plant.

    Parameters
    ----------
    plant : BatchedStateSpace
        Rotational plant channels ``T_ext,G1 -> wdot`` (inputs ``T[0..2]`` [N m], outputs
        ``wdot[0..2]`` [rad/s^2]), possibly a model array with leading batch dimensions.
    spec : DesignSpecification, optional
        Weights and component data (paper values by default).

    Returns
    -------
    WeightedInterconnection
    """
    spec = spec or comp.DesignSpecification()
    if plant.inputs != PLANT_INPUTS or plant.outputs != PLANT_OUTPUTS:
        plant = plant_statespace(plant.A, plant.B, plant.C, plant.D)
    system = connect([plant, *diagram_parts(spec)], DISTURBANCES + CONTROLS, ERRORS + MEASUREMENTS)
    return WeightedInterconnection(system, spec, plant)


def diagram_parts(spec: comp.DesignSpecification) -> list[BatchedStateSpace]:
    """Every block of Fig. controldesign except the plant, as named systems for ``connect``.

    The plant to add reads ``T[0..2]`` and produces ``wdot[0..2]`` (it may have more channels,
    e.g. the ``w``/``z`` channels of its uncertain blocks, passed as external signals).
    """
    v = channel_names
    return [
        comp.integrator("wdot", "w"),
        comp.integrator("w", "phi"),
        comp.star_tracker(spec, "phi", "phi_sst"),
        comp.gyro(spec, "w", "w_gyro"),
        comp.rolloff_filter(spec, "u_K", "u"),
        *(
            [comp.reaction_wheels(spec, "u", "T_rw_c"), comp.hold(spec, "T_rw_c", "T_rw")]
            if spec.sampled
            else [comp.reaction_wheels(spec, "u", "T_rw")]
        ),
        comp.disturbance_weight(spec, "d_ext", "T_dist"),
        sum_block(v("T", 3), [v("T_rw", 3), v("T_dist", 3)], [1.0, 1.0]),
        comp.static_gain(spec.noise_star_tracker, "n_sst", "n_sst_w"),
        comp.static_gain(spec.noise_gyro, "n_gyro", "n_gyro_w"),
        sum_block(v("y_att", 3), [v("phi_sst", 3), v("n_sst_w", 3)], [-1.0, -1.0]),
        sum_block(v("y_rate", 3), [v("w_gyro", 3), v("n_gyro_w", 3)], [-1.0, -1.0]),
        comp.static_gain(1.0 / spec.pointing_requirement, "phi", "e_p"),
        comp.static_gain(spec.control_weight, "u", "e_u"),
    ]
