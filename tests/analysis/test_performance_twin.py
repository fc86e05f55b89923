"""Performance confirmation on a linear twin: the LFR closed loop simulated in scipy with wcgain's
worst perturbation and worst input reaches wcgain's lower bound (issue 32, must show)."""

import control
import numpy as np
import pandas as pd
import pytest

from oos_drake.analysis.performance_twin import (
    channel_direction,
    linear_twin_gain,
    perturbed_loop,
    phasor,
    worst_gain_cases,
)
from oos_drake.lfr import as_lfr, feedback, hstack, ultidyn, ureal, vstack
from oos_drake.robust.wcgain import wcgain

S = control.tf("s")


def _mimo_loop():
    """Two inputs, two outputs, a real damping and a dynamic uncertainty."""
    z = ureal("z", 0.15, plusminus=0.05)
    integ = control.tf(1, [1, 0])
    resonant = feedback(integ * feedback(integ, 2 * z), 1.0)  # 1/(s^2 + 2 z s + 1)
    delta = ultidyn("delta", (1, 1), bound=0.3)
    lag = as_lfr(control.tf(1, [1, 1])) * (1 + delta)
    top = hstack([resonant, 0.5 * resonant])
    bottom = lag * hstack([0.3, 1.0])  # delta once (one occurrence)
    return vstack([top, bottom])


def _published_loop():
    """MathWorks RCT wcgain example (tests/robust/published.py): a dynamic block only."""
    delta = ultidyn("delta", (1, 1), bound=0.4)
    G = as_lfr(control.tf(1, [1, 0])) + delta
    C = control.ss(2 - 0.04 * S / (0.02 * S + 1))  # MATLAB pid(2, 0, -0.04, 0.02)
    return feedback(1, G * C)


@pytest.mark.parametrize("build", [_mimo_loop, _published_loop])
def test_linear_twin_reaches_wcgain_lower_bound(build):
    sys = build()
    res = wcgain(sys, guaranteed=False)
    omega = res.critical_frequency
    loop = perturbed_loop(sys, res.worst_case_normalized, omega)
    rows = range(sys.shape[0])
    sigma, v = channel_direction(loop, rows, omega)
    # the simulated steady state (scipy, time domain) reaches wcgain's lower bound within 1 %
    gain = linear_twin_gain(loop, v, omega, rows)
    assert gain == pytest.approx(res.lower, rel=0.01)
    # and the realized loop's frequency response there (a second computation)
    assert gain == pytest.approx(sigma, rel=1e-3)
    # and a worse one than any other input direction tried (v is the worst)
    other = np.ones(sys.shape[1], dtype=complex) / np.sqrt(sys.shape[1])
    assert linear_twin_gain(loop, other, omega, rows) <= gain * (1 + 1e-3)


def test_phasor_recovers_a_sinusoid():
    t = np.linspace(0.0, 10.0, 2001)
    w = 2 * np.pi * 0.4
    Y = np.array([0.3 - 0.2j, -1.5j])
    y = 0.7 + np.real(np.outer(np.exp(1j * w * t), Y))
    np.testing.assert_allclose(phasor(t, y, w), Y, atol=1e-12)


def test_worst_gain_cases_take_the_largest_finite_lower_bound():
    table = pd.DataFrame(
        {
            "channel": ["e_p", "e_p", "e_p", "e_u"],
            "subset": ["total"] * 4,
            "model": [0, 0, 1, 0],
            "time [s]": [10.0, 10.0, 20.0, 10.0],
            "frequency [Hz]": [0.1, 0.2, 0.3, 0.1],
            "gain nominal [-]": [0.5, 0.6, 0.7, 0.1],
            "gain lower [-]": [0.9, np.inf, 1.2, 0.2],
            "gain upper [-]": [1.0, np.inf, 1.3, 0.3],
        }
    )
    cases = worst_gain_cases(table)
    assert [(c.channel, c.time, c.lower) for c in cases] == [("e_p", 20.0, 1.2), ("e_u", 10.0, 0.2)]
    assert cases[0].omega == pytest.approx(2 * np.pi * 0.3)


@pytest.mark.slow
def test_drake_twin_gain_matches_the_sampled_data_loop():
    """heavy_target, baseline controller, a worst pointing gain at 269 s and 0.05 Hz: the Drake
    twin (nonlinear multibody mission, flight software) driven by the worst input reaches the
    gain of the linear sampled-data loop at z = exp(j omega dt) (a second, frequency-domain
    computation) within 2 %, and the continuous linear twin within 3 %."""
    from oos_drake.analysis.confirm import Peak, _peak_models
    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.performance_twin import GainCase, confirm_gain_case
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario("heavy_target")
    controller = scenario_controller(None, scenario)
    case = GainCase("e_p", "total", 269.0, 2 * np.pi * 0.05, 0.0, 0.0, 0.0)
    closed, _ = _peak_models(Peak("mission", "", 269.0, np.nan, 1.0, 1, 1), controller, scenario)
    row = confirm_gain_case(case, controller, scenario, uncertainty_subsets(closed.uncertainty))
    assert row["gain twin [-]"] == pytest.approx(row["gain linear sampled [-]"], rel=0.02)
    assert row["gain twin [-]"] == pytest.approx(row["gain linear twin [-]"], rel=0.03)
    assert row["gain linear twin [-]"] == pytest.approx(row["gain of the perturbation [-]"], 1e-3)


def test_perturbed_loop_equals_the_loop_rebuilt_with_the_realized_blocks():
    """A dynamic block occurring twice and a real parameter: the loop closed on the worst
    perturbation equals the same expression built again with the block replaced by its stable
    interpolant and the parameter by its value (LFR arithmetic, no substitution code), at the
    critical frequency and away from it. The time check closes its loops the same way."""
    from oos_drake.robust.interpolant import lti_interpolant

    def build(delta, k):
        plant = as_lfr(control.tf(1, [1, 0.2, 1])) * (1 + delta) * k
        C = control.ss(2 - 0.04 * S / (0.02 * S + 1))
        return feedback(1, plant * C) + 0.5 * delta  # delta occurs twice

    delta = ultidyn("delta", (1, 1), bound=0.4)
    k = ureal("k", 1.0, plusminus=0.3)
    sys = build(delta, k)
    omega = 1.3
    value = 0.8 * np.exp(0.7j)  # normalized (|value| <= 1)
    loop = perturbed_loop(sys, {"delta": np.array([[value]]), "k": -0.6}, omega)
    realized = control.ss(lti_interpolant(np.array([[0.4 * value]]), omega))
    expected = build(as_lfr(realized), 1.0 - 0.6 * 0.3)
    for w in (omega, 0.3, 5.0):
        got = np.asarray(control.evalfr(loop.to_ss(), 1j * w))
        ref = np.asarray(control.evalfr(expected.to_ss(), 1j * w))
        assert np.allclose(got, ref, rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="unknown block"):
        perturbed_loop(sys, {"kk": 0.1}, omega)


def test_axis_direction_is_the_worst_input_for_one_axis():
    """Against 20000 random unit inputs: none gives a larger single-axis response."""
    from oos_drake.analysis.performance_twin import axis_direction

    rng = np.random.default_rng(4)
    H = rng.standard_normal((3, 9)) + 1j * rng.standard_normal((3, 9))
    gain, v = axis_direction(H)
    assert np.linalg.norm(v) == pytest.approx(1.0)
    assert np.abs(H @ v).max() == pytest.approx(gain, rel=1e-12)
    V = rng.standard_normal((9, 20000)) + 1j * rng.standard_normal((9, 20000))
    V /= np.linalg.norm(V, axis=0)
    assert np.abs(H @ V).max() <= gain * (1 + 1e-12)
    assert np.abs(H @ V).max() > 0.75 * gain  # the sampling comes close (18 real dimensions)
