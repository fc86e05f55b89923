"""The flight software's sample-and-hold: the rational model against the exact sampled loop."""

import dataclasses

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import block_diag

from oos_drake.control import components as comp
from oos_drake.control.baseline import baseline_gains, inertia_from_plant
from oos_drake.control.interconnection import weighted_interconnection
from oos_drake.control.plants import synthetic_flexible_plants
from oos_drake.control.sampled import (
    continuous_poles,
    controller_chain,
    sampled_loop,
    spectral_abscissa,
)


def _hold_response(spec, omega):
    A, B, C, D = comp.sample_hold(spec)
    s = 1j * omega
    X = np.linalg.solve(
        s[:, None, None] * np.eye(A.shape[0]) - A, np.broadcast_to(B, (s.size,) + B.shape)
    )
    return (C @ X)[:, 0, 0] + D[0, 0]


@pytest.mark.parametrize("delay", [0.0, 0.03])
def test_hold_model_against_the_exact_hold(delay):
    spec = comp.DesignSpecification(sampled=True, computation_delay_s=delay)
    T = 1.0 / spec.flight_software_rate_hz
    omega = 2 * np.pi * np.array([0.01, 0.1, 0.5, 0.83, 1.5])
    exact = (1 - np.exp(-1j * omega * T)) / (1j * omega * T) * np.exp(-1j * omega * delay)
    ours = _hold_response(spec, omega)
    # the (2, 2) Pade error is O((w T)^4) (about (w T)^4 / 720): 1e-4 at 0.83 Hz and 10 Hz
    bound = ((omega * T) ** 4 + (omega * delay) ** 4) / 700
    assert np.all(np.abs(ours / exact - 1) <= bound)
    # and it carries the half-sample lag: 15 deg at 0.83 Hz (the number)
    assert np.degrees(-np.angle(ours[3])) == pytest.approx(
        np.degrees(omega[3] * (T / 2 + delay)), abs=0.05
    )


def test_no_hold_in_the_continuous_loop():
    A, B, C, D = comp.sample_hold(comp.DesignSpecification())
    assert A.shape == (0, 0) and D[0, 0] == 1.0


def _rigid_plant(J):
    """``wdot = J^-1 T``: no states, closed forms for the ZOH."""
    return (np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((3, 0)), np.linalg.inv(J))


def test_zoh_of_the_double_integrator_is_the_closed_form():
    J = np.diag([200.0, 300.0, 250.0])
    spec = comp.DesignSpecification()
    loop = sampled_loop(_rigid_plant(J), baseline_gains(J), spec)
    T = loop.period
    # states [w; phi]: w+ = w + T J^-1 u, phi+ = phi + T w + T^2/2 J^-1 u
    Phi = np.block([[np.eye(3), np.zeros((3, 3))], [T * np.eye(3), np.eye(3)]])
    Gamma = np.vstack([T * np.linalg.inv(J), T**2 / 2 * np.linalg.inv(J)])
    np.testing.assert_allclose(loop.Phi, Phi, atol=1e-14)
    np.testing.assert_allclose(loop.Gamma0, Gamma, atol=1e-14)
    assert np.all(loop.Gamma1 == 0) and loop.shift == 0


@pytest.mark.parametrize("delay", [0.0, 0.13])
def test_discrete_closed_loop_matches_a_simulation_of_the_hybrid_loop(delay):
    """A^k x0 of the discrete closed loop against solve_ivp of the continuous plant driven by
    the controller's held outputs (controller stepped separately, delay applied on the
    continuous time axis)."""
    plants = synthetic_flexible_plants(2, modes=2, uncertain=False).nominal()
    P = (plants.A[0], plants.B[0], plants.C[0], plants.D[0])
    J = inertia_from_plant(plants)[0]
    K = baseline_gains(J) * np.array([40, 40, 40, 6, 6, 6])
    spec = comp.DesignSpecification(computation_delay_s=delay)
    loop = sampled_loop(P, K, spec)
    A_cl = loop.closed_loop()
    n, T = loop.Phi.shape[0], loop.period
    rng = np.random.default_rng(1)
    x0 = np.zeros(A_cl.shape[0])
    x0[:n] = rng.normal(size=n) * 1e-3  # plant and integrators; controller and buffer at rest
    # independent hybrid simulation
    from oos_drake.control.sampled import plant_with_integrators

    Aa, Ba, Ca = plant_with_integrators(P)
    Ac, Bc, Cc, Dc = loop.controller
    xc, xp = np.zeros(Ac.shape[0]), x0[:n].copy()
    commands = []  # (time it reaches the plant, torque)
    steps = 25
    states = [xp.copy()]
    applied = np.zeros(3)
    for k in range(steps):
        y = Ca @ xp
        u = Cc @ xc + Dc @ y
        xc = Ac @ xc + Bc @ y
        commands.append((k * T + delay, u))
        # integrate over [kT, (k+1)T] with the held torque switching at command times
        edges = sorted({k * T, (k + 1) * T, *[c for c, _ in commands if k * T < c < (k + 1) * T]})
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            for c, value in commands:
                if c <= a + 1e-12:
                    applied = value
            sol = solve_ivp(
                lambda _t, x, u=applied: Aa @ x + Ba @ u, (a, b), xp, rtol=1e-11, atol=1e-14
            )
            xp = sol.y[:, -1]
        states.append(xp.copy())
    x = x0.copy()
    scale = np.max(np.abs(np.array(states)))
    for k in range(steps + 1):
        np.testing.assert_allclose(x[:n], states[k], atol=1e-7 * scale)
        x = A_cl @ x


def _gain_boundary(abscissa, lo=0.1, hi=40.0, iterations=50):
    assert abscissa(lo) < 0 < abscissa(hi)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if abscissa(mid) >= 0 else (mid, hi)
    return 0.5 * (lo + hi)


def test_hold_model_predicts_the_sampled_gain_boundary():
    """Scale the gain until the loop goes unstable: the continuous loop misses the 10 Hz hold,
    the rational model lands within 2 % of the exact sampled loop."""
    plants = synthetic_flexible_plants(2, modes=2, uncertain=False).nominal()
    P = (plants.A[1], plants.B[1], plants.C[1], plants.D[1])
    J = inertia_from_plant(plants)[1]
    K = baseline_gains(J) * np.array([40, 40, 40, 6, 6, 6])
    spec = comp.DesignSpecification()
    model = dataclasses.replace(spec, sampled=True)
    exact = _gain_boundary(lambda g: spectral_abscissa(sampled_loop(P, g * K, spec).poles()))
    ours = _gain_boundary(lambda g: spectral_abscissa(continuous_poles(P, g * K, model)))
    cont = _gain_boundary(lambda g: spectral_abscissa(continuous_poles(P, g * K, spec)))
    assert abs(ours / exact - 1) < 0.02
    assert abs(ours / exact - 1) < 0.5 * abs(cont / exact - 1)


def test_closed_loop_with_hold_model_keeps_the_interconnection_structure():
    """The hold adds 2 states per axis and leaves the nominal response at DC unchanged."""
    plants = synthetic_flexible_plants(2, modes=2, uncertain=False).nominal()
    J = inertia_from_plant(plants)[0]
    K = baseline_gains(J)
    plain = weighted_interconnection(plants).close(K)
    held = weighted_interconnection(plants, comp.DesignSpecification(sampled=True)).close(K)
    assert held.A.shape[-1] == plain.A.shape[-1] + 6
    w = np.array([1e-4])
    np.testing.assert_allclose(held.freqresp(w), plain.freqresp(w), rtol=1e-5, atol=1e-9)
    # the hold is also in the modal loop formula of the synthesis
    ours = weighted_interconnection(plants, comp.DesignSpecification(sampled=True)).loop
    omega = np.broadcast_to(np.array([0.3, 2.0, 9.0]), (2, 3))
    np.testing.assert_allclose(
        ours.response(K, omega), held.freqresp(np.array([0.3, 2.0, 9.0])), rtol=1e-9, atol=1e-12
    )


def test_tustin_of_the_chain_is_the_chain_of_tustins():
    """The flight software discretizes block by block; the exact loop discretizes the chain."""
    import scipy.signal

    spec = comp.DesignSpecification()
    K = np.arange(18.0).reshape(3, 6) + 1
    T = 1.0 / spec.flight_software_rate_hz
    Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete(controller_chain(K, spec), T, "bilinear")
    z = np.exp(1j * 2 * np.pi * 1.3 * T)
    whole = Cd @ np.linalg.solve(z * np.eye(Ad.shape[0]) - Ad, Bd) + Dd

    def tustin(siso):
        a, b, c, d, _ = scipy.signal.cont2discrete(siso, T, "bilinear")
        return (c @ np.linalg.solve(z * np.eye(a.shape[0]) - a, b) + d)[0, 0]

    sst = tustin(comp.first_order_lowpass(spec.star_tracker_cutoff_hz))
    gyro = tustin(comp.first_order_lowpass(spec.gyro_cutoff_hz))
    ro = tustin(comp.butterworth(spec.rolloff_order, spec.rolloff_cutoff_hz))
    rw = tustin(comp.second_order(spec.wheel_frequency_hz, spec.wheel_damping))
    blocks = rw * ro * (-K @ block_diag(sst * np.eye(3), gyro * np.eye(3)))
    np.testing.assert_allclose(whole, blocks, rtol=1e-9)


def test_bad_input():
    with pytest.raises(ValueError, match="computation_delay_s"):
        comp.DesignSpecification(computation_delay_s=-1.0)
    with pytest.raises(ValueError, match="flight_software_rate_hz"):
        comp.DesignSpecification(flight_software_rate_hz=0.0)
    with pytest.raises(ValueError, match="3x3"):
        sampled_loop(
            (np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((2, 0)), np.eye(2)), np.ones((3, 6))
        )
