# ruff: noqa: E402  (BLAS threads are limited before numpy-heavy imports)
"""Quick check: mu of the target arrays' modes alone ({w1_SA3, w1_SA4}) after the first docking,
for the modeled target-array orientation and turned 90 deg; and of the chaser arrays alone."""

import sys

import numpy as np

from oos_drake.blas import limit_blas_threads

limit_blas_threads(1)
from oos_drake.analysis.controller import load_controller
from oos_drake.analysis.stability import SweepOptions, certified_sweep
from oos_drake.control.analysis_model import close_loop
from oos_drake.lfr import usubs
from oos_drake.scenario.data import load_scenario
from oos_drake.scenario.model import build_mission_model, mission_values
from oos_drake.titop.spatial import angle_to_tau

times = np.linspace(256.0, 860.0, 8)
omega = 2 * np.pi * np.geomspace(0.05, 5.0, 25)
ctl = load_controller(sys.argv[1])
scenario = load_scenario("paper")
model = build_mission_model(scenario)
for angle in (0.0, np.pi / 2):
    values = mission_values(times, scenario)
    values["tau_theta3"] = np.full(times.size, angle_to_tau(angle))
    values["tau_theta4"] = np.full(times.size, angle_to_tau(-angle))
    sysm = close_loop(usubs(model, values), ctl.K, ctl.spec)
    res = certified_sweep(
        sysm,
        omega,
        {"SA3,4": ["w1_SA3", "w1_SA4"], "SA1,2": ["w1_SA1", "w1_SA2"]},
        times=times,
        options=SweepOptions(n_jobs=1),
        progress=False,
    )
    for name, c in res.certificates.items():
        print(
            f"target arrays at {np.degrees(angle):3.0f} deg: {name} alone "
            f"mu in [{c.mu_lower:.3f}, {c.mu_upper:.3f}] "
            f"at t = {c.time:.0f} s, {c.frequency:.3f} Hz",
            flush=True,
        )
