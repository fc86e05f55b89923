"""Multi-port rigid body, inverted port and rigid link against closed forms and a numeric invio."""

import numpy as np
import pytest

from oos_drake.lfr import ureal, usubs
from oos_drake.titop import (
    connection_parameter,
    rigid_body_direct,
    rigid_body_inverse,
    rigid_link,
    uncertain_inertia,
    uncertain_mass,
)
from oos_drake.titop.spatial import kinematic_matrix, rigid_spatial_inertia

MASS = 24.96
INERTIA = np.array([[2.684, 0.058, 0.054], [0.058, 2.012, -0.104], [0.054, -0.104, 2.32]])
PORTS = [np.array([0.0, 0.3395, 0.0]), np.array([0.0, -0.3395, 0.0]), np.array([0.3, 0.1, -0.2])]


def static_gain(system):
    return system.freqresp(np.array([0.0]))[..., 0, :, :].real


def d_G(mass, inertia):
    d = np.zeros((6, 6))
    d[:3, :3] = mass * np.eye(3)
    d[3:, 3:] = inertia
    return d


def inverse_closed_form(mass, inertia, ports):
    """xdd_G = D_G^-1 (W_ext + sum tau^T W_i), xdd_i = tau_{P_i G} xdd_G (numpy)."""
    taus = [kinematic_matrix(-p) for p in ports]
    gather = np.hstack([np.eye(6)] + [t.T for t in taus])
    spread = np.vstack([np.eye(6)] + taus)
    return spread @ np.linalg.inv(d_G(mass, inertia)) @ gather


def invio(matrix, channels):
    """Partial inversion of a static map (MATLAB invio): swap input/output of ``channels``."""
    keep = np.setdiff1d(np.arange(matrix.shape[0]), channels)
    m11 = matrix[np.ix_(keep, keep)]
    m12 = matrix[np.ix_(keep, channels)]
    m21 = matrix[np.ix_(channels, keep)]
    m22i = np.linalg.inv(matrix[np.ix_(channels, channels)])
    out = np.zeros_like(matrix)
    out[np.ix_(keep, keep)] = m11 - m12 @ m22i @ m21
    out[np.ix_(keep, channels)] = m12 @ m22i
    out[np.ix_(channels, keep)] = -m22i @ m21
    out[np.ix_(channels, channels)] = m22i
    return out


def uncertain_hub():
    mass = uncertain_mass("RH2", MASS, 10.0)
    inertia = uncertain_inertia("RH2", INERTIA, [10.0, 10.0, 10.0])
    return mass, inertia


def test_inverse_model_matches_closed_form_and_counts():
    mass, inertia = uncertain_hub()
    model = rigid_body_inverse(mass, inertia, PORTS, body="RH2")
    assert model.shape == (24, 24)
    assert model.occurrences == {"Jxx_RH2": 1, "Jyy_RH2": 1, "Jzz_RH2": 1, "m_RH2": 3}
    values = {"m_RH2": 26.0, "Jxx_RH2": 2.5, "Jyy_RH2": 2.2, "Jzz_RH2": 2.4}
    inertia_value = INERTIA.copy()
    np.fill_diagonal(inertia_value, [2.5, 2.2, 2.4])
    np.testing.assert_allclose(
        static_gain(usubs(model, values)),
        inverse_closed_form(26.0, inertia_value, PORTS),
        rtol=1e-11,
        atol=1e-13,
    )


def test_direct_model_equals_numeric_partial_inversion_of_inverse_model():
    mass, inertia = uncertain_hub()
    parent = np.array([0.3395, 0.0, 0.0])
    direct = rigid_body_direct(mass, inertia, PORTS[:2], parent, external=True, body="RH2")
    assert direct.occurrences == {"Jxx_RH2": 1, "Jyy_RH2": 1, "Jzz_RH2": 1, "m_RH2": 3}
    values = {"m_RH2": 23.0, "Jxx_RH2": 2.8, "Jyy_RH2": 1.9, "Jzz_RH2": 2.2}
    inertia_value = INERTIA.copy()
    np.fill_diagonal(inertia_value, [2.8, 1.9, 2.2])
    inverse = inverse_closed_form(23.0, inertia_value, PORTS[:2] + [parent])
    inverted = invio(inverse, np.arange(18, 24))
    inverted[18:, :] *= -1.0  # TITOP convention: wrench applied BY the body to its parent
    np.testing.assert_allclose(static_gain(usubs(direct, values)), inverted, rtol=1e-10, atol=1e-12)


def test_shared_inverted_port_of_rh2_has_paper_counts_and_switches_position():
    mass, inertia = uncertain_hub()
    d1, d2 = connection_parameter("delta_C1"), connection_parameter("delta_C2")
    g2d2, g2d3 = np.array([0.3395, 0.0, 0.0]), np.array([0.0, 0.0, 0.3395])
    model = rigid_body_direct(
        mass, inertia, PORTS[:2], np.zeros(3), parent_terms=[(d1, g2d2), (d2, g2d3)], body="RH2"
    )
    # Delta_RH2 = diag(delta_m I3, dJxx, dJyy, dJzz, delta_C1 I4, delta_C2 I4)
    assert model.occurrences == {
        "Jxx_RH2": 1,
        "Jyy_RH2": 1,
        "Jzz_RH2": 1,
        "m_RH2": 3,
        "delta_C1": 4,
        "delta_C2": 4,
    }
    for c1, c2, position in [(1.0, 0.0, g2d2), (0.0, 1.0, g2d3), (0.0, 0.0, np.zeros(3))]:
        value = static_gain(
            usubs(
                model,
                {
                    "delta_C1": c1,
                    "delta_C2": c2,
                    "m_RH2": MASS,
                    "Jxx_RH2": INERTIA[0, 0],
                    "Jyy_RH2": INERTIA[1, 1],
                    "Jzz_RH2": INERTIA[2, 2],
                },
            )
        )
        full = inverse_closed_form(MASS, INERTIA, PORTS[:2] + [position])
        reference = invio(full, np.arange(18, 24))
        reference = reference[6:, 6:]  # drop the external wrench channel
        reference[12:, :] *= -1.0
        np.testing.assert_allclose(value, reference, rtol=1e-10, atol=1e-12)


def test_rigid_link_is_titop_two_port():
    mass = 8.393
    inertia = np.diag([0.0152, 0.2269, 0.2269])
    p_JG = np.array([0.28, 0.0, 0.0])
    p_JJ = np.array([0.425, -0.1197, 0.0])
    link = rigid_link(mass, inertia, -p_JG, p_JJ - p_JG)
    tau_CP = kinematic_matrix(-p_JJ)  # vector C -> P
    d_P = rigid_spatial_inertia(mass, inertia, p_JG)
    expected = np.block([[np.zeros((6, 6)), tau_CP], [tau_CP.T, -d_P]])
    np.testing.assert_allclose(static_gain(link), expected, atol=1e-13)


def test_rigid_body_validation_errors():
    with pytest.raises(ValueError, match="RH9: mass must be > 0"):
        rigid_body_inverse(-1.0, INERTIA, PORTS, body="RH9")
    with pytest.raises(ValueError, match="positive definite"):
        rigid_body_inverse(1.0, -INERTIA, PORTS, body="RH9")
    with pytest.raises(ValueError, match="port 0 position"):
        rigid_body_inverse(1.0, INERTIA, [[0.0, 1.0]], body="RH9")
    with pytest.raises(ValueError, match="percent must be >= 0"):
        uncertain_mass("RH9", 1.0, -5.0)
    with pytest.raises(ValueError, match="mass must be a float or a 1x1 LFR"):
        rigid_body_inverse(ureal("a", 1.0, percent=1) * np.ones((1, 2)), INERTIA, PORTS)


def test_invert_channels_turns_inverse_model_into_direct_model():
    from oos_drake.titop.inversion import invert_channels

    mass, inertia = uncertain_hub()
    parent = np.array([0.3395, 0.0, 0.0])
    inverse = rigid_body_inverse(mass, inertia, PORTS[:2] + [parent], body="RH2")
    inverted = invert_channels(inverse, np.arange(18, 24))
    assert inverted.occurrences == inverse.occurrences  # no new occurrences
    direct = rigid_body_direct(mass, inertia, PORTS[:2], parent, external=True, body="RH2")
    values = {"m_RH2": 22.9, "Jxx_RH2": 2.5, "Jyy_RH2": 2.1, "Jzz_RH2": 2.5}
    got = static_gain(usubs(inverted, values))
    got[18:, :] *= -1.0  # wrench applied by the body to its parent
    np.testing.assert_allclose(got, static_gain(usubs(direct, values)), rtol=1e-10, atol=1e-12)
    # inverting twice gives the original model back
    twice = invert_channels(inverted, np.arange(18, 24))
    np.testing.assert_allclose(
        static_gain(usubs(twice, values)), static_gain(usubs(inverse, values)), atol=1e-12
    )
    with pytest.raises(ValueError, match="out of 0..23"):
        invert_channels(inverse, [24])
    with pytest.raises(ValueError, match="singular"):
        invert_channels(rigid_link(1.0, np.eye(3), [0, 0, 0], [1.0, 0, 0]), np.arange(6))
