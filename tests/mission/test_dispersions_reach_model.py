"""Each dispersed value reaches the simulated model: change it, see the dynamics change.

Free-decay tests isolate one degree of freedom of the mission diagram by locking every other joint
in the context (continuous plant), then compare the measured frequency / decay with closed forms:

- ``w1_SAk``: the first mode hinge of array k alone oscillates at the dispersed cantilever
  frequency (the realization's mode body has hinge inertia ``k^2`` and spring ``k^2 w^2``);
- ``m_RH2``, ``k_shear_SMi``, ``d_shear_SMi``: the target on a docking bushing, displaced along the
  port axis through its centre of mass: ``omega = sqrt(k / m)``, decay rate ``d / (2 m)``;
- ``Jzz_RH2``, ``k_tors_SM2``: torsion about that axis, ``omega = sqrt(k_tors / Jzz)``;
- ``Delta_mul``, ``Delta_add``: the applied torque minus the wheel torque and the disturbance is the
  all-pass perturbation of the wheel torque (checked against an independent continuous lsim);
- ``phi0_*``, ``w0_*``: the first logged sample; ``noise_seed``: reproducible and effective.
"""

import numpy as np
import pytest
import scipy.signal

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator  # noqa: E402

from oos_drake.control.components import DesignSpecification  # noqa: E402
from oos_drake.multibody.flight_software import allpass  # noqa: E402


def _free_decay(mission, values, start, keep, coordinate, set_initial, duration=4.0, rate=200.0):
    """Simulate with every joint locked except ``keep``; return times and ``coordinate(pc)``."""
    h = mission.handles
    context, _, _ = mission.initial_context(values, 0, start, start + duration)
    pc = h.plant.GetMyMutableContextFromRoot(context)
    joints = [h.plant.get_joint(j) for j in h.plant.GetJointIndices()]
    for joint in joints:
        if joint.num_velocities() > 0 and joint.index() not in keep:
            joint.Lock(pc)
    set_initial(pc)
    simulator = Simulator(h.diagram, context)
    ResetIntegratorFromFlags(simulator, "runge_kutta3", 1e-3)
    simulator.get_mutable_integrator().set_target_accuracy(1e-9)
    times = start + np.arange(1, int(duration * rate) + 1) / rate
    samples = []
    for t in times:
        simulator.AdvanceTo(t)
        samples.append(coordinate(pc))
    return times - start, np.asarray(samples)


def _frequency_and_decay(t, x):
    """Damped frequency [rad/s] from upward zero crossings, decay rate [1/s] from the peaks."""
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossings = t[up] - x[up] * (t[up + 1] - t[up]) / (x[up + 1] - x[up])
    period = np.mean(np.diff(crossings))
    spans = zip(crossings[:-1], crossings[1:], strict=True)
    peaks = [np.abs(x[(t >= a) & (t < b)]).max() for a, b in spans]
    decay = -np.polyfit(crossings[:-1], np.log(peaks), 1)[0]
    return 2 * np.pi / period, decay


@pytest.mark.parametrize("array", ["SA1", pytest.param("SA3", marks=pytest.mark.slow)])
def test_first_mode_frequency_reaches_the_mode_hinge(mission, array):
    nominal = mission._by_name[f"w1_{array}"].nominal
    measured = {}
    for factor in (1.0, 1.15):
        joint = mission.handles.mode_joints[array][0]
        t, q = _free_decay(
            mission,
            {f"w1_{array}": nominal * factor},
            1000.0,
            {joint.index()},
            lambda pc, j=joint: j.get_angle(pc),
            lambda pc, j=joint: j.set_angle(pc, 1e-3),
            duration=6.0 / factor,
        )
        omega_d, decay = _frequency_and_decay(t, q)
        zeta = 0.01  # paper's modal damping
        w = nominal * factor
        np.testing.assert_allclose(omega_d, w * np.sqrt(1 - zeta**2), rtol=3e-3)
        np.testing.assert_allclose(decay, zeta * w, rtol=0.1)
        measured[factor] = omega_d
    np.testing.assert_allclose(measured[1.15] / measured[1.0], 1.15, rtol=3e-3)


def _target_on_hub(mission, values, mode):
    """Free decay of the docked target on SM2 (D3 on the z axis of RH2 through G2)."""
    h = mission.handles
    target = h.target_joint

    def shift(pc):
        if mode == "translation":
            X = target.GetPose(pc)
            R = X.rotation().matrix()
            target.SetTranslation(pc, X.translation() + R[:, 2] * 1e-3)
        else:
            rpy = target.get_angles(pc).copy()
            rpy[2] += 1e-3
            target.set_angles(pc, rpy)

    def coordinate(pc):
        if mode == "translation":
            X_D1D3 = h.frames["D1"].CalcPose(pc, h.frames["D3"]).inverse()
            return X_D1D3.translation()[2]
        return target.get_angles(pc)[2]

    return _free_decay(
        mission, values, 1000.0, {target.index()}, coordinate, shift, duration=3.0, rate=400.0
    )


def _target_arrays(scenario):
    """Mass [kg] and inertia about z_RH2 through G2 [kg m^2] of the target's two (locked,
    rigid) arrays, from the scenario data."""
    mass, Jzz = 0.0, 0.0
    for name in ("SA3", "SA4"):
        mount = scenario.arrays[name]
        model = mount.model
        R = np.asarray(mount.R_G_P0)
        p_G_S = np.asarray(mount.p_G_P) + R @ np.asarray(model.p_P_S)
        J = R @ np.asarray(model.inertia) @ R.T
        mass += model.mass
        Jzz += J[2, 2] + model.mass * (p_G_S[0] ** 2 + p_G_S[1] ** 2)
    return mass, Jzz


@pytest.mark.slow
@pytest.mark.parametrize("m, k, d", [(24.96, 2.0e4, 20.0), (27.0, 5.0e4, 60.0)])
def test_target_mass_and_sm2_shear_set_the_docking_mode(mission, m, k, d):
    values = {"m_RH2": m, "k_shear_SM2": k, "d_shear_SM2": d}
    t, x = _target_on_hub(mission, values, "translation")
    omega_d, decay = _frequency_and_decay(t, x)
    m_total = m + _target_arrays(mission.handles.scenario)[0]
    omega = np.sqrt(k / m_total)
    np.testing.assert_allclose(decay, d / (2 * m_total), rtol=0.03)
    np.testing.assert_allclose(omega_d, np.sqrt(omega**2 - (d / (2 * m_total)) ** 2), rtol=2e-3)


@pytest.mark.slow
def test_target_inertia_and_sm2_torsion_set_the_torsion_mode(mission):
    J_arrays = _target_arrays(mission.handles.scenario)[1]
    measured = {}
    for Jzz in (2.088, 2.552):
        k = 3.0e4
        values = {"Jzz_RH2": Jzz, "k_tors_SM2": k, "d_tors_SM2": 0.0}
        t, angle = _target_on_hub(mission, values, "torsion")
        measured[Jzz] = _frequency_and_decay(t, angle)[0]
        np.testing.assert_allclose(measured[Jzz], np.sqrt(k / (Jzz + J_arrays)), rtol=1e-3)
    predicted = np.sqrt((2.088 + J_arrays) / (2.552 + J_arrays))
    np.testing.assert_allclose(measured[2.552] / measured[2.088], predicted, rtol=2e-4)


@pytest.mark.slow
def test_sm1_shear_stiffness_reaches_the_grasp(mission):
    """Target on the arm tip (start after the capture ramp): displacement along y_D2 (through
    G2 only approximately, so only the change of frequency with k is checked: ratio sqrt(2))."""
    h = mission.handles
    target = h.target_joint
    omegas = []
    for k in (1.0e4, 2.0e4):
        values = {"k_shear_SM1": k, "d_shear_SM1": 0.0, "k_tors_SM1": 1e6, "d_tors_SM1": 0.0}

        def shift(pc):
            X = target.GetPose(pc)
            target.SetTranslation(pc, X.translation() + X.rotation().matrix()[:, 0] * 1e-4)

        def coordinate(pc):
            return h.frames["J7"].CalcPose(pc, h.frames["D2"]).translation()[1]

        t, y = _free_decay(
            mission, values, 400.0, {target.index()}, coordinate, shift, duration=2.0, rate=800.0
        )
        omegas.append(_frequency_and_decay(t, y - y.mean())[0])
    assert abs(omegas[1] / omegas[0] - np.sqrt(2.0)) < 0.05


def test_lti_perturbations_reach_the_applied_torque(mission_10hz_log):
    mission = mission_10hz_log
    start, end = 1050.0, 1080.0
    n = int((end - start) * 10) + 2
    table = np.zeros((n, 9))
    table[:, 6:9] = [1.0, -1.0, 1.0]
    delta_mul = np.array([[1.0, -1.0, 0.5], [0.2, -0.7, 1.0], [0.0, 0.3, 1.0]])
    delta_add = -0.5
    values = {
        f"Delta_mul_{r}{c}": delta_mul[i, j]
        for i, r in enumerate("xyz")
        for j, c in enumerate("xyz")
    }
    frequency_hz = 0.3
    result = mission.run(
        {**values, "Delta_add": delta_add},
        start=start,
        end=end,
        noise_table=table,
        perturbation_frequency_hz=frequency_hz,
    )
    ts = result.timeseries
    cols = lambda p: ts[[f"{p}_{a} [N m]" for a in "xyz"]].to_numpy()  # noqa: E731
    T_rw, T, T_dist = cols("T_rw"), cols("T"), cols("T_dist")
    residual = T - T_rw - T_dist
    spec = DesignSpecification()
    W_mul = np.full((3, 3), spec.multiplicative_off_diagonal)
    np.fill_diagonal(W_mul, spec.multiplicative_diagonal)
    J_ref = mission.handles.flight_software.design.J_ref
    t = ts["time [s]"].to_numpy() - start
    filtered = np.stack(
        [scipy.signal.lsim(allpass(frequency_hz), T_rw[:, i], t)[1] for i in range(3)], axis=1
    )
    expected = filtered @ (delta_mul * W_mul + delta_add * spec.additive_weight * J_ref).T
    scale = np.abs(expected).max()
    assert scale > 1e-5
    np.testing.assert_allclose(residual[5:], expected[5:], atol=0.03 * scale)
    nominal = mission.run({}, start=start, end=end, noise_table=table).timeseries
    np.testing.assert_allclose(
        (
            nominal[[f"T_{a} [N m]" for a in "xyz"]]
            - nominal[[f"T_rw_{a} [N m]" for a in "xyz"]].to_numpy()
            - nominal[[f"T_dist_{a} [N m]" for a in "xyz"]].to_numpy()
        ).to_numpy(),
        0.0,
        atol=1e-15,
    )


def test_initial_attitude_and_rate_errors_are_the_initial_state(mission_10hz_log):
    values = {
        "phi0_x": 0.01,
        "phi0_y": -0.02,
        "phi0_z": 0.005,
        "w0_x": 1e-3,
        "w0_y": -2e-3,
        "w0_z": 5e-4,
    }
    ts = mission_10hz_log.run(values, start=1050.0, end=1051.0).timeseries
    first = ts.iloc[0]
    assert first["time [s]"] == 1050.0
    for a in "xyz":
        assert first[f"phi_{a} [rad]"] == pytest.approx(values[f"phi0_{a}"], abs=1e-12)
        assert first[f"w_{a} [rad/s]"] == pytest.approx(values[f"w0_{a}"], abs=1e-12)


def test_noise_seed_is_reproducible_and_effective(mission):
    run = lambda **v: mission.run(v, seed=3, start=1050.0, end=1070.0, log=False).metrics  # noqa: E731
    a, b, c = run(noise_seed=5), run(noise_seed=5), run(noise_seed=6)
    assert dict(a) == dict(b)
    assert a["rms_attitude"] != c["rms_attitude"]
    assert dict(run()) == dict(
        mission.run({"noise_seed": 3}, seed=99, start=1050.0, end=1070.0, log=False).metrics
    )


@pytest.mark.parametrize("sm, time", [("SM1", 500.0), ("SM2", 1000.0)])
def test_every_bushing_value_reaches_the_context(mission, sm, time):
    """The four constants of the connected bushing, read back from the plant context."""
    values = {f"k_shear_{sm}": 1.5e4, f"k_tors_{sm}": 2.5e4, f"d_shear_{sm}": 35.0,
              f"d_tors_{sm}": 45.0}  # fmt: skip
    context, _, _ = mission.initial_context(values, 0, time, time + 1.0)
    pc = mission.handles.plant.GetMyContextFromRoot(context)
    bushing = mission.handles.bushings[sm]
    np.testing.assert_array_equal(bushing.GetForceStiffnessConstants(pc), [1.5e4] * 3)
    np.testing.assert_array_equal(bushing.GetTorqueStiffnessConstants(pc), [2.5e4] * 3)
    np.testing.assert_array_equal(bushing.GetForceDampingConstants(pc), [35.0] * 3)
    np.testing.assert_array_equal(bushing.GetTorqueDampingConstants(pc), [45.0] * 3)
    other = mission.handles.bushings["SM2" if sm == "SM1" else "SM1"]
    np.testing.assert_array_equal(other.GetForceStiffnessConstants(pc), [0.0] * 3)
