"""Scenario data file: paper table values, derived inertias, every validation error."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from oos_drake.scenario.data import (
    DEFAULT_SCENARIO_PATH,
    ScenarioError,
    load_scenario,
)
from oos_drake.titop.spatial import rigid_spatial_inertia as spatial_inertia
from oos_drake.titop.spatial import skew

PAPER_TEXT = DEFAULT_SCENARIO_PATH.read_text()


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


# ---------------------------------------------------------------------------------------------
# values of the paper's data table
# ---------------------------------------------------------------------------------------------
def test_paper_table_values(scenario):
    rh1, rh2 = scenario.hubs["RH1"], scenario.hubs["RH2"]
    assert rh1.mass == 188.5
    assert rh1.inertia[0, 1] == 3.84 and rh1.inertia[2, 2] == 42.64
    assert rh2.mass == 24.96 and rh2.mass_uncertainty_percent == 10.0
    np.testing.assert_array_equal(rh2.inertia_uncertainty_percent, [10, 10, 10])
    np.testing.assert_allclose(rh2.mass_range, (22.464, 27.456), rtol=1e-12)
    sa12, sa34 = scenario.array_models["SA1_2"], scenario.array_models["SA3_4"]
    assert sa12.mass == 88.93 and sa34.mass == 11.3497
    np.testing.assert_allclose(sa12.omega[0], 2 * np.pi * 1.2850, rtol=1e-15)
    assert sa12.first_mode_uncertainty_percent == 20.0 and sa34.frequencies_hz[0] == 0.6493
    np.testing.assert_array_equal(sa12.damping_ratios, 0.01)
    # participation rows = modes: mode 1 of SA1,2 is out-of-plane bending (Tz, Rx)
    np.testing.assert_array_equal(sa12.participation[0, 2:4], [7.8872, 11.7690])
    np.testing.assert_array_equal(sa34.participation[1, [0, 5]], [2.8655, -2.9305])
    assert scenario.arrays["SA2"].model is sa12 and scenario.arrays["SA4"].model is sa34
    np.testing.assert_array_equal(scenario.arrays["SA2"].p_G_P, [0, -0.4365, 0])
    np.testing.assert_array_equal(scenario.arm.p_G_J0, [0.6508, 0, -0.4020])
    masses = [link.mass for link in scenario.arm.links]
    assert masses == [4, 3.7, 8.393, 2.275, 1.219, 1.219, 0.1879]
    assert scenario.arm.links[2].p_J_G[0] == 0.28 and scenario.arm.links[3].p_J_G[0] == 0.25
    np.testing.assert_allclose(scenario.arm.total_mass, 20.9939, rtol=1e-12)
    assert scenario.docking.damping == 100.0
    assert (
        scenario.docking.stiffness_sweep[0] == 0.1 and scenario.docking.stiffness_sweep[-1] == 1e5
    )


def test_arm_geometry_is_ur5(scenario):
    """Offsets J_i -> J_i+1 reproduce the UR5 DH lengths (d1, a2, a3, d4, d5, d6)."""
    offsets = np.array([link.p_J_Jnext for link in scenario.arm.links])
    assert offsets[0, 2] == 0.089159  # d1
    assert offsets[2, 0] == 0.425 and offsets[3, 0] == 0.39225  # a2, a3 along link x
    np.testing.assert_allclose(offsets[1, 1] + offsets[2, 1] + offsets[4, 1], 0.10915, atol=1e-15)
    assert offsets[5, 2] == -0.09465 and offsets[6, 1] == 0.0823  # d5, d6


def test_rigid_spatial_inertia_closed_form(scenario):
    """D_P of SA1,2 against the hand-written parallel-axis matrix (S = P + [0, y, z])."""
    model = scenario.array_models["SA1_2"]
    m, (x, y, z), J = model.mass, model.p_P_S, model.inertia
    assert x == 0
    expected = np.zeros((6, 6))
    expected[:3, :3] = m * np.eye(3)
    # force = m (a_P + wdot x PS):  d F / d wdot = -m skew(PS)
    expected[:3, 3:] = -m * np.array([[0, -z, y], [z, 0, 0], [-y, 0, 0]])
    expected[3:, :3] = expected[:3, 3:].T
    expected[3:, 3:] = J + m * np.array(
        [[y * y + z * z, 0, 0], [0, z * z, -y * z], [0, -y * z, y * y]]
    )
    np.testing.assert_allclose(model.rigid_spatial_inertia, expected, rtol=1e-14, atol=1e-12)


def test_spatial_inertia_is_parallel_axis():
    rng = np.random.default_rng(7)
    r = rng.normal(size=3)
    A = rng.normal(size=(3, 3))
    J = A @ A.T + np.eye(3)
    D = spatial_inertia(2.5, J, r)
    np.testing.assert_allclose(
        D[3:, 3:], J + 2.5 * (r @ r * np.eye(3) - np.outer(r, r)), rtol=1e-13
    )
    np.testing.assert_allclose(D[:3, 3:], -2.5 * skew(r), rtol=1e-13)
    np.testing.assert_allclose(D, D.T, atol=1e-13)


def test_residual_mass_rows_are_modes(scenario):
    """Rows = modes gives D_P0 >= 0; the printed columns-as-modes reading is unphysical."""
    for name, worst in (("SA1_2", -140.0), ("SA3_4", -10.55)):
        model = scenario.array_models[name]
        assert np.linalg.eigvalsh(model.residual_mass)[0] > 0
        L = model.participation
        wrong = model.rigid_spatial_inertia - L @ L.T
        assert np.linalg.eigvalsh(wrong)[0] == pytest.approx(worst, abs=0.01)


def test_scenario_is_immutable(scenario):
    with pytest.raises(dataclasses.FrozenInstanceError):
        scenario.hubs["RH1"].mass = 1.0
    with pytest.raises(ValueError):
        scenario.hubs["RH1"].inertia[0, 0] = 1.0
    with pytest.raises(TypeError):
        scenario.hubs["RH3"] = scenario.hubs["RH1"]
    assert load_scenario() is scenario  # cached per file version


def test_rotations_and_axes_are_valid(scenario):
    matrices = [scenario.arm.R_G_L0] + [a.R_G_P0 for a in scenario.arrays.values()]
    matrices += [p.R_G_D for p in scenario.ports.values()]
    for R in matrices:
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
        assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(np.linalg.norm(scenario.arm.joint_axes, axis=1), 1.0)


# ---------------------------------------------------------------------------------------------
# validation errors: small modified copies of the data file
# ---------------------------------------------------------------------------------------------
SA12_ROWS = """  [-0.0007, -0.0078, 7.8872, 11.7690, 0.0005, 0.0010],
  [-7.9401, 0.0, 0.0007, -0.0008, 0.1089, 12.1014],
  [-0.3604, 0.0, 0.0006, 0.0017, -2.6631, 0.5399],
  [0.0019, -0.0066, 3.9818, 0.9098, -0.0007, -0.0033],
  [0.0272, 0.0003, -0.0145, -0.0019, 0.4907, -0.0221],
  [-0.0010, 0.0357, -2.2185, -0.2320, -0.0029, 0.0012],"""


def _transposed_rows() -> str:
    rows = np.array(
        [[float(v) for v in line.strip(" [],").split(",")] for line in SA12_ROWS.splitlines()]
    )
    return "\n".join("  [" + ", ".join(repr(float(v)) for v in row) + "]," for row in rows.T)


ERROR_CASES = [
    # (id, old text, new text, regex of the message)
    ("mass", "mass = 188.5 ", "mass = -188.5 ", r"^RH1: mass must be > 0, got -188\.5$"),
    (
        "inertia-pd",
        "inertia = [[2.684, 0.058, 0.054],",
        "inertia = [[-2.684, 0.058, 0.054],",
        r"^RH2: inertia not positive definite \(min eigenvalue -2\.6",
    ),
    (
        "inertia-symmetric",
        "[3.84, 43.89, 0.0],",
        "[3.85, 43.89, 0.0],",
        r"^RH1: inertia not symmetric",
    ),
    (
        "triangle",
        "[0.0, 0.0, 2.2968]]",
        "[0.0, 0.0, 2.5]]",
        r"^SA3_4: inertia at S violates the triangle inequality "
        r"\(principal moments 0\.3404 \+ 1\.957 < 2\.5\)$",
    ),
    (
        "uncertainty-corner",
        "inertia_uncertainty_percent = [10.0, 10.0, 10.0]",
        "inertia_uncertainty_percent = [60.0, 60.0, 60.0]",
        r"^RH2: inertia at uncertainty corner \(-, -, \+\) violates the triangle inequality",
    ),
    (
        "residual-mass",
        SA12_ROWS,
        _transposed_rows(),
        r"^SA1_2: residual mass D_P0 not positive semi-definite \(min eigenvalue -140\)$",
    ),
    (
        "damping",
        "damping_ratios = [0.01, 0.01, 0.01, 0.01, 0.01, 0.01]                # [-]",
        "damping_ratios = [0.01, -0.02, 0.01, 0.01, 0.01, 0.01]",
        r"^SA1_2: damping ratio must be >= 0, got -0\.02$",
    ),
    (
        "damping-length",
        "damping_ratios = [0.01, 0.01, 0.01, 0.01, 0.01, 0.01]                # [-]",
        "damping_ratios = [0.01, 0.01]",
        r"^SA1_2: damping_ratios has 2 entries for 6 modes$",
    ),
    (
        "frequency",
        "frequencies_hz = [0.6493,",
        "frequencies_hz = [0.0,",
        r"^SA3_4: modal frequency must be > 0, got 0 Hz$",
    ),
    (
        "percent-negative",
        "mass_uncertainty_percent = 10.0 ",
        "mass_uncertainty_percent = -5.0 ",
        r"^RH2: mass uncertainty must be >= 0 %, got -5 %$",
    ),
    (
        "percent-100",
        "first_mode_uncertainty_percent = 20.0          # paper",
        "first_mode_uncertainty_percent = 100.0          # paper",
        r"^SA1_2: first-mode frequency uncertainty must be < 100 %, got 100 %$",
    ),
    (
        "participation-shape",
        "  [-0.0010, 0.0357, -2.2185, -0.2320, -0.0029, 0.0012],\n",
        "",
        r"^SA1_2: participation matrix must be 6x6 \(rows = modes, columns = DOF\), got 5x6$",
    ),
    (
        "participation-width",
        "[0.0008, 0.0001, -0.0007, 0.0, 0.0596, -0.0009],",
        "[0.0008, 0.0001, -0.0007, 0.0, 0.0596],",
        r"^SA3_4: participation must be numeric",
    ),
    (
        "unknown-key",
        "mass = 188.5 ",
        "masss = 188.5 ",
        r"^RH1: unknown key 'masss' \(did you mean 'mass'\?\)$",
    ),
    (
        "unknown-extra-key",
        'description = "chaser rigid hub;',
        'colour = "gold"\ndescription = "chaser rigid hub;',
        r"^RH1: unknown key 'colour' \(allowed: ",
    ),
    (
        "unknown-section",
        "schema_version = 1\n",
        "schema_version = 1\nmagic = 3\n",
        r"^paper\.toml: unknown key 'magic'",
    ),
    (
        "rotation",
        "R_G_P0 = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]   # half turn about z_RH1",
        "R_G_P0 = [[-1.0, 0.0, 0.0], [0.0, -0.9, 0.0], [0.0, 0.0, 1.0]]",
        r"^SA2: R_G_P0 not orthonormal",
    ),
    (
        "reflection",
        "R_G_P0 = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]   # half turn about z_RH1",
        "R_G_P0 = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
        r"^SA2: R_G_P0 is a reflection",
    ),
    (
        "joint-axis",
        "joint_axis = [0.0, 1.0, 0.0]                   # elbow, alpha_3",
        "joint_axis = [0.0, 2.0, 0.0]",
        r"^arm link L3: joint axis must be a unit vector, got norm 2$",
    ),
    (
        "link-mass",
        "mass = 2.275",
        "mass = 0.0",
        r"^arm link L3: mass must be > 0, got 0$",
    ),
    (
        "angle-range",
        "  [3.141592653589793, 0.0, 0.0, -1.5707963267948966, 0.0, 0.0],\n",
        "  [3.5, 0.0, 0.0, -1.5707963267948966, 0.0, 0.0],\n",
        r"^mission\.arm_waypoints: alpha out of \[-pi, pi\] \(tau = tan\(angle/4\)\): 3\.5$",
    ),
    (
        "waypoint-times",
        "times = [0.0, 100.0, 160.0, 200.0, 255.0, 880.0, 940.0, 1050.0, 1500.0]",
        "times = [0.0, 100.0, 160.0, 200.0, 255.0, 880.0, 1050.0, 940.0, 1500.0]",
        r"^mission\.arm_waypoints: waypoint times must be strictly increasing$",
    ),
    (
        "labels-count",
        '"retreat", "parked", "parked"]',
        '"retreat", "parked"]',
        r"^mission\.arm_waypoints: 8 labels for 9 waypoints$",
    ),
    (
        "labels-docking",
        '"grasp", "docked", "retreat"',
        '"grasp", "closed-loop", "retreat"',
        r"^mission\.arm_waypoints: needs a waypoint labelled 'docked' at t = 880 s$",
    ),
    (
        "approach-distance",
        "grasp_approach_distance = 0.15 ",
        "grasp_approach_distance = -0.15 ",
        r"^mission: grasp_approach_distance must be >= 0, got -0\.15$",
    ),
    (
        "loop-closure",
        "p_G_D = [0.0, 0.0, -0.4020]                    # [m] G1 -> D1",
        "p_G_D = [0.0, 0.05, -0.4020]  # [m] G1 -> D1",
        r"^mission\.arm_waypoints: waypoint 'pre-grasp' misses its arm-tip pose by 0\.05 "
        r"\(m or rad\); re-solve it with oos_drake\.scenario\.kinematics\.waypoint_ik$",
    ),
    (
        "both-switches",
        "start = 880.0\nend = 1500.0\ndelta_C1 = 0.0",
        "start = 880.0\nend = 1500.0\ndelta_C1 = 1.0",
        r"^mission\.connection_states\[2\]: delta_C1 and delta_C2 cannot both be 1$",
    ),
    (
        "event-order",
        "tilt_start_time = 1100.0",
        "tilt_start_time = 700.0",
        r"^mission: event times must satisfy",
    ),
    (
        "port-body",
        'body = "RH2"\n# CHOICE: the fixture',
        'body = "RH1"\n# CHOICE: the fixture',
        r"^port D2: must be on 'RH2', got 'RH1'$",
    ),
    (
        "toml-syntax",
        "schema_version = 1\n",
        "schema_version = = 1\n",
        r"^paper\.toml: invalid TOML",
    ),
    ("type", "mass = 88.93 ", 'mass = "heavy" ', r"^SA1_2: mass must be a number, got 'heavy'$"),
    ("missing", "p_P_S = [0.0, 0.7446, 0.0]", "", r"^SA3_4: missing key 'p_P_S'$"),
]


@pytest.mark.parametrize(
    ("old", "new", "pattern"), [c[1:] for c in ERROR_CASES], ids=[c[0] for c in ERROR_CASES]
)
def test_validation_errors(tmp_path, old, new, pattern):
    assert PAPER_TEXT.count(old) == 1, f"test fixture text not unique in paper.toml: {old!r}"
    path = tmp_path / "paper.toml"
    path.write_text(PAPER_TEXT.replace(old, new))
    with pytest.raises(ScenarioError, match=pattern) as info:
        load_scenario(path)
    message = str(info.value)
    assert "\n" not in message
    assert isinstance(info.value, ValueError)
    assert message.startswith(info.value.body + ": ")


def test_unmodified_copy_loads(tmp_path):
    path = tmp_path / "copy.toml"
    path.write_text(PAPER_TEXT)
    copy = load_scenario(path)
    assert copy.source == path.resolve()
    np.testing.assert_array_equal(
        copy.array_models["SA3_4"].participation,
        load_scenario().array_models["SA3_4"].participation,
    )
