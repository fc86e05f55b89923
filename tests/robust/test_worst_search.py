"""Worst cases against brute force: destabilizing real boxes, complex phases, robstab, mussv.

The oracles here are written plainly (closed loop by ``numpy.linalg.solve``, a scan and a
bisection of the spectral abscissa along rays; a grid over the phases then Nelder-Mead), not
with the searched code.
"""

import control
import numpy as np
import pytest
from scipy.optimize import minimize

from oos_drake.lfr import feedback, ureal, usubs
from oos_drake.robust import mussv, robstab
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.worst_search import complex_phase_search, real_destabilizing


# ----------------------------------------------------------------------------- oracles
def _random_real_lfr(seed, n=6, reps=(1, 2, 1)):
    """A stable state space with ``len(reps)`` repeated real parameters in its Delta channel."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A -= (np.linalg.eigvals(A).real.max() + 0.5) * np.eye(n)
    nz = sum(reps)
    Bw = rng.standard_normal((n, nz))
    Cz = 0.5 * rng.standard_normal((nz, n))
    Dzw = 0.1 * rng.standard_normal((nz, nz))
    blk = [[-r, 0] for r in reps]
    return A, Bw, Cz, Dzw, blk


def _oracle_abscissa(A, Bw, Cz, Dzw, reps, X):
    """Spectral abscissa of ``A + Bw D (I - Dzw D)^{-1} Cz`` for each row ``x`` of ``X``."""
    X = np.asarray(X, dtype=float)
    D = np.zeros((len(X), Dzw.shape[0], Dzw.shape[0]))
    idx = np.arange(Dzw.shape[0])
    D[:, idx, idx] = np.repeat(X, reps, axis=1)
    X_inv_Cz = np.linalg.solve(
        np.eye(Dzw.shape[0]) - Dzw @ D, np.broadcast_to(Cz, (len(X),) + Cz.shape)
    )
    return np.linalg.eigvals(A + Bw @ D @ X_inv_Cz).real.max(axis=1)


def _oracle_first_crossing(A, Bw, Cz, Dzw, reps, d, t_max, steps=80):
    """Smallest ``t <= t_max`` with ``t d`` unstable (scan of ``steps`` then bisection)."""
    ts = np.linspace(0.0, t_max, steps + 1)[1:]
    alpha = _oracle_abscissa(A, Bw, Cz, Dzw, reps, ts[:, None] * d[None])
    bad = np.flatnonzero(alpha >= 0)
    if bad.size == 0:
        return np.inf
    lo, hi = (ts[bad[0] - 1] if bad[0] else 0.0), ts[bad[0]]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if _oracle_abscissa(A, Bw, Cz, Dzw, reps, [mid * d])[0] >= 0:
            hi = mid
        else:
            lo = mid
    return hi


def _oracle_box(A, Bw, Cz, Dzw, reps, t_max, rng, random_points=1000):
    """Brute force: all vertices, ``random_points`` random directions and a fine grid of the
    faces of the first two parameters, each ray scanned for its first instability.

    The dense part is screened at ``t_max`` first (a ray stable there cannot beat it)."""
    k = len(reps)
    V = 2.0 * ((np.arange(2**k)[:, None] >> np.arange(k)) & 1) - 1.0
    R = rng.uniform(-1, 1, (random_points, k))
    g = np.linspace(-1, 1, 41)
    F = []
    for a in g:  # faces |x0| = 1 or |x1| = 1, others at the best vertex's signs later
        F += [[1.0, a], [-1.0, a], [a, 1.0], [a, -1.0]]
    dirs = [V, R / np.abs(R).max(axis=1, keepdims=True)]
    best = np.inf
    for D in dirs:
        alpha = _oracle_abscissa(A, Bw, Cz, Dzw, reps, t_max * D)
        for d in D[alpha >= 0]:
            best = min(best, _oracle_first_crossing(A, Bw, Cz, Dzw, reps, d, min(best, t_max)))
    if k >= 2 and np.isfinite(best):
        # fine grid on the first two parameters, the others at each vertex of theirs
        rest = 2.0 * ((np.arange(2 ** (k - 2))[:, None] >> np.arange(k - 2)) & 1) - 1.0
        G = np.array([np.concatenate([f, r]) for f in F for r in rest])
        alpha = _oracle_abscissa(A, Bw, Cz, Dzw, reps, best * G)
        for d in G[alpha >= 0]:
            best = min(best, _oracle_first_crossing(A, Bw, Cz, Dzw, reps, d, best))
    return best


# ----------------------------------------------------------------------------- real boxes
@pytest.mark.parametrize("seed", range(4))
def test_real_destabilizing_box_as_small_as_brute_force(seed):
    A, Bw, Cz, Dzw, blk = _random_real_lfr(seed)
    reps = [-b[0] for b in blk]
    structure = parse_blk(blk)
    found = real_destabilizing(A, Bw, Cz, Dzw, structure, scale=10.0)
    assert found is not None
    brute = _oracle_box(A, Bw, Cz, Dzw, reps, 10.0, np.random.default_rng(100 + seed))
    assert 1.0 / found.mu_lower <= brute * (1 + 5e-3)
    # certified: re-checked without the search, and a pole on the axis at omega
    assert found.check(A, Bw, Cz, Dzw, structure)
    D = found.delta.real
    Acl = A + Bw @ D @ np.linalg.solve(np.eye(len(D)) - Dzw @ D, Cz)
    poles = np.linalg.eigvals(Acl)
    scale = np.abs(poles).max()
    assert np.min(np.abs(poles - 1j * found.omega)) < 1e-8 * scale
    assert poles.real.max() < 1e-8 * scale  # no pole beyond the axis: the first crossing


def test_check_refuses_what_is_not_a_certificate():
    A, Bw, Cz, Dzw, blk = _random_real_lfr(0)
    structure = parse_blk(blk)
    found = real_destabilizing(A, Bw, Cz, Dzw, structure, scale=10.0)
    assert found.check(A, Bw, Cz, Dzw, structure)
    smaller = type(found)(
        found.mu_lower / 0.99, found.omega, 0.99 * found.delta, found.residual, found.source
    )
    assert not smaller.check(A, Bw, Cz, Dzw, structure)  # a smaller delta is not singular
    shifted = type(found)(found.mu_lower, found.omega * 1.01 + 0.01, found.delta, 0.0, "x")
    assert not shifted.check(A, Bw, Cz, Dzw, structure)  # wrong frequency
    broken = found.delta.copy()
    broken[1, 1] *= -1  # the repeated block (rows 1, 2) no longer a scalar times I
    bad = type(found)(found.mu_lower, found.omega, broken, 0.0, "x")
    assert not bad.check(A, Bw, Cz, Dzw, structure)
    lying = type(found)(2 * found.mu_lower, found.omega, found.delta, 0.0, "x")
    assert not lying.check(A, Bw, Cz, Dzw, structure)  # claims more than its size proves


def test_twelve_parameters_against_vertices_and_random_points():
    A, Bw, Cz, Dzw, blk = _random_real_lfr(7, n=8, reps=(1,) * 12)
    A = A - 1.0 * np.eye(8)
    reps = [1] * 12
    structure = parse_blk(blk)
    found = real_destabilizing(A, Bw, Cz, Dzw, structure, scale=10.0)
    assert found is not None and found.check(A, Bw, Cz, Dzw, structure)
    rng = np.random.default_rng(3)
    V = 2.0 * ((np.arange(2**12)[:, None] >> np.arange(12)) & 1) - 1.0
    R = rng.uniform(-1, 1, (1000, 12))
    D = np.vstack([V, R / np.abs(R).max(axis=1, keepdims=True)])
    t = 1.0 / found.mu_lower
    # nothing in the brute-force set is unstable at 0.995 times the box found
    assert _oracle_abscissa(A, Bw, Cz, Dzw, reps, 0.995 * t * D).max() < 0


# ----------------------------------------------------------------------------- complex phases
def _phase_oracle(M, reps, rng):
    """``max_theta rho(M diag(e^{j theta}))`` by 8000 random phases and Nelder-Mead."""
    n, k = M.shape[0], len(reps)
    owner = np.repeat(np.arange(k), reps)

    def rho(th):
        th = np.atleast_2d(th)
        full = np.concatenate([np.zeros((th.shape[0], 1)), th], axis=1)
        D = np.zeros((th.shape[0], n, n), complex)
        D[:, np.arange(n), np.arange(n)] = np.exp(1j * full[:, owner])
        return np.abs(np.linalg.eigvals(M @ D)).max(axis=1)

    P = rng.uniform(-np.pi, np.pi, (8000, k - 1))
    values = rho(P)
    return max(
        -minimize(
            lambda t: -rho(t)[0],
            P[i],
            method="Nelder-Mead",
            options=dict(xatol=1e-10, fatol=1e-13, maxiter=4000),
        ).fun  # fmt: skip
        for i in np.argsort(-values)[:4]
    )


@pytest.mark.parametrize("seed", range(3))
def test_complex_scalar_mu_lower_bound_matches_the_phase_brute_force(seed):
    rng = np.random.default_rng(seed)
    reps = (2, 1, 2, 1)
    blk = [[r, 0] for r in reps]
    n = sum(reps)
    M = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    brute = _phase_oracle(M, reps, np.random.default_rng(50 + seed))
    res = mussv(M, blk)
    assert res.lower >= 0.99 * brute
    assert res.upper >= brute * (1 - 1e-9)
    value, delta, _ = complex_phase_search(M, parse_blk(blk))
    assert value >= 0.999 * brute
    # certified: I - M delta singular, delta = phases / lambda, |delta_k| = 1 / value
    assert np.linalg.svd(np.eye(n) - M @ delta, compute_uv=False)[-1] < 1e-9 * np.linalg.norm(M)
    assert np.allclose(np.abs(np.diag(delta)), 1.0 / value, rtol=1e-12)
    assert np.count_nonzero(delta - np.diag(np.diag(delta))) == 0
    for start, r in zip(np.cumsum((0,) + reps[:-1]), reps, strict=True):
        assert np.allclose(np.diag(res.delta)[start : start + r], res.delta[start, start])


# ----------------------------------------------------------------------------- robstab
def test_robstab_worst_case_beats_the_box_search_and_puts_a_pole_on_the_axis():
    """A loop with a non-vertex worst case: robstab's perturbation at least as small as the
    vertices' and 1000 random points' first instabilities (within 0.5 %), substituted by name
    in the LFR, gives a closed-loop pole at ``j critical_frequency``."""
    k = ureal("k", 30.0, plusminus=10.0)
    p = ureal("p", 3.0, plusminus=1.0)
    q = ureal("q", 1.0, plusminus=0.5)
    integrator = control.tf(1, [1, 0])
    inner = feedback(integrator, p) * feedback(integrator, q)  # 1 / ((s + p)(s + q))
    loop = feedback(k * control.tf(1, [1, 2]) * inner, 1)
    assert np.linalg.eigvals(np.asarray(loop.A)).real.max() < 0
    res = robstab(loop, guaranteed=False)
    names = list(loop.uncertainty)

    def abscissa(X):
        vals = {n: X[:, i] for i, n in enumerate(names)}
        return np.linalg.eigvals(np.asarray(usubs(loop, vals, normalized=True).A)).real.max(-1)

    rng = np.random.default_rng(9)
    k = len(names)
    V = 2.0 * ((np.arange(2**k)[:, None] >> np.arange(k)) & 1) - 1.0
    R = rng.uniform(-1, 1, (1000, k))
    D = np.vstack([V, R / np.abs(R).max(axis=1, keepdims=True)])
    assert abscissa(0.995 * res.upper * D).max() < 0
    one = usubs(loop, res.worst_case)
    poles = np.linalg.eigvals(np.asarray(one.A))
    assert np.min(np.abs(poles - 1j * res.critical_frequency)) < 1e-7 * np.abs(poles).max()


# ----------------------------------------------------------------------------- wcgain
def _three_modes():
    """Sum of three uncertain oscillators ``1 / (s^2 + c_i s + k_i)`` (six parameters)."""
    integ = control.tf(1, [1, 0])

    def second_order(k, c):
        return feedback(integ * feedback(integ, c), k)

    return (
        second_order(ureal("k1", 1.0, plusminus=0.3), ureal("c1", 0.05, plusminus=0.02))
        + second_order(ureal("k2", 4.0, plusminus=1.0), ureal("c2", 0.1, plusminus=0.04))
        + second_order(ureal("k3", 9.0, plusminus=2.0), ureal("c3", 0.2, plusminus=0.1))
    )


def test_wcgain_lower_bound_as_good_as_vertices_and_random_points():
    from oos_drake.robust import wcgain
    from oos_drake.robust.hinf import hinfnorm

    sys = _three_modes()
    names = list(sys.uncertainty)
    k = len(names)
    rng = np.random.default_rng(11)
    V = 2.0 * ((np.arange(2**k)[:, None] >> np.arange(k)) & 1) - 1.0
    P = np.vstack([V, rng.uniform(-1, 1, (1000, k))])
    loop = usubs(sys, {n: P[:, i] for i, n in enumerate(names)}, normalized=True)
    brute = float(np.max(hinfnorm((loop.A, loop.Bu, loop.Cy, loop.Dyu)).norm))
    res = wcgain(sys, guaranteed=False)
    assert res.lower >= brute * (1 - 5e-3)
    # attained: the named worst case substituted gives a stable loop with that peak gain
    one = usubs(sys, res.worst_case)
    assert np.linalg.eigvals(np.asarray(one.A)).real.max() < 0
    exact = hinfnorm((one.A, one.Bu, one.Cy, one.Dyu)).norm
    assert float(exact) >= res.lower * (1 - 1e-6)
    assert (res.gap_note != "") == ((res.upper - res.lower) / res.upper > 0.05)


def test_worst_gain_check_refuses_what_is_not_attained():
    from oos_drake.robust.lfr_analysis import block_map
    from oos_drake.robust.worst_search import real_worst_gain

    sys = _three_modes()
    bmap = block_map(sys)
    A, B = np.asarray(sys.A), np.hstack([sys.Bw, sys.Bu])
    C, D = np.vstack([sys.Cz, sys.Cy]), np.block([[sys.Dzw, sys.Dzu], [sys.Dyw, sys.Dyu]])
    nz, nw = np.shape(sys.Dzw)
    structure = parse_blk(bmap.blk)
    found = real_worst_gain(A, B, C, D, nz, nw, structure, [1.0, 2.0, 3.0], random_points=200)
    assert found.check(A, B, C, D, nz, nw, structure)
    Worst = type(found)
    more = Worst(found.gain * 1.01, found.omega, found.x, "x", 0)
    assert not more.check(A, B, C, D, nz, nw, structure)
    outside = Worst(found.gain, found.omega, 1.5 * found.x, "x", 0)
    assert not outside.check(A, B, C, D, nz, nw, structure)
    elsewhere = Worst(found.gain, 0.3 * found.omega, found.x, "x", 0)
    assert not elsewhere.check(A, B, C, D, nz, nw, structure)


def test_robstab_mixed_structure_against_brute_force():
    """``k G (1 + 0.4 D)`` in unit feedback, ``k`` real, ``D`` a scalar ``ultidyn``: at each
    frequency and ``k = 1 + 0.5 x`` the singular ``D`` solves a linear equation, so the
    smallest destabilizing size is ``min max(|x|, |delta(x, omega)|)`` on a dense grid."""
    from oos_drake.lfr import ultidyn
    from oos_drake.robust.lfr_analysis import block_map, delta_channel_response

    k = ureal("k", 1.0, plusminus=0.5)
    loop = feedback(k * control.tf(1, [0.5, 1.2, 1.4, 1]) * (1 + 0.4 * ultidyn("D", (1, 1))), 1)
    res = robstab(loop, guaranteed=False)
    A, Bw, Cz, Dzw = (np.asarray(m) for m in (loop.A, loop.Bw, loop.Cz, loop.Dzw))
    omega = np.concatenate([[0.0], np.geomspace(0.1, 10.0, 2001)])
    M = delta_channel_response(A, Bw, Cz, Dzw, omega)
    ik = list(block_map(loop).names).index("k")
    iD = 1 - ik
    x = np.linspace(-0.3, 0.3, 2001)[:, None]
    m11, m12, m21, m22 = (M[None, :, i, j] for i, j in ((ik, ik), (ik, iD), (iD, ik), (iD, iD)))
    d = (1 - m11 * x) / (m22 * (1 - m11 * x) + m12 * m21 * x)
    brute = float(np.maximum(np.abs(x), np.abs(d)).min())
    assert res.upper <= brute * (1 + 5e-3)
    # certified: the perturbation at the critical frequency makes I - M delta singular
    Mc = delta_channel_response(A, Bw, Cz, Dzw, [res.critical_frequency])[0]
    delta = np.zeros((2, 2), complex)
    delta[ik, ik] = res.worst_case_normalized["k"]
    delta[iD, iD] = np.asarray(res.worst_case_normalized["D"]).ravel()[0]
    assert np.linalg.svd(np.eye(2) - Mc @ delta, compute_uv=False)[-1] < 1e-7
    np.testing.assert_allclose(np.abs(delta).max(), res.upper, rtol=1e-9)
