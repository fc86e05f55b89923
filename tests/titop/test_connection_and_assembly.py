"""Switches, spring-dampers and the signal-name assembly (hub + array) against closed forms."""

import numpy as np
import pytest
from appendage_oracle import effective_mass_model  # tests/ is on sys.path
from scipy.spatial.transform import Rotation

from oos_drake.lfr import as_lfr, usubs
from oos_drake.scenario.data import load_scenario
from oos_drake.titop import (
    Component,
    angle_parameter,
    assemble,
    flexible_appendage,
    rigid_body_inverse,
    rotation_frame_change,
    spring_damper,
    spring_damper_parameters,
)
from oos_drake.titop.spatial import frame_change_matrix, kinematic_matrix, rigid_spatial_inertia

HUB_MASS = 188.5
HUB_INERTIA = np.array([[41.98, 3.84, 0.0], [3.84, 43.89, 0.0], [0.0, 0.0, 42.64]])
P_G_P = np.array([0.0, 0.4365, 0.0])


def test_spring_damper_matches_closed_form():
    blocks = spring_damper_parameters("SM1")
    system = spring_damper(blocks["k_shear"], blocks["k_tors"], blocks["d_shear"], blocks["d_tors"])
    assert system.occurrences == {
        "d_shear_SM1": 3,
        "d_tors_SM1": 3,
        "k_shear_SM1": 3,
        "k_tors_SM1": 3,
    }
    assert system.nstates == 12
    values = {"k_shear_SM1": 2.5e3, "k_tors_SM1": 40.0, "d_shear_SM1": 100.0, "d_tors_SM1": 7.0}
    omega = np.array([0.05, 1.0, 30.0])
    response = usubs(system, values).freqresp(omega)
    k = np.diag([2.5e3] * 3 + [40.0] * 3)
    d = np.diag([100.0] * 3 + [7.0] * 3)
    for f, s in enumerate(1j * omega):
        h = (k + d * s) / s**2
        expected = np.block([[-h, h], [h, -h]])
        np.testing.assert_allclose(response[f], expected, rtol=1e-10, atol=1e-12)
    with pytest.raises(ValueError, match="k_shear must be >= 0"):
        spring_damper(-1.0, 1.0, 1.0, 1.0)


def hub_with_array(theta_block, data):
    d_P = rigid_spatial_inertia(data.mass, data.inertia, data.p_P_S)
    appendage = flexible_appendage(
        d_P, np.asarray(data.participation).T, data.omega, data.damping_ratios
    )
    axis = [0.0, 1.0, 0.0]
    array = (
        rotation_frame_change(theta_block, axis, transpose=True)
        @ appendage
        @ rotation_frame_change(theta_block, axis)
    )
    components = [
        Component(
            "hub",
            rigid_body_inverse(HUB_MASS, HUB_INERTIA, [P_G_P]),
            ("W_ext", "W_P"),
            ("xdd_G", "xdd_P"),
        ),
        Component("array", array, ("xdd_P",), ("W_P",)),
    ]
    return assemble(components, ["W_ext"], ["xdd_G"]), d_P


def test_hub_plus_array_equals_closed_form_and_antiresonances_at_cantilever_modes():
    data = load_scenario().array_models["SA1_2"]
    tau = angle_parameter("tau_theta1")
    model, d_P = hub_with_array(tau, data)
    assert model.occurrences == {"tau_theta1": 16}
    theta = 0.7
    fixed = usubs(model, {"tau_theta1": np.tan(theta / 4)})
    omega = np.array([0.0, 2.0, 8.07, 40.0])
    response = fixed.freqresp(omega)
    dcm = Rotation.from_rotvec([0.0, theta, 0.0]).as_matrix().T
    t = frame_change_matrix(dcm)
    tau_PG = kinematic_matrix(-P_G_P)
    d_hub = np.diag([HUB_MASS] * 3 + [0.0] * 3)
    d_hub[3:, 3:] = HUB_INERTIA
    participation = np.asarray(data.participation).T
    for f, w in enumerate(omega):
        m_P = effective_mass_model(1j * w, d_P, participation, data.omega, data.damping_ratios)
        expected = np.linalg.inv(d_hub + tau_PG.T @ t.T @ m_P @ t @ tau_PG)
        np.testing.assert_allclose(response[f], expected, rtol=1e-9, atol=1e-13)
    # anti-resonances: the zeros of xdd_G(s) = M(s)^-1 W are the poles of M(s), i.e. the
    # cantilevered modes of the array (eigenvalues of the inverse system A - B D^-1 C)
    ss = fixed.to_ss()
    zeros = np.linalg.eigvals(ss.A - ss.B @ np.linalg.solve(ss.D, ss.C))
    xi, w = np.asarray(data.damping_ratios), np.asarray(data.omega)
    cantilever = np.concatenate(
        [-xi * w + 1j * w * np.sqrt(1 - xi**2), -xi * w - 1j * w * np.sqrt(1 - xi**2)]
    )
    np.testing.assert_allclose(np.sort_complex(zeros), np.sort_complex(cantilever), rtol=1e-8)
    # and the coupled resonances lie above them (added hub flexibility raises the frequencies)
    poles = np.linalg.eigvals(ss.A)
    assert np.min(np.abs(poles)) > np.min(w)


def test_assembly_errors_name_the_signal():
    gain = as_lfr(np.eye(6))
    with pytest.raises(ValueError, match="signal 'y' is produced twice"):
        assemble(
            [Component("a", gain, ("u",), ("y",)), Component("b", gain, ("y",), ("y",))],
            ["u"],
            ["y"],
        )
    with pytest.raises(ValueError, match="input signal 'v' is neither"):
        assemble([Component("a", gain, ("v",), ("y",))], ["u"], ["y"])
    with pytest.raises(ValueError, match="output signal 'z' is not produced"):
        assemble([Component("a", gain, ("u",), ("y",))], ["u"], ["z"])
    with pytest.raises(ValueError, match="component 'a': system shape"):
        Component("a", as_lfr(np.eye(5)), ("u",), ("y",))
