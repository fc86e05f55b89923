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
paper's ``u = K_att [phi_ref - phi; w_ref - w]``, or any linear controller ``y -> u_K``
(:class:`ControllerSystem`: a PID per axis, a fixed-order state space, continuous or discrete
at the flight software's rate; the static gain is the one without states). The closed loop
``M = F_l(P_tot, K)`` maps ``d -> e``; the synthesis goal is ``||M||_inf < 1`` (Eq.
controlreq).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg

from oos_drake.control import components as comp
from oos_drake.control.loop_response import LoopResponse
from oos_drake.control.statespace import BatchedStateSpace, channel_names, connect, sum_block

DISTURBANCES = channel_names("d_ext", 3) + channel_names("n_sst", 3) + channel_names("n_gyro", 3)
CONTROLS = channel_names("u_K", 3)
ERRORS = channel_names("e_p", 3) + channel_names("e_u", 3)
MEASUREMENTS = channel_names("y_att", 3) + channel_names("y_rate", 3)
PLANT_INPUTS = channel_names("T", 3)
PLANT_OUTPUTS = channel_names("wdot", 3)
#: Controller structures of ``controller.json`` (``[control] structure``).
STRUCTURES = ("static", "pid", "state-space")


@dataclass(frozen=True, eq=False)
class ControllerSystem:
    r"""A linear attitude controller ``y (6) -> u_K (3)``, continuous or discrete.

    .. math::

        \dot x \ (\text{or } x_{k+1}) = A x + B y, \qquad u_K = C x + D y,

    with ``y = [y_att; y_rate]`` (:data:`MEASUREMENTS`: [rad], [rad/s]) and ``u_K``
    (:data:`CONTROLS`, [N m]) the command in front of the roll-off. The static gain
    ``[K_p, K_d]`` is the controller without states (:meth:`static`); every stage downstream of
    the synthesis (analysis, margins, confirmation, flight software, campaign) takes this one
    type.

    Attributes
    ----------
    A, B, C, D : numpy.ndarray
        Shapes ``(n, n)``, ``(n, 6)``, ``(3, n)``, ``(3, 6)``; units of ``B``, ``C``, ``D``
        those of ``u_K`` over ``y`` (``D = [K_p, K_d]``: [N m/rad], [N m s/rad]).
    sampling_time : float
        ``0`` for a continuous controller, else its sample period [s] (discrete ``A``).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    sampling_time: float = 0.0

    #: Signals read and driven, in order.
    inputs = MEASUREMENTS
    outputs = CONTROLS

    def __post_init__(self):
        D = np.array(self.D, dtype=float, ndmin=2)
        n = int(np.size(self.A) and np.shape(self.A)[0])
        A = np.array(self.A, dtype=float).reshape(n, n)
        B = np.array(self.B, dtype=float).reshape((n, -1) if n else (0, D.shape[1]))
        C = np.array(self.C, dtype=float).reshape((-1, n) if n else (D.shape[0], 0))
        if D.shape != (3, 6) or B.shape != (n, 6) or C.shape != (3, n):
            raise ValueError(
                f"controller: must map y (6) to u_K (3), got B {B.shape}, C {C.shape}, D {D.shape}"
            )
        if not all(np.all(np.isfinite(M)) for M in (A, B, C, D)):
            raise ValueError("controller: A, B, C, D must be finite")
        ts = float(self.sampling_time)
        if not (np.isfinite(ts) and ts >= 0):
            raise ValueError(f"controller: sampling_time must be >= 0 s, got {self.sampling_time}")
        for name, M in zip("ABCD", (A, B, C, D), strict=True):
            M.setflags(write=False)
            object.__setattr__(self, name, M)
        object.__setattr__(self, "sampling_time", ts)

    @classmethod
    def static(cls, K) -> ControllerSystem:
        """The static gain ``u_K = K y`` (``K = [K_p, K_d]``, 3x6) as a controller."""
        K = np.asarray(K, dtype=float)
        if K.shape != (3, 6):
            raise ValueError(f"controller gain K must be 3x6, got shape {K.shape}")
        return cls(np.zeros((0, 0)), np.zeros((0, 6)), np.zeros((3, 0)), K)

    @classmethod
    def from_named(
        cls, A, B, C, D, inputs, outputs, sampling_time: float = 0.0
    ) -> ControllerSystem:
        """A controller from matrices with named channels (a subset of ``y``, every ``u_K``).

        ``inputs`` must be names of :data:`MEASUREMENTS` (the columns of ``y`` it does not read
        are zero, e.g. a PID on ``y_att`` alone), ``outputs`` the three :data:`CONTROLS` in any
        order.

        Raises
        ------
        ValueError
            A channel that is not a measurement or a control (named), a missing control.
        """
        inputs, outputs = [str(n) for n in inputs], [str(n) for n in outputs]
        unknown = [n for n in inputs if n not in MEASUREMENTS]
        unknown += [n for n in outputs if n not in CONTROLS]
        if unknown:
            raise ValueError(
                f"controller: channel {unknown[0]!r} is not a measurement {MEASUREMENTS} or a "
                f"control {CONTROLS}"
            )
        if sorted(outputs) != sorted(CONTROLS):
            raise ValueError(f"controller: must drive every control {CONTROLS}, got {outputs}")
        D = np.array(D, dtype=float, ndmin=2).reshape(len(outputs), len(inputs))
        n = int(np.size(A) and np.shape(A)[0])
        B = np.array(B, dtype=float).reshape(n, len(inputs))
        C = np.array(C, dtype=float).reshape(len(outputs), n)
        cols = [MEASUREMENTS.index(name) for name in inputs]
        rows = [outputs.index(name) for name in CONTROLS]
        B6, D6 = np.zeros((n, 6)), np.zeros((len(outputs), 6))
        B6[:, cols], D6[:, cols] = B, D
        return cls(np.reshape(A, (n, n)), B6, C[rows], D6[rows], sampling_time)

    @classmethod
    def from_statespace(cls, system) -> ControllerSystem:
        """From a python-control ``StateSpace`` with named inputs and outputs (``dt`` kept)."""
        dt = system.dt
        ts = 0.0 if not dt or dt is True else float(dt)
        return cls.from_named(
            system.A, system.B, system.C, system.D, system.input_labels, system.output_labels, ts
        )

    @property
    def nstates(self) -> int:
        """Number of controller states."""
        return int(self.A.shape[0])

    @property
    def is_static(self) -> bool:
        """Whether the controller is a static gain (no states)."""
        return self.nstates == 0

    @property
    def is_discrete(self) -> bool:
        """Whether the controller is discrete (``sampling_time > 0``) with states."""
        return self.sampling_time > 0 and not self.is_static

    @property
    def K(self) -> np.ndarray:
        """The static gain ``[K_p, K_d]`` (3x6).

        Raises
        ------
        ValueError
            The controller has states.
        """
        if not self.is_static:
            raise ValueError(
                f"controller: a dynamic controller ({self.nstates} states) has no static gain K"
            )
        return self.D

    def continuous(self) -> ControllerSystem:
        """The continuous controller (a discrete one: the inverse of its zero-order hold).

        A continuous controller and a static gain are returned as they are. A discrete one is
        mapped back by the matrix logarithm of ``[[A_d, B_d], [0, I]]`` (the exact inverse of
        :meth:`discretize`: ``A = log(A_d) / T``); it exists, real, when no pole of ``A_d``
        is on the closed negative real axis.

        Raises
        ------
        ValueError
            A discrete pole with no continuous zero-order-hold equivalent (named).
        """
        if not self.is_discrete:
            return self if self.sampling_time == 0 else self._with(self.A, self.B, 0.0)
        n, T = self.nstates, self.sampling_time
        poles = np.linalg.eigvals(self.A)
        bad = poles[(np.abs(poles.imag) <= 1e-12 * np.maximum(1, abs(poles))) & (poles.real <= 0)]
        if bad.size:
            raise ValueError(
                f"controller: discrete pole z = {bad[0].real:.6g} has no continuous zero-order-"
                "hold equivalent (on the negative real axis)"
            )
        M = np.block([[self.A, self.B], [np.zeros((6, n)), np.eye(6)]])
        L = scipy.linalg.logm(M) / T
        if np.max(np.abs(np.imag(L)), initial=0.0) > 1e-9 * max(np.max(np.abs(L)), 1.0):
            raise ValueError("controller: the discrete controller has no real continuous form")
        L = np.real(L)
        return self._with(L[:n, :n], L[:n, n:], 0.0)

    def discretize(self, period: float) -> ControllerSystem:
        """The controller at ``period`` [s]: zero-order hold of a continuous one (exact for a
        measurement held over the period), a discrete one at its own rate as it is.

        Raises
        ------
        ValueError
            A discrete controller at another rate.
        """
        period = float(period)
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"controller: the sample period must be > 0 s, got {period}")
        if self.is_static:
            return self if self.sampling_time == period else self._with(self.A, self.B, period)
        if self.is_discrete:
            if not np.isclose(self.sampling_time, period, rtol=1e-12, atol=0.0):
                raise ValueError(
                    f"controller: discrete at {1 / self.sampling_time:g} Hz, not at the flight "
                    f"software's {1 / period:g} Hz"
                )
            return self
        n = self.nstates
        E = scipy.linalg.expm(np.block([[self.A, self.B], [np.zeros((6, n + 6))]]) * period)
        return self._with(E[:n, :n], E[:n, n:], period)

    def _with(self, A, B, sampling_time) -> ControllerSystem:
        return ControllerSystem(A, B, self.C, self.D, sampling_time)

    def response(self, x) -> np.ndarray:
        """``C (x I - A)^-1 B + D`` (``x.shape + (3, 6)``) at complex points ``x`` (``s`` of
        a continuous controller, ``z`` of a discrete one)."""
        x = np.asarray(x, dtype=complex)
        if self.is_static:
            return np.broadcast_to(self.D, x.shape + (3, 6)).astype(complex)
        n = self.nstates
        M = x[..., None, None] * np.eye(n) - self.A
        return self.C @ np.linalg.solve(M, np.broadcast_to(self.B, x.shape + (n, 6))) + self.D

    def frequency_response(self, omega) -> np.ndarray:
        """Response at ``s = j omega`` (continuous) or ``z = exp(j omega T)`` (discrete),
        ``omega`` [rad/s]; shape ``omega.shape + (3, 6)``."""
        omega = np.asarray(omega, dtype=float)
        if self.is_discrete:
            return self.response(np.exp(1j * omega * self.sampling_time))
        return self.response(1j * omega)

    def statespace(self):
        """The controller as a python-control ``StateSpace`` with named channels."""
        import control

        return control.ss(
            self.A,
            self.B,
            self.C,
            self.D,
            self.sampling_time if self.is_discrete else 0,
            inputs=list(self.inputs),
            outputs=list(self.outputs),
            name="controller",
        )

    def record(self) -> dict:
        """JSON-ready ``{"A", "B", "C", "D", "inputs", "outputs", "sampling_time_s"}``."""
        return {
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            "sampling_time_s": self.sampling_time,
        }

    def equals(self, other: ControllerSystem, rtol: float = 1e-9) -> bool:
        """Same sampling time and matrices (to ``rtol`` relative to each matrix's size)."""
        if self.sampling_time != other.sampling_time or self.nstates != other.nstates:
            return False
        mine, theirs = (self.A, self.B, self.C, self.D), (other.A, other.B, other.C, other.D)
        for a, b in zip(mine, theirs, strict=True):
            if not np.allclose(a, b, rtol=rtol, atol=rtol * np.max(np.abs(a), initial=0.0)):
                return False
        return True


def as_controller(controller) -> ControllerSystem:
    """A :class:`ControllerSystem` from itself or a static 3x6 gain ``[K_p, K_d]``."""
    if isinstance(controller, ControllerSystem):
        return controller
    return ControllerSystem.static(controller)


def read_controller(path) -> tuple[dict, ControllerSystem]:
    """Read a ``controller.json`` written by ``oos synth``: its record and its controller.

    The one reader of the file (the analysis' :func:`~oos_drake.analysis.controller.
    load_controller` and the Drake mission use it). A static controller is read from
    ``controller.K_p/K_d.value``, a PID or state space from ``controller.state_space``
    (``A, B, C, D``, named ``inputs``/``outputs``, ``sampling_time_s``).

    Parameters
    ----------
    path : str or Path
        The JSON file, or a directory holding ``controller.json``.

    Returns
    -------
    record : dict
        The whole JSON record.
    system : ControllerSystem

    Raises
    ------
    ValueError
        Missing file, unknown structure, missing or malformed fields (one line naming the file
        and the field).
    """
    path = Path(path)
    if path.is_dir():
        path = path / "controller.json"
    if not path.is_file():
        raise ValueError(f"controller file {path} not found")
    try:
        record = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"controller file {path}: not JSON ({exc})") from exc
    structure = record.get("structure", "static") if isinstance(record, dict) else None
    if structure not in STRUCTURES:
        raise ValueError(
            f"controller file {path}: unknown structure {structure!r} "
            f"(one of {', '.join(STRUCTURES)})"
        )
    gains = record.get("controller")
    gains = gains if isinstance(gains, dict) else {}
    system = _static_system(path, gains) if structure == "static" else _dynamic_system(path, gains)
    return record, system


def _static_system(path: Path, gains: dict) -> ControllerSystem:
    """``controller.K_p/K_d.value`` of a static controller."""
    try:
        K_p = np.asarray(gains["K_p"]["value"], dtype=float)
        K_d = np.asarray(gains["K_d"]["value"], dtype=float)
    except (KeyError, TypeError) as exc:
        raise ValueError(f"controller file {path}: missing field controller.K_p/K_d.value") from exc
    if K_p.shape != (3, 3) or K_d.shape != (3, 3):
        raise ValueError(
            f"controller file {path}: K_p and K_d must be 3x3, got {K_p.shape} and {K_d.shape}"
        )
    return ControllerSystem.static(np.hstack([K_p, K_d]))


def _dynamic_system(path: Path, gains: dict) -> ControllerSystem:
    """``controller.state_space`` (``A, B, C, D``, named ``inputs``/``outputs``,
    ``sampling_time_s``) of a PID or state-space controller."""
    record = gains.get("state_space")
    if not isinstance(record, dict):
        raise ValueError(
            f"controller file {path}: missing field controller.state_space (the realization "
            "oos synth records for a dynamic controller)"
        )
    try:
        args = [np.asarray(record[k], dtype=float) for k in "ABCD"]
        names = [list(record["inputs"]), list(record["outputs"])]
        ts = float(record.get("sampling_time_s", 0.0) or 0.0)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(
            f"controller file {path}: controller.state_space needs A, B, C, D, inputs, "
            f"outputs ({exc})"
        ) from exc
    try:
        return ControllerSystem.from_named(*args, *names, ts)
    except ValueError as exc:
        raise ValueError(f"controller file {path}: controller.state_space: {exc}") from exc


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
        K : array_like, shape (3, 6) or (..., 3, 6), or ControllerSystem
            Static gain ``[K_p, K_d]``: ``K_p`` [N m/rad], ``K_d`` [N m s/rad]; or a linear
            controller (a discrete one by its continuous form,
            :meth:`ControllerSystem.continuous`): its states follow the plant's.
        """
        if isinstance(K, ControllerSystem):
            if K.is_static:
                K = K.D
            else:
                return self._close_dynamic(K.continuous())
        K = np.asarray(K, dtype=float)
        if K.shape[-2:] != (3, 6):
            raise ValueError(f"controller gain K must be 3x6, got shape {K.shape}")
        A, B1, B2, C1, C2, D11, D12, D21 = self.partitions()
        B2K = B2 @ K
        D12K = D12 @ K
        return BatchedStateSpace(
            A + B2K @ C2, B1 + B2K @ D21, C1 + D12K @ C2, D11 + D12K @ D21, DISTURBANCES, ERRORS
        )

    def _close_dynamic(self, controller: ControllerSystem) -> BatchedStateSpace:
        """``F_l(P_tot, C)`` of a continuous controller with states (states ``[x; x_c]``)."""
        A, B1, B2, C1, C2, D11, D12, D21 = self.partitions()
        Ak, Bk, Ck, Dk = controller.A, controller.B, controller.C, controller.D
        batch = A.shape[:-2]
        n, nk = A.shape[-1], Ak.shape[0]

        def tile(M):
            return np.broadcast_to(M, batch + M.shape)

        Acl = np.concatenate(
            [
                np.concatenate([A + B2 @ Dk @ C2, B2 @ Ck], axis=-1),
                np.concatenate([Bk @ C2, tile(Ak)], axis=-1),
            ],
            axis=-2,
        )
        Bcl = np.concatenate([B1 + B2 @ Dk @ D21, Bk @ D21], axis=-2)
        Ccl = np.concatenate([C1 + D12 @ Dk @ C2, D12 @ Ck], axis=-1)
        assert Acl.shape[-1] == n + nk
        return BatchedStateSpace(Acl, Bcl, Ccl, D11 + D12 @ Dk @ D21, DISTURBANCES, ERRORS)


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
        *signal_sums_and_weights(spec),
    ]


def signal_sums_and_weights(spec: comp.DesignSpecification) -> list[BatchedStateSpace]:
    """The static blocks of Fig. controldesign, the same in continuous and sampled time: the
    torque sum ``T = T_rw + T_dist``, the weighted sensor noises, the measurements ``y_att``,
    ``y_rate`` (negative feedback) and the error weights ``e_p`` [1/rad], ``e_u`` [1/(N m)]."""
    v = channel_names
    return [
        sum_block(v("T", 3), [v("T_rw", 3), v("T_dist", 3)], [1.0, 1.0]),
        comp.static_gain(spec.noise_star_tracker, "n_sst", "n_sst_w"),
        comp.static_gain(spec.noise_gyro, "n_gyro", "n_gyro_w"),
        sum_block(v("y_att", 3), [v("phi_sst", 3), v("n_sst_w", 3)], [-1.0, -1.0]),
        sum_block(v("y_rate", 3), [v("w_gyro", 3), v("n_gyro_w", 3)], [-1.0, -1.0]),
        comp.static_gain(1.0 / spec.pointing_requirement, "phi", "e_p"),
        comp.static_gain(spec.control_weight, "u", "e_u"),
    ]
