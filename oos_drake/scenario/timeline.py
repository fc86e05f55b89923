"""Mission timeline: quintic joint trajectories, connection switches and named configurations.

The arm angles ``alpha_1..6`` and the chaser array angles ``theta_1,2`` follow fifth-order
polynomial segments through the waypoints of the scenario file, with zero velocity and zero
acceleration at every waypoint (the "minimum-jerk" blend)

.. math:: q(t) = q_k + (q_{k+1} - q_k)\\,(10 u^3 - 15 u^4 + 6 u^5),\\quad
          u = (t - t_k) / (t_{k+1} - t_k),

the target arrays stay at ``theta_3,4`` (0 in the paper) and the connection switches follow the
docking states: ``(delta_C1, delta_C2) = (0, 0)`` before the first docking (255 s),
``(1, 0)`` while the arm holds the target, ``(0, 1)`` once the target is docked at the hub
(880 s). The scheduled LFR parameters are ``tau = tan(angle / 4)`` in [-1, 1].

Examples
--------
>>> from oos_drake.scenario.timeline import mission_timeline
>>> timeline = mission_timeline()
>>> config = timeline.configuration(300.0)
>>> (float(config.delta_C1), float(config.delta_C2))
(1.0, 0.0)
>>> timeline.configuration([0.0, 1500.0]).theta.shape
(2, 4)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from types import MappingProxyType

import numpy as np

from oos_drake.scenario.data import Scenario, Waypoints

__all__ = [
    "ALPHA_PARAMETERS",
    "CONNECTION_PARAMETERS",
    "THETA_PARAMETERS",
    "Configuration",
    "ConfigurationRates",
    "MissionTimeline",
    "NamedConfiguration",
    "QuinticTrajectory",
    "mission_timeline",
]

#: Names of the scheduled LFR parameters (physical value = tau = tan(angle/4)).
ALPHA_PARAMETERS = tuple(f"tau_alpha{i}" for i in range(1, 7))
THETA_PARAMETERS = tuple(f"tau_theta{i}" for i in range(1, 5))
CONNECTION_PARAMETERS = ("delta_C1", "delta_C2")

_ANGLE_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class QuinticTrajectory:
    """Piecewise quintic through waypoints with zero velocity and acceleration at each one.

    Attributes
    ----------
    times : (n,) ndarray
        Strictly increasing waypoint times [s].
    values : (n, k) ndarray
        Values at the waypoints (k channels).
    """

    times: np.ndarray
    values: np.ndarray

    @classmethod
    def from_waypoints(cls, waypoints: Waypoints) -> QuinticTrajectory:
        """Trajectory through the waypoints of a scenario file."""
        return cls(times=waypoints.times, values=waypoints.values)

    def __call__(self, t, derivative: int = 0) -> np.ndarray:
        """Value (or time derivative) at time(s) ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s) [s] within ``[times[0], times[-1]]``.
        derivative : {0, 1, 2}
            0: value, 1: rate [unit/s], 2: acceleration [unit/s^2].

        Returns
        -------
        ndarray
            Shape ``t.shape + (k,)``.
        """
        if derivative not in (0, 1, 2):
            raise ValueError(f"derivative must be 0, 1 or 2, got {derivative}")
        t = np.asarray(t, dtype=float)
        t0, t1 = self.times[0], self.times[-1]
        bad = ~((t >= t0) & (t <= t1))
        if np.any(bad):
            raise ValueError(f"time {t[bad].flat[0]:g} s outside the mission [{t0:g}, {t1:g}] s")
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        h = self.times[k + 1] - self.times[k]
        u = (t - self.times[k]) / h
        if derivative == 0:
            s = u**3 * (10.0 + u * (-15.0 + 6.0 * u))
        elif derivative == 1:
            s = 30.0 * u**2 * (1.0 - u) ** 2 / h
        else:
            s = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / h**2
        delta = self.values[k + 1] - self.values[k]
        base = self.values[k] if derivative == 0 else 0.0
        return base + delta * s[..., None]


@dataclass(frozen=True, eq=False)
class Configuration:
    """Geometric configuration and connection switches at one time or at a vector of times.

    Attributes
    ----------
    time : ndarray
        Shape ``()`` or ``(N,)`` [s].
    alpha : ndarray
        Arm joint angles alpha_1..6, shape ``time.shape + (6,)`` [rad].
    theta : ndarray
        Array tilt angles theta_1..4, shape ``time.shape + (4,)`` [rad].
    delta_C1 : ndarray
        1 when the arm tip J7 holds D2, else 0; shape ``time.shape``.
    delta_C2 : ndarray
        1 when D3 is docked to D1, else 0; shape ``time.shape``.
    """

    time: np.ndarray
    alpha: np.ndarray
    theta: np.ndarray
    delta_C1: np.ndarray
    delta_C2: np.ndarray

    def __post_init__(self):
        shape = np.shape(self.time)
        for name, width in (("alpha", 6), ("theta", 4)):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != shape + (width,):
                raise ValueError(
                    f"Configuration.{name} must have shape {shape + (width,)}, got {value.shape}"
                )
            bad = ~(np.abs(value) <= np.pi + _ANGLE_TOL)
            if np.any(bad):
                raise ValueError(
                    f"Configuration.{name}: angle {value[bad].flat[0]:.6g} rad outside [-pi, pi]"
                )
        for name in CONNECTION_PARAMETERS:
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != shape:
                raise ValueError(f"Configuration.{name} must have shape {shape}, got {value.shape}")
            if np.any((value < 0) | (value > 1)):
                raise ValueError(f"Configuration.{name} must be in [0, 1]")
        for name in ("time", "alpha", "theta", *CONNECTION_PARAMETERS):
            array = np.array(getattr(self, name), dtype=float)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @classmethod
    def from_angles(
        cls, alpha, theta=(0.0, 0.0, 0.0, 0.0), delta_C1=0.0, delta_C2=0.0, time=0.0
    ) -> Configuration:
        """Build one configuration by hand (angles [rad], switches in {0, 1})."""
        return cls(
            time=np.asarray(time, dtype=float),
            alpha=np.asarray(alpha, dtype=float),
            theta=np.asarray(theta, dtype=float),
            delta_C1=np.asarray(delta_C1, dtype=float),
            delta_C2=np.asarray(delta_C2, dtype=float),
        )

    @property
    def is_batch(self) -> bool:
        """True when the configuration holds a vector of times."""
        return self.time.ndim == 1

    def __len__(self) -> int:
        if not self.is_batch:
            raise TypeError("a single Configuration has no len()")
        return int(self.time.shape[0])

    def __getitem__(self, index: int) -> Configuration:
        """The ``index``-th configuration of a batch."""
        if not self.is_batch:
            raise TypeError("a single Configuration cannot be indexed")
        return Configuration(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @property
    def tau_alpha(self) -> np.ndarray:
        """``tan(alpha / 4)``, shape ``time.shape + (6,)``."""
        return np.tan(self.alpha / 4.0)

    @property
    def tau_theta(self) -> np.ndarray:
        """``tan(theta / 4)``, shape ``time.shape + (4,)``."""
        return np.tan(self.theta / 4.0)

    def parameters(self) -> dict[str, np.ndarray]:
        """Physical values of the scheduled LFR blocks (for ``usubs``).

        Returns
        -------
        dict
            ``{"tau_alpha1".."tau_alpha6", "tau_theta1".."tau_theta4", "delta_C1", "delta_C2"}``
            -> value(s) of shape ``time.shape``.
        """
        values = {name: self.tau_alpha[..., i] for i, name in enumerate(ALPHA_PARAMETERS)}
        values.update({name: self.tau_theta[..., i] for i, name in enumerate(THETA_PARAMETERS)})
        values["delta_C1"] = self.delta_C1
        values["delta_C2"] = self.delta_C2
        return values


@dataclass(frozen=True, eq=False)
class ConfigurationRates:
    """Angular rates and accelerations of the scheduled angles.

    Attributes
    ----------
    time : ndarray
        Shape ``()`` or ``(N,)`` [s].
    alpha_dot, alpha_ddot : ndarray
        Arm joint rates [rad/s] and accelerations [rad/s^2], ``time.shape + (6,)``.
    theta_dot, theta_ddot : ndarray
        Array tilt rates [rad/s] and accelerations [rad/s^2], ``time.shape + (4,)``.
    """

    time: np.ndarray
    alpha_dot: np.ndarray
    alpha_ddot: np.ndarray
    theta_dot: np.ndarray
    theta_ddot: np.ndarray


@dataclass(frozen=True, eq=False)
class NamedConfiguration:
    """A named instant of the mission: the paper's moments 1..6 and docking phases 7, 8.

    Attributes
    ----------
    name : str
        ``"1"`` .. ``"8"``.
    kind : str
        ``"moment"`` or ``"docking phase"``.
    description : str
        Free text from the scenario file.
    configuration : Configuration
        Angles and rigid-connection switches at that time (for a docking phase: the state
        that starts at the docking instant).
    spring_dampers : tuple of str
        Docking phases only: spring-dampers (``"SM1"``: J7/D2, ``"SM2"``: D1/D3) that replace
        the rigid connections in the phase model (empty for moments).
    """

    name: str
    kind: str
    description: str
    configuration: Configuration
    spring_dampers: tuple[str, ...] = ()

    @property
    def time(self) -> float:
        """Mission time [s]."""
        return float(self.configuration.time)


@dataclass(frozen=True, eq=False)
class MissionTimeline:
    """Configuration of the system at any mission time.

    Attributes
    ----------
    scenario : Scenario
        Data the timeline was built from.
    arm : QuinticTrajectory
        alpha_1..6 [rad].
    arrays : QuinticTrajectory
        theta_1, theta_2 [rad].
    """

    scenario: Scenario
    arm: QuinticTrajectory
    arrays: QuinticTrajectory

    @property
    def t_start(self) -> float:
        """Mission start [s]."""
        return self.scenario.mission.t_start

    @property
    def t_end(self) -> float:
        """Mission end [s]."""
        return self.scenario.mission.t_end

    def _times(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if t.ndim > 1:
            raise ValueError(f"time must be a scalar or a 1-D array, got shape {t.shape}")
        bad = ~((t >= self.t_start) & (t <= self.t_end))
        if np.any(bad):
            raise ValueError(
                f"time {t[bad].flat[0]:g} s outside the mission "
                f"[{self.t_start:g}, {self.t_end:g}] s"
            )
        return t

    def switches(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Connection switches ``(delta_C1, delta_C2)`` at time(s) ``t`` (each ``t.shape``)."""
        t = self._times(t)
        states = self.scenario.mission.connection_states
        starts = np.array([s.start for s in states])
        index = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(states) - 1)
        delta_C1 = np.array([s.delta_C1 for s in states])[index]
        delta_C2 = np.array([s.delta_C2 for s in states])[index]
        return delta_C1, delta_C2

    def configuration(self, t) -> Configuration:
        """Angles and switches at time(s) ``t`` [s] (scalar or 1-D array)."""
        t = self._times(t)
        theta12 = self.arrays(t)
        theta34 = np.broadcast_to(self.scenario.mission.target_array_angles, t.shape + (2,))
        delta_C1, delta_C2 = self.switches(t)
        return Configuration(
            time=t,
            alpha=self.arm(t),
            theta=np.concatenate([theta12, theta34], axis=-1),
            delta_C1=delta_C1,
            delta_C2=delta_C2,
        )

    def rates(self, t) -> ConfigurationRates:
        """Angular rates and accelerations at time(s) ``t`` (theta_3,4 are fixed: zero)."""
        t = self._times(t)
        zeros = np.zeros(t.shape + (2,))
        return ConfigurationRates(
            time=t,
            alpha_dot=self.arm(t, 1),
            alpha_ddot=self.arm(t, 2),
            theta_dot=np.concatenate([self.arrays(t, 1), zeros], axis=-1),
            theta_ddot=np.concatenate([self.arrays(t, 2), zeros], axis=-1),
        )

    def frozen(self, t: float) -> MissionTimeline:
        """The same mission with the arm and the arrays held at their configuration of time
        ``t`` [s] over the whole mission (zero rates; connection switches unchanged)."""
        t = float(self._times(t))
        times = np.array([self.t_start, self.t_end], dtype=float)

        def hold(trajectory: QuinticTrajectory) -> QuinticTrajectory:
            value = np.asarray(trajectory(t), dtype=float)
            return QuinticTrajectory(times=times, values=np.vstack([value, value]))

        return MissionTimeline(scenario=self.scenario, arm=hold(self.arm), arrays=hold(self.arrays))

    def sample(self, n: int = 330) -> Configuration:
        """``n`` equally spaced configurations over the whole mission (paper: 330)."""
        if n < 2:
            raise ValueError(f"need at least 2 samples, got {n}")
        return self.configuration(np.linspace(self.t_start, self.t_end, n))

    @property
    def moments(self) -> Mapping[str, NamedConfiguration]:
        """The paper's six moments ``"1"`` .. ``"6"``."""
        return self._named("moment", self.scenario.mission.moments)

    @property
    def docking_phases(self) -> Mapping[str, NamedConfiguration]:
        """Docking phases ``"7"`` (arm docks to the target) and ``"8"`` (target docks to RH1)."""
        return self._named("docking phase", self.scenario.mission.docking_phases)

    def _named(self, kind: str, specs) -> Mapping[str, NamedConfiguration]:
        """``MomentSpec`` or ``DockingPhaseSpec`` entries as named configurations."""
        return MappingProxyType(
            {
                spec.name: NamedConfiguration(
                    name=spec.name,
                    kind=kind,
                    description=spec.description,
                    configuration=self.configuration(spec.time),
                    spring_dampers=getattr(spec, "spring_dampers", ()),
                )
                for spec in specs
            }
        )

    @property
    def named(self) -> Mapping[str, NamedConfiguration]:
        """Moments 1..6 and docking phases 7, 8 in one mapping."""
        return MappingProxyType({**self.moments, **self.docking_phases})


def mission_timeline(scenario: Scenario) -> MissionTimeline:
    """Build the mission timeline of a scenario.

    Parameters
    ----------
    scenario : Scenario
        Loaded scenario (:func:`~oos_drake.scenario.data.load_scenario`).

    Returns
    -------
    MissionTimeline
        (a schema-2 tree: its phase boundaries as numbered ``moments``,
        :meth:`~oos_drake.scenario.tree_scenario.TreeScenario.named_instants`)
    """
    from oos_drake.scenario.tree_scenario import is_tree

    if is_tree(scenario):
        return scenario.named_instants()
    mission = scenario.mission
    return MissionTimeline(
        scenario=scenario,
        arm=QuinticTrajectory.from_waypoints(mission.arm_waypoints),
        arrays=QuinticTrajectory.from_waypoints(mission.array_waypoints),
    )
