"""Scenario data: load and validate ``paper.toml`` into typed, frozen dataclasses.

The data file ``oos_drake/scenario/data/paper.toml`` is the single source of truth for the
paper's data table and for every geometric choice the paper leaves open. ``load_scenario()``
parses it strictly (unknown keys are errors), checks the physics and returns a ``Scenario``:

``Scenario``
    ``hubs["RH1"|"RH2"]`` -> ``RigidHub`` (mass [kg], inertia at G in the hub frame [kg m^2],
    uncertainty half-ranges [%]);
    ``array_models["SA1_2"|"SA3_4"]`` -> ``FlexibleArrayModel`` (mass, P->S, inertia at S,
    modal frequencies [Hz], damping ratios, participation matrix L with one ROW PER MODE and
    columns [Tx Ty Tz Rx Ry Rz], derived ``rigid_spatial_inertia`` D_P and ``residual_mass``
    D_P0 = D_P - L^T L);
    ``arrays["SA1".."SA4"]`` -> ``ArrayMount`` (parent hub, G->P, R_G_P0, tilt axis, model);
    ``arm`` -> ``Arm`` (J0 on RH1, R_RH1_L0, seven ``ArmLink`` L0..L6 with CoM, inertia, joint
    axis and the offset J_i -> J_{i+1} in R_Li);
    ``ports["D1"|"D2"|"D3"]`` -> ``Port`` (body, G->D, R_G_D; ports mate when frames coincide);
    ``docking`` -> ``DockingSettings`` (spring-damper stiffness sweep and damping);
    ``mission`` -> ``Mission`` (event times, waypoints, connection states, the paper's six
    moments and the docking phases 7 and 8);
    ``control`` -> ``ControlRequirements`` (pointing requirement [rad], torque bound [N m],
    flight software rate [Hz], sensor and actuator models, roll-off, weights).

Conventions: SI units ([kg], [m], [kg m^2], [s], [rad]); ``p_A_B`` is the vector A -> B in A's
frame; ``R_A_B`` has B's axes as columns, written in A (``v_A = R_A_B v_B``); 6-DOF vectors are
``[translation; rotation]``. Every array field is a read-only ``numpy.ndarray``.

Validation raises ``ScenarioError`` (a ``ValueError``) whose one-line message names the body
and the quantity, e.g. ``SA1_2: residual mass D_P0 not positive semi-definite (min eigenvalue
-140.2)``.

Examples
--------
>>> from oos_drake.scenario.data import load_scenario
>>> scenario = load_scenario()
>>> scenario.hubs["RH2"].mass
24.96
>>> scenario.array_models["SA1_2"].participation.shape
(6, 6)
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import itertools
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from oos_drake.resources import package_path
from oos_drake.titop.spatial import residual_mass, rigid_spatial_inertia

if TYPE_CHECKING:  # annotations only: tree_scenario imports this module
    from oos_drake.scenario.tree_scenario import TreeScenario

__all__ = [
    "DEFAULT_SCENARIO_PATH",
    "Arm",
    "ArmLink",
    "ArrayMount",
    "ConnectionState",
    "ControlRequirements",
    "DockingPhaseSpec",
    "DockingSettings",
    "FlexibleArrayModel",
    "Mission",
    "MomentSpec",
    "Port",
    "RigidHub",
    "Scenario",
    "ScenarioError",
    "Table",
    "Waypoints",
    "check_inertia",
    "check_percent",
    "check_positive",
    "check_rotation",
    "check_unit",
    "load_scenario",
    "read_control",
    "scenario_path",
    "scenario_record",
    "shipped_scenarios",
]

DEFAULT_SCENARIO_PATH = package_path("oos_drake.scenario", "data", "paper.toml")
SCENARIO_DIRECTORY = DEFAULT_SCENARIO_PATH.parent

_ARRAY_NAMES = ("SA1", "SA2", "SA3", "SA4")
_HUB_NAMES = ("RH1", "RH2")
_PORT_NAMES = ("D1", "D2", "D3")
_LINK_NAMES = ("L0", "L1", "L2", "L3", "L4", "L5", "L6")
_SPRING_DAMPERS = ("SM1", "SM2")
_ORTHO_TOL = 1e-9
_ANGLE_TOL = 1e-12
_PSD_RELTOL = 1e-6


class ScenarioError(ValueError):
    """Invalid scenario data; the message names the body and the quantity.

    Attributes
    ----------
    body : str
        The body, port or section at fault (``"RH2"``, ``"SA1_2"``, ``"arm link L3"``, ...).
    detail : str
        What is wrong with which quantity, with the offending value.
    """

    def __init__(self, body: str, detail: str):
        self.body = body
        self.detail = detail
        super().__init__(f"{body}: {detail}")


# ----------------------------------------------------------------------------------------------
# dataclasses
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RigidHub:
    """A rigid hub (RH1 chaser, RH2 target); reference point and frame at its CoM G.

    Attributes
    ----------
    name : str
        ``"RH1"`` or ``"RH2"``.
    description : str
        Free text.
    mass : float
        Nominal mass [kg].
    inertia : (3, 3) ndarray
        Nominal inertia tensor at G in the hub frame [kg m^2].
    mass_uncertainty_percent : float
        Relative half-range of the mass [%] (``m = m0 (1 + r delta)``, ``|delta| <= 1``).
    inertia_uncertainty_percent : (3,) ndarray
        Relative half-ranges of Jxx, Jyy, Jzz [%]; products of inertia are nominal.
    """

    name: str
    description: str
    mass: float
    inertia: np.ndarray
    mass_uncertainty_percent: float
    inertia_uncertainty_percent: np.ndarray

    @property
    def spatial_inertia(self) -> np.ndarray:
        """``D_G = diag(m I3, J_G)`` (6x6) [kg, kg m^2]."""
        return rigid_spatial_inertia(self.mass, self.inertia, np.zeros(3))

    @property
    def mass_range(self) -> tuple[float, float]:
        """(min, max) mass over the uncertainty range [kg]."""
        r = self.mass_uncertainty_percent / 100.0
        return (self.mass * (1 - r), self.mass * (1 + r))

    @property
    def inertia_diagonal_ranges(self) -> np.ndarray:
        """(3, 2) array of (min, max) of Jxx, Jyy, Jzz over the uncertainty range [kg m^2]."""
        diagonal = np.diag(self.inertia)
        r = self.inertia_uncertainty_percent / 100.0
        return np.stack([diagonal * (1 - r), diagonal * (1 + r)], axis=1)


@dataclass(frozen=True, eq=False)
class FlexibleArrayModel:
    """Cantilevered flexible solar array (data at its attachment point P, in frame R_SA).

    Attributes
    ----------
    name : str
        Model name (``"SA1_2"``: arrays SA1 and SA2; ``"SA3_4"``).
    description : str
        Free text.
    mass : float
        Array mass [kg].
    p_P_S : (3,) ndarray
        Attachment point P -> centre of mass S in R_SA [m].
    inertia : (3, 3) ndarray
        Inertia tensor at S in R_SA [kg m^2].
    frequencies_hz : (n,) ndarray
        Cantilevered modal frequencies [Hz] (``omega`` gives rad/s).
    damping_ratios : (n,) ndarray
        Modal damping ratios [-].
    first_mode_uncertainty_percent : float
        Relative half-range of the first modal frequency [%].
    participation : (n, 6) ndarray
        Modal participation factors at P in R_SA, one ROW per mode, columns
        [Tx Ty Tz Rx Ry Rz] [kg^0.5, kg^0.5 m].
    """

    name: str
    description: str
    mass: float
    p_P_S: np.ndarray
    inertia: np.ndarray
    frequencies_hz: np.ndarray
    damping_ratios: np.ndarray
    first_mode_uncertainty_percent: float
    participation: np.ndarray

    @property
    def n_modes(self) -> int:
        """Number of flexible modes."""
        return int(self.frequencies_hz.shape[0])

    @property
    def omega(self) -> np.ndarray:
        """Cantilevered modal angular frequencies [rad/s]."""
        return 2.0 * np.pi * self.frequencies_hz

    @property
    def rigid_spatial_inertia(self) -> np.ndarray:
        """``D_P``: rigid spatial inertia of the array at P in R_SA (6x6) [kg, kg m, kg m^2]."""
        return rigid_spatial_inertia(self.mass, self.inertia, self.p_P_S)

    @property
    def residual_mass(self) -> np.ndarray:
        """``D_P0 = D_P - L^T L`` (rows of L = modes): residual mass at P in R_SA (6x6)."""
        return residual_mass(self.rigid_spatial_inertia, self.participation.T)


@dataclass(frozen=True, eq=False)
class ArrayMount:
    """One solar array attached to a hub.

    The array frame is ``R_G_SA(theta) = R_G_P0 @ rot(axis, theta)`` at point P.

    Attributes
    ----------
    name : str
        ``"SA1"`` .. ``"SA4"``.
    model : FlexibleArrayModel
        Mechanical data of the array.
    parent : str
        Hub it is attached to (``"RH1"`` or ``"RH2"``).
    p_G_P : (3,) ndarray
        Hub CoM G -> attachment point P, in the hub frame [m].
    R_G_P0 : (3, 3) ndarray
        Orientation of R_SA0 (the array frame at theta = 0) in the hub frame.
    axis : (3,) ndarray
        Unit tilt axis in R_SA0 (the paper's y_P).
    """

    name: str
    model: FlexibleArrayModel
    parent: str
    p_G_P: np.ndarray
    R_G_P0: np.ndarray
    axis: np.ndarray


@dataclass(frozen=True, eq=False)
class ArmLink:
    """One rigid arm link L_i, frame R_Li at joint J_i.

    Attributes
    ----------
    name : str
        ``"L0"`` (base, fixed to RH1 at J0) .. ``"L6"`` (wrist 3, tip J7).
    mass : float
        Link mass [kg].
    p_J_G : (3,) ndarray
        J_i -> link CoM in R_Li [m].
    inertia : (3, 3) ndarray
        Inertia tensor at the CoM in R_Li [kg m^2].
    p_J_Jnext : (3,) ndarray
        J_i -> J_{i+1} in R_Li [m] (for L6: J6 -> arm tip J7).
    joint_axis : (3,) ndarray or None
        Unit axis of joint J_i (angle alpha_i) in R_L(i-1) (= in R_Li); ``None`` for L0.
    """

    name: str
    mass: float
    p_J_G: np.ndarray
    inertia: np.ndarray
    p_J_Jnext: np.ndarray
    joint_axis: np.ndarray | None


@dataclass(frozen=True, eq=False)
class Arm:
    """The UR5-like robotic arm: ``R_L(i-1)_Li = rot(joint_axis_i, alpha_i)``, i = 1..6.

    Attributes
    ----------
    parent : str
        Hub carrying the arm (``"RH1"``).
    p_G_J0 : (3,) ndarray
        G1 -> J0 in R_RH1 [m].
    R_G_L0 : (3, 3) ndarray
        Orientation of the base frame R_L0 in R_RH1.
    links : tuple of ArmLink
        L0 .. L6.
    """

    parent: str
    p_G_J0: np.ndarray
    R_G_L0: np.ndarray
    links: tuple[ArmLink, ...]

    @property
    def joint_axes(self) -> np.ndarray:
        """(6, 3) unit joint axes of alpha_1 .. alpha_6."""
        return np.stack([link.joint_axis for link in self.links[1:]])

    @property
    def total_mass(self) -> float:
        """Sum of the link masses [kg]."""
        return float(sum(link.mass for link in self.links))


@dataclass(frozen=True, eq=False)
class Port:
    """A docking/grasp port frame rigidly attached to a hub (ports mate when frames coincide).

    Attributes
    ----------
    name : str
        ``"D1"`` (on RH1), ``"D2"``, ``"D3"`` (on RH2).
    description : str
        Free text.
    body : str
        Hub carrying the port.
    p_G_D : (3,) ndarray
        Hub CoM G -> port D in the hub frame [m].
    R_G_D : (3, 3) ndarray
        Orientation of the port frame in the hub frame.
    """

    name: str
    description: str
    body: str
    p_G_D: np.ndarray
    R_G_D: np.ndarray


@dataclass(frozen=True, eq=False)
class DockingSettings:
    """Nominal spring-damper data of the docking phases (paper Fig. sigma_plot_springmass).

    Attributes
    ----------
    stiffness_sweep : (k,) ndarray
        Shear [N/m] and torsional [N m/rad] stiffness values swept during docking.
    damping : float
        Damping of the active spring-damper [N s/m] or [N m s/rad].
    rigid_stiffness : float
        Stiffness of the connection that is already rigid during a phase-8 sweep.
    rigid_damping : float
        Damping of that rigid connection.
    """

    stiffness_sweep: np.ndarray
    damping: float
    rigid_stiffness: float
    rigid_damping: float


@dataclass(frozen=True, eq=False)
class Waypoints:
    """Times and values of a piecewise quintic trajectory.

    Attributes
    ----------
    times : (n,) ndarray
        Strictly increasing waypoint times [s], first = mission start, last = mission end.
    values : (n, k) ndarray
        Angles at the waypoints [rad], in [-pi, pi].
    labels : tuple of str
        One name per waypoint (arm: ``"grasp"`` at the first docking, ``"docked"`` at the
        second; ``"pre-grasp"``, ``"grasp"``, ``"docked"``, ``"retreat"`` are IK solutions).
    """

    times: np.ndarray
    values: np.ndarray
    labels: tuple[str, ...] = ()

    def at(self, label: str) -> np.ndarray:
        """Values of the (first) waypoint called ``label``."""
        return self.values[self._index(label)]

    def time_of(self, label: str) -> float:
        """Time [s] of the (first) waypoint called ``label``."""
        return float(self.times[self._index(label)])

    def _index(self, label: str) -> int:
        if label not in self.labels:
            raise ValueError(f"no waypoint labelled '{label}' (have {list(self.labels)})")
        return self.labels.index(label)


@dataclass(frozen=True)
class ConnectionState:
    """Connection switches on ``[start, end)`` (the last state also holds at the mission end).

    Attributes
    ----------
    start, end : float
        Interval [s].
    delta_C1 : float
        1 when the arm tip J7 is docked to D2, else 0.
    delta_C2 : float
        1 when the target's D3 is docked to the chaser's D1, else 0.
    description : str
        Free text.
    """

    start: float
    end: float
    delta_C1: float
    delta_C2: float
    description: str


@dataclass(frozen=True)
class MomentSpec:
    """One of the paper's six named moments (Fig. simscape_rep).

    Attributes
    ----------
    name : str
        ``"1"`` .. ``"6"``.
    time : float
        Mission time [s].
    description : str
        Free text.
    """

    name: str
    time: float
    description: str


@dataclass(frozen=True)
class DockingPhaseSpec:
    """A docking phase (paper Fig. springmass): 7 (arm docks) or 8 (target docks at the hub).

    Attributes
    ----------
    name : str
        ``"7"`` or ``"8"``.
    time : float
        Mission time [s].
    spring_dampers : tuple of str
        Active spring-dampers (``"SM1"``: J7/D2, ``"SM2"``: D1/D3).
    description : str
        Free text.
    """

    name: str
    time: float
    spring_dampers: tuple[str, ...]
    description: str


@dataclass(frozen=True, eq=False)
class Mission:
    """Mission timeline data (see ``oos_drake.scenario.timeline`` for the trajectories).

    Attributes
    ----------
    t_start, t_end : float
        Mission interval [s].
    first_docking_time : float
        Arm tip J7 grasps D2 [s].
    second_docking_time : float
        D3 docks to D1 and the arm is released [s].
    tilt_start_time : float
        The chaser arrays start tilting [s].
    first_docking_standoff : float
        Distance along z_D1 between the docked target pose and its pose at the first docking [m].
    grasp_approach_distance : float
        Arm-tip distance out of the D2 fixture (along -y_J7) before grasping and after release [m].
    target_array_angles : (2,) ndarray
        theta_3, theta_4 [rad] (fixed).
    arm_waypoints : Waypoints
        alpha_1..6 waypoints, values (n, 6).
    array_waypoints : Waypoints
        theta_1, theta_2 waypoints, values (n, 2).
    connection_states : tuple of ConnectionState
        Contiguous switch states covering the mission.
    moments : tuple of MomentSpec
        The paper's six moments.
    docking_phases : tuple of DockingPhaseSpec
        Docking phases 7 and 8.
    """

    t_start: float
    t_end: float
    first_docking_time: float
    second_docking_time: float
    tilt_start_time: float
    first_docking_standoff: float
    grasp_approach_distance: float
    target_array_angles: np.ndarray
    arm_waypoints: Waypoints
    array_waypoints: Waypoints
    connection_states: tuple[ConnectionState, ...]
    moments: tuple[MomentSpec, ...]
    docking_phases: tuple[DockingPhaseSpec, ...]


@dataclass(frozen=True)
class ControlRequirements:
    """The ``[control]`` section: requirements, sensors, actuators, weights, software rate.

    ``oos_drake.control.components.DesignSpecification.from_requirements`` turns it into the
    design data of the synthesis and the analysis; the Drake mission and the campaign take the
    torque bound and the flight software rate from it.

    Attributes
    ----------
    pointing_requirement : float
        Absolute pointing error bound [rad] (performance weight ``W_p``: ``e_p = phi / W_p``).
    torque_limit : float
        Reaction-wheel torque bound [N m] (control weight ``W_u = 1 / torque_limit``; the
        saturation of the Drake mission).
    flight_software_rate_hz : float
        Sample rate of the flight software [Hz] (Drake mission, campaigns).
    star_tracker_cutoff_hz, gyro_cutoff_hz : float
        First-order low-pass cut-offs of the star tracker and the gyroscope [Hz].
    star_tracker_noise : float
        Star-tracker noise weight ``W_n,sst`` [rad].
    gyro_noise : float
        Gyroscope noise weight ``W_n,gyro`` [rad/s].
    wheel_frequency_hz : float
        Reaction-wheel second-order natural frequency [Hz].
    wheel_damping : float
        Reaction-wheel damping ratio [-].
    rolloff_order : int
        Order of the Butterworth roll-off on the command [-].
    rolloff_cutoff_hz : float
        Roll-off cut-off [Hz].
    disturbance_gains : tuple of float
        Numerators of ``W_n,ext = diag(g_i) / (a s + b)`` [N m].
    disturbance_denominator : tuple of float
        ``(a, b)`` of ``W_n,ext``'s denominator [s, -].
    additive_weight_db : float
        ``W_add`` of ``Delta_add`` [dB].
    multiplicative_diagonal, multiplicative_off_diagonal : float
        ``W_mul`` on the diagonal and off-diagonal scalars of ``Delta_mul`` [-].
    gain_margin_db, phase_margin_deg : float or None
        Required loop-at-a-time gain [dB] and phase [deg] margins at ``loop_opening`` (hard
        goals of ``oos synth``; both or neither; None: no margin goal).
    loop_opening : str
        Where the margins are measured: ``"wheel_input"`` (the actuator command, default) or
        ``"measurements"`` (the six sensor channels).
    min_damping : float or None
        Minimum damping ratio of every closed-loop pole [-] (a hard goal; None: none).
    structure : str
        Controller structure tuned by ``oos synth``: ``"static"`` (the 3x6 gain
        ``[K_p K_d]``), ``"pid"`` (per axis, derivative filter) or ``"state-space"``.
    order : int or None
        Roll-off order of the PID (optional) or state order of the state-space controller
        (required) [-]; not allowed for ``"static"``.
    rate_hz : float or None
        Controller rate [Hz]: when given (it must be ``flight_software_rate_hz``) the margins
        are required on the sampled-data loop; None: on the continuous loop.
    """

    pointing_requirement: float
    torque_limit: float
    flight_software_rate_hz: float
    star_tracker_cutoff_hz: float
    gyro_cutoff_hz: float
    star_tracker_noise: float
    gyro_noise: float
    wheel_frequency_hz: float
    wheel_damping: float
    rolloff_order: int
    rolloff_cutoff_hz: float
    disturbance_gains: tuple[float, float, float]
    disturbance_denominator: tuple[float, float]
    additive_weight_db: float
    multiplicative_diagonal: float
    multiplicative_off_diagonal: float
    gain_margin_db: float | None = None
    phase_margin_deg: float | None = None
    loop_opening: str = "wheel_input"
    min_damping: float | None = None
    structure: str = "static"
    order: int | None = None
    rate_hz: float | None = None

    @property
    def has_tuning_goals(self) -> bool:
        """Whether ``[control]`` asks for margins or damping (hard goals beyond the weighted
        H-infinity criterion)."""
        return self.gain_margin_db is not None or self.min_damping is not None


@dataclass(frozen=True, eq=False)
class Scenario:
    """The validated scenario (see the module docstring for the field map).

    Attributes
    ----------
    name, description : str
        Scenario identification.
    hubs : Mapping[str, RigidHub]
        ``"RH1"``, ``"RH2"``.
    array_models : Mapping[str, FlexibleArrayModel]
        Shared array data (``"SA1_2"``, ``"SA3_4"``).
    arrays : Mapping[str, ArrayMount]
        ``"SA1"`` .. ``"SA4"``.
    arm : Arm
        The robotic arm.
    ports : Mapping[str, Port]
        ``"D1"``, ``"D2"``, ``"D3"``.
    docking : DockingSettings
        Spring-damper nominal values.
    mission : Mission
        Timeline data.
    control : ControlRequirements
        Control requirements and design data (``[control]``).
    source : pathlib.Path
        File the scenario was loaded from.
    overrides : tuple of (str, float)
        Values set over the file's (``load_scenario(path, overrides)``: parameter studies).

    Notes
    -----
    A scenario pickles as itself (its validated data, not its file: a worker process receives
    exactly the caller's scenario even if the file changed since); the copy is as read-only as
    the original.
    """

    name: str
    description: str
    hubs: Mapping[str, RigidHub]
    array_models: Mapping[str, FlexibleArrayModel]
    arrays: Mapping[str, ArrayMount]
    arm: Arm
    ports: Mapping[str, Port]
    docking: DockingSettings
    mission: Mission
    control: ControlRequirements
    source: Path
    overrides: tuple[tuple[str, float], ...] = ()

    def __reduce__(self):
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for name in _MAPPING_FIELDS:
            fields[name] = dict(fields[name])
        return _unpickle_scenario, (fields,)


#: Fields of :class:`Scenario` that are read-only mappings (``MappingProxyType`` does not pickle).
_MAPPING_FIELDS = ("hubs", "array_models", "arrays", "ports")


def _unpickle_scenario(fields: dict[str, Any]) -> Scenario:
    for name in _MAPPING_FIELDS:
        fields[name] = MappingProxyType(fields[name])
    scenario = Scenario(**fields)
    _freeze_arrays(scenario)
    return scenario


def _freeze_arrays(value: Any) -> None:
    """Make every ``numpy`` array reachable from ``value`` read-only (an unpickled array is
    writeable)."""
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            _freeze_arrays(getattr(value, f.name))
    elif isinstance(value, Mapping):
        for item in value.values():
            _freeze_arrays(item)
    elif isinstance(value, tuple | list):
        for item in value:
            _freeze_arrays(item)


# ----------------------------------------------------------------------------------------------
# strict TOML reading helpers
# ----------------------------------------------------------------------------------------------
class Table:
    """A TOML table read key by key; ``close()`` rejects the keys nobody asked for."""

    def __init__(self, raw: Any, body: str, what: str = "table"):
        if not isinstance(raw, dict):
            raise ScenarioError(body, f"expected a {what}, got {type(raw).__name__}")
        self.raw = raw
        self.body = body
        self.used: set[str] = set()

    def get(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key not in self.raw:
            if default is ...:
                typo = difflib.get_close_matches(key, [k for k in self.raw if k not in self.used])
                if typo:
                    raise ScenarioError(
                        self.body, f"unknown key '{typo[0]}' (did you mean '{key}'?)"
                    )
                raise ScenarioError(self.body, f"missing key '{key}'")
            return default
        return self.raw[key]

    def number(self, key: str, default: Any = ...) -> float:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ScenarioError(self.body, f"{key} must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ScenarioError(self.body, f"{key} must be finite, got {value}")
        return value

    def text(self, key: str, default: Any = ...) -> str:
        value = self.get(key, default)
        if not isinstance(value, str):
            raise ScenarioError(self.body, f"{key} must be a string, got {value!r}")
        return value

    def array(self, key: str, shape: tuple[int | None, ...], default: Any = ...) -> np.ndarray:
        value = self.get(key, default)
        try:
            array = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise ScenarioError(self.body, f"{key} must be numeric, got {value!r}") from None
        if array.ndim != len(shape) or any(
            want is not None and got != want for got, want in zip(array.shape, shape, strict=True)
        ):
            want = "x".join("n" if s is None else str(s) for s in shape)
            raise ScenarioError(
                self.body, f"{key} must have shape {want}, got {'x'.join(map(str, array.shape))}"
            )
        if not np.all(np.isfinite(array)):
            raise ScenarioError(self.body, f"{key} must be finite")
        array.setflags(write=False)
        return array

    def sub(self, key: str, body: str | None = None) -> Table:
        return Table(self.get(key), body or f"{self.body}.{key}")

    def close(self) -> None:
        unknown = sorted(set(self.raw) - self.used)
        if unknown:
            allowed = ", ".join(sorted(self.used))
            raise ScenarioError(self.body, f"unknown key '{unknown[0]}' (allowed: {allowed})")


# ----------------------------------------------------------------------------------------------
# physical checks
# ----------------------------------------------------------------------------------------------
def check_positive(body: str, quantity: str, value: float) -> None:
    """Refuse ``value`` <= 0 (:class:`ScenarioError` naming ``body`` and ``quantity``)."""
    if not value > 0:
        raise ScenarioError(body, f"{quantity} must be > 0, got {value:g}")


def _check_nonnegative(body: str, quantity: str, value: float) -> None:
    if value < 0:
        raise ScenarioError(body, f"{quantity} must be >= 0, got {value:g}")


def check_percent(body: str, quantity: str, value: np.ndarray | float, upper: float) -> None:
    """Refuse a relative half-range [%] outside ``[0, upper)`` (scalar or array)."""
    values = np.atleast_1d(value)
    if np.any(values < 0):
        raise ScenarioError(body, f"{quantity} must be >= 0 %, got {values.min():g} %")
    if np.any(values >= upper):
        raise ScenarioError(body, f"{quantity} must be < {upper:g} %, got {values.max():g} %")


def check_inertia(body: str, quantity: str, inertia: np.ndarray) -> None:
    """Refuse an inertia matrix [kg m^2] that is not symmetric, positive definite and
    physical (principal moments satisfy the triangle inequality)."""
    scale = max(float(np.max(np.abs(inertia))), 1e-300)
    asymmetry = float(np.max(np.abs(inertia - inertia.T)))
    if asymmetry > 1e-12 * scale:
        raise ScenarioError(body, f"{quantity} not symmetric (max asymmetry {asymmetry:.3g})")
    principal = np.linalg.eigvalsh(inertia)
    if principal[0] <= 0:
        raise ScenarioError(
            body, f"{quantity} not positive definite (min eigenvalue {principal[0]:.4g})"
        )
    a, b, c = principal  # ascending: the binding inequality is a + b >= c
    if a + b < c * (1 - 1e-12):
        raise ScenarioError(
            body,
            f"{quantity} violates the triangle inequality "
            f"(principal moments {a:.4g} + {b:.4g} < {c:.4g})",
        )


def check_rotation(body: str, quantity: str, R: np.ndarray) -> None:
    """Refuse a 3x3 matrix [-] that is not a proper rotation (orthonormal, det = +1)."""
    error = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if error > _ORTHO_TOL:
        raise ScenarioError(body, f"{quantity} not orthonormal (max |R^T R - I| = {error:.3g})")
    det = float(np.linalg.det(R))
    if det < 0:
        raise ScenarioError(body, f"{quantity} is a reflection (det = {det:.6g}), not a rotation")


def check_unit(body: str, quantity: str, axis: np.ndarray) -> None:
    """Refuse an axis [-] whose norm is not 1."""
    norm = float(np.linalg.norm(axis))
    if abs(norm - 1.0) > _ORTHO_TOL:
        raise ScenarioError(body, f"{quantity} must be a unit vector, got norm {norm:.6g}")


def _check_angles(body: str, quantity: str, values: np.ndarray) -> None:
    bad = np.abs(values) > np.pi + _ANGLE_TOL
    if np.any(bad):
        worst = float(values[bad].flat[0])
        raise ScenarioError(body, f"{quantity} out of [-pi, pi] (tau = tan(angle/4)): {worst:.6g}")


# ----------------------------------------------------------------------------------------------
# section readers
# ----------------------------------------------------------------------------------------------
def _read_hub(name: str, raw: Any) -> RigidHub:
    t = Table(raw, name)
    hub = RigidHub(
        name=name,
        description=t.text("description", ""),
        mass=t.number("mass"),
        inertia=t.array("inertia", (3, 3)),
        mass_uncertainty_percent=t.number("mass_uncertainty_percent", 0.0),
        inertia_uncertainty_percent=t.array("inertia_uncertainty_percent", (3,), [0.0, 0.0, 0.0]),
    )
    t.close()
    check_positive(name, "mass", hub.mass)
    check_inertia(name, "inertia", hub.inertia)
    check_percent(name, "mass uncertainty", hub.mass_uncertainty_percent, 100.0)
    check_percent(name, "inertia uncertainty", hub.inertia_uncertainty_percent, 100.0)
    # every corner of the uncertain diagonal must stay a physical inertia
    ranges = hub.inertia_diagonal_ranges
    for corner in itertools.product((0, 1), repeat=3):
        if all(ranges[i, 0] == ranges[i, 1] for i in range(3)):
            break
        inertia = hub.inertia.copy()
        inertia[np.diag_indices(3)] = [ranges[i, corner[i]] for i in range(3)]
        signs = ", ".join("+" if c else "-" for c in corner)
        check_inertia(name, f"inertia at uncertainty corner ({signs})", inertia)
    return hub


def _read_array_model(name: str, raw: Any) -> FlexibleArrayModel:
    t = Table(raw, name)
    frequencies = t.array("frequencies_hz", (None,))
    n = frequencies.shape[0]
    model = FlexibleArrayModel(
        name=name,
        description=t.text("description", ""),
        mass=t.number("mass"),
        p_P_S=t.array("p_P_S", (3,)),
        inertia=t.array("inertia", (3, 3)),
        frequencies_hz=frequencies,
        damping_ratios=t.array("damping_ratios", (None,)),
        first_mode_uncertainty_percent=t.number("first_mode_uncertainty_percent", 0.0),
        participation=t.array("participation", (None, None)),
    )
    t.close()
    check_positive(name, "mass", model.mass)
    check_inertia(name, "inertia at S", model.inertia)
    if n == 0:
        raise ScenarioError(name, "frequencies_hz must list at least one mode")
    if np.any(frequencies <= 0):
        raise ScenarioError(name, f"modal frequency must be > 0, got {frequencies.min():g} Hz")
    if model.damping_ratios.shape != (n,):
        raise ScenarioError(
            name, f"damping_ratios has {model.damping_ratios.shape[0]} entries for {n} modes"
        )
    _check_nonnegative(name, "damping ratio", model.damping_ratios.min())
    check_percent(
        name, "first-mode frequency uncertainty", model.first_mode_uncertainty_percent, 100.0
    )
    if model.participation.shape != (n, 6):
        shape = "x".join(map(str, model.participation.shape))
        raise ScenarioError(
            name, f"participation matrix must be {n}x6 (rows = modes, columns = DOF), got {shape}"
        )
    D_P = model.rigid_spatial_inertia
    min_eig = float(np.linalg.eigvalsh(model.residual_mass)[0])
    if min_eig < -_PSD_RELTOL * float(np.linalg.eigvalsh(D_P)[-1]):
        raise ScenarioError(
            name, f"residual mass D_P0 not positive semi-definite (min eigenvalue {min_eig:.4g})"
        )
    return model


def _read_array(name: str, raw: Any, models: Mapping[str, FlexibleArrayModel]) -> ArrayMount:
    t = Table(raw, name)
    model_name = t.text("model")
    parent = t.text("parent")
    mount = dict(
        p_G_P=t.array("p_G_P", (3,)),
        R_G_P0=t.array("R_G_P0", (3, 3)),
        axis=t.array("axis", (3,)),
    )
    t.close()
    if model_name not in models:
        raise ScenarioError(name, f"unknown array model '{model_name}' (have {sorted(models)})")
    if parent not in _HUB_NAMES:
        raise ScenarioError(name, f"parent must be one of {_HUB_NAMES}, got '{parent}'")
    check_rotation(name, "R_G_P0", mount["R_G_P0"])
    check_unit(name, "tilt axis", mount["axis"])
    return ArrayMount(name=name, model=models[model_name], parent=parent, **mount)


def _read_arm(raw: Any) -> Arm:
    t = Table(raw, "arm")
    parent = t.text("parent")
    p_G_J0 = t.array("p_G_J0", (3,))
    R_G_L0 = t.array("R_G_L0", (3, 3))
    raw_links = t.get("links")
    t.close()
    if parent != "RH1":
        raise ScenarioError("arm", f"parent must be 'RH1', got '{parent}'")
    check_rotation("arm", "R_G_L0", R_G_L0)
    if not isinstance(raw_links, list) or len(raw_links) != len(_LINK_NAMES):
        count = len(raw_links) if isinstance(raw_links, list) else "no"
        raise ScenarioError("arm", f"needs {len(_LINK_NAMES)} links L0..L6, got {count}")
    links = []
    for index, (expected, raw_link) in enumerate(zip(_LINK_NAMES, raw_links, strict=True)):
        lt = Table(raw_link, f"arm link #{index}")
        name = lt.text("name")
        body = f"arm link {name}"
        lt.body = body
        if name != expected:
            raise ScenarioError(
                body, f"links must be listed in order L0..L6, expected '{expected}'"
            )
        link = ArmLink(
            name=name,
            mass=lt.number("mass"),
            p_J_G=lt.array("p_J_G", (3,)),
            inertia=lt.array("inertia", (3, 3)),
            p_J_Jnext=lt.array("p_J_Jnext", (3,)),
            joint_axis=lt.array("joint_axis", (3,)) if index > 0 else None,
        )
        lt.close()
        check_positive(body, "mass", link.mass)
        check_inertia(body, "inertia", link.inertia)
        if link.joint_axis is not None:
            check_unit(body, "joint axis", link.joint_axis)
        links.append(link)
    return Arm(parent=parent, p_G_J0=p_G_J0, R_G_L0=R_G_L0, links=tuple(links))


def _read_port(name: str, raw: Any) -> Port:
    body = f"port {name}"
    t = Table(raw, body)
    port = Port(
        name=name,
        description=t.text("description", ""),
        body=t.text("body"),
        p_G_D=t.array("p_G_D", (3,)),
        R_G_D=t.array("R_G_D", (3, 3)),
    )
    t.close()
    expected = "RH1" if name == "D1" else "RH2"
    if port.body != expected:
        raise ScenarioError(body, f"must be on '{expected}', got '{port.body}'")
    check_rotation(body, "R_G_D", port.R_G_D)
    return port


def _read_docking(raw: Any) -> DockingSettings:
    t = Table(raw, "docking")
    settings = DockingSettings(
        stiffness_sweep=t.array("stiffness_sweep", (None,)),
        damping=t.number("damping"),
        rigid_stiffness=t.number("rigid_stiffness"),
        rigid_damping=t.number("rigid_damping"),
    )
    t.close()
    sweep = settings.stiffness_sweep
    if sweep.size == 0 or np.any(sweep <= 0) or np.any(np.diff(sweep) <= 0):
        raise ScenarioError("docking", "stiffness_sweep must be positive and increasing")
    _check_nonnegative("docking", "damping", settings.damping)
    _check_nonnegative("docking", "rigid_damping", settings.rigid_damping)
    check_positive("docking", "rigid_stiffness", settings.rigid_stiffness)
    return settings


def _read_waypoints(raw: Any, body: str, key: str, width: int, t0: float, t1: float) -> Waypoints:
    t = Table(raw, body)
    times = t.array("times", (None,))
    values = t.array(key, (times.shape[0], width))
    labels = t.get("labels", [""] * times.shape[0])
    t.close()
    if not isinstance(labels, list) or not all(isinstance(label, str) for label in labels):
        raise ScenarioError(body, "labels must be a list of strings")
    if len(labels) != times.shape[0]:
        raise ScenarioError(body, f"{len(labels)} labels for {times.shape[0]} waypoints")
    if times.shape[0] < 2:
        raise ScenarioError(body, "needs at least two waypoints")
    if np.any(np.diff(times) <= 0):
        raise ScenarioError(body, "waypoint times must be strictly increasing")
    if times[0] != t0 or times[-1] != t1:
        raise ScenarioError(
            body,
            f"waypoints must span the mission [{t0:g}, {t1:g}] s, got "
            f"[{times[0]:g}, {times[-1]:g}] s",
        )
    _check_angles(body, key, values)
    return Waypoints(times=times, values=values, labels=tuple(labels))


def _read_mission(raw: Any) -> Mission:
    t = Table(raw, "mission")
    t_start = t.number("t_start")
    t_end = t.number("t_end")
    first = t.number("first_docking_time")
    second = t.number("second_docking_time")
    tilt = t.number("tilt_start_time")
    if not t_start < first < second < tilt < t_end:
        raise ScenarioError(
            "mission",
            "event times must satisfy t_start < first_docking_time < second_docking_time "
            f"< tilt_start_time < t_end, got {t_start:g}, {first:g}, {second:g}, {tilt:g}, "
            f"{t_end:g} s",
        )
    standoff = t.number("first_docking_standoff")
    _check_nonnegative("mission", "first_docking_standoff", standoff)
    approach = t.number("grasp_approach_distance")
    _check_nonnegative("mission", "grasp_approach_distance", approach)
    target_angles = t.array("target_array_angles", (2,))
    _check_angles("mission", "target_array_angles", target_angles)
    arm_wp = _read_waypoints(
        t.get("arm_waypoints"), "mission.arm_waypoints", "alpha", 6, t_start, t_end
    )
    array_wp = _read_waypoints(
        t.get("array_waypoints"), "mission.array_waypoints", "theta", 2, t_start, t_end
    )
    for label, time in (("grasp", first), ("docked", second)):
        if label not in arm_wp.labels or arm_wp.time_of(label) != time:
            raise ScenarioError(
                "mission.arm_waypoints",
                f"needs a waypoint labelled '{label}' at t = {time:g} s",
            )
    states = []
    for index, raw_state in enumerate(t.get("connection_states")):
        st = Table(raw_state, f"mission.connection_states[{index}]")
        state = ConnectionState(
            start=st.number("start"),
            end=st.number("end"),
            delta_C1=st.number("delta_C1"),
            delta_C2=st.number("delta_C2"),
            description=st.text("description", ""),
        )
        st.close()
        for key in ("delta_C1", "delta_C2"):
            if getattr(state, key) not in (0.0, 1.0):
                raise ScenarioError(st.body, f"{key} must be 0 or 1, got {getattr(state, key):g}")
        if state.delta_C1 == 1.0 and state.delta_C2 == 1.0:
            raise ScenarioError(st.body, "delta_C1 and delta_C2 cannot both be 1")
        if not state.end > state.start:
            raise ScenarioError(
                st.body, f"end {state.end:g} s must be after start {state.start:g} s"
            )
        states.append(state)
    if not states:
        raise ScenarioError("mission", "connection_states is empty")
    edges = [states[0].start] + [s.end for s in states]
    if (
        states[0].start != t_start
        or states[-1].end != t_end
        or any(a.end != b.start for a, b in itertools.pairwise(states))
    ):
        raise ScenarioError(
            "mission", "connection_states must be contiguous and cover [t_start, t_end]"
        )
    expected_switches = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)]
    if [(s.delta_C1, s.delta_C2) for s in states] != expected_switches or edges[1:3] != [
        first,
        second,
    ]:
        raise ScenarioError(
            "mission",
            "connection_states must be decoupled (0, 0), arm docked (1, 0) from "
            "first_docking_time, target docked (0, 1) from second_docking_time",
        )
    moments = []
    for index, raw_moment in enumerate(t.get("moments")):
        mt = Table(raw_moment, f"mission.moments[{index}]")
        moment = MomentSpec(
            name=mt.text("name"), time=mt.number("time"), description=mt.text("description", "")
        )
        mt.close()
        if not t_start <= moment.time <= t_end:
            raise ScenarioError(mt.body, f"time {moment.time:g} s outside the mission")
        moments.append(moment)
    if [m.name for m in moments] != ["1", "2", "3", "4", "5", "6"]:
        raise ScenarioError("mission", "moments must be named '1' .. '6' in order")
    phases = []
    for index, raw_phase in enumerate(t.get("docking_phases")):
        pt = Table(raw_phase, f"mission.docking_phases[{index}]")
        phase = DockingPhaseSpec(
            name=pt.text("name"),
            time=pt.number("time"),
            spring_dampers=tuple(pt.get("spring_dampers")),
            description=pt.text("description", ""),
        )
        pt.close()
        if not set(phase.spring_dampers) <= set(_SPRING_DAMPERS):
            raise ScenarioError(pt.body, f"spring_dampers must be among {_SPRING_DAMPERS}")
        phases.append(phase)
    if [p.name for p in phases] != ["7", "8"] or [p.time for p in phases] != [first, second]:
        raise ScenarioError(
            "mission",
            "docking_phases must be '7' at first_docking_time and '8' at second_docking_time",
        )
    t.close()
    return Mission(
        t_start=t_start,
        t_end=t_end,
        first_docking_time=first,
        second_docking_time=second,
        tilt_start_time=tilt,
        first_docking_standoff=standoff,
        grasp_approach_distance=approach,
        target_array_angles=target_angles,
        arm_waypoints=arm_wp,
        array_waypoints=array_wp,
        connection_states=tuple(states),
        moments=tuple(moments),
        docking_phases=tuple(phases),
    )


def read_control(raw: Any) -> ControlRequirements:
    """Read a ``[control]`` section (schema 1 and 2): every number checked with its unit.

    Parameters
    ----------
    raw : dict or Table
        The section's TOML table. A :class:`Table` whose caller already read its own keys
        (schema 2's ``controlled_body``) is closed here with those keys allowed.

    Returns
    -------
    ControlRequirements

    Raises
    ------
    ScenarioError
        One line naming ``control.<field>``.
    """
    top = raw if isinstance(raw, Table) else Table(raw, "control")

    def positive(table: Table, key: str, unit: str, *, upper: float = math.inf) -> float:
        value = table.number(key)
        if not 0 < value < upper:
            bound = "" if upper == math.inf else f" and < {upper:g} {unit}"
            raise ScenarioError(
                f"{table.body}.{key}", f"must be > 0 {unit}{bound}, got {value:g} {unit}"
            )
        return value

    def positive_list(table: Table, key: str, size: int, unit: str) -> tuple[float, ...]:
        values = table.array(key, (size,))
        if not np.all(values > 0):
            raise ScenarioError(
                f"{table.body}.{key}", f"must be > 0 {unit}, got {values.tolist()} {unit}"
            )
        return tuple(float(v) for v in values)

    sensors, actuators = top.sub("sensors"), top.sub("actuators")
    rolloff, weights = top.sub("rolloff"), top.sub("weights")
    order = rolloff.number("order")
    if order != int(order) or not 1 <= order <= 12:
        raise ScenarioError("control.rolloff.order", f"must be an integer in 1..12, got {order:g}")
    rate = positive(top, "flight_software_rate_hz", "Hz")
    sensor_cutoffs = {
        key: positive(sensors, key, "Hz") for key in ("star_tracker_cutoff_hz", "gyro_cutoff_hz")
    }
    rolloff_cutoff = positive(rolloff, "cutoff_hz", "Hz")
    if rolloff_cutoff >= rate / 2:
        raise ScenarioError(
            "control.rolloff.cutoff_hz",
            f"{rolloff_cutoff:g} Hz must be below the flight software's Nyquist frequency "
            f"({rate / 2:g} Hz)",
        )
    additive_db = weights.number("additive_weight_db")
    tuning = _read_tuning(top, rate)
    control = ControlRequirements(
        pointing_requirement=positive(top, "pointing_requirement", "rad"),
        torque_limit=positive(top, "torque_limit", "N m"),
        flight_software_rate_hz=rate,
        star_tracker_cutoff_hz=sensor_cutoffs["star_tracker_cutoff_hz"],
        gyro_cutoff_hz=sensor_cutoffs["gyro_cutoff_hz"],
        star_tracker_noise=positive(sensors, "star_tracker_noise", "rad"),
        gyro_noise=positive(sensors, "gyro_noise", "rad/s"),
        wheel_frequency_hz=positive(actuators, "wheel_frequency_hz", "Hz"),
        wheel_damping=positive(actuators, "wheel_damping", "-"),
        rolloff_order=int(order),
        rolloff_cutoff_hz=rolloff_cutoff,
        disturbance_gains=positive_list(weights, "disturbance_gains", 3, "N m"),
        disturbance_denominator=positive_list(weights, "disturbance_denominator", 2, "s, -"),
        additive_weight_db=additive_db,
        multiplicative_diagonal=positive(weights, "multiplicative_diagonal", "-"),
        multiplicative_off_diagonal=positive(weights, "multiplicative_off_diagonal", "-"),
        **tuning,
    )
    for table in (sensors, actuators, rolloff, weights, top):
        table.close()
    return control


CONTROLLER_STRUCTURES = ("static", "pid", "state-space")
LOOP_OPENINGS = ("wheel_input", "measurements")


def _read_tuning(top: Table, flight_software_rate_hz: float) -> dict[str, Any]:
    """The tuning goals and controller structure of ``[control]`` (all optional)."""

    def optional(key: str, low: float, high: float, unit: str, closed: bool = False):
        if key not in top.raw:
            top.used.add(key)
            return None
        value = top.number(key)
        if not (low <= value if closed else low < value) or not value < high:
            interval = f"{'[' if closed else '('}{low:g}, {high:g})"
            raise ScenarioError(
                f"control.{key}", f"must be in {interval} {unit}, got {value:g} {unit}"
            )
        return value

    def choice(key: str, allowed: tuple[str, ...], default: str) -> str:
        value = top.text(key, default)
        if value not in allowed:
            raise ScenarioError(
                f"control.{key}", f"must be one of {', '.join(allowed)}, got {value!r}"
            )
        return value

    gain_margin = optional("gain_margin_db", 0.0, 40.0, "dB")
    phase_margin = optional("phase_margin_deg", 0.0, 180.0, "deg", closed=True)
    if (gain_margin is None) != (phase_margin is None):
        missing = "phase_margin_deg" if phase_margin is None else "gain_margin_db"
        raise ScenarioError(f"control.{missing}", "missing (margins need both)")
    structure = choice("structure", CONTROLLER_STRUCTURES, "static")
    order = None
    if "order" in top.raw:
        value = top.number("order")
        if value != int(value) or value < 1:
            raise ScenarioError("control.order", f"must be an integer >= 1, got {value:g}")
        if structure == "static":
            raise ScenarioError("control.order", "not allowed with structure = 'static'")
        order = int(value)
    top.used.add("order")
    if structure == "state-space" and order is None:
        raise ScenarioError("control.order", "missing (structure 'state-space' needs an order)")
    rate = optional("rate_hz", 0.0, math.inf, "Hz")
    if rate is not None and rate != flight_software_rate_hz:
        raise ScenarioError(
            "control.rate_hz",
            f"{rate:g} Hz must be the flight software rate ({flight_software_rate_hz:g} Hz)",
        )
    return dict(
        gain_margin_db=gain_margin,
        phase_margin_deg=phase_margin,
        loop_opening=choice("loop_opening", LOOP_OPENINGS, "wheel_input"),
        min_damping=optional("min_damping", 0.0, 1.0, "-", closed=True),
        structure=structure,
        order=order,
        rate_hz=rate,
    )


def _named(table: Table, key: str, names: tuple[str, ...]) -> dict[str, Any]:
    raw = table.get(key)
    if not isinstance(raw, dict):
        raise ScenarioError(key, "expected a table")
    if set(raw) != set(names):
        missing = sorted(set(names) - set(raw))
        extra = sorted(set(raw) - set(names))
        what = f"missing {missing}" if missing else f"unknown {extra}"
        raise ScenarioError(key, f"must define exactly {list(names)}: {what}")
    return raw


def _parse(document: dict[str, Any], source: Path) -> Scenario:
    top = Table(document, source.name, "document")
    version = top.number("schema_version")
    if version != 1:
        raise ScenarioError(source.name, f"schema_version must be 1, got {version:g}")
    name = top.text("name")
    description = top.text("description", "")
    hubs = {n: _read_hub(n, raw) for n, raw in _named(top, "hubs", _HUB_NAMES).items()}
    raw_models = top.get("array_models")
    if not isinstance(raw_models, dict) or not raw_models:
        raise ScenarioError("array_models", "expected a non-empty table of array models")
    models = {n: _read_array_model(n, raw) for n, raw in raw_models.items()}
    arrays = {
        n: _read_array(n, raw, models)
        for n, raw in sorted(_named(top, "arrays", _ARRAY_NAMES).items())
    }
    for n, mount in arrays.items():
        expected = "RH1" if n in ("SA1", "SA2") else "RH2"
        if mount.parent != expected:
            raise ScenarioError(n, f"parent must be '{expected}', got '{mount.parent}'")
    arm = _read_arm(top.get("arm"))
    ports = {n: _read_port(n, raw) for n, raw in sorted(_named(top, "ports", _PORT_NAMES).items())}
    docking = _read_docking(top.get("docking"))
    mission = _read_mission(top.get("mission"))
    control = read_control(top.get("control"))
    top.close()
    scenario = Scenario(
        name=name,
        description=description,
        hubs=MappingProxyType(hubs),
        array_models=MappingProxyType(models),
        arrays=MappingProxyType(arrays),
        arm=arm,
        ports=MappingProxyType(ports),
        docking=docking,
        mission=mission,
        control=control,
        source=source,
    )
    _check_ik_waypoints(scenario)
    return scenario


_IK_TOLERANCE = 1e-6  # [m] and [rad]: stored IK waypoints must hit their arm-tip pose


def _check_ik_waypoints(scenario: Scenario) -> None:
    """Stored IK waypoints (grasp, docked, ...) must still reach their pose (geometry edits)."""
    from oos_drake.scenario.kinematics import (  # late: kinematics imports this module
        IK_WAYPOINTS,
        arm_tip_pose,
        pose_error,
        waypoint_tip_pose,
    )

    waypoints = scenario.mission.arm_waypoints
    for label in IK_WAYPOINTS:
        if label not in waypoints.labels:
            continue
        error = pose_error(
            arm_tip_pose(scenario, waypoints.at(label)), waypoint_tip_pose(scenario, label)
        )
        miss = float(np.abs(error).max())
        if miss > _IK_TOLERANCE:
            raise ScenarioError(
                "mission.arm_waypoints",
                f"waypoint '{label}' misses its arm-tip pose by {miss:.3g} (m or rad); "
                f"re-solve it with oos_drake.scenario.kinematics.waypoint_ik",
            )


def _set_value(document: dict[str, Any], path: str, value: float) -> None:
    """Set the number at dotted ``path`` of a parsed scenario document.

    ``hubs.RH2.mass``; list entries by index: ``array_models.SA3_4.frequencies_hz.0``.
    """
    node: Any = document
    keys = path.split(".")
    for depth, key in enumerate(keys):
        where = ".".join(keys[:depth]) or "the scenario"
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                raise ScenarioError(
                    path, f"unknown path: {where} is a list of {len(node)}, not '{key}'"
                )
            index: Any = int(key)
        elif isinstance(node, dict):
            if key not in node:
                close = difflib.get_close_matches(key, list(node))
                hint = f" (did you mean '{close[0]}'?)" if close else f" (have {', '.join(node)})"
                raise ScenarioError(path, f"unknown path: no '{key}' in {where}{hint}")
            index = key
        else:
            raise ScenarioError(path, f"unknown path: {where} is a number, not a table")
        if depth == len(keys) - 1:
            old = node[index]
            if isinstance(old, bool) or not isinstance(old, int | float):
                raise ScenarioError(path, f"is not a number (it holds {type(old).__name__})")
            node[index] = float(value) if isinstance(old, float) else value
        node = node[index]


@functools.lru_cache(maxsize=16)
def _load_cached(
    path: str, mtime_ns: int, size: int, overrides: tuple[tuple[str, float], ...] = ()
) -> Scenario:
    source = Path(path)
    try:
        with source.open("rb") as stream:
            document = tomllib.load(stream)
    except tomllib.TOMLDecodeError as error:
        raise ScenarioError(source.name, f"invalid TOML ({error})") from None
    if document.get("schema_version") == 2:  # a spacecraft tree: the stages' adapter
        from oos_drake.scenario.tree_scenario import tree_scenario

        if overrides:
            raise ScenarioError(
                source.name, f"overrides {dict(overrides)}: not available for a schema-2 tree"
            )
        return tree_scenario(document, source)
    for key, value in overrides:
        _set_value(document, key, value)
    scenario = _parse(document, source)
    return dataclasses.replace(scenario, overrides=overrides) if overrides else scenario


def scenario_record(scenario: Scenario) -> dict[str, Any]:
    """What identifies a scenario in result summaries: name, file, its SHA-256, overrides."""
    import hashlib

    return {
        "name": scenario.name,
        "file": str(scenario.source),
        "sha256": hashlib.sha256(scenario.source.read_bytes()).hexdigest(),
        "overrides": dict(scenario.overrides),
    }


def shipped_scenarios() -> list[str]:
    """Names of the scenario files shipped with the package: ``paper``, ``heavy_target`` and
    the schema-2 trees of ``data/trees`` (``flexible_satellite``, ...)."""
    names = [p.stem for p in SCENARIO_DIRECTORY.glob("*.toml")]
    return sorted(names + [p.stem for p in (SCENARIO_DIRECTORY / "trees").glob("*.toml")])


def scenario_path(name: str | Path | None = None) -> Path:
    """The scenario file for a path or the bare name of a shipped scenario (default: paper).

    Raises
    ------
    ValueError
        No such file (the message lists the shipped scenarios).
    """
    if name is None:
        return DEFAULT_SCENARIO_PATH.resolve()
    path = Path(name)
    if not path.is_file() and path.parent == Path():
        file = path.with_suffix(".toml").name
        for folder in (SCENARIO_DIRECTORY, SCENARIO_DIRECTORY / "trees"):
            if (folder / file).is_file():
                path = folder / file
                break
    if not path.is_file():
        raise ValueError(
            f"scenario {name}: file not found (shipped scenarios: {', '.join(shipped_scenarios())})"
        )
    return path.resolve()


def load_scenario(
    path: str | Path | None = None, overrides: Mapping[str, float] | None = None
) -> Scenario | TreeScenario:
    """Load and validate a scenario data file.

    Parameters
    ----------
    path : str or Path, optional
        TOML file, or the name of a shipped scenario (``"heavy_target"``); default: the paper's
        scenario ``oos_drake/scenario/data/paper.toml``.
    overrides : mapping of str to float, optional
        Numbers set over the file's before validation, keyed by their dotted path in the file
        (``{"hubs.RH2.mass": 100.0}``, ``"array_models.SA3_4.frequencies_hz.0"``): parameter
        studies. An unknown path or a non-numeric entry is a ``ScenarioError`` naming the path.

    Returns
    -------
    Scenario or TreeScenario
        Frozen, validated data (cached per file version: loading twice returns the same object).
        A ``schema_version = 2`` file (a spacecraft tree) gives a
        :class:`~oos_drake.scenario.tree_scenario.TreeScenario`, which the pipeline's stages
        read like a ``Scenario``.

    Raises
    ------
    ScenarioError
        Invalid data; the one-line message names the body and the quantity.
    ValueError
        The file does not exist.
    """
    source = scenario_path(path)
    stat = source.stat()
    key = tuple((str(k), v) for k, v in (overrides or {}).items())
    return _load_cached(str(source), stat.st_mtime_ns, stat.st_size, key)
