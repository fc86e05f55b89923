"""Flight software of the mission simulation as one periodic discrete Drake system.

Every component of the paper's control loop (Fig. controldesign) that is not the plant runs in a
single :class:`FlightSoftware` ``LeafSystem`` with **one periodic discrete update** at the control
rate, vectorized with small numpy products: a Python system called inside the integrator's
derivative evaluations would dominate the run time, whereas a system whose output depends only
on its discrete state is evaluated once per sample (Drake caches the output). One update costs
about 30 us of processor time (two matrix products, a scalar-math rotation, one state write), 3 %
of a whole-mission run (``benchmarks/bench_mission_sim.py --profile``).

At each sample ``t_k`` the update reads the plant state and computes, for the three axes at once,

.. math::

    y_{att} = -(\\mathrm{SST}\\,\\phi + W_{n,sst}\\,n_{sst}), \\quad
    y_{rate} = -(\\mathrm{GYRO}\\,\\omega + W_{n,gyro}\\,n_{gyro}), \\quad
    u_K = C(z) \\begin{bmatrix} y_{att} \\\\ y_{rate} \\end{bmatrix}, \\quad
    u = F_{ro}\\, u_K,

    T_{rw} = \\mathrm{RW}\\, \\mathrm{sat}_{T_{max}}(u), \\quad
    T = (I + (W_{mul} \\circ \\Delta_{mul})\\, a(s))\\, T_{rw}
        + \\delta_{add} J_{ref} W_{add}\\, a(s)\\, T_{rw} + W_{n,ext}\\, d_{ext},

with ``phi`` the hub roll-pitch-yaw angles (attitude reference zero), ``omega`` the hub body rate,
``n`` unit white Gaussian sequences scaled by the paper's noise levels, ``a(s) = (p - s)/(p + s)``
a unit all-pass (the stable realization of the LTI perturbations: ``Delta_mul`` is the 3x3
matrix of the dispersed scalars ``Delta_mul_xx .. Delta_mul_zz``, weighted entry by entry by
``W_mul``, ``delta_add`` = ``Delta_add``, all in [-1, 1]) and ``d_ext`` a unit
white sequence shaped by ``W_n,ext``. The torque ``T`` (hub axes) is held over the sample period
(zero-order hold) and applied to the hub's floating joint as ``R_WB T``.

The all-pass is set per run with the perturbation scalars
(:meth:`FlightSoftware.set_perturbations`): its phase is -90 deg at the run's frequency ``f``
(the critical frequency of the campaign region the run explores, ``frequency [Hz]`` of
``worst_cases.parquet``), exactly also after the discretization (:func:`allpass_block`
pre-warps the corner). A frequency at or above the Nyquist frequency of the flight software, an
infinite one (an ill-posed mu peak) included, is realized as the static gain ``a = 1``: a real
discrete-time system is real at ``z = -1``, and the value of a unit LTI perturbation at
infinite frequency is real (the scalar's sign covers ``-1``).

Each linear block is discretized with the bilinear (Tustin) transform at the control rate, so a
block with a bandwidth above the sample rate (gyro, wheels at 200 Hz) reduces to its DC gain with
no artificial one-sample delay. The controller ``C(z)`` (``y -> u_K``) is the static gain
``K = [K_p, K_d]`` of the paper or any linear controller
(:class:`~oos_drake.control.interconnection.ControllerSystem`: a PID, a fixed-order state
space): a continuous one is discretized exactly for the sampled measurement it reads, held
over the period (zero-order hold), a discrete one runs as tuned (at this rate); its state is
part of the discrete state, kept from one sample to the next. The blocks before the torque
saturation and those after it are merged into two linear stages (their matrices are obtained
once by probing the block-by-block reference chain with unit vectors), so an update costs two
small matrix products.

A run may also carry a *dynamic perturbation* (:func:`perturbation_block`,
:meth:`FlightSoftware.set_dynamic_perturbation`, states declared with the system): a discrete
block from the plant-input torque ``T_rw + T_dist`` (the analysis' ``T``, whose ``P_hat``
perturbs the external disturbance as well) to a torque added to ``T`` and to an attitude and
rate added to the measurements. ``oos confirm`` realizes the analysis' worst complex blocks
with it, at the peak's frequency (``Delta_mul`` as the torque part, ``Delta_add`` as the exact
sampled response of the acceleration it stands for).

The discrete state also carries the run's metrics (running maxima of ``|phi|`` and ``|u|``,
sum of squares), so they are computed at the control rate without any logging. With a dynamic
perturbation, ``phi`` there is the hub's attitude plus the realized ``Delta_add``'s (the
output of the analysis' ``P_hat``; the hub alone drifts by that part's ramp, see
:func:`perturbation_block`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import scipy.signal
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from oos_drake.control import components as comp
from oos_drake.control.interconnection import ControllerSystem, as_controller
from oos_drake.control.sampled import plant_with_integrators
from oos_drake.robust.interpolant import lti_interpolant

__all__ = [
    "DiscreteBlock",
    "FlightSoftwareDesign",
    "FlightSoftware",
    "NOISE_CHANNELS",
    "LOG_SIGNALS",
    "METRIC_SLOTS",
    "allpass",
    "allpass_block",
    "complex_blocks",
    "discretize",
    "perturbation_block",
    "rpy_to_rotation",
]

#: Columns of the per-sample noise table: star tracker (3), gyro (3), external disturbance (3).
NOISE_CHANNELS = 9
#: Signals of the ``log`` output port, in order (3 axes each).
LOG_SIGNALS = ("u", "T_rw", "T", "T_dist")
#: Slots of the metrics part of the discrete state.
METRIC_SLOTS = ("max_phi", "max_u", "sumsq_phi", "max_T")


@dataclass(frozen=True, eq=False)
class DiscreteBlock:
    """A discrete state-space block ``x+ = A x + B u``, ``y = C x + D u``.

    Attributes
    ----------
    A, B, C, D : ndarray
        Discrete-time matrices (sample period of the flight software).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray

    @property
    def nstates(self) -> int:
        """Number of states."""
        return int(self.A.shape[0])

    def step(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x+, y) = (A x + B u, C x + D u)``."""
        return self.A @ x + self.B @ u, self.C @ x + self.D @ u


def discretize(A, B, C, D, period: float) -> DiscreteBlock:
    """Bilinear (Tustin) discretization of a continuous block at ``period`` [s]."""
    A, B, C, D = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, C, D))
    if A.size == 0:
        return DiscreteBlock(
            np.zeros((0, 0)), np.zeros((0, B.shape[1])), np.zeros((C.shape[0], 0)), D
        )
    Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete((A, B, C, D), period, method="bilinear")
    return DiscreteBlock(Ad, Bd, Cd, Dd)


def allpass(frequency_hz: float) -> tuple[np.ndarray, ...]:
    """``(A, B, C, D)`` of the unit all-pass ``a(s) = (p - s)/(p + s)``, ``p = 2 pi f`` [rad/s].

    Stable, ``|a(j w)| = 1`` at every frequency, ``a(0) = 1``, ``a(j p) = -j`` (phase -90 deg at
    ``f``), phase -180 deg at high frequency: the standard realization of a unit-norm LTI
    perturbation with a phase that turns at ``f``.
    """
    p = 2.0 * np.pi * float(frequency_hz)
    if not (np.isfinite(p) and p > 0):
        raise ValueError(f"all-pass: frequency must be finite and > 0 Hz, got {frequency_hz}")
    # a(s) = -1 + 2 p / (s + p)
    return np.array([[-p]]), np.array([[1.0]]), np.array([[2.0 * p]]), np.array([[-1.0]])


def allpass_block(frequency_hz: float, period: float) -> DiscreteBlock:
    """The three-axis discrete all-pass of the LTI perturbations, phase -90 deg at ``frequency_hz``.

    Tustin maps ``H_d(e^{j w T}) = H_c(j (2/T) tan(w T / 2))``, so the continuous corner is
    pre-warped to ``p = (2/T) tan(pi f T)``: the discrete all-pass then equals ``a(j 2 pi f) = -j``
    exactly at ``f``. ``f >= 1/(2T)`` (the Nyquist frequency, ``inf`` included) and NaN (no
    frequency: only valid with zero perturbation scalars) give the static ``a = 1`` (one unused
    state per axis, so the state layout does not depend on the frequency).

    Parameters
    ----------
    frequency_hz : float
        Frequency where the all-pass phase is -90 deg [Hz] (> 0, may be ``inf`` or NaN).
    period : float
        Sample period of the flight software [s].
    """
    f = float(frequency_hz)
    if not (f > 0 or np.isnan(f)):
        raise ValueError(f"all-pass: frequency must be > 0 Hz (or inf), got {frequency_hz}")
    if np.isnan(f) or f * period >= 0.5:
        zero = np.zeros((3, 3))
        return DiscreteBlock(zero, zero, zero, np.eye(3))
    warped_hz = np.tan(np.pi * f * period) / (np.pi * period)
    return discretize(*comp.per_axis(allpass(warped_hz)), period)


@dataclass(frozen=True, eq=False)
class FlightSoftwareDesign:
    """Discretized components of the control loop (three axes each).

    Attributes
    ----------
    period : float
        Sample period [s].
    controller : DiscreteBlock
        The controller ``y (6) -> u_K (3)`` at the period (no states for the static gain
        ``[K_p, K_d]`` [N m/rad, N m s/rad]).
    star_tracker, gyro, rolloff, wheels, disturbance : DiscreteBlock
        SST, GYRO, F_ro, RW and W_n,ext (the all-pass of the LTI perturbations is set per run:
        :func:`allpass_block`).
    noise_star_tracker : float
        Star tracker noise level W_n,sst [rad] (std of one sample).
    noise_gyro : float
        Gyro noise level W_n,gyro [rad/s] (std of one sample).
    torque_limit : float
        Wheel command saturation [N m].
    W_mul : ndarray, shape (3, 3)
        Multiplicative weight (paper: 4e-2 diagonal, 4e-3 off-diagonal) [-].
    W_add : float
        Additive weight [(rad/s^2)/(N m)] (paper: -75 dB).
    J_ref : ndarray, shape (3, 3)
        Inertia turning the additive acceleration perturbation into a hub torque [kg m^2].
    """

    period: float
    controller: DiscreteBlock
    star_tracker: DiscreteBlock
    gyro: DiscreteBlock
    rolloff: DiscreteBlock
    wheels: DiscreteBlock
    disturbance: DiscreteBlock
    noise_star_tracker: float
    noise_gyro: float
    torque_limit: float
    W_mul: np.ndarray
    W_add: float
    J_ref: np.ndarray

    @classmethod
    def create(
        cls,
        K,
        control_rate: float,
        *,
        spec: comp.DesignSpecification | None = None,
        torque_limit: float = 2.0,
        J_ref=None,
    ) -> FlightSoftwareDesign:
        """Discretize the paper's components at ``control_rate`` [Hz].

        Parameters
        ----------
        K : array_like, shape (3, 6), or ControllerSystem
            Controller gain ``[K_p, K_d]``, or a linear controller ``y -> u_K`` (continuous:
            discretized with a zero-order hold at ``control_rate``; discrete: at that rate).
        control_rate : float
            Sample rate of the flight software [Hz].
        spec : DesignSpecification, optional
            Component data and weights (paper values by default).
        torque_limit : float
            Wheel torque limit [N m] (paper: 2).
        J_ref : array_like, shape (3, 3), optional
            Inertia for the additive perturbation [kg m^2] (default identity).
        """
        if not isinstance(K, ControllerSystem):
            K = np.asarray(K, dtype=float)
            if K.shape != (3, 6) or not np.all(np.isfinite(K)):
                raise ValueError(
                    f"flight software: controller gain K must be a finite 3x6, got {K.shape}"
                )
        if not (np.isfinite(control_rate) and control_rate > 0):
            raise ValueError(f"flight software: control_rate must be > 0 Hz, got {control_rate}")
        try:
            controller = as_controller(K).discretize(1.0 / float(control_rate))
        except ValueError as exc:
            raise ValueError(f"flight software: {exc}") from exc
        if not torque_limit > 0:
            raise ValueError(f"flight software: torque_limit must be > 0 N m, got {torque_limit}")
        spec = spec or comp.DesignSpecification()
        T = 1.0 / float(control_rate)
        W_ext = comp.disturbance_weight(spec)
        W_mul = np.full((3, 3), spec.multiplicative_off_diagonal)
        np.fill_diagonal(W_mul, spec.multiplicative_diagonal)
        sst, gyro, rolloff, wheels = (discretize(*comp.per_axis(f), T) for f in comp.filters(spec))
        return cls(
            period=T,
            controller=DiscreteBlock(controller.A, controller.B, controller.C, controller.D),
            star_tracker=sst,
            gyro=gyro,
            rolloff=rolloff,
            wheels=wheels,
            disturbance=discretize(W_ext.A, W_ext.B, W_ext.C, W_ext.D, T),
            noise_star_tracker=float(spec.noise_star_tracker),
            noise_gyro=float(spec.noise_gyro),
            torque_limit=float(torque_limit),
            W_mul=W_mul,
            W_add=float(spec.additive_weight),
            J_ref=np.eye(3) if J_ref is None else np.asarray(J_ref, dtype=float),
        )

    @property
    def K(self) -> np.ndarray:
        """The static gain ``[K_p, K_d]`` (3x6) of a controller without states.

        Raises
        ------
        ValueError
            A dynamic controller.
        """
        if self.controller.nstates:
            raise ValueError(
                f"flight software: a dynamic controller ({self.controller.nstates} states) has "
                "no static gain K"
            )
        return self.controller.D

    def slices(self) -> dict[str, slice]:
        """Block name -> slice of the discrete state (filters, controller, held outputs,
        metrics, counter)."""
        sizes = {
            "star_tracker": self.star_tracker.nstates,
            "gyro": self.gyro.nstates,
            "controller": self.controller.nstates,
            "rolloff": self.rolloff.nstates,
            "wheels": self.wheels.nstates,
            "disturbance": self.disturbance.nstates,
            "mul": 3,
            "add": 3,
            "tau_W": 3,
            "log": 3 * len(LOG_SIGNALS),
            "metrics": 3 * len(METRIC_SLOTS),
            "counter": 1,
        }
        return dict(zip(sizes, _consecutive(sizes.values()), strict=True))


def _zero_perturbation(n: int) -> DiscreteBlock:
    """The zero dynamic perturbation with ``n`` states (input 3, outputs 9)."""
    return DiscreteBlock(np.zeros((n, n)), np.zeros((n, 3)), np.zeros((9, n)), np.zeros((9, 3)))


def perturbation_block(
    design: FlightSoftwareDesign,
    omega: float,
    *,
    delta_mul=None,
    delta_add=None,
) -> DiscreteBlock:
    r"""The analysis' complex blocks as one discrete block of the flight software.

    The analysis' plant is ``P_hat = (P + W_add Delta_add)(I + W_mul o Delta_mul)``
    (:func:`oos_drake.control.analysis_model.uncertain_plant`, ``T -> wdot``). At a peak each
    block has a worst complex value at the critical frequency ``omega``; both are realized
    here as stable systems taking that value there
    (:func:`oos_drake.robust.interpolant.lti_interpolant`, MATLAB ``wcu``'s interpolation):

    The blocks act on the plant-input torque ``T_in = T_rw + T_dist`` (wheels and external
    disturbance), as ``P_hat`` acts on the analysis' ``T = RW u + W_n,ext d_ext``.

    - ``Delta_mul`` acts on the torque: ``T_m = T_in + Delta_m(z) T_in`` with ``Delta_m(z)``
      the discrete interpolant of ``W_mul o Delta_mul`` (Tustin, pre-warped:
      ``Delta_m(e^{j omega dt}) = W_mul o Delta_mul`` exactly), computed at the sample and held
      with the torque.
    - ``Delta_add`` is an angular acceleration ``W_add Delta_add(s) T_m`` of the hub, which a
      multibody twin cannot take as a torque without inverting its plant. Its effect on what
      the loop measures is ``[dphi; dw] = [I/s^2; I/s] W_add Delta_add(s) T_m``; ``T_m`` is
      held over each period, so the zero-order-hold discretization of that continuous system
      (``Delta_add(s)`` the continuous interpolant) gives exactly the perturbation's attitude
      and rate at the samples: added to the measurements, it closes the same sampled-data loop
      as the plant ``P + W_add Delta_add(s)`` behind the hold (its double integrator duplicates
      the plant's rigid-body one: the loop gains six unobservable states at ``z = 1``, and the
      hub attitude drifts by the perturbation's ``-dphi``, the measured sum is regulated).

    Parameters
    ----------
    design : FlightSoftwareDesign
        Period and the weights ``W_mul``, ``W_add``.
    omega : float
        Critical frequency [rad/s] (below the flight software's Nyquist frequency).
    delta_mul : array_like, shape (3, 3), optional
        Normalized worst ``Delta_mul`` (entry ``ij`` = ``Delta_mul_ij``) [-], complex.
    delta_add : array_like, shape (3, 3), optional
        Normalized worst ``Delta_add`` [-], complex.

    Returns
    -------
    DiscreteBlock
        Input ``T_in = T_rw + T_dist`` [N m] (3), outputs ``[dT [N m]; dphi [rad]; dw
        [rad/s]]`` (9), for
        :meth:`FlightSoftware.set_dynamic_perturbation`.
    """
    T = design.period
    zero = np.zeros((3, 3), dtype=complex)
    mul = zero if delta_mul is None else np.asarray(delta_mul, dtype=complex)
    add = zero if delta_add is None else np.asarray(delta_add, dtype=complex)
    if mul.shape != (3, 3) or add.shape != (3, 3):
        raise ValueError(
            f"perturbation block: Delta_mul and Delta_add must be 3x3, got {mul.shape}, {add.shape}"
        )
    m = lti_interpolant(design.W_mul * mul, omega, dt=T)
    Am, Bm, Cm, Dm = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (m.A, m.B, m.C, m.D))
    nm = Am.shape[0] if Am.size else 0
    Am, Bm, Cm = Am.reshape(nm, nm), Bm.reshape(nm, 3), Cm.reshape(3, nm)
    # [dphi; dw] = [I/s^2; I/s] W_add Delta_add(s) T_m: states [x_a; w_a; phi_a] (none
    # without Delta_add)
    if delta_add is None:
        Ad, Bd, Cd = np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((6, 0))
    else:
        a = lti_interpolant(design.W_add * add, omega)
        Ac, Bc, Cc = plant_with_integrators(a)  # outputs [dphi; dw]
        Ad, Bd, Cd, _, _ = scipy.signal.cont2discrete(
            (Ac, Bc, Cc, np.zeros((6, 3))), T, method="zoh"
        )
    n = nm + Ad.shape[0]
    # T_m = Cm x_m + (I + Dm) T_in drives the additive part
    A = np.zeros((n, n))
    A[:nm, :nm] = Am
    A[nm:, :nm] = Bd @ Cm
    A[nm:, nm:] = Ad
    B = np.vstack([Bm, Bd @ (np.eye(3) + Dm)])
    C = np.zeros((9, n))
    C[:3, :nm] = Cm
    C[3:, nm:] = Cd
    D = np.zeros((9, 3))
    D[:3] = Dm
    return DiscreteBlock(A, B, C, D)


def complex_blocks(perturbation) -> dict:
    """The analysis' worst complex blocks of a perturbation as :func:`perturbation_block` takes
    them: ``{"delta_mul": 3x3, "delta_add": 3x3}`` (normalized [-]; a block the perturbation
    leaves out is absent).

    Parameters
    ----------
    perturbation : Mapping
        Block name -> normalized value (``Delta_add`` a 3x3 complex, ``Delta_mul_xy`` a
        complex scalar or 1x1; real blocks ignored).
    """
    from oos_drake.control.analysis_model import ADDITIVE_BLOCK, MULTIPLICATIVE_BLOCKS

    axes = ("x", "y", "z")
    out = {}
    if ADDITIVE_BLOCK in perturbation:
        out["delta_add"] = np.asarray(perturbation[ADDITIVE_BLOCK], dtype=complex)
    if any(n in perturbation for n in MULTIPLICATIVE_BLOCKS):
        mul = np.zeros((3, 3), dtype=complex)
        for name in MULTIPLICATIVE_BLOCKS:
            i, j = axes.index(name[-2]), axes.index(name[-1])
            mul[i, j] = complex(np.ravel(perturbation.get(name, 0.0))[0])
        out["delta_mul"] = mul
    return out


def _consecutive(sizes) -> tuple[slice, ...]:
    """Consecutive slices of the given sizes (Python ``int`` bounds)."""
    bounds = [0, *itertools.accumulate(int(size) for size in sizes)]
    return tuple(itertools.starmap(slice, itertools.pairwise(bounds)))


class FlightSoftware(LeafSystem):
    """Sensors, controller, roll-off, wheels, perturbations and disturbances (one discrete update).

    Ports
    -----
    input ``plant_state`` (nq + nv): the MultibodyPlant state.
    output ``generalized_force`` (nv): the held hub torque on the hub's floating joint.
    output ``log`` (12): ``[u; T_rw; T; T_dist]`` held values [N m].

    Context
    -------
    numeric parameter 0 (11): ``[delta_add, Delta_mul (3x3, row-major)]`` [-], the LTI
    perturbation scalars, and the all-pass frequency [Hz] (NaN by default: no perturbation).
    abstract parameter 0: ``(n_samples, 9)`` array of unit noise ``[n_sst; n_gyro; d_ext]``
    (row ``k`` is used at the k-th sample after the start; rows wrap around).
    abstract parameter 1: the dynamic perturbation (a :class:`DiscreteBlock` with
    ``perturbation_states`` states, :func:`perturbation_block`; zero by default).

    Parameters
    ----------
    design : FlightSoftwareDesign
    nq, nv : int
        Positions and velocities of the plant.
    hub_q_start, hub_v_start : int
        Start of the hub's floating joint in ``q`` and ``v``.
    perturbation_states : int
        States of the dynamic perturbation block set per run
        (:meth:`set_dynamic_perturbation`); 0: none.
    """

    def __init__(
        self,
        design: FlightSoftwareDesign,
        nq: int,
        nv: int,
        hub_q_start: int,
        hub_v_start: int,
        *,
        perturbation_states: int = 0,
    ):
        super().__init__()
        self._design = design
        self._nq, self._nv = nq, nv
        self._qs, self._vs = hub_q_start, hub_v_start
        self._slices = design.slices()
        n_p = int(perturbation_states)
        if n_p < 0:
            raise ValueError(f"flight software: perturbation_states must be >= 0, got {n_p}")
        end = self._slices["counter"].stop
        self._slices["perturbation"] = slice(end, end + n_p)
        size = end + n_p
        self._state_index = self.DeclareDiscreteState(size)
        self._plant_state = self.DeclareVectorInputPort("plant_state", nq + nv)
        default = np.concatenate([np.zeros(10), [np.nan]])
        self._perturbation_index = self.DeclareNumericParameter(BasicVector(default))
        self._noise_index = self.DeclareAbstractParameter(
            AbstractValue.Make(np.zeros((1, NOISE_CHANNELS)))
        )
        self._dynamic_index = self.DeclareAbstractParameter(
            AbstractValue.Make(_zero_perturbation(n_p))
        )
        self.DeclarePeriodicDiscreteUpdateEvent(design.period, 0.0, self._update)
        ticket = {self.xd_ticket()}
        self.DeclareVectorOutputPort(
            "generalized_force", nv, self._calc_force, prerequisites_of_calc=ticket
        )
        self.DeclareVectorOutputPort(
            "log", 3 * len(LOG_SIGNALS), self._calc_log, prerequisites_of_calc=ticket
        )
        controller = design.controller
        self._Kp, self._Kd = controller.D[:, :3], controller.D[:, 3:]
        self._J_Wadd = design.J_ref * design.W_add
        self._build_stages()

    @property
    def design(self) -> FlightSoftwareDesign:
        """The discretized components."""
        return self._design

    @property
    def state_slices(self) -> dict[str, slice]:
        """Named slices of the discrete state."""
        return dict(self._slices)

    def set_perturbations(
        self, context, delta_mul, delta_add: float, frequency_hz: float = math.nan
    ) -> None:
        """Set the LTI perturbations of a run.

        Parameters
        ----------
        delta_mul : array_like
            3x3 matrix (or a scalar for every entry) of the multiplicative scalars [-], in [-1, 1].
        delta_add : float
            Additive scalar [-], in [-1, 1].
        frequency_hz : float
            Where the all-pass phase is -90 deg [Hz] (see :func:`allpass_block`); NaN only when
            every scalar is zero.

        Raises
        ------
        ValueError
            A nonzero scalar without a frequency, or a frequency <= 0.
        """
        matrix = np.broadcast_to(np.asarray(delta_mul, dtype=float), (3, 3))
        frequency_hz = float(frequency_hz)
        if np.isnan(frequency_hz) and (float(delta_add) != 0.0 or np.any(matrix != 0.0)):
            raise ValueError(
                "flight software: Delta_add / Delta_mul are nonzero but no frequency realizes "
                "them (give the critical frequency of the region the run explores)"
            )
        allpass_block(frequency_hz, self._design.period)  # checks the frequency
        context.get_mutable_numeric_parameter(self._perturbation_index).SetFromVector(
            np.concatenate([[float(delta_add)], matrix.ravel(), [frequency_hz]])
        )

    def set_noise(self, context, noise: np.ndarray) -> None:
        """Set the per-sample unit noise table (``(n, 9)``) of a run."""
        noise = np.asarray(noise, dtype=float)
        if noise.ndim != 2 or noise.shape[1] != NOISE_CHANNELS or noise.shape[0] < 1:
            raise ValueError(f"flight software: noise table must be (n, 9), got {noise.shape}")
        context.get_mutable_abstract_parameter(self._noise_index).set_value(noise)

    def set_dynamic_perturbation(self, context, block: DiscreteBlock | None) -> None:
        """Set the dynamic perturbation of a run (None: zero).

        ``block`` (:func:`perturbation_block`) has input ``T_rw + T_dist`` [N m] (3: the
        wheel torque and the external disturbance, the analysis' plant input) and outputs
        ``[dT; dphi; dw]`` (9): ``dT`` [N m] is added to the hub torque, ``dphi`` [rad] and ``dw``
        [rad/s] to the measured attitude and rate; its state count is the constructor's
        ``perturbation_states`` and the measurement rows have no feedthrough.

        Raises
        ------
        ValueError
            Wrong shapes or a measurement feedthrough.
        """
        n = self._slices["perturbation"].stop - self._slices["perturbation"].start
        block = _zero_perturbation(n) if block is None else block
        shapes = (block.A.shape, block.B.shape, block.C.shape, block.D.shape)
        if shapes != ((n, n), (n, 3), (9, n), (9, 3)):
            raise ValueError(
                f"flight software: dynamic perturbation must be a {n}-state 3 -> 9 block, got "
                f"shapes {shapes}"
            )
        if np.any(block.D[3:] != 0.0):
            raise ValueError(
                "flight software: the measurement rows of a dynamic perturbation "
                "must have no feedthrough (an algebraic loop)"
            )
        context.get_mutable_abstract_parameter(self._dynamic_index).set_value(block)

    def metrics(self, context) -> dict[str, np.ndarray]:
        """Running metrics: ``max_phi`` [rad], ``max_u`` [N m], ``sumsq_phi`` [rad^2],
        ``max_T`` [N m] (3 axes each) and ``samples``."""
        x = context.get_discrete_state(self._state_index).get_value()
        m = x[self._slices["metrics"]].reshape(len(METRIC_SLOTS), 3)
        out = {name: m[i].copy() for i, name in enumerate(METRIC_SLOTS)}
        out["samples"] = float(x[self._slices["counter"]][0])
        return out

    def linear_update(
        self,
        delta_mul=0.0,
        delta_add: float = 0.0,
        frequency_hz: float = math.nan,
        dynamic: DiscreteBlock | None = None,
    ) -> DiscreteBlock:
        """The update as it runs, without noise and below the torque limit: a discrete system.

        ``x_{k+1} = A x_k + B [phi_k; w_k]``, ``T_k = C x_k + D [phi_k; w_k]`` with ``x`` the
        filter states (both stages, then those of ``dynamic``), ``phi`` the hub roll-pitch-yaw
        angles [rad], ``w`` its body rate [rad/s] sampled at ``t_k`` and ``T`` the hub torque
        [N m] held over ``[t_k, t_{k+1})`` (no computation delay: the torque computed at ``t_k``
        acts from ``t_k``). ``delta_mul``, ``delta_add``, ``frequency_hz`` as in
        :meth:`set_perturbations`, ``dynamic`` as in :meth:`set_dynamic_perturbation`.
        """
        matrix = np.broadcast_to(np.asarray(delta_mul, dtype=float), (3, 3))
        M2 = self._output_stage(
            np.concatenate([[float(delta_add)], matrix.ravel(), [float(frequency_hz)]])
        )
        dynamic = _zero_perturbation(0) if dynamic is None else dynamic
        n1, n2 = self._n1, self._n2
        A1, B1 = self._M1[:n1, :n1], self._M1[:n1, n1 : n1 + 6]
        C1, D1 = self._M1[n1:, :n1], self._M1[n1:, n1 : n1 + 6]
        A2, B2 = M2[:n2, :n2], M2[:n2, n2 : n2 + 3]
        # T_in = T_rw + T_dist, the dynamic perturbation's input (no noise: T_dist is the
        # disturbance filter's free response)
        Cw = M2[n2 : n2 + 3, :n2] + M2[n2 + 3 : n2 + 6, :n2]
        Dw = M2[n2 : n2 + 3, n2 : n2 + 3] + M2[n2 + 3 : n2 + 6, n2 : n2 + 3]
        C2, D2 = M2[n2 + 12 :, :n2], M2[n2 + 12 :, n2 : n2 + 3]  # T
        Ap, Bp, Cp, Dp = dynamic.A, dynamic.B, dynamic.C, dynamic.D
        Ct, Dt, Cm = Cp[:3], Dp[:3], Cp[3:]  # dT; [dphi; dw] (no feedthrough)
        # measurements z + Cm xp; u = C1 x1 + D1 (z + Cm xp); T_in = Cw x2 + Dw u
        zero = np.zeros
        A = np.block(
            [
                [A1, zero((n1, n2)), B1 @ Cm],
                [B2 @ C1, A2, B2 @ D1 @ Cm],
                [Bp @ Dw @ C1, Bp @ Cw, Ap + Bp @ Dw @ D1 @ Cm],
            ]
        )
        B = np.vstack([B1, B2 @ D1, Bp @ Dw @ D1])
        C = np.hstack([(D2 + Dt @ Dw) @ C1, C2 + Dt @ Cw, Ct + (D2 + Dt @ Dw) @ D1 @ Cm])
        return DiscreteBlock(A, B, C, (D2 + Dt @ Dw) @ D1)

    # -- the two linear stages ------------------------------------------------------------------
    def _stage1_reference(self, x1, z1):
        """Sensors, controller and roll-off, block by block: ``z1 = [phi; w_B; n_sst;
        n_gyro]``, ``x1 = [SST; GYRO; C; F_ro]`` -> ``(x1+, u)``."""
        d, s = self._design, self._stage1_slices
        rpy, w_B, n_sst, n_gyro = z1[0:3], z1[3:6], z1[6:9], z1[9:12]
        out = np.empty_like(x1)
        sst, gyro, ro, c = d.star_tracker, d.gyro, d.rolloff, d.controller
        out[s[0]], phi_sst = sst.step(x1[s[0]], rpy)
        out[s[1]], w_gyro = gyro.step(x1[s[1]], w_B)
        y_att = -(phi_sst + d.noise_star_tracker * n_sst)
        y_rate = -(w_gyro + d.noise_gyro * n_gyro)
        u_K = self._Kp @ y_att + self._Kd @ y_rate  # the feedthrough D = [K_p, K_d]
        if c.nstates:
            xc = x1[s[2]]
            out[s[2]] = c.A @ xc + c.B @ np.concatenate([y_att, y_rate])
            u_K = u_K + c.C @ xc
        out[s[3]], u = ro.step(x1[s[3]], u_K)
        return out, u

    def _stage2_reference(self, x2, z2, ap: DiscreteBlock):
        """Wheels, disturbance and all-passes ``ap``: ``z2 = [sat(u); d_ext]``,
        ``x2 = [RW; W_n,ext; a_mul; a_add]`` -> ``(x2+, [T_rw; T_dist; a_mul; a_add])``."""
        d, s = self._design, self._stage2_slices
        sat_u, d_ext = z2[0:3], z2[3:6]
        out = np.empty_like(x2)
        rw, dist = d.wheels, d.disturbance
        out[s[0]], T_rw = rw.step(x2[s[0]], sat_u)
        out[s[1]], T_dist = dist.step(x2[s[1]], d_ext)
        out[s[2]], a_mul = ap.step(x2[s[2]], T_rw)
        out[s[3]], a_add = ap.step(x2[s[3]], T_rw)
        return out, np.concatenate([T_rw, T_dist, a_mul, a_add])

    @staticmethod
    def _probe(function, nx: int, nz: int) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D)`` of a linear map ``(x, z) -> (x+, y)`` from its unit responses."""
        columns = [function(e, np.zeros(nz)) for e in np.eye(nx)]
        inputs = [function(np.zeros(nx), e) for e in np.eye(nz)]
        A = np.column_stack([c[0] for c in columns]) if nx else np.zeros((0, 0))
        C = np.column_stack([c[1] for c in columns])
        B = np.column_stack([c[0] for c in inputs])
        D = np.column_stack([c[1] for c in inputs])
        return A, B, C, D

    def _build_stages(self) -> None:
        d, s = self._design, self._slices
        sizes1 = (
            d.star_tracker.nstates,
            d.gyro.nstates,
            d.controller.nstates,
            d.rolloff.nstates,
        )
        self._stage1_slices = _consecutive(sizes1)
        sizes2 = (d.wheels.nstates, d.disturbance.nstates, 3, 3)
        self._stage2_slices = _consecutive(sizes2)
        self._x1 = slice(s["star_tracker"].start, s["rolloff"].stop)
        self._x2 = slice(s["wheels"].start, s["add"].stop)
        assert self._x1.stop - self._x1.start == sum(sizes1)
        assert self._x2.stop - self._x2.start == sum(sizes2)
        A1, B1, C1, D1 = self._probe(self._stage1_reference, sum(sizes1), 12)
        # one product per stage: [x+; y] = M [x; z] (stage 2: per all-pass, _output_stage)
        self._M1 = np.block([[A1, B1], [C1, D1]])
        self._n1, self._n2 = sum(sizes1), sum(sizes2)
        # the update writes the discrete state in one piece: check the layout it assumes
        order = ("tau_W", "log", "metrics", "counter")
        assert [s[name].start for name in order] == [
            self._x2.stop + offset
            for offset in (
                0,
                3,
                3 + 3 * len(LOG_SIGNALS),
                3 + 3 * (len(LOG_SIGNALS) + len(METRIC_SLOTS)),
            )
        ]
        assert self._x1.start == 0 and self._x1.stop == self._x2.start
        self._metrics = s["metrics"]
        self._tau_slice = s["tau_W"]
        self._tau = np.zeros(self._nv)
        self._mix_key, self._mix = None, None

    # -- Drake callbacks ------------------------------------------------------------------------
    def _output_stage(self, perturbation: np.ndarray) -> np.ndarray:
        """Stage 2 extended with the torque mixing for the run's perturbations.

        ``[x2+; T_rw; T_dist; a_mul; a_add; T] = M [x2; sat(u); d_ext]`` with
        ``T = T_rw + (W_mul o Delta_mul) a_mul + delta_add J_ref W_add a_add + T_dist`` and the
        all-passes at the run's frequency. The matrix depends only on the (per-run constant)
        perturbation parameters, so it is kept for the last value seen.
        """
        key = perturbation.tobytes()
        if key != self._mix_key:
            d = self._design
            delta_add, delta_mul = perturbation[0], perturbation[1:10].reshape(3, 3)
            ap = allpass_block(perturbation[10], d.period)
            A2, B2, C2, D2 = self._probe(lambda x, z: self._stage2_reference(x, z, ap), self._n2, 6)
            M2 = np.block([[A2, B2], [C2, D2]])
            eye = np.eye(3)
            mix = np.hstack([eye, eye, d.W_mul * delta_mul, delta_add * self._J_Wadd])
            self._mix = np.vstack([M2, mix @ M2[self._n2 :]])
            self._mix_key = key
        return self._mix

    def _update(self, context, discrete_state):
        x = context.get_discrete_state(self._state_index).get_value()
        plant_x = self._plant_state.Eval(context)
        qs, vs = self._qs, self._nq + self._vs
        rpy = plant_x[qs : qs + 3]
        R_WB = rpy_to_rotation(rpy[0], rpy[1], rpy[2])
        w_B = R_WB.T @ plant_x[vs : vs + 3]
        k = int(x[self._slices["counter"].start])
        noise_table = context.get_abstract_parameter(self._noise_index).get_value()
        noise = noise_table[k % noise_table.shape[0]]
        M2 = self._output_stage(context.get_numeric_parameter(self._perturbation_index).get_value())
        n1, n2 = self._n1, self._n2
        xp = x[self._slices["perturbation"]]
        measured = np.concatenate([rpy, w_B])
        attitude = rpy  # what the metrics see: the analysis' attitude (P_hat's output)
        if xp.size:
            dynamic = context.get_abstract_parameter(self._dynamic_index).get_value()
            measured = measured + dynamic.C[3:] @ xp
            attitude = measured[0:3]  # the hub's plus the realized Delta_add's
        out1 = self._M1 @ np.concatenate([x[self._x1], measured, noise[0:6]])
        u = out1[n1:]
        limit = self._design.torque_limit
        out2 = M2 @ np.concatenate(
            [x[self._x2], np.minimum(np.maximum(u, -limit), limit), noise[6:9]]
        )
        # out2 = [x2+; T_rw; T_dist; a_mul; a_add; T]
        T_rw, T_dist, T = out2[n2 : n2 + 3], out2[n2 + 3 : n2 + 6], out2[n2 + 12 :]
        if xp.size:  # the analysis' P_hat perturbs the plant-input torque T_rw + T_dist
            T_in = T_rw + T_dist
            T = T + dynamic.C[:3] @ xp + dynamic.D[:3] @ T_in
            xp = dynamic.A @ xp + dynamic.B @ T_in
        m = x[self._metrics]
        metrics = np.concatenate(
            [
                np.maximum(m[0:3], np.abs(attitude)),
                np.maximum(m[3:6], np.abs(u)),
                m[6:9] + attitude * attitude,
                np.maximum(m[9:12], np.abs(T)),
            ]
        )
        if not math.isfinite(metrics.sum()):  # entries are >= 0 or NaN
            metrics = np.full_like(metrics, np.inf)
        # state layout: filters of stage 1 and 2, tau_W, log [u, T_rw, T, T_dist], metrics, k,
        # dynamic perturbation
        discrete_state.get_mutable_vector(self._state_index).SetFromVector(
            np.concatenate(
                [out1[:n1], out2[:n2], R_WB @ T, u, T_rw, T, T_dist, metrics, [k + 1.0], xp]
            )
        )

    def _calc_force(self, context, output):
        x = context.get_discrete_state(self._state_index).get_value()
        tau = self._tau
        tau[self._vs : self._vs + 3] = x[self._tau_slice]
        output.SetFromVector(tau)

    def _calc_log(self, context, output):
        x = context.get_discrete_state(self._state_index).get_value()
        output.SetFromVector(x[self._slices["log"]])


def rpy_to_rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation matrix ``R_WB = R_z(yaw) R_y(pitch) R_x(roll)`` of roll-pitch-yaw angles [rad].

    The same convention as Drake's ``RollPitchYaw(rpy).ToRotationMatrix()`` (space-fixed x-y-z),
    computed with scalar math: the flight software calls it at every sample, where the
    round trip through two pydrake objects costs more than the arithmetic.
    """
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )
