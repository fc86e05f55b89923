"""The Drake mission follows the scenario file: SDF generated from it, [control] numbers in the
flight software (checked on the built diagram, against the file's numbers)."""

import numpy as np
import pytest

pytestmark = [pytest.mark.drake, pytest.mark.slow]  # builds the Drake mission: ~8 s idle
pytest.importorskip("pydrake")

from oos_drake.campaign.drake_simulator import DrakeMissionSimulator  # noqa: E402
from oos_drake.scenario.data import DEFAULT_SCENARIO_PATH, load_scenario  # noqa: E402


def test_heavy_target_twin_follows_its_scenario_file(tmp_path):
    text = (DEFAULT_SCENARIO_PATH.parent / "heavy_target.toml").read_text()
    text = text.replace("flight_software_rate_hz = 10.0", "flight_software_rate_hz = 5.0")
    text = text.replace("torque_limit = 2.0 ", "torque_limit = 3.0 ")
    text = text.replace("star_tracker_cutoff_hz = 8.0", "star_tracker_cutoff_hz = 2.0")
    scenario_file = tmp_path / "heavy.toml"
    scenario_file.write_text(text)
    scenario = load_scenario(scenario_file)
    assert scenario.control.flight_software_rate_hz == 5.0

    simulator = DrakeMissionSimulator(scenario=str(scenario_file), log_rate=1.0)
    handles = simulator.simulation.handles
    # the target of the twin weighs what the file says (SDF generated from it)
    assert handles.target_body.default_mass() == pytest.approx(250.0, rel=1e-12)
    design = handles.flight_software.design
    assert design.period == pytest.approx(1 / 5.0) and design.torque_limit == 3.0
    # star tracker: bilinear discretization of 1 / (s / w_c + 1) has its pole at
    # (1 + w_c T / 2) / (1 - w_c T / 2) with w_c = -2 pi 2 Hz
    wT = -2 * np.pi * 2.0 * 0.2
    pole = np.linalg.eigvals(design.star_tracker.A)
    np.testing.assert_allclose(pole, (1 + wT / 2) / (1 - wT / 2), rtol=1e-12)
    # dispersion ranges of the target come from the file (+-10 % of 250 kg)
    m = simulator.simulation._by_name["m_RH2"]
    assert (m.lower, m.upper) == pytest.approx((225.0, 275.0))
