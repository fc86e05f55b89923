"""Sensors, actuators, roll-off and weights against their closed-form frequency responses."""

import numpy as np
import pytest

from oos_drake.control import components as comp
from oos_drake.control.statespace import BatchedStateSpace

SPEC = comp.DesignSpecification()


def siso_response(parts, omega):
    sys = BatchedStateSpace(*parts, ("u",), ("y",))
    return sys.freqresp(omega)[:, 0, 0]


def test_butterworth_magnitude_is_the_closed_form():
    w = 2 * np.pi * np.array([0.0, 0.1, 0.7, 2.0, 7.0])
    wc = 2 * np.pi * 0.7
    H = siso_response(comp.butterworth(4, 0.7), w)
    np.testing.assert_allclose(np.abs(H), 1 / np.sqrt(1 + (w / wc) ** 8), rtol=1e-10)


def test_sensors_and_wheels_match_their_transfer_functions():
    w = np.array([0.0, 3.0, 50.0, 1256.0, 5000.0])
    s = 1j * w
    w8, w200 = 2 * np.pi * 8, 2 * np.pi * 200
    np.testing.assert_allclose(
        siso_response(comp.first_order_lowpass(8.0), w), 1 / (s / w8 + 1), rtol=1e-12
    )
    np.testing.assert_allclose(
        siso_response(comp.second_order(200.0, 0.7), w),
        w200**2 / (s**2 + 2 * 0.7 * w200 * s + w200**2),
        rtol=1e-12,
    )


def test_disturbance_weight_is_diagonal_first_order():
    W = comp.disturbance_weight(SPEC)
    w = np.array([0.0, 0.1, 1.0])
    H = W.freqresp(w)
    gains = np.array([0.002577, 0.009685, 0.01239])
    expected = gains[None, :] / (2.236 * 1j * w[:, None] + 0.2236)
    np.testing.assert_allclose(np.diagonal(H, axis1=1, axis2=2), expected, rtol=1e-12)
    assert np.abs(H[:, 0, 1]).max() == 0


def test_analysis_weights_follow_the_paper():
    assert SPEC.additive_weight == pytest.approx(10 ** (-75 / 20))
    assert SPEC.multiplicative_diagonal == 4e-2 and SPEC.multiplicative_off_diagonal == 4e-3


def test_bad_specification_names_the_field():
    with pytest.raises(ValueError, match="gyro_cutoff_hz"):
        comp.DesignSpecification(gyro_cutoff_hz=-1.0)
