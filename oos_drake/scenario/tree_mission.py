"""The mission as data over a spacecraft tree: phases, waypoints, and the timeline they give.

A tree file's optional ``[mission]`` lists phases in order; each phase has a duration and, at
its end, waypoints for the revolute joints of the tree (arm links, array drives, any body on a
revolute joint)::

    [mission]
    interpolation = "smooth"                # or "linear", "quintic" (see below)

    [[mission.phases]]
    name = "observation"
    duration = 600.0                        # [s]; no waypoint: every joint holds its angle

    [[mission.phases]]
    name = "array_slew"
    duration = 400.0
    joints = { SA1 = 1.5, SA2 = 1.5 }       # [rad] joint angles at the phase end, by body

    [[mission.phases]]
    name = "approach"
    duration = 300.0
    joints = { SA1 = 0.0 }
    [mission.phases.tip]                    # this phase's port pose
    port = "GRASP"
    p_G_D = [1.75, 0.25, -0.35]
    R_G_D = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]

- The mission starts at ``t = 0`` with every joint at its file angle (``joint.angle``); a joint
  not named by a phase holds its angle through that phase.
- ``joints``: angle [rad] at the phase end of any body on a revolute joint, within its limits.
- ``tip``: pose of a port at the phase end, in the root's centre-of-mass frame (``R_G_D`` port
  axes in root axes [-], ``p_G_D`` root centre of mass -> port [m]); the revolute joints between
  the root and the port (an arm chain) are solved by inverse kinematics once, when the timeline
  is built (:func:`oos_drake.multibody.tree_ik.mission_timeline`, Drake), starting from the
  previous waypoint; a pose out of reach is an error that gives the residual. A phase cannot
  also name a joint of that chain in ``joints``.
- ``captured = [PORT, TARGET_PORT]``: through the whole phase a target (a ``free = true`` body
  of the file) is welded to the tree, the two ports coinciding with aligned axes
  (:func:`oos_drake.scenario.tree.captured_tree`); without it the target is free and not in
  the models.
- ``docked = { ports = [PORT, TARGET_PORT], k_shear = ..., k_tors = ..., d_shear = ...,
  d_tors = ..., stiffness_percent = ..., damping_percent = ... }``: through the phase a target is
  held by a 6-DOF spring-damper between the two ports (at rest where they coincide, axes
  aligned; stiffness [N/m, N m/rad], damping [N s/m, N m s/rad], uncertain by the percentages:
  blocks ``k_shear_<PORT>``, ``k_tors_<PORT>``, ``d_shear_<PORT>``, ``d_tors_<PORT>``, or
  ``..._<NAME>`` with the optional ``name = NAME``); :func:`oos_drake.scenario.tree.docked_tree`.
  The phase's start is a docking event (unless the previous phase holds the target at the same
  ports): ``oos analyze`` studies it (``docking-<phase>``, the stiffness swept as schema 1's
  phases 7 and 8, :meth:`oos_drake.scenario.tree_scenario.TreeScenario.docking_plant`).
- Between waypoints the angles are interpolated per phase: ``"smooth"`` (default) is the cubic
  ``q = q0 + (3 s^2 - 2 s^3) (q1 - q0)``, ``s = (t - t0) / (t1 - t0)``, so every joint starts and
  ends each phase at rest; ``"quintic"`` is ``q0 + (10 s^3 - 15 s^4 + 6 s^5) (q1 - q0)`` (at
  rest with zero acceleration at both ends: schema 1's joint trajectories,
  :mod:`oos_drake.scenario.timeline`); ``"linear"`` is ``q0 + s (q1 - q0)`` (constant rate in a
  phase). All stay between the two waypoints, hence within the joint limits.

Without ``[mission]`` the timeline is the single instant ``t = 0`` at the file's angles.

Examples
--------
>>> from oos_drake.scenario.tree import load_tree
>>> from oos_drake.scenario.tree_mission import build_timeline
>>> timeline = build_timeline(load_tree("flexible_satellite"))
>>> timeline.phase_names
('observation', 'array_slew', 'observation_2')
>>> [round(c.time) for c in timeline.configurations(3)]
[0, 600, 800, 1000, 1600]
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from oos_drake.scenario.data import (
    ScenarioError,
    Table,
    check_percent,
    check_positive,
    check_rotation,
)

if TYPE_CHECKING:  # annotations only: the tree module imports this one
    from oos_drake.scenario.tree import SpacecraftTree

__all__ = [
    "INTERPOLATIONS",
    "ANALYSIS_INSTANTS",
    "TipWaypoint",
    "Docking",
    "MissionPhase",
    "TreeMission",
    "IkSolution",
    "Configuration",
    "Timeline",
    "read_mission",
    "build_timeline",
]

#: Interpolation of the joint angles between two waypoints (see the module docstring).
INTERPOLATIONS = ("smooth", "linear", "quintic")
#: Evenly spaced instants of :meth:`Timeline.configurations` by default (the phase boundaries
#: are added): the configurations that ``oos validate`` checks.
ANALYSIS_INSTANTS = 5


@dataclass(frozen=True, eq=False)
class TipWaypoint:
    """Pose of a port at a phase end, reached by moving the revolute joints of its chain.

    Attributes
    ----------
    port : str
        The port (an arm's tip port, for instance).
    R_G_D : (3, 3) ndarray
        Port axes in the root's axes [-].
    p_G_D : (3,) ndarray
        Root centre of mass ``G`` -> port ``D``, root axes [m].
    chain : tuple of str
        Bodies on revolute joints between the root and the port, root side first (the joints
        the inverse kinematics moves).
    """

    port: str
    R_G_D: np.ndarray
    p_G_D: np.ndarray
    chain: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class Docking:
    """A target held by a spring-damper between two ports (a docking interface).

    Attributes
    ----------
    port, target_port : str
        Port of the tree and port of a target; at rest they coincide, axes aligned.
    k_shear : float
        Translational stiffness [N/m] (block ``k_shear_<port>``).
    k_tors : float
        Rotational stiffness [N m/rad] (``k_tors_<port>``).
    d_shear : float
        Translational damping [N s/m] (``d_shear_<port>``).
    d_tors : float
        Rotational damping [N m s/rad] (``d_tors_<port>``).
    stiffness_percent, damping_percent : float
        Relative half-ranges of the stiffness and damping blocks [%] (0: known).
    name : str or None
        Name of the spring-damper in its blocks' names (``k_shear_<name>``, ...); None: the
        port's (``oos tree convert`` names schema 1's ``SM1``, ``SM2``).
    """

    port: str
    target_port: str
    k_shear: float
    k_tors: float
    d_shear: float
    d_tors: float
    stiffness_percent: float = 0.0
    damping_percent: float = 0.0
    name: str | None = None

    @property
    def label(self) -> str:
        """The spring-damper's name in its blocks' names: ``name``, else the port."""
        return self.name or self.port

    @property
    def connection(self) -> tuple[str, str]:
        """``(port, target port)``."""
        return (self.port, self.target_port)


@dataclass(frozen=True, eq=False)
class MissionPhase:
    """One phase of the mission.

    Attributes
    ----------
    name : str
        Phase name (unique).
    duration : float
        Duration [s], > 0.
    joints : Mapping[str, float]
        Joint angles [rad] at the phase end, by body on a revolute joint.
    tip : TipWaypoint or None
        A port pose at the phase end (joints of its chain by inverse kinematics).
    captured : tuple of (str, str) or None
        ``(port of the tree, port of a target)`` welded through the whole phase (a rigid
        capture), or None: the target is free.
    docked : Docking or None
        A target held by a spring-damper through the whole phase.
    """

    name: str
    duration: float
    joints: Mapping[str, float]
    tip: TipWaypoint | None
    captured: tuple[str, str] | None = None
    docked: Docking | None = None


@dataclass(frozen=True, eq=False)
class TreeMission:
    """The ``[mission]`` section of a tree file.

    Attributes
    ----------
    phases : tuple of MissionPhase
        Phases in order, the first starting at ``t = 0``.
    interpolation : str
        ``"smooth"``, ``"linear"`` or ``"quintic"``.
    """

    phases: tuple[MissionPhase, ...]
    interpolation: str

    @property
    def duration(self) -> float:
        """Mission duration [s]."""
        return float(sum(phase.duration for phase in self.phases))

    @property
    def has_tip_waypoints(self) -> bool:
        """Whether building the timeline needs inverse kinematics."""
        return any(phase.tip is not None for phase in self.phases)


@dataclass(frozen=True)
class IkSolution:
    """Joint angles that place a port, with the residual they leave.

    Attributes
    ----------
    port : str
        The port placed.
    angles : Mapping[str, float]
        Angle [rad] of every revolute joint of the chain, by body.
    position_error : float
        Distance from the port to its target [m].
    orientation_error : float
        Angle of the rotation from the port's axes to the target's [rad].
    """

    port: str
    angles: Mapping[str, float]
    position_error: float
    orientation_error: float


@dataclass(frozen=True, eq=False)
class Configuration:
    """The tree at one instant of the timeline.

    Attributes
    ----------
    time : float
        Mission time [s].
    phase : str
        Phase the instant belongs to (at a boundary: the phase ending there; ``t = 0``: the
        first phase).
    angles : Mapping[str, float]
        Angle [rad] of every revolute joint, by body.
    captured : tuple of (str, str) or None
        Ports welded in this phase (see :attr:`MissionPhase.captured`).
    docked : Docking or None
        Spring-damper holding a target in this phase (see :attr:`MissionPhase.docked`).
    """

    time: float
    phase: str
    angles: Mapping[str, float]
    captured: tuple[str, str] | None = None
    docked: Docking | None = None


#: ``(phase name, tip waypoint, joint angles before the phase end) -> IkSolution``.
TipSolver = Callable[[str, TipWaypoint, Mapping[str, float]], IkSolution]


@dataclass(frozen=True, eq=False)
class Timeline:
    """Joint angles at any mission time: waypoints at the phase boundaries, interpolated.

    Attributes
    ----------
    joint_names : tuple of str
        Bodies on revolute joints (columns of ``waypoints``).
    boundaries : (K + 1,) ndarray
        Phase boundaries [s]: ``0``, the end of each phase.
    waypoints : (K + 1, J) ndarray
        Joint angles at the boundaries [rad] (row 0: the file's angles).
    phase_names : tuple of str
        The K phases.
    interpolation : str
        ``"smooth"``, ``"linear"`` or ``"quintic"``.
    tip_solutions : Mapping[str, IkSolution]
        Inverse-kinematics solution of each phase with a tip waypoint, by phase name (with the
        residual left).
    captures : tuple
        Per phase, the welded ports ``(port, target port)`` or None.
    dockings : tuple
        Per phase, the :class:`Docking` holding a target, or None.
    """

    joint_names: tuple[str, ...]
    boundaries: np.ndarray
    waypoints: np.ndarray
    phase_names: tuple[str, ...]
    interpolation: str
    tip_solutions: Mapping[str, IkSolution]
    captures: tuple = ()
    dockings: tuple = ()

    @property
    def duration(self) -> float:
        """Mission duration [s]."""
        return float(self.boundaries[-1])

    def _phase_index(self, time: float) -> int:
        if not -1e-9 <= time <= self.duration * (1 + 1e-12) + 1e-9:
            raise ValueError(f"time {time:g} s outside the mission [0, {self.duration:g}] s")
        if len(self.phase_names) == 0:
            return -1
        index = int(np.searchsorted(self.boundaries, time, side="left")) - 1
        return min(max(index, 0), len(self.phase_names) - 1)

    def phase_at(self, time: float) -> str:
        """Name of the phase at ``time`` [s] (at a boundary: the phase ending there)."""
        index = self._phase_index(float(time))
        return self.phase_names[index] if index >= 0 else ""

    def angles(self, time: float) -> dict[str, float]:
        """Angle [rad] of every revolute joint at mission time ``time`` [s], by body."""
        row = self.angle_table(np.array([float(time)]))[0]
        return dict(zip(self.joint_names, row.tolist(), strict=True))

    def angle_table(self, times) -> np.ndarray:
        """Angles [rad] of the revolute joints (columns: :attr:`joint_names`) at mission
        ``times`` [s] (rows).

        ``q0 + h(s) (q1 - q0)`` in the phase at each time (at a boundary: the phase ending
        there, whose end waypoint it returns exactly), in numpy's arithmetic in this order, as
        schema 1's :class:`~oos_drake.scenario.timeline.QuinticTrajectory`: a schema-1 file
        converted to a tree has its angles to the last bit.
        """
        times = np.atleast_1d(np.asarray(times, dtype=float))
        if len(self.phase_names) == 0:
            return np.broadcast_to(self.waypoints[0], (times.size, len(self.joint_names))).copy()
        index = np.array([self._phase_index(float(t)) for t in times], dtype=int)
        t0, t1 = self.boundaries[index], self.boundaries[index + 1]
        s = np.clip((times - t0) / (t1 - t0), 0.0, 1.0)
        if self.interpolation == "linear":
            h = s
        elif self.interpolation == "quintic":
            h = s**3 * (10.0 + s * (-15.0 + 6.0 * s))
        else:
            h = s * s * (3.0 - 2.0 * s)
        q0, q1 = self.waypoints[index], self.waypoints[index + 1]
        return np.where(h[:, None] == 1.0, q1, q0 + (q1 - q0) * h[:, None])

    def configurations(self, n: int = ANALYSIS_INSTANTS) -> tuple[Configuration, ...]:
        """Configurations for the analysis: ``n`` instants evenly spaced over the mission and
        every phase boundary (merged, in time order; so at least ``n`` unless the mission is a
        single instant).

        Parameters
        ----------
        n : int
            Number of evenly spaced instants (>= 1; 1 gives ``t = 0`` and the boundaries;
            default :data:`ANALYSIS_INSTANTS`).
        """
        if n < 1:
            raise ValueError(f"configurations: n must be >= 1, got {n}")
        times = np.concatenate([np.linspace(0.0, self.duration, int(n)), self.boundaries])
        times = np.sort(times)
        keep = np.r_[True, np.diff(times) > 1e-9 * max(self.duration, 1.0)]
        return tuple(
            Configuration(
                float(t),
                self.phase_at(t),
                MappingProxyType(self.angles(t)),
                self.captured_at(t),
                self.docked_at(t),
            )
            for t in times[keep]
        )

    def docked_at(self, time: float) -> Docking | None:
        """Docking interface at ``time`` [s] (that of the phase at that time), or None."""
        index = self._phase_index(float(time))
        return self.dockings[index] if index >= 0 and self.dockings else None

    def captured_at(self, time: float) -> tuple[str, str] | None:
        """Ports welded at ``time`` [s] (those of the phase at that time), or None."""
        index = self._phase_index(float(time))
        return self.captures[index] if index >= 0 and self.captures else None


# ----------------------------------------------------------------------------------------------
# reading
# ----------------------------------------------------------------------------------------------
def _read_tip(raw: Any, where: str, tree: SpacecraftTree) -> TipWaypoint:
    t = Table(raw, where)
    port = t.text("port")
    if port not in tree.ports:
        raise ScenarioError(where, f"port '{port}' is not a port (ports: {', '.join(tree.ports)})")
    R = t.array("R_G_D", (3, 3))
    p = t.array("p_G_D", (3,))
    t.close()
    check_rotation(where, "R_G_D", R)
    chain = tree.revolute_chain(tree.ports[port].body)
    if not chain:
        raise ScenarioError(where, f"port '{port}': no revolute joint between the root and it")
    return TipWaypoint(port, R, p, chain)


def _read_captured(raw: Any, where: str, tree: SpacecraftTree) -> tuple[str, str]:
    if not (isinstance(raw, list) and len(raw) == 2 and all(isinstance(p, str) for p in raw)):
        raise ScenarioError(where, f"expected [PORT, TARGET_PORT], got {raw!r}")
    port, target_port = raw
    if port not in tree.ports:
        raise ScenarioError(where, f"'{port}' is not a port of the tree ({', '.join(tree.ports)})")
    known = [p for target in tree.targets.values() for p in target.ports]
    if target_port not in known:
        raise ScenarioError(
            where, f"'{target_port}' is not a port of a target ({', '.join(known) or 'none'})"
        )
    return (port, target_port)


def _read_docked(raw: Any, where: str, tree: SpacecraftTree) -> Docking:
    t = Table(raw, where)
    ports = t.get("ports")
    port, target_port = _read_captured(ports, f"{where}.ports", tree)
    target = next(x for x in tree.targets.values() if target_port in x.ports)
    if target.ports[target_port].body != target.root:
        raise ScenarioError(
            f"{where}.ports", f"'{target_port}' must be on the target's root body '{target.root}'"
        )
    values = {key: t.number(key) for key in ("k_shear", "k_tors", "d_shear", "d_tors")}
    percents = {key: t.number(key, 0.0) for key in ("stiffness_percent", "damping_percent")}
    name = t.text("name", "") or None
    t.close()
    if name is not None and not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name):
        raise ScenarioError(f"{where}.name", f"{name!r}: letters, digits and _ only")
    for key, value in values.items():
        check_positive(where, key, value)
    for key, value in percents.items():
        check_percent(where, key, value, 100.0)
    return Docking(port, target_port, **values, **percents, name=name)


def _read_phase(raw: Any, index: int, tree: SpacecraftTree) -> MissionPhase:
    label = raw.get("name") if isinstance(raw, dict) else None
    where = f"mission.{label or f'phases[{index}]'}"
    t = Table(raw, where)
    name = t.text("name")
    duration = t.number("duration")
    check_positive(where, "duration [s]", duration)
    raw_joints = t.get("joints", {})
    if not isinstance(raw_joints, dict):
        raise ScenarioError(f"{where}.joints", "expected a table { BODY = angle [rad] }")
    revolute = tree.revolute_bodies
    joints = {}
    for body, value in raw_joints.items():
        if body not in revolute:
            raise ScenarioError(
                f"{where}.joints",
                f"{body} is not a body on a revolute joint ({', '.join(revolute) or 'none'})",
            )
        angle = Table({body: value}, f"{where}.joints").number(body)
        joint = tree.body(body).joint
        if not joint.lower <= angle <= joint.upper:
            raise ScenarioError(
                f"{where}.joints",
                f"{body} = {angle:g} rad out of its limits [{joint.lower:g}, {joint.upper:g}]",
            )
        joints[body] = angle
    tip = _read_tip(t.get("tip"), f"{where}.tip", tree) if "tip" in t.raw else None
    t.get("tip", None)
    captured = (
        _read_captured(t.get("captured"), f"{where}.captured", tree)
        if "captured" in t.raw
        else None
    )
    t.get("captured", None)
    docked = None
    if "docked" in t.raw:
        docked = _read_docked(t.get("docked"), f"{where}.docked", tree)
    t.get("description", "")
    t.close()
    if tip is not None:
        both = sorted(set(tip.chain) & set(joints))
        if both:
            raise ScenarioError(
                f"{where}.joints",
                f"{both[0]} is moved by the tip waypoint of port '{tip.port}' "
                "(give one or the other)",
            )
    if captured is not None and docked is not None:
        raise ScenarioError(where, "captured and docked: give one connection per phase")
    return MissionPhase(name, duration, MappingProxyType(joints), tip, captured, docked)


def read_mission(raw: Any, tree: SpacecraftTree) -> TreeMission:
    """Read and check a ``[mission]`` section against its tree.

    Parameters
    ----------
    raw : dict
        The section's TOML table.
    tree : SpacecraftTree
        The tree it moves (bodies, joint limits, ports).

    Raises
    ------
    ScenarioError
        One line naming ``mission.<phase>`` and the field.
    """
    t = Table(raw, "mission")
    interpolation = t.text("interpolation", "smooth")
    if interpolation not in INTERPOLATIONS:
        raise ScenarioError(
            "mission", f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}"
        )
    raw_phases = t.get("phases")
    t.close()
    if not isinstance(raw_phases, list) or not raw_phases:
        raise ScenarioError("mission", "phases: expected a non-empty list of [[mission.phases]]")
    phases = tuple(_read_phase(raw, index, tree) for index, raw in enumerate(raw_phases))
    seen = set()
    for phase in phases:
        if phase.name in seen:
            raise ScenarioError(f"mission.{phase.name}", "name: two phases have this name")
        seen.add(phase.name)
    return TreeMission(phases, interpolation)


# ----------------------------------------------------------------------------------------------
# timeline
# ----------------------------------------------------------------------------------------------
def build_timeline(tree: SpacecraftTree, solve_tip: TipSolver | None = None) -> Timeline:
    """The timeline of a tree's mission.

    Parameters
    ----------
    tree : SpacecraftTree
        The tree (its ``mission`` may be None: a single instant at the file's angles).
    solve_tip : callable, optional
        ``(phase name, TipWaypoint, angles before) -> IkSolution``: the inverse kinematics of
        tip waypoints (needed only when the mission has some; Drake's is
        :func:`oos_drake.multibody.tree_ik.mission_timeline`).

    Raises
    ------
    ScenarioError
        A tip waypoint without a solver, or the solver's error (out of reach, with the residual).
    """
    names = tree.revolute_bodies
    current = tree.operating_angles()
    rows = [[current[name] for name in names]]
    boundaries = [0.0]
    solutions = {}
    mission = tree.mission
    phases = () if mission is None else mission.phases
    for phase in phases:
        current.update(phase.joints)
        if phase.tip is not None:
            if solve_tip is None:
                raise ScenarioError(
                    f"mission.{phase.name}.tip",
                    "a tip-pose waypoint needs inverse kinematics: build the timeline with "
                    "oos_drake.multibody.tree_ik.mission_timeline",
                )
            solution = solve_tip(phase.name, phase.tip, dict(current))
            current.update(solution.angles)
            solutions[phase.name] = solution
        rows.append([current[name] for name in names])
        boundaries.append(boundaries[-1] + phase.duration)
    waypoints = np.array(rows, dtype=float).reshape(len(rows), len(names))
    boundaries = np.array(boundaries)
    waypoints.setflags(write=False)
    boundaries.setflags(write=False)
    return Timeline(
        joint_names=names,
        boundaries=boundaries,
        waypoints=waypoints,
        phase_names=tuple(phase.name for phase in phases),
        interpolation="linear" if mission is None else mission.interpolation,
        tip_solutions=MappingProxyType(solutions),
        captures=tuple(phase.captured for phase in phases),
        dockings=tuple(phase.docked for phase in phases),
    )
