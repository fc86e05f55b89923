# ruff: noqa: E402  (BLAS threads are limited before numpy-heavy imports)
"""Quick check: how much the open geometry (target arrays' orientation) and the controller move
the certified mission peak near the first docking (t = 255 .. 300 s, total set)."""

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
from oos_drake.scenario.model import build_mission_model, mission_values
from oos_drake.titop.spatial import angle_to_tau

times = np.linspace(256.0, 300.0, 12)
omega = 2 * np.pi * np.geomspace(0.05, 5.0, 25)
scenario = load_scenario("paper")
model = build_mission_model(scenario)
cases = []
synth = load_controller(sys.argv[1])
for label, angle, ctl in [
    ("as modeled (target arrays theta3,4 = 0), synthesized K", 0.0, synth),
    ("target arrays turned 45 deg about their mount axis", np.pi / 4, synth),
    ("target arrays turned 90 deg about their mount axis", np.pi / 2, synth),
    ("as modeled, BASELINE PD", 0.0, scenario_controller(None, scenario)),
]:
    values = mission_values(times, scenario)
    values["tau_theta3"] = np.full(times.size, angle_to_tau(angle))
    values["tau_theta4"] = np.full(times.size, angle_to_tau(-angle))
    plant = usubs(model, values)
    sysm = close_loop(plant, ctl.K, ctl.spec)
    subs = uncertainty_subsets(sysm.uncertainty)
    c0 = time.process_time()
    res = certified_sweep(
        sysm,
        omega,
        {"total": subs["total"], "modal": subs["modal"]},
        times=times,
        options=SweepOptions(n_jobs=1),
        progress=False,
    )
    for name in ("total", "modal"):
        c = res.certificates[name]
        wc = {k: v for k, v in c.worst_case.items() if k.startswith("w1_")}
        print(
            f"{label:58s} {name:6s} mu in [{c.mu_lower:.3f}, {c.mu_upper:.3f}] "
            f"at t = {c.time:.0f} s, "
            f"{c.frequency:.3f} Hz; worst w1 [Hz]: "
            + ", ".join(
                f"{k}={v / (2 * np.pi):.3f}" for k, v in wc.items() if isinstance(v, float)
            ),
            flush=True,
        )
    print(f"   ({time.process_time() - c0:.0f} s CPU)", flush=True)
