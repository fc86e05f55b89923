"""Flight software components and the exact quintic trajectories (no simulation)."""

import numpy as np
import pytest
import scipy.signal

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.control import components as comp  # noqa: E402
from oos_drake.multibody.flight_software import (  # noqa: E402
    FlightSoftwareDesign,
    allpass,
    allpass_block,
    discretize,
)
from oos_drake.multibody.mission import (  # noqa: E402
    MissionOptions,
    effective_inertia,
    mission_controller,
    quintic_piecewise_polynomial,
)
from oos_drake.scenario.timeline import mission_timeline  # noqa: E402


def _dc_gain(block):
    n = block.A.shape[0]
    return block.C @ np.linalg.solve(np.eye(n) - block.A, block.B) + block.D


@pytest.mark.parametrize("rate", [5.0, 10.0, 50.0])
def test_discretized_blocks_keep_dc_gain_and_match_the_continuous_response(rate):
    design = FlightSoftwareDesign.create(np.ones((3, 6)), rate)
    for block in (design.star_tracker, design.gyro, design.rolloff, design.wheels):
        np.testing.assert_allclose(_dc_gain(block), np.eye(3), atol=1e-9)
    a, b = comp.DesignSpecification().disturbance_denominator
    gains = np.asarray(comp.DesignSpecification().disturbance_gains)
    np.testing.assert_allclose(_dc_gain(design.disturbance), np.diag(gains / b), rtol=1e-9)
    # Tustin: H_d(e^{j w T}) = H_c(j (2/T) tan(w T / 2)); check the roll-off at 0.3 Hz
    T = 1.0 / rate
    w = 2 * np.pi * 0.3
    A, B, C, D = comp.butterworth(4, 0.7)
    warped = 2.0 / T * np.tan(w * T / 2.0)
    hc = (C @ np.linalg.solve(1j * warped * np.eye(4) - A, B) + D)[0, 0]
    z = np.exp(1j * w * T)
    ro = design.rolloff
    hd = (ro.C @ np.linalg.solve(z * np.eye(ro.nstates) - ro.A, ro.B) + ro.D)[0, 0]
    np.testing.assert_allclose(hd, hc, rtol=1e-9)


def test_allpass_has_unit_gain_and_is_stable():
    A, B, C, D = allpass(0.4)
    w = np.logspace(-3, 3, 50)
    _, h = scipy.signal.freqresp((A, B, C, D), w)
    p = 2 * np.pi * 0.4
    np.testing.assert_allclose(h, (p - 1j * w) / (p + 1j * w), rtol=1e-12)  # the closed form
    assert np.all(np.linalg.eigvals(A).real < 0)
    block = discretize(A, B, C, D, 0.1)
    assert np.all(np.abs(np.linalg.eigvals(block.A)) < 1)


def _response(block, frequency_hz, period):
    z = np.exp(2j * np.pi * frequency_hz * period)
    n = block.A.shape[0]
    return block.C @ np.linalg.solve(z * np.eye(n) - block.A, block.B) + block.D


@pytest.mark.parametrize("rate", [10.0, 50.0])
@pytest.mark.parametrize("frequency_hz", [0.0889, 0.8247, 3.0])
def test_discrete_allpass_is_minus_j_at_its_frequency(rate, frequency_hz):
    """Pre-warped Tustin: the discrete all-pass equals the continuous a(j 2 pi f) = -j at f
    (closed form), has unit gain on the whole unit circle and is stable."""
    T = 1.0 / rate
    block = allpass_block(frequency_hz, T)
    np.testing.assert_allclose(_response(block, frequency_hz, T), -1j * np.eye(3), atol=1e-12)
    for f in np.geomspace(1e-3, 0.499 * rate, 40):
        np.testing.assert_allclose(np.abs(np.diag(_response(block, f, T))), 1.0, rtol=1e-12)
    assert np.all(np.abs(np.linalg.eigvals(block.A)) < 1)
    # without pre-warping the phase at f would be off by the Tustin warp
    plain = discretize(*[np.kron(np.eye(3), m) for m in allpass(frequency_hz)], T)
    warp = abs(np.angle(_response(plain, frequency_hz, T)[0, 0]) + np.pi / 2)
    assert warp > 1e-6  # the pre-warped one is exact to 1e-12


@pytest.mark.parametrize("frequency_hz", [5.0, 7.0, np.inf, np.nan])
def test_allpass_at_or_above_nyquist_is_static(frequency_hz):
    block = allpass_block(frequency_hz, 0.1)
    for f in (0.01, 1.0, 4.9):
        np.testing.assert_allclose(_response(block, f, 0.1), np.eye(3), atol=0)
    with pytest.raises(ValueError, match="frequency"):
        allpass_block(0.0, 0.1)


def test_design_rejects_bad_inputs():
    with pytest.raises(ValueError, match="3x6"):
        FlightSoftwareDesign.create(np.ones((3, 3)), 10.0)
    with pytest.raises(ValueError, match="control_rate"):
        FlightSoftwareDesign.create(np.ones((3, 6)), 0.0)
    with pytest.raises(ValueError, match="log_rate"):
        MissionOptions(control_rate=10.0, log_rate=3.0)
    with pytest.raises(ValueError, match="accuracy"):
        MissionOptions(accuracy=-1.0)


def test_quintic_polynomial_equals_the_timeline_trajectory(paper_scenario):
    timeline = mission_timeline(paper_scenario)
    pp = quintic_piecewise_polynomial(timeline.arm)
    times = np.linspace(0.0, 1500.0, 301)
    values = np.stack([pp.value(t).ravel() for t in times])
    rates = np.stack([pp.EvalDerivative(t, 1).ravel() for t in times])
    np.testing.assert_allclose(values, timeline.arm(times), atol=1e-12)
    np.testing.assert_allclose(rates, timeline.arm(times, 1), atol=1e-12)


def test_baseline_gain_from_the_coupled_inertia(tmp_path, paper_scenario):
    K = mission_controller(None, paper_scenario).K
    omega = 2 * np.pi * 0.01
    Kp, Kd = K[:, :3], K[:, 3:]
    np.testing.assert_allclose(Kd, 2 * omega * Kp / omega**2, rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(0.5 * (Kp + Kp.T)) > 0)
    # effective inertia of a point mass offset from G1: J = D_rr - D_rt D_tt^-1 D_tr
    m, r = 2.0, np.array([1.0, 0.0, 0.0])
    D = np.zeros((6, 6))
    D[:3, :3] = m * np.eye(3)
    S = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    D[:3, 3:], D[3:, :3], D[3:, 3:] = -m * S, m * S, -m * S @ S
    np.testing.assert_allclose(effective_inertia(D), np.zeros((3, 3)), atol=1e-12)
    (tmp_path / "c.json").write_text(
        '{"controller": {"K_p": {"value": [[1,0,0],[0,1,0],[0,0,1]]},'
        ' "K_d": {"value": [[2,0,0],[0,2,0],[0,0,2]]}}}'
    )
    np.testing.assert_allclose(
        mission_controller(tmp_path / "c.json", paper_scenario).K,
        np.hstack([np.eye(3), 2 * np.eye(3)]),
    )
    with pytest.raises(ValueError, match="not found"):
        mission_controller(tmp_path / "missing.json", paper_scenario)


def test_merged_stages_equal_the_block_by_block_chain():
    from oos_drake.multibody.flight_software import FlightSoftware

    design = FlightSoftwareDesign.create(np.arange(18.0).reshape(3, 6) / 7.0, 10.0)
    fsw = FlightSoftware(design, nq=12, nv=12, hub_q_start=0, hub_v_start=0)
    rng = np.random.default_rng(0)
    frequency_hz = 0.4
    perturbation = np.concatenate([np.zeros(10), [frequency_hz]])
    n2 = design.wheels.nstates + design.disturbance.nstates + 6
    M2 = fsw._output_stage(perturbation)[: n2 + 12]  # without the torque mixing row
    ap = allpass_block(frequency_hz, design.period)
    for stage, reference, nz in (
        (fsw._M1, fsw._stage1_reference, 12),
        (M2, lambda x, z: fsw._stage2_reference(x, z, ap), 6),
    ):
        nx = stage.shape[1] - nz
        x, z = rng.standard_normal(nx), rng.standard_normal(nz)
        x_next, y = reference(x, z)
        np.testing.assert_allclose(
            stage @ np.concatenate([x, z]), np.concatenate([x_next, y]), rtol=1e-12, atol=1e-12
        )


def test_docking_schedule_ramps_and_releases():
    from oos_drake.multibody.mission_sim import _Schedule

    values = {
        "k_shear_SM1": 1e5, "k_tors_SM1": 2e4, "d_shear_SM1": 100.0, "d_tors_SM1": 50.0,
        "k_shear_SM2": 3e4, "k_tors_SM2": 1e5, "d_shear_SM2": 80.0, "d_tors_SM2": 90.0,
    }  # fmt: skip
    schedule = _Schedule(255.0, 880.0, 2.0, 10, 0.1, values)
    assert schedule.settings(254.9) == {"SM1": (0, 0, 0, 0), "SM2": (0, 0, 0, 0)}
    first = schedule.settings(255.0)["SM1"]
    assert first == pytest.approx((0.1, 0.1, 100.0, 50.0))
    last_step = schedule.settings(256.95)["SM1"]
    assert last_step == pytest.approx((1e5, 2e4, 100.0, 50.0))
    # log-spaced: ten steps from 0.1 to 1e5 -> ratio (1e6)^(1/9) per step
    k = [schedule.settings(255.0 + 0.2 * i + 0.01)["SM1"][0] for i in range(10)]
    np.testing.assert_allclose(np.diff(np.log(k)), np.log(1e6) / 9, rtol=1e-9)
    assert schedule.settings(500.0) == {"SM1": (1e5, 2e4, 100.0, 50.0), "SM2": (0, 0, 0, 0)}
    docking = schedule.settings(880.0)
    assert docking["SM1"] == (1e5, 2e4, 100.0, 50.0)
    assert docking["SM2"] == pytest.approx((0.1, 0.1, 80.0, 90.0))
    releasing = schedule.settings(882.0)
    assert releasing["SM2"] == (3e4, 1e5, 80.0, 90.0)
    assert releasing["SM1"] == pytest.approx((1e5, 2e4, 100.0, 50.0))
    assert schedule.settings(883.95)["SM1"] == pytest.approx((0.1, 0.1, 100.0, 50.0))
    assert schedule.settings(884.0) == {"SM1": (0, 0, 0, 0), "SM2": (3e4, 1e5, 80.0, 90.0)}
    assert schedule.breakpoints(250.0, 300.0) == pytest.approx([255.0 + 0.2 * i for i in range(11)])


def test_rpy_rotation_equals_drake_convention():
    from pydrake.math import RollPitchYaw

    from oos_drake.multibody.flight_software import rpy_to_rotation

    rng = np.random.default_rng(3)
    for rpy in rng.uniform(-3.0, 3.0, size=(50, 3)):
        expected = RollPitchYaw(rpy).ToRotationMatrix().matrix()
        np.testing.assert_allclose(rpy_to_rotation(*rpy), expected, rtol=0, atol=1e-15)


def test_update_equals_the_block_by_block_chain_with_perturbations():
    """One discrete update against an independent evaluation of the equations of the module doc
    (stage references, saturation, torque mixing, rotation, metrics), for two perturbation sets in
    a row (the mixing matrix is cached per perturbation value)."""
    from pydrake.math import RollPitchYaw
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from oos_drake.multibody.flight_software import FlightSoftware

    rng = np.random.default_rng(7)
    K = 40.0 * rng.standard_normal((3, 6))  # large: the saturation is active on some axes
    design = FlightSoftwareDesign.create(K, 10.0, J_ref=np.diag([500.0, 100.0, 300.0]))
    nq = nv = 12
    builder = DiagramBuilder()
    fsw = builder.AddSystem(FlightSoftware(design, nq, nv, hub_q_start=3, hub_v_start=6))
    plant_x = rng.standard_normal(nq + nv) * 0.3
    source = builder.AddSystem(ConstantVectorSource(plant_x))
    builder.Connect(source.get_output_port(), fsw.get_input_port(0))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    fc = fsw.GetMyMutableContextFromRoot(context)
    noise = rng.standard_normal((5, 9))
    fsw.set_noise(fc, noise)
    s = fsw.state_slices
    with pytest.raises(ValueError, match="no frequency"):
        fsw.set_perturbations(fc, np.eye(3), 0.0)
    for delta_mul, delta_add, frequency_hz in (
        (rng.uniform(-1, 1, (3, 3)), 0.7, 0.31),
        (np.eye(3) * -0.4, -1.0, 0.82),
    ):
        fsw.set_perturbations(fc, delta_mul, delta_add, frequency_hz)
        x = rng.standard_normal(s["counter"].stop)
        x[s["metrics"]] = np.abs(x[s["metrics"]])
        x[s["counter"]] = 2.0
        fc.get_mutable_discrete_state(0).SetFromVector(x)
        new = diagram.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).CopyToVector()
        rpy = plant_x[3:6]
        R = RollPitchYaw(rpy).ToRotationMatrix().matrix()
        w_B = R.T @ plant_x[nq + 6 : nq + 9]
        n = noise[2]
        x1 = x[s["star_tracker"].start : s["rolloff"].stop]
        x1_next, u = fsw._stage1_reference(x1, np.concatenate([rpy, w_B, n[0:6]]))
        sat = np.clip(u, -design.torque_limit, design.torque_limit)
        x2 = x[s["wheels"].start : s["add"].stop]
        x2_next, y2 = fsw._stage2_reference(
            x2, np.concatenate([sat, n[6:9]]), allpass_block(frequency_hz, design.period)
        )
        T_rw, T_dist, a_mul, a_add = y2.reshape(4, 3)
        T = (
            T_rw
            + (design.W_mul * delta_mul) @ a_mul
            + delta_add * design.W_add * (design.J_ref @ a_add)
            + T_dist
        )
        np.testing.assert_allclose(
            new[s["star_tracker"].start : s["rolloff"].stop], x1_next, atol=1e-12
        )
        np.testing.assert_allclose(new[s["wheels"].start : s["add"].stop], x2_next, atol=1e-12)
        np.testing.assert_allclose(new[s["tau_W"]], R @ T, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(new[s["log"]], np.concatenate([u, T_rw, T, T_dist]), atol=1e-12)
        m = x[s["metrics"]].reshape(4, 3)
        expected = np.concatenate(
            [
                np.maximum(m[0], abs(rpy)),
                np.maximum(m[1], abs(u)),
                m[2] + rpy**2,
                np.maximum(m[3], abs(T)),
            ]
        )
        np.testing.assert_allclose(new[s["metrics"]], expected, atol=1e-12)
        assert new[s["counter"]][0] == 3.0
        assert np.any(np.abs(u) > design.torque_limit)  # the saturation was exercised
