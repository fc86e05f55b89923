"""Block-level cross-checks of the Drake twin against closed forms written out here.

- multi-port rigid body (target hub from sdf/): wrench at D2 -> acceleration at D3 equals
  ``tau_D3G D_G^-1 tau_D2G^T W``;
- the arm alone (sdf/arm_ur5.sdf) at random joint angles: Drake's composite spatial inertia at
  J0 equals the sum of ``tau^T T^T D_link T tau`` from an independent forward kinematics;
- a LinearBushingRollPitchYaw equals the spring-damper ``W = -(K + D s)/s^2 xdd_rel``.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.drake

pydrake = pytest.importorskip("pydrake")

from pydrake.math import RigidTransform, RollPitchYaw  # noqa: E402
from pydrake.multibody.math import SpatialForce  # noqa: E402
from pydrake.multibody.parsing import Parser  # noqa: E402
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant  # noqa: E402
from pydrake.multibody.tree import (  # noqa: E402
    FixedOffsetFrame,
    LinearBushingRollPitchYaw,
    SpatialInertia,
)
from pydrake.systems.framework import DiagramBuilder  # noqa: E402

from oos_drake.multibody.linearization import add_hub_io, linearize_hub  # noqa: E402
from oos_drake.multibody.plant_parts import (  # noqa: E402
    add_floating_joint,
    drake_spatial_inertia_to_matrix,
)
from oos_drake.multibody.scenario_sdf import SDF_DIRECTORY  # noqa: E402
from oos_drake.scenario.data import load_scenario  # noqa: E402

SCENARIO = load_scenario()


def skew(v):
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def tau(p_PB):
    """xdd_P = tau(PB) xdd_B, [translation; rotation]."""
    out = np.eye(6)
    out[:3, 3:] = skew(p_PB)
    return out


def rotation(axis, angle):
    K = skew(np.asarray(axis, float))
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_multiport_rigid_body_wrench_at_D2_acceleration_at_D3():
    plant = MultibodyPlant(0.0)
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    instance = Parser(plant).AddModels(str(SDF_DIRECTORY / "hub_RH2.sdf"))[0]
    body = plant.GetBodyByName("RH2", instance)
    add_floating_joint(plant, body, RigidTransform())
    plant.Finalize()
    context = plant.CreateDefaultContext()
    hub, d2, d3 = SCENARIO.hubs["RH2"], SCENARIO.ports["D2"], SCENARIO.ports["D3"]
    rng = np.random.default_rng(4)
    W_D2 = rng.normal(size=6)  # [F; T at D2] in R_RH2 (= world at the operating point)
    force = ExternallyAppliedSpatialForce()
    force.body_index = body.index()
    force.p_BoBq_B = d2.p_G_D
    force.F_Bq_W = SpatialForce(tau=W_D2[3:], f=W_D2[:3])
    plant.get_applied_spatial_force_input_port().FixValue(context, [force])
    A_WD3 = plant.GetFrameByName("D3", instance).CalcSpatialAccelerationInWorld(context)
    drake = np.concatenate([A_WD3.translational(), A_WD3.rotational()])

    D_G = np.zeros((6, 6))
    D_G[:3, :3] = hub.mass * np.eye(3)
    D_G[3:, 3:] = hub.inertia
    expected = tau(-d3.p_G_D) @ np.linalg.solve(D_G, tau(-d2.p_G_D).T @ W_D2)
    np.testing.assert_allclose(drake, expected, rtol=1e-12, atol=1e-14)


def arm_inertia_at_J0(alpha):
    """Composite spatial inertia of L0..L6 at J0 in R_L0 from the scenario data (numpy FK)."""
    R, p = np.eye(3), np.zeros(3)
    total = np.zeros((6, 6))
    links = SCENARIO.arm.links
    for i, link in enumerate(links):
        if i > 0:
            p = p + R @ links[i - 1].p_J_Jnext
            R = R @ rotation(link.joint_axis, alpha[i - 1])
        T = np.zeros((6, 6))
        T[:3, :3] = T[3:, 3:] = R.T  # L0 components -> Li components
        D_link = np.zeros((6, 6))  # at J_i in R_Li
        c = link.p_J_G
        D_link[:3, :3] = link.mass * np.eye(3)
        D_link[:3, 3:] = -link.mass * skew(c)
        D_link[3:, :3] = link.mass * skew(c)
        D_link[3:, 3:] = link.inertia - link.mass * skew(c) @ skew(c)
        # xdd_Ji (in Li) = T tau(J_i -> J0) xdd_J0 (in L0)
        kin = T @ tau(-p)
        total += kin.T @ D_link @ kin
    return total


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_arm_alone_at_random_angles_matches_rigid_inertia(seed):
    plant = MultibodyPlant(0.0)
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    instance = Parser(plant).AddModels(str(SDF_DIRECTORY / "arm_ur5.sdf"))[0]
    base = plant.GetBodyByName("L0", instance)
    joint = add_floating_joint(plant, base, RigidTransform())
    plant.Finalize()
    context = plant.CreateDefaultContext()
    alpha = np.random.default_rng(seed).uniform(-np.pi, np.pi, 6)
    for i, angle in enumerate(alpha, start=1):
        plant.GetJointByName(f"alpha_{i}", instance).set_angle(context, angle)
    M = plant.CalcSpatialInertia(context, base.body_frame(), plant.GetBodyIndices(instance))
    expected = arm_inertia_at_J0(alpha)
    np.testing.assert_allclose(drake_spatial_inertia_to_matrix(M), expected, atol=1e-12)
    assert joint.num_velocities() == 6


@pytest.mark.parametrize("seed", [0, 1])
def test_arm_with_locked_joints_linearizes_to_inverse_rigid_inertia(seed):
    """Motion-driven (locked) joints: wrench at J0 -> acceleration at J0 is inv(D_J0)."""
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("plant", MultibodyPlant(0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    instance = Parser(plant).AddModels(str(SDF_DIRECTORY / "arm_ur5.sdf"))[0]
    base = plant.GetBodyByName("L0", instance)
    joint = add_floating_joint(plant, base, RigidTransform())
    plant.Finalize()
    ports = add_hub_io(builder, plant, joint)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    alpha = np.random.default_rng(10 + seed).uniform(-np.pi, np.pi, 6)
    for i, angle in enumerate(alpha, start=1):
        arm_joint = plant.GetJointByName(f"alpha_{i}", instance)
        arm_joint.set_angle(plant_context, angle)
        arm_joint.Lock(plant_context)
    system = linearize_hub(diagram, context, ports)
    np.testing.assert_allclose(
        system.D[0:6, :], np.linalg.inv(arm_inertia_at_J0(alpha)), rtol=1e-9, atol=1e-9
    )


def test_bushing_matches_spring_damper_formula():
    """Body C tied to the world by a bushing at Q: G(s) = s^2 (D s^2 + T^T (K + D s) T)^-1."""
    k_shear, k_tors, d_shear, d_tors = 250.0, 40.0, 3.0, 0.7
    mass, p_com = 12.0, np.array([0.05, -0.02, 0.1])
    J_c = np.array([[1.2, 0.1, 0.0], [0.1, 0.9, -0.05], [0.0, -0.05, 1.5]])
    X_CQ = RigidTransform(RollPitchYaw(0.3, -0.2, 0.5), [0.4, 0.1, -0.3])

    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("plant", MultibodyPlant(0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    body = plant.AddRigidBody(
        "C",
        plant.AddModelInstance("C"),
        SpatialInertia.MakeFromCentralInertia(mass, p_com, _rotational(J_c)),
    )
    frame_C = plant.AddFrame(FixedOffsetFrame("Q_on_C", body.body_frame(), X_CQ))
    frame_A = plant.AddFrame(FixedOffsetFrame("Q_on_world", plant.world_frame(), X_CQ))
    plant.AddForceElement(
        LinearBushingRollPitchYaw(
            frame_A, frame_C, [k_tors] * 3, [d_tors] * 3, [k_shear] * 3, [d_shear] * 3
        )
    )
    joint = add_floating_joint(plant, body, RigidTransform())
    plant.Finalize()
    ports = add_hub_io(builder, plant, joint)
    diagram = builder.Build()
    system = linearize_hub(diagram, diagram.CreateDefaultContext(), ports)[0:6, :]

    D = np.zeros((6, 6))
    D[:3, :3] = mass * np.eye(3)
    D[:3, 3:] = -mass * skew(p_com)
    D[3:, :3] = mass * skew(p_com)
    D[3:, 3:] = J_c - mass * skew(p_com) @ skew(p_com)
    T = np.zeros((6, 6))
    R_CQ = X_CQ.rotation().matrix()
    T[:3, :3] = T[3:, 3:] = R_CQ.T  # C components -> Q components
    kin = T @ tau(-X_CQ.translation())  # xdd_Q (in Q) = T tau(Q -> Co) xdd_Co
    K = np.diag([k_shear] * 3 + [k_tors] * 3)
    Dm = np.diag([d_shear] * 3 + [d_tors] * 3)
    omega = np.logspace(-2, 3, 60)
    for w in omega:
        s = 1j * w
        expected = s**2 * np.linalg.inv(D * s**2 + kin.T @ (K + Dm * s) @ kin)
        error = np.linalg.norm(system(s) - expected, 2) / np.linalg.norm(expected, 2)
        assert error < 1e-9, (w, error)


def _rotational(J):
    from pydrake.multibody.tree import RotationalInertia

    return RotationalInertia(J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2])


def test_hub_wrench_input_is_a_body_frame_wrench_at_any_attitude():
    """The wrench input is exact away from the operating attitude (nonlinear simulations)."""
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("plant", MultibodyPlant(0.0))
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    instance = Parser(plant).AddModels(str(SDF_DIRECTORY / "hub_RH1.sdf"))[0]
    body = plant.GetBodyByName("RH1", instance)
    joint = add_floating_joint(plant, body, RigidTransform())
    plant.Finalize()
    ports = add_hub_io(builder, plant, joint)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    rpy = RollPitchYaw(0.3, -0.5, 1.0)
    joint.set_angles(plant_context, rpy.vector())
    W_B = np.array([1.0, -2.0, 0.5, 0.3, 0.7, -1.1])
    diagram.GetInputPort(ports.wrench_input).FixValue(context, W_B)
    vdot = plant.get_generalized_acceleration_output_port().Eval(plant_context)
    R_WB = rpy.ToRotationMatrix().matrix()
    vs = joint.velocity_start()
    a_B = R_WB.T @ vdot[vs + 3 : vs + 6]
    wdot_B = R_WB.T @ vdot[vs : vs + 3]
    hub = SCENARIO.hubs["RH1"]
    D_G = np.zeros((6, 6))
    D_G[:3, :3] = hub.mass * np.eye(3)
    D_G[3:, 3:] = hub.inertia
    np.testing.assert_allclose(np.concatenate([a_B, wdot_B]), np.linalg.solve(D_G, W_B), rtol=1e-12)
