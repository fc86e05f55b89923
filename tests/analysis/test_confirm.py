"""``oos confirm``: oscillation identification, the physical ray, boundaries, bad input."""

import numpy as np
import pandas as pd
import pytest

from oos_drake.analysis.confirm import (
    BodyInertia,
    Peak,
    boundary_along_ray,
    physical_alpha_max,
    physical_violation,
    read_peaks,
)
from oos_drake.analysis.oscillation import dominant_oscillation
from oos_drake.app.main import main
from oos_drake.scenario.data import load_scenario
from oos_drake.scenario.model import physical_blocks


def test_matrix_pencil_finds_a_damped_sinusoid_under_a_drift_and_a_faster_mode():
    t = np.arange(0.0, 40.0, 0.1) + 8.0
    sigma, f = -0.013, 0.8127
    slow = 5e-3 * np.exp(-0.05 * t)  # the rigid attitude's return: not an oscillation
    fast = 2e-3 * np.exp(-0.4 * t) * np.sin(2 * np.pi * 2.1 * t)  # decays before the end
    y = np.column_stack(
        [
            1e-3 * np.exp(sigma * t) * np.cos(2 * np.pi * f * t + 0.3) + slow + fast,
            -4e-4 * np.exp(sigma * t) * np.sin(2 * np.pi * f * t),
            slow,
        ]
    )
    found = dominant_oscillation(t, y)
    assert found.frequency == pytest.approx(f, rel=1e-8)
    assert found.decay_rate == pytest.approx(sigma, abs=1e-8)
    assert found.fit_error < 1e-8


def test_matrix_pencil_sees_a_growing_oscillation_in_noise():
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 30.0, 0.1)
    y = np.exp(0.004 * t) * np.cos(2 * np.pi * 0.78 * t) + 1e-5 * rng.standard_normal(t.size)
    found = dominant_oscillation(t, y, rtol=1e-3)
    assert found.frequency == pytest.approx(0.78, rel=1e-4)
    assert found.decay_rate == pytest.approx(0.004, abs=2e-4)
    with pytest.raises(ValueError, match="no oscillation"):
        dominant_oscillation(t, np.exp(-0.1 * t))


def test_the_verdict_follows_the_expected_oscillation_not_a_larger_slower_one():
    # a large, lightly damped attitude mode (0.13 Hz) decaying beside a small critical mode
    # (0.77 Hz) that grows: the largest oscillation says "stable", the expected one "growing"
    t = np.arange(0.0, 37.0, 0.1) + 8.0
    y = 2e-3 * np.exp(-0.05 * t) * np.cos(2 * np.pi * 0.134 * t) + 1e-5 * np.exp(0.02 * t) * np.cos(
        2 * np.pi * 0.77 * t + 0.4
    )
    largest = dominant_oscillation(t, y)
    assert largest.frequency == pytest.approx(0.134, rel=1e-6)
    assert largest.decay_rate < 0
    expected = dominant_oscillation(t, y, near_hz=0.75)
    assert expected.frequency == pytest.approx(0.77, rel=1e-6)
    assert expected.decay_rate == pytest.approx(0.02, abs=1e-6)
    # nothing near the expected frequency: the largest oscillation, as without it
    assert dominant_oscillation(t, y, near_hz=3.0).frequency == pytest.approx(0.134, rel=1e-6)


def test_physical_limit_along_a_ray_matches_the_closed_forms():
    specs = physical_blocks(load_scenario())
    half = {n: 0.5 * (specs[n].range[1] - specs[n].range[0]) for n in specs}
    nominal = {n: specs[n].nominal for n in specs}
    # inertia: Jxx up, Jyy and Jzz down, diagonal tensor: Jyy + Jzz = Jxx at the limit
    body = BodyInertia(("Jxx_RH2", "Jyy_RH2", "Jzz_RH2"), np.diag([1.0, 1.0, 1.0]))
    direction = {"Jxx_RH2": 2.0, "Jyy_RH2": -2.0, "Jzz_RH2": -2.0, "m_RH2": 1.0}
    expected = (nominal["Jyy_RH2"] + nominal["Jzz_RH2"] - nominal["Jxx_RH2"]) / (
        2.0 * (half["Jxx_RH2"] + half["Jyy_RH2"] + half["Jzz_RH2"])
    )
    alpha, reason = physical_alpha_max(specs, direction, (body,), tol=1e-9)
    assert alpha == pytest.approx(expected, abs=1e-8)
    assert "triangle" in reason
    # a mass driven through zero, a modal frequency driven through zero
    for name in ("m_RH2", "w1_SA3"):
        alpha, reason = physical_alpha_max(specs, {name: -3.0}, tol=1e-9)
        assert alpha == pytest.approx(nominal[name] / (3.0 * half[name]), abs=1e-8)
        assert name in reason
    # the ray never leaves the physical domain: a mass going up
    assert physical_alpha_max(specs, {"m_RH2": 1.0})[0] == np.inf
    assert "stiffness" in physical_violation({"k_tors_SM1": -1.0}, {"k_tors_SM1": "stiffness"})


def test_boundary_along_ray_finds_the_first_instability():
    calls = []

    def unstable(alpha):
        calls.append(alpha)
        return 0.7371 < alpha < 1.2 or alpha > 3.0  # the first crossing counts

    assert boundary_along_ray(unstable, 4.0, rtol=1e-6) == pytest.approx(0.7371, rel=1e-6)
    assert boundary_along_ray(lambda a: False, 2.0) == np.inf
    assert boundary_along_ray(lambda a: True, 2.0) < 1e-4  # unstable from the start


def test_bad_input_through_the_cli(tmp_path, capsys):
    assert (
        main(["confirm", "--analysis", str(tmp_path / "missing"), "--out", str(tmp_path / "o")])
        == 2
    )
    assert "folder not found" in capsys.readouterr().err
    folder = tmp_path / "analysis"
    folder.mkdir()
    pd.DataFrame({"study": ["mission"]}).to_parquet(folder / "stability_peaks.parquet")
    assert main(["confirm", "--analysis", str(folder), "--out", str(tmp_path / "o")]) == 2
    assert "peak_perturbations.npz not found" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_read_peaks_refuses_a_peak_without_its_perturbation(tmp_path):
    pd.DataFrame(
        {
            "study": ["mission"],
            "subset": ["modal"],
            "time [s]": [1.0],
            "mu_lower": [0.3],
            "mu_upper": [0.31],
        }
    ).to_parquet(tmp_path / "stability_peaks.parquet")
    np.savez(tmp_path / "peak_perturbations.npz", **{"mission|real|omega [rad/s]": 1.0})
    with pytest.raises(ValueError, match="no perturbation for mission|modal"):
        read_peaks(tmp_path)
    assert Peak(
        "mission", "modal", 1.0, np.nan, 1.0, 0.3, 0.3, {"Delta_add": np.eye(3)}
    ).has_complex


def test_confirm_runs_on_the_scenario_the_analysis_recorded(tmp_path):
    from oos_drake.app.analyze import _analysis_scenario
    from oos_drake.scenario.data import scenario_path, scenario_record

    paper, heavy = scenario_path("paper"), scenario_path("heavy_target")
    assert _analysis_scenario(None, "A", None) == str(paper)  # analyses written before records
    record = scenario_record(load_scenario("heavy_target"))
    assert _analysis_scenario(record, "A", None) == str(heavy)
    assert _analysis_scenario(record, "A", "heavy_target") == str(heavy)
    with pytest.raises(ValueError, match="--scenario paper: not the scenario of --analysis A"):
        _analysis_scenario(record, "A", "paper")
    copy = tmp_path / "mine.toml"
    copy.write_bytes(heavy.read_bytes())
    mine = scenario_record(load_scenario(copy))
    copy.write_text(copy.read_text() + "\n# edited after the analysis\n")
    with pytest.raises(ValueError, match="gone or changed since the analysis"):
        _analysis_scenario(mine, "A", None)
    with pytest.raises(ValueError, match="overrides scenario values"):
        _analysis_scenario(dict(record, overrides={"hubs.RH2.mass": 500.0}), "A", None)
