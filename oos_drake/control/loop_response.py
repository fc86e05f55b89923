"""Closed-loop frequency response of the weighted interconnection from the plant's modal form.

The closed loop ``M = F_l(P_tot, K)`` of Fig. controldesign has 81 states (48 plant, 33 sensors,
actuators, filters, integrators), but every block except the plant is a per-axis SISO filter that
does not depend on the model, and the controller is static. At ``s = j omega``, with the scalar
responses ``sst, gyro`` (sensors), ``ro`` (roll-off), ``rw`` (wheels, times the sample-and-hold
model when ``spec.sampled``), ``w_i`` (disturbance weights) and the plant ``P(s)`` (3x3):

.. math::

    K_g = K_p\\,\\frac{sst}{s^2} + K_d\\,\\frac{gyro}{s}, \\qquad
    S = (I + rw\\,ro\\,K_g P)^{-1}, \\qquad Q = P S, \\qquad
    N = -[W_{sst} K_p,\\; W_{gyro} K_d]

.. math::

    M(s) = \\begin{bmatrix} Q\\,W_{ext} / (W_p s^2) & rw\\,ro\\,Q N / (W_p s^2) \\\\
                            -W_u\\,ro\\,K_g Q\\,W_{ext} & W_u\\,ro\\,S N \\end{bmatrix}

(``e_p = phi / W_p``, ``phi = P T / s^2``, ``e_u = W_u u``). A dynamic controller
(:class:`~oos_drake.control.interconnection.ControllerSystem`) enters the same formula with
``[K_p, K_d]`` replaced by its response ``C(j omega)`` (3x6) at each frequency (a discrete one
by its continuous form). Only ``P(s)`` depends on the model: its
modal form (one 48-state eigendecomposition per plant, independent of ``K``) gives it at any
frequency with one small product, so a gamma evaluation needs only the closed-loop **eigenvalues**
(stability, frequency grid), not the closed-loop eigenvectors. The formula has no cancellation at
low frequency (``S`` absorbs the double integrator: ``Q / s^2`` stays O(1)); ``omega = 0`` itself is
evaluated at ``OMEGA_MIN = 1e-9 rad/s``, where sigma differs from its DC value by
``O((1e-9 / |lambda|_min)^2)`` relative (1e-14 for the slowest closed-loop poles, ~0.01 rad/s).
"""

from __future__ import annotations

import numpy as np

from oos_drake.control import components as comp
from oos_drake.control.statespace import BatchedStateSpace
from oos_drake.lfr import LFR

#: Eigenvector basis condition number of a plant above which its response uses LU solves.
PLANT_CONDITION_LIMIT = 1e10
#: Frequencies below this [rad/s] are evaluated at it (the formula divides by s^2).
OMEGA_MIN = 1e-9


def _siso_modal(siso):
    """Poles, residues and feedthrough of a small SISO ``(A, B, C, D)`` with distinct poles."""
    A, B, C, D = (np.asarray(M, dtype=float) for M in siso)
    lam, V = np.linalg.eig(A)
    residues = (C @ V).ravel() * np.linalg.solve(V, B).ravel()
    return lam, residues, float(D[0, 0])


def _inverse3(M):
    """Inverse of a stack of 3x3 matrices by cofactors (elementwise: no per-matrix call)."""
    a, b, c = M[..., 0, 0], M[..., 0, 1], M[..., 0, 2]
    d, e, f = M[..., 1, 0], M[..., 1, 1], M[..., 1, 2]
    g, h, i = M[..., 2, 0], M[..., 2, 1], M[..., 2, 2]
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    inv_det = 1.0 / (a * A + b * B + c * C)
    out = np.empty_like(M)
    out[..., 0, 0], out[..., 1, 0], out[..., 2, 0] = A * inv_det, B * inv_det, C * inv_det
    out[..., 0, 1] = (c * h - b * i) * inv_det
    out[..., 1, 1] = (a * i - c * g) * inv_det
    out[..., 2, 1] = (b * g - a * h) * inv_det
    out[..., 0, 2] = (b * f - c * e) * inv_det
    out[..., 1, 2] = (c * d - a * f) * inv_det
    out[..., 2, 2] = (a * e - b * d) * inv_det
    return out


def _siso_response(modal, s):
    lam, residues, d = modal
    return np.sum(residues / (s[..., None] - lam), axis=-1) + d


class LoopResponse:
    """Closed-loop responses ``d -> e`` of a plant array for any controller, by frequency.

    Parameters
    ----------
    plant : LFR or BatchedStateSpace
        Plant array ``T -> wdot`` (3x3), leading dimension N: a certain LFR model array (what
        other packages pass) or the control package's own state space.
    spec : DesignSpecification
        Weights and components (the same as the interconnection's).

    Notes
    -----
    The test suite checks :meth:`response` against the state-space closed loop
    ``WeightedInterconnection.close(K).freqresp`` (a second, independent method).
    """

    def __init__(self, plant: BatchedStateSpace | LFR, spec: comp.DesignSpecification):
        A, B, C, D = plant.A, plant.B, plant.C, plant.D
        if isinstance(plant, LFR):  # a certain LFR model array (the border type)
            if plant.uncertainty:
                raise ValueError("LoopResponse: the plant still has uncertain blocks")
            if plant.shape != (3, 3):
                raise ValueError(f"LoopResponse: the plant must be 3x3, got {plant.shape}")
            A, B, C, D = (np.array(M, dtype=float) for M in (A, B, C, D))  # contiguous copies
        A = np.asarray(A, dtype=float)
        if A.ndim == 2:
            raise ValueError("LoopResponse: the plant must be an array (leading dimension N)")
        self.A, self.B, self.C, self.D = A, B, C, D
        N, n = A.shape[0], A.shape[-1]
        self.spec = spec
        if n:
            self.lam, V = np.linalg.eig(A)
            Vinv = np.linalg.inv(V)
            cond = np.linalg.norm(V, 1, axis=(-2, -1)) * np.linalg.norm(Vinv, 1, axis=(-2, -1))
            self.exact = ~np.isfinite(cond) | (cond > PLANT_CONDITION_LIMIT)
            CV, VB = self.C @ V, Vinv @ self.B
            self.residues = (CV.transpose(0, 2, 1)[..., :, None] * VB[..., None, :]).reshape(
                N, n, 9
            )
        else:
            self.lam = np.zeros((N, 0), dtype=complex)
            self.residues = np.zeros((N, 0, 9), dtype=complex)
            self.exact = np.zeros(N, dtype=bool)
        self.star_tracker, self.gyro, self.rolloff, self.wheels = map(
            _siso_modal, comp.filters(spec)
        )
        self.hold = _siso_modal(comp.sample_hold(spec))

    @property
    def size(self) -> int:
        """Number of plants."""
        return self.A.shape[0]

    def plant_response(self, omega, index=None) -> np.ndarray:
        """``P_i(j omega)`` (N, F, 3, 3) for ``omega`` (N, F) [rad/s] (models ``index``)."""
        index = np.arange(self.size) if index is None else np.asarray(index)
        omega = np.asarray(omega, dtype=float)
        lam, residues = self.lam[index], self.residues[index]
        resolvent = 1.0 / (1j * omega[..., None] - lam[:, None, :])
        H = (resolvent @ residues).reshape(omega.shape + (3, 3)) + self.D[index][:, None]
        exact = self.exact[index]
        if np.any(exact):
            sub = np.flatnonzero(exact)
            i = index[sub]
            n = self.A.shape[-1]
            M = 1j * omega[sub][..., None, None] * np.eye(n) - self.A[i][:, None]
            X = np.linalg.solve(M, np.broadcast_to(self.B[i][:, None], M.shape[:2] + (n, 3)) + 0j)
            H[sub] = self.C[i][:, None] @ X + self.D[i][:, None]
        return H

    def _terms(self, K, omega, index):
        """The scalar and 3x3 pieces of the module formula at ``omega`` (any shape); ``K`` a
        3x6 gain or a ``ControllerSystem`` (its response ``C(s)``, ``omega.shape + (3, 6)``)."""
        from oos_drake.control.interconnection import ControllerSystem

        spec = self.spec
        omega = np.maximum(np.asarray(omega, dtype=float), OMEGA_MIN)
        s = 1j * omega
        if isinstance(K, ControllerSystem):
            K = K.D if K.is_static else K.continuous().response(s)
        K = np.asarray(K)
        t = {"s": s, "K": K}
        t["P"] = P = self.plant_response(omega, index)
        t["sst"] = _siso_response(self.star_tracker, s)
        t["gyro"] = _siso_response(self.gyro, s)
        t["ro"] = _siso_response(self.rolloff, s)
        t["c"] = c = _siso_response(self.wheels, s) * _siso_response(self.hold, s) * t["ro"]
        Kp, Kd = K[..., :3], K[..., 3:]
        t["Kg"] = Kg = (
            Kp * (t["sst"] / s**2)[..., None, None] + Kd * (t["gyro"] / s)[..., None, None]
        )
        t["S"] = S = _inverse3(np.eye(3) + c[..., None, None] * (Kg @ P))
        t["Q"] = P @ S
        a, b = spec.disturbance_denominator
        t["w_ext"] = np.asarray(spec.disturbance_gains, dtype=float) / (a * s[..., None] + b)
        t["N"] = -np.concatenate(
            [spec.noise_star_tracker * Kp, spec.noise_gyro * Kd], axis=-1
        )  # (..., 3, 6)
        t["to_e_p"] = 1.0 / (spec.pointing_requirement * s**2)
        t["u_gain"] = spec.control_weight * t["ro"]
        return t

    def response(self, K, omega, index=None) -> np.ndarray:
        """Closed-loop ``M_i(j omega)`` (N, F, 6, 9) with the controller ``K``.

        Parameters
        ----------
        K : array_like, shape (3, 6), or ControllerSystem
            ``[K_p, K_d]`` [N m/rad, N m s/rad], or a linear controller ``y -> u_K``.
        omega : array_like, shape (N, F)
            Frequencies [rad/s]; values below :data:`OMEGA_MIN` are evaluated at it.
        index : array_like of int, optional
            Models (default all); ``omega`` has one row per model.
        """
        return self._response(self._terms(K, omega, index))

    @staticmethod
    def _response(t) -> np.ndarray:
        """:meth:`response` from the pieces :meth:`_terms` gave."""
        Q, S, c, w_ext, to_e_p, u_gain = (
            t[k] for k in ("Q", "S", "c", "w_ext", "to_e_p", "u_gain")
        )
        out = np.empty(np.shape(t["s"]) + (6, 9), dtype=complex)
        out[..., :3, :3] = Q * (w_ext * to_e_p[..., None])[..., None, :]
        out[..., :3, 3:] = (Q @ t["N"]) * (c * to_e_p)[..., None, None]
        out[..., 3:, :3] = -(t["Kg"] @ Q) * (u_gain[..., None] * w_ext)[..., None, :]
        out[..., 3:, 3:] = (S @ t["N"]) * u_gain[..., None, None]
        return out

    def loop_gain(self, K, omega, index=None) -> np.ndarray:
        """Loop ``L_i(j omega) = rw ro K_g P`` (N, F, 3, 3) broken at the wheel input ``u``
        (negative feedback: ``u = -L u``; with the hold model when ``spec.sampled``).

        Parameters
        ----------
        K : array_like, shape (3, 6), or ControllerSystem
        omega : array_like, shape (N, F)
            Frequencies [rad/s].
        index : array_like of int, optional
            Models (default all).
        """
        t = self._terms(K, omega, index)
        return t["c"][..., None, None] * (t["Kg"] @ t["P"])

    def gain_sensitivity(self, K, omega, index):
        r"""``(M, G12, G21)`` at one frequency per model: ``dM = G12 dK G21``.

        ``G12`` (k, 6, 3) maps an input added to ``u_K`` to ``e``, ``G21`` (k, 6, 9) maps ``d``
        to ``y``, both in closed loop (Apkarian-Noll's subgradient pieces):

        .. math::

            G_{12} = \begin{bmatrix} rw\,ro\,Q / (W_p s^2) \\ W_u\,ro\,S \end{bmatrix},
            \quad
            G_{21} = \begin{bmatrix} -G Q W_{ext} & (rw\,ro\,G Q K - I) W_n \end{bmatrix},
            \quad G = \begin{bmatrix} sst/s^2\, I \\ gyro/s\, I \end{bmatrix}

        Parameters
        ----------
        K : array_like, shape (3, 6)
        omega : array_like, shape (k,)
            Frequencies [rad/s].
        index : array_like of int, shape (k,)
            Models.
        """
        omega = np.asarray(omega, dtype=float)[:, None]
        t = self._terms(K, omega, index)
        M = self._response(t)[:, 0]
        Q, S = t["Q"][:, 0], t["S"][:, 0]
        s, c, ro = t["s"][:, 0], t["c"][:, 0], t["ro"][:, 0]
        G12 = np.concatenate(
            [
                Q * (c * t["to_e_p"][:, 0])[:, None, None],
                S * (self.spec.control_weight * ro)[:, None, None],
            ],
            axis=1,
        )
        GQ = np.concatenate(
            [Q * (t["sst"][:, 0] / s**2)[:, None, None], Q * (t["gyro"][:, 0] / s)[:, None, None]],
            axis=1,
        )  # (k, 6, 3)
        noise = np.array([self.spec.noise_star_tracker] * 3 + [self.spec.noise_gyro] * 3)
        G21 = np.concatenate(
            [
                -GQ * t["w_ext"][:, 0][:, None, :],
                (c[:, None, None] * (GQ @ t["K"]) - np.eye(6)) * noise,
            ],
            axis=2,
        )
        return M, G12, G21


class LoopSigma:
    """``sigma_max`` of :meth:`LoopResponse.response` at a fixed gain, for the peak search.

    Same interface as :class:`oos_drake.robust.peak_gain.ModalResponse` for ``sigma`` and
    ``take``.
    """

    def __init__(self, loop: LoopResponse, K, index=None):
        self.loop, self.K = loop, np.asarray(K, dtype=float)
        self.index = np.arange(loop.size) if index is None else np.asarray(index)
        self.p, self.m = 6, 9

    def take(self, index) -> LoopSigma:
        """The evaluator restricted to models ``index`` (positions in this evaluator)."""
        return LoopSigma(self.loop, self.K, self.index[index])

    def response(self, omega) -> np.ndarray:
        """Closed-loop response (N, F, 6, 9) at ``omega`` (N, F) [rad/s]."""
        return self.loop.response(self.K, omega, self.index)

    def sigma(self, omega, *, prune: bool = False) -> np.ndarray:
        """Largest singular value (N, F) (``prune``: see ``peak_gain.pruned_sigma``)."""
        from oos_drake.robust.peak_gain import _sigma_max, pruned_sigma

        H = self.response(omega)
        return pruned_sigma(H) if prune else _sigma_max(H)
