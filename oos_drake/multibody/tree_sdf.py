"""SDF files of a spacecraft tree (:mod:`oos_drake.scenario.tree`), written from the same data
as its TITOP LFR.

Files (one folder per tree)::

    spacecraft.sdf             assembly model ``spacecraft``: one link per rigid body, a frame
                               ``<body>_J`` on the parent link per joint, ports as frames, one
                               ``<include>`` per flexible appendage, joints ``<body>_joint``
    appendage_<NAME>.sdf       each flexible appendage realized by mode bodies
                               (:func:`oos_drake.multibody.appendage_sdf.appendage_model`)

Link frames: the root's link frame is its centre of mass ``G`` (hub axes), so the twin's
floating joint and hub outputs are at ``G`` as in the TITOP model; every other rigid link's frame
is its body frame (origin at its joint), with the centre of mass at ``p_B_G``. An appendage's
``root`` link frame is its attachment frame ``R_SA`` (origin ``P``). Joint frames coincide with
the child's frame at angle 0; revolute axes are expressed in it; limits are the file's. Not in
SDF (added by :mod:`oos_drake.multibody.tree_plant`): the modal residual bodies and the root's
floating joint.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from oos_drake.multibody.appendage_sdf import ROOT_LINK, appendage_model
from oos_drake.multibody.sdf_writer import (
    Frame,
    Include,
    Inertial,
    Joint,
    Link,
    Model,
    Pose,
    pose_from_matrix,
    to_sdf_text,
)
from oos_drake.scenario.tree import SpacecraftTree

__all__ = [
    "TREE_ASSEMBLY_FILE",
    "TREE_ASSEMBLY_MODEL",
    "TREE_SDF_PACKAGE",
    "appendage_file",
    "joint_name",
    "generate_tree_sdf_texts",
    "write_tree_sdf",
]

TREE_ASSEMBLY_FILE = "spacecraft.sdf"
TREE_ASSEMBLY_MODEL = "spacecraft"
#: Package name of a tree's SDF folder in Drake's PackageMap (includes are package:// URIs).
TREE_SDF_PACKAGE = "oos_tree_sdf"


def appendage_file(body: str) -> str:
    """SDF file of flexible appendage ``body``: ``appendage_<body>.sdf``."""
    return f"appendage_{body}.sdf"


def joint_name(body: str) -> str:
    """Name of the joint that attaches ``body`` to its parent: ``<body>_joint``."""
    return f"{body}_joint"


def _link_origin(tree: SpacecraftTree, body) -> np.ndarray:
    """Body frame origin -> link frame origin, in body axes [m] (the root's link is at G)."""
    return np.asarray(body.p_B_G, dtype=float) if body.name == tree.root else np.zeros(3)


def _generated_by(tree: SpacecraftTree) -> str:
    source = tree.source.name if tree.source is not None else f"tree '{tree.name}'"
    return f"oos_drake.multibody.tree_sdf from {source}"


def _appendage_models(tree: SpacecraftTree) -> dict[str, Model]:
    return {
        body.name: appendage_model(
            f"appendage_{body.name}",
            body.mass,
            body.p_P_S,
            body.inertia,
            body.omega,
            body.damping_ratios,
            body.participation,
        )
        for body in tree.bodies
        if body.kind == "flexible"
    }


def _assembly_model(tree: SpacecraftTree) -> Model:
    links, frames, joints, includes = [], [], [], []
    by_name = {b.name: b for b in tree.bodies}
    for body in tree.bodies:
        name = body.name
        if body.joint is not None:
            parent = by_name[body.parent]
            p_link_J = np.asarray(body.joint.p_parent_joint) - _link_origin(tree, parent)
            frames.append(
                Frame(
                    f"{name}_J", parent.name, pose_from_matrix(body.joint.R_parent_joint, p_link_J)
                )
            )
        if body.kind == "rigid":
            pose = Pose() if body.joint is None else Pose(relative_to=f"{name}_J")
            com = np.asarray(body.p_B_G) - _link_origin(tree, body)
            links.append(Link(name, Inertial(body.mass, body.inertia, Pose(tuple(com))), pose))
            child = name
        else:
            includes.append(
                Include(
                    f"package://{TREE_SDF_PACKAGE}/{appendage_file(name)}",
                    name,
                    Pose(relative_to=f"{name}_J"),
                )
            )
            child = f"{name}::{ROOT_LINK}"
        if body.joint is not None:
            revolute = body.joint.type == "revolute"
            joints.append(
                Joint(
                    joint_name(name),
                    "revolute" if revolute else "fixed",
                    body.parent,
                    child,
                    axis=tuple(float(v) for v in body.joint.axis) if revolute else None,
                    limits=(body.joint.lower, body.joint.upper) if revolute else None,
                )
            )
    for port in tree.ports.values():
        owner = by_name[port.body]
        p = np.asarray(port.p_B_D) - _link_origin(tree, owner)
        frames.append(Frame(port.name, port.body, pose_from_matrix(port.R_B_D, p)))
    comment = (
        f"Spacecraft tree '{tree.name}': {tree.description}.",
        f"Root (controlled body) {tree.root}: link frame at its centre of mass; other rigid links",
        "at their joint; joints <body>_joint (revolute ones are motion-driven in the models).",
        "oos_drake.multibody.tree_plant adds the modal residual bodies and the root's floating",
        "joint.",
    )
    return Model(
        name=TREE_ASSEMBLY_MODEL,
        comment=comment,
        includes=tuple(includes),
        links=tuple(links),
        frames=tuple(frames),
        joints=tuple(joints),
        canonical_link=tree.root,
    )


def generate_tree_sdf_texts(tree: SpacecraftTree) -> dict[str, str]:
    """Return ``{file name: SDF text}`` for the tree's assembly and its appendages."""
    generated_by = _generated_by(tree)
    texts = {
        appendage_file(name): to_sdf_text(model, generated_by=generated_by)
        for name, model in _appendage_models(tree).items()
    }
    texts[TREE_ASSEMBLY_FILE] = to_sdf_text(_assembly_model(tree), generated_by=generated_by)
    return texts


def write_tree_sdf(tree: SpacecraftTree, directory: str | Path) -> list[Path]:
    """Write the tree's SDF files into ``directory`` (created); return the paths written."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, text in generate_tree_sdf_texts(tree).items():
        path = directory / name
        path.write_text(text)
        paths.append(path)
    return paths
