"""The exact sampled loop of ``control.sampled`` runs the flight software's discrete controller."""

import numpy as np
import pytest

from oos_drake.control import components as comp
from oos_drake.control.sampled import sampled_loop

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")


def _response(block, z):
    n = block.A.shape[0]
    if n == 0:
        return block.D
    return block.C @ np.linalg.solve(z * np.eye(n) - block.A, block.B) + block.D


def test_controller_of_the_exact_loop_is_the_flight_softwares():
    from oos_drake.multibody.flight_software import FlightSoftwareDesign

    spec = comp.DesignSpecification()
    K = np.arange(18.0).reshape(3, 6) / 7 + 1
    design = FlightSoftwareDesign.create(K, spec.flight_software_rate_hz, spec=spec)
    plant = (np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((3, 0)), np.eye(3))
    Ac, Bc, Cc, Dc = sampled_loop(plant, K, spec).controller
    assert design.period == pytest.approx(1.0 / spec.flight_software_rate_hz)
    for f_hz in (0.05, 0.83, 3.0):
        z = np.exp(1j * 2 * np.pi * f_hz * design.period)
        ours = Cc @ np.linalg.solve(z * np.eye(Ac.shape[0]) - Ac, Bc) + Dc
        # flight software: y = -[SST phi; GYRO w], u = F_ro K y, T_rw = RW u
        sensors = np.zeros((6, 6), dtype=complex)
        sensors[:3, :3] = -_response(design.star_tracker, z)
        sensors[3:, 3:] = -_response(design.gyro, z)
        theirs = _response(design.wheels, z) @ _response(design.rolloff, z) @ K @ sensors
        np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-12)
