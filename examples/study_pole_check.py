"""Independent check of one value of an ``oos study``: closed-loop poles at its worst parameters.

For the worst study of the value (mission or docking phase, subset ``total``), the saved
destabilizing perturbation of the analysis (``peak_perturbations.npz``, size ``1 / mu_lower``)
is substituted into the uncertain closed loop of the value's scenario with ``usubs`` (complex
blocks realized by a stable first-order system that interpolates the perturbation at the
critical frequency) and the eigenvalues of the resulting state matrix are computed directly:

- at the saved size ``1 / mu_lower`` a pole must sit on the imaginary axis at the critical
  frequency (what the lower bound claims);
- scaled to ``s`` times that size, the largest real part of the poles says on which side of
  the axis the loop is (the margin's meaning: ``1 / mu_lower < 1`` means a destabilizing
  perturbation lies inside the uncertainty set).

Usage::

    python examples/study_pole_check.py STUDY_DIR INDEX [--controller FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def interpolant(value, omega: float):
    """A stable real system ``G`` with ``G(j omega) = value`` (entry by entry
    ``a + b - 2 b omega / (s + omega)`` for ``value = a + j b``)."""
    import control

    value = np.atleast_2d(np.asarray(value, dtype=complex))
    p, q = value.shape
    n = p * q
    A = -omega * np.eye(n)
    B = np.zeros((n, q))
    C = np.zeros((p, n))
    for k, (i, j) in enumerate(np.ndindex(p, q)):
        B[k, j] = 1.0
        C[i, k] = -2.0 * value[i, j].imag * omega
    return control.ss(A, B, C, value.real + value.imag)


def main() -> None:
    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.models import docking_closed_loop, mission_closed_loop
    from oos_drake.lfr import usubs
    from oos_drake.scenario.data import load_scenario

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", type=Path)
    parser.add_argument("index", type=int)
    parser.add_argument("--controller", default=None)
    args = parser.parse_args()
    analysis = args.study / "points" / str(args.index) / "analysis"
    summary = json.loads((analysis / "summary.json").read_text())
    record = summary["scenario"]
    scenario = load_scenario(record["file"], record["overrides"])
    controller = scenario_controller(args.controller, scenario)
    studies = {"mission": summary["mission"]["mu_peak_lower"]}
    studies |= {f"docking-{k}": v["mu_lower"] for k, v in summary["docking"].items()}
    study = max(studies, key=studies.get)
    import pandas as pd

    peaks = pd.read_parquet(analysis / "stability_peaks.parquet")
    row = peaks[(peaks["study"] == study) & (peaks["subset"] == "total")].iloc[0]
    if study == "mission":
        one = mission_closed_loop(controller, [row["time [s]"]], scenario).system.model(0)
        where = f"t = {row['time [s]']:.1f} s"
    else:
        k = row["stiffness [N/m or N m/rad]"]
        one = docking_closed_loop(controller, study[-1], [k], scenario=scenario).system.model(0)
        where = f"stiffness {k:.4g}"
    saved = np.load(analysis / "peak_perturbations.npz")
    key = f"{study}|total|"
    omega = float(saved[key + "omega [rad/s]"])
    print(
        f"{record['overrides']}: worst study {study} at {where}, f = {omega / 2 / np.pi:.4g} Hz, "
        f"mu in [{row['mu lower [-]']:.4g}, {row['mu upper [-]']:.4g}], perturbation size "
        f"1/mu_lower = {1 / row['mu lower [-]']:.4g}"
    )
    for scale in (1.0, 0.98, 1.02, row["mu lower [-]"]):
        values = {}
        for name, spec in one.uncertainty.items():
            if key + name not in saved:
                values[name] = 0.0 if spec.kind == "ureal" else np.zeros(spec.shape)
                continue
            value = scale * saved[key + name]
            values[name] = float(value) if spec.kind == "ureal" else interpolant(value, omega)
        poles = np.linalg.eigvals(np.asarray(usubs(one, values, normalized=True).A))
        nearest = poles[np.argmin(np.abs(poles - 1j * omega))]
        size = scale / row["mu lower [-]"]
        print(
            f"  perturbation size {size:.4g} (x{scale:.4g} the saved one): max Re(pole) = "
            f"{poles.real.max():+.3e} 1/s; pole nearest j*omega: {nearest:.5g} "
            f"(|p - j omega| = {abs(nearest - 1j * omega):.2e})"
        )


if __name__ == "__main__":
    main()
