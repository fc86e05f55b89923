r"""Multi-model structured tuning of controllers against soft and hard goals (MATLAB systune).

.. math::

    \min_x \; F(x) = \max_{i,\ \text{soft } s} f_s(P_i, K(x)) \quad \text{s.t.} \quad
    G(x) = \max_{i,\ \text{hard } h} g_h(P_i, K(x)) \le 1,

every closed loop ``F_l(P_i, K(x))`` stable, over the models ``P_i`` of the plant array; ``x``
are the parameters of the tunable blocks (:mod:`oos_drake.control.tunable`), the goals
normalized values (:mod:`oos_drake.control.goals`).

Algorithm (Apkarian-Noll nonsmooth descent, the package's optimizer):

1. **Generalized plants.** Per goal, the plants, fixed blocks, summing junctions of the
   injection points and the controller states (integrators, or unit delays at the
   controller rate) are connected by signal name (:func:`~oos_drake.control.statespace.
   connect`); the tunable blocks are pulled out as one block-diagonal static matrix ``K(x)``
   (see :mod:`~oos_drake.control.tunable`). Continuous plants are discretized (zero-order
   hold) when the controller is discrete.
2. **Pieces.** Every goal is a max of smooth pieces with analytic gradients in ``K``: peaks of
   ``sigma_max`` over models and frequencies (weighted gains and margins, Apkarian-Noll
   gradients from the singular vectors, :func:`~oos_drake.control.objective.active_set`; a
   discrete loop's peaks are searched on its bilinear image, an exact frequency map), poles
   (eigenvalue perturbation from left/right eigenvectors) and H2 norms (adjoint Lyapunov
   equations); ``dK/dx`` comes from complex-step differentiation of the realization. No
   finite differences anywhere. Every goal's generalized plant has the same ``A, B2, C2``
   (plants, fixed blocks, controller states; the goals differ in their exogenous channels),
   so the closed-loop eigendecomposition is computed once per evaluation and shared by the
   goals' peak searches and the stability test (``SystuneOptions.shared_modes``; a discrete
   loop's bilinear image ``(A + I)^-1 (A - I)`` keeps the eigenvectors, its eigenvalues are
   ``(lambda - 1)/(lambda + 1)``: no inverse, no second decomposition).
3. **Phases** from each start (the given values and ``restarts`` seeded log-normal
   perturbations): (0) if a closed loop is unstable, minimize the spectral abscissa (of
   ``s = ln(z)/T_s`` for discrete loops) below ``-stability_floor``; (1) if a hard goal
   exceeds 1, minimize ``G`` until ``G <= 1 - hard_margin``; (2) minimize the fixed max
   function

   .. math:: \Phi(x) = \max\big(F(x),\; c + \rho\,(G(x) - 1)\big), \quad c = F(x_0),\;
             \rho = \text{penalty} \cdot c,

   from the feasible ``x_0``: every point with ``Phi <= c`` has ``G <= 1``, so the descent
   stays feasible and, at the end, ``G <= 1 - (c - F)/rho``; the phase is repeated with
   ``c`` updated until ``F`` stops decreasing (the tightening vanishes). Phases 1-2 (and the
   working set's check, step 5) tune every hard goal with the relative surplus
   ``SystuneOptions.hard_surplus``, i.e. to ``<= 1 / (1 + hard_surplus)``, so that it holds
   between the models too; the status tests ``<= 1``. Each phase is BFGS-SQP
   on the nearly active pieces (:func:`~oos_drake.control.nonsmooth_bfgs.minimize_bundle_cycles`:
   metric cycles and kicks, the static-gain synthesis' driver),
   unstable trial points rejected.
4. The best run (feasible first, then lowest ``F``; else lowest ``G``) is re-evaluated
   exactly (certified H-infinity norms, all models) and reported per goal.
5. **Working set** (``SystuneOptions.working_set``, as the static synthesis'
   :func:`~oos_drake.control.synthesis.synthesize`): phases 0-2 run on a few evenly spaced
   models; then every goal is evaluated exactly on every model, and the models outside the
   set that are unstable, miss a hard goal or exceed the set's soft value join it (the worst
   ``models_per_round`` first); phases 0-2 run again from the current parameters (warm
   start), until no model violates or ``max_rounds`` ends. The goals' values reported are
   always over every model, so a hard goal met between the tuned models is never assumed:
   a budget that ends with a violator gives the status ``"infeasible"``.
6. **Verification** (``verify`` models, e.g. between those of the array): every goal is
   evaluated there once at the end (``TuningResult.verified``); a hard goal missed there or
   an unstable loop gives the status ``"infeasible"``.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import control
import numpy as np
import scipy.linalg

from oos_drake.control.goals import Margins, Poles, Variance, WeightedGain
from oos_drake.control.margins import disk_gain_phase
from oos_drake.control.nonsmooth_bfgs import QP_SOLVERS, minimize_bundle_cycles
from oos_drake.control.objective import active_set, peak_gradients
from oos_drake.control.statespace import BatchedStateSpace, connect, sum_block
from oos_drake.control.tunable import FixedBlock, _Tunable
from oos_drake.lfr import LFR
from oos_drake.robust.peak_gain import ModalResponse, eigendecompose, peak_gain

__all__ = ["SystuneOptions", "GoalValue", "TuningResult", "systune"]


@dataclass(frozen=True)
class SystuneOptions:
    """Options of :func:`systune`.

    Attributes
    ----------
    restarts : int
        Random restarts besides the given start values.
    restart_spread : float
        Standard deviation of the log-normal perturbation of a restart [-] (parameters that
        start at zero get an additive one of the block's mean magnitude).
    seed : int
        Seed of the restarts' ``numpy.random.Generator``.
    max_iterations : int
        BFGS-SQP iterations per phase and start.
    metric_cycle : int
        The BFGS metric is reset every ``metric_cycle`` iterations while a cycle improves,
        then two kicks (:func:`~oos_drake.control.nonsmooth_bfgs.minimize_bundle_cycles`).
    active_tolerance : float
        Pieces within this fraction of the maximum enter the local model [-].
    penalty : float
        ``rho / c`` of phase 2 (see the module docstring) [-].
    hard_margin : float
        Phase 1 stops at ``G <= 1 - hard_margin`` [-].
    min_decay : float
        A closed loop counts as stable when every pole has ``Re s < -min_decay`` [1/s]
        (MATLAB's ``MinDecay``; keeps nearly marginal loops, e.g. an integral gain going to
        zero, out of the feasible set).
    stability_floor : float
        Phase 0 drives the spectral abscissa below ``-stability_floor`` [1/s]
        (``> min_decay``).
    feasibility_tolerance : float
        A hard goal counts as met when its exact value is ``<= 1 + feasibility_tolerance``.
    qp : str
        Solver of the bundle step's dual QP: ``"slsqp"`` (default) or ``"active-set"`` (see
        ``SynthesisOptions.qp``).
    shared_modes : bool
        Decompose the closed-loop ``A`` once per evaluation for every goal and the stability
        test (the goals' generalized plants share it; a discrete loop's bilinear images
        keep its eigenvectors). ``False``: each goal decomposes its own (the earlier
        sessions' path, the baseline of ``benchmarks/bench_systune.py``; same values up to
        round-off).
    workers : int
        Threads of that eigendecomposition (LAPACK without the GIL; 2 on the 2-core target).
    working_set : int
        Models in the initial working set the optimizer tunes on (evenly spaced over the
        array, its ends included); ``0`` (default) or at least the
        number of models: all of them. After each tuning every model is checked (every
        goal's exact value) and the violators join the set (the static synthesis' working
        set, :class:`~oos_drake.control.synthesis.SynthesisOptions`), so each goal's reported
        value holds on every model, not only on the tuned ones.
    models_per_round : int
        Largest number of violating models added per round (the worst ones first).
    soft_rtol : float
        Relative excess of a model's soft value over the working set's that makes it a
        violator [-] (``inf``: the working set grows on the hard goals and stability only).
    max_rounds : int
        Largest number of rounds (tuning on the working set + check of every model). When it
        ends with a model violating a hard goal, the result's status is ``"infeasible"``.
    hard_surplus : float
        Relative surplus the tuning keeps on every hard goal [-]: the optimizer and the
        working set's check drive each hard goal to ``<= 1 / (1 + hard_surplus)``, while the
        status and ``GoalValue.met`` still test ``<= 1``. A goal tuned exactly to its bound
        on the checked models dips above it between them (a continuous family of plants,
        e.g. mission configurations); the surplus keeps it met there. Default ``1e-3``
        (0.006 dB on a 6 dB disk gain margin), about 10 times the dip measured on the paper's
        margins design tuned to its bound: 6.0000 dB on its 200 configurations, 5.9994 dB
        between them, ``9.2e-5`` in the normalized value. A family that varies faster between
        its models needs more (the two-mass family of
        ``tests/control/test_systune_surplus.py``, spring 3 -> 0.3 N/m over 8 of its 16
        intervals, dips by about 2 % and is tuned with ``2e-2``); ``systune``'s ``verify``
        models show whether it sufficed. ``0``: tuned to the bound (the earlier behaviour).
    """

    restarts: int = 0
    restart_spread: float = 0.5
    seed: int = 0
    max_iterations: int = 300
    metric_cycle: int = 50
    active_tolerance: float = 0.1
    penalty: float = 20.0
    hard_margin: float = 0.01
    min_decay: float = 1e-7
    stability_floor: float = 1e-4
    feasibility_tolerance: float = 1e-6
    qp: str = "slsqp"
    shared_modes: bool = True
    workers: int = 1
    working_set: int = 0
    models_per_round: int = 5
    soft_rtol: float = 1e-3
    max_rounds: int = 12
    hard_surplus: float = 1e-3


@dataclass(frozen=True)
class GoalValue:
    """A goal's achieved value in the tuned loop (exact re-evaluation over all models).

    Attributes
    ----------
    name : str
        The goal's label.
    kind : str
        ``"soft"`` or ``"hard"``.
    value : float
        Normalized value (``<= 1``: met), max over models (and channels).
    per_model : numpy.ndarray
        Normalized value per model.
    details : Mapping[str, float]
        Physical values: ``hinf_norm`` (weighted gain), ``disk_margin``, ``gain_margin_db``,
        ``phase_margin_deg`` (worst channel and model, implied by the disk margin),
        ``min_damping``, ``max_frequency_rad_s`` (poles), ``h2_norm`` (variance).
    """

    name: str
    kind: str
    value: float
    per_model: np.ndarray
    details: Mapping[str, float]

    @property
    def met(self) -> bool:
        return bool(self.value <= 1.0)


@dataclass(frozen=True)
class TuningResult:
    """Outcome of :func:`systune`.

    Attributes
    ----------
    parameters : Mapping[str, Mapping[str, numpy.ndarray]]
        Per tunable block, its named physical values (``TunablePID``: ``kp``, ``ki``, ``kd``,
        ``tf``...; ``TunableGain``: ``D``; ``TunableSS``: ``A, B, C, D, poles``).
    x : numpy.ndarray
        The raw parameter vector (blocks in order).
    controller : control.StateSpace
        The whole controller (tunable and fixed blocks) from the signals it reads to the
        signals it drives, at ``sampling_time``.
    blocks : Mapping[str, control.StateSpace]
        Each tunable block at its tuned value.
    goals : tuple of GoalValue
        Each goal's exact value.
    soft : float
        Max of the soft goals' values (``0`` when there are none).
    hard : float
        Max of the hard goals' values (``0`` when there are none).
    status : str
        ``"ok"`` (stable and every hard goal met) or ``"infeasible"`` (the best values reached
        are reported; the hard goals above 1 are not met).
    sampling_time : float
        Controller rate [s] (``0``: continuous).
    runs : tuple of dict
        Per round and start: ``round``, ``start``, ``models`` (in the working set), ``soft``,
        ``hard`` (over the working set), ``stable``, ``iterations``, ``message``.
    working_set : tuple of int
        The models the optimizer tuned on at the end (indices into the plant array; all of
        them without a working set). The goals' values are over every model.
    rounds : tuple of dict
        Per round: ``round``, ``models`` (in the working set), ``soft``, ``hard`` (exact, over
        every model), ``violators`` (models outside the set violating a goal), ``added``.
    verified : tuple of GoalValue
        Each goal's exact value over :func:`systune`'s ``verify`` models (empty without them):
        models between those of the array, checked after the tuning only. A hard goal above
        1 there (or an unstable loop) makes the status ``"infeasible"``.
    """

    parameters: Mapping[str, Mapping[str, np.ndarray]]
    x: np.ndarray
    controller: control.StateSpace
    blocks: Mapping[str, control.StateSpace]
    goals: tuple[GoalValue, ...]
    soft: float
    hard: float
    status: str
    sampling_time: float
    runs: tuple[dict, ...]
    working_set: tuple[int, ...] = ()
    rounds: tuple[dict, ...] = ()
    verified: tuple[GoalValue, ...] = ()

    @property
    def models_checked(self) -> int:
        """Number of models every goal was evaluated on (the whole plant array)."""
        return int(self.goals[0].per_model.size) if self.goals else 0

    @property
    def models_verified(self) -> int:
        """Number of models the goals hold on as reported: the plant array's and
        :func:`systune`'s ``verify`` models (never tuned on, never added to the working set)."""
        return self.models_checked + (int(self.verified[0].per_model.size) if self.verified else 0)

    def verified_value(self, name: str) -> float:
        """Goal ``name``'s largest value over the plant array and the ``verify`` models."""
        values = [g.value for g in self.goals + self.verified if g.name == name]
        if not values:
            raise KeyError(f"no goal named {name!r}; goals: {[g.name for g in self.goals]}")
        return max(values)

    def goal(self, name: str) -> GoalValue:
        """The :class:`GoalValue` labelled ``name``."""
        for g in self.goals:
            if g.name == name:
                return g
        raise KeyError(f"no goal named {name!r}; goals: {[g.name for g in self.goals]}")


# --------------------------------------------------------------------------- closed loops


@dataclass(frozen=True)
class _ClosedLoop:
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray


@dataclass(frozen=True)
class _Loop:
    """Generalized plant of one goal term, batched over models: ``[z; y] = P [w; u]``,
    ``D22 = 0``; the interface :func:`~oos_drake.control.objective.active_set` reads."""

    A: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    C1: np.ndarray
    C2: np.ndarray
    D11: np.ndarray
    D12: np.ndarray
    D21: np.ndarray
    sampling_time: float

    loop = None  # no modal fast path: objective falls back to LU solves

    def partitions(self):
        return self.A, self.B1, self.B2, self.C1, self.C2, self.D11, self.D12, self.D21

    def closed(self, K) -> _ClosedLoop:
        """``F_l(P, K)`` in the loop's own time domain."""
        B2K, D12K = self.B2 @ K, self.D12 @ K
        return _ClosedLoop(
            self.A + B2K @ self.C2,
            self.B1 + B2K @ self.D21,
            self.C1 + D12K @ self.C2,
            self.D11 + D12K @ self.D21,
        )

    def close(self, K, image=None) -> _ClosedLoop:
        """The closed loop as a continuous model with the same H-infinity norm (for a discrete
        loop its bilinear image ``z = (1 + s)/(1 - s)``, frequency ``w_c = tan(w T_s / 2)``).

        ``image``: ``(F, F (A_cl - I))`` with ``F = (A_cl + I)^-1`` when already computed
        (loops sharing ``A, B2, C2``: :meth:`_ClosedModes.image`)."""
        M = self.closed(K)
        if self.sampling_time == 0:
            return M
        if image is None:
            image = _bilinear(M.A)
        F, A = image
        return _ClosedLoop(A, np.sqrt(2) * F @ M.B, np.sqrt(2) * M.C @ F, M.D - M.C @ F @ M.B)

    def points(self, omega):
        """Evaluation points of :meth:`close`'s frequencies in the loop's own domain."""
        omega = np.asarray(omega, dtype=float)
        return 1j * omega if self.sampling_time == 0 else (1 + 1j * omega) / (1 - 1j * omega)

    def physical_frequency(self, omega):
        """:meth:`close`'s frequency -> the loop's frequency [rad/s]."""
        omega = np.asarray(omega, dtype=float)
        if self.sampling_time == 0:
            return omega
        return 2 * np.arctan(omega) / self.sampling_time

    def select(self, rows, cols) -> _Loop:
        """The term from the exogenous inputs ``cols`` to the exogenous outputs ``rows``."""
        rows, cols = np.asarray(rows), np.asarray(cols)
        return replace(
            self,
            B1=self.B1[..., :, cols],
            C1=self.C1[..., rows, :],
            D11=self.D11[..., rows[:, None], cols],
            D12=self.D12[..., rows, :],
            D21=self.D21[..., :, cols],
        )

    def weighted(self, left, right) -> _Loop:
        """``W_L T W_R`` with static weights (matrices)."""
        return replace(
            self,
            B1=self.B1 @ right,
            C1=left @ self.C1,
            D11=left @ self.D11 @ right,
            D12=left @ self.D12,
            D21=self.D21 @ right,
        )


def _bilinear(A_cl):
    """``(F, F (A_cl - I))``, ``F = (A_cl + I)^-1``: the pieces of a discrete loop's bilinear
    image (:meth:`_Loop.close`)."""
    eye = np.eye(A_cl.shape[-1])
    F = np.linalg.inv(A_cl + eye)
    return F, F @ (A_cl - eye)


def _poles_s(A_cl, sampling_time):
    """Closed-loop eigenvalues and eigenvectors (right ``V``, left rows ``W = V^-1``) and the
    equivalent continuous poles ``s`` (``ln(z)/T_s`` for a discrete loop)."""
    lam, V = np.linalg.eig(A_cl)
    W = np.linalg.inv(V)
    if sampling_time == 0:
        return lam, V, W, lam, np.ones_like(lam)
    s = np.log(lam.astype(complex)) / sampling_time
    return lam, V, W, s, 1.0 / (lam * sampling_time)  # ds/dlam


# --------------------------------------------------------------------------- goal terms


class _ClosedModes:
    """The eigendecomposition ``(lambda, V, V^-1)`` of the closed-loop ``A`` of the goals'
    loops at the last ``K`` asked (every goal's generalized plant has the same ``A, B2, C2``:
    the plants, fixed blocks and controller states; the goals differ in their exogenous
    channels): one decomposition per evaluation, shared by the goals and the stability test."""

    def __init__(self, loop: _Loop, workers: int = 1):
        self.loop, self.workers = loop, workers
        self._key, self._value, self._image = None, None, None

    def shares(self, loop: _Loop) -> bool:
        """Whether ``loop`` has this ``A, B2, C2`` and sampling time."""
        mine = self.loop
        return loop.sampling_time == mine.sampling_time and all(
            np.array_equal(a, b)
            for a, b in ((loop.A, mine.A), (loop.B2, mine.B2), (loop.C2, mine.C2))
        )

    def __call__(self, K):
        """``(lambda, V, V^-1)`` at ``K``, or None when ``V`` is singular."""
        key = np.asarray(K, dtype=float).tobytes()
        if key != self._key:
            A_cl = self.loop.closed(K).A  # the same expression as every term's closed loop
            try:
                value = eigendecompose(A_cl, self.workers)
            except np.linalg.LinAlgError:  # defective: each term decomposes its own
                value = None
            self._key, self._value, self._image = key, value, None
        return self._value

    def image(self, K):
        """:func:`_bilinear` of the closed-loop ``A`` at ``K`` (a discrete loop; computed once
        per ``K`` for every goal)."""
        self(K)
        if self._image is None:
            self._image = _bilinear(self.loop.closed(K).A)
        return self._image


class _HinfTerm:
    """``scale * ||F_l(P, K)||_inf`` over the models of one loop (``modes``: the shared
    closed-loop eigendecomposition when the loop has its ``A``)."""

    def __init__(self, loop: _Loop, scale: float = 1.0, modes: _ClosedModes | None = None):
        self.loop, self.scale = loop, float(scale)
        self.points = None if loop.sampling_time == 0 else loop.points
        self.modes = modes if modes is not None and modes.shares(loop) else None

    def _eigen(self, K):
        """The shared decomposition for :meth:`_Loop.close`'s ``A``: a discrete loop's
        bilinear image ``(A + I)^-1 (A - I)`` has the eigenvectors of ``A`` and the
        eigenvalues ``(lambda - 1) / (lambda + 1)``."""
        eigen = None if self.modes is None else self.modes(K)
        if eigen is None or self.loop.sampling_time == 0:
            return eigen
        lam, V, W = eigen
        return (lam - 1.0) / (lam + 1.0), V, W

    def _close(self, K) -> _ClosedLoop:
        """:meth:`_Loop.close`, the bilinear image's inverse shared by the goals."""
        if self.modes is None or self.loop.sampling_time == 0:
            return self.loop.close(K)
        return self.loop.close(K, self.modes.image(K))

    def pieces(self, K, eps):
        eigen = self._eigen(K)
        a = active_set(
            self.loop, K, eps=eps, points=self.points, eigen=eigen, closed=self._close(K)
        )
        if not np.isfinite(a.gamma):
            return None
        which = a.which if a.which is not None else np.zeros(a.values.size, int)
        return self.scale * a.values, self.scale * a.gradients, a.models, a.omegas, which

    def regrad(self, K, models, omegas, which, lam):
        values, grads = peak_gradients(self.loop, K, models, omegas, which, points=self.points)
        return self.scale * values, self.scale * grads

    def exact(self, K):
        """``(scale * norm per model, peak frequency per model [rad/s])``, certified."""
        M = self._close(K)
        eigen = self._eigen(K)
        modal = None if eigen is None else ModalResponse(M.A, M.B, M.C, M.D, eigen=eigen)
        peaks = peak_gain(M.A, M.B, M.C, M.D, certify=True, modal=modal)
        return self.scale * peaks.gamma, self.loop.physical_frequency(peaks.omega)


class _H2Term:
    """``||F_l(P, K)||_2 / max_std`` per model, gradient from adjoint Lyapunov equations."""

    def __init__(self, loop: _Loop, max_std: float):
        self.loop, self.scale = loop, 1.0 / max_std

    def _model(self, K, i):
        L = self.loop
        A, B1, B2, C1, C2, D11, D12, D21 = (M[i] for M in L.partitions())
        Ac, Bc = A + B2 @ K @ C2, B1 + B2 @ K @ D21
        Cc, Dc = C1 + D12 @ K @ C2, D11 + D12 @ K @ D21
        if L.sampling_time == 0:
            if np.max(np.linalg.eigvals(Ac).real) >= 0 or np.any(np.abs(Dc) > 1e-12):
                return np.inf, np.zeros_like(K)
            X = scipy.linalg.solve_continuous_lyapunov(Ac, -Bc @ Bc.T)
            Y = scipy.linalg.solve_continuous_lyapunov(Ac.T, -Cc.T @ Cc)
            f = float(np.trace(Cc @ X @ Cc.T))
            g = 2 * (B2.T @ Y @ X @ C2.T + B2.T @ Y @ Bc @ D21.T + D12.T @ Cc @ X @ C2.T)
        else:
            if np.max(np.abs(np.linalg.eigvals(Ac))) >= 1:
                return np.inf, np.zeros_like(K)
            X = scipy.linalg.solve_discrete_lyapunov(Ac, Bc @ Bc.T)
            Y = scipy.linalg.solve_discrete_lyapunov(Ac.T, Cc.T @ Cc)
            f = float(np.trace(Cc @ X @ Cc.T + Dc @ Dc.T))
            g = 2 * (
                B2.T @ Y @ Ac @ X @ C2.T
                + B2.T @ Y @ Bc @ D21.T
                + D12.T @ Cc @ X @ C2.T
                + D12.T @ Dc @ D21.T
            )
        norm = np.sqrt(max(f, 0.0))
        return self.scale * norm, self.scale * g / (2 * max(norm, 1e-300))

    def values(self, K, models=None):
        models = range(self.loop.A.shape[0]) if models is None else models
        out = [self._model(K, int(i)) for i in models]
        return np.array([v for v, _ in out]), np.array([g for _, g in out])

    def pieces(self, K, eps):
        v, g = self.values(K)
        if not np.all(np.isfinite(v)):
            return None
        keep = np.flatnonzero(v >= v.max() - eps * abs(v.max()))
        keep = keep[np.argsort(-v[keep])]
        zeros = np.zeros(keep.size)
        return v[keep], g[keep], keep, zeros, zeros.astype(int)

    def regrad(self, K, models, omegas, which, lam):
        return self.values(K, models)

    def exact(self, K):
        return self.values(K)[0], np.full(self.loop.A.shape[0], np.nan)


class _PoleTerm:
    """Closed-loop pole goal (``Poles``) or, with ``goal=None``, the spectral abscissa
    ``max Re s`` [1/s] (stabilization)."""

    def __init__(self, loop: _Loop, goal: Poles | None, min_decay: float = 0.0):
        self.loop, self.goal, self.min_decay = loop, goal, min_decay

    def _value(self, s):
        """Value per pole and its partial derivatives w.r.t. ``Re s`` and ``Im s``."""
        sr, si = s.real, s.imag
        if self.goal is None:
            return sr, np.ones_like(sr), np.zeros_like(sr)
        r = np.maximum(np.abs(s), 1e-12)
        zeta_min, wmax = self.goal.min_damping, self.goal.max_frequency
        zeta = -sr / r
        v_damp = (1 - zeta) / (1 - zeta_min)
        dz_r, dz_i = -(si**2) / r**3, sr * si / r**3
        vd_r, vd_i = -dz_r / (1 - zeta_min), -dz_i / (1 - zeta_min)
        if np.isfinite(wmax):
            v_freq = r / wmax
            damp = v_damp >= v_freq
            return (
                np.where(damp, v_damp, v_freq),
                np.where(damp, vd_r, sr / (r * wmax)),
                np.where(damp, vd_i, si / (r * wmax)),
            )
        return v_damp, vd_r, vd_i

    def _all(self, K):
        A, _, B2, _, C2, *_ = self.loop.partitions()
        lam, V, W, s, ds = _poles_s(A + B2 @ K @ C2, self.loop.sampling_time)
        return lam, V, W, s, ds, B2, C2

    def _gradient(self, V, W, ds, B2, C2, i, k, h_r, h_i):
        # d lam = w_k B2 dK C2 v_k  (w_k row of V^-1): d h = Re((h_r - j h_i) ds d lam)
        G = np.outer(B2[i].T @ W[i, k, :], C2[i] @ V[i, :, k])
        return np.real((h_r - 1j * h_i) * ds[i, k] * G)

    def pieces(self, K, eps):
        lam, V, W, s, ds, B2, C2 = self._all(K)
        v, h_r, h_i = self._value(s)
        top = v.max()
        tol = eps * max(abs(top), 1.0 if self.goal is not None else 1e-3)
        models, poles = np.nonzero(v >= top - tol)
        order = np.argsort(-v[models, poles])[:24]
        models, poles = models[order], poles[order]
        grads = np.array(
            [
                self._gradient(V, W, ds, B2, C2, i, k, h_r[i, k], h_i[i, k])
                for i, k in zip(models, poles, strict=True)
            ]
        )
        zeros = np.zeros(models.size)
        return v[models, poles], grads, models, zeros, zeros.astype(int), lam[models, poles]

    def regrad(self, K, models, omegas, which, lam_old):
        lam, V, W, s, ds, B2, C2 = self._all(K)
        v, h_r, h_i = self._value(s)
        values, grads = [], []
        for i, l0 in zip(models, lam_old, strict=True):
            k = int(np.argmin(np.abs(lam[i] - l0)))  # the same pole, followed
            values.append(v[i, k])
            grads.append(self._gradient(V, W, ds, B2, C2, i, k, h_r[i, k], h_i[i, k]))
        return np.array(values), np.array(grads)

    def exact(self, K):
        _, _, _, s, *_ = self._all(K)
        return self._value(s)[0].max(axis=-1), np.full(s.shape[0], np.nan)

    def stable(self, K, modes: _ClosedModes | None = None) -> np.ndarray:
        """Per model: every closed-loop pole decays faster than ``min_decay`` [1/s]
        (``|z| < exp(-min_decay T_s)`` for a discrete loop); ``modes``: the shared
        eigendecomposition of this loop, when the goals use it."""
        eigen = None if modes is None else modes(K)
        if eigen is not None:
            lam = eigen[0]
        else:
            A, _, B2, _, C2, *_ = self.loop.partitions()
            lam = np.linalg.eigvals(A + B2 @ K @ C2)
        ts = self.loop.sampling_time
        if ts == 0:
            return np.max(lam.real, axis=-1) < -self.min_decay
        return np.max(np.abs(lam), axis=-1) < np.exp(-self.min_decay * ts)


# --------------------------------------------------------------------------- problem assembly


def _as_batched(plant, sampling_time: float) -> list[BatchedStateSpace]:
    """The plants as model arrays of equal order, discretized (ZOH) for a discrete controller."""
    if isinstance(plant, LFR):
        if not plant.is_certain:
            names = ", ".join(plant.occurrences)
            raise ValueError(f"systune: the LFR plant still has uncertain blocks ({names})")
        if None in (plant.input_names or (None,)) or None in (plant.output_names or (None,)):
            raise ValueError("systune: the LFR plant needs input and output names")
        A = plant.A if plant.batch_shape else plant.A[None]
        B, C, D = ((M if plant.batch_shape else M[None]) for M in (plant.Bu, plant.Cy, plant.Dyu))
        A, B, C, D = (M.reshape((-1,) + M.shape[-2:]) for M in (A, B, C, D))
        plant = BatchedStateSpace(A, B, C, D, tuple(plant.input_names), tuple(plant.output_names))
    if isinstance(plant, BatchedStateSpace):
        A, B, C, D = (np.asarray(M, dtype=float) for M in (plant.A, plant.B, plant.C, plant.D))
        if A.ndim == 2:
            A, B, C, D = (M[None] for M in (A, B, C, D))
        A, B, C, D = (M.reshape((-1,) + M.shape[-2:]) for M in (A, B, C, D))
        if sampling_time > 0:
            A, B = _zoh(A, B, sampling_time)
        return [BatchedStateSpace(A, B, C, D, plant.inputs, plant.outputs)]
    models = list(plant) if isinstance(plant, Sequence) else [plant]
    if not models:
        raise ValueError("systune: no plant given")
    groups: dict[int, list] = {}
    labels = None
    for k, sys in enumerate(models):
        if not isinstance(sys, control.StateSpace):
            raise ValueError(
                f"systune: plant {k} is a {type(sys).__name__}, expected a control.StateSpace, "
                "a BatchedStateSpace or a certain LFR"
            )
        these = (tuple(sys.input_labels), tuple(sys.output_labels))
        if labels is None:
            labels = these
        elif these != labels:
            raise ValueError(f"systune: plant {k} has other signal names than plant 0")
        if sys.dt and sys.dt != sampling_time:
            raise ValueError(
                f"systune: plant {k} has sampling time {sys.dt} s, the controller {sampling_time} s"
            )
        groups.setdefault(sys.nstates, []).append(sys)
    out = []
    for group in groups.values():
        A, B, C, D = (np.stack([getattr(s, m) for s in group]) for m in "ABCD")
        if sampling_time > 0 and not group[0].dt:
            A, B = _zoh(A, B, sampling_time)
        out.append(BatchedStateSpace(A, B, C, D, *labels))
    return out


def _zoh(A, B, sampling_time):
    """Zero-order-hold discretization of batched ``(A, B)``."""
    n, m = A.shape[-1], B.shape[-1]
    Ad, Bd = np.empty_like(A), np.empty_like(B)
    for i in range(A.shape[0]):
        M = np.zeros((n + m, n + m))
        M[:n, :n], M[:n, n:] = A[i], B[i]
        E = scipy.linalg.expm(M * sampling_time)
        Ad[i], Bd[i] = E[:n, :n], E[:n, n:]
    return Ad, Bd


def _matches(name: str, labels) -> list[str]:
    """Channels named ``name`` or ``name[i]``."""
    pattern = re.compile(re.escape(name) + r"\[\d+\]$")
    return [lab for lab in labels if lab == name or pattern.match(lab)]


class _Structure:
    """The tunable blocks as the block-diagonal ``K(x)`` and its Jacobian."""

    def __init__(self, tunables: list[_Tunable]):
        self.tunables = tunables
        sizes = [t.nparameters for t in tunables]
        self.slices = [slice(a, a + s) for a, s in zip(np.cumsum([0, *sizes]), sizes, strict=False)]
        self.nx = int(sum(sizes))
        self.shapes = [(t.nstates + len(t.outputs), t.nstates + len(t.inputs)) for t in tunables]
        self.shape = tuple(int(sum(s[k] for s in self.shapes)) for k in (0, 1))

    def initial(self) -> np.ndarray:
        return np.concatenate([t.initial_parameters() for t in self.tunables])

    def K(self, x) -> np.ndarray:
        K = np.zeros(self.shape)
        r = c = 0
        for t, sl, (p, m) in zip(self.tunables, self.slices, self.shapes, strict=True):
            K[r : r + p, c : c + m] = np.real(t.matrix(x[sl]))
            r, c = r + p, c + m
        return K

    def chain(self, x, grad_K) -> np.ndarray:
        """``dF/dx`` from ``dF/dK`` (..., rows, cols)."""
        out = np.zeros(grad_K.shape[:-2] + (self.nx,))
        r = c = 0
        for t, sl, (p, m) in zip(self.tunables, self.slices, self.shapes, strict=True):
            J = t.jacobian(x[sl])  # (p, m, k)
            out[..., sl] = np.einsum("...ij,ijk->...k", grad_K[..., r : r + p, c : c + m], J)
            r, c = r + p, c + m
        return out

    @property
    def linear(self) -> np.ndarray:
        """Gain-like parameters (each block's ``linear_parameters``)."""
        return np.concatenate([t.linear_parameters for t in self.tunables])

    def scale(self, x0) -> np.ndarray:
        """Per-parameter scale of the optimization variables: a gain's own magnitude, ``1``
        for logarithms and pole coordinates.

        A gain that starts at zero gets the mean magnitude of its *family* (``kp[0..2]``,
        ``B[...]``: the same name before the index, same unit), else of its block's nonzero
        gains. Each gain keeps its own magnitude however small: a PID's ``ki`` (1e-3) beside
        its ``kd`` (1e2) in one block-wide scale takes steps 1e5 times its size, and the
        line search ends at the first stability boundary (the integrator pole).
        """
        out = np.ones(self.nx)
        for t, sl in zip(self.tunables, self.slices, strict=True):
            x, linear = np.abs(x0[sl]), t.linear_parameters
            families = np.array([n.split("[", 1)[0] for n in t.parameter_names])
            typical = np.mean(x[linear & (x > 0)]) if np.any(linear & (x > 0)) else 1.0
            own = np.ones_like(x)
            nonzero = linear & (x > 1e-9 * typical)
            for i in np.flatnonzero(linear):
                same = nonzero & (families == families[i])
                own[i] = x[i] if nonzero[i] else (np.mean(x[same]) if np.any(same) else typical)
            out[sl] = own
        return out


class _Problem:
    """Signals, blocks and generalized plants of one systune call."""

    def __init__(self, plants, blocks, min_decay: float = 0.0, shared_modes=True, workers=1):
        blocks = list(blocks) if isinstance(blocks, Sequence) else [blocks]
        self.tunables = [b for b in blocks if isinstance(b, _Tunable)]
        self.fixed = [b for b in blocks if isinstance(b, FixedBlock)]
        for b in blocks:
            if not isinstance(b, _Tunable | FixedBlock):
                raise ValueError(
                    f"systune: unknown controller structure {type(b).__name__}; use TunableGain,"
                    " TunablePID, TunableSS or FixedBlock"
                )
        if not self.tunables:
            raise ValueError("systune: the controller has no tunable block")
        names = [b.name for b in blocks]
        if len(set(names)) != len(names):
            raise ValueError(f"systune: block names must be unique, got {names}")
        rates = {t.sampling_time for t in self.tunables if t.nstates or t.sampling_time}
        if len(rates) > 1:
            raise ValueError(f"systune: tunable blocks at different rates {sorted(rates)} s")
        self.sampling_time = rates.pop() if rates else 0.0
        groups = _as_batched(plants, self.sampling_time)
        if len(groups) > 1:
            orders = sorted(g.A.shape[-1] for g in groups)
            raise ValueError(
                f"systune: plants of different orders {orders} are not supported (the models "
                "are batched); reduce or pad them to one order"
            )
        self.plant = plant = groups[0]
        self.structure = _Structure(self.tunables)
        self.fixed_systems = []
        for b in self.fixed:
            A, B, C, D = b.realization(self.sampling_time)
            self.fixed_systems.append(BatchedStateSpace(A, B, C, D, b.inputs, b.outputs))
        produced = list(plant.outputs) + [s for f in self.fixed for s in f.outputs]
        produced += [s for t in self.tunables for s in t.outputs]
        if len(set(produced)) != len(produced):
            twice = sorted({s for s in produced if produced.count(s) > 1})
            raise ValueError(f"systune: signals {twice} are produced by two blocks")
        self.produced = set(produced)
        consumed = list(plant.inputs) + [s for f in self.fixed for s in f.inputs]
        self.free = [s for s in dict.fromkeys(consumed) if s not in self.produced]
        self.signals = list(dict.fromkeys(produced + consumed))
        for t in self.tunables:
            for s in t.inputs:
                if s not in self.produced and s not in self.free:
                    raise ValueError(
                        f"systune: block {t.name!r} reads signal {s!r}, which no plant or "
                        "block produces"
                    )
        # controller-side channel names: [x_k; y] -> [xdot_k; u] per block
        self.states = [tuple(f"{t.name}.x[{i}]" for i in range(t.nstates)) for t in self.tunables]
        self.loop = self.loops((), ())
        self.stability = _PoleTerm(self.loop, None, min_decay)
        self.modes = _ClosedModes(self.loop, workers) if shared_modes else None

    @property
    def size(self) -> int:
        """Number of models."""
        return int(self.plant.A.shape[0])

    def subset(self, index) -> _Problem:
        """The same problem over the models ``index`` only (a working set)."""
        index = np.asarray(index, dtype=int)
        sub = copy.copy(self)
        p = self.plant
        sub.plant = replace(p, A=p.A[index], B=p.B[index], C=p.C[index], D=p.D[index])
        sub.loop = sub.loops((), ())
        sub.stability = _PoleTerm(sub.loop, None, self.stability.min_decay)
        if self.modes is not None:
            sub.modes = _ClosedModes(sub.loop, self.modes.workers)
        return sub

    def stable(self, K) -> np.ndarray:
        """Per model: the closed loop at ``K`` is stable (see :meth:`_PoleTerm.stable`)."""
        return self.stability.stable(K, self.modes)

    def resolve(self, names, label: str) -> list[str]:
        out = []
        for name in names:
            found = _matches(name, self.signals)
            if not found:
                known = ", ".join(self.signals[:12]) + (", ..." if len(self.signals) > 12 else "")
                raise ValueError(
                    f"goal {label!r}: signal {name!r} does not exist (signals: {known})"
                )
            out += found
        return out

    def loops(self, inputs, outputs, half: bool = False) -> _Loop:
        """Generalized plant (batched over the models) from the signals ``inputs`` (injected
        where produced) to ``outputs``; ``half`` subtracts ``I/2`` from ``D11`` (``S - I/2``
        of a loop opening)."""
        return self._generalized(self.plant, inputs, outputs, half)

    def _generalized(self, plant, inputs, outputs, half) -> _Loop:
        inject = [s for s in inputs if s in self.produced]
        renamed = {s: s + "~" for s in inject}

        def rename(sys):
            return replace(sys, outputs=tuple(renamed.get(s, s) for s in sys.outputs))

        parts = [rename(plant)] + [rename(f) for f in self.fixed_systems]
        for names in self.states:
            if names:
                n = len(names)
                parts.append(
                    BatchedStateSpace(
                        np.zeros((n, n)),
                        np.eye(n),
                        np.eye(n),
                        np.zeros((n, n)),
                        tuple(s + "'" for s in names),
                        names,
                    )
                )
        parts += [sum_block((s,), [(s + "~",), ("d:" + s,)], [1.0, 1.0]) for s in inject]
        exo_in = ["d:" + s if s in renamed else s for s in inputs]
        rest = [s for s in self.free if s not in inputs]
        u_aug, y_aug = [], []
        for t, names in zip(self.tunables, self.states, strict=True):
            u_aug += [s + "'" for s in names] + [renamed.get(s, s) for s in t.outputs]
            y_aug += list(names) + list(t.inputs)
        sys = connect(parts, exo_in + rest + u_aug, list(outputs) + y_aug)
        k, q, nu = len(inputs), len(outputs), len(u_aug)
        A, B, C, D = sys.A, sys.B, sys.C, sys.D
        if A.ndim == 2:
            A, B, C, D = (M[None] for M in (A, B, C, D))
        N = plant.A.shape[0] if plant.A.ndim == 3 else 1
        A, B, C, D = (np.broadcast_to(M, (N,) + M.shape[-2:]) for M in (A, B, C, D))
        D22 = D[..., q:, -nu:]
        if np.any(D22 != 0):
            raise ValueError(
                "systune: the loop through the tunable blocks has a direct feedthrough "
                "(a tunable block feeds another, or a plant/fixed block is not strictly proper)"
            )
        D11 = D[..., :q, :k].copy()
        if half:
            D11 = D11 - 0.5 * np.eye(q)
        return _Loop(
            A,
            B[..., :k],
            B[..., -nu:],
            C[..., :q, :],
            C[..., q:, :],
            D11,
            D[..., :q, -nu:],
            D[..., q:, :k],
            self.sampling_time,
        )

    def terms(self, goal, index: int):
        """The goal's terms (each a max over models) as ``(term, goal index, channel label)``."""
        if isinstance(goal, WeightedGain):
            inputs = self.resolve(goal.inputs, goal.label)
            outputs = self.resolve(goal.outputs, goal.label)
            loop = self.loops(inputs, outputs)
            left = _weight(goal.left_weight, len(outputs), goal.label, "left_weight")
            right = _weight(goal.right_weight, len(inputs), goal.label, "right_weight")
            return [(_HinfTerm(loop.weighted(left, right), modes=self.modes), index, "")]
        if isinstance(goal, Margins):
            channels = self.resolve(goal.loop_opening, goal.label)
            loop = self.loops(channels, channels, half=True)
            if goal.multiloop or len(channels) == 1:
                return [(_HinfTerm(loop, goal.alpha, self.modes), index, ",".join(channels))]
            return [
                (_HinfTerm(loop.select([i], [i]), goal.alpha, self.modes), index, c)
                for i, c in enumerate(channels)
            ]
        if isinstance(goal, Poles):
            return [(_PoleTerm(self.loop, goal), index, "")]
        if isinstance(goal, Variance):
            inputs = self.resolve(goal.inputs, goal.label)
            outputs = self.resolve(goal.outputs, goal.label)
            loop = self.loops(inputs, outputs)
            feedthrough = np.any(loop.D11 != 0) or (np.any(loop.D12 != 0) and np.any(loop.D21 != 0))
            if self.sampling_time == 0 and feedthrough:
                raise ValueError(
                    f"goal {goal.label!r}: the closed loop has a direct feedthrough from the "
                    "noise to the outputs (infinite H2 norm in continuous time)"
                )
            return [(_H2Term(loop, goal.max_std), index, "")]
        raise ValueError(f"systune: unknown goal type {type(goal).__name__}")


def _weight(w, size: int, label: str, which: str) -> np.ndarray:
    w = np.asarray(w, dtype=float)
    if w.ndim == 0:
        return float(w) * np.eye(size)
    if w.ndim == 1 and w.size == size:
        return np.diag(w)
    if w.shape == (size, size):
        return w
    raise ValueError(f"goal {label!r}: {which} must be a scalar, {size} values or {size}x{size}")


# --------------------------------------------------------------------------- objective


class _Objective:
    """``max_t (a_t * term_t + b_t)`` over terms, in scaled variables ``xi = x / scale``
    (the interface of :func:`minimize_bundle_bfgs`)."""

    #: Largest number of pieces in the local model (as :func:`active_set`'s cap).
    max_pieces = 24

    def __init__(self, problem: _Problem, terms, affine, scale, eps, floor=None):
        self.problem, self.terms, self.affine = problem, terms, affine
        self.scale, self.eps, self.floor = scale, eps, floor

    def x(self, xi):
        return xi * self.scale

    def __call__(self, xi):
        x = self.x(xi)
        with np.errstate(over="ignore", invalid="ignore"):
            K = self.problem.structure.K(x)
        nx = x.size
        if not np.all(np.isfinite(K)):  # a trial step overflowed a log-parameter
            return np.inf, np.array([np.inf]), np.zeros((1, nx)), _empty_pieces(1)
        need_stable = any(not isinstance(t, _PoleTerm) or t.goal is not None for t in self.terms)
        if need_stable and not np.all(self.problem.stable(K)):
            return np.inf, np.array([np.inf]), np.zeros((1, nx)), _empty_pieces(1)
        values, grads, pieces = [], [], []
        for j, (term, (a, b)) in enumerate(zip(self.terms, self.affine, strict=True)):
            p = term.pieces(K, self.eps)
            if p is None:
                return np.inf, np.array([np.inf]), np.zeros((1, nx)), _empty_pieces(1)
            v, g, models, omegas, which, *lam = p
            lam = lam[0] if lam else np.zeros(v.size, complex)
            values.append(a * v + b)
            grads.append(a * g)
            pieces.append((np.full(v.size, j), models, omegas, which, lam))
        if self.floor is not None:
            values.append(np.array([self.floor]))
            grads.append(np.zeros((1,) + K.shape))
            pieces.append(
                (
                    np.array([-1]),
                    np.zeros(1, int),
                    np.zeros(1),
                    np.zeros(1, int),
                    np.zeros(1, complex),
                )
            )
        values = np.concatenate(values)
        grads = np.concatenate(grads)
        pieces = tuple(np.concatenate(c) for c in zip(*pieces, strict=True))
        f = values.max()
        keep = np.flatnonzero(values >= f - self.eps * max(abs(f), 1e-3))
        keep = keep[np.argsort(-values[keep], kind="stable")][: self.max_pieces]
        gx = self.problem.structure.chain(x, grads[keep]) * self.scale
        return float(f), values[keep], gx, tuple(c[keep] for c in pieces)

    def regrad(self, xi, pieces):
        x = self.x(xi)
        K = self.problem.structure.K(x)
        term_index, models, omegas, which, lam = pieces
        values = np.full(term_index.size, -np.inf)
        grads = np.zeros((term_index.size,) + K.shape)
        for j in np.unique(term_index):
            rows = np.flatnonzero(term_index == j)
            if j < 0:
                values[rows] = self.floor
                continue
            if np.any(~np.isfinite(omegas[rows])):
                continue
            a, b = self.affine[j]
            v, g = self.terms[j].regrad(K, models[rows], omegas[rows], which[rows], lam[rows])
            values[rows], grads[rows] = a * v + b, a * g
        return values, self.problem.structure.chain(x, grads) * self.scale

    def value(self, xi) -> float:
        return self(xi)[0]


def _empty_pieces(k):
    return (
        np.full(k, -1),
        np.zeros(k, int),
        np.full(k, np.nan),
        np.zeros(k, int),
        np.zeros(k, complex),
    )


def _minimize(objective: _Objective, xi, options: SystuneOptions):
    """:func:`minimize_bundle_cycles` (metric cycles and kicks, as the static-gain synthesis)."""
    res = minimize_bundle_cycles(
        objective,
        xi,
        regrad=objective.regrad,
        max_iterations=options.max_iterations,
        restart_every=options.metric_cycle,
        qp=QP_SOLVERS[options.qp],
    )
    return res.x, res.f, res.iterations, res.message


# --------------------------------------------------------------------------- entry point


def systune(
    plants,
    controller,
    goals,
    *,
    options: SystuneOptions | None = None,
    progress=None,
    verify=None,
) -> TuningResult:
    """Tune the parameters of a structured controller over a plant array (MATLAB ``systune``).

    Minimizes the worst soft goal subject to every hard goal ``<= 1`` (normalized values, see
    :mod:`oos_drake.control.goals`), every closed loop stable, over all models (see the module
    docstring for the algorithm).

    Parameters
    ----------
    plants : list of control.StateSpace, BatchedStateSpace or LFR
        The plant models with named inputs and outputs (python-control's ``inputs``/
        ``outputs`` labels; a certain :class:`~oos_drake.lfr.LFR` model array with names; a
        :class:`~oos_drake.control.statespace.BatchedStateSpace` model array). Exogenous
        inputs, the controls the controller drives and the measurements it reads are all
        channels of the plants. The controller is connected by these names with no sign
        change (``u = C(s) y``): put the error ``r - y`` in the plant.
    controller : block or sequence of blocks
        :class:`~oos_drake.control.tunable.TunableGain`, ``TunablePID``, ``TunableSS`` and
        :class:`~oos_drake.control.tunable.FixedBlock` connected by signal name (e.g. a gain
        ``y -> u_K`` behind a fixed roll-off ``u_K -> u``). Tunable blocks may not feed each
        other directly, and the loop must be strictly proper.
    goals : sequence of WeightedGain, Margins, Poles, Variance
        Each ``kind="soft"`` or ``"hard"``.
    options : SystuneOptions, optional
    progress : callable, optional
        ``progress(message: str)`` for log lines (one per run and per check of every model).
    verify : same types as ``plants``, optional
        Models on which the tuned controller is only checked (e.g. configurations between
        those of ``plants``): every goal's exact value there is
        :attr:`TuningResult.verified`, and a hard goal above 1 or an unstable loop there
        makes the status ``"infeasible"``. Never tuned on, never added to the working set.

    Returns
    -------
    TuningResult
        Status ``"infeasible"`` when the best point reached misses a hard goal (its values are
        reported, never passed off as meeting the goals).

    Raises
    ------
    ValueError
        Unknown structure or goal, a goal naming a signal that does not exist, goals that
        cannot be met (one line naming the culprit).

    Examples
    --------
    A PI controller on a first-order lag, with a weighted gain (soft) and margins (hard):

    >>> import control
    >>> from oos_drake.control.systune import systune
    >>> from oos_drake.control.tunable import TunablePID
    >>> from oos_drake.control.goals import Margins, WeightedGain
    >>> lag = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [-1.0]], [[0, 0], [0, 0]],
    ...                  inputs=["u", "d"], outputs=["y", "e"])
    >>> pi = TunablePID("C", inputs="e", outputs="u", terms="PI", kp=1.0, ki=1.0)
    >>> result = systune([lag], pi, [WeightedGain("d", "y"), Margins("u", 6.0, 45.0)])
    >>> result.status
    'ok'
    >>> bool(result.goal("Margins(u)").details["phase_margin_deg"] >= 45.0 - 1e-6)
    True
    """
    options = options or SystuneOptions()
    if options.qp not in QP_SOLVERS:
        raise ValueError(f"systune: qp must be one of {sorted(QP_SOLVERS)}, got {options.qp!r}")
    goals = list(goals)
    if not goals:
        raise ValueError("systune: no goal given")
    problem = _Problem(plants, controller, options.min_decay, options.shared_modes, options.workers)
    for goal in goals:
        if not hasattr(goal, "kind"):
            raise ValueError(f"systune: unknown goal type {type(goal).__name__}")
    terms, owners = _goal_terms(problem, goals)
    soft = [i for i, (g, _) in enumerate(owners) if goals[g].kind == "soft"]
    hard = [i for i, (g, _) in enumerate(owners) if goals[g].kind == "hard"]
    structure = problem.structure
    x0 = structure.initial()
    scale = structure.scale(x0)
    _check_reachable(problem, goals, terms, owners, hard, structure.K(x0))
    rng = np.random.default_rng(options.seed)
    starts = [x0]
    linear = structure.linear
    for _ in range(options.restarts):
        z = options.restart_spread * rng.normal(size=x0.size)
        starts.append(np.where(linear & (x0 != 0), x0 * np.exp(z), x0 + z * scale))
    log = progress or (lambda message: None)
    N = problem.size
    working = _initial_working_set(options.working_set, N)
    runs, rounds, x, stable = [], [], x0, False
    max_rounds = max(1, options.max_rounds)
    for round_ in range(max_rounds):
        sub = problem if working.size == N else problem.subset(working)
        sub_terms = terms if sub is problem else _goal_terms(sub, goals)[0]
        best = None
        for r, start in enumerate(starts if round_ == 0 else [x]):
            xr, ok, iterations, message = _run(sub, sub_terms, soft, hard, start, scale, options)
            F, G = _soft_hard(sub, sub_terms, soft, hard, structure.K(xr))
            runs.append(
                dict(round=round_, start=r, models=int(working.size), soft=F, hard=G, stable=ok)
                | dict(iterations=iterations, message=message)
            )
            log(
                f"round {round_} run {r}: soft {F:.6g}, hard {G:.6g} over {working.size} "
                f"models ({iterations} it, {message})"
            )
            feasible = G <= 1.0 + options.feasibility_tolerance
            key = (not feasible, F if feasible else G)  # feasible first, then the lowest F
            if ok and (best is None or key < best[0]):
                best = (key, xr, F, G)
        if best is None:  # no stable point on the working set: report the start
            x, stable = (starts[0] if round_ == 0 else x), round_ > 0 and stable
            break
        x, stable, F_working = best[1], True, best[2]
        if working.size == N:
            rounds.append(dict(round=round_, models=N, soft=F_working, hard=best[3]))
            rounds[-1] |= dict(violators=0, added=0)
            break
        # every model: the exact values of the goals at x; the violators join the set
        add, violators, soft_all, hard_all = _violators(
            problem, terms, soft, hard, structure.K(x), working, F_working, options
        )
        if round_ + 1 == max_rounds:  # the budget ends: the violators stay outside
            add = add[:0]
        rounds.append(
            dict(round=round_, models=int(working.size), soft=soft_all, hard=hard_all)
            | dict(violators=int(violators), added=int(add.size))
        )
        log(
            f"round {round_}: over all {N} models soft {soft_all:.6g}, hard {hard_all:.6g}; "
            f"{violators} violator(s), {add.size} added"
        )
        if not add.size:
            break
        working = np.concatenate([working, add])
    stable = stable and bool(np.all(problem.stable(structure.K(x))))  # on every model
    result = _result(problem, goals, terms, owners, x, options, runs, stable)
    result = replace(result, working_set=tuple(int(i) for i in working), rounds=tuple(rounds))
    if verify is None:
        return result
    # the tuned controller on the verification models, checked only
    checked = _Problem(verify, controller, options.min_decay, options.shared_modes, options.workers)
    K = checked.structure.K(result.x)
    verified = _goal_values(goals, *_goal_terms(checked, goals), K)
    stable_there = np.all(checked.stable(K))
    hard_there = max((v.value for v in verified if v.kind == "hard"), default=0.0)
    met = stable_there and hard_there <= 1.0 + options.feasibility_tolerance
    log(
        f"verified on {checked.size} more models: hard {hard_there:.6g}"
        + ("" if stable_there else " (unstable loops)")
    )
    status = result.status if met else "infeasible"
    return replace(result, verified=tuple(verified), status=status)


def _goal_terms(problem: _Problem, goals):
    """Every goal's terms over ``problem``'s models and their owners ``(goal index, channel)``."""
    terms, owners = [], []
    for g, goal in enumerate(goals):
        for term, index, channel in problem.terms(goal, g):
            terms.append(term)
            owners.append((index, channel))
    return terms, owners


def _per_model(problem: _Problem, terms, indices, K) -> np.ndarray:
    """Exact max over the terms ``indices`` per model (``-inf`` without terms)."""
    values = [np.asarray(terms[i].exact(K)[0], dtype=float) for i in indices]
    return np.max(values, axis=0) if values else np.full(problem.size, -np.inf)


def _initial_working_set(size: int, N: int) -> np.ndarray:
    """``size`` evenly spaced models of ``N`` (the ends included); all of them when ``size``
    is 0 or at least ``N``."""
    if not 0 < size < N:
        return np.arange(N)
    return np.unique(np.round(np.linspace(0, N - 1, size)).astype(int))


def _violators(problem: _Problem, terms, soft, hard, K, working, F_working, options):
    """Models outside ``working`` that are unstable at ``K``, miss a hard goal, or exceed the
    working set's soft value ``F_working`` by ``soft_rtol``: ``(the worst ones to add (at most
    models_per_round), number of violators, soft max, hard max over every model)``."""
    N = problem.size
    stable = problem.stable(K)
    soft_v = np.full(N, np.inf)
    hard_v = np.full(N, np.inf)
    if np.any(stable):
        soft_v[stable] = _per_model(problem, terms, soft, K)[stable]
        hard_v[stable] = _per_model(problem, terms, hard, K)[stable]
    outside = np.ones(N, dtype=bool)
    outside[working] = False
    # the tuning's bound (with the surplus), not only the goal's
    bad_hard = outside & (
        hard_v * (1.0 + options.hard_surplus) > 1.0 + options.feasibility_tolerance
    )
    bad_soft = outside & (soft_v > F_working * (1.0 + options.soft_rtol))
    bad = bad_hard | bad_soft
    # the hard violators first (worst first), then the soft ones (worst first)
    order = np.lexsort((-np.where(np.isfinite(soft_v), soft_v, np.inf), -hard_v, ~bad_hard))
    order = order[bad[order]]
    soft_max = float(soft_v.max()) if soft else 0.0
    hard_max = float(hard_v.max()) if hard else (0.0 if np.all(stable) else np.inf)
    return order[: options.models_per_round], int(bad.sum()), soft_max, hard_max


def _run(problem: _Problem, terms, soft, hard, start, scale, options: SystuneOptions):
    """Phases 0-2 (module docstring) from ``start``: ``(x, stable, iterations, message)``."""
    eps, structure = options.active_tolerance, problem.structure

    def objective(indices, affine, floor=None):
        return _Objective(problem, [terms[i] for i in indices], affine, scale, eps, floor)

    xi = start / scale
    iterations, message = 0, "no iteration"
    # phase 0: stabilize
    if not np.all(problem.stable(structure.K(xi * scale))):
        obj = _Objective(
            problem, [problem.stability], [(1.0, 0.0)], scale, eps, -options.stability_floor
        )
        xi, _, it, message = _minimize(obj, xi, options)
        iterations += it
    if not np.all(problem.stable(structure.K(xi * scale))):
        return xi * scale, False, iterations, message
    # phase 1: hard goals (times 1 + hard_surplus) down to 1 - hard_margin
    G, surplus = 0.0, 1.0 + options.hard_surplus
    if hard:
        obj = objective(hard, [(surplus, 0.0)] * len(hard), floor=1.0 - options.hard_margin)
        G = obj.value(xi)
        if G > 1.0:
            xi, G, it, message = _minimize(obj, xi, options)
            iterations += it
    # phase 2: soft goals, the hard ones kept <= 1 (c updated until F stalls)
    if soft and G <= 1.0:
        soft_only = objective(soft, [(1.0, 0.0)] * len(soft))
        F0 = soft_only.value(xi)
        for _ in range(4):
            rho = options.penalty * max(F0, 1e-12)
            hard_affine = [(rho * surplus, F0 - rho)] * len(hard)
            obj = objective(soft + hard, [(1.0, 0.0)] * len(soft) + hard_affine)
            xi, _, it, message = _minimize(obj, xi, options)
            iterations += it
            F1 = soft_only.value(xi)
            if not hard or F1 >= F0 * (1 - 1e-4):
                break
            F0 = F1
    return xi * scale, True, iterations, message


def _soft_hard(problem, terms, soft, hard, K):
    """Exact ``(F, G)`` (certified norms, all models)."""
    if not np.all(problem.stable(K)):
        return np.inf, np.inf
    F = max((float(np.max(terms[i].exact(K)[0])) for i in soft), default=0.0)
    G = max((float(np.max(terms[i].exact(K)[0])) for i in hard), default=0.0)
    return F, G


def _zero_transfer(A, B, C, D) -> bool:
    """Whether ``C (sI - A)^-1 B + D`` vanishes for every model: every Markov parameter
    ``D, C B, C A B, ..., C A^(n-1) B`` is zero (Cayley-Hamilton)."""
    if np.any(D != 0):
        return False
    X = B
    for _ in range(A.shape[-1]):
        if np.any(np.abs(C @ X) > 1e-12 * (1 + np.abs(C).max() * np.abs(X).max())):
            return False
        X = A @ X
    return True


def _check_reachable(problem, goals, terms, owners, hard, K) -> None:
    """Refuse a hard goal whose closed loop does not depend on the controller (no path from
    its inputs to the controller, or from the controller to its outputs) and exceeds 1."""
    for i in hard:
        term = terms[i]
        if not isinstance(term, _HinfTerm | _H2Term):
            continue
        A, B1, B2, C1, C2, D11, D12, D21 = term.loop.partitions()
        if not (_zero_transfer(A, B1, C2, D21) or _zero_transfer(A, B2, C1, D12)):
            continue
        if isinstance(term, _H2Term):
            value = float(np.max(term.values(K)[0]))
        else:
            M = term.loop.close(K)
            value = term.scale * float(np.max(peak_gain(M.A, M.B, M.C, M.D).gamma))
        if value > 1.0:
            raise ValueError(
                f"hard goal {goals[owners[i][0]].label!r} cannot be met: it does not depend on "
                f"the controller and its value is {value:.4g} > 1"
            )


def _controller(problem: _Problem, x) -> control.StateSpace:
    """The whole controller at ``x`` from the signals it reads to the plant inputs it drives."""
    parts = []
    for t, sl in zip(problem.tunables, problem.structure.slices, strict=True):
        A, B, C, D = (np.real(M) for M in t.realize(x[sl]))
        parts.append(BatchedStateSpace(A, B, C, D, t.inputs, t.outputs))
    for f in problem.fixed:
        A, B, C, D = f.realization(problem.sampling_time)
        parts.append(BatchedStateSpace(A, B, C, D, f.inputs, f.outputs))
    produced = {s for p in parts for s in p.outputs}
    inputs = [s for s in dict.fromkeys(s for p in parts for s in p.inputs) if s not in produced]
    plant_inputs = set(problem.plant.inputs)
    outputs = [s for p in parts for s in p.outputs if s in plant_inputs]
    sys = connect(parts, inputs, outputs)
    return control.ss(
        sys.A,
        sys.B,
        sys.C,
        sys.D,
        problem.sampling_time,
        inputs=inputs,
        outputs=outputs,
        name="controller",
    )


def _goal_values(goals, terms, owners, K) -> list[GoalValue]:
    """Each goal's exact value over the models of ``terms`` at ``K``."""
    values = []
    for g, goal in enumerate(goals):
        mine = [i for i, (owner, _) in enumerate(owners) if owner == g]
        exact = [terms[i].exact(K) for i in mine]
        per_model = np.max([e[0] for e in exact], axis=0)
        details: dict[str, float] = {}
        if isinstance(goal, WeightedGain):
            details["hinf_norm"] = float(per_model.max())
            details["peak_frequency_rad_s"] = float(exact[0][1][np.argmax(exact[0][0])])
        elif isinstance(goal, Margins):
            disk = 2.0 / (2.0 * per_model.max() / goal.alpha) if per_model.max() > 0 else np.inf
            gm, pm = disk_gain_phase(disk)
            details.update(
                disk_margin=float(disk), gain_margin_db=float(gm), phase_margin_deg=float(pm)
            )
        elif isinstance(goal, Poles):
            _, _, _, s, *_ = terms[mine[0]]._all(K)
            r = np.maximum(np.abs(s), 1e-300)
            details.update(
                min_damping=float(np.min(-s.real / r)), max_frequency_rad_s=float(np.max(np.abs(s)))
            )
        elif isinstance(goal, Variance):
            details["h2_norm"] = float(per_model.max() * goal.max_std)
        values.append(GoalValue(goal.label, goal.kind, float(per_model.max()), per_model, details))
    return values


def _result(problem, goals, terms, owners, x, options, runs, stable) -> TuningResult:
    K = problem.structure.K(x)
    values = _goal_values(goals, terms, owners, K)
    soft = max((v.value for v in values if v.kind == "soft"), default=0.0)
    hard = max((v.value for v in values if v.kind == "hard"), default=0.0)
    ok = stable and hard <= 1.0 + options.feasibility_tolerance and np.isfinite(soft)
    blocks = {
        t.name: t.statespace(x[sl])
        for t, sl in zip(problem.tunables, problem.structure.slices, strict=True)
    }
    parameters = {
        t.name: t.values(x[sl])
        for t, sl in zip(problem.tunables, problem.structure.slices, strict=True)
    }
    x = np.array(x, dtype=float)
    x.setflags(write=False)
    return TuningResult(
        parameters=parameters,
        x=x,
        controller=_controller(problem, x),
        blocks=blocks,
        goals=tuple(values),
        soft=float(soft),
        hard=float(hard),
        status="ok" if ok else "infeasible",
        sampling_time=problem.sampling_time,
        runs=tuple(runs),
    )
