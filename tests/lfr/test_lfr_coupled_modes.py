"""The eigendecomposition-free route of ``freqresp`` (``oos_drake.lfr.coupled_modes``).

State matrices that are 2x2-block diagonal up to a low-rank coupling (flexible modes on a hub)
are evaluated with the Woodbury identity instead of a per-model ``dgeev``. Every case is checked
against an exact direct solve ``C (j w I - A)^-1 B + D`` of the same matrices and against
python-control: general sensors/actuators, sensors on the coupling, sensors and actuators on the
coupling ("hub"), integrator tails, first-order modes paired two by two with a padding state,
coupling ranks 0 .. 4, and the rejections (rank too high, undamped block) that fall back to the
modal route.
"""

import control
import numpy as np
import pytest
from lfr_helpers import assert_response_close, control_response

import oos_drake.lfr.coupled_modes as cm
import oos_drake.lfr.frequency as fr
from oos_drake.lfr import LFR, append, feedback, freqresp, inv, ureal, usubs

OMEGA = np.logspace(-2, 2, 37)
RTOL = 1e-9


def _batch(systems):
    return LFR.from_ss(
        np.stack([s.A for s in systems]),
        np.stack([s.B for s in systems]),
        np.stack([s.C for s in systems]),
        np.stack([s.D for s in systems]),
    )


def _direct(sys_ss, omega=OMEGA):
    return fr._direct_response(sys_ss.A, sys_ss.B, sys_ss.C, sys_ss.D, 1j * omega)


def _coupled_system(rng, modes, rank, ny, nu, *, hub=False, tail=0, first_order=0, undamped=False):
    """Flexible modes (position/velocity pairs, 0.2 .. 5 % damping) and ``first_order`` real
    poles, coupled through a rank-``rank`` term acting on the velocity rows only (a hub), states
    shuffled; optionally a chain of ``tail`` integrators driven by the coupling (rigid body).
    ``hub``: B and C (and the tail) see the modes only through the coupling; ``undamped``: the
    first mode has no damping of its own."""
    m = 2 * modes + first_order
    A = np.zeros((m, m))
    rate_rows = []
    for j in range(modes):
        w = 10 ** rng.uniform(-0.5, 1.5)
        z = 0.0 if undamped and j == 0 else 10 ** rng.uniform(-2.7, -1.3)
        p, v = 2 * j, 2 * j + 1
        A[p, v] = 1.0
        A[v, p], A[v, v] = -w * w, -2 * z * w
        rate_rows.append(v)
    for i in range(2 * modes, m):
        A[i, i] = -(10 ** rng.uniform(-1, 1))
        rate_rows.append(i)
    U = np.zeros((m, rank))
    U[rate_rows] = rng.standard_normal((len(rate_rows), rank))
    Wt = 0.3 * rng.standard_normal((rank, m))
    A += U @ Wt
    if hub:
        B = U @ rng.standard_normal((rank, nu))
        C = rng.standard_normal((ny, rank)) @ Wt
    else:
        B = np.zeros((m, nu))
        B[rate_rows] = rng.standard_normal((len(rate_rows), nu))
        C = rng.standard_normal((ny, m))
    perm = np.random.default_rng(m).permutation(m)  # the same state order across a batch
    A, B, C = A[np.ix_(perm, perm)], B[perm], C[:, perm]
    if tail:
        n = m + tail
        Af = np.zeros((n, n))
        Af[:m, :m] = A
        Af[m, :m] = rng.standard_normal(rank) @ Wt[:, perm]  # driven by the coupling
        for i in range(1, tail):
            Af[m + i, m + i - 1] = 1.0
        Bf = np.vstack([B, rng.standard_normal((tail, nu))])
        Cf = np.hstack([np.zeros((ny, m)) if hub else C, rng.standard_normal((ny, tail))])
        A, B, C = Af, Bf, Cf
    return control.ss(A, B, C, 0.2 * rng.standard_normal((ny, nu)))


def _route(batch, omega=OMEGA):
    """Run the coupled route alone on a batch: ``(ok, response)``."""
    n = batch.nstates
    core, tail, powers = fr._integrator_tail(batch.M[:, :n, :n])
    pairs = cm.block_pairs(np.any(batch.M[:, core[:, None], core[None, :]] != 0, axis=0))
    assert pairs is not None
    out = np.zeros((batch.M.shape[0], omega.size) + batch.shape, dtype=complex)
    ok = cm.coupled_response(batch.M, n, core, tail, powers, omega, pairs, out)
    return ok, out


@pytest.mark.parametrize(
    ("modes", "rank", "ny", "nu", "hub", "tail", "first_order"),
    [
        (9, 3, 2, 3, False, 0, 0),  # general B, C
        (9, 3, 3, 3, True, 0, 0),  # hub: sensors and actuators on the coupling
        (8, 3, 3, 2, True, 2, 0),  # hub + rigid-body double integrator
        (8, 2, 2, 2, False, 2, 0),  # general + tail (partial fractions)
        (7, 1, 1, 2, False, 1, 3),  # rank 1, first-order modes paired (odd core: padding)
        (8, 2, 3, 1, True, 0, 1),  # rank 2, hub, odd core
        (6, 0, 2, 2, False, 0, 0),  # uncoupled modes: A already block diagonal
    ],
)
def test_coupled_route_matches_direct_solve_and_control(
    modes, rank, ny, nu, hub, tail, first_order
):
    rng = np.random.default_rng(7 * modes + 3 * rank + ny + 5 * tail + 11 * first_order)
    systems = [
        _coupled_system(rng, modes, rank, ny, nu, hub=hub, tail=tail, first_order=first_order)
        for _ in range(5)
    ]
    batch = _batch(systems)
    ok, resp = _route(batch)
    assert ok.all()
    full = freqresp(batch, OMEGA)
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], _direct(sys), rtol=RTOL)
        assert_response_close(full[k], control_response(sys, OMEGA), rtol=RTOL)


@pytest.mark.parametrize("hub", [False, True])
def test_rank_four_uses_the_batched_solve_when_allowed(hub, monkeypatch):
    rng = np.random.default_rng(5)
    systems = [_coupled_system(rng, 12, 4, 2, 2, hub=hub) for _ in range(3)]
    batch = _batch(systems)
    ok, _ = _route(batch)
    assert not ok.any()  # rank 4 > RANK_LIMIT: left to the modal route
    monkeypatch.setattr(cm, "RANK_LIMIT", 4)
    ok, resp = _route(batch)
    assert ok.all()
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], _direct(sys), rtol=RTOL)


def test_rejected_models_fall_back_inside_a_batch():
    """A mode without damping of its own (its block pole sits on the imaginary axis) and a
    dense full-rank state matrix: the route declines them and freqresp still answers exactly
    (modal route) for them and for the good models of the same batch."""
    rng = np.random.default_rng(9)
    good = [_coupled_system(rng, 9, 3, 2, 2) for _ in range(3)]
    undamped = _coupled_system(rng, 9, 3, 2, 2, undamped=True)
    systems = good + [undamped]
    ok, _ = _route(_batch(systems))
    assert ok.tolist() == [True, True, True, False]
    resp = freqresp(_batch(systems), OMEGA)
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], _direct(sys), rtol=RTOL)
    dense = control.ss(
        rng.standard_normal((18, 18)) - 6 * np.eye(18),
        rng.standard_normal((18, 2)),
        rng.standard_normal((2, 18)),
        np.zeros((2, 2)),
    )
    ok, _ = _route(_batch([dense, dense]))
    assert not ok.any()
    assert_response_close(freqresp(_batch([dense]), OMEGA)[0], _direct(dense), rtol=RTOL)


def _small_spacecraft():
    """A hub with uncertain inertias carrying one appendage with 12 uncertain modes
    (the benchmark's construction, smaller): hub torques in, hub angles out."""
    integ = control.tf(1, [1, 0])
    inertia = [
        ureal(f"J{a}", nom, percent=10)
        for a, nom in zip("xyz", (900.0, 1100.0, 700.0), strict=True)
    ]
    rng = np.random.default_rng(4)
    modes, gains, directions = [], [], []
    for j in range(12):
        w = ureal(f"w{j}", 0.6 * 1.35**j, percent=10)
        xi = ureal(f"xi{j}", 0.005, range=(0.002, 0.01))
        g = ureal(f"g{j}", 1.0, percent=20)
        K = 2 * xi * w + w * w * integ
        modes.append(feedback(K * integ, 1))
        gains.append(g)
        directions.append(rng.standard_normal(3) * 3.0)
    L = np.stack(directions, axis=1)
    Gm = append(*gains)
    torque = L * Gm * append(*modes) * Gm * (-L.T)
    accel = feedback(append(*(inv(J) for J in inertia)), torque, sign=1)
    return append(*([integ * integ] * 3)) * accel


def test_spacecraft_model_array_takes_the_route_and_matches_control():
    sys = _small_spacecraft()
    rng = np.random.default_rng(12)
    values = {name: spec.sample(rng, 6) for name, spec in sys.uncertainty.items()}
    models = usubs(sys, values)
    ok, resp = _route(models)
    assert ok.all()
    modal = freqresp(models, OMEGA, coupled=False)
    full = freqresp(models, OMEGA)
    for k in range(6):
        one = usubs(sys, {name: v[k] for name, v in values.items()}).to_ss()
        assert_response_close(resp[k], control_response(one, OMEGA), rtol=RTOL)
        assert_response_close(full[k], modal[k], rtol=RTOL)


def test_result_independent_of_threads_and_chunks(monkeypatch):
    sys = _small_spacecraft()
    rng = np.random.default_rng(13)
    values = {name: spec.sample(rng, 40) for name, spec in sys.uncertainty.items()}
    models = usubs(sys, values)
    ref = freqresp(models, OMEGA)
    monkeypatch.setattr(fr, "COUPLED_CHUNK", 8)
    assert np.array_equal(freqresp(models, OMEGA, workers=2), freqresp(models, OMEGA))
    monkeypatch.setattr(cm, "SUB_CHUNK_ENTRIES", 1)
    assert_response_close(freqresp(models, OMEGA).reshape(-1, 9), ref.reshape(-1, 9), rtol=1e-12)


def test_block_pairs_from_pattern():
    pattern = np.zeros((5, 5), dtype=bool)
    pattern[0, 3] = True  # kinematic row: state 0 integrates state 3
    pattern[3] = True
    pattern[[1, 2, 4], :] = True
    pairs = cm.block_pairs(pattern)
    assert pairs.tolist() == [[0, 3], [1, 2], [4, 5]]  # 5 = padding state
    assert cm.block_pairs(np.ones((3, 3), dtype=bool)) is None


@pytest.mark.parametrize(
    ("hub", "tail", "expected"),
    [(False, 0, "general"), (True, 0, "hub"), (True, 2, "hub"), (False, 2, "general")],
)
def test_reduction_chosen_from_the_structure(hub, tail, expected, monkeypatch):
    """Sensors and actuators on the coupling select the r x r evaluation; generic ones the full
    one (checked by recording what the frequency evaluation receives)."""
    seen = []
    evaluate = cm._evaluate

    def record(coef, det, tr, poly, basis, gam, is_hub, *rest):
        seen.append("hub" if is_hub else ("sensors" if gam is not None else "general"))
        return evaluate(coef, det, tr, poly, basis, gam, is_hub, *rest)

    monkeypatch.setattr(cm, "_evaluate", record)
    rng = np.random.default_rng(31)
    systems = [_coupled_system(rng, 9, 3, 2, 2, hub=hub, tail=tail) for _ in range(2)]
    ok, resp = _route(_batch(systems))
    assert ok.all()
    assert set(seen) == {expected}
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], _direct(sys), rtol=RTOL)


def test_sensors_on_the_coupling_only():
    """C = Gamma W^T but a generic B: the sensors-only evaluation G = Gamma(s) K^-1 H_wb."""
    rng = np.random.default_rng(17)
    systems = []
    for _ in range(3):
        hub_sys = _coupled_system(rng, 9, 3, 2, 2, hub=True)
        B = rng.standard_normal(hub_sys.B.shape)
        B[np.abs(hub_sys.A).sum(axis=1) == 1.0] = 0.0  # keep the kinematic rows input-free
        systems.append(control.ss(hub_sys.A, B, hub_sys.C, hub_sys.D))
    ok, resp = _route(_batch(systems))
    assert ok.all()
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], _direct(sys), rtol=RTOL)


def test_empty_frequency_grid():
    rng = np.random.default_rng(3)
    batch = _batch([_coupled_system(rng, 9, 3, 2, 2) for _ in range(2)])
    assert freqresp(batch, np.zeros(0)).shape == (2, 0, 2, 2)
