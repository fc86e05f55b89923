"""The spacecraft as a tree of bodies: scenario schema version 2, loaded into frozen dataclasses.

A tree file names its bodies, each with a parent and the joint that attaches it, a ``[control]``
section naming the attitude-controlled body, and optional ports::

    schema_version = 2
    name = "flexible_satellite"

    [control]
    controlled_body = "HUB"           # the root: a rigid body, free-floating
    pointing_requirement = 0.005      # [rad] and every other field of schema 1's [control]
    ...                               # (torque_limit, flight_software_rate_hz, [control.sensors],
                                      #  [control.actuators], [control.rolloff], [control.weights])

    [[bodies]]
    name = "HUB"
    kind = "rigid"
    mass = 300.0                      # [kg]
    inertia = [[...], [...], [...]]   # [kg m^2] at the centre of mass G, body axes
    p_B_G = [0.0, 0.0, 0.0]           # [m] body frame origin B -> G (default 0)

    [[bodies]]
    name = "SA1"
    kind = "flexible"                 # cantilevered modal appendage, body frame at its port P
    parent = "HUB"
    joint = { type = "revolute", p_parent_joint = [0.0, 0.6, 0.0], axis = [0.0, 1.0, 0.0] }
    mass = 25.0
    p_P_S = [0.0, 1.9, 0.0]
    inertia = [[...]]                 # at S, appendage axes
    frequencies_hz = [0.8, 2.6, 4.1]
    damping_ratios = [0.005, 0.005, 0.005]
    participation = [[...6...], [...6...], [...6...]]   # ROW i = mode i, [Tx Ty Tz Rx Ry Rz]
    uncertainty = { w1 = { percent = 20.0 } }

    [ports.DOCK]
    body = "HUB"
    p_B_D = [0.0, 0.0, -0.9]          # [m]; optional R_B_D [-] (port axes in body axes) and
                                      # block: name of the switch block of the connections a
                                      # mission makes at this port (default delta_DOCK)

    [mission]                         # optional: phases and waypoints, see tree_mission
    [[mission.phases]]
    name = "array_slew"
    duration = 400.0                  # [s]
    joints = { SA1 = 1.5 }            # [rad] at the phase end

Body kinds
----------
``rigid``
    mass, inertia at the centre of mass ``G`` (body axes), ``p_B_G``; optional
    ``mass_uncertainty_percent`` and ``inertia_uncertainty_percent`` (Jxx, Jyy, Jzz). A chain of
    rigid bodies on revolute joints is an arm.
``arm``
    a chain of any number of revolute links: ``parent`` and ``[[bodies.links]]``, each link a
    rigid body (``name``, ``mass``, ``inertia``, ``p_B_G``, ...) with its revolute ``joint`` (the
    first link's joint pose is in the arm's parent frame, every other one in the previous link's);
    optional ``tip = {name, p_B_D, R_B_D}`` declares a port on the last link. The links become
    ordinary rigid bodies of the tree.
``flexible``
    a cantilevered appendage given by its modal data at its attachment port ``P`` (its body frame
    origin): mass, ``p_P_S``, inertia at ``S``, ``frequencies_hz``, ``damping_ratios`` and the
    participation rows; any mode uncertain through ``uncertainty.w<i>`` (``percent`` or
    ``range_hz``). A flexible body is a leaf (no child body, no port).

Joints
------
The root (the controlled body) has none: it floats. Every other body has
``joint = {type, p_parent_joint, R_parent_joint, axis, angle, lower, upper}``:

- ``p_parent_joint`` [m], ``R_parent_joint`` [-]: pose of the joint frame ``J`` in the parent's
  body frame (``v_parent = R_parent_joint v_J``); the child's body frame is ``J`` turned by
  ``angle`` about ``axis`` (in ``J``), i.e. ``R_parent_child = R_parent_joint R(axis, angle)``;
- ``type = "fixed"`` (no axis, angle 0) or ``"revolute"`` (motion-driven: the LFR's scheduled
  block ``tau_<body> = tan(angle/4)``; ``angle`` [rad] is the operating angle of the file,
  ``lower``/``upper`` [rad] optional limits within [-pi, pi]; ``block`` optional: another name
  for that block, unique in the tree, e.g. a schema-1 file's ``tau_theta1`` kept by
  ``oos tree convert``).

Free bodies
-----------
A rigid root with ``free = true`` is a target: a second free body with its own subtree and
ports, kept apart in :attr:`SpacecraftTree.targets` (in no model while free); a mission phase
``captured = [PORT, TARGET_PORT]`` welds it to the tree (:func:`captured_tree`).

Conventions and errors are those of :mod:`oos_drake.scenario.data` (SI units, ``p_A_B`` the
vector A -> B in A's frame, one-line :class:`~oos_drake.scenario.data.ScenarioError` naming the
body and the field, unknown keys rejected). The tree is checked for duplicate names, missing or
misspelt parents, cycles, ports on bodies that do not exist, a controlled body that does not exist
or is not the root, and appendages whose residual mass ``D_P - L^T L`` is not positive definite.

Examples
--------
>>> from oos_drake.scenario.tree import load_tree
>>> tree = load_tree("flexible_satellite")
>>> [body.name for body in tree.bodies]
['HUB', 'SA1', 'SA2']
>>> tree.children("HUB")
('SA1', 'SA2')
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from oos_drake.resources import package_path
from oos_drake.scenario.data import (
    ControlRequirements,
    ScenarioError,
    Table,
    check_inertia,
    check_percent,
    check_positive,
    check_rotation,
    check_unit,
    read_control,
)
from oos_drake.scenario.tree_mission import TreeMission, read_mission
from oos_drake.titop.parameters import check_name
from oos_drake.titop.spatial import rigid_spatial_inertia, rotation_matrix

__all__ = [
    "TREE_SCHEMA_VERSION",
    "TREE_DIRECTORY",
    "BODY_KINDS",
    "JOINT_TYPES",
    "Joint",
    "RigidBodyData",
    "FlexibleBodyData",
    "ModeUncertainty",
    "TreePort",
    "TreeControl",
    "SpacecraftTree",
    "body_poses",
    "port_pose",
    "captured_tree",
    "docked_tree",
    "load_tree",
    "parse_tree",
    "tree_path",
    "shipped_trees",
]

TREE_SCHEMA_VERSION = 2
#: Shipped tree scenarios (``oos_drake/scenario/data/trees/<name>.toml``).
TREE_DIRECTORY = package_path("oos_drake.scenario", "data", "trees")
BODY_KINDS = ("rigid", "flexible")
#: Entries of ``[[bodies]]`` that expand into several bodies (an arm: a chain of revolute links).
CHAIN_KINDS = ("arm",)
JOINT_TYPES = ("fixed", "revolute")
#: Relative margin below which ``D_P - L^T L`` counts as singular (its smallest eigenvalue over
#: the largest entry of ``D_P``): the Drake twin's mass matrix inherits that conditioning.
RESIDUAL_MASS_RTOL = 1e-9


# ----------------------------------------------------------------------------------------------
# dataclasses
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Joint:
    """How a body hangs on its parent.

    Attributes
    ----------
    type : str
        ``"fixed"`` or ``"revolute"`` (motion-driven at a linearization point).
    p_parent_joint : (3,) ndarray
        Parent body frame origin -> joint frame origin ``J``, in the parent's frame [m].
    R_parent_joint : (3, 3) ndarray
        Joint frame axes in the parent's frame (``v_parent = R_parent_joint v_J``) [-].
    axis : (3,) ndarray
        Unit rotation axis in the joint frame [-] (zeros for a fixed joint).
    angle : float
        Operating angle of the file [rad] (0 for a fixed joint).
    lower, upper : float
        Joint limits [rad], within [-pi, pi] (the LFR's ``tau = tan(angle/4)`` covers that range).
    docking : Docking or None
        Only for ``type = "bushing"`` (made by :func:`docked_tree`, not read from files): the
        spring-damper holding the child.
    block : str
        Name of the scheduled block of a revolute joint in the models (``joint.block`` in the
        file, e.g. ``"tau_theta1"`` to keep a schema-1 scenario's name; "": ``tau_<body>``).
    """

    type: str
    p_parent_joint: np.ndarray
    R_parent_joint: np.ndarray
    axis: np.ndarray
    angle: float
    lower: float
    upper: float
    docking: Any = None
    block: str = ""

    def R_parent_child(self, angle: float | None = None) -> np.ndarray:
        """Child body axes in the parent's frame at ``angle`` [rad] (default: the file's)."""
        angle = self.angle if angle is None else float(angle)
        if self.type != "revolute":
            return np.array(self.R_parent_joint)
        return self.R_parent_joint @ rotation_matrix(self.axis, angle)


@dataclass(frozen=True, eq=False)
class RigidBodyData:
    """A rigid body (hub, boom, arm link).

    Attributes
    ----------
    name : str
        Body name (block names ``m_<name>``, ``Jxx_<name>``, ``tau_<name>``).
    parent : str
        Parent body ("" for the root).
    joint : Joint or None
        Joint to the parent (None for the root).
    mass : float
        Nominal mass [kg].
    inertia : (3, 3) ndarray
        Inertia at the centre of mass ``G``, body axes [kg m^2].
    p_B_G : (3,) ndarray
        Body frame origin ``B`` -> ``G`` in body axes [m].
    mass_uncertainty_percent : float
        Relative half-range of the mass [%] (0: known).
    inertia_uncertainty_percent : (3,) ndarray
        Relative half-ranges of Jxx, Jyy, Jzz [%].
    description : str
        Free text.
    """

    name: str
    parent: str
    joint: Joint | None
    mass: float
    inertia: np.ndarray
    p_B_G: np.ndarray
    mass_uncertainty_percent: float
    inertia_uncertainty_percent: np.ndarray
    description: str = ""

    kind = "rigid"


@dataclass(frozen=True, eq=False)
class ModeUncertainty:
    """Range of one uncertain mode frequency.

    Attributes
    ----------
    mode : int
        Mode number, 1-based (block ``w<mode>_<body>``).
    percent : float or None
        Relative half-range [%] (``w = w0 (1 + percent/100 delta)``).
    range_hz : (float, float) or None
        Absolute range [Hz], containing the nominal strictly.
    """

    mode: int
    percent: float | None
    range_hz: tuple[float, float] | None


@dataclass(frozen=True, eq=False)
class FlexibleBodyData:
    """A cantilevered flexible appendage; its body frame ``R_SA`` has its origin at the port ``P``.

    Attributes
    ----------
    name, parent, joint, description
        As for :class:`RigidBodyData`.
    mass : float
        Appendage mass [kg].
    p_P_S : (3,) ndarray
        ``P`` -> centre of mass ``S`` in ``R_SA`` [m].
    inertia : (3, 3) ndarray
        Inertia at ``S`` in ``R_SA`` [kg m^2].
    frequencies_hz : (n,) ndarray
        Cantilevered mode frequencies [Hz].
    damping_ratios : (n,) ndarray
        Modal damping ratios [-].
    participation : (n, 6) ndarray
        Participation factors at ``P`` in ``R_SA``, ROW i = mode i, columns
        ``[Tx Ty Tz Rx Ry Rz]`` [sqrt(kg), sqrt(kg) m].
    uncertainty : tuple of ModeUncertainty
        Uncertain mode frequencies (any number, any modes).
    """

    name: str
    parent: str
    joint: Joint
    mass: float
    p_P_S: np.ndarray
    inertia: np.ndarray
    frequencies_hz: np.ndarray
    damping_ratios: np.ndarray
    participation: np.ndarray
    uncertainty: tuple[ModeUncertainty, ...]
    description: str = ""

    kind = "flexible"

    @property
    def omega(self) -> np.ndarray:
        """Mode frequencies [rad/s]."""
        return 2.0 * np.pi * self.frequencies_hz

    @property
    def rigid_spatial_inertia(self) -> np.ndarray:
        """``D_P`` (6x6) at ``P`` in ``R_SA`` [kg, kg m, kg m^2]."""
        return rigid_spatial_inertia(self.mass, self.inertia, self.p_P_S)

    @property
    def residual_mass(self) -> np.ndarray:
        """``D_P0 = D_P - L^T L`` (participation rows = modes) [kg, kg m, kg m^2]."""
        return self.rigid_spatial_inertia - self.participation.T @ self.participation


@dataclass(frozen=True, eq=False)
class TreePort:
    """A port (grasp point, docking port) fixed in a body.

    Attributes
    ----------
    name : str
        Port name.
    body : str
        Body it belongs to.
    p_B_D : (3,) ndarray
        Body frame origin -> port ``D`` in body axes [m].
    R_B_D : (3, 3) ndarray
        Port axes in body axes [-].
    block : str
        Name of the switch block of the connections a mission makes at this port of the tree
        (``block`` in the file, e.g. ``"delta_C1"`` to keep a schema-1 scenario's name;
        "": ``delta_<port>``, :func:`oos_drake.scenario.tree_model.switch_block_name`).
    """

    name: str
    body: str
    p_B_D: np.ndarray
    R_B_D: np.ndarray
    block: str = ""


@dataclass(frozen=True, eq=False)
class TreeControl:
    """What the attitude control acts on.

    Attributes
    ----------
    controlled_body : str
        The attitude-controlled body (the tree's root, rigid): sensors measure its attitude and
        rate, actuators apply their torque to it; the models' input is the external wrench at its
        centre of mass and their output its acceleration twist there, in its axes.
    requirements : ControlRequirements
        Pointing requirement [rad], torque bound [N m], flight-software rate [Hz], sensors,
        actuators, roll-off and weights: the rest of ``[control]``, read by
        :func:`oos_drake.scenario.data.read_control` exactly as in a schema-1 file.
    """

    controlled_body: str
    requirements: ControlRequirements


@dataclass(frozen=True, eq=False)
class SpacecraftTree:
    """A spacecraft as a tree of bodies (schema version 2).

    Attributes
    ----------
    name : str
        Scenario name.
    description : str
        Free text.
    bodies : tuple of RigidBodyData or FlexibleBodyData
        Every body, parents before children (the root first).
    ports : Mapping[str, TreePort]
        Ports by name.
    control : TreeControl
        The attitude-controlled body and the control requirements.
    mission : TreeMission or None
        Phases and waypoints (:mod:`oos_drake.scenario.tree_mission`); None without
        ``[mission]``.
    targets : Mapping[str, SpacecraftTree]
        Free bodies (``free = true`` roots) with their subtrees and ports, by root name (their
        ``control`` is None): not part of the models until captured (:func:`captured_tree`).
    source : Path or None
        File the tree was read from.
    closures : tuple
        Spring-dampers (:class:`~oos_drake.scenario.tree_mission.Docking`) that close a loop
        between two bodies of the tree besides its joints (made by :func:`docked_tree`, not read
        from files): the target of a docking event still held at another port.
    """

    name: str
    description: str
    bodies: tuple
    ports: Mapping[str, TreePort]
    control: TreeControl | None
    mission: TreeMission | None = None
    targets: Mapping[str, SpacecraftTree] = dataclasses.field(
        default_factory=lambda: MappingProxyType({})
    )
    source: Path | None = None
    closures: tuple = ()

    @property
    def root(self) -> str:
        """Name of the root body (the controlled body)."""
        return self.bodies[0].name

    def body(self, name: str):
        """The body named ``name`` (``KeyError`` naming the known bodies otherwise)."""
        for body in self.bodies:
            if body.name == name:
                return body
        raise KeyError(f"no body {name!r} (bodies: {', '.join(b.name for b in self.bodies)})")

    def children(self, name: str) -> tuple[str, ...]:
        """Names of the bodies whose parent is ``name``, in file order."""
        return tuple(b.name for b in self.bodies if b.parent == name)

    @property
    def revolute_bodies(self) -> tuple[str, ...]:
        """Bodies on revolute joints (their angles are the scheduled blocks ``tau_<body>``)."""
        return tuple(
            b.name for b in self.bodies if b.joint is not None and b.joint.type == "revolute"
        )

    def revolute_chain(self, name: str) -> tuple[str, ...]:
        """Bodies on revolute joints between the root and body ``name`` (included), root side
        first: the joints that move ``name``."""
        path = []
        body = self.body(name)
        while body.joint is not None:
            if body.joint.type == "revolute":
                path.append(body.name)
            body = self.body(body.parent)
        return tuple(reversed(path))

    def angle_block(self, name: str) -> str:
        """Name of the scheduled block of body ``name``'s revolute joint: its ``joint.block``,
        else ``tau_<name>``."""
        return self.body(name).joint.block or f"tau_{name}"

    def operating_angles(self) -> dict[str, float]:
        """The file's joint angles [rad] by body, for the revolute joints."""
        return {name: float(self.body(name).joint.angle) for name in self.revolute_bodies}

    def joint_angles(self, angles: Mapping[str, float] | None = None) -> dict[str, float]:
        """Angles [rad] of every revolute joint: ``angles`` over the file's operating angles.

        Raises
        ------
        ValueError
            A body not on a revolute joint, or an angle outside its joint's limits.
        """
        chosen = self.operating_angles()
        for name, value in (angles or {}).items():
            if name not in chosen:
                raise ValueError(f"{name}: not a body on a revolute joint ({sorted(chosen)})")
            joint = self.body(name).joint
            value = float(value)
            if not joint.lower <= value <= joint.upper:
                raise ValueError(
                    f"{name}.joint: angle {value:g} rad out of its limits "
                    f"[{joint.lower:g}, {joint.upper:g}]"
                )
            chosen[name] = value
        return chosen


# ----------------------------------------------------------------------------------------------
# kinematics of the tree
# ----------------------------------------------------------------------------------------------
def body_poses(
    tree: SpacecraftTree, angles: Mapping[str, float] | None = None
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Pose of every body frame relative to the root's centre-of-mass frame (forward kinematics).

    Parameters
    ----------
    tree : SpacecraftTree
        The tree.
    angles : Mapping[str, float], optional
        Revolute joint angles [rad] by body; the file's operating angles for the others.

    Returns
    -------
    dict
        Body name -> ``(R_G_B, p_G_B)``: body axes in the root's axes [-] and the root's centre of
        mass ``G`` -> body frame origin in the root's axes [m]. For a flexible body the frame is
        its attachment frame (origin ``P``), undeformed.
    """
    chosen = tree.joint_angles(angles)
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for body in tree.bodies:
        if body.joint is None:
            poses[body.name] = (np.eye(3), -np.asarray(body.p_B_G, dtype=float))
            continue
        R_parent, p_parent = poses[body.parent]
        R_body = R_parent @ body.joint.R_parent_child(chosen.get(body.name, 0.0))
        poses[body.name] = (R_body, p_parent + R_parent @ np.asarray(body.joint.p_parent_joint))
    return poses


def port_pose(
    tree: SpacecraftTree, port: str, angles: Mapping[str, float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(R_G_D, p_G_D)`` of port ``port`` in the root's centre-of-mass frame (see
    :func:`body_poses`) [-, m]."""
    if port not in tree.ports:
        raise KeyError(f"no port {port!r} (ports: {', '.join(tree.ports)})")
    spec = tree.ports[port]
    R_body, p_body = body_poses(tree, angles)[spec.body]
    return R_body @ spec.R_B_D, p_body + R_body @ spec.p_B_D


# ----------------------------------------------------------------------------------------------
# readers
# ----------------------------------------------------------------------------------------------
def _read_joint(body: str, raw: Any) -> Joint:
    t = Table(raw, f"{body}.joint")
    kind = t.text("type")
    if kind not in JOINT_TYPES:
        raise ScenarioError(f"{body}.joint", f"type must be one of {JOINT_TYPES}, got {kind!r}")
    p = t.array("p_parent_joint", (3,), [0.0, 0.0, 0.0])
    R = t.array("R_parent_joint", (3, 3), np.eye(3).tolist())
    check_rotation(f"{body}.joint", "R_parent_joint", R)
    block = ""
    if kind == "fixed":
        axis = np.zeros(3)
        angle, lower, upper = 0.0, 0.0, 0.0
    else:
        block = t.text("block", "")
        if block and not block.isidentifier():
            raise ScenarioError(f"{body}.joint", f"block {block!r}: not a valid block name")
        axis = t.array("axis", (3,))
        check_unit(f"{body}.joint", "axis", axis)
        lower = t.number("lower", -math.pi)
        upper = t.number("upper", math.pi)
        angle = t.number("angle", 0.0)
        if not -math.pi <= lower < upper <= math.pi:
            raise ScenarioError(
                f"{body}.joint",
                f"limits must satisfy -pi <= lower < upper <= pi, got [{lower:g}, {upper:g}]",
            )
        if not lower <= angle <= upper:
            raise ScenarioError(
                f"{body}.joint", f"angle {angle:g} rad out of its limits [{lower:g}, {upper:g}]"
            )
    t.close()
    axis.setflags(write=False)
    return Joint(kind, p, R, axis, angle, lower, upper, block=block)


def _read_rigid(t: Table, name: str, parent: str, joint) -> RigidBodyData:
    body = RigidBodyData(
        name=name,
        parent=parent,
        joint=joint,
        mass=t.number("mass"),
        inertia=t.array("inertia", (3, 3)),
        p_B_G=t.array("p_B_G", (3,), [0.0, 0.0, 0.0]),
        mass_uncertainty_percent=t.number("mass_uncertainty_percent", 0.0),
        inertia_uncertainty_percent=t.array("inertia_uncertainty_percent", (3,), [0.0] * 3),
        description=t.text("description", ""),
    )
    t.close()
    check_positive(name, "mass", body.mass)
    check_inertia(name, "inertia", body.inertia)
    check_percent(name, "mass_uncertainty_percent", body.mass_uncertainty_percent, 100.0)
    check_percent(name, "inertia_uncertainty_percent", body.inertia_uncertainty_percent, 100.0)
    return body


def _read_mode_uncertainty(name: str, raw: Any, frequencies_hz: np.ndarray):
    if not isinstance(raw, dict):
        raise ScenarioError(
            f"{name}.uncertainty", "expected a table like { w1 = { percent = 20 } }"
        )
    modes = []
    for key, entry in raw.items():
        where = f"{name}.uncertainty.{key}"
        if not (key.startswith("w") and key[1:].isdigit()):
            raise ScenarioError(where, "keys are mode frequencies w1, w2, ... (1-based)")
        mode = int(key[1:])
        if not 1 <= mode <= frequencies_hz.size:
            raise ScenarioError(
                where, f"mode {mode} does not exist ({frequencies_hz.size} modes in frequencies_hz)"
            )
        t = Table(entry, where)
        percent = t.number("percent", None) if "percent" in entry else None
        range_hz = None
        if "range_hz" in entry:
            low, high = (float(v) for v in t.array("range_hz", (2,)))
            nominal = float(frequencies_hz[mode - 1])
            if not 0 < low < nominal < high:
                raise ScenarioError(
                    where, f"range_hz [{low:g}, {high:g}] must contain the nominal {nominal:g} Hz "
                    "strictly and be > 0"
                )  # fmt: skip
            range_hz = (low, high)
        t.close()
        if (percent is None) == (range_hz is None):
            raise ScenarioError(where, "give exactly one of percent or range_hz")
        if percent is not None:
            check_percent(where, "percent", percent, 100.0)
            check_positive(where, "percent", percent)
        modes.append(ModeUncertainty(mode, percent, range_hz))
    return tuple(sorted(modes, key=lambda m: m.mode))


def _read_flexible(t: Table, name: str, parent: str, joint) -> FlexibleBodyData:
    frequencies = t.array("frequencies_hz", (None,))
    n = frequencies.size
    body = FlexibleBodyData(
        name=name,
        parent=parent,
        joint=joint,
        mass=t.number("mass"),
        p_P_S=t.array("p_P_S", (3,)),
        inertia=t.array("inertia", (3, 3)),
        frequencies_hz=frequencies,
        damping_ratios=t.array("damping_ratios", (n,)),
        participation=t.array("participation", (n, 6)),
        uncertainty=_read_mode_uncertainty(name, t.get("uncertainty", {}), frequencies),
        description=t.text("description", ""),
    )
    t.close()
    check_positive(name, "mass", body.mass)
    check_inertia(name, "inertia", body.inertia)
    if n == 0:
        raise ScenarioError(name, "frequencies_hz: a flexible body needs at least one mode")
    if not np.all(frequencies > 0):
        raise ScenarioError(name, f"frequencies_hz must be > 0, got {frequencies.min():g}")
    if not np.all(body.damping_ratios >= 0):
        raise ScenarioError(name, f"damping_ratios must be >= 0, got {body.damping_ratios.min():g}")
    D_P = body.rigid_spatial_inertia
    min_eig = float(np.linalg.eigvalsh(0.5 * (body.residual_mass + body.residual_mass.T)).min())
    if min_eig <= RESIDUAL_MASS_RTOL * float(np.abs(D_P).max()):
        raise ScenarioError(
            name,
            f"participation: residual mass D_P - L^T L is not positive definite (min eigenvalue "
            f"{min_eig:.4g}); the modes carry more inertia than the appendage (rows = modes?)",
        )
    return body


def _read_body(raw: Any, index: int, known_name: str | None = None):
    label = known_name or (raw.get("name") if isinstance(raw, dict) else None) or f"bodies[{index}]"
    t = Table(raw, str(label))
    name = known_name if known_name is not None else t.text("name")
    try:
        check_name(name, "body name")
    except ValueError:
        detail = f"name {name!r} must be letters, digits, underscores"
        raise ScenarioError(str(label), detail) from None
    kind = t.text("kind")
    if kind not in BODY_KINDS:
        raise ScenarioError(name, f"kind must be one of {BODY_KINDS + CHAIN_KINDS}, got {kind!r}")
    parent = t.text("parent", "")
    joint = None
    if parent:
        joint = _read_joint(name, t.get("joint"))
    elif "joint" in t.raw:
        raise ScenarioError(name, "joint given without a parent (the root floats)")
    if kind == "rigid":
        return _read_rigid(t, name, parent, joint)
    if not parent:
        raise ScenarioError(name, "parent: a flexible appendage must hang on a body")
    return _read_flexible(t, name, parent, joint)


def _expand_arm(raw: dict, name: str) -> tuple[list[tuple[str, dict]], dict]:
    """An ``arm`` entry -> its links as rigid-body entries (each on its revolute joint, parent the
    previous link) and its tip port (``{port name: table}``, empty without ``tip``)."""
    t = Table(raw, name)
    t.text("kind")
    parent = t.text("parent")
    links = t.get("links")
    tip = t.get("tip", None)
    t.get("description", "")
    t.close()
    if not isinstance(links, list) or not links:
        raise ScenarioError(name, "links: an arm needs a non-empty list of [[bodies.links]]")
    entries = []
    for k, link in enumerate(links):
        where = f"{name}.links[{k}]"
        if not isinstance(link, dict):
            raise ScenarioError(where, "expected a table")
        link_name = link.get("name", where)
        joint = link.get("joint")
        if not isinstance(joint, dict) or joint.get("type") != "revolute":
            raise ScenarioError(str(link_name), "joint: every arm link needs a revolute joint")
        if "kind" in link or "parent" in link:
            raise ScenarioError(str(link_name), "kind and parent of an arm link are implied")
        entries.append((str(link_name), {**link, "kind": "rigid", "parent": parent}))
        parent = str(link_name)
    ports = {}
    if tip is not None:
        t = Table(tip, f"{name}.tip")
        port = t.text("name")
        ports[port] = {"body": parent, **{k: v for k, v in tip.items() if k != "name"}}
        t.used.update(tip)
        t.close()
    return entries, ports


def _read_bodies(raw: Any) -> tuple[list, dict, set]:
    """Bodies from ``[[bodies]]`` entries or ``[bodies.NAME]`` tables (``arm`` entries expanded
    into their links); returns the bodies, the arms' tip ports and the free roots (targets)."""
    if isinstance(raw, list):
        named = [(entry.get("name") if isinstance(entry, dict) else None, entry) for entry in raw]
        from_table = False
    elif isinstance(raw, dict):
        named = list(raw.items())
        from_table = True
    else:
        raise ScenarioError("bodies", "expected [[bodies]] entries or [bodies.NAME] tables")
    bodies, ports, free = [], {}, set()
    for index, (name, entry) in enumerate(named):
        if isinstance(entry, dict) and "free" in entry:
            label = str(name if name is not None else entry.get("name", f"bodies[{index}]"))
            if entry["free"] is not True or "parent" in entry or entry.get("kind") != "rigid":
                raise ScenarioError(
                    label, "free: only 'free = true' on a rigid body without parent (a target)"
                )
            entry = {k: v for k, v in entry.items() if k != "free"}
            free.add(label)
        if isinstance(entry, dict) and entry.get("kind") == "arm":
            arm_name = str(name if name is not None else f"bodies[{index}]")
            if not from_table:
                entry = {k: v for k, v in entry.items() if k != "name"}
            links, tip = _expand_arm(entry, arm_name)
            bodies += [_read_body(link, index) for _, link in links]
            ports.update(tip)
        else:
            bodies.append(_read_body(entry, index, name if from_table else None))
    return bodies, ports, free


def _ordered(bodies: list, free: set[str] = frozenset()) -> tuple:
    """Check the topology (names, parents, one root besides the free ones, no cycle); return
    parents before children, the controlled tree first, then each free body's subtree."""
    by_name: dict[str, Any] = {}
    for body in bodies:
        if body.name in by_name:
            raise ScenarioError(body.name, "name: two bodies have this name")
        by_name[body.name] = body
    for body in bodies:
        if body.parent and body.parent not in by_name:
            close = difflib.get_close_matches(body.parent, list(by_name))
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ScenarioError(body.name, f"parent '{body.parent}' is not a body{hint}")
        if body.parent == body.name:
            raise ScenarioError(body.name, "parent: a body cannot be its own parent")
    for body in bodies:  # cycles: walk up from every body
        seen = [body.name]
        current = body
        while current.parent:
            current = by_name[current.parent]
            if current.name in seen:
                loop = " -> ".join(seen[seen.index(current.name) :] + [current.name])
                raise ScenarioError(body.name, f"parent: the tree has a cycle ({loop})")
            seen.append(current.name)
    roots = [b.name for b in bodies if not b.parent and b.name not in free]
    if len(roots) != 1:
        raise ScenarioError(
            roots[1] if len(roots) > 1 else "bodies",
            f"parent: the tree needs exactly one root (free-floating body), got {roots} "
            "(a target: free = true)",
        )
    roots += [b.name for b in bodies if b.name in free]
    for body in bodies:
        parent = by_name.get(body.parent)
        if parent is not None and parent.kind == "flexible":
            raise ScenarioError(
                body.name, f"parent '{body.parent}' is a flexible appendage (appendages are leaves)"
            )
    order = []
    for root in roots:
        frontier = [root]
        while frontier:
            order += frontier
            frontier = [b.name for b in bodies if b.parent in frontier]
    return tuple(by_name[name] for name in order)


def _read_ports(raw: Any, bodies: Mapping[str, Any]) -> dict[str, TreePort]:
    if not isinstance(raw, dict):
        raise ScenarioError("ports", "expected [ports.NAME] tables")
    ports = {}
    for name, entry in raw.items():
        where = f"ports.{name}"
        t = Table(entry, where)
        body = t.text("body")
        if body not in bodies:
            close = difflib.get_close_matches(body, list(bodies))
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ScenarioError(where, f"body '{body}' is not a body{hint}")
        port = TreePort(
            name=name,
            body=body,
            p_B_D=t.array("p_B_D", (3,), [0.0, 0.0, 0.0]),
            R_B_D=t.array("R_B_D", (3, 3), np.eye(3).tolist()),
            block=t.text("block", ""),
        )
        t.close()
        check_rotation(where, "R_B_D", port.R_B_D)
        if bodies[body].kind == "flexible":
            raise ScenarioError(where, f"body '{body}' is a flexible appendage (no ports on it)")
        ports[name] = port
    return ports


def _read_control(raw: Any, bodies: Mapping[str, Any], root: str) -> TreeControl:
    t = Table(raw, "control")
    controlled = t.text("controlled_body")
    if controlled not in bodies:
        close = difflib.get_close_matches(controlled, list(bodies))
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ScenarioError("control", f"controlled_body '{controlled}' is not a body{hint}")
    if controlled != root:
        raise ScenarioError(
            "control",
            f"controlled_body '{controlled}' must be the tree's root '{root}' (the free-floating "
            "body whose attitude is controlled)",
        )
    return TreeControl(controlled, read_control(t))


def _components(bodies: tuple) -> dict[str, tuple]:
    """Bodies grouped by root (``_ordered`` order: the controlled tree first)."""
    by_name = {b.name: b for b in bodies}
    groups: dict[str, list] = {}
    for body in bodies:
        root = body
        while root.parent:
            root = by_name[root.parent]
        groups.setdefault(root.name, []).append(body)
    return {root: tuple(members) for root, members in groups.items()}


def _attach_target(
    tree: SpacecraftTree, port: str, target_port: str, docking=None, closures: tuple = ()
):
    if port not in tree.ports:
        raise KeyError(f"no port {port!r} (ports: {', '.join(tree.ports)})")
    owner = [t for t in tree.targets.values() if target_port in t.ports]
    if not owner:
        known = [p for t in tree.targets.values() for p in t.ports]
        raise KeyError(f"no target port {target_port!r} (target ports: {', '.join(known)})")
    target = owner[0]
    chaser_port, weld_port = tree.ports[port], target.ports[target_port]
    R_BT = chaser_port.R_B_D @ weld_port.R_B_D.T
    p_BT = chaser_port.p_B_D - R_BT @ weld_port.p_B_D
    R_BT.setflags(write=False)
    p_BT.setflags(write=False)
    kind = "fixed" if docking is None else "bushing"
    joint = Joint(kind, p_BT, R_BT, np.zeros(3), 0.0, 0.0, 0.0, docking)
    root = dataclasses.replace(target.bodies[0], parent=chaser_port.body, joint=joint)
    others = {k: v for k, v in tree.targets.items() if k != target.name}
    return dataclasses.replace(
        tree,
        name=f"{tree.name}+{target.name}",
        bodies=tree.bodies + (root,) + target.bodies[1:],
        ports=MappingProxyType({**tree.ports, **target.ports}),
        targets=MappingProxyType(others),
        mission=None,
        closures=tuple(closures),
    )


def captured_tree(tree: SpacecraftTree, port: str, target_port: str) -> SpacecraftTree:
    """The tree with a target welded to it: ports ``port`` (of ``tree``) and ``target_port``
    (of one of ``tree.targets``) coincide, axes aligned (a rigid capture).

    The target's root becomes a child of ``port``'s body on a fixed joint at

    .. math::

        R_{BT} = R_{B D} R_{T D'}^T, \\qquad p_{BT} = p_{B D} - R_{BT}\\, p_{T D'}

    (``B`` the chaser body, ``T`` the target root's body frame, ``D``/``D'`` the two ports);
    its bodies and ports join the tree, the mission is dropped.

    Raises
    ------
    KeyError
        ``port`` not a port of ``tree``, or ``target_port`` not a port of a target.
    """
    return _attach_target(tree, port, target_port)


def docked_tree(tree: SpacecraftTree, docking, also: tuple = ()) -> SpacecraftTree:
    """The tree with a target held by a spring-damper between two ports
    (:class:`oos_drake.scenario.tree_mission.Docking`), at rest where the ports coincide.

    As :func:`captured_tree`, but the target's root hangs on a ``"bushing"`` joint carrying
    ``docking``: the TITOP model keeps the target as a free rigid body (inverse model) and
    connects the two ports through the spring-damper.

    ``also``: more spring-dampers holding the same target at other ports at the same time
    (a closed loop, schema 1's docking phase 8: the arm still holds the target when it docks),
    each at rest where its ports coincide, between the target's root and a rigid body of the
    tree (:attr:`SpacecraftTree.closures`).

    Raises
    ------
    ValueError
        A spring-damper of ``also`` on another target, off the target's root, or on a port
        that is not the tree's.
    """
    target = next((t for t in tree.targets.values() if docking.target_port in t.ports), None)
    for extra in also:
        if target is None or extra.target_port not in target.ports:
            raise ValueError(
                f"docking {extra.port}-{extra.target_port}: not the target held at "
                f"{docking.target_port}"
            )
        if target.ports[extra.target_port].body != target.root:
            raise ValueError(
                f"ports.{extra.target_port}: must be on the target's root body '{target.root}'"
            )
        if extra.port not in tree.ports:
            raise ValueError(f"docking {extra.port}: not a port of the tree")
    return _attach_target(tree, docking.port, docking.target_port, docking, tuple(also))


def _check_block_names(bodies: tuple) -> None:
    """Every revolute joint's scheduled block has its own name (``joint.block`` or
    ``tau_<body>``)."""
    seen: dict[str, str] = {}
    for body in bodies:
        if body.joint is None or body.joint.type != "revolute":
            continue
        block = body.joint.block or f"tau_{body.name}"
        if block in seen:
            raise ScenarioError(
                f"{body.name}.joint", f"block {block!r}: also the block of {seen[block]}'s joint"
            )
        seen[block] = body.name


def parse_tree(document: Mapping[str, Any], source: Path | None = None) -> SpacecraftTree:
    """Validate a parsed TOML document of schema version 2 into a :class:`SpacecraftTree`.

    Raises
    ------
    ScenarioError
        One line naming the body (or section) and the field.
    """
    where = source.name if source is not None else "tree"
    top = Table(dict(document), where, "document")
    version = top.number("schema_version")
    if version != TREE_SCHEMA_VERSION:
        hint = (
            " (convert a version 1 file with: oos tree convert FILE OUT.toml)"
            if version == 1
            else ""
        )
        raise ScenarioError(
            where, f"schema_version must be {TREE_SCHEMA_VERSION}, got {version:g}" + hint
        )
    name = top.text("name")
    description = top.text("description", "")
    bodies, tip_ports, free = _read_bodies(top.get("bodies"))
    bodies = _ordered(bodies, free)
    by_name = {b.name: b for b in bodies}
    raw_ports = top.get("ports", {})
    if not isinstance(raw_ports, dict):
        raise ScenarioError("ports", "expected [ports.NAME] tables")
    for port in tip_ports:
        if port in raw_ports:
            raise ScenarioError(f"ports.{port}", "name: also the tip port of an arm")
    ports = _read_ports({**raw_ports, **tip_ports}, by_name)
    control = _read_control(top.get("control"), by_name, bodies[0].name)
    raw_mission = top.get("mission", None)
    top.close()
    _check_block_names(bodies)
    components = _components(bodies)
    targets = {
        root: SpacecraftTree(
            name=root,
            description=by_name[root].description,
            bodies=members,
            ports=MappingProxyType({k: p for k, p in ports.items() if p.body in members_names}),
            control=None,
            source=source,
        )
        for root, members in list(components.items())[1:]
        for members_names in [{b.name for b in members}]
    }
    main = components[bodies[0].name]
    main_names = {b.name for b in main}
    tree = SpacecraftTree(
        name=name,
        description=description,
        bodies=main,
        ports=MappingProxyType({k: p for k, p in ports.items() if p.body in main_names}),
        control=control,
        targets=MappingProxyType(targets),
        source=source,
    )
    if raw_mission is None:
        return tree
    return dataclasses.replace(tree, mission=read_mission(raw_mission, tree))


def shipped_trees() -> list[str]:
    """Names of the shipped tree scenarios (``flexible_satellite``, ``geo_satellite``)."""
    return sorted(p.stem for p in Path(TREE_DIRECTORY).glob("*.toml"))


def tree_path(name: str | Path) -> Path:
    """The file of a path or of the bare name of a shipped tree scenario."""
    path = Path(name)
    if not path.is_file() and path.parent == Path():
        shipped = Path(TREE_DIRECTORY) / path.with_suffix(".toml").name
        path = shipped if shipped.is_file() else path
    if not path.is_file():
        raise ValueError(
            f"tree scenario {name}: file not found (shipped: {', '.join(shipped_trees())})"
        )
    return path.resolve()


@functools.lru_cache(maxsize=16)
def _load_cached(path: str, mtime_ns: int, size: int) -> SpacecraftTree:
    source = Path(path)
    try:
        with source.open("rb") as stream:
            document = tomllib.load(stream)
    except tomllib.TOMLDecodeError as error:
        raise ScenarioError(source.name, f"invalid TOML ({error})") from None
    return parse_tree(document, source)


def load_tree(path: str | Path) -> SpacecraftTree:
    """Load and validate a tree scenario file (schema version 2).

    Parameters
    ----------
    path : str or Path
        TOML file, or the name of a shipped tree (``"flexible_satellite"``, ``"geo_satellite"``).

    Returns
    -------
    SpacecraftTree
        Frozen, validated (cached per file version).

    Raises
    ------
    ScenarioError
        Invalid data (one line naming the body and the field).
    ValueError
        No such file.
    """
    source = tree_path(path)
    stat = source.stat()
    return _load_cached(str(source), stat.st_mtime_ns, stat.st_size)
