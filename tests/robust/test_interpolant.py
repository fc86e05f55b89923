"""Stable interpolants of worst complex perturbations (MATLAB ``wcu``'s all-pass sections)."""

import control
import numpy as np
import pytest

from oos_drake.robust.interpolant import lti_interpolant

VALUES = [2 + 1j, 2 - 1j, -2 + 1j, -2 - 1j, 3.0, -3.0, 0.5j, -0.5j]


def _peak_gain(G, dt=None) -> float:
    """Largest singular value over a dense grid (and at 0, the all-pass's other extreme)."""
    omegas = np.concatenate([[0.0], np.logspace(-4, 3, 3000)])
    if dt is not None:
        omegas = omegas[omegas < np.pi / dt]
    points = 1j * omegas if dt is None else np.exp(1j * omegas * dt)
    return max(np.linalg.norm(np.atleast_2d(G(z)), 2) for z in points)


@pytest.mark.parametrize("value", VALUES)
def test_scalar_takes_the_value_is_stable_and_all_pass(value):
    omega = 1.3
    G = lti_interpolant(value, omega)
    assert complex(G(1j * omega)) == pytest.approx(value, abs=1e-12)
    assert np.all(np.linalg.eigvals(G.A).real < 0) if G.nstates else True
    assert _peak_gain(G) == pytest.approx(abs(value), rel=1e-9)


def test_rank_one_matrix_keeps_its_norm_on_the_whole_axis():
    rng = np.random.default_rng(3)
    u = rng.standard_normal(3) + 1j * rng.standard_normal(3)
    v = rng.standard_normal(2) + 1j * rng.standard_normal(2)
    value = 2.5 * np.outer(u, v.conj()) / (np.linalg.norm(u) * np.linalg.norm(v))
    omega = 5.18
    G = lti_interpolant(value, omega)
    np.testing.assert_allclose(G(1j * omega), value, atol=1e-12)
    assert np.linalg.eigvals(G.A).real.max() < 0
    # a second method for the H-infinity norm: the Hamiltonian bisection of python-control
    assert control.linfnorm(G)[0] == pytest.approx(2.5, rel=1e-6)


def test_discrete_interpolant_takes_the_value_on_the_unit_circle():
    rng = np.random.default_rng(4)
    value = np.outer(rng.standard_normal(3) + 1j, rng.standard_normal(3) - 2j)
    omega, dt = 5.1, 0.1
    G = lti_interpolant(value, omega, dt=dt)
    assert G.dt == dt
    np.testing.assert_allclose(G(np.exp(1j * omega * dt)), value, atol=1e-12)
    assert np.abs(np.linalg.eigvals(G.A)).max() < 1
    assert _peak_gain(G, dt) == pytest.approx(np.linalg.norm(value, 2), rel=1e-9)


def test_static_cases_and_bad_input():
    G = lti_interpolant(np.array([[1.5, -2.0]]), np.inf)
    assert G.nstates == 0
    np.testing.assert_array_equal(G.D, [[1.5, -2.0]])
    with pytest.raises(ValueError, match="must be real"):
        lti_interpolant(1 + 1j, np.inf)
    with pytest.raises(ValueError, match="Nyquist"):
        lti_interpolant(1 + 1j, 40.0, dt=0.1)
    with pytest.raises(ValueError, match="omega"):
        lti_interpolant(1 + 1j, -1.0)


def test_worst_case_realization_of_a_dynamic_block():
    """``realize_complex_matrix`` (the ultidyn worst case of robstab/wcgain/the analysis): the
    dominant singular pair of the value at ``omega``, a norm equal to the value's on the whole
    axis, and a real gain at ``omega = 0``; checked by evaluating the systems directly."""
    from oos_drake.robust.lfr_analysis import realize_complex_matrix

    rng = np.random.default_rng(3)
    u, v = (
        rng.normal(size=2) + 1j * rng.normal(size=2),
        rng.normal(size=3) + 1j * rng.normal(size=3),
    )
    rank_one = np.outer(u, v)
    G = realize_complex_matrix(rank_one, 0.7)
    np.testing.assert_allclose(G(0.7j), rank_one, atol=1e-12)
    assert np.all(np.linalg.eigvals(G.A).real < 0)
    assert _peak_gain(G) == pytest.approx(np.linalg.norm(rank_one, 2), rel=1e-9)
    full = rank_one + 0.3 * np.outer(rng.normal(size=2), rng.normal(size=3))
    U, S, Vh = np.linalg.svd(full)
    np.testing.assert_allclose(
        realize_complex_matrix(full, 2.0)(2.0j), S[0] * np.outer(U[:, 0], Vh[0]), atol=1e-12
    )
    real = np.outer([1.0, -2.0], [0.5, 1.0, 3.0])
    np.testing.assert_allclose(realize_complex_matrix(real, 0.0).D, real, atol=1e-12)
