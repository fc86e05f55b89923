r"""Tunable controller blocks for :func:`oos_drake.control.systune.systune` (MATLAB-like).

Every block maps named input signals to named output signals and is realized, for a parameter
vector ``x``, as a state space ``(A_k, B_k, C_k, D_k)``. The synthesis pulls all tunable blocks
out of the loop (as hinfstruct/systune do): the controller states become states of the
generalized plant, and the tunable part is the block-diagonal *static* matrix

.. math::

    K(x) = \operatorname{diag}_j \begin{bmatrix} A_j(x_j) & B_j(x_j) \\ C_j(x_j) & D_j(x_j)
    \end{bmatrix}, \qquad \begin{bmatrix} \dot x_k \\ u \end{bmatrix} =
    K(x) \begin{bmatrix} x_k \\ y \end{bmatrix},

so the static-gain machinery (:mod:`oos_drake.control.objective`) serves every structure; the
chain rule goes through the Jacobian ``dK/dx``, computed by complex-step differentiation of the
realization (exact to rounding, no step-size trade-off: every realization below is analytic in
``x``).

Blocks:

- :class:`TunableGain` -- static gain ``D`` (free entries);
- :class:`TunablePID` -- per channel ``Kp + Ki/s + Kd s/(Tf s + 1)`` with an optional roll-off
  ``(w_r / (s + w_r))^order``; ``Tf = exp(theta)``, ``w_r = exp(rho)`` stay positive; discrete
  (``sampling_time > 0``) with forward-Euler integrator and derivative
  (``Ki Ts/(z - 1)``, ``Kd / (Tf + Ts/(z - 1))``, MATLAB's default ``IFormula``/``DFormula``),
  ``Tf = Ts/2 + exp(theta)`` so the filter pole ``1 - Ts/Tf`` stays in the unit disk;
- :class:`TunableSS` -- fixed order ``n``, *modal* form, stable by construction: ``A`` is
  block diagonal with 2x2 blocks ``[[-exp(a1), b], [-b, -exp(a2)]]`` (trace < 0 and
  determinant ``exp(a1 + a2) + b^2 > 0``: every stable real or complex pair, and only those)
  and one ``-exp(a)`` for odd ``n``; ``B, C, D`` free. Discrete: ``A_d`` is the Tustin image
  ``(I - A Ts/2)^-1 (I + A Ts/2)`` of that ``A`` (in the unit disk by construction);
- :class:`FixedBlock` -- a fixed python-control model (e.g. a roll-off filter) in series with
  the tunable blocks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import control
import numpy as np

__all__ = ["TunableGain", "TunablePID", "TunableSS", "FixedBlock"]

#: Step of the complex-step derivative (any tiny value works: no subtractive cancellation).
_COMPLEX_STEP = 1e-30


def _names(names, label: str) -> tuple[str, ...]:
    names = (names,) if isinstance(names, str) else tuple(names)
    if not names or not all(isinstance(n, str) and n for n in names):
        raise ValueError(f"{label}: signal names must be non-empty strings, got {names!r}")
    return names


def _check_sampling_time(name: str, sampling_time: float) -> float:
    sampling_time = float(sampling_time)
    if not sampling_time >= 0:
        raise ValueError(f"block {name!r}: sampling_time must be >= 0 [s], got {sampling_time}")
    return sampling_time


def _series(first, second):
    """``second * first`` of two realizations (complex-safe: no in-place float casts)."""
    A1, B1, C1, D1 = first
    A2, B2, C2, D2 = second
    n1, n2 = A1.shape[0], A2.shape[0]
    A = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    B = np.vstack([B1, B2 @ D1])
    C = np.hstack([D2 @ C1, C2])
    return A, B, C, D2 @ D1


def _block_diagonal(parts):
    """Block-diagonal realization of parallel channels (one input, one output each)."""
    n = sum(p[0].shape[0] for p in parts)
    m = sum(p[1].shape[1] for p in parts)
    q = sum(p[2].shape[0] for p in parts)
    dtype = np.result_type(*(M for p in parts for M in p))
    A, B = np.zeros((n, n), dtype), np.zeros((n, m), dtype)
    C, D = np.zeros((q, n), dtype), np.zeros((q, m), dtype)
    i = j = k = 0
    for Ap, Bp, Cp, Dp in parts:
        ni, mi, qi = Ap.shape[0], Bp.shape[1], Cp.shape[0]
        A[i : i + ni, i : i + ni], B[i : i + ni, j : j + mi] = Ap, Bp
        C[k : k + qi, i : i + ni], D[k : k + qi, j : j + mi] = Cp, Dp
        i, j, k = i + ni, j + mi, k + qi
    return A, B, C, D


class _Tunable:
    """Common interface: ``parameter_names``, ``initial_parameters()``, ``realize(x)``."""

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    sampling_time: float

    @property
    def nparameters(self) -> int:
        return len(self.parameter_names)

    @property
    def linear_parameters(self) -> np.ndarray:
        """Which parameters are gains (scaled by their magnitude, perturbed multiplicatively
        at restarts) rather than logarithms or pole coordinates (unit scale, additive)."""
        return np.array(
            [not n.startswith(("log_", "a1[", "a2[", "a[", "b[")) for n in self.parameter_names]
        )

    def matrix(self, x) -> np.ndarray:
        """``[[A, B], [C, D]]`` at ``x`` (complex ``x`` allowed)."""
        A, B, C, D = self.realize(x)
        return np.block([[A, B], [C, D]])

    def jacobian(self, x) -> np.ndarray:
        """``d matrix / d x`` of shape ``(rows, cols, nparameters)`` by complex step."""
        x = np.asarray(x, dtype=float)
        M0 = self.matrix(x)
        J = np.zeros(M0.shape + (x.size,))
        for k in range(x.size):
            xc = x.astype(complex)
            xc[k] += 1j * _COMPLEX_STEP
            J[..., k] = np.imag(self.matrix(xc)) / _COMPLEX_STEP
        return J

    def statespace(self, x) -> control.StateSpace:
        """The block at ``x`` as a python-control model with named channels."""
        A, B, C, D = (np.real(M) for M in self.realize(np.asarray(x, dtype=float)))
        return control.ss(
            A,
            B,
            C,
            D,
            self.sampling_time,
            inputs=list(self.inputs),
            outputs=list(self.outputs),
            name=self.name,
        )

    def values(self, x) -> dict[str, np.ndarray]:
        """Named, physical values of the parameters at ``x`` (see each block)."""
        raise NotImplementedError


@dataclass(frozen=True)
class TunableGain(_Tunable):
    """Tunable static gain ``u = D y`` (MATLAB ``tunableGain``).

    Parameters
    ----------
    name : str
        Block name (used in results and error messages).
    inputs, outputs : sequence of str
        Signals read and driven (channel names of the plants or of other blocks).
    initial : array_like, shape (len(outputs), len(inputs)), optional
        Start value (zero by default).
    """

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    initial: np.ndarray | None = None
    sampling_time: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "inputs", _names(self.inputs, f"TunableGain {self.name!r}"))
        object.__setattr__(self, "outputs", _names(self.outputs, f"TunableGain {self.name!r}"))
        shape = (len(self.outputs), len(self.inputs))
        initial = np.zeros(shape) if self.initial is None else np.array(self.initial, float)
        if initial.shape != shape:
            raise ValueError(
                f"TunableGain {self.name!r}: initial must have shape {shape}, got {initial.shape}"
            )
        initial.setflags(write=False)
        object.__setattr__(self, "initial", initial)
        object.__setattr__(
            self, "sampling_time", _check_sampling_time(self.name, self.sampling_time)
        )

    nstates = 0

    @property
    def parameter_names(self) -> tuple[str, ...]:
        p, m = self.initial.shape
        return tuple(f"D[{i},{j}]" for i in range(p) for j in range(m))

    def initial_parameters(self) -> np.ndarray:
        return self.initial.ravel().copy()

    def realize(self, x):
        D = np.asarray(x).reshape(self.initial.shape)
        p, m = D.shape
        return np.zeros((0, 0)), np.zeros((0, m)), np.zeros((p, 0)), D

    def values(self, x) -> dict[str, np.ndarray]:
        """``{"D": gain}`` [output unit / input unit]."""
        return {"D": np.asarray(x, float).reshape(self.initial.shape)}


@dataclass(frozen=True)
class TunablePID(_Tunable):
    """Tunable PID per channel with derivative filter and optional roll-off (``tunablePID``).

    .. math::

        u_i = \\Big(K_{p,i} + \\frac{K_{i,i}}{s} + \\frac{K_{d,i} s}{T_{f,i} s + 1}\\Big)
              \\Big(\\frac{\\omega_{r,i}}{s + \\omega_{r,i}}\\Big)^{n_r} e_i

    Parameters
    ----------
    name : str
    inputs, outputs : sequence of str
        One input and one output signal per channel (diagonal PID).
    terms : str
        Which terms are tuned: ``"PID"``, ``"PI"``, ``"PD"`` or ``"P"``.
    kp, ki, kd : float or array_like
        Start values of the gains (per channel or one for all) [output unit / input unit,
        times 1/s for ``ki``, times s for ``kd``].
    tf : float or array_like
        Start value of the derivative filter time constant ``Tf`` [s].
    rolloff_order : int
        Order ``n_r`` of the roll-off (``0``: none).
    rolloff_frequency : float or array_like
        Start value of the roll-off frequency ``omega_r`` [rad/s] (tuned).
    sampling_time : float
        ``0`` for continuous time, else the controller rate [s].
    """

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    terms: str = "PID"
    kp: float | np.ndarray = 1.0
    ki: float | np.ndarray = 0.1
    kd: float | np.ndarray = 0.1
    tf: float | np.ndarray = 0.1
    rolloff_order: int = 0
    rolloff_frequency: float | np.ndarray = 10.0
    sampling_time: float = 0.0

    def __post_init__(self):
        label = f"TunablePID {self.name!r}"
        object.__setattr__(self, "inputs", _names(self.inputs, label))
        object.__setattr__(self, "outputs", _names(self.outputs, label))
        if len(self.inputs) != len(self.outputs):
            raise ValueError(f"{label}: needs one input per output (a PID per channel)")
        if self.terms not in ("PID", "PI", "PD", "P"):
            raise ValueError(f"{label}: unknown structure terms={self.terms!r} (PID, PI, PD, P)")
        if int(self.rolloff_order) != self.rolloff_order or self.rolloff_order < 0:
            raise ValueError(f"{label}: rolloff_order must be an integer >= 0")
        ts = _check_sampling_time(self.name, self.sampling_time)
        object.__setattr__(self, "sampling_time", ts)
        n = len(self.inputs)
        for key in ("kp", "ki", "kd", "tf", "rolloff_frequency"):
            value = np.broadcast_to(np.asarray(getattr(self, key), float), (n,)).copy()
            value.setflags(write=False)
            object.__setattr__(self, key, value)
        if "D" in self.terms and np.any(self.tf <= ts / 2):
            raise ValueError(f"{label}: tf must be > sampling_time/2 = {ts / 2} s")
        if self.rolloff_order and np.any(self.rolloff_frequency <= 0):
            raise ValueError(f"{label}: rolloff_frequency must be > 0 [rad/s]")

    @property
    def _fields(self) -> tuple[str, ...]:
        fields = ["kp"] + (["ki"] if "I" in self.terms else [])
        fields += ["kd", "log_tf"] if "D" in self.terms else []
        return tuple(fields + (["log_wr"] if self.rolloff_order else []))

    @property
    def nstates(self) -> int:
        per = ("I" in self.terms) + ("D" in self.terms) + self.rolloff_order
        return per * len(self.inputs)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"{f}[{i}]" for i in range(len(self.inputs)) for f in self._fields)

    def initial_parameters(self) -> np.ndarray:
        ts = self.sampling_time
        start = {
            "kp": self.kp,
            "ki": self.ki,
            "kd": self.kd,
            "log_tf": np.log(self.tf - ts / 2),
            "log_wr": np.log(self.rolloff_frequency),
        }
        return np.array([start[f][i] for i in range(len(self.inputs)) for f in self._fields])

    def _channel(self, p: dict):
        """Realization of one channel from its named parameters (complex-safe)."""
        ts = self.sampling_time
        one = np.ones((1, 1))
        parts = [(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), p["kp"] * one)]
        if "I" in self.terms:  # Ki/s, or forward Euler Ki Ts/(z - 1)
            gain = p["ki"] * (ts if ts > 0 else 1.0)
            parts.append((one * (1.0 if ts > 0 else 0.0), one, gain * one, 0 * one))
        if "D" in self.terms:
            if ts > 0:  # Kd/(Tf + Ts/(z - 1)) = Kd/Tf (1 - (Ts/Tf)/(z - a)), a = 1 - Ts/Tf
                tf = ts / 2 + np.exp(p["log_tf"])
                a = 1.0 - ts / tf
                parts.append((a * one, one, -(p["kd"] / tf) * (ts / tf) * one, p["kd"] / tf * one))
            else:  # Kd s/(Tf s + 1) = Kd/Tf - (Kd/Tf^2)/(s + 1/Tf)
                tf = np.exp(p["log_tf"])
                parts.append((-one / tf, one, -p["kd"] / tf**2 * one, p["kd"] / tf * one))
        # parallel sum of the terms: one input, summed outputs
        A, B, C, D = _block_diagonal(parts)
        B = B.sum(axis=1, keepdims=True)
        C = C.sum(axis=0, keepdims=True)
        D = D.sum(keepdims=True)
        if self.rolloff_order:
            wr = np.exp(p["log_wr"])
            if ts > 0:  # exact ZOH discretization of w_r/(s + w_r)
                pole = np.exp(-wr * ts)
                lag = (pole * one, (1 - pole) * one, one, 0 * one)
            else:
                lag = (-wr * one, wr * one, one, 0 * one)
            for _ in range(self.rolloff_order):
                A, B, C, D = _series((A, B, C, D), lag)
        return A, B, C, D

    def realize(self, x):
        x = np.asarray(x)
        k = len(self._fields)
        parts = [
            self._channel(dict(zip(self._fields, x[i * k : (i + 1) * k], strict=True)))
            for i in range(len(self.inputs))
        ]
        return _block_diagonal(parts)

    def values(self, x) -> dict[str, np.ndarray]:
        """Per channel: ``kp``, ``ki`` [1/s], ``kd`` [s], ``tf`` [s], ``rolloff_frequency``
        [rad/s] (the terms present)."""
        x = np.asarray(x, float).reshape(len(self.inputs), len(self._fields))
        out = {}
        for j, f in enumerate(self._fields):
            if f == "log_tf":
                out["tf"] = self.sampling_time / 2 + np.exp(x[:, j])
            elif f == "log_wr":
                out["rolloff_frequency"] = np.exp(x[:, j])
            else:
                out[f] = x[:, j].copy()
        return out


@dataclass(frozen=True)
class TunableSS(_Tunable):
    """Tunable fixed-order state space in modal form, stable by construction (``tunableSS``).

    See the module docstring for the parameterization of ``A``. Only stable controllers are
    representable (no integrator: put a fixed integrator in series with :class:`FixedBlock`).

    Parameters
    ----------
    name : str
    inputs, outputs : sequence of str
    order : int
        Number of states (>= 1).
    pole_frequency : float
        Start: every pole at ``-pole_frequency`` [rad/s] (real, ``b = 0``).
    feedthrough : bool
        Whether ``D`` is tuned (else ``D = 0``: strictly proper).
    sampling_time : float
        ``0`` for continuous time, else the controller rate [s].
    initial_scale : float
        Start value of every entry of ``B`` and ``C`` (nonzero, else ``B = C = 0`` is a saddle
        where the gradients w.r.t. ``B``, ``C`` and ``A`` vanish).
    """

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    order: int = 1
    pole_frequency: float = 1.0
    feedthrough: bool = True
    sampling_time: float = 0.0
    initial_scale: float = 0.1

    def __post_init__(self):
        label = f"TunableSS {self.name!r}"
        object.__setattr__(self, "inputs", _names(self.inputs, label))
        object.__setattr__(self, "outputs", _names(self.outputs, label))
        if int(self.order) != self.order or self.order < 1:
            raise ValueError(f"{label}: order must be an integer >= 1, got {self.order!r}")
        if not self.pole_frequency > 0:
            raise ValueError(f"{label}: pole_frequency must be > 0 [rad/s]")
        ts = _check_sampling_time(self.name, self.sampling_time)
        object.__setattr__(self, "sampling_time", ts)

    @property
    def nstates(self) -> int:
        return int(self.order)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        n, m, p = self.nstates, len(self.inputs), len(self.outputs)
        names = []
        for b in range(n // 2):
            names += [f"a1[{b}]", f"a2[{b}]", f"b[{b}]"]
        names += [f"a[{n // 2}]"] if n % 2 else []
        names += [f"B[{i},{j}]" for i in range(n) for j in range(m)]
        names += [f"C[{i},{j}]" for i in range(p) for j in range(n)]
        names += [f"D[{i},{j}]" for i in range(p) for j in range(m)] if self.feedthrough else []
        return tuple(names)

    def initial_parameters(self) -> np.ndarray:
        n, m, p = self.nstates, len(self.inputs), len(self.outputs)
        a0 = np.log(self.pole_frequency)
        poles = [a0, a0, 0.0] * (n // 2) + [a0] * (n % 2)
        s = self.initial_scale
        return np.concatenate(
            [poles, np.full(n * m + p * n, s), np.zeros(p * m if self.feedthrough else 0)]
        )

    def _modal_a(self, x):
        n = self.nstates
        rows = []
        for b in range(n // 2):
            a1, a2, c = x[3 * b : 3 * b + 3]
            rows.append(np.array([[-np.exp(a1), c], [-c, -np.exp(a2)]]))
        if n % 2:
            rows.append(np.array([[-np.exp(x[3 * (n // 2)])]]))
        return _block_diagonal(
            [
                (R, np.zeros((R.shape[0], 0)), np.zeros((0, R.shape[0])), np.zeros((0, 0)))
                for R in rows
            ]
        )[0]

    def realize(self, x):
        x = np.asarray(x)
        n, m, p = self.nstates, len(self.inputs), len(self.outputs)
        k = 3 * (n // 2) + n % 2
        A = self._modal_a(x)
        B = x[k : k + n * m].reshape(n, m)
        C = x[k + n * m : k + n * m + p * n].reshape(p, n)
        D = x[k + n * m + p * n :].reshape(p, m) if self.feedthrough else np.zeros((p, m))
        if self.sampling_time > 0:  # Tustin image of the stable A: in the unit disk
            h = self.sampling_time / 2
            A = np.linalg.solve(np.eye(n) - h * A, np.eye(n) + h * A)
        return A, B, C, D

    def values(self, x) -> dict[str, np.ndarray]:
        """``A`` [1/s, or -], ``B``, ``C``, ``D`` and the controller ``poles`` [rad/s or z]."""
        A, B, C, D = (np.real(M) for M in self.realize(np.asarray(x, float)))
        return {"A": A, "B": B, "C": C, "D": D, "poles": np.linalg.eigvals(A)}


@dataclass(frozen=True)
class FixedBlock:
    """A fixed (not tuned) model in the controller, e.g. a roll-off filter behind a gain.

    Parameters
    ----------
    name : str
    system : control.StateSpace or control.TransferFunction
        The model; continuous models are discretized (zero-order hold) when the tunable blocks
        are discrete.
    inputs, outputs : sequence of str, optional
        Signal names (default: the model's own ``input_labels``/``output_labels``).
    """

    name: str
    system: object
    inputs: tuple[str, ...] | None = None
    outputs: tuple[str, ...] | None = None
    sampling_time: float = field(init=False, default=0.0)

    def __post_init__(self):
        sys = control.ss(self.system)
        object.__setattr__(self, "system", sys)
        inputs = sys.input_labels if self.inputs is None else self.inputs
        outputs = sys.output_labels if self.outputs is None else self.outputs
        object.__setattr__(self, "inputs", _names(inputs, f"FixedBlock {self.name!r}"))
        object.__setattr__(self, "outputs", _names(outputs, f"FixedBlock {self.name!r}"))
        if (len(self.outputs), len(self.inputs)) != (sys.noutputs, sys.ninputs):
            raise ValueError(
                f"FixedBlock {self.name!r}: {len(self.inputs)} input / {len(self.outputs)} "
                f"output names for a {sys.noutputs}x{sys.ninputs} model"
            )
        object.__setattr__(self, "sampling_time", float(sys.dt or 0.0))

    def realization(self, sampling_time: float):
        """``(A, B, C, D)`` at the loop's rate (zero-order hold of a continuous model)."""
        sys = self.system
        if sampling_time > 0 and not sys.dt:
            sys = control.c2d(sys, sampling_time, "zoh")
        elif (sys.dt or 0.0) != sampling_time:
            raise ValueError(
                f"FixedBlock {self.name!r}: sampling time {sys.dt} differs from the "
                f"controller's {sampling_time} s"
            )
        return sys.A, sys.B, sys.C, sys.D
