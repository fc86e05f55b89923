"""Human-readable summary of a validated scenario (for ``oos model check-data``-style commands).

Examples
--------
>>> from oos_drake.scenario.summary import scenario_summary
>>> text = scenario_summary()
>>> "RH2" in text and "closed loop" in text
True
"""

from __future__ import annotations

import numpy as np

from oos_drake.scenario.data import Scenario, load_scenario
from oos_drake.scenario.kinematics import (
    IK_WAYPOINTS,
    arm_tip_pose,
    forward_kinematics,
    pose_error,
    rigid_spatial_inertia_at_G1,
    waypoint_tip_pose,
)
from oos_drake.scenario.timeline import mission_timeline

__all__ = ["scenario_summary"]


def _fmt(values) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in np.ravel(values)) + "]"


def scenario_summary(scenario: Scenario | None = None) -> str:
    """Multi-line summary: bodies, array models, ports, IK waypoints, named configurations.

    Parameters
    ----------
    scenario : Scenario, optional
        Default: the paper's scenario.

    Returns
    -------
    str
        Plain text; every number in SI units (frequencies in Hz, angles in degrees).
    """
    scenario = load_scenario() if scenario is None else scenario
    lines = [f"scenario '{scenario.name}' ({scenario.source})", "", "rigid hubs:"]
    for hub in scenario.hubs.values():
        lines.append(
            f"  {hub.name}: mass {hub.mass:g} kg (+-{hub.mass_uncertainty_percent:g} %), "
            f"J_G diag {_fmt(np.diag(hub.inertia))} kg m^2 "
            f"(+-{_fmt(hub.inertia_uncertainty_percent)} %)"
        )
    lines.append("array models (participation rows = modes):")
    for model in scenario.array_models.values():
        residual = np.linalg.eigvalsh(model.residual_mass)[0]
        lines.append(
            f"  {model.name}: mass {model.mass:g} kg, modes {_fmt(model.frequencies_hz)} Hz "
            f"(first +-{model.first_mode_uncertainty_percent:g} %), "
            f"min eig D_P0 {residual:.3g}"
        )
    lines.append(
        f"arm: {len(scenario.arm.links)} links, {scenario.arm.total_mass:.4f} kg, "
        f"J0 {_fmt(scenario.arm.p_G_J0)} m"
    )
    lines.append("ports:")
    for port in scenario.ports.values():
        lines.append(f"  {port.name} on {port.body} at {_fmt(port.p_G_D)} m")
    lines.append("inverse-kinematics waypoints (arm-tip pose error, m or rad):")
    waypoints = scenario.mission.arm_waypoints
    for label in IK_WAYPOINTS:
        if label in waypoints.labels:
            alpha = waypoints.at(label)
            error = pose_error(arm_tip_pose(scenario, alpha), waypoint_tip_pose(scenario, label))
            note = " (closed loop J7 = D2, D3 = D1)" if label == "docked" else ""
            lines.append(
                f"  {label:9s} t = {waypoints.time_of(label):6g} s  alpha "
                f"{_fmt(np.degrees(alpha))} deg  error {np.abs(error).max():.1e}{note}"
            )
    lines.append("named configurations (mass and Jxx, Jyy, Jzz at G1 in R_RH1):")
    timeline = mission_timeline(scenario)
    for named in timeline.named.values():
        config = named.configuration
        D = rigid_spatial_inertia_at_G1(scenario, config)
        poses = forward_kinematics(scenario, config)
        gap = np.linalg.norm(poses.ports["D3"].p - poses.ports["D1"].p)
        lines.append(
            f"  {named.name} t = {named.time:6g} s  dC = ({config.delta_C1:g}, "
            f"{config.delta_C2:g})  theta_1 {np.degrees(config.theta[0]):6.1f} deg  "
            f"|D1D3| {gap:.3f} m  mass {D[0, 0]:.2f} kg  J {_fmt(np.diag(D[3:, 3:]))}"
            + (f"  springs {','.join(named.spring_dampers)}" if named.spring_dampers else "")
        )
    return "\n".join(lines)
