"""``geo_satellite``: its weights scaled to its size, and ``oos run`` on it end to end.

Fast: the total inertia written out here from the TOML (parallel-axis theorem, every body at
its file angle) against the model's ``G(0)^-1``; the additive weight's share of ``1 / J`` and
the gyro noise's torque through the baseline PD's rate gain (closed form), the design rules
the file's comments state. Slow: ``oos run --scenario geo_satellite --quick`` at reduced
sizes with the shipped campaign (3 runs), the confirmation left out (its cost).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest
import tomli_w
from reduced_run import assert_stable_at_range_corners, reduce_run_stages, sweep_peak
from tree_documents import rotation, shipped_document

from oos_drake.scenario.data import load_scenario, scenario_path


def _total_inertia(name: str) -> np.ndarray:
    """Total inertia [kg m^2] of a shipped one-level tree about its centre of mass, in the
    hub's axes, from the TOML alone (revolute joints at their file angles)."""
    bodies = shipped_document(name)["bodies"]
    masses, centres, inertias = [], [], []
    for body in bodies:
        if body["kind"] == "rigid":
            R, c = np.eye(3), np.asarray(body["p_B_G"], float)
        else:
            joint = body["joint"]
            R = np.asarray(joint.get("R_parent_joint", np.eye(3)), float)
            if joint["type"] == "revolute":
                R = R @ np.asarray(rotation(joint["axis"], joint["angle"]))
            c = np.asarray(joint["p_parent_joint"], float) + R @ np.asarray(body["p_P_S"], float)
        masses.append(body["mass"])
        centres.append(c)
        inertias.append(R @ np.asarray(body["inertia"], float) @ R.T)
    m = np.asarray(masses)
    G = (m[:, None] * np.asarray(centres)).sum(0) / m.sum()
    J = np.zeros((3, 3))
    for mass, c, inertia in zip(masses, centres, inertias, strict=True):
        r = c - G
        J += inertia + mass * (r @ r * np.eye(3) - np.outer(r, r))
    return J


@pytest.mark.parametrize("name", ["flexible_satellite", "geo_satellite"])
def test_total_inertia_by_hand_is_the_models(name):
    from oos_drake.control.baseline import OMEGA_ATT, scenario_baseline_gains

    J_model = scenario_baseline_gains(load_scenario(name))[:, :3] / OMEGA_ATT**2
    np.testing.assert_allclose(J_model, _total_inertia(name), rtol=1e-9, atol=1e-6)


def test_geo_weights_are_scaled_to_its_inertia():
    """``Delta_add`` is an angular acceleration per torque: ``W_add`` relative to ``1 / J``.
    geo_satellite's share of its own ``1 / J`` lies within flexible_satellite's (the paper's
    -75 dB on a 161-768 kg m^2 spacecraft); the paper's -75 dB would be 55-181 % here. Its
    gyro noise through the baseline PD's rate gain ``2 xi omega J`` stays below half the
    wheels' torque bound."""
    from oos_drake.control.baseline import OMEGA_ATT, XI_ATT

    shares = {}
    for name in ("flexible_satellite", "geo_satellite"):
        weight = 10 ** (load_scenario(name).control.additive_weight_db / 20)
        shares[name] = weight * np.linalg.eigvalsh(_total_inertia(name))[[0, -1]]
    assert shares["flexible_satellite"][0] <= shares["geo_satellite"][0]
    assert shares["geo_satellite"][1] <= shares["flexible_satellite"][1]
    J_geo = np.linalg.eigvalsh(_total_inertia("geo_satellite"))
    assert 10 ** (-75 / 20) * J_geo[0] > 0.5  # the file's former weight
    control = load_scenario("geo_satellite").control
    rate_gain = 2 * XI_ATT * OMEGA_ATT * J_geo[-1]  # [N m s/rad]
    assert control.gyro_noise * rate_gain <= 0.5 * control.torque_limit
    assert 5e-4 * rate_gain > 3 * control.torque_limit  # the file's former gyro noise


@pytest.mark.slow
def test_oos_run_on_geo_satellite_end_to_end(tmp_path, monkeypatch):
    """``oos run --scenario geo_satellite --quick`` at reduced sizes: every stage but the
    confirmation (the shipped campaign with 3 runs included); the validation within 1e-6 on
    every configuration; the controller's gamma the peak of a dense frequency sweep of its
    closed loops; the analysis' closed loops stable at the corners of the declared ranges
    (eigenvalues). The confirmation is left out: its slow peaks (~0.016 Hz) need runs of
    eight periods, 380 s of this test's 594 s at load 9 (measured with it); a tree's
    confirmation is tested in tests/tree/test_tree_confirm.py (the geo twin with every block
    substituted against the substituted LFR; a worst case confirmed end to end on
    flexible_satellite), and geo's own in the full run of docs/TREE.md."""
    import oos_drake.app.pipeline as pipeline
    from oos_drake.app.main import build_parser

    covered = "covered by tests/tree/test_tree_confirm.py"
    reduce_run_stages(monkeypatch, skip={"confirm": covered})
    out = tmp_path / "out"
    # the shipped file without its hard margin goals: the reduced synthesis (4 configurations,
    # 25 iterations) does not reach them (4.0 dB of 5 measured), and `oos run` stops on an
    # infeasible controller; the full run reaches them (docs/TREE.md). Measured (branch sy5):
    # at 60 iterations the reduced synthesis meets them (5.005 dB, 5.008 dB at the midpoints,
    # 9.3 s CPU) and this test passes with them, but its analysis stage then takes 902 s (the
    # whole test 1116 s at load 10-11): over the slow suite's budget, so they stay stripped
    document = shipped_document("geo_satellite")
    for goal in ("gain_margin_db", "phase_margin_deg"):
        document["control"].pop(goal, None)
    scenario_file = tmp_path / "geo_satellite.toml"
    scenario_file.write_bytes(tomli_w.dumps(document).encode())
    spec = tmp_path / "campaign.toml"
    shipped = pipeline.default_campaign(scenario_path("geo_satellite"))
    assert shipped.name == "geo_satellite.toml"
    text = shipped.read_text().replace("n_runs = 48", "n_runs = 3")
    spec.write_text(text.replace('scenario = "geo_satellite"', f'scenario = "{scenario_file}"'))
    argv = ["run", "--scenario", str(scenario_file), "--quick", "--out", str(out)]
    assert pipeline.run_pipeline(build_parser().parse_args([*argv, "--campaign", str(spec)])) == 0
    timings = json.loads((out / "timings.json").read_text())
    assert set(timings["skipped"]) == {"model figures", "confirm"}
    assert {"validate", "controller", "analysis", "margins"} <= set(timings["stages_s"])

    validation = (out / "validate" / "validate.txt").read_text()
    errors = [float(m) for m in re.findall(r"^t=\S+ s \S+\s+(\S+)", validation, re.M)]
    assert len(errors) >= 5 and max(errors) <= 1e-6

    (campaign,) = out.glob("campaign-*")
    runs = pd.read_parquet(campaign / "runs.parquet")
    assert len(runs) == 3 and (runs["status"] == "ok").all()

    record = json.loads((out / "controller" / "controller.json").read_text())
    loops = np.load(out / "controller" / "closed_loop.npz")
    assert np.linalg.eigvals(loops["A"]).real.max() < 0
    peak = sweep_peak(loops)
    assert record["gamma"] * (1 - 1e-3) <= peak <= record["gamma"] * (1 + 1e-6)

    scenario = load_scenario(str(scenario_file))
    assert_stable_at_range_corners(
        out / "controller" / "controller.json",
        scenario,
        np.linspace(0.0, scenario.mission.t_end, 4),
    )
