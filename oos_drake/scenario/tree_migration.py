"""Convert a schema-1 scenario (``paper.toml``, ``heavy_target.toml``) into a schema-2 tree.

The tree: the chaser's hub ``RH1``, its arrays ``SA1``, ``SA2`` (revolute drives, first-mode
uncertainty kept as ``uncertainty.w1``), the arm base ``L0`` (fixed at ``J0``) and links
``L1``..``L6`` (revolute joints ``alpha_1..6``, limits [-pi, pi]), the chaser's port ``D1`` and
the arm tip ``J7`` as a port of ``L6``; the target ``RH2`` as a free body (``free = true``) with
its arrays ``SA3``, ``SA4`` (drives at ``target_array_angles``) and its ports ``D2``, ``D3``.
The mission: one phase between consecutive instants of the arm's and the arrays' waypoints and
of the connection states (``interpolation = "quintic"``, schema 1's joint trajectories; a
waypoint segment split by another instant must be constant), each phase's ``joints`` the
angles at its end; ``delta_C1 = 1`` is ``docked = { ports = ["J7", "D2"], name = "SM1", ... }``,
``delta_C2 = 1`` is ``docked = { ports = ["D1", "D3"], name = "SM2", ... }``, both with the
``[docking]`` rigid stiffness and damping (no uncertainty; schema 1's spring-dampers SM1 and
SM2, welded rigid in the mission model as schema 1's ``delta_C1``, ``delta_C2``), the switch
blocks named ``delta_C1`` (port ``J7``) and ``delta_C2`` (``D1``). The two docking events are
schema 1's docking phases: the start of the J7-D2 phase (t = 255 s) is phase 7 (SM1 swept), the
start of the D1-D3 phase (880 s) phase 8 (SM2 swept while SM1 still holds the target at its
rigid values): ``oos analyze`` studies them as ``docking-<phase name>`` with the same plants
(``TreeScenario.docking_plant``; the swept damping is the file's, the ``[docking]`` rigid
damping, schema 1's ``damping`` being dropped).
At a phase boundary a tree's timeline is in the phase ending there, schema 1's connection
states in the one starting there: the two differ at the switching instants only. The moments,
the docking studies (phases 7, 8 and their stiffness sweep) and the mission's CHOICE numbers
have no place in schema 2 yet: :func:`tree_document_from_v1` lists them in ``dropped``. The
``[control]`` section is copied field by field (it is read by the same reader in both
schemas).

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
    "docking.stiffness_sweep",
    "docking.damping",
    "mission.moments",
    "mission.first_docking_standoff",
    "mission.grasp_approach_distance",
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


def _hub_entry(hub) -> dict:
    return {
        "name": hub.name,
        "kind": "rigid",
        "description": hub.description,
        "mass": float(hub.mass),
        "inertia": _list(hub.inertia),
        "p_B_G": [0.0, 0.0, 0.0],
        "mass_uncertainty_percent": float(hub.mass_uncertainty_percent),
        "inertia_uncertainty_percent": _list(hub.inertia_uncertainty_percent),
    }


def _segment_value(waypoints, time: float, what: str) -> np.ndarray:
    """Values of piecewise-quintic ``waypoints`` at ``time``: a waypoint's, or those of a
    constant segment (a moving segment split by another instant is not a tree phase)."""
    times = np.asarray(waypoints.times, dtype=float)
    values = np.asarray(waypoints.values, dtype=float)
    hit = np.flatnonzero(np.isclose(times, time, rtol=0.0, atol=1e-9))
    if hit.size:
        return values[hit[0]]
    k = int(np.searchsorted(times, time)) - 1
    if k < 0 or k + 1 >= times.size:
        return values[0] if k < 0 else values[-1]
    if not np.array_equal(values[k], values[k + 1]):
        raise ValueError(
            f"mission.{what}: the segment {times[k]:g}-{times[k + 1]:g} s moves and is split at "
            f"{time:g} s by another event: not a sequence of tree phases"
        )
    return values[k]


def _mission_table(scenario: Scenario) -> dict:
    """Schema 1's timeline as tree phases (module docstring)."""
    mission = scenario.mission
    t0 = float(mission.t_start)
    instants = {float(mission.t_end)}
    for waypoints in (mission.arm_waypoints, mission.array_waypoints):
        instants.update(float(t) for t in waypoints.times)
    for state in mission.connection_states:
        instants.update((float(state.start), float(state.end)))
    instants = sorted(t for t in instants if t0 < t <= float(mission.t_end))
    arm = mission.arm_waypoints
    labels = dict(zip(map(float, arm.times), arm.labels, strict=True))
    docking = scenario.docking
    phases, names, start = [], set(), t0
    for end in instants:
        name = labels.get(end, f"t{end:g}")
        name = name if name not in names else f"{name}_{end:g}"
        names.add(name)
        alpha = _segment_value(mission.arm_waypoints, end, "arm_waypoints")
        theta = _segment_value(mission.array_waypoints, end, "array_waypoints")
        phase = {
            "name": name,
            "duration": end - start,
            "joints": {f"L{i + 1}": float(a) for i, a in enumerate(alpha)}
            | {f"SA{k + 1}": float(v) for k, v in enumerate(theta)},
        }
        middle = 0.5 * (start + end)
        state = next(s for s in mission.connection_states if s.start <= middle < s.end)
        if state.delta_C1 and state.delta_C2:
            raise ValueError(
                f"mission.connection_states: {state.start:g}-{state.end:g} s connects both "
                "J7/D2 and D1/D3: one connection per tree phase"
            )
        for flag, ports, name in ((state.delta_C1, ["J7", "D2"], "SM1"),
                                  (state.delta_C2, ["D1", "D3"], "SM2")):  # fmt: skip
            if flag:
                phase["docked"] = {
                    "ports": ports,
                    "name": name,
                    "k_shear": float(docking.rigid_stiffness),
                    "k_tors": float(docking.rigid_stiffness),
                    "d_shear": float(docking.rigid_damping),
                    "d_tors": float(docking.rigid_damping),
                }
        phases.append(phase)
        start = end
    return {"interpolation": "quintic", "phases": phases}


def tree_document_from_v1(scenario: Scenario | str | Path) -> tuple[dict, tuple[str, ...]]:
    """The schema-2 document of a schema-1 scenario (chaser, target, mission), and what was
    left out.

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
    mission = scenario.mission
    alpha0 = np.asarray(mission.arm_waypoints.values[0], dtype=float)  # the file's angles
    bodies = [_hub_entry(hub)]
    target_name = next(name for name in scenario.hubs if name != chaser)
    theta0 = {
        **{f"SA{k + 1}": float(v) for k, v in enumerate(mission.array_waypoints.values[0])},
        **{f"SA{k + 3}": float(v) for k, v in enumerate(mission.target_array_angles)},
    }
    target_bodies = [_hub_entry(scenario.hubs[target_name]) | {"free": True}]
    for name, mount in scenario.arrays.items():
        model = mount.model
        entry = {
            "name": name,
            "kind": "flexible",
            "description": model.description,
            "parent": mount.parent,
            "joint": {
                "type": "revolute",
                "p_parent_joint": _list(mount.p_G_P),
                "R_parent_joint": _list(mount.R_G_P0),
                "axis": _list(mount.axis),
                "angle": theta0[name],
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
        (bodies if mount.parent == chaser else target_bodies).append(entry)
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
                "angle": float(alpha0[int(link.name[1:]) - 1]),
                "block": f"tau_alpha{link.name[1:]}",  # schema 1's block name, kept
            }
        bodies.append(entry)
        previous = link
    ports = {
        name: {"body": port.body, "p_B_D": _list(port.p_G_D), "R_B_D": _list(port.R_G_D)}
        for name, port in scenario.ports.items()
    }
    ports["J7"] = {"body": previous.name, "p_B_D": _list(previous.p_J_Jnext)}
    ports["J7"]["block"] = "delta_C1"  # schema 1's switch names, kept
    ports["D1"]["block"] = "delta_C2"
    document = {
        "schema_version": 2,
        "name": f"{scenario.name}_tree",
        "description": f"scenario '{scenario.name}' converted from schema 1",
        "control": _control_table(scenario, chaser),
        "bodies": bodies + target_bodies,
        "ports": ports,
        "mission": _mission_table(scenario),
    }
    return document, V1_DROPPED
