"""A cheap single-axis flexible attitude simulator for tests, demos and benchmarks.

Three inertias rotate about one axis: the chaser hub (``J_hub``), the first cantilevered mode of a
solar array (modal inertia ``J_a``, frequency ``f_array``) hinged on the hub by a torsional spring,
and a target (``J_target``) that is captured at ``capture_time`` by a docking spring-damper
(``k_dock``, ``c_dock``) while turning at ``omega_capture`` relative to the hub.

.. math::

    M \\ddot\\theta + C \\dot\\theta + K \\theta = e_{hub} (\\mathrm{sat}(u) (1 + \\delta_{mul})
    + T_{ext}),
    \\qquad k_a = J_a (2 \\pi f_{array})^2, \\quad c_a = 2 \\zeta_a \\sqrt{k_a J_a}

A discrete PD controller at ``control_rate`` reads a star tracker (attitude, white noise) and a gyro
(rate, white noise) whose noise comes from the run seed, and commands the reaction wheel; the wheel
torque saturates at ``torque_limit``. Between controller samples the plant is linear with a held
input, so it is integrated exactly (zero-order hold: matrix exponential of the augmented
matrix, ``scipy.linalg.expm``): the result does not depend on an ODE solver tolerance, and reruns
are bit-identical.

Metrics: ``ape`` = max |hub attitude| over the window [rad], ``peak_torque`` = max |commanded
torque| [N m], ``rms_attitude`` [rad]. A hub attitude beyond ``divergence_limit`` (lost attitude
control, e.g. for a large initial rate against the torque limit) or a non-finite state raises
:class:`~oos_drake.campaign.simulator.SimulationDiverged`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.linalg

from oos_drake.blas import single_threaded_blas
from oos_drake.campaign.simulator import (
    Parameter,
    ParameterKind,
    RunCase,
    RunOutput,
    SimulationDiverged,
    check_options,
)

_REAL, _STIFF = ParameterKind.REAL_BLOCK, ParameterKind.STIFFNESS
_INIT, _LTI = ParameterKind.INITIAL_CONDITION, ParameterKind.LTI
#: The fields of one :class:`Parameter` per row: name, unit, nominal, lower, upper, kind,
#: description.
_ROWS = (
    ("J_hub", "kg m^2", 500.0, 250.0, 750.0, _REAL, "chaser hub inertia about the axis"),
    ("J_target", "kg m^2", 300.0, 150.0, 450.0, _REAL, "target inertia about the axis"),
    ("f_array", "Hz", 0.3, 0.1, 1.0, _REAL, "first cantilevered array mode frequency"),
    ("k_dock", "N m/rad", 2e3, 1e2, 1e5, _STIFF, "docking torsional stiffness after capture"),
    ("c_dock", "N m s/rad", 50.0, 0.0, 500.0, _STIFF, "docking torsional damping after capture"),
    (
        "delta_mul",
        "-",
        0.0,
        -0.3,
        0.3,
        _LTI,
        "static multiplicative actuator perturbation (Delta_mul gain)",
    ),
    ("T_ext", "N m", 0.005, -0.05, 0.05, _REAL, "constant external disturbance torque"),
    ("theta0", "rad", 0.0, -0.005, 0.005, _INIT, "initial hub attitude error"),
    ("omega0", "rad/s", 0.0, -0.1, 0.1, _INIT, "initial hub rate error"),
    (
        "omega_capture",
        "rad/s",
        0.002,
        -0.01,
        0.01,
        _INIT,
        "target rate relative to the hub at capture",
    ),
)
_PARAMETERS = tuple(Parameter(*row) for row in _ROWS)

_METRICS = {"ape": "rad", "peak_torque": "N m", "rms_attitude": "rad"}
_SIGNALS = {
    "theta_hub": "rad",
    "omega_hub": "rad/s",
    "deflection_array": "rad",
    "theta_target_rel": "rad",
    "torque_command": "N m",
    "torque_applied": "N m",
}


@dataclass(frozen=True)
class FlexibleAttitudeSimulator:
    """Single-axis hub + array mode + captured target under a saturated discrete PD loop.

    Parameters
    ----------
    control_rate : float
        Controller and sensor sampling rate [Hz].
    torque_limit : float
        Reaction-wheel torque saturation [N m].
    bandwidth : float
        PD design bandwidth [rad/s] (gains sized on the nominal coupled inertia).
    damping_ratio : float
        PD design damping ratio [-].
    star_tracker_noise : float
        Star-tracker white noise standard deviation [rad].
    gyro_noise : float
        Gyro white noise standard deviation [rad/s].
    array_modal_inertia : float
        Modal inertia of the array mode about the axis [kg m^2].
    array_damping_ratio : float
        Structural damping ratio of the array mode [-].
    mission_duration : float
        Mission length [s].
    capture_time : float
        Time of capture [s] (snapped to the controller grid).
    divergence_limit : float
        Hub attitude beyond which the run is declared diverged [rad].
    log_every : int
        Log one controller sample in ``log_every`` (1 = every sample).
    """

    control_rate: float = 10.0
    torque_limit: float = 3.0
    bandwidth: float = 0.2
    damping_ratio: float = 0.7
    star_tracker_noise: float = 1.5343e-5
    gyro_noise: float = 1.0e-4
    array_modal_inertia: float = 100.0
    array_damping_ratio: float = 0.005
    mission_duration: float = 300.0
    capture_time: float = 100.0
    divergence_limit: float = 0.5
    log_every: int = 1

    def __post_init__(self) -> None:
        for name in (
            "control_rate",
            "torque_limit",
            "bandwidth",
            "mission_duration",
            "divergence_limit",
            "array_modal_inertia",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"flexible-attitude option {name}={value} must be positive")
        if int(self.log_every) < 1:
            raise ValueError(f"flexible-attitude option log_every={self.log_every} must be >= 1")

    # --- declarations -------------------------------------------------------------------------
    def parameters(self) -> tuple[Parameter, ...]:
        """Dispersible parameters (see the module table)."""
        return _PARAMETERS

    def metric_units(self) -> Mapping[str, str]:
        """``ape`` [rad], ``peak_torque`` [N m], ``rms_attitude`` [rad]."""
        return dict(_METRICS)

    def signal_units(self) -> Mapping[str, str]:
        """Logged signals: hub attitude and rate, array deflection, target relative attitude
        (NaN before capture), commanded and applied torque."""
        return dict(_SIGNALS)

    def metric_signals(self) -> Mapping[str, str]:
        """``ape`` bounds ``theta_hub``; ``peak_torque`` bounds ``torque_command``."""
        return {"ape": "theta_hub", "peak_torque": "torque_command"}

    def events(self) -> Mapping[str, float]:
        """``capture`` at ``capture_time`` [s]."""
        return {"capture": float(self.capture_time)}

    def duration(self) -> float:
        """Mission length [s]."""
        return float(self.mission_duration)

    # --- model ---------------------------------------------------------------------------------
    def gains(self) -> tuple[float, float]:
        """PD gains (Kp [N m/rad], Kd [N m s/rad]) sized on the nominal coupled inertia."""
        nominal = {p.name: p.nominal for p in _PARAMETERS}
        inertia = nominal["J_hub"] + self.array_modal_inertia + nominal["J_target"]
        omega = self.bandwidth
        return inertia * omega**2, 2.0 * self.damping_ratio * omega * inertia

    def continuous_model(self, values: Mapping[str, float], docked: bool):
        """(A, B) of the state ``[theta_hub, theta_array, theta_target, rates]``; input: hub
        torque [N m]."""
        j_a = self.array_modal_inertia
        inertia = np.array([values["J_hub"], j_a, values["J_target"]])
        k_a = j_a * (2.0 * math.pi * values["f_array"]) ** 2
        c_a = 2.0 * self.array_damping_ratio * math.sqrt(k_a * j_a)
        pair_ha = np.array([[1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
        pair_ht = np.array([[1.0, 0.0, -1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 1.0]])
        stiffness = k_a * pair_ha + (values["k_dock"] * pair_ht if docked else 0.0)
        damping = c_a * pair_ha + (values["c_dock"] * pair_ht if docked else 0.0)
        A = np.zeros((6, 6))
        A[:3, 3:] = np.eye(3)
        A[3:, :3] = -stiffness / inertia[:, None]
        A[3:, 3:] = -damping / inertia[:, None]
        B = np.zeros(6)
        B[3] = 1.0 / inertia[0]
        return A, B

    def discrete_model(self, values: Mapping[str, float], docked: bool):
        """Exact zero-order-hold (Ad, Bd) over one controller period."""
        A, B = self.continuous_model(values, docked)
        augmented = np.zeros((7, 7))
        augmented[:6, :6] = A
        augmented[:6, 6] = B
        # one BLAS thread: a 7 x 7 exponential gains nothing from threads spinning on a busy machine
        with single_threaded_blas():
            phi = scipy.linalg.expm(augmented / self.control_rate)
        return phi[:6, :6], phi[:6, 6]

    # --- run -----------------------------------------------------------------------------------
    def run(self, case: RunCase) -> RunOutput:
        """Simulate the case's window; see the module docstring for the model and metrics."""
        values = case.values
        period = 1.0 / self.control_rate
        t0, t1 = case.window.start, case.window.end
        n_steps = max(1, int(round((t1 - t0) * self.control_rate)))
        capture_step = int(math.ceil((self.capture_time - t0) * self.control_rate - 1e-9))
        rng = np.random.default_rng(case.seed)
        noise = rng.standard_normal((n_steps, 2)) * [self.star_tracker_noise, self.gyro_noise]
        kp, kd = self.gains()
        limit = self.torque_limit
        gain = 1.0 + values["delta_mul"]
        t_ext = values["T_ext"]
        free = self.discrete_model(values, docked=False)
        docked = self.discrete_model(values, docked=True)

        x = np.zeros(6)
        x[[0, 1, 2]] = values["theta0"]
        x[[3, 4, 5]] = values["omega0"]
        if capture_step <= 0:
            Ad, Bd = docked
        else:
            Ad, Bd = free
        log = np.empty((n_steps + 1, 6))
        command = np.empty(n_steps + 1)
        applied = np.empty(n_steps + 1)
        for k in range(n_steps + 1):
            if k == capture_step and k > 0:
                # latch: the target joins at the hub's attitude with its relative rate
                x[2] = x[0]
                x[5] = x[3] + values["omega_capture"]
                Ad, Bd = docked
            theta, omega = x[0], x[3]
            if not (math.isfinite(theta) and abs(theta) <= self.divergence_limit):
                raise SimulationDiverged(
                    f"hub attitude {theta:.3g} rad beyond the {self.divergence_limit} rad "
                    f"divergence limit at t = {t0 + k * period:.1f} s"
                )
            j = min(k, n_steps - 1)
            u = -kp * (theta + noise[j, 0]) - kd * (omega + noise[j, 1])
            u_applied = min(max(u, -limit), limit) * gain
            log[k] = x
            command[k] = u
            applied[k] = u_applied
            if k < n_steps:
                x = Ad @ x + Bd * (u_applied + t_ext)

        theta_hub = log[:, 0]
        metrics = {
            "ape": float(np.max(np.abs(theta_hub))),
            "peak_torque": float(np.max(np.abs(command))),
            "rms_attitude": float(np.sqrt(np.mean(theta_hub**2))),
        }
        step = int(self.log_every)
        time = t0 + period * np.arange(n_steps + 1)
        docked_mask = np.arange(n_steps + 1) >= max(capture_step, 0)
        timeseries = pd.DataFrame(
            {
                "time [s]": time,
                "theta_hub [rad]": theta_hub,
                "omega_hub [rad/s]": log[:, 3],
                "deflection_array [rad]": log[:, 1] - log[:, 0],
                "theta_target_rel [rad]": np.where(docked_mask, log[:, 2] - log[:, 0], np.nan),
                "torque_command [N m]": command,
                "torque_applied [N m]": applied,
            }
        ).iloc[::step]
        return RunOutput(metrics=metrics, timeseries=timeseries.reset_index(drop=True))


def make_simulator(**options) -> FlexibleAttitudeSimulator:
    """Factory registered as ``"flexible-attitude"``; options are the dataclass fields."""
    check_options("flexible-attitude", options, set(FlexibleAttitudeSimulator.__dataclass_fields__))
    return FlexibleAttitudeSimulator(**options)
