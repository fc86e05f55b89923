"""Write SDFormat 1.9 text from plain numbers (deterministic, round-trip float formatting).

Only what the scenario needs: links with inertials, frames, revolute/fixed joints with
``<dynamics>`` (damping, spring stiffness, which Drake's parser honors as joint damping and a
``RevoluteSpring``), ``<include>`` of part files, and comments. Numbers are written with
``repr(float)`` so that regenerating from the same data gives byte-identical files (the staleness
test relies on it).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Pose",
    "pose_from_matrix",
    "Inertial",
    "Link",
    "Frame",
    "Joint",
    "Include",
    "Model",
    "to_sdf_text",
]


def _num(value: float) -> str:
    value = float(value)
    if value == 0.0:
        return "0"
    return repr(value)


@dataclass(frozen=True)
class Pose:
    """A pose ``xyz`` [m] + roll-pitch-yaw [rad] (SDF convention: extrinsic X-Y-Z).

    ``relative_to`` names the frame it is expressed in ("" = SDF default).
    """

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    relative_to: str = ""

    def text(self) -> str:
        return " ".join(_num(v) for v in (*self.xyz, *self.rpy))

    def element(self) -> ET.Element:
        element = ET.Element("pose")
        if self.relative_to:
            element.set("relative_to", self.relative_to)
        element.text = self.text()
        return element


def pose_from_matrix(R: np.ndarray, p: Sequence[float], relative_to: str = "") -> Pose:
    """Return the :class:`Pose` of a rotation matrix ``R`` (3x3) and position ``p`` [m].

    Uses the SDF roll-pitch-yaw convention ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
    """
    R = np.asarray(R, dtype=float)
    pitch = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    if abs(math.cos(pitch)) > 1e-9:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    else:  # gimbal lock: put everything in yaw
        roll = 0.0
        yaw = math.atan2(-R[0, 1], R[1, 1])
    clean = tuple(0.0 if abs(v) < 1e-15 else float(v) for v in (roll, pitch, yaw))
    return Pose(tuple(float(v) for v in p), clean, relative_to)


@dataclass(frozen=True)
class Inertial:
    """Mass [kg], centre of mass pose in the link frame, and central inertia [kg m^2]
    (expressed in the axes of ``pose``)."""

    mass: float
    inertia: np.ndarray
    pose: Pose = Pose()

    def element(self) -> ET.Element:
        element = ET.Element("inertial")
        element.append(self.pose.element())
        ET.SubElement(element, "mass").text = _num(self.mass)
        inertia = ET.SubElement(element, "inertia")
        J = np.asarray(self.inertia, dtype=float)
        for tag in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):  # i<row><column>
            ET.SubElement(inertia, tag).text = _num(J["xyz".index(tag[1]), "xyz".index(tag[2])])
        return element


@dataclass(frozen=True)
class Link:
    """An SDF link."""

    name: str
    inertial: Inertial
    pose: Pose = Pose()

    def element(self) -> ET.Element:
        element = ET.Element("link", name=self.name)
        element.append(self.pose.element())
        element.append(self.inertial.element())
        return element


@dataclass(frozen=True)
class Frame:
    """An SDF frame attached to a link or frame."""

    name: str
    attached_to: str
    pose: Pose = Pose()

    def element(self) -> ET.Element:
        element = ET.Element("frame", name=self.name, attached_to=self.attached_to)
        element.append(self.pose.element())
        return element


@dataclass(frozen=True)
class Joint:
    """A revolute or fixed SDF joint; ``axis`` is expressed in the joint frame.

    ``actuated=False`` writes a zero effort limit (no Drake ``JointActuator``): used for the
    mode hinges, which are structural, not driven. ``limits`` are the position limits
    ``(lower, upper)`` [rad] (None: unlimited, written as +-1e16).
    """

    name: str
    kind: str
    parent: str
    child: str
    pose: Pose = Pose()
    axis: tuple[float, float, float] | None = None
    damping: float = 0.0
    spring_stiffness: float = 0.0
    actuated: bool = True
    limits: tuple[float, float] | None = None

    def element(self) -> ET.Element:
        element = ET.Element("joint", name=self.name, type=self.kind)
        ET.SubElement(element, "parent").text = self.parent
        ET.SubElement(element, "child").text = self.child
        element.append(self.pose.element())
        if self.axis is not None:
            axis = ET.SubElement(element, "axis")
            ET.SubElement(axis, "xyz").text = " ".join(_num(v) for v in self.axis)
            limit = ET.SubElement(axis, "limit")
            lower, upper = ("-1e16", "1e16") if self.limits is None else map(_num, self.limits)
            ET.SubElement(limit, "lower").text = lower
            ET.SubElement(limit, "upper").text = upper
            if not self.actuated:
                # Drake's parser adds a JointActuator unless the effort limit is zero
                ET.SubElement(limit, "effort").text = "0"
            dynamics = ET.SubElement(axis, "dynamics")
            ET.SubElement(dynamics, "damping").text = _num(self.damping)
            ET.SubElement(dynamics, "spring_reference").text = "0"
            ET.SubElement(dynamics, "spring_stiffness").text = _num(self.spring_stiffness)
        return element


@dataclass(frozen=True)
class Include:
    """Include of another SDF file as a nested model."""

    uri: str
    name: str
    pose: Pose = Pose()

    def element(self) -> ET.Element:
        element = ET.Element("include")
        ET.SubElement(element, "uri").text = self.uri
        ET.SubElement(element, "name").text = self.name
        element.append(self.pose.element())
        return element


@dataclass(frozen=True)
class Model:
    """An SDF model: comment lines, then includes, links, frames and joints in that order."""

    name: str
    comment: tuple[str, ...] = ()
    links: tuple[Link, ...] = ()
    frames: tuple[Frame, ...] = ()
    joints: tuple[Joint, ...] = ()
    includes: tuple[Include, ...] = ()
    canonical_link: str = ""


def to_sdf_text(
    model: Model,
    *,
    generated_by: str = "`oos sdf generate` from oos_drake/scenario/data/paper.toml",
) -> str:
    """Return the SDFormat 1.9 text of ``model`` (ends with a newline).

    ``generated_by`` names the command and data file in the header comment.
    """
    root = ET.Element("sdf", version="1.9")
    element = ET.SubElement(root, "model", name=model.name)
    if model.canonical_link:
        element.set("canonical_link", model.canonical_link)
    for item in (*model.includes, *model.links, *model.frames, *model.joints):
        element.append(item.element())
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    header = ['<?xml version="1.0"?>']
    header.append(f"<!-- GENERATED by {generated_by}.")
    header.append("     Do not edit: edit the scenario data and regenerate. -->")
    if model.comment:
        header.append("<!--")
        header.extend(f"  {line}" for line in model.comment)
        header.append("-->")
    return "\n".join(header) + "\n" + body + "\n"
