"""Convert a schema-1 scenario (``paper.toml``, ``heavy_target.toml``) into a schema-2 tree.

What a tree holds today is the chaser: the hub ``RH1``, its arrays ``SA1``, ``SA2`` (revolute
drives, first-mode uncertainty kept as ``uncertainty.w1``), the arm base ``L0`` (fixed at ``J0``)
and links ``L1``..``L6`` (revolute joints ``alpha_1..6``, limits [-pi, pi]), the chaser's port
``D1`` and the arm tip ``J7`` as a port of ``L6``. The target (``RH2``, ``SA3``, ``SA4``, ports
``D2``, ``D3``), the docking spring-dampers and the mission timeline have no place in schema 2
yet: :func:`tree_document_from_v1` lists them in ``dropped``. The ``[control]`` section is copied
field by field (it is read by the same reader in both schemas).

Block names are schema 1's: each revolute joint names its block (``joint.block``:
``tau_theta1``, ``tau_theta2`` for the array drives, ``tau_alpha<i>`` for the links ``L<i>``,
instead of the tree's default ``tau_<body>``); ``w1_SA1``, ``w1_SA2`` and the hub's ``m_RH1``,
``J.._RH1`` are the same in both schemas.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from oos_drake.scenario.data import Scenario, load_scenario

__all__ = ["tree_document_from_v1", "V1_DROPPED"]

#: Parts of a schema-1 scenario that a schema-2 tree does not hold yet.
V1_DROPPED = (
    "hubs.RH2",
    "arrays.SA3",
    "arrays.SA4",
    "ports.D2",
    "ports.D3",
    "docking",
    "mission",
)


def _list(array) -> list:
    return np.asarray(array, dtype=float).tolist()


def _control_table(scenario: Scenario, controlled_body: str) -> dict:
    """``[control]`` of a tree: the controlled body and the schema-1 requirements, as written in
    a schema-1 file (the inverse of :func:`oos_drake.scenario.data.read_control`)."""
    c = scenario.control
    return {
        "controlled_body": controlled_body,
        "pointing_requirement": c.pointing_requirement,
        "torque_limit": c.torque_limit,
        "flight_software_rate_hz": c.flight_software_rate_hz,
        "sensors": {
            "star_tracker_cutoff_hz": c.star_tracker_cutoff_hz,
            "gyro_cutoff_hz": c.gyro_cutoff_hz,
            "star_tracker_noise": c.star_tracker_noise,
            "gyro_noise": c.gyro_noise,
        },
        "actuators": {"wheel_frequency_hz": c.wheel_frequency_hz, "wheel_damping": c.wheel_damping},
        "rolloff": {"order": c.rolloff_order, "cutoff_hz": c.rolloff_cutoff_hz},
        "weights": {
            "disturbance_gains": list(c.disturbance_gains),
            "disturbance_denominator": list(c.disturbance_denominator),
            "additive_weight_db": c.additive_weight_db,
            "multiplicative_diagonal": c.multiplicative_diagonal,
            "multiplicative_off_diagonal": c.multiplicative_off_diagonal,
        },
    }


def tree_document_from_v1(scenario: Scenario | str | Path) -> tuple[dict, tuple[str, ...]]:
    """The schema-2 document of a schema-1 scenario's chaser, and what was left out.

    Parameters
    ----------
    scenario : Scenario, str or Path
        A loaded schema-1 scenario, or its file / shipped name.

    Returns
    -------
    document : dict
        TOML-ready document (``tomli_w.dumps``), valid for
        :func:`oos_drake.scenario.tree.parse_tree`.
    dropped : tuple of str
        Sections of the schema-1 file not converted (:data:`V1_DROPPED`).
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    chaser = scenario.arm.parent
    hub = scenario.hubs[chaser]
    bodies = [
        {
            "name": chaser,
            "kind": "rigid",
            "description": hub.description,
            "mass": float(hub.mass),
            "inertia": _list(hub.inertia),
            "p_B_G": [0.0, 0.0, 0.0],
            "mass_uncertainty_percent": float(hub.mass_uncertainty_percent),
            "inertia_uncertainty_percent": _list(hub.inertia_uncertainty_percent),
        }
    ]
    for name, mount in scenario.arrays.items():
        if mount.parent != chaser:
            continue
        model = mount.model
        entry = {
            "name": name,
            "kind": "flexible",
            "description": model.description,
            "parent": chaser,
            "joint": {
                "type": "revolute",
                "p_parent_joint": _list(mount.p_G_P),
                "R_parent_joint": _list(mount.R_G_P0),
                "axis": _list(mount.axis),
                "block": f"tau_theta{name[-1]}",  # schema 1's block name, kept
            },
            "mass": float(model.mass),
            "p_P_S": _list(model.p_P_S),
            "inertia": _list(model.inertia),
            "frequencies_hz": _list(model.frequencies_hz),
            "damping_ratios": _list(model.damping_ratios),
            "participation": _list(model.participation),
        }
        if model.first_mode_uncertainty_percent > 0:
            entry["uncertainty"] = {"w1": {"percent": float(model.first_mode_uncertainty_percent)}}
        bodies.append(entry)
    arm = scenario.arm
    previous = None
    for link in arm.links:
        entry = {
            "name": link.name,
            "kind": "rigid",
            "parent": chaser if previous is None else previous.name,
            "mass": float(link.mass),
            "inertia": _list(link.inertia),
            "p_B_G": _list(link.p_J_G),
        }
        if previous is None:
            entry["joint"] = {
                "type": "fixed",
                "p_parent_joint": _list(arm.p_G_J0),
                "R_parent_joint": _list(arm.R_G_L0),
            }
        else:
            entry["joint"] = {
                "type": "revolute",
                "p_parent_joint": _list(previous.p_J_Jnext),
                "axis": _list(link.joint_axis),
                "block": f"tau_alpha{link.name[1:]}",  # schema 1's block name, kept
            }
        bodies.append(entry)
        previous = link
    ports = {
        name: {"body": chaser, "p_B_D": _list(port.p_G_D), "R_B_D": _list(port.R_G_D)}
        for name, port in scenario.ports.items()
        if port.body == chaser
    }
    ports["J7"] = {"body": previous.name, "p_B_D": _list(previous.p_J_Jnext)}
    document = {
        "schema_version": 2,
        "name": f"{scenario.name}_chaser",
        "description": f"chaser of scenario '{scenario.name}' (converted from schema 1)",
        "control": _control_table(scenario, chaser),
        "bodies": bodies,
        "ports": ports,
    }
    return document, V1_DROPPED
