"""Dynamic controllers downstream of the synthesis (issue 31, item 3).

Every check is against an independent construction: the closed loop of Fig. controldesign with
python-control's ``interconnect`` (blocks written out from their textbook forms), the exact
sampled-data loop with python-control's ``c2d`` and ``feedback``, the zero-order hold with
``control.c2d``; the static gain is the degenerate case (no states) and gives the numbers of
the static code path.
"""

import json

import control
import numpy as np
import pytest
import scipy.signal

from oos_drake.analysis.controller import Controller, load_controller, recorded_controller
from oos_drake.control.analysis_model import close_loop
from oos_drake.control.baseline import baseline_gains
from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import (
    CONTROLS,
    MEASUREMENTS,
    ControllerSystem,
    plant_statespace,
    weighted_interconnection,
)
from oos_drake.control.loop_response import LoopResponse
from oos_drake.control.plants import flexible_rotational_plant
from oos_drake.control.sampled import controller_chain, sampled_loop
from oos_drake.control.tunable import TunablePID
from oos_drake.lfr import LFR

J = np.array([[120.0, 5.0, 0.0], [5.0, 150.0, -3.0], [0.0, -3.0, 100.0]])
L = np.array([[3.0, 0.5], [0.2, 2.5], [0.4, -0.3]])
RATE_HZ = 10.0


def sig(name):
    return [f"{name}[{i}]" for i in range(3)]


def _plant():
    return flexible_rotational_plant(J - L @ L.T, L, [8.0, 20.0], 0.01)


def _pid() -> control.StateSpace:
    """A PID per axis on ``y_att`` with derivative filter and a first-order roll-off."""
    K = baseline_gains(J, 2 * np.pi * 0.05, 0.8)
    pid = TunablePID(
        "C",
        MEASUREMENTS[:3],
        CONTROLS,
        kp=np.diag(K[:, :3]),
        ki=0.02 * np.diag(K[:, :3]),
        kd=np.diag(K[:, 3:]),
        tf=0.3,
        rolloff_order=1,
        rolloff_frequency=2 * np.pi * 2.0,
    )
    return pid.statespace(pid.initial_parameters())


def _second_order() -> control.StateSpace:
    """A hand-built 2-state controller ``y (6) -> u_K (3)``: a lead on the attitude of every
    axis sharing two states, plus a static PD."""
    rng = np.random.default_rng(3)
    K = baseline_gains(J, 2 * np.pi * 0.05, 0.8)
    A = np.array([[-2.0, 0.7], [-0.7, -3.0]])
    B = 0.05 * rng.standard_normal((2, 6))
    C = 10.0 * rng.standard_normal((3, 2))
    return control.ss(A, B, C, K, inputs=MEASUREMENTS, outputs=CONTROLS)


CONTROLLERS = {"pid": _pid, "second-order": _second_order}


def reference_closed_loop(plant: control.StateSpace, controller: control.StateSpace):
    """Fig. controldesign with python-control's interconnect, the controller by its names."""
    I3 = np.eye(3)
    P = control.ss(plant.A, plant.B, plant.C, plant.D, inputs=sig("T"), outputs=sig("wdot"))
    s = control.tf("s")
    integ1 = control.ss(control.tf(1, [1, 0]) * I3, inputs=sig("wdot"), outputs=sig("w"))
    integ2 = control.ss(control.tf(1, [1, 0]) * I3, inputs=sig("w"), outputs=sig("phi"))
    w8, w200 = 2 * np.pi * 8, 2 * np.pi * 200
    sst = control.ss(1 / (s / w8 + 1) * I3, inputs=sig("phi"), outputs=sig("phi_m"))
    gyro = control.ss(1 / (s / w200 + 1) * I3, inputs=sig("w"), outputs=sig("w_m"))
    rw = control.ss(
        w200**2 / (s**2 + 1.4 * w200 * s + w200**2) * I3, inputs=sig("u"), outputs=sig("T_rw")
    )
    b, a = scipy.signal.butter(4, 2 * np.pi * 0.7, analog=True)
    ro = control.ss(control.tf(b, a) * I3, inputs=sig("u_K"), outputs=sig("u"))
    wext = control.ss(
        control.tf([1], [2.236, 0.2236]) * np.diag([0.002577, 0.009685, 0.01239]),
        inputs=sig("d_ext"),
        outputs=sig("T_dist"),
    )
    sum_T = control.summing_junction(inputs=["T_rw", "T_dist"], output="T", dimension=3)
    meas_att = control.ss(
        [], [], [], np.hstack([-I3, -1.5343e-5 * I3]),
        inputs=sig("phi_m") + sig("n_sst"), outputs=sig("y_att"),
    )  # fmt: skip
    meas_rate = control.ss(
        [], [], [], np.hstack([-I3, -9.1987e-4 * I3]),
        inputs=sig("w_m") + sig("n_gyro"), outputs=sig("y_rate"),
    )  # fmt: skip
    e_p = control.ss([], [], [], I3 / 0.0079, inputs=sig("phi"), outputs=sig("e_p"))
    e_u = control.ss([], [], [], 0.5 * I3, inputs=sig("u"), outputs=sig("e_u"))
    blocks = [P, integ1, integ2, sst, gyro, rw, ro, wext, sum_T, meas_att, meas_rate, e_p, e_u]
    return control.interconnect(
        [*blocks, controller],
        inputs=sig("d_ext") + sig("n_sst") + sig("n_gyro"),
        outputs=sig("e_p") + sig("e_u"),
    )


def _matched(a, b):
    """Max distance between two pole sets matched greedily (relative to ``1 + |p|``)."""
    a, b = list(np.asarray(a)), list(np.asarray(b))
    assert len(a) == len(b), (len(a), len(b))
    worst = 0.0
    for p in a:
        k = int(np.argmin([abs(p - q) for q in b]))
        worst = max(worst, abs(p - b.pop(k)) / (1 + abs(p)))
    return worst


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_analysis_closed_loop_equals_python_control_interconnect(name):
    """``close_loop`` (the LFR of the analysis, certain part), ``WeightedInterconnection.close``
    and ``LoopResponse.response`` against python-control: same poles, same responses."""
    A, B, C, D = _plant()
    ref_controller = CONTROLLERS[name]()
    controller = ControllerSystem.from_statespace(ref_controller)
    ref = reference_closed_loop(control.ss(A, B, C, D), ref_controller)
    lfr = close_loop(LFR.from_ss(A, B, C, D), controller, additive=False, multiplicative=False)
    ss = lfr.to_ss()
    assert _matched(np.linalg.eigvals(ss.A), ref.poles()) < 1e-7
    closed = weighted_interconnection(plant_statespace(A, B, C, D)).close(controller)
    assert closed.A.shape[-1] == ss.A.shape[0]
    assert _matched(np.linalg.eigvals(closed.A), ref.poles()) < 1e-7
    omega = np.array([0.003, 0.05, 0.3, 2.0, 8.0, 30.0])
    H_ref = np.moveaxis(ref(1j * omega), -1, 0)
    scale = np.abs(H_ref).max(axis=(1, 2), keepdims=True)
    H_lfr = np.stack([ss.C @ np.linalg.solve(1j * w * np.eye(ss.A.shape[0]) - ss.A, ss.B)
                      + ss.D for w in omega])  # fmt: skip
    np.testing.assert_allclose(H_lfr / scale, H_ref / scale, atol=1e-8)
    np.testing.assert_allclose(closed.freqresp(omega) / scale, H_ref / scale, atol=1e-8)
    loop = LoopResponse(plant_statespace(A[None], B[None], C[None], D[None]),
                        DesignSpecification())  # fmt: skip
    H_modal = loop.response(controller, omega[None])[0]
    np.testing.assert_allclose(H_modal / scale, H_ref / scale, atol=1e-8)


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_loop_gain_is_the_loop_broken_at_the_wheel_input(name):
    """``LoopResponse.loop_gain``: the open loop ``u_in -> -u`` with python-control."""
    A, B, C, D = _plant()
    ref_controller = CONTROLLERS[name]()
    I3 = np.eye(3)
    s = control.tf("s")
    w8, w200 = 2 * np.pi * 8, 2 * np.pi * 200
    b, a = scipy.signal.butter(4, 2 * np.pi * 0.7, analog=True)
    parts = [
        control.ss(A, B, C, D, inputs=sig("T"), outputs=sig("wdot")),
        control.ss(w200**2 / (s**2 + 1.4 * w200 * s + w200**2) * I3, inputs=sig("u_in"),
                   outputs=sig("T")),
        control.ss(control.tf(1, [1, 0]) * I3, inputs=sig("wdot"), outputs=sig("w")),
        control.ss(control.tf(1, [1, 0]) * I3, inputs=sig("w"), outputs=sig("phi")),
        control.ss(-1 / (s / w8 + 1) * I3, inputs=sig("phi"), outputs=sig("y_att")),
        control.ss(-1 / (s / w200 + 1) * I3, inputs=sig("w"), outputs=sig("y_rate")),
        control.ss(control.tf(b, a) * I3, inputs=sig("u_K"), outputs=sig("u")),
        ref_controller,
    ]  # fmt: skip
    open_loop = control.interconnect(parts, inputs=sig("u_in"), outputs=sig("u"))
    omega = np.array([0.01, 0.2, 1.0, 5.0])
    L_ref = -np.moveaxis(open_loop(1j * omega), -1, 0)
    loop = LoopResponse(plant_statespace(A[None], B[None], C[None], D[None]),
                        DesignSpecification())  # fmt: skip
    controller = ControllerSystem.from_statespace(ref_controller)
    L_mine = loop.loop_gain(controller, omega[None])[0]
    np.testing.assert_allclose(L_mine, L_ref, rtol=1e-6, atol=1e-7 * np.abs(L_ref).max())


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_exact_sampled_loop_with_a_dynamic_controller(name):
    """The exact sampled loop: ZOH plant with integrators, Tustin sensors and filters, the
    controller by ``control.c2d(..., "zoh")``, closed with ``control.feedback``."""
    A, B, C, D = _plant()
    ref_controller = CONTROLLERS[name]()
    spec = DesignSpecification()
    T = 1 / spec.flight_software_rate_hz
    n = A.shape[0]
    # T -> [phi; w], states [x; w; phi]
    Aa = np.zeros((n + 6, n + 6))
    Aa[:n, :n], Aa[n : n + 3, :n], Aa[n + 3 :, n : n + 3] = A, C, np.eye(3)
    Ba = np.vstack([B, D, np.zeros((3, 3))])
    Ca = np.zeros((6, n + 6))
    Ca[:3, n + 3 :], Ca[3:, n : n + 3] = np.eye(3), np.eye(3)
    G = control.c2d(control.ss(Aa, Ba, Ca, 0, inputs=sig("T"),
                               outputs=sig("phi") + sig("w")), T, "zoh")  # fmt: skip
    s = control.tf("s")
    I3 = np.eye(3)
    w8, w200 = 2 * np.pi * 8, 2 * np.pi * 200
    b, a = scipy.signal.butter(4, 2 * np.pi * 0.7, analog=True)

    def tustin(sys, inputs, outputs):
        return control.c2d(control.ss(sys, inputs=inputs, outputs=outputs), T, "tustin")

    chain = control.interconnect(
        [
            tustin(-1 / (s / w8 + 1) * I3, sig("phi"), sig("y_att")),
            tustin(-1 / (s / w200 + 1) * I3, sig("w"), sig("y_rate")),
            control.c2d(ref_controller, T, "zoh"),
            tustin(control.tf(b, a) * I3, sig("u_K"), sig("u")),
            tustin(w200**2 / (s**2 + 1.4 * w200 * s + w200**2) * I3, sig("u"), sig("T_rw")),
        ],
        inputs=sig("phi") + sig("w"),
        outputs=sig("T_rw"),
    )
    closed = control.feedback(G, chain, sign=+1)  # chain already carries y = -sensors
    z_ref = closed.poles()
    loop = sampled_loop((A, B, C, D), ControllerSystem.from_statespace(ref_controller), spec)
    z_mine = np.linalg.eigvals(loop.closed_loop())
    z_mine = z_mine[np.abs(z_mine) > 1e-12]  # the held-command buffer (no delay: z = 0)
    assert _matched(z_mine, z_ref) < 1e-7
    # the loop gain at z: broken at the wheel input, python-control's series
    omega = np.array([0.05, 0.6, 3.0])
    open_loop = control.series(G, chain)
    L_ref = -np.moveaxis(open_loop(np.exp(1j * omega * T)), -1, 0)
    L_mine = loop.loop_gain(omega)
    np.testing.assert_allclose(L_mine, L_ref, rtol=1e-7, atol=1e-9 * np.abs(L_ref).max())


def test_static_gain_is_the_degenerate_case():
    """``ControllerSystem.static(K)`` gives the static code path's numbers: the same closed-loop
    matrices and responses bit for bit, and the exact sampled loop of the Tustin transform of
    the continuous chain (the former implementation) to rounding."""
    A, B, C, D = _plant()
    K = baseline_gains(J) * np.array([20, 20, 20, 4, 4, 4])
    K[0, 4] = 3.0
    static = ControllerSystem.static(K)
    assert static.is_static and static.nstates == 0
    np.testing.assert_array_equal(static.K, K)
    W = weighted_interconnection(plant_statespace(A, B, C, D))
    for mine, theirs in zip(
        (lambda M: (M.A, M.B, M.C, M.D))(W.close(static)),
        (lambda M: (M.A, M.B, M.C, M.D))(W.close(K)),
        strict=True,
    ):
        np.testing.assert_array_equal(mine, theirs)
    plant = LFR.from_ss(A, B, C, D)
    np.testing.assert_array_equal(close_loop(plant, static).M, close_loop(plant, K).M)
    loop = LoopResponse(plant_statespace(A[None], B[None], C[None], D[None]),
                        DesignSpecification())  # fmt: skip
    omega = np.geomspace(1e-3, 30, 7)[None]
    np.testing.assert_array_equal(loop.response(static, omega), loop.response(K, omega))
    np.testing.assert_array_equal(loop.loop_gain(static, omega), loop.loop_gain(K, omega))
    # exact sampled loop: Tustin of the continuous chain with K (the static path before)
    spec = DesignSpecification()
    T = 1 / spec.flight_software_rate_hz
    Ac, Bc, Cc, Dc, _ = scipy.signal.cont2discrete(controller_chain(K, spec), T, "bilinear")
    mine = sampled_loop((A, B, C, D), K, spec)
    for M, R in zip(mine.controller, (Ac, Bc, Cc, Dc), strict=True):
        assert M.shape == R.shape
    omega = np.array([0.01, 0.3, 2.0, 9.0])
    z = np.exp(1j * omega * T)
    chain_mine = [
        mine.controller[2]
        @ np.linalg.solve(zk * np.eye(Ac.shape[0]) - mine.controller[0], mine.controller[1])
        + mine.controller[3]
        for zk in z
    ]
    chain_ref = [Cc @ np.linalg.solve(zk * np.eye(Ac.shape[0]) - Ac, Bc) + Dc for zk in z]
    np.testing.assert_allclose(chain_mine, chain_ref, rtol=1e-12, atol=1e-12 * np.abs(Dc).max())
    z_mine = np.linalg.eigvals(mine.closed_loop())
    z_mine = z_mine[np.abs(z_mine) > 1e-12]  # the held-command buffer (no delay: z = 0)
    z_ref = np.linalg.eigvals(_former_closed_loop(mine, (Ac, Bc, Cc, Dc)))
    assert _matched(z_mine, z_ref) < 1e-10


def _former_closed_loop(loop, chain):
    """The sampled loop's closed-loop matrix with another controller chain (no delay)."""
    Ac, Bc, Cc, Dc = chain
    Phi, G0, Cp = loop.Phi, loop.Gamma0, loop.C
    return np.block([[Phi + G0 @ Dc @ Cp, G0 @ Cc], [Bc @ Cp, Ac]])


def test_zero_order_hold_and_its_inverse():
    """``discretize`` is python-control's zero-order hold; ``continuous`` inverts it exactly;
    a static gain is the same at any rate; a discrete controller at another rate is refused."""
    sys = _second_order()
    c = ControllerSystem.from_statespace(sys)
    T = 1 / RATE_HZ
    d = c.discretize(T)
    ref = control.c2d(sys, T, "zoh")
    for mine, theirs in zip((d.A, d.B, d.C, d.D), (ref.A, ref.B, ref.C, ref.D), strict=True):
        np.testing.assert_allclose(mine, theirs, rtol=1e-12, atol=1e-14)
    back = d.continuous()
    assert back.sampling_time == 0 and back.equals(c, rtol=1e-10)
    assert ControllerSystem.from_statespace(ref).equals(d)
    with pytest.raises(ValueError, match="not at the flight software's 20 Hz"):
        d.discretize(0.05)
    static = ControllerSystem.static(np.ones((3, 6)))
    np.testing.assert_array_equal(static.discretize(T).D, static.D)
    with pytest.raises(ValueError, match="no static gain"):
        _ = c.K


def _write_dynamic(path, sys, **extra):
    record = {
        "structure": "pid",
        "status": "ok",
        "gamma": 0.9,
        "controller": {
            "structure": "pid",
            "state_space": {
                "A": sys.A.tolist(),
                "B": sys.B.tolist(),
                "C": sys.C.tolist(),
                "D": sys.D.tolist(),
                "inputs": list(sys.input_labels),
                "outputs": list(sys.output_labels),
                "sampling_time_s": 0.0,
            },
        },
        **extra,
    }
    path.write_text(json.dumps(record))
    return path


def test_load_a_pid_controller_json(tmp_path):
    """A PID record (``state_space`` on ``y_att`` only) is read into the 6-input controller
    whose ``y_rate`` columns are zero; its response is the PID's."""
    sys = _pid()
    c = load_controller(_write_dynamic(tmp_path / "controller.json", sys))
    assert c.structure == "pid" and not c.is_static and c.system.nstates == sys.nstates
    np.testing.assert_array_equal(c.system.B[:, 3:], 0.0)
    np.testing.assert_array_equal(c.system.D[:, 3:], 0.0)
    s = 1j * np.array([0.01, 0.5, 4.0])
    np.testing.assert_allclose(
        c.system.response(s)[:, :, :3], np.moveaxis(sys(s), -1, 0), rtol=1e-10, atol=1e-12
    )
    with pytest.raises(ValueError, match="no static gain"):
        _ = c.K
    # the analysis records it in summary.json and reads it back
    assert recorded_controller({"state_space": c.system.record()}, None).equals(c.system)
    again = Controller(c.system, c.spec, "x", "y", structure="pid")
    assert again.system is c.system


def test_bad_controller_files_name_the_culprit(tmp_path):
    sys = _pid()
    no_ss = tmp_path / "no_ss.json"
    no_ss.write_text(json.dumps({"structure": "pid", "controller": {}}))
    with pytest.raises(ValueError, match="controller.state_space"):
        load_controller(no_ss)
    bad_name = control.ss(sys.A, sys.B, sys.C, sys.D, inputs=["phi[0]", "y_att[1]", "y_att[2]"],
                          outputs=CONTROLS)  # fmt: skip
    with pytest.raises(ValueError, match=r"'phi\[0\]' is not a measurement"):
        load_controller(_write_dynamic(tmp_path / "bad_name.json", bad_name))
    unknown = tmp_path / "unknown.json"
    unknown.write_text(json.dumps({"structure": "lqg", "controller": {}}))
    with pytest.raises(ValueError, match="unknown structure 'lqg'"):
        load_controller(unknown)
