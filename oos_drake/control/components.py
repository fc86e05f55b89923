"""Sensors, actuators, roll-off filter and the weights of the paper's control design (section 3).

All values default to the paper's (Fig. controldesign, Eq. controlreq), which are also the
``[control]`` section of the paper's scenario file (``DesignSpecification.from_requirements``
reads any scenario's; a test keeps the two equal). Every component is a
per-axis SISO model replicated on the three axes, returned as a named
:class:`~oos_drake.control.statespace.BatchedStateSpace`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.signal

from oos_drake.control.statespace import BatchedStateSpace, channel_names

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class DesignSpecification:
    """Sensor, actuator, filter and weight data of the attitude-control design.

    Parameters
    ----------
    star_tracker_cutoff_hz : float
        Star tracker first-order low-pass cut-off [Hz] (paper: 8).
    gyro_cutoff_hz : float
        Gyroscope first-order low-pass cut-off [Hz] (paper: 200).
    wheel_frequency_hz : float
        Reaction-wheel second-order natural frequency [Hz] (paper: 200).
    wheel_damping : float
        Reaction-wheel damping ratio [-] (paper: 0.7).
    rolloff_order : int
        Order of the Butterworth roll-off on the command (paper: 4).
    rolloff_cutoff_hz : float
        Roll-off cut-off [Hz] (paper: 0.7).
    noise_gyro : float
        Gyro noise weight W_n,gyro [rad/s] (paper: 9.1987e-4, times I3).
    noise_star_tracker : float
        Star-tracker noise weight W_n,sst [rad] (paper: 1.5343e-5, times I3).
    disturbance_gains : tuple of float
        Numerators of W_n,ext = diag(g_i) / (a s + b) [N m] (paper: 0.002577, 0.009685, 0.01239).
    disturbance_denominator : tuple of float
        ``(a, b)`` of W_n,ext's denominator [s, -] (paper: 2.236, 0.2236).
    pointing_requirement : float
        Absolute pointing error bound W_p [rad] (paper: 0.0079); ``e_p = phi / W_p``.
    control_weight : float
        W_u [1/(N m)] (paper: 0.5, i.e. a 2 N m bound); ``e_u = W_u u``.
    additive_weight_db : float
        W_add of Delta_add (full 3x3 LTI, analysis only) [dB] (paper: -75).
    multiplicative_diagonal : float
        W_mul,L on the diagonal LTI scalars of Delta_mul (analysis only) [-] (paper: 4e-2).
    multiplicative_off_diagonal : float
        W_mul,R on the off-diagonal LTI scalars of Delta_mul (analysis only) [-] (paper: 4e-3).
    flight_software_rate_hz : float
        Sample rate of the flight software [Hz] (10: the Drake mission's default
        ``MissionOptions.control_rate`` reads it here). The one place that holds the rate.
    computation_delay_s : float
        Delay between a sample and the torque computed from it [s]. 0: the flight software
        (``multibody/flight_software.py``) writes the torque at the sample instant itself.
    sampled : bool
        Model the flight software's sample-and-hold in the loop (:func:`sample_hold`, between
        the reaction wheels and the plant); ``False`` (default): the continuous loop of the
        paper.
    hold_order : int
        Order of the rational (Pade-type) approximation of the hold and of the delay
        (:func:`sample_hold`).
    """

    star_tracker_cutoff_hz: float = 8.0
    gyro_cutoff_hz: float = 200.0
    wheel_frequency_hz: float = 200.0
    wheel_damping: float = 0.7
    rolloff_order: int = 4
    rolloff_cutoff_hz: float = 0.7
    noise_gyro: float = 9.1987e-4
    noise_star_tracker: float = 1.5343e-5
    disturbance_gains: tuple[float, float, float] = (0.002577, 0.009685, 0.01239)
    disturbance_denominator: tuple[float, float] = (2.236, 0.2236)
    pointing_requirement: float = 0.0079
    control_weight: float = 0.5
    additive_weight_db: float = -75.0
    multiplicative_diagonal: float = 4e-2
    multiplicative_off_diagonal: float = 4e-3
    flight_software_rate_hz: float = 10.0
    computation_delay_s: float = 0.0
    sampled: bool = False
    hold_order: int = 2

    def __post_init__(self):
        for name in (
            "star_tracker_cutoff_hz",
            "gyro_cutoff_hz",
            "wheel_frequency_hz",
            "wheel_damping",
            "rolloff_cutoff_hz",
            "noise_gyro",
            "noise_star_tracker",
            "pointing_requirement",
            "control_weight",
            "flight_software_rate_hz",
        ):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"DesignSpecification.{name} must be positive, got {value!r}")
        if self.rolloff_order < 1:
            raise ValueError(
                f"DesignSpecification.rolloff_order must be >= 1, got {self.rolloff_order}"
            )
        if not (np.isfinite(self.computation_delay_s) and self.computation_delay_s >= 0):
            raise ValueError(
                "DesignSpecification.computation_delay_s must be >= 0 s, got "
                f"{self.computation_delay_s!r}"
            )
        if self.hold_order not in (1, 2, 3, 4):
            raise ValueError(
                f"DesignSpecification.hold_order must be 1..4, got {self.hold_order!r}"
            )
        if len(self.disturbance_gains) != 3 or len(self.disturbance_denominator) != 2:
            raise ValueError("DesignSpecification.disturbance_gains needs 3 values, denominator 2")

    @classmethod
    def from_requirements(cls, control) -> DesignSpecification:
        """The specification of a scenario's ``[control]`` section.

        Parameters
        ----------
        control : oos_drake.scenario.data.ControlRequirements
            ``scenario.control``; the control weight is ``W_u = 1 / torque_limit`` [1/(N m)].
        """
        return cls(
            star_tracker_cutoff_hz=control.star_tracker_cutoff_hz,
            gyro_cutoff_hz=control.gyro_cutoff_hz,
            wheel_frequency_hz=control.wheel_frequency_hz,
            wheel_damping=control.wheel_damping,
            rolloff_order=control.rolloff_order,
            rolloff_cutoff_hz=control.rolloff_cutoff_hz,
            noise_gyro=control.gyro_noise,
            noise_star_tracker=control.star_tracker_noise,
            disturbance_gains=tuple(control.disturbance_gains),
            disturbance_denominator=tuple(control.disturbance_denominator),
            pointing_requirement=control.pointing_requirement,
            control_weight=1.0 / control.torque_limit,
            additive_weight_db=control.additive_weight_db,
            multiplicative_diagonal=control.multiplicative_diagonal,
            multiplicative_off_diagonal=control.multiplicative_off_diagonal,
            flight_software_rate_hz=control.flight_software_rate_hz,
        )

    @property
    def additive_weight(self) -> float:
        """W_add as a gain [(rad/s^2)/(N m)] (10^(dB/20))."""
        return 10.0 ** (self.additive_weight_db / 20.0)

    def to_dict(self) -> dict:
        """Return the specification as a JSON-ready dict."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}

    def design_data(self) -> dict:
        """:meth:`to_dict` without the loop model (``sampled``, ``computation_delay_s``,
        ``hold_order``: how the synthesis modelled the flight software, set by ``oos synth
        --sampled``/``--delay`` or ``[control] rate_hz``): the sensors, actuators, weights and
        rate that belong to the spacecraft and its requirements."""
        loop_model = ("sampled", "computation_delay_s", "hold_order")
        return {k: v for k, v in self.to_dict().items() if k not in loop_model}


def first_order_lowpass(cutoff_hz: float) -> tuple[np.ndarray, ...]:
    """Return ``(A, B, C, D)`` of ``1 / (s / w_c + 1)``, ``w_c = 2 pi cutoff_hz`` [rad/s]."""
    wc = TWO_PI * cutoff_hz
    return np.array([[-wc]]), np.array([[wc]]), np.array([[1.0]]), np.array([[0.0]])


def second_order(frequency_hz: float, damping: float) -> tuple[np.ndarray, ...]:
    """Return ``(A, B, C, D)`` of ``w^2 / (s^2 + 2 xi w s + w^2)`` (unit DC gain)."""
    w = TWO_PI * frequency_hz
    A = np.array([[0.0, w], [-w, -2.0 * damping * w]])
    return A, np.array([[0.0], [w]]), np.array([[1.0, 0.0]]), np.array([[0.0]])


def butterworth(order: int, cutoff_hz: float) -> tuple[np.ndarray, ...]:
    """Return ``(A, B, C, D)`` of the analog Butterworth low-pass (scipy.signal.butter).

    Realized from zeros/poles/gain, balanced by a diagonal similarity for conditioning.
    """
    z, p, k = scipy.signal.butter(order, TWO_PI * cutoff_hz, analog=True, output="zpk")
    A, B, C, D = scipy.signal.zpk2ss(z, p, k)
    # diagonal scaling: companion forms carry w_c^k entries
    scale = np.abs(TWO_PI * cutoff_hz) ** np.arange(A.shape[0])[::-1]
    T, Ti = np.diag(scale), np.diag(1.0 / scale)
    return Ti @ A @ T, Ti @ B, C @ T, D


@functools.lru_cache(maxsize=8)
def filters(spec: DesignSpecification) -> tuple[tuple[np.ndarray, ...], ...]:
    """SISO ``(A, B, C, D)`` of the star tracker, gyro, roll-off and wheels (cached per spec)."""
    return (
        first_order_lowpass(spec.star_tracker_cutoff_hz),
        first_order_lowpass(spec.gyro_cutoff_hz),
        butterworth(spec.rolloff_order, spec.rolloff_cutoff_hz),
        second_order(spec.wheel_frequency_hz, spec.wheel_damping),
    )


def sample_hold(spec: DesignSpecification) -> tuple[np.ndarray, ...]:
    r"""``(A, B, C, D)`` of the rational model of the flight software's sample-and-hold.

    A signal sampled every ``T = 1 / flight_software_rate_hz`` and held (zero-order hold) after
    a computation delay ``tau = computation_delay_s`` reaches the plant, at frequencies well
    below the Nyquist frequency, through

    .. math::

        H(s) = \frac{1 - e^{-sT}}{sT}\, e^{-s\tau}
        \approx \frac{1 - R_n(sT)}{sT}\, R_n(s\tau),

    with ``R_n`` the ``(n, n)`` Pade approximant of ``e^{-x}`` (``n = hold_order``,
    python-control's :func:`control.pade`). ``1 - R_n(x)`` has no constant term, so the hold
    factor is a strictly proper rational function of order ``n`` (``n = 2``:
    ``1 / (1 + sT/2 + (sT)^2/12)``), exact in gain AND phase to ``O((wT)^{2n})``: it keeps the
    hold's ``sinc`` droop (-0.1 dB at 0.83 Hz, 10 Hz) with its half-sample lag
    (``-w T / 2``: 15 deg at 0.83 Hz). What it omits are the aliases of the sampled signal, which
    the flight software's 0.7 Hz roll-off and the plant's double integrator attenuate by
    ``(f / f_s)^2`` and more. ``tests/control/test_sampled.py`` measures the error against the
    exact sampled-data loop.

    Returns
    -------
    tuple of ndarray
        SISO ``(A, B, C, D)`` [-], unit DC gain; ``(0 x 0, ..., D = 1)`` when ``spec.sampled``
        is false.
    """
    import control

    if not spec.sampled:
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.ones((1, 1))
    n, T, tau = spec.hold_order, 1.0 / spec.flight_software_rate_hz, spec.computation_delay_s
    num, den = control.pade(T, n)  # e^{-sT} ~ num / den, highest power first
    hold = control.tf(np.polysub(den, num)[:-1] / T, den)  # (1 - e^{-sT}) / (sT)
    if tau > 0:
        hold = hold * control.tf(*control.pade(tau, n))
    ss = control.ss(hold)
    return tuple(np.atleast_2d(np.asarray(m, dtype=float)) for m in (ss.A, ss.B, ss.C, ss.D))


def per_axis(siso) -> tuple[np.ndarray, ...]:
    """Block-diagonal replication ``kron(I3, M)`` of a SISO ``(A, B, C, D)`` on three axes."""
    return tuple(np.kron(np.eye(3), np.atleast_2d(np.asarray(m, dtype=float))) for m in siso)


def _axes(siso, name_in: str, name_out: str) -> BatchedStateSpace:
    return BatchedStateSpace(*per_axis(siso), channel_names(name_in, 3), channel_names(name_out, 3))


def star_tracker(spec: DesignSpecification, name_in="phi", name_out="phi_sst"):
    """Star tracker ``SST``: first-order low-pass on each attitude angle [rad -> rad]."""
    return _axes(first_order_lowpass(spec.star_tracker_cutoff_hz), name_in, name_out)


def gyro(spec: DesignSpecification, name_in="w", name_out="w_gyro"):
    """Gyroscope ``GYRO``: first-order low-pass on each rate [rad/s -> rad/s]."""
    return _axes(first_order_lowpass(spec.gyro_cutoff_hz), name_in, name_out)


def reaction_wheels(spec: DesignSpecification, name_in="u", name_out="T_rw"):
    """Reaction wheels ``RW``: second-order torque response per axis [N m -> N m]."""
    return _axes(second_order(spec.wheel_frequency_hz, spec.wheel_damping), name_in, name_out)


def rolloff_filter(spec: DesignSpecification, name_in="u_K", name_out="u"):
    """Roll-off ``F_ro``: Butterworth low-pass on each controller output [N m -> N m]."""
    return _axes(butterworth(spec.rolloff_order, spec.rolloff_cutoff_hz), name_in, name_out)


def hold(spec: DesignSpecification, name_in="T_rw_c", name_out="T_rw"):
    """Sample-and-hold of the flight software (:func:`sample_hold`) on each torque [N m -> N m]."""
    return _axes(sample_hold(spec), name_in, name_out)


def disturbance_weight(spec: DesignSpecification, name_in="d_ext", name_out="T_dist"):
    """``W_n,ext = diag(g_i) / (a s + b)``: normalized disturbance -> torque [N m]."""
    a, b = spec.disturbance_denominator
    gains = np.asarray(spec.disturbance_gains, dtype=float)
    A = -(b / a) * np.eye(3)
    B = np.eye(3)
    C = np.diag(gains / a)
    return BatchedStateSpace(
        A, B, C, np.zeros((3, 3)), channel_names(name_in, 3), channel_names(name_out, 3)
    )


def integrator(name_in: str, name_out: str) -> BatchedStateSpace:
    """Three integrators ``1/s`` (rate from acceleration, attitude from rate)."""
    return BatchedStateSpace(
        np.zeros((3, 3)),
        np.eye(3),
        np.eye(3),
        np.zeros((3, 3)),
        channel_names(name_in, 3),
        channel_names(name_out, 3),
    )


def static_gain(gain, name_in: str, name_out: str) -> BatchedStateSpace:
    """Static 3x3 gain (scalar times I3, or a matrix)."""
    D = np.asarray(gain, dtype=float)
    if D.ndim == 0:
        D = D * np.eye(3)
    return BatchedStateSpace.static(D, channel_names(name_in, 3), channel_names(name_out, 3))
