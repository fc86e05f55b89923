"""Exact modal realization of a flexible array: algebra, and Drake vs the closed form M_P(s)."""

import numpy as np
import pytest

from oos_drake.multibody.modal_realization import (
    is_physical_spatial_inertia,
    realize_appendage,
    realize_mode,
)
from oos_drake.scenario.data import load_scenario

SCENARIO = load_scenario()
ARRAY_MODELS = sorted(SCENARIO.array_models)


def closed_form_effective_mass(model, s: complex) -> np.ndarray:
    """TITOP one-port M_P(s) written out from the paper (rows of L = modes)."""
    L = np.asarray(model.participation)
    w = 2 * np.pi * np.asarray(model.frequencies_hz)
    xi = np.asarray(model.damping_ratios)
    D_P = np.asarray(model.rigid_spatial_inertia)
    out = D_P - L.T @ L
    for i in range(len(w)):
        out = out + np.outer(L[i], L[i]) * (2 * xi[i] * w[i] * s + w[i] ** 2) / (
            s**2 + 2 * xi[i] * w[i] * s + w[i] ** 2
        )
    return out


def linearized_mass_matrix(realization) -> np.ndarray:
    """Linearized mass matrix in coordinates ``(x_P, q_1..q_N)`` (6+N square)."""
    n = len(realization.modes)
    out = np.zeros((6 + n, 6 + n))
    out[:6, :6] = realization.D_P
    for i, mode in enumerate(realization.modes):
        column = mode.spatial_inertia @ mode.twist
        out[:6, 6 + i] = column
        out[6 + i, :6] = column
        out[6 + i, 6 + i] = mode.twist @ column
    return out


@pytest.mark.parametrize("name", ARRAY_MODELS)
def test_mode_bodies_satisfy_realization_conditions(name):
    model = SCENARIO.array_models[name]
    realization = realize_appendage(
        model.rigid_spatial_inertia,
        model.omega,
        model.damping_ratios,
        model.participation,
        name=name,
    )
    for mode, l in zip(realization.modes, model.participation, strict=True):
        M, H, k = mode.spatial_inertia, mode.twist, mode.scale
        np.testing.assert_allclose(M @ H, k * l, atol=1e-10 * np.abs(k * l).max())
        np.testing.assert_allclose(H @ M @ H, k**2, rtol=1e-12)
        assert is_physical_spatial_inertia(M), "each mode body must be a real rigid body"
        np.testing.assert_allclose(np.linalg.norm(mode.axis), 1.0, rtol=1e-14)
        assert abs(mode.axis @ l[:3]) < 1e-12 * max(1.0, np.linalg.norm(l))  # n orthogonal to a
    # the whole appendage keeps the rigid inertia D_P
    total = realization.residual_inertia + sum(m.spatial_inertia for m in realization.modes)
    np.testing.assert_allclose(total, model.rigid_spatial_inertia, atol=1e-9)


@pytest.mark.parametrize("name", ARRAY_MODELS)
def test_linearized_mass_matrix_is_positive_definite_with_schur_complement_D_P0(name):
    model = SCENARIO.array_models[name]
    realization = realize_appendage(
        model.rigid_spatial_inertia, model.omega, model.damping_ratios, model.participation
    )
    mass_matrix = linearized_mass_matrix(realization)
    assert np.linalg.eigvalsh(mass_matrix).min() > 0
    K = np.diag([m.scale for m in realization.modes])
    block = mass_matrix[:6, 6:]
    schur = mass_matrix[:6, :6] - block @ np.linalg.solve(mass_matrix[6:, 6:], block.T)
    np.testing.assert_allclose(schur, model.residual_mass, atol=1e-9)
    np.testing.assert_allclose(mass_matrix[6:, 6:], K**2, rtol=1e-12)


def test_chaser_array_root_is_not_physical_as_documented():
    model = SCENARIO.array_models["SA1_2"]
    realization = realize_appendage(
        model.rigid_spatial_inertia, model.omega, model.damping_ratios, model.participation
    )
    # sum |a_i|^2 ~ 146 kg > 88.93 kg: a per-mode realization needs a negative root mass
    assert realization.residual_inertia[0, 0] < 0
    assert not realization.residual_is_physical


def test_columns_as_modes_reading_is_refused():
    model = SCENARIO.array_models["SA1_2"]
    with pytest.raises(ValueError, match="not positive semi-definite"):
        realize_appendage(
            model.rigid_spatial_inertia,
            model.omega,
            model.damping_ratios,
            model.participation.T,
            name="SA1_2",
        )


@pytest.mark.parametrize(
    "participation, frequency, ratio, match",
    [
        (np.zeros(6), 1.0, 0.01, "nonzero"),
        (np.ones(6), -1.0, 0.01, "frequency"),
        (np.ones(6), 1.0, -0.1, "damping ratio"),
    ],
)
def test_bad_mode_is_refused(participation, frequency, ratio, match):
    with pytest.raises(ValueError, match=match):
        realize_mode(participation, frequency, ratio, name="bad")


@pytest.mark.parametrize(
    "l",
    [
        [1.0, 0.0, 0.0, 2.0, 0.0, 0.0],  # rotation parallel to translation
        [0.0, 0.0, 0.0, 0.0, 0.0, 3.0],  # pure rotation
        [0.0, 2.0, 0.0, 0.0, 0.0, 0.0],  # pure translation
    ],
)
def test_degenerate_participation_vectors_are_realized(l):
    l = np.array(l)
    mode = realize_mode(l, 5.0, 0.02)
    np.testing.assert_allclose(mode.spatial_inertia @ mode.twist, mode.scale * l, atol=1e-12)
    np.testing.assert_allclose(mode.twist @ mode.spatial_inertia @ mode.twist, mode.scale**2)
    assert is_physical_spatial_inertia(mode.spatial_inertia)


@pytest.mark.drake
@pytest.mark.parametrize("name", ARRAY_MODELS)
def test_drake_hub_plus_array_matches_closed_form_one_port(name, tmp_path):
    """Hub + one array from the generated SDF: Drake linearization vs inv(D_hub + tau^T M_P tau)."""
    from pydrake.math import RigidTransform
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import RotationalInertia, SpatialInertia
    from pydrake.systems.framework import DiagramBuilder

    from oos_drake.multibody.appendage_sdf import appendage_model
    from oos_drake.multibody.linearization import add_hub_io, linearize_hub
    from oos_drake.multibody.plant_parts import add_floating_joint, add_modal_residual
    from oos_drake.multibody.sdf_writer import to_sdf_text

    model = SCENARIO.array_models[name]
    path = tmp_path / "array.sdf"
    path.write_text(
        to_sdf_text(
            appendage_model(
                "array",
                model.mass,
                model.p_P_S,
                model.inertia,
                model.omega,
                model.damping_ratios,
                model.participation,
            )
        )
    )
    hub_mass, hub_J = 188.5, np.array([[41.98, 3.84, 0.0], [3.84, 43.89, 0.0], [0.0, 0.0, 42.64]])
    p_GP = np.array([0.1, 0.4365, -0.05])
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("plant", MultibodyPlant(0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    instance = Parser(plant).AddModels(str(path))[0]
    add_modal_residual(plant, instance)
    hub = plant.AddRigidBody(
        "hub",
        plant.AddModelInstance("hub"),
        SpatialInertia.MakeFromCentralInertia(
            hub_mass,
            np.zeros(3),
            RotationalInertia(
                hub_J[0, 0], hub_J[1, 1], hub_J[2, 2], hub_J[0, 1], hub_J[0, 2], hub_J[1, 2]
            ),
        ),
    )
    plant.WeldFrames(hub.body_frame(), plant.GetFrameByName("P", instance), RigidTransform(p_GP))
    joint = add_floating_joint(plant, hub, RigidTransform())
    plant.Finalize()
    ports = add_hub_io(builder, plant, joint)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    system = linearize_hub(diagram, context, ports)[0:6, :]

    # the assembled mass matrix stays positive definite despite the non-physical root
    mass_matrix = plant.CalcMassMatrix(plant.GetMyContextFromRoot(context))
    assert np.linalg.eigvalsh(mass_matrix).min() > 0

    D_hub = np.zeros((6, 6))
    D_hub[:3, :3] = hub_mass * np.eye(3)
    D_hub[3:, 3:] = hub_J
    tau_PG = np.eye(6)  # xdd_P = tau_PG xdd_G, PG = -p_GP
    x, y, z = -p_GP
    tau_PG[:3, 3:] = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    omega = 2 * np.pi * np.logspace(-2, 2, 400)
    drake = np.moveaxis(system(1j * omega), -1, 0)
    reference = np.array(
        [
            np.linalg.inv(D_hub + tau_PG.T @ closed_form_effective_mass(model, 1j * w) @ tau_PG)
            for w in omega
        ]
    )
    error = np.linalg.norm(drake - reference, 2, axis=(1, 2)).max()
    assert error / np.linalg.norm(reference, 2, axis=(1, 2)).max() < 1e-9
