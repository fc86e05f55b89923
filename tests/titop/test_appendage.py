"""Cantilevered flexible appendage: M_P(0) = D_P, M_P(inf) = D_P0, realization vs formula."""

import numpy as np
import pytest
from appendage_oracle import effective_mass_model  # tests/ is on sys.path

from oos_drake.lfr import ureal, usubs
from oos_drake.scenario.data import load_scenario
from oos_drake.titop import flexible_appendage
from oos_drake.titop.appendage import check_appendage_data
from oos_drake.titop.spatial import rigid_spatial_inertia


def array_data(model):
    """(D_P, L with columns = modes, omega [rad/s], xi) recomputed from the raw table values."""
    d_P = rigid_spatial_inertia(model.mass, model.inertia, model.p_P_S)
    return (
        d_P,
        np.asarray(model.participation).T,
        2 * np.pi * np.asarray(model.frequencies_hz),
        np.asarray(model.damping_ratios),
    )


@pytest.fixture(scope="module", params=["SA1_2", "SA3_4"])
def data(request):
    return request.param, array_data(load_scenario().array_models[request.param])


def test_static_and_high_frequency_limits(data):
    name, (d_P, participation, omega, xi) = data
    block = flexible_appendage(d_P, participation, omega, xi, name=name)
    assert block.nstates == 2 * omega.size
    # block output is -M_P(s) xdd_P
    m_0 = -block.freqresp(np.array([0.0]))[0].real
    np.testing.assert_allclose(m_0, d_P, rtol=1e-10, atol=1e-10)
    m_inf = -block.to_ss().D  # feedthrough = M_P(infinity)
    np.testing.assert_allclose(m_inf, d_P - participation @ participation.T, atol=1e-10)
    # the formula gives the same limits
    np.testing.assert_allclose(
        effective_mass_model(0.0, d_P, participation, omega, xi).real, d_P, atol=1e-10
    )
    np.testing.assert_allclose(
        effective_mass_model(1e9j, d_P, participation, omega, xi), m_inf, atol=1e-4
    )


def test_uncertain_first_mode_matches_formula(data):
    name, (d_P, participation, omega, xi) = data
    w1 = ureal(f"w1_{name}", omega[0], percent=20)
    block = flexible_appendage(d_P, participation, omega, xi, uncertain_frequencies={0: w1})
    assert block.occurrences == {f"w1_{name}": 2}
    assert block.nstates == 2 * omega.size
    shifted = omega.copy()
    shifted[0] *= 1.13
    frequencies = np.array([0.1, omega[0] * 1.13, 3.0, 40.0, 200.0])
    response = -usubs(block, {f"w1_{name}": shifted[0]}).freqresp(frequencies)
    expected = effective_mass_model(1j * frequencies, d_P, participation, shifted, xi)
    np.testing.assert_allclose(response, expected, rtol=1e-9, atol=1e-8)


def test_poles_are_cantilever_modes(data):
    _, (d_P, participation, omega, xi) = data
    block = flexible_appendage(d_P, participation, omega, xi)
    poles = np.sort_complex(np.linalg.eigvals(block.to_ss().A))
    expected = np.concatenate(
        [
            -xi * omega + 1j * omega * np.sqrt(1 - xi**2),
            -xi * omega - 1j * omega * np.sqrt(1 - xi**2),
        ]
    )
    np.testing.assert_allclose(poles, np.sort_complex(expected), rtol=1e-10)


def test_validation_errors():
    d_P, participation, omega, xi = array_data(load_scenario().array_models["SA1_2"])
    with pytest.raises(ValueError, match="SA1: residual mass D_P0 .* not positive semi-definite"):
        check_appendage_data(d_P, participation.T, omega, xi, name="SA1")  # rows/columns swapped
    with pytest.raises(ValueError, match="SA1: need 6 mode frequencies > 0"):
        check_appendage_data(d_P, participation, np.r_[0.0, omega[1:]], xi, name="SA1")
    with pytest.raises(ValueError, match="SA1: damping ratios must be >= 0"):
        check_appendage_data(d_P, participation, omega, -0.01, name="SA1")
    with pytest.raises(ValueError, match="SA1: participation must be 6 x N"):
        check_appendage_data(d_P, participation[:5], omega, xi, name="SA1")
    with pytest.raises(ValueError, match="SA1: uncertain mode index 7"):
        flexible_appendage(
            d_P,
            participation,
            omega,
            xi,
            name="SA1",
            uncertain_frequencies={7: ureal("w", 1.0, percent=1)},
        )
