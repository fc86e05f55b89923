"""The Drake flight software with a dynamic controller (issue 31, item 3).

Closed loop on a linear rigid plant, simulated by Drake, against the same sampled-data loop
built independently with python-control (``c2d``: zero-order hold plant and controller, Tustin
sensors and filters) and simulated by ``control.initial_response`` (a ``dlsim``); the
controller's state is carried from one sample to the next. The static gain is the degenerate
case: the same update as the former static code path.
"""

import control
import numpy as np
import pytest
import scipy.signal

from oos_drake.control.baseline import baseline_gains
from oos_drake.control.interconnection import CONTROLS, MEASUREMENTS, ControllerSystem
from oos_drake.control.tunable import TunablePID

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402
from pydrake.systems.primitives import LinearSystem  # noqa: E402

from oos_drake.multibody.flight_software import (  # noqa: E402
    FlightSoftware,
    FlightSoftwareDesign,
)

J = np.diag([100.0, 120.0, 80.0])
RATE_HZ = 10.0


def sig(name):
    return [f"{name}[{i}]" for i in range(3)]


def _pid() -> control.StateSpace:
    """PID per axis on ``y_att`` (derivative filter, first-order roll-off): 4 states/axis."""
    K = baseline_gains(J, 2 * np.pi * 0.05, 0.8)
    pid = TunablePID(
        "C",
        MEASUREMENTS[:3],
        CONTROLS,
        kp=np.diag(K[:, :3]),
        ki=0.05 * np.diag(K[:, :3]),
        kd=np.diag(K[:, 3:]),
        tf=0.3,
        rolloff_order=1,
        rolloff_frequency=2 * np.pi * 2.0,
    )
    return pid.statespace(pid.initial_parameters())


def _second_order() -> control.StateSpace:
    """A hand-built 2-state controller on ``y`` (6) with a PD feedthrough."""
    rng = np.random.default_rng(3)
    K = baseline_gains(J, 2 * np.pi * 0.05, 0.8)
    A = np.array([[-2.0, 0.7], [-0.7, -3.0]])
    return control.ss(
        A, 0.05 * rng.standard_normal((2, 6)), 2.0 * rng.standard_normal((3, 2)), K,
        inputs=MEASUREMENTS, outputs=CONTROLS,
    )  # fmt: skip


def _reference(controller: control.StateSpace, x0, samples: int):
    """The sampled loop with python-control: attitudes ``phi_k`` at the samples."""
    T = 1 / RATE_HZ
    I3 = np.eye(3)
    A = np.block([[np.zeros((3, 3)), I3], [np.zeros((3, 6))]])
    B = np.vstack([np.zeros((3, 3)), np.linalg.inv(J)])
    G = control.c2d(control.ss(A, B, np.eye(6), 0, inputs=sig("T"),
                               outputs=sig("phi") + sig("w")), T, "zoh")  # fmt: skip
    s = control.tf("s")
    w8, w200 = 2 * np.pi * 8, 2 * np.pi * 200
    b, a = scipy.signal.butter(4, 2 * np.pi * 0.7, analog=True)

    def tustin(sys, inputs, outputs):
        return control.c2d(control.ss(sys, inputs=inputs, outputs=outputs), T, "tustin")

    chain = control.interconnect(
        [
            tustin(-1 / (s / w8 + 1) * I3, sig("phi"), sig("y_att")),
            tustin(-1 / (s / w200 + 1) * I3, sig("w"), sig("y_rate")),
            control.c2d(controller, T, "zoh"),
            tustin(control.tf(b, a) * I3, sig("u_K"), sig("u")),
            tustin(w200**2 / (s**2 + 1.4 * w200 * s + w200**2) * I3, sig("u"), sig("T_rw")),
        ],
        inputs=sig("phi") + sig("w"),
        outputs=sig("T_rw"),
    )
    closed = control.feedback(G, chain, sign=+1)  # the chain carries y = -sensors
    X0 = np.concatenate([x0, np.zeros(closed.nstates - 6)])  # plant states first
    assert np.max(np.abs(closed.poles())) < 1.0
    response = control.initial_response(closed, T=np.arange(samples) * T, X0=X0)
    return response.outputs[:3].T


def _drake_loop(controller, x0, samples: int):
    """Drake: the flight software closing a linear rigid body (``q = [rpy; 0]``,
    ``v = [w; 0]``, ``vdot = J^-1 tau``), the plant's attitude at each sample."""
    T = 1 / RATE_HZ
    design = FlightSoftwareDesign.create(controller, RATE_HZ, torque_limit=1e6)
    builder = DiagramBuilder()
    fsw = builder.AddSystem(FlightSoftware(design, 6, 6, 0, 0))
    A = np.zeros((12, 12))
    A[:6, 6:] = np.eye(6)
    B = np.zeros((12, 6))
    B[6:9, :3] = np.linalg.inv(J)
    plant = builder.AddSystem(LinearSystem(A, B, np.eye(12), np.zeros((12, 6))))
    builder.Connect(plant.get_output_port(), fsw.get_input_port(0))
    builder.Connect(fsw.GetOutputPort("generalized_force"), plant.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    state = np.zeros(12)
    state[:3], state[6:9] = x0[:3], x0[3:]
    plant.GetMyMutableContextFromRoot(context).SetContinuousState(state)
    integrator = simulator.get_mutable_integrator()
    integrator.set_target_accuracy(1e-12)
    integrator.set_maximum_step_size(T / 4)
    out = []
    for k in range(samples):
        simulator.AdvanceTo(k * T)
        out.append(plant.GetMyContextFromRoot(context).get_continuous_state_vector().
                   CopyToVector()[:3])  # fmt: skip
    return np.array(out), fsw, design


@pytest.mark.parametrize("make", [_pid, _second_order], ids=["pid", "second-order"])
def test_flight_software_runs_a_dynamic_controller_as_the_sampled_loop(make):
    """Small angles (1e-8 rad): the flight software's rotations (``R_WB = I + O(phi)``) are
    the identity to 1e-8 relative, so the Drake run is the linear sampled loop to that order."""
    sys = make()
    x0 = 1e-8 * np.array([1.0, -0.6, 0.4, 0.0, 2e-2, -1e-2])
    samples = 200
    ref = _reference(sys, x0, samples)
    phi, fsw, design = _drake_loop(ControllerSystem.from_statespace(sys), x0, samples)
    assert design.controller.nstates == sys.nstates
    assert fsw.state_slices["controller"].stop - fsw.state_slices["controller"].start == sys.nstates
    scale = np.abs(ref).max()
    assert scale > 5e-9  # a transient, not a zero run
    np.testing.assert_allclose(phi, ref, rtol=0, atol=1e-7 * scale)


def test_static_gain_is_the_degenerate_case():
    """A static gain: no controller state; the merged update equals the former static one
    (sensors, ``u_K = K_p y_att + K_d y_rate``, roll-off, written out here)."""
    rng = np.random.default_rng(5)
    K = rng.standard_normal((3, 6))
    design = FlightSoftwareDesign.create(K, RATE_HZ)
    same = FlightSoftwareDesign.create(ControllerSystem.static(K), RATE_HZ)
    assert design.controller.nstates == 0
    np.testing.assert_array_equal(design.K, K)
    a, b = FlightSoftware(design, 6, 6, 0, 0), FlightSoftware(same, 6, 6, 0, 0)
    np.testing.assert_array_equal(a.linear_update().A, b.linear_update().A)
    np.testing.assert_array_equal(a.linear_update().D, b.linear_update().D)
    # the former stage-1 arithmetic, block by block
    d = design
    x = rng.standard_normal(d.star_tracker.nstates + d.gyro.nstates + d.rolloff.nstates)
    z = rng.standard_normal(12)
    n1, n2 = d.star_tracker.nstates, d.gyro.nstates
    x_sst, phi_sst = d.star_tracker.step(x[:n1], z[0:3])
    x_gyro, w_gyro = d.gyro.step(x[n1 : n1 + n2], z[3:6])
    y_att = -(phi_sst + d.noise_star_tracker * z[6:9])
    y_rate = -(w_gyro + d.noise_gyro * z[9:12])
    x_ro, u = d.rolloff.step(x[n1 + n2 :], K[:, :3] @ y_att + K[:, 3:] @ y_rate)
    out, u_mine = a._stage1_reference(x, z)
    np.testing.assert_array_equal(out, np.concatenate([x_sst, x_gyro, x_ro]))
    np.testing.assert_array_equal(u_mine, u)
