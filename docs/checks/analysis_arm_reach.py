# ruff: noqa: E402  (BLAS threads are limited before numpy-heavy imports)
"""Quick check: does holding the target farther out (stretched arm) let the target arrays' first
mode couple into the attitude loop? Prints, at the t = 300 s configuration (arm holds the target)
and for two other arm poses: the first-mode modal inertia of SA1 and SA3 seen at G1 (as a share of
the system's rigid inertia), and the certified mu of {w1_SA3, w1_SA4} alone and of the total set.

Run: ``.venv/bin/python docs/checks/analysis_arm_reach.py CONTROLLER.json`` (or ``baseline``).
"""

import sys
import time

import numpy as np

from oos_drake.blas import limit_blas_threads

limit_blas_threads(1)
from oos_drake.analysis.controller import load_controller, scenario_controller
from oos_drake.analysis.stability import SweepOptions, certified_sweep
from oos_drake.analysis.subsets import uncertainty_subsets
from oos_drake.control.analysis_model import close_loop
from oos_drake.lfr import usubs
from oos_drake.scenario.data import load_scenario
from oos_drake.scenario.kinematics import forward_kinematics, rigid_spatial_inertia_at_G1
from oos_drake.scenario.model import build_mission_model, configuration_values
from oos_drake.scenario.timeline import Configuration, mission_timeline

T_CHECK = 300.0  # [s] after the first docking: the arm holds the target
omega = 2 * np.pi * np.geomspace(0.05, 5.0, 40)
scenario = load_scenario("paper")
ctl = (
    scenario_controller(None, scenario)
    if sys.argv[1] == "baseline"
    else load_controller(sys.argv[1])
)
model = build_mission_model(scenario)
nominal = mission_timeline(scenario).configuration(T_CHECK)
poses_deg = {
    "as modeled (t = 300 s)": np.degrees(nominal.alpha),
    "stretched arm (0,-90,0,0,90,0)": [0, -90, 0, 0, 90, 0],
    "arm (0,-120,60,0,90,0)": [0, -120, 60, 0, 90, 0],
}


def modal_inertia_share(config):
    """First-mode modal inertia of SA1 and SA3 at G1, in % of the rigid inertia diagonal."""
    poses = forward_kinematics(scenario, config)
    J = np.diag(rigid_spatial_inertia_at_G1(scenario, config))[3:]
    share = {}
    for name in ("SA1", "SA3"):
        l1 = scenario.arrays[name].model.participation[0]  # rows = modes, [Tx Ty Tz Rx Ry Rz] at P
        pose = poses.bodies[name]
        trans, rot = pose.R @ l1[:3], pose.R @ l1[3:]
        rot_G1 = rot + np.cross(pose.p, trans)  # moment arm G1 -> P
        share[name] = 100 * rot_G1**2 / J
    return poses.centers_of_mass["RH2"], J, share


for label, alpha_deg in poses_deg.items():
    alpha = np.radians(np.asarray(alpha_deg, dtype=float))
    config = Configuration(
        time=np.array(T_CHECK),
        alpha=alpha,
        theta=nominal.theta,
        delta_C1=np.array(1.0),
        delta_C2=np.array(0.0),
    )
    com, J, share = modal_inertia_share(config)
    print(
        f"{label}: target CoM {np.linalg.norm(com):.2f} m from G1, J diag {np.round(J)} kg m^2; "
        + "; ".join(f"{k} mode-1 share of Jxx,yy,zz {np.round(v, 1)} %" for k, v in share.items())
    )
    values = configuration_values(
        np.tile(alpha, (2, 1)), np.tile(nominal.theta, (2, 1)), np.ones(2), np.zeros(2)
    )
    sysm = close_loop(usubs(model, values), ctl.K, ctl.spec)
    total = uncertainty_subsets(sysm.uncertainty)["total"]
    subsets = {"SA3,4": ["w1_SA3", "w1_SA4"], "total": total}
    c0 = time.process_time()
    res = certified_sweep(
        sysm,
        omega,
        subsets,
        times=np.full(2, T_CHECK),
        options=SweepOptions(n_jobs=1),
        progress=False,
    )
    for name, cert in res.certificates.items():
        print(
            f"    {name:6s} mu in [{cert.mu_lower:.3f}, {cert.mu_upper:.3f}] "
            f"at {cert.frequency:.3f} Hz",
            flush=True,
        )
    print(f"    ({time.process_time() - c0:.0f} s CPU)", flush=True)
