"""The sinusoidal input of the Drake mission and the worst case as simulator values."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("pydrake")

from oos_drake.analysis.performance_twin import mission_values, worst_case_columns  # noqa: E402
from oos_drake.lfr.blocks import ULTIDyn, UReal  # noqa: E402
from oos_drake.multibody.mission_sim import (  # noqa: E402
    SINE_CHANNELS,
    disturbance_parameters,
    sine_table,
)

#: The analysis' disturbance order [d_ext; n_sst; n_gyro] -> the noise-table order
#: [n_sst; n_gyro; d_ext] (written out here, independently of the module's index array).
LFR_TO_TABLE = [6, 7, 8, 0, 1, 2, 3, 4, 5]


def _values(amplitude, frequency, c):
    values = {p.name: p.nominal for p in disturbance_parameters()}
    values |= {"sine_amplitude": amplitude, "sine_frequency": frequency}
    for channel, entry in zip(SINE_CHANNELS, c, strict=True):
        values[f"sine_re_{channel}"], values[f"sine_im_{channel}"] = entry.real, entry.imag
    return values


def test_sine_table_is_the_sampled_sinusoid():
    rng = np.random.default_rng(3)
    c = 0.5 * (rng.standard_normal(9) + 1j * rng.standard_normal(9))
    t = 40.0 + np.arange(50) / 10.0
    table = sine_table(_values(1.7, 0.23, c), t)
    # a Re(c/|c| e^{jwt}) = a/|c| (Re c cos wt - Im c sin wt), column by column
    w = 2 * np.pi * 0.23
    expected = (
        1.7
        / np.sqrt(np.sum(np.abs(c) ** 2))
        * (np.outer(np.cos(w * t), c.real) - np.outer(np.sin(w * t), c.imag))
    )
    np.testing.assert_allclose(table, expected, rtol=1e-12, atol=1e-15)
    # its 2-norm over the channels: the amplitude of a unit phasor's real part never exceeds a
    assert np.linalg.norm(table, axis=1).max() <= 1.7 + 1e-12
    assert not sine_table(_values(0.0, 0.23, c), t).any()
    assert not sine_table(_values(1.0, 0.23, np.zeros(9)), t).any()
    names = {p.name for p in disturbance_parameters()}
    assert {"noise_scale", "sine_amplitude", "sine_frequency"} < names and len(names) == 21


def test_worst_case_as_simulator_values():
    specs = {
        "m": UReal("m", 250.0, 225.0, 275.0),
        "Delta_add": ULTIDyn("Delta_add", (3, 3)),
        "Delta_mul_xx": ULTIDyn("Delta_mul_xx", (1, 1)),
    }
    add = np.diag([0.3 - 0.4j, 0.1 + 0.0j, 0.0])  # trace: 0.4 - 0.4j, Re(j trace) = 0.4 > 0
    normalized = {"m": 0.5, "Delta_add": add, "Delta_mul_xx": 0.6 + 0.8j}
    rng = np.random.default_rng(5)
    v = rng.standard_normal(9) + 1j * rng.standard_normal(9)
    v /= np.linalg.norm(v)
    omega = 2 * np.pi * 0.08
    values = mission_values(normalized, specs, v, omega)
    assert values["m"] == pytest.approx(262.5)  # nominal + 0.5 half-range
    assert values["Delta_add"] == pytest.approx(0.5)  # |0.3 - 0.4j|, sign of Re(j trace) > 0
    assert values["Delta_mul_xx"] == pytest.approx(-1.0)  # |0.6 + 0.8j|, Re(j c) = -0.8 < 0
    assert values["noise_scale"] == 0.0 and values["sine_amplitude"] == 1.0
    assert values["sine_frequency"] == pytest.approx(0.08)
    # the simulator's sinusoid is the analysis' input Re(v e^{jwt}), channels reordered
    t = np.linspace(0.0, 30.0, 301)
    table = sine_table(values, t)
    expected = np.real(np.outer(np.exp(1j * omega * t), v))  # LFR order
    np.testing.assert_allclose(table[:, LFR_TO_TABLE], expected, rtol=1e-12, atol=1e-14)
    columns = worst_case_columns(normalized, specs, v, omega)
    stored = np.array(json.loads(columns["worst input"]))
    np.testing.assert_allclose(stored[LFR_TO_TABLE, 0] + 1j * stored[LFR_TO_TABLE, 1], v)
    assert json.loads(columns["worst values"]) == pytest.approx(values)
    assert json.loads(columns["worst perturbation"])["Delta_mul_xx"] == [0.6, 0.8]
