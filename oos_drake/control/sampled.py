r"""The flight software's sampled-data loop, exactly, at fixed parameter values.

The Drake mission runs the flight software (``multibody/flight_software.py``) as one periodic
discrete update every ``T = 1 / DesignSpecification.flight_software_rate_hz``: it samples the
hub attitude ``phi`` and rate ``w``, runs the sensors, the gain ``K``, the roll-off and the
wheels as their bilinear (Tustin) discretizations, and holds the torque ``T_rw`` (zero-order
hold) from the sample instant on (no computation delay: ``computation_delay_s = 0``). At fixed
parameter values that loop is exactly a discrete-time linear system:

- the plant ``T -> [phi; w]`` (``P(s)`` with the two integrators) discretized **exactly** with
  a zero-order hold and a computation delay ``tau = m T + tau_f`` (``0 <= tau_f < T``):

  .. math::

      x_{k+1} = \Phi x_k + \Gamma_0 v_k + \Gamma_1 v_{k-1}, \quad v_k = T_{k-m},\quad
      \Phi = e^{AT},\ \Gamma_0 = \int_0^{T-\tau_f} e^{As} ds\, B,\
      \Gamma_1 = e^{A(T-\tau_f)} \int_0^{\tau_f} e^{As} ds\, B;

- the controller chain ``[phi; w] -> T_rw``: the sensors, the roll-off and the wheels
  discretized with the bilinear transform as the flight software does, block by block, and the
  controller ``y -> u_K`` between them at the flight software's rate
  (:meth:`~oos_drake.control.interconnection.ControllerSystem.discretize`: the static gain as
  it is, a continuous dynamic controller by its zero-order hold, a discrete one as tuned).

Its closed-loop eigenvalues ``z`` decide stability (``|z| < 1``); ``log(z) / T`` are the
equivalent continuous poles that :func:`continuous_poles` (the continuous loop, or the rational
hold model of :func:`~oos_drake.control.components.sample_hold` when ``spec.sampled``) is compared
with. Exact discrete-time mu is not available (the zero-order-hold equivalent is not rational in
the uncertain parameters): this module is the exact reference at fixed parameters, used to
measure the error of the rational hold model that keeps the LFR structure.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.linalg
import scipy.signal

from oos_drake.control import components as comp
from oos_drake.control.interconnection import (
    CONTROLS,
    DISTURBANCES,
    ERRORS,
    MEASUREMENTS,
    PLANT_INPUTS,
    PLANT_OUTPUTS,
    ControllerSystem,
    as_controller,
    plant_statespace,
    signal_sums_and_weights,
    weighted_interconnection,
)
from oos_drake.control.statespace import BatchedStateSpace, channel_names, connect

__all__ = [
    "SampledLoop",
    "continuous_poles",
    "discrete_controller_chain",
    "sampled_interconnection",
    "sampled_loop",
    "spectral_abscissa",
]


def _series(first, second) -> tuple[np.ndarray, ...]:
    """``second after first`` for state-space tuples ``(A, B, C, D)``."""
    A1, B1, C1, D1 = first
    A2, B2, C2, D2 = second
    n1, n2 = A1.shape[0], A2.shape[0]
    A = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    return A, np.vstack([B1, B2 @ D1]), np.hstack([D2 @ C1, C2]), D2 @ D1


def controller_chain(K, spec: comp.DesignSpecification) -> tuple[np.ndarray, ...]:
    """Continuous ``(A, B, C, D)`` of ``[phi; w] (6) -> T_rw (3)``: sensors, K, roll-off, wheels.

    ``u = F_ro C(s) [-(SST phi); -(GYRO w)]``, ``T_rw = RW u`` (noise-free, reference zero);
    ``K`` a 3x6 gain or a ``ControllerSystem`` (a discrete one by its continuous form).
    """
    sensors, (rolloff, wheels) = _chain_parts(spec)
    gain = _negated(as_controller(K).continuous())
    return _series(_series(_series(sensors, gain), rolloff), wheels)


def _chain_parts(spec: comp.DesignSpecification):
    """Continuous sensors ``[phi; w] -> [phi_sst; w_gyro]`` and per-axis ``(F_ro, RW)``."""
    sst, gyro, rolloff, wheels = (comp.per_axis(f) for f in comp.filters(spec))
    sensors = tuple(scipy.linalg.block_diag(a, b) for a, b in zip(sst, gyro, strict=True))
    return sensors, (rolloff, wheels)


def _negated(controller: ControllerSystem) -> tuple[np.ndarray, ...]:
    """``(A, B, C, D)`` of ``[phi_sst; w_gyro] -> u_K`` (``y`` is minus the sensor outputs)."""
    return controller.A, controller.B, -controller.C, -controller.D


def discrete_controller_chain(K, spec: comp.DesignSpecification) -> tuple[np.ndarray, ...]:
    """Discrete ``(A, B, C, D)`` of ``[phi; w] -> T_rw`` as the flight software runs it.

    The sensors, the roll-off and the wheels by the bilinear transform at
    ``T = 1 / spec.flight_software_rate_hz``, the controller ``y -> u_K`` at ``T`` between them
    (:meth:`ControllerSystem.discretize`). For a static gain this equals the bilinear transform
    of :func:`controller_chain` (a cascade of Tustin blocks is the Tustin transform of the
    cascade).
    """
    T = 1.0 / spec.flight_software_rate_hz
    sensors, (rolloff, wheels) = _chain_parts(spec)
    controller = as_controller(K).discretize(T)

    def tustin(block):
        if np.size(block[0]) == 0:
            return block
        return scipy.signal.cont2discrete(block, T, method="bilinear")[:4]

    return _series(_series(tustin(sensors), _negated(controller)), tustin(_series(rolloff, wheels)))


def _tustin_axes(siso, period: float, name_in: str, name_out: str) -> BatchedStateSpace:
    """A SISO filter on three axes, discretized with the bilinear transform at ``period`` [s]
    (as the flight software's ``discretize``)."""
    A, B, C, D = comp.per_axis(siso)
    if A.size:
        A, B, C, D, _ = scipy.signal.cont2discrete((A, B, C, D), period, method="bilinear")
    return BatchedStateSpace(A, B, C, D, channel_names(name_in, 3), channel_names(name_out, 3))


def sampled_interconnection(
    plant: BatchedStateSpace, spec: comp.DesignSpecification | None = None
) -> BatchedStateSpace:
    r"""The weighted interconnection ``P_tot`` as the flight software runs it, discrete at ``T``.

    Same signals as :func:`~oos_drake.control.interconnection.weighted_interconnection`
    (inputs ``d`` and ``u_K``, outputs ``e`` and ``y``), every block as the Drake mission's
    flight software has it at ``T = 1 / spec.flight_software_rate_hz``: the sensors, the
    roll-off, the wheels and the disturbance weight ``W_n,ext`` by the bilinear transform, the
    torque ``T = T_rw + T_dist`` held over the period, the plant ``T -> [phi; w]`` (``P(s)``
    with its two integrators) discretized **exactly** with that zero-order hold. A discrete
    controller ``y -> u_K`` at ``T`` closed on it is exactly the loop of :func:`sampled_loop`
    (same poles, same loop gain at the wheel input), so goals tuned on it hold for the
    flight software; ``d_ext`` enters as a held sequence and ``e_p`` is ``phi`` at the
    sample instants.

    Parameters
    ----------
    plant : BatchedStateSpace
        Plant array ``T [N m] -> wdot [rad/s^2]`` (3x3, batch dimensions allowed).
    spec : DesignSpecification, optional
        Components, weights and ``flight_software_rate_hz`` [Hz]; ``computation_delay_s`` must
        be 0 (``sampled`` is not read).

    Returns
    -------
    BatchedStateSpace
        The discrete model ``x_{k+1} = A x_k + B [d; u_K]_k``, ``[e; y]_k = C x_k + D [d; u_K]_k``.

    Raises
    ------
    ValueError
        A nonzero computation delay (not modelled here).
    """
    spec = spec or comp.DesignSpecification()
    if spec.computation_delay_s != 0:
        raise ValueError(
            f"sampled_interconnection: computation_delay_s = {spec.computation_delay_s} s is not "
            "modelled (the discrete design assumes the torque held from the sample instant)"
        )
    T = 1.0 / spec.flight_software_rate_hz
    v = channel_names
    if plant.inputs != PLANT_INPUTS or plant.outputs != PLANT_OUTPUTS:
        plant = plant_statespace(plant.A, plant.B, plant.C, plant.D)
    continuous = connect(
        [plant, comp.integrator("wdot", "w"), comp.integrator("w", "phi")],
        PLANT_INPUTS,
        v("phi", 3) + v("w", 3),
    )
    A, B = (np.asarray(M, dtype=float) for M in (continuous.A, continuous.B))
    n, m = A.shape[-1], B.shape[-1]
    M = np.zeros(A.shape[:-2] + (n + m, n + m))
    M[..., :n, :n], M[..., :n, n:] = A, B
    E = np.stack([scipy.linalg.expm(Mi * T) for Mi in M.reshape((-1, n + m, n + m))])
    E = E.reshape(M.shape)
    held = BatchedStateSpace(
        E[..., :n, :n],
        E[..., :n, n:],
        continuous.C,
        continuous.D,
        continuous.inputs,
        continuous.outputs,
    )
    sst, gyro, rolloff, wheels = comp.filters(spec)
    W_ext = comp.disturbance_weight(spec, "d_ext", "T_dist")
    Wd = scipy.signal.cont2discrete((W_ext.A, W_ext.B, W_ext.C, W_ext.D), T, method="bilinear")
    parts = [
        held,
        _tustin_axes(sst, T, "phi", "phi_sst"),
        _tustin_axes(gyro, T, "w", "w_gyro"),
        _tustin_axes(rolloff, T, "u_K", "u"),
        _tustin_axes(wheels, T, "u", "T_rw"),
        BatchedStateSpace(*Wd[:4], v("d_ext", 3), v("T_dist", 3)),
        *signal_sums_and_weights(spec),
    ]
    return connect(parts, DISTURBANCES + CONTROLS, ERRORS + MEASUREMENTS)


def plant_with_integrators(plant) -> tuple[np.ndarray, ...]:
    """``(A, B, C)`` of ``T -> [phi; w]`` from a certain plant ``T -> wdot`` (states
    ``[x; w; phi]``).

    Parameters
    ----------
    plant : LFR without uncertain blocks, state space, or tuple ``(A, B, C, D)``
        Certain 3x3 plant ``T [N m] -> wdot [rad/s^2]``.
    """
    return _with_integrators(*_matrices(plant, "plant_with_integrators"))


def _with_integrators(A, B, C, D) -> tuple[np.ndarray, ...]:
    n = A.shape[0]
    Aa = np.zeros((n + 6, n + 6))
    Aa[:n, :n] = A
    Aa[n : n + 3, :n] = C
    Aa[n + 3 :, n : n + 3] = np.eye(3)
    Ba = np.vstack([B, D, np.zeros((3, 3))])
    Ca = np.zeros((6, n + 6))
    Ca[:3, n + 3 :] = np.eye(3)
    Ca[3:, n : n + 3] = np.eye(3)
    return Aa, Ba, Ca


def _hold_integral(A, B, t) -> tuple[np.ndarray, np.ndarray]:
    """``(e^{At}, int_0^t e^{As} ds B)`` from one matrix exponential."""
    n, m = B.shape
    E = scipy.linalg.expm(np.block([[A, B], [np.zeros((m, n + m))]]) * t)
    return E[:n, :n], E[:n, n:]


@dataclasses.dataclass(frozen=True, eq=False)
class SampledLoop:
    """The exact sampled-data loop at one parameter value (see the module docstring).

    Attributes
    ----------
    period : float
        Sample period ``T`` [s].
    Phi, Gamma0, Gamma1, C : ndarray
        Zero-order-hold plant ``T -> [phi; w]`` (states ``[x; w; phi]``) [-, -, -, -].
    shift : int
        Whole samples ``m`` of the computation delay.
    controller : tuple of ndarray
        Discrete ``(A, B, C, D)`` of the controller chain ``[phi; w] -> T_rw``
        (:func:`discrete_controller_chain`).
    K : ControllerSystem
        The controller ``y -> u_K`` at the period ``T`` (the static gain: no states).
    spec : DesignSpecification
    """

    period: float
    Phi: np.ndarray
    Gamma0: np.ndarray
    Gamma1: np.ndarray
    C: np.ndarray
    shift: int
    controller: tuple
    K: ControllerSystem
    spec: comp.DesignSpecification

    def closed_loop(self) -> np.ndarray:
        """Discrete closed-loop state matrix (states ``[x_p; x_c; T_{k-1} .. T_{k-m-1}]``)."""
        Ac, Bc, Cc, Dc = self.controller
        n, nc, m = self.Phi.shape[0], Ac.shape[0], self.shift
        nb = 3 * (m + 1)  # past commands T_{k-1} .. T_{k-m-1}
        N = n + nc + nb
        # T_k = Cc x_c + Dc C x_p  as a row block over the whole state
        Tk = np.zeros((3, N))
        Tk[:, :n] = Dc @ self.C
        Tk[:, n : n + nc] = Cc
        buffer = [np.zeros((3, N)) for _ in range(m + 1)]
        for i in range(m + 1):
            buffer[i][:, n + nc + 3 * i : n + nc + 3 * i + 3] = np.eye(3)
        v_now = Tk if m == 0 else buffer[m - 1]  # v_k = T_{k-m}
        v_last = buffer[m]  # v_{k-1} = T_{k-m-1}
        A = np.zeros((N, N))
        A[:n] = self.Gamma0 @ v_now + self.Gamma1 @ v_last
        A[:n, :n] += self.Phi
        A[n : n + nc] = Bc @ self.C @ np.eye(n, N) + Ac @ np.eye(N)[n : n + nc]
        A[n + nc : n + nc + 3] = Tk
        for i in range(1, m + 1):
            A[n + nc + 3 * i : n + nc + 3 * i + 3] = buffer[i - 1]
        return A

    def poles(self) -> np.ndarray:
        """Equivalent continuous closed-loop poles ``log(z) / T`` [rad/s] (``z = 0`` dropped)."""
        z = np.linalg.eigvals(self.closed_loop())
        z = z[np.abs(z) > 1e-12]
        return np.log(z.astype(complex)) / self.period

    def loop_gain(self, omega) -> np.ndarray:
        """Loop ``L(e^{j omega T})`` (F, 3, 3) broken at the wheel input ``u`` (``u = -L u``).

        The Tustin blocks are evaluated at ``s_w = j (2/T) tan(omega T / 2)`` (exact for the
        bilinear transform), the discrete controller at ``z``; the plant by one solve per
        frequency. ``omega`` [rad/s] in ``(0, pi / T]``.
        """
        spec, T = self.spec, self.period
        omega = np.atleast_1d(np.asarray(omega, dtype=float))
        z = np.exp(1j * omega * T)
        w_w = (2.0 / T) * np.tan(np.minimum(omega * T / 2.0, np.pi / 2 - 1e-9))  # s_w = j w_w
        n = self.Phi.shape[0]
        M = z[:, None, None] * np.eye(n) - self.Phi
        rhs = (self.Gamma0 + self.Gamma1 / z[:, None, None]) * z[:, None, None] ** (-self.shift)
        G = self.C @ np.linalg.solve(M, rhs)  # (F, 6, 3): T -> [phi; w]
        sst, gyro, rolloff, wheels = comp.filters(spec)
        sensors = np.concatenate(
            [np.repeat(_siso(sst, w_w)[:, None], 3, 1), np.repeat(_siso(gyro, w_w)[:, None], 3, 1)],
            axis=1,
        )
        c = _siso(rolloff, w_w) * _siso(wheels, w_w)
        gain = self.K.D if self.K.is_static else self.K.response(z)
        return c[:, None, None] * ((gain * sensors[:, None, :]) @ G)


def _siso(siso, omega) -> np.ndarray:
    """Response of a SISO ``(A, B, C, D)`` at ``j omega`` (``omega`` [rad/s])."""
    return BatchedStateSpace(*siso, ("in",), ("out",)).freqresp(omega)[:, 0, 0]


def sampled_loop(plant, K, spec: comp.DesignSpecification | None = None) -> SampledLoop:
    """The exact sampled-data loop of a certain plant ``T -> wdot`` (3x3).

    Parameters
    ----------
    plant : tuple ``(A, B, C, D)`` or an object with ``A, B, C, D`` attributes
        Certain plant ``T [N m] -> wdot [rad/s^2]`` (an LFR without blocks works).
    K : array_like, shape (3, 6), or ControllerSystem
        ``[K_p, K_d]`` [N m/rad, N m s/rad], or a linear controller ``y -> u_K`` (continuous:
        run as its zero-order hold at the flight software's rate; discrete: at that rate).
    spec : DesignSpecification, optional
        Components, ``flight_software_rate_hz`` and ``computation_delay_s`` (``sampled`` is
        not read: this is the exact loop whatever the continuous model).
    """
    spec = spec or comp.DesignSpecification()
    A, B, C, D = _matrices(plant)
    T = 1.0 / spec.flight_software_rate_hz
    try:
        controller = as_controller(K).discretize(T)
    except ValueError as exc:
        raise ValueError(f"sampled_loop: {exc}") from exc
    Aa, Ba, Ca = _with_integrators(A, B, C, D)
    shift = int(np.floor(spec.computation_delay_s / T + 1e-12))
    frac = max(spec.computation_delay_s - shift * T, 0.0)
    E_late, Gamma0 = _hold_integral(Aa, Ba, T - frac)
    _, early = _hold_integral(Aa, Ba, frac)
    Phi = E_late @ scipy.linalg.expm(Aa * frac)
    Gamma1 = E_late @ early
    chain = discrete_controller_chain(controller, spec)
    return SampledLoop(T, Phi, Gamma0, Gamma1, Ca, shift, chain, controller, spec)


def _matrices(plant, who: str = "sampled_loop") -> tuple[np.ndarray, ...]:
    """``(A, B, C, D)`` of a certain 3x3 plant (a tuple, a state space or an LFR w/o blocks)."""
    if isinstance(plant, tuple):
        A, B, C, D = plant
    else:
        if getattr(plant, "nw", 0):
            raise ValueError(f"{who}: the plant still has uncertain blocks; substitute them")
        A, B, C, D = plant.A, plant.B, plant.C, plant.D
    A, B, C, D = (np.asarray(m, dtype=float) for m in (A, B, C, D))
    if D.shape != (3, 3):
        raise ValueError(f"{who}: the plant must be 3x3 (T -> wdot), got {D.shape}")
    return A, B, C, D


def continuous_poles(plant, K, spec: comp.DesignSpecification | None = None) -> np.ndarray:
    """Closed-loop poles [rad/s] of the continuous loop model (with the rational hold model
    when ``spec.sampled``), disturbance-weight poles excluded.

    The weighted interconnection's closed loop (:mod:`oos_drake.control.interconnection`) also
    holds the poles of ``W_n,ext`` (``-b/a``), which are not poles of the feedback loop; they
    are removed so the comparison with :meth:`SampledLoop.poles` is one to one.
    """
    spec = spec or comp.DesignSpecification()
    A, B, C, D = _matrices(plant)
    closed = weighted_interconnection(plant_statespace(A, B, C, D), spec).close(as_controller(K))
    poles = np.linalg.eigvals(closed.A)
    a, b = spec.disturbance_denominator
    drop = np.argsort(np.abs(poles + b / a))[:3]
    return np.delete(poles, drop)


def spectral_abscissa(poles) -> float:
    """Largest real part of ``poles`` [rad/s]."""
    return float(np.max(np.real(poles)))
