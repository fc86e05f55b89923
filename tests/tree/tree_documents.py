"""Tree documents for the tests: the shipped ones as dicts, and a tree with a non-trivial mount."""

from __future__ import annotations

import copy
import tomllib

import numpy as np

from oos_drake.scenario.tree import tree_path


def shipped_document(name: str) -> dict:
    """A fresh, mutable copy of a shipped tree file's document."""
    with tree_path(name).open("rb") as stream:
        return copy.deepcopy(tomllib.load(stream))


def rotation(axis, angle) -> list[list[float]]:
    """Rotation matrix about ``axis`` by ``angle`` [rad] (Rodrigues), written out here."""
    n = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    R = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    return R.tolist()


def boom_body(p_parent_joint, angle: float) -> dict:
    """A rigid boom ``BOOM`` on the hub ``HUB``: a revolute joint at ``p_parent_joint`` [m]
    (mount rotated 0.7 rad about (1, 1, 1), skewed axis), at ``angle`` [rad]."""
    axis = (np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])).tolist()
    return {
        "name": "BOOM",
        "kind": "rigid",
        "parent": "HUB",
        "joint": {
            "type": "revolute",
            "p_parent_joint": list(p_parent_joint),
            "R_parent_joint": rotation([1.0, 1.0, 1.0], 0.7),
            "axis": axis,
            "angle": angle,
        },
        "mass": 12.0,
        "inertia": [[3.0, 0.1, 0.0], [0.1, 2.5, -0.05], [0.0, -0.05, 1.2]],
        "p_B_G": [0.1, 0.05, 0.6],
    }


def boom_document() -> dict:
    """Hub + rigid boom on a skewed revolute joint + a flexible panel fixed to the boom at a
    non-trivial rotation + a flexible array on the hub at a skewed fixed mount + ports."""
    document = shipped_document("flexible_satellite")
    hub, array = document["bodies"][0], document["bodies"][1]
    boom = boom_body([0.4, -0.2, 1.5], angle=0.9)
    boom["mass_uncertainty_percent"] = 10.0
    panel = copy.deepcopy(array)
    panel.update(
        name="PANEL",
        parent="BOOM",
        joint={
            "type": "fixed",
            "p_parent_joint": [0.0, 0.1, 1.2],
            "R_parent_joint": (
                np.array(rotation([0.0, 0.0, 1.0], 0.9)) @ np.array(rotation([1.0, 0.0, 0.0], 0.5))
            ).tolist(),
        },
        uncertainty={"w1": {"percent": 10.0}, "w3": {"range_hz": [3.0, 3.5]}},
    )
    skewed = copy.deepcopy(array)
    skewed.update(
        name="SKEWED",
        joint={
            "type": "fixed",
            "p_parent_joint": [-0.5, 0.3, 0.2],
            "R_parent_joint": rotation([0.2, -1.0, 0.4], 2.1),
        },
    )
    skewed.pop("uncertainty")
    document["name"] = "boom_tree"
    document.pop("mission")  # the satellite's mission drives SA1/SA2, which this tree lacks
    document["bodies"] = [hub, boom, panel, skewed]
    document["ports"]["TIP"] = {"body": "BOOM", "p_B_D": [0.0, 0.0, 1.3]}
    return document
