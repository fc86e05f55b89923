"""Tune a PID with roll-off on a two-mass flexible plant over three spring stiffnesses.

Two masses m1 = m2 = 1 kg joined by a spring k in {0.5, 1, 2} N/m and a damper 0.1 N s/m; the
force u acts on mass 1, the position y of mass 2 is measured (non-collocated), a low-frequency
disturbance d (through 0.2/(s + 0.2)) pushes mass 2. Goals: disturbance rejection
``||T_dy||_inf`` (soft), 6 dB / 30 deg margins at the plant input and 2 % closed-loop damping
(hard). Then the same PID, discrete at 5 Hz.

Run: ``python examples/systune_pid.py``
"""

import control
import numpy as np

from oos_drake.control.goals import Margins, Poles, WeightedGain
from oos_drake.control.systune import SystuneOptions, systune
from oos_drake.control.tunable import TunablePID


def two_mass(k: float, c: float = 0.1, a: float = 0.2) -> control.StateSpace:
    """States x1, x2 [m], v1, v2 [m/s], disturbance filter; inputs u, d [N]; outputs y, e [m]."""
    A = np.array(
        [[0, 0, 1, 0, 0], [0, 0, 0, 1, 0], [-k, k, -c, c, 0], [k, -k, c, -c, 1], [0, 0, 0, 0, -a]],
        float,
    )
    B = np.array([[0, 0], [0, 0], [1, 0], [0, 0], [0, a]], float)
    C = np.array([[0, 1, 0, 0, 0], [0, -1, 0, 0, 0]], float)
    return control.ss(A, B, C, np.zeros((2, 2)), inputs=["u", "d"], outputs=["y", "e"])


def main() -> None:
    plants = [two_mass(k) for k in (0.5, 1.0, 2.0)]
    goals = [
        WeightedGain("d", "y"),
        Margins("u", gain_margin_db=6.0, phase_margin_deg=30.0, kind="hard"),
        Poles(min_damping=0.02, kind="hard"),
    ]
    for sampling_time in (0.0, 0.2):
        pid = TunablePID(
            "C",
            "e",
            "u",
            kp=0.1,
            ki=1e-3,
            kd=0.3,
            tf=1.0,
            rolloff_order=1,
            rolloff_frequency=5.0,
            sampling_time=sampling_time,
        )
        result = systune(plants, pid, goals, options=SystuneOptions(restarts=1, seed=0))
        print(
            f"\nsampling time {sampling_time} s: status {result.status}, "
            f"soft {result.soft:.4g}, hard {result.hard:.4g}"
        )
        for name, value in result.parameters["C"].items():
            print(f"  {name:18s} {value[0]:.5g}")
        for goal in result.goals:
            details = ", ".join(f"{k} {v:.4g}" for k, v in goal.details.items())
            print(f"  {goal.kind:4s} {goal.name:22s} value {goal.value:.4g} ({details})")


if __name__ == "__main__":
    main()
