"""systune on a PID for a two-mass flexible plant, checked against independent computations.

Every goal value of a result is recomputed without the systune code: closed loops from
python-control's ``interconnect`` of the plant and the returned controller, H-infinity norms
with slycot's ``ab13dd``, H2 norms with ``ab13bd``, margins with ``stability_margins`` and the
balanced disk margin's closed form ``1 / max |S - 1/2|`` on a dense grid, pole damping from
``numpy.linalg.eig``. The tuned PID is compared with a brute-force search over a grid of its
four parameters, written with polynomial transfer functions (no state space at all).
"""

import itertools

import control
import numpy as np
import pytest
from slycot import ab13bd, ab13dd

from oos_drake.control.goals import Margins, Poles, Variance, WeightedGain, disk_alpha
from oos_drake.control.margins import disk_gain_phase
from oos_drake.control.systune import SystuneOptions, systune
from oos_drake.control.tunable import FixedBlock, TunableGain, TunablePID, TunableSS

#: Two equal masses m1 = m2 = 1 [kg], spring k [N/m], damper c [N s/m]; force u on mass 1,
#: disturbance d through a/(s + a) on mass 2, position y of mass 2 measured (non-collocated).
SPRINGS = (0.5, 1.0, 2.0)
DAMPER = 0.1
FILTER = 0.2  # a [rad/s]


def two_mass(k, c=DAMPER, a=FILTER):
    A = np.array(
        [[0, 0, 1, 0, 0], [0, 0, 0, 1, 0], [-k, k, -c, c, 0], [k, -k, c, -c, 1], [0, 0, 0, 0, -a]],
        float,
    )
    B = np.array([[0, 0], [0, 0], [1, 0], [0, 0], [0, a]], float)
    C = np.array([[0, 1, 0, 0, 0], [0, -1, 0, 0, 0]], float)
    return control.ss(A, B, C, np.zeros((2, 2)), inputs=["u", "d"], outputs=["y", "e"])


PLANTS = [two_mass(k) for k in SPRINGS]


def pid(**kwargs):
    return TunablePID("C", "e", "u", kp=0.1, ki=1e-3, kd=0.3, tf=1.0, **kwargs)


def ab13dd_norm(sys):
    A, B, C, D = (np.atleast_2d(M) for M in (sys.A, sys.B, sys.C, sys.D))
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    dico = "D" if sys.dt else "C"
    return ab13dd(dico, "I", "N", "D", n, m, p, A, np.eye(n), B, C, D, tol=1e-10)[0]


def closed_loop(plant, controller, inputs, outputs):
    """python-control's own interconnection of the plant and the tuned controller."""
    return control.interconnect([plant, controller], inplist=inputs, outlist=outputs)


def loop_at_u(plant, controller):
    """``L`` of the loop broken at u, negative feedback: ``u = -L u``."""
    return -controller * plant[plant.output_labels.index("e"), plant.input_labels.index("u")]


def disk_margin(L, omega):
    """Balanced disk margin ``1 / max |S - 1/2|``, ``S = 1 / (1 + L)`` (closed form)."""
    Lw = np.squeeze(L(1j * omega if not L.dt else np.exp(1j * omega * L.dt)))
    return 1.0 / np.max(np.abs(1.0 / (1.0 + Lw) - 0.5))


OMEGA = np.logspace(-4, 3, 20000)


@pytest.fixture(scope="module")
def soft_result():
    return systune(
        PLANTS,
        pid(),
        [WeightedGain("d", "y")],
        options=SystuneOptions(restarts=1, seed=3, max_iterations=100),
    )


@pytest.fixture(scope="module")
def constrained_result():
    goals = [
        WeightedGain("d", "y"),
        Margins("u", gain_margin_db=6.0, phase_margin_deg=30.0, kind="hard"),
        Poles(min_damping=0.02, kind="hard"),
        Variance("d", "y", max_std=100.0, kind="hard"),
    ]
    return systune(PLANTS, pid(), goals, options=SystuneOptions(max_iterations=60))


# ------------------------------------------------------------------ brute force (no state space)


def _conv(a, b):
    out = np.zeros((a.shape[0], a.shape[1] + b.shape[1] - 1))
    for i in range(a.shape[1]):
        out[:, i : i + b.shape[1]] += a[:, i : i + 1] * b
    return out


def brute_force(kp, ki, kd, tf, omega):
    """Per grid point: ``max_k ||T_dy||_inf`` and ``max_k max |S - 1/2|`` on ``omega``
    (``inf`` when a closed loop is unstable), from polynomial transfer functions:
    ``P_yu = q / Delta``, ``P_yd = a/(s + a) (s^2 + q) / Delta``, ``q = c s + k``,
    ``Delta = s^2 (s^2 + 2 q)``, ``C = Kp + Ki/s + Kd s/(Tf s + 1)``."""
    KP, KI, KD, TF = (g.ravel() for g in np.meshgrid(kp, ki, kd, tf, indexing="ij"))
    N = KP.size
    s = 1j * omega
    hinf, sens = np.zeros(N), np.zeros(N)
    stable = np.ones(N, dtype=bool)
    den_c = np.stack([TF, np.ones(N), np.zeros(N)], axis=1)
    num_c = np.stack([KP * TF + KD, KP + KI * TF, KI], axis=1)
    for k in SPRINGS:
        # characteristic polynomial den_C Delta + num_C q (degree 6)
        char = _conv(den_c, np.tile([1, 2 * DAMPER, 2 * k, 0, 0], (N, 1)))
        char[:, 3:] += _conv(num_c, np.tile([DAMPER, k], (N, 1)))
        companion = np.zeros((N, 6, 6))
        companion[:, 0, :] = -char[:, 1:] / char[:, :1]
        companion[:, 1:, :-1] = np.eye(5)
        stable &= np.linalg.eigvals(companion).real.max(axis=1) < 0
        q = DAMPER * s + k
        delta = s**2 * (s**2 + 2 * q)
        for lo in range(0, N, 1000):
            rows = slice(lo, lo + 1000)
            C = KP[rows, None] + KI[rows, None] / s + KD[rows, None] * s / (TF[rows, None] * s + 1)
            S = 1.0 / (1.0 + C * q / delta)
            T = FILTER / (s + FILTER) * (s**2 + q) / delta * S
            hinf[rows] = np.maximum(hinf[rows], np.abs(T).max(axis=1))
            sens[rows] = np.maximum(sens[rows], np.abs(S - 0.5).max(axis=1))
    params = np.stack([KP, KI, KD, TF], axis=1)
    return params, np.where(stable, hinf, np.inf), np.where(stable, sens, np.inf)


@pytest.fixture(scope="module")
def grid():
    return brute_force(
        np.logspace(-2, 0.5, 10),
        np.logspace(-4, -1, 5),
        np.logspace(-2, 1, 10),
        np.logspace(-1.5, 0.7, 8),
        np.logspace(-3, 2, 600),
    )


def _exact_hinf(params):
    """``max_k ||T_dy||_inf`` of a PID given by its parameters (ab13dd)."""
    kp, ki, kd, tf = params
    C = control.tf([kp * tf + kd, kp + ki * tf, ki], [tf, 1, 0])
    C = control.ss(C, inputs="e", outputs="u")
    return max(ab13dd_norm(closed_loop(P, C, "d", "y")) for P in PLANTS)


def test_tuned_pid_beats_the_brute_force_grid(soft_result, grid):
    params, hinf, _ = grid
    best = params[np.argmin(hinf)]
    brute = _exact_hinf(best)
    assert soft_result.status == "ok"
    assert soft_result.soft <= brute * (1 + 1e-6)
    # and it is a genuine minimum: no grid point is better, nor any of the 80 neighbours at
    # +-2 % of each parameter (exact norms)
    assert soft_result.soft <= np.min(hinf) * (1 + 1e-6)
    tuned = soft_result.parameters["C"]
    x = np.array([tuned[key][0] for key in ("kp", "ki", "kd", "tf")])
    neighbours = itertools.product((0.98, 1.0, 1.02), repeat=4)
    assert min(_exact_hinf(x * np.array(f)) for f in neighbours) >= soft_result.soft * (1 - 1e-9)


def test_constrained_pid_beats_the_feasible_grid(constrained_result, grid):
    params, hinf, sens = grid
    alpha = disk_alpha(6.0, 30.0)
    feasible = alpha * sens <= 1.0
    assert feasible.any()
    best = params[np.argmin(np.where(feasible, hinf, np.inf))]
    assert constrained_result.status == "ok"
    assert constrained_result.soft <= _exact_hinf(best) * (1 + 1e-6)


def test_weighted_gain_agrees_with_ab13dd(soft_result, constrained_result):
    for result in (soft_result, constrained_result):
        goal = result.goals[0]
        for P, reported in zip(PLANTS, goal.per_model, strict=True):
            reference = ab13dd_norm(closed_loop(P, result.controller, "d", "y"))
            assert reported == pytest.approx(reference, rel=1e-6)
        assert goal.value == pytest.approx(np.max(goal.per_model), rel=1e-12)


def test_hard_margins_are_met_independently(constrained_result):
    result = constrained_result
    margins = result.goal("Margins(u)")
    assert margins.met and result.status == "ok"
    alpha_required = disk_alpha(6.0, 30.0)
    disks = []
    for P in PLANTS:
        L = loop_at_u(P, result.controller)
        gm, pm, *_ = control.stability_margins(L)
        assert 20 * np.log10(gm) >= 6.0 - 1e-6
        assert pm >= 30.0 - 1e-6
        alpha = disk_margin(L, OMEGA)
        assert alpha >= alpha_required * (1 - 1e-6)
        disks.append(alpha)
    # the reported disk margin is the worst model's, its GM/PM the disk's
    assert margins.details["disk_margin"] == pytest.approx(min(disks), rel=1e-4)
    gm_db, pm_deg = disk_gain_phase(min(disks))
    assert margins.details["gain_margin_db"] == pytest.approx(gm_db, rel=1e-3)
    assert margins.details["phase_margin_deg"] == pytest.approx(pm_deg, rel=1e-3)


def test_pole_damping_and_variance_agree(constrained_result):
    result = constrained_result
    dampings, h2 = [], []
    for P in PLANTS:
        T = closed_loop(P, result.controller, "d", "y")
        lam = np.linalg.eigvals(T.A)
        assert lam.real.max() < 0
        dampings.append(np.min(-lam.real / np.abs(lam)))
        n, m, p = T.nstates, T.ninputs, T.noutputs
        h2.append(ab13bd("C", "H", n, m, p, T.A, T.B, T.C, T.D))
    poles = result.goal("Poles")
    assert poles.details["min_damping"] == pytest.approx(min(dampings), abs=1e-9)
    assert poles.met and min(dampings) >= 0.02 - 1e-9
    variance = result.goal("Variance(d->y)")
    assert variance.details["h2_norm"] == pytest.approx(max(h2), rel=1e-6)


def test_discrete_pid_with_rolloff_agrees_with_ab13dd():
    controller = pid(sampling_time=0.2, rolloff_order=1, rolloff_frequency=3.0)
    result = systune(
        PLANTS,
        controller,
        [WeightedGain("d", "y"), Margins("u", 6.0, 30.0, kind="hard")],
        options=SystuneOptions(max_iterations=40),
    )
    assert result.controller.dt == 0.2
    margins = result.goal("Margins(u)")
    for i, P in enumerate(PLANTS):
        Pd = control.c2d(P, 0.2, "zoh")
        T = closed_loop(Pd, result.controller, "d", "y")
        assert result.goals[0].per_model[i] == pytest.approx(ab13dd_norm(T), rel=1e-6)
        L = loop_at_u(Pd, result.controller)
        alpha = disk_margin(L, np.linspace(1e-4, np.pi / 0.2, 20000))
        # normalized value = required / achieved disk margin (achieved on a fine grid)
        assert margins.per_model[i] == pytest.approx(disk_alpha(6.0, 30.0) / alpha, rel=1e-4)
        assert (alpha >= disk_alpha(6.0, 30.0) * (1 - 1e-6)) == (margins.per_model[i] <= 1.0)


def test_gain_behind_fixed_rolloff():
    # a lag 1/(s + 1)^2 with an output disturbance; the gain v = G e drives u through F
    lag = control.ss(control.tf([1.0], [1.0, 2.0, 1.0]))
    plant = control.ss(
        lag.A,
        np.hstack([lag.B, np.zeros((2, 1))]),
        np.vstack([lag.C, -lag.C]),
        [[0.0, 1.0], [0.0, -1.0]],
        inputs=["u", "d"],
        outputs=["y", "e"],
    )
    rolloff = FixedBlock("F", control.tf([4.0], [1.0, 4.0]), inputs=["v"], outputs=["u"])
    gain = TunableGain("G", ["e"], ["v"], initial=[[0.5]])
    result = systune(
        [plant], [gain, rolloff], [WeightedGain("d", "y"), Margins("v", 6.0, 45.0, kind="hard")]
    )
    assert result.status == "ok"
    # fixed block in series: the controller is G * F
    G = result.parameters["G"]["D"][0, 0]
    expected = control.ss(control.tf([4.0 * G], [1.0, 4.0]))
    w = np.logspace(-2, 2, 7)
    np.testing.assert_allclose(
        np.squeeze(result.controller(1j * w)), np.squeeze(expected(1j * w)), rtol=1e-10
    )
    T = closed_loop(plant, result.controller, "d", "y")
    assert np.linalg.eigvals(T.A).real.max() < 0
    assert result.goals[0].value == pytest.approx(ab13dd_norm(T), rel=1e-6)
    # the margin goal at the gain's output v (inside the controller): L = -G F P_eu
    L = -G * control.tf([4.0], [1.0, 4.0]) * control.tf([-1.0], [1.0, 2.0, 1.0])
    alpha = disk_margin(L, OMEGA)
    assert alpha >= disk_alpha(6.0, 45.0) * (1 - 1e-6)
    assert result.goal("Margins(v)").details["disk_margin"] == pytest.approx(alpha, rel=1e-4)


def test_state_space_controller_is_stable_by_construction():
    block = TunableSS("K", ["e"], ["u"], order=3, sampling_time=0.0)
    rng = np.random.default_rng(0)
    for _ in range(20):
        x = 3 * rng.normal(size=block.nparameters)
        assert np.max(np.linalg.eigvals(np.real(block.realize(x)[0])).real) < 0
    discrete = TunableSS("K", ["e"], ["u"], order=3, sampling_time=0.1)
    x = 3 * rng.normal(size=discrete.nparameters)
    assert np.max(np.abs(np.linalg.eigvals(np.real(discrete.realize(x)[0])))) < 1


# ------------------------------------------------------------------ bad input


def test_unknown_structure_is_refused():
    with pytest.raises(ValueError, match="unknown controller structure str"):
        systune(PLANTS, "pid", [WeightedGain("d", "y")])
    with pytest.raises(ValueError, match="unknown structure terms='PIDF'"):
        TunablePID("C", "e", "u", terms="PIDF")


def test_order_below_one_is_refused():
    with pytest.raises(ValueError, match="TunableSS 'K': order must be an integer >= 1"):
        TunableSS("K", "e", "u", order=0)


def test_goal_naming_a_missing_signal_is_refused():
    with pytest.raises(ValueError, match="goal 'WeightedGain\\(d->z\\)': signal 'z' does not"):
        systune(PLANTS, pid(), [WeightedGain("d", "z")])
    with pytest.raises(ValueError, match="block 'C' reads signal 'err'"):
        systune(PLANTS, TunablePID("C", "err", "u"), [WeightedGain("d", "y")])


def test_variance_with_direct_feedthrough_is_refused():
    with pytest.raises(ValueError, match="'Variance\\(d->d\\)': the closed loop has a direct"):
        systune(PLANTS, pid(), [Variance("d", "d")])


def test_unreachable_hard_goals_are_refused():
    with pytest.raises(ValueError, match="'Margins\\(u\\)' cannot be met"):
        Margins("u", gain_margin_db=6.0, phase_margin_deg=100.0)
    with pytest.raises(ValueError, match="'Poles' cannot be met"):
        Poles(min_damping=1.2, kind="hard")
    # the disturbance filter is outside the loop: d -> filter state cannot be changed
    plant = two_mass(1.0)
    with pytest.raises(ValueError, match="hard goal 'tiny' cannot be met: it does not depend"):
        systune([plant], pid(), [WeightedGain("d", "d", left_weight=2.0, kind="hard", name="tiny")])


def test_infeasible_design_is_reported_as_such():
    # the disturbance filter pole (0.2 rad/s) is fixed: no controller brings every pole below
    # 0.1 rad/s
    result = systune(
        PLANTS,
        pid(),
        [WeightedGain("d", "y"), Poles(max_frequency=0.1, kind="hard")],
        options=SystuneOptions(max_iterations=20),
    )
    assert result.status == "infeasible"
    poles = result.goal("Poles")
    assert not poles.met and result.hard > 1
    assert poles.details["max_frequency_rad_s"] >= 0.2 - 1e-9


# ------------------------------------------------------------------ today's static-gain synthesis


def _static_gain_problem(configurations, modes):
    from oos_drake.control.baseline import baseline_gains, inertia_from_plant
    from oos_drake.control.interconnection import weighted_interconnection
    from oos_drake.control.plants import synthetic_flexible_plants

    plants = synthetic_flexible_plants(configurations, modes=modes, uncertain=False)
    K0 = baseline_gains(inertia_from_plant(plants.evaluate([1]))[0])
    N, P = plants.size, len(plants.parameters)
    nominal = np.broadcast_to(plants.nominal_values, (N, P))
    return plants, K0, weighted_interconnection(plants.evaluate(np.arange(N), nominal)).system


def _systune_static(system, K, max_iterations):
    from oos_drake.control.interconnection import (
        CONTROLS,
        DISTURBANCES,
        ERRORS,
        MEASUREMENTS,
    )

    return systune(
        system,
        TunableGain("K", MEASUREMENTS, CONTROLS, initial=K),
        [WeightedGain(DISTURBANCES, ERRORS)],
        options=SystuneOptions(max_iterations=max_iterations),
    )


def test_static_gain_problem_is_today_synthesis_problem():
    from oos_drake.control.synthesis import SynthesisOptions, synthesize

    plants, K0, system = _static_gain_problem(2, 1)
    options = SynthesisOptions(restarts=0, max_iterations=8, worst_case_rounds=0, working_set=0)
    reference = synthesize(plants, K0, options=options)
    # systune's weighted gain of the synthesis' gain, no iteration: the same gamma
    at_reference = _systune_static(system, reference.K, 0)
    assert at_reference.soft == pytest.approx(reference.gamma, rel=1e-9)
    np.testing.assert_allclose(
        at_reference.goals[0].per_model, reference.models["gamma [-]"], rtol=1e-9
    )
    # and systune does not lose what the synthesis reached (warm start)
    assert _systune_static(system, reference.K, 10).soft <= reference.gamma * (1 + 1e-12)


@pytest.mark.slow
def test_static_gain_synthesis_reproduced_at_convergence():
    from oos_drake.control.interconnection import CONTROLS, DISTURBANCES, ERRORS, MEASUREMENTS
    from oos_drake.control.synthesis import SynthesisOptions, synthesize

    plants, K0, system = _static_gain_problem(2, 1)
    options = SynthesisOptions(restarts=0, max_iterations=300, worst_case_rounds=0, working_set=0)
    reference = synthesize(plants, K0, options=options)
    # From K0 alone the nonsmooth descent can stop in another local minimum: with one BLAS
    # thread it stops at 1.0027 x the synthesis' gamma, with two at 0.9996 x (the round-off
    # takes another path). Two seeded restarts, as systune is meant to be run, reach it or a
    # lower one (0.9989 x with drake 1.51.1 / numpy 2.4.6 / scipy 1.17.1).
    tuned = systune(
        system,
        TunableGain("K", MEASUREMENTS, CONTROLS, initial=K0),
        [WeightedGain(DISTURBANCES, ERRORS)],
        options=SystuneOptions(max_iterations=300, restarts=2),
    )
    assert tuned.soft <= reference.gamma * (1 + 1e-3)
    # and the synthesis, started at systune's gain, finds nothing lower there: systune's point
    # is converged, its value the synthesis' own evaluation of that gain
    again = synthesize(plants, tuned.parameters["K"]["D"], options=options)
    assert again.gamma == pytest.approx(tuned.soft, rel=1e-3)


def test_multiloop_and_loop_at_a_time_margins_on_a_coupled_plant():
    # y = G u + d, G = (sI - A)^-1 B coupled 2x2; e = -y; u = K e with a 2x2 gain
    A, B = np.diag([-1.0, -2.0]), np.array([[1.0, 0.6], [0.4, 1.0]])
    plant = control.ss(
        A,
        np.hstack([B, np.zeros((2, 2))]),
        np.vstack([np.eye(2), -np.eye(2)]),
        np.block([[np.zeros((2, 2)), np.eye(2)], [np.zeros((2, 2)), -np.eye(2)]]),
        inputs=["u[0]", "u[1]", "d[0]", "d[1]"],
        outputs=["y[0]", "y[1]", "e[0]", "e[1]"],
    )
    goals = [
        WeightedGain("d", "y"),
        Margins("u", 6.0, 45.0, multiloop=True, kind="hard", name="multiloop"),
        Margins("u", 8.0, 50.0, kind="hard", name="loop at a time"),
    ]
    gain = TunableGain("K", ["e[0]", "e[1]"], ["u[0]", "u[1]"], initial=np.eye(2))
    result = systune([plant], gain, goals, options=SystuneOptions(max_iterations=40))
    assert result.status == "ok"
    K = result.parameters["K"]["D"]
    w = np.logspace(-3, 3, 4000)
    G = np.linalg.solve(1j * w[:, None, None] * np.eye(2) - A, np.broadcast_to(B, (w.size, 2, 2)))
    S = np.linalg.inv(np.eye(2) + K @ G)  # sensitivity at u, L = K G
    multiloop = disk_alpha(6.0, 45.0) * np.linalg.norm(S - np.eye(2) / 2, 2, axis=(1, 2)).max()
    assert result.goal("multiloop").value == pytest.approx(multiloop, rel=1e-4)
    assert multiloop <= 1 + 1e-6
    # loop at a time: channel i sees S_ii with the other loop closed
    each = np.abs(np.diagonal(S, axis1=1, axis2=2) - 0.5).max(axis=0)
    assert result.goal("loop at a time").value == pytest.approx(
        disk_alpha(8.0, 50.0) * each.max(), rel=1e-4
    )
    assert result.goal("loop at a time").details["disk_margin"] == pytest.approx(
        1 / each.max(), rel=1e-4
    )


def test_lfr_model_array_is_the_list_of_plants():
    from oos_drake.lfr import LFR

    stacked = [np.stack([getattr(P, m) for P in PLANTS]) for m in "ABCD"]
    array = LFR.from_ss(*stacked, input_names=["u", "d"], output_names=["y", "e"])
    options = SystuneOptions(max_iterations=15)
    from_array = systune(array, pid(), [WeightedGain("d", "y")], options=options)
    from_list = systune(PLANTS, pid(), [WeightedGain("d", "y")], options=options)
    np.testing.assert_allclose(from_array.x, from_list.x, rtol=1e-12)
    np.testing.assert_allclose(from_array.goals[0].per_model, from_list.goals[0].per_model)


def test_pid_started_with_a_tiny_integral_gain_still_reaches_the_grid_optimum(grid):
    """From a start whose gains span four decades (``ki`` 1e4 times below ``kd``, as a PID
    started from the paper's baseline with ``ki = 0.01 kp``), the tuning still reaches the
    brute-force optimum: each gain is scaled by its own magnitude, not its block's mean."""
    start = TunablePID("C", "e", "u", kp=0.1, ki=1e-5, kd=0.3, tf=1.0)
    result = systune(
        PLANTS, start, [WeightedGain("d", "y")], options=SystuneOptions(max_iterations=100)
    )
    params, hinf, _ = grid
    assert result.status == "ok"
    assert result.soft <= np.min(hinf) * (1 + 1e-6)
    assert result.soft <= _exact_hinf(params[np.argmin(hinf)]) * (1 + 1e-6)


def test_discrete_goals_share_one_decomposition():
    # a discrete loop's bilinear image keeps its eigenvectors: the goals' peaks from the one
    # shared decomposition equal those of each goal decomposing its own image, and ab13dd's
    from oos_drake.control.systune import _Problem

    controller = pid(sampling_time=0.2, rolloff_order=1, rolloff_frequency=3.0)
    goals = [WeightedGain("d", "y"), Margins("u", 6.0, 30.0, kind="hard")]
    shared, own = (_Problem(PLANTS, controller, shared_modes=flag) for flag in (True, False))
    x = shared.structure.initial()
    K = shared.structure.K(x)
    assert shared.modes is not None and own.modes is None
    for g, goal in enumerate(goals):
        (a, _, _), (b, _, _) = shared.terms(goal, g)[0], own.terms(goal, g)[0]
        assert a.modes is not None
        np.testing.assert_allclose(a.exact(K)[0], b.exact(K)[0], rtol=1e-9)
        pa, pb = a.pieces(K, 0.1), b.pieces(K, 0.1)
        np.testing.assert_allclose(pa[0][0], pb[0][0], rtol=1e-9)  # the maximum
    plant_controller = controller.statespace(x)
    for i, P in enumerate(PLANTS):
        T = closed_loop(control.c2d(P, 0.2, "zoh"), plant_controller, "d", "y")
        weighted = shared.terms(goals[0], 0)[0][0]
        assert weighted.exact(K)[0][i] == pytest.approx(ab13dd_norm(T), rel=1e-6)
