"""Destabilizing perturbations on loops with known stability margins (closed forms)."""

import control
import numpy as np
import pytest
from peak_oracle import certify_peak  # tests/analysis is on sys.path (rootdir imports)

from oos_drake.analysis.destabilizing import destabilizing_perturbation
from oos_drake.lfr import feedback, ultidyn, ureal, usubs


def _parts(sys):
    return (np.asarray(sys.A), np.asarray(sys.Bw), np.asarray(sys.Cz), np.asarray(sys.Dzw))


def test_real_gain_margin_closed_form():
    """k/(s+1)(s+2)(s+3) with k = 40 +- 10: unstable at k = 60 (delta = 2), omega = sqrt(11)."""
    k = ureal("k", 40.0, plusminus=10.0)
    loop = feedback(k * control.tf(1, [1, 6, 11, 6]), 1)
    A, Bw, Cz, Dzw = _parts(loop)
    d = destabilizing_perturbation(A, Bw, Cz, Dzw, loop.blk, [1.0, 10.0])
    np.testing.assert_allclose(d.mu_lower, 0.5, rtol=1e-6)
    np.testing.assert_allclose(d.omega, np.sqrt(11.0), rtol=1e-5)
    assert d.residual < 1e-6


def test_complex_block_small_gain_closed_form():
    """Loop 1/(s+1) with Delta of bound b in feedback: mu = sup |G| b = b (at omega = 0)."""
    delta = ultidyn("D", (1, 1), bound=0.5)
    loop = feedback(control.tf(1, [1, 1]), delta, sign=1)
    A, Bw, Cz, Dzw = _parts(loop)
    d = destabilizing_perturbation(A, Bw, Cz, Dzw, loop.blk, [1e-3, 10.0])
    # |G(j w)| = 1/sqrt(1+w^2) peaks at w -> 0: mu(w) = 0.5/sqrt(1 + w^2)
    np.testing.assert_allclose(d.mu_lower, 0.5 / np.sqrt(1 + d.omega**2), rtol=1e-6)
    assert d.mu_lower > 0.49


def test_certified_peak_brackets_and_destabilizes():
    """Bounds within 5 %, and the perturbation puts a pole at j omega (checked with usubs)."""
    k = ureal("k", 40.0, plusminus=10.0)
    loop = feedback(k * control.tf(1, [1, 6, 11, 6]), 1)
    cert = certify_peak(loop, "k", ["k"], 0, np.sqrt(11) / (2 * np.pi))
    assert cert.mu_lower <= cert.mu_upper * (1 + 1e-9)
    assert cert.gap < 0.05
    value = cert.worst_case["k"]
    np.testing.assert_allclose(value, 60.0, rtol=1e-5)
    # beyond the modeled range (mu < 1): substitute the normalized value
    closed = usubs(loop, {"k": cert.worst_case_normalized["k"]}, normalized=True)
    poles = np.linalg.eigvals(np.asarray(closed.A))
    w = 2 * np.pi * cert.frequency
    assert np.min(np.abs(poles - 1j * w)) < 1e-4 * w


def test_a_mass_driven_to_zero_is_an_ill_posed_crossing_at_infinite_frequency():
    """m x'' = -k x - c x' with m = m0 (1 + 0.5 delta): the loop is stable for every m > 0 and
    ill-posed at delta = -2 (m = 0), where a pole leaves through infinity: mu = 1/2 exactly, at
    omega = inf (not a crossing of the imaginary axis at 0 Hz)."""
    from oos_drake.analysis.destabilizing import destabilizing_perturbation, ill_posed_perturbation

    m0, k, c = 2.0, 3.0, 0.4
    A = np.array([[0.0, 1.0], [-k / m0, -c / m0]])
    Bw = np.array([[0.0], [-0.5]])
    Cz = np.array([[-k / m0, -c / m0]])
    Dzw = np.array([[-0.5]])
    found = destabilizing_perturbation(A, Bw, Cz, Dzw, [[-1, 0]], [0.1, 10.0])
    assert found.mu_lower == pytest.approx(0.5, rel=1e-6)
    assert np.isinf(found.omega)
    assert found.residual < 1e-6
    exact = ill_posed_perturbation(Dzw, [[-1, 0]])
    assert exact.mu_lower == pytest.approx(0.5, rel=1e-12) and np.isinf(exact.omega)
    assert exact.delta[0, 0].real == pytest.approx(-2.0, rel=1e-12)


@pytest.mark.parametrize(
    "Dzw, blk, mu",
    [
        (np.diag([0.5, -0.25]), [[-1, 0], [-1, 0]], 0.5),  # diagonal: max |entry|
        (np.array([[0.0, 0.8], [0.2, 0.0]]), [[-1, 0], [-1, 0]], 0.4),  # sqrt(|a b|)
        (np.array([[0.0, 0.8], [-0.2, 0.0]]), [[-1, 0], [-1, 0]], 0.4),  # sign of a b: vertex
    ],
)
def test_ill_posing_vertex_matches_the_closed_form_real_mu(Dzw, blk, mu):
    from oos_drake.analysis.destabilizing import ill_posed_perturbation

    found = ill_posed_perturbation(Dzw, blk)
    assert found.mu_lower == pytest.approx(mu, rel=1e-12)
    delta = found.delta
    assert np.linalg.svd(np.eye(2) - Dzw @ delta, compute_uv=False)[-1] < 1e-12
