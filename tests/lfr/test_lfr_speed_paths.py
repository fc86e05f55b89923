"""The fast paths of the model-array hot path against the reference paths and python-control.

* ``freqresp``: the real pairwise modal route (LAPACK ``dgeev`` real eigenvector basis, real
  pair sums, one matrix product per model) against the general complex path of the same module
  (``real_pairs=False``), the exact direct solve ``C (jwI - A)^-1 B + D`` and
  python-control; with integrator tails, odd core sizes, all-real spectra, ill-conditioned models
  mixed into a batch, complex data, and worker threads (bitwise identical results).
* ``usubs``: the threaded batched substitution against the single-threaded one and a per-sample
  scalar loop.
"""

import control
import numpy as np
import pytest
from lfr_helpers import assert_response_close, control_response, random_ss

import oos_drake.lfr.frequency as fr
import oos_drake.lfr.substitution as subs
from oos_drake.lfr import LFR, append, feedback, freqresp, inv, ureal, usubs

OMEGA = np.logspace(-2, 2, 41)
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


def _general(sys, omega):
    return freqresp(sys, omega, real_pairs=False)


def _with_tail(rng, core_ss, chain: int):
    """Append a chain of ``chain`` pure integrators driven by the core (rigid-body-like tail)."""
    m = core_ss.A.shape[0]
    n = m + chain
    A = np.zeros((n, n))
    A[:m, :m] = core_ss.A
    A[m, :m] = rng.standard_normal(m)
    for i in range(1, chain):
        A[m + i, m + i - 1] = 1.0
    B = np.vstack([core_ss.B, rng.standard_normal((chain, core_ss.B.shape[1]))])
    C = np.hstack([core_ss.C, rng.standard_normal((core_ss.C.shape[0], chain))])
    return control.ss(A, B, C, core_ss.D)


def _lightly_damped(rng, modes: int, reals: int, ny: int, nu: int):
    """Real block-diagonal modal system, hidden by a random similarity: ``modes`` lightly damped
    pairs (damping 0.2 % .. 5 %, frequencies 0.1 .. 50 rad/s) and ``reals`` real poles."""
    blocks = []
    for _ in range(modes):
        w = 10 ** rng.uniform(-1, 1.7)
        z = 10 ** rng.uniform(-2.7, -1.3)
        blocks.append(
            np.array([[-z * w, w * np.sqrt(1 - z * z)], [-w * np.sqrt(1 - z * z), -z * w]])
        )
    blocks.extend(np.array([[-(10 ** rng.uniform(-1, 1))]]) for _ in range(reals))
    n = 2 * modes + reals
    A = np.zeros((n, n))
    i = 0
    for blk in blocks:
        A[i : i + blk.shape[0], i : i + blk.shape[0]] = blk
        i += blk.shape[0]
    S = rng.standard_normal((n, n)) + 3 * np.eye(n)
    A = S @ A @ np.linalg.inv(S)
    return control.ss(
        A, rng.standard_normal((n, nu)), rng.standard_normal((ny, n)), rng.standard_normal((ny, nu))
    )


@pytest.mark.parametrize(
    ("modes", "reals", "chain"),
    [(3, 0, 0), (2, 1, 0), (2, 3, 0), (0, 5, 0), (4, 2, 2), (3, 1, 1), (2, 0, 3)],
)
def test_real_pair_path_matches_direct_solve_and_control(modes, reals, chain):
    rng = np.random.default_rng(100 + 10 * modes + reals + 7 * chain)
    systems = []
    for _ in range(4):
        core = _lightly_damped(rng, modes, reals, 2, 3)
        systems.append(_with_tail(rng, core, chain) if chain else core)
    batch = _batch(systems)
    core_idx, tail_idx, _ = fr._integrator_tail(batch.M[:, : batch.nstates, : batch.nstates])
    assert tail_idx.size == chain
    # the fast route takes every model unless small poles beside a long tail make the partial
    # fractions unsafe (then the general path answers)
    m = batch.nstates
    _, ok = fr._real_pair_response(batch.M, m, core_idx, tail_idx, chain, OMEGA)
    lam_min = np.array(
        [np.abs(np.linalg.eigvals(s.A[: m - chain, : m - chain])).min() for s in systems]
    )
    expected_fast = (OMEGA.max() / lam_min) ** chain < 1e6 if chain else np.ones(4, bool)
    assert ok.tolist() == expected_fast.tolist()
    assert ok.any() or chain == 3
    resp = freqresp(batch, OMEGA)
    general = _general(batch, OMEGA)
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], _direct(sys), rtol=RTOL)
        # python-control's own evaluation loses digits on a triple integrator at w = 0.01
        # (|G| ~ 1e6 there); the exact direct solve above is the 1e-9 reference
        rtol_control = RTOL if chain < 3 else 1e-8
        assert_response_close(resp[k], control_response(sys, OMEGA), rtol=rtol_control)
        assert_response_close(resp[k], general[k], rtol=RTOL)


def test_random_dense_batches_match_control():
    rng = np.random.default_rng(11)
    for n, ny, nu in [(1, 1, 1), (2, 1, 2), (7, 3, 2), (12, 2, 4)]:
        systems = [random_ss(rng, n, ny, nu) for _ in range(6)]
        resp = freqresp(_batch(systems), OMEGA)
        for k, sys in enumerate(systems):
            assert_response_close(resp[k], control_response(sys, OMEGA), rtol=RTOL)


def test_ill_conditioned_models_fall_back_inside_a_batch():
    """A defective (Jordan) model and a small-pole model with an integrator tail among good
    models: the fast route flags them and the general path computes them exactly."""
    rng = np.random.default_rng(3)
    good = _lightly_damped(rng, 2, 1, 1, 2)
    jordan = np.array([[-0.5, 1.0], [0.0, -0.5]])
    A = np.zeros((5, 5))
    A[:2, :2] = jordan
    A[2:, 2:] = _lightly_damped(rng, 1, 1, 1, 1).A
    A[:2, 2:] = rng.standard_normal((2, 3))
    T = np.linalg.qr(rng.standard_normal((5, 5)))[0]
    defective = control.ss(T @ A @ T.T, good.B, good.C, good.D)
    slow = control.ss(
        np.diag([-1e-5, -2.0, -3.0, -4.0, -5.0]) + np.triu(np.ones((5, 5)), 1),
        good.B,
        good.C,
        good.D,
    )
    systems = [_with_tail(rng, s, 2) for s in (good, defective, slow, good)]
    batch = _batch(systems)
    core, tail, q = fr._integrator_tail(batch.M[:, :7, :7])
    _, ok = fr._real_pair_response(batch.M, 7, core, tail, q, OMEGA)
    assert ok.tolist() == [True, False, False, True]
    resp = freqresp(batch, OMEGA)
    for k, sys in enumerate(systems):
        assert_response_close(resp[k], _direct(sys), rtol=RTOL)
    assert_response_close(resp.reshape(-1, 2), _general(batch, OMEGA).reshape(-1, 2), rtol=RTOL)


def test_complex_data_uses_the_general_path():
    rng = np.random.default_rng(4)
    sys = random_ss(rng, 4, 2, 2)
    A = sys.A + 0.3j * rng.standard_normal((4, 4))
    lfr = LFR.from_ss(A, sys.B, sys.C, sys.D)
    expected = fr._direct_response(A, sys.B, sys.C, sys.D, 1j * OMEGA)
    assert_response_close(freqresp(lfr, OMEGA), expected, rtol=RTOL)


def test_worker_threads_give_bitwise_identical_responses(monkeypatch):
    rng = np.random.default_rng(5)
    systems = [_with_tail(rng, _lightly_damped(rng, 3, 1, 2, 2), 2) for _ in range(12)]
    batch = _batch(systems)
    monkeypatch.setattr(fr, "CHUNK_ENTRIES", 1)  # one model per chunk: many tasks
    single = freqresp(batch, OMEGA)
    threaded = freqresp(batch, OMEGA, workers=2)
    assert np.array_equal(single, threaded)


def _mini_spacecraft():
    """One flexible appendage on a rigid hub, scheduled rotation: the benchmark's structure."""
    integ = control.tf(1, [1, 0])
    J = ureal("J", 800.0, percent=10)
    tau = ureal("tau", 0.0, range=(-1.0, 1.0))
    N = np.array([[0.0, -1.0], [1.0, 0.0]])
    rot = inv(np.eye(2) - tau * N) * (np.eye(2) + tau * N)
    modes, gains = [], []
    for j in range(3):
        w = ureal(f"w{j}", 0.8 * 1.7**j, percent=10)
        xi = ureal(f"xi{j}", 0.005, range=(0.002, 0.01))
        K = 2 * xi * w + w * w * integ
        modes.append(feedback(K * integ, 1))
        gains.append(ureal(f"g{j}", 1.0, percent=20))
    L = np.array([[1.0, 0.5, -0.3], [0.2, -1.0, 0.7]])
    G = append(*gains)
    torque = rot * L * G * append(*modes) * G * (-L.T)
    accel = feedback(append(inv(J), inv(J)), torque, sign=1)
    return append(integ * integ, integ * integ) * accel


def test_usubs_then_freqresp_matches_a_per_sample_control_loop(monkeypatch):
    sys = _mini_spacecraft()
    rng = np.random.default_rng(6)
    values = {name: spec.sample(rng, 9) for name, spec in sys.uncertainty.items()}
    models = usubs(sys, values)
    resp = models.freqresp(OMEGA)
    monkeypatch.setattr(subs, "SUBS_CHUNK_ENTRIES", 1)  # one model per chunk
    chunked = usubs(sys, values)
    np.testing.assert_allclose(chunked.M, models.M, rtol=1e-12, atol=1e-12 * np.abs(models.M).max())
    threaded = usubs(sys, values, workers=2)
    assert np.array_equal(threaded.M, chunked.M)  # same chunks: bitwise equal
    assert np.array_equal(freqresp(threaded, OMEGA, workers=2), chunked.freqresp(OMEGA))
    for k in range(9):
        ss_k = usubs(sys, {name: v[k] for name, v in values.items()}).to_ss()
        assert_response_close(resp[k], control_response(ss_k, OMEGA), rtol=RTOL)


def test_left_and_right_substitution_recursions_agree_with_the_general_solve():
    """The two batched recursions (over the rows of M_ks or the columns of M_sk) against the
    general per-model path (a dense solve per coupled component, broadcasting over models)."""
    sys = _mini_spacecraft()
    rng = np.random.default_rng(7)
    names = sorted(sys.uncertainty)
    values = {name: sys.uncertainty[name].sample(rng, 5) for name in names}
    deltas = subs._normalized_values(sys, values, False)
    plan = subs._scalar_plan(sys, names)
    entries = {e.spec.name: e for e in sys.block_entries}
    d = np.concatenate(
        [np.repeat(np.asarray(deltas[k])[:, None], entries[k].reps, axis=1) for k in names], axis=1
    )[:, plan["perm"]]
    left = subs._close_scalar_values_left(plan, d, names)
    right = subs._close_scalar_values_right(plan, d, names)
    general = subs._close_scalar_general(plan, d, (5,), names)
    scale = np.abs(general).max()
    np.testing.assert_allclose(left, general, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(right, general, rtol=0, atol=1e-12 * scale)


def test_duplicated_subsystems_use_an_exact_path():
    """Redundant LFR algebra (``P b + P b`` in parallel, then in series; found by hypothesis):
    repeated eigenvalues, some flagged ill-conditioned and some not. The clustered-block method
    would divide by their (near-zero) separation (1e-7 errors); such models take the direct
    solve and match it to 1e-9."""
    rng = np.random.default_rng(0)
    a, b = ureal("a", 1.0, percent=40), ureal("b", 2.0, range=(1.0, 5.0))
    first, second, _ = (random_ss(rng, k, 1, 1, d_scale=0.2) for k in (1, 2, 0))
    expr = first * a
    expr = expr + second * b + second * b
    expr = expr * (a * first)
    expr = expr * (b * second)
    models = usubs(
        expr, {"a": np.array([-1.0, 0.0, 1.0]), "b": np.array([-1.0, 0.0, 1.0])}, normalized=True
    )
    n = models.nstates
    resp = freqresp(models, OMEGA, coupled=False)
    for k in range(3):
        M = models.M[k]
        direct = fr._direct_response(M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:], 1j * OMEGA)
        assert_response_close(resp[k], direct, rtol=RTOL)
