"""``[control] rate_hz``: the controller is tuned discrete on the loop the flight software runs.

Checked against independent constructions: the discrete weighted interconnection closed by a
discrete controller has the poles and the loop gain of the exact sampled-data loop of
:func:`oos_drake.control.sampled.sampled_loop` (built another way: plant hold integrals, the
controller chain, the loop gain from the bilinear frequency map); a PID tuned at 10 Hz is
written to ``controller.json`` and read back by the Drake flight software unchanged, and its
margins on the exact sampled loop (loop at a time, the balanced disk margin from its closed
form ``1 / max |S_ii - 1/2|``) are the goal values the tuning reports.
"""

import dataclasses
import json

import control
import numpy as np
import pytest
import scipy.optimize

from oos_drake.control.baseline import baseline_gains, inertia_from_plant
from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import (
    CONTROLS,
    MEASUREMENTS,
    ControllerSystem,
    read_controller,
)
from oos_drake.control.plants import synthetic_flexible_plants
from oos_drake.control.report import tuning_record, write_tuning
from oos_drake.control.requirements import (
    tune_to_requirements,
    tuning_specification,
)
from oos_drake.control.sampled import sampled_interconnection, sampled_loop
from oos_drake.control.systune import SystuneOptions
from oos_drake.control.tunable import TunablePID
from oos_drake.scenario.data import load_scenario

T = 0.1  # [s] the paper's 10 Hz flight software


def _plants(n=2):
    plants = synthetic_flexible_plants(n, modes=1, uncertain=False)
    nominal = np.broadcast_to(plants.nominal_values, (plants.size, len(plants.parameters)))
    return plants, plants.evaluate(np.arange(plants.size), nominal)


def _matched(a, b, tol):
    """Every value of ``a`` within ``tol`` of one of ``b`` and conversely (multisets of poles
    with repeated values per axis)."""
    d = np.abs(a[:, None] - b[None, :])
    return d.min(axis=1).max() < tol and d.min(axis=0).max() < tol


def _discrete_pid():
    pid = TunablePID(
        "C", MEASUREMENTS[:3], CONTROLS, kp=20.0, ki=0.5, kd=200.0, tf=0.3, sampling_time=T
    )
    return ControllerSystem.from_statespace(pid.statespace(pid.initial_parameters()))


def _closed(P, i, K: ControllerSystem):
    """Closed-loop ``A`` of the discrete interconnection ``P`` (model ``i``) with ``u_K = K y``."""
    rows = [P.outputs.index(s) for s in MEASUREMENTS]
    cols = [P.inputs.index(s) for s in CONTROLS]
    A, B2, C2 = P.A[i], P.B[i][:, cols], P.C[i][rows]
    assert np.allclose(P.D[i][np.ix_(rows, cols)], 0.0)  # strictly proper: no algebraic loop
    return np.block([[A + B2 @ K.D @ C2, B2 @ K.C], [K.B @ C2, K.A]])


@pytest.mark.parametrize("controller", ["static", "pid"])
def test_discrete_interconnection_is_the_exact_sampled_loop(controller):
    _, models = _plants()
    spec = DesignSpecification()
    K0 = baseline_gains(inertia_from_plant(models)[0])
    K = ControllerSystem.static(K0).discretize(T)
    K = K if controller == "static" else _discrete_pid()
    P = sampled_interconnection(models, spec)
    a, b = spec.disturbance_denominator
    w_ext = (1 - b * T / (2 * a)) / (1 + b * T / (2 * a))  # Tustin pole of W_n,ext (not fed back)
    omega = np.array([0.05, 0.3, 1.0, 4.0, 12.0, 30.0])  # [rad/s], below pi / T
    rows = [P.outputs.index(s) for s in MEASUREMENTS]
    cols = [P.inputs.index(s) for s in CONTROLS]
    for i in range(models.A.shape[0]):
        z = np.linalg.eigvals(_closed(P, i, K))
        z = np.delete(z, np.argsort(np.abs(z - w_ext))[:3])
        loop = sampled_loop((models.A[i], models.B[i], models.C[i], models.D[i]), K, spec)
        reference = np.linalg.eigvals(loop.closed_loop())
        assert _matched(z[np.abs(z) > 1e-9], reference[np.abs(reference) > 1e-9], 1e-7)
        # loop broken at u_K: u_K = K(z) P_yu(z) u_K, so L = -K P_yu (the roll-off and wheels
        # are the same scalar filter on every axis: the same loop as at the wheel input)
        zs = np.exp(1j * omega * T)
        Pyu = np.stack(
            [
                P.C[i][rows] @ np.linalg.solve(zk * np.eye(P.A.shape[-1]) - P.A[i], P.B[i][:, cols])
                for zk in zs
            ]
        )
        Kz = K.response(zs) if not K.is_static else np.broadcast_to(K.D, (zs.size, 3, 6))
        assert np.allclose(-Kz @ Pyu, loop.loop_gain(omega), rtol=1e-8, atol=1e-10)


def _disk_margin(loop, channel):
    """Balanced disk margin of ``channel`` opened, the others closed: ``1 / max |S_ii - 1/2|``
    with ``S = (I + L)^-1`` of the exact sampled loop (dense grid, then refined)."""

    def distance(w):
        L = loop.loop_gain(np.atleast_1d(w))
        S = np.linalg.inv(np.eye(3) + L)
        return np.abs(S[:, channel, channel] - 0.5)

    grid = np.geomspace(1e-3, np.pi / T * (1 - 1e-6), 5000)
    values = distance(grid)
    k = int(np.argmax(values))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    best = scipy.optimize.minimize_scalar(
        lambda w: -distance(w)[0], bounds=(lo, hi), method="bounded", options={"xatol": 1e-10}
    )
    return 1.0 / max(values[k], -best.fun)


@pytest.mark.slow
def test_pid_tuned_at_the_rate_is_what_flies_and_meets_its_margins(tmp_path):
    plants, models = _plants()
    requirements = dataclasses.replace(
        load_scenario().control,
        structure="pid",
        order=None,
        rate_hz=1.0 / T,
        gain_margin_db=6.0,
        phase_margin_deg=30.0,
    )
    spec = DesignSpecification()
    K0 = baseline_gains(inertia_from_plant(models)[0])
    options = SystuneOptions(max_iterations=20)
    result = tune_to_requirements(plants, K0, spec, requirements, options)
    assert result.sampling_time == T and result.controller.dt == T
    record = tuning_record(
        result, requirements, K0, plants, tuning_specification(spec, requirements), options
    )
    path = write_tuning(tmp_path, record)["controller"]
    _, stored = read_controller(path)
    tuned = ControllerSystem.from_statespace(result.controller)
    assert stored.is_discrete and stored.sampling_time == T and stored.equals(tuned)
    pytest.importorskip("pydrake")
    from oos_drake.multibody.flight_software import FlightSoftwareDesign

    flies = FlightSoftwareDesign.create(stored, 1.0 / T, spec=spec).controller
    for name in "ABCD":  # the flight software runs the tuned matrices, not a re-discretization
        assert np.array_equal(getattr(flies, name), getattr(stored, name))
    # the goal's value is the margin of the exact sampled-data loop (loop at a time)
    goal = result.goal(f"margins at {requirements.loop_opening}")
    worst = min(
        _disk_margin(
            sampled_loop((models.A[i], models.B[i], models.C[i], models.D[i]), stored, spec), c
        )
        for i in range(plants.size)
        for c in range(3)
    )
    assert worst == pytest.approx(goal.details["disk_margin"], rel=1e-5)
    if result.status == "ok":
        assert goal.details["gain_margin_db"] >= 6.0 - 1e-4
        assert goal.details["phase_margin_deg"] >= 30.0 - 1e-4
    json.loads(path.read_text())  # valid JSON
    assert control.isdtime(result.controller, strict=True)


def test_zero_order_hold_inflates_a_pid_derivative():
    """Why the flight software must not re-discretize a continuous PID: at ``Tf = T`` the
    hold of ``s / (Tf s + 1)`` is ``(z - 1) / (Tf (z - e^-1))`` (closed form), gain
    ``2 / (1 + e^-1) = 1.462`` times ``1 / Tf`` at the Nyquist frequency, where the
    continuous derivative never exceeds ``1 / Tf``."""
    held = control.c2d(control.tf([1.0, 0.0], [T, 1.0]), T, "zoh")
    assert abs(held(-1.0)) * T == pytest.approx(2.0 / (1.0 + np.exp(-1.0)), rel=1e-12)
    w = np.pi / (2 * T)  # a quarter of the sample rate
    ratio = abs(held(np.exp(1j * w * T))) / abs(1j * w / (1j * w * T + 1.0))
    assert ratio == pytest.approx(1.57, abs=0.005)
