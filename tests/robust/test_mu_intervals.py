"""Frequency intervals of D-G scalings and covers of the frequency axis (mu_intervals).

Every check is against an independent computation: dense sampling of the LMI eigenvalue
(``lmi_residual``), a direct evaluation of the discrete-time response, closed-form worst-case
gains and brute-force sweeps of the parameter box with the H-infinity norm.
"""

import control
import numpy as np
import pytest

from oos_drake.lfr import as_lfr, feedback, ureal
from oos_drake.robust import mussv, robstab, wcgain
from oos_drake.robust.hinf import hinfnorm
from oos_drake.robust.lfr_analysis import block_map
from oos_drake.robust.mu_intervals import (
    Realization,
    Scalings,
    _gaps,
    cover_axis,
    dg_interval,
    mu_solver,
    scalings_at,
)
from oos_drake.robust.mu_upper import lmi_residual

INTEG = control.tf(1, [1, 0])


def second_order(k, c):
    """``1 / (s^2 + c s + k)`` built from integrators (``k``, ``c`` may be uncertain)."""
    integ = as_lfr(INTEG)
    return feedback(integ * feedback(integ, c), k)


def oscillator(k0=1.0, kpm=0.5, c0=0.02, cpm=0.01):
    return second_order(ureal("k", k0, plusminus=kpm), ureal("c", c0, plusminus=cpm))


def delta_realization(sys):
    return Realization(sys.A, sys.Bw, sys.Cz, sys.Dzw), block_map(sys).blk


def sampled_component(real, sc, beta, omega0, grid):
    """Ends of the sampled component of ``{lambda_max(LMI) <= 0}`` around ``omega0`` on ``grid``
    (the sign itself, not the round-off tolerance of a certificate check)."""
    ok = lmi_residual(real.response(grid), beta, sc.D_left, sc.D_right, sc.G) <= 0.0
    i0 = int(np.argmin(np.abs(grid - omega0)))
    assert ok[i0]
    a = b = i0
    while a > 0 and ok[a - 1]:
        a -= 1
    while b < grid.size - 1 and ok[b + 1]:
        b += 1
    return grid[a], grid[b], a == 0, b == grid.size - 1


def interval_and_sampled(real, blk, w0, grid):
    """``dg_interval`` of mussv's scalings at ``w0`` (level 1.005 x its bound) and the sampled
    component on ``grid``: ``(lo, hi, a, b, a_end, b_end, scalings, beta)``."""
    res = mussv(real.response([w0]), blk)
    sc = Scalings(res.D_left[0], res.D_right[0], res.G[0]).conditioned()
    beta = 1.005 * float(res.upper[0])
    lo, hi = dg_interval(real, sc, beta, w0)
    return (lo, hi, *sampled_component(real, sc, beta, w0, grid), sc, beta)


def assert_every_frequency_proved(real, cert, dense):
    """Each frequency of ``dense`` lies in an interval of ``cert`` whose scalings satisfy the LMI
    there at its level (the sign of ``lambda_max``, sampled on ``real``'s own response)."""
    Ms = real.response(dense)
    proved = np.zeros(dense.size, dtype=bool)
    for (lo, hi), sc, lev in zip(cert.interval, cert.scalings, cert.level, strict=True):
        if np.isfinite(lo):
            inside = (dense >= lo) & (dense <= hi)
            assert np.all(lmi_residual(Ms[inside], lev, sc.D_left, sc.D_right, sc.G) <= 0.0)
            proved |= inside
    assert np.all(proved)


def two_modes():
    k1, c1 = ureal("k1", 1.0, plusminus=0.3), ureal("c1", 0.01, plusminus=0.005)
    k2, c2 = ureal("k2", 9.0, plusminus=3.0), ureal("c2", 0.03, plusminus=0.01)
    return second_order(k1, c1) + second_order(k2, c2)


@pytest.mark.parametrize(
    "make, omegas",
    [
        (oscillator, [0.0, 0.3, 0.95, 1.0, 1.2, 5.0]),
        (lambda: oscillator(c0=0.006, cpm=0.003), [0.7, 1.0, 1.3]),
        (two_modes, [0.5, 1.0, 2.0, 3.0, 3.3]),
    ],
)
def test_interval_matches_dense_sampling(make, omegas):
    real, blk = delta_realization(make())
    grid = np.linspace(0.0, 12.0, 120001)  # spacing 1e-4 rad/s
    for w0 in omegas:
        lo, hi, a, b, a_end, b_end, sc, beta = interval_and_sampled(real, blk, w0, grid)
        step = grid[1] - grid[0]
        # never outside the sampled sign change; inside it by at most a sample plus the
        # round-off band where lambda_max is within STRICT of zero (up to 1e-3 relative here)
        if a_end:
            assert lo == 0.0
        else:
            assert a - step <= lo <= a + 1e-3 * a
        if b_end:
            assert hi >= grid[-1]
        else:
            assert b - 1e-3 * b <= hi <= b + step
        # and the LMI holds on a fine grid inside the exact interval
        inner = np.linspace(lo, min(hi, 1e3), 2001)
        lmi = lmi_residual(real.response(inner), beta, sc.D_left, sc.D_right, sc.G)
        assert np.all(lmi <= 0.0)


def test_discrete_interval_on_the_unit_circle():
    Ts = 0.05
    sysd = control.c2d(control.ss(oscillator(c0=0.02).nominal.to_ss()), Ts)  # shape check only
    del sysd
    sys = oscillator()
    cont = control.ss(sys.A, sys.Bw, sys.Cz, sys.Dzw)
    dis = control.c2d(cont, Ts, method="zoh")
    real = Realization.from_lti(dis)
    assert real.sample_time == Ts and real.nyquist == pytest.approx(np.pi / Ts)
    # the Cayley route equals a direct evaluation of C (z I - A)^{-1} B + D on the circle
    w = np.linspace(0.0, np.pi / Ts * 0.999, 37)
    z = np.exp(1j * w * Ts)
    direct = np.array(
        [dis.C @ np.linalg.solve(zk * np.eye(dis.nstates) - dis.A, dis.B) + dis.D for zk in z]
    )
    np.testing.assert_allclose(real.response(w), direct, rtol=1e-10, atol=1e-12)
    blk = block_map(sys).blk
    grid = np.linspace(0.0, np.pi / Ts, 60001)
    for w0 in (0.5, 1.0, 1.1, 20.0):
        lo, hi, a, b, a_end, b_end, sc, beta = interval_and_sampled(real, blk, w0, grid)
        step = grid[1] - grid[0]
        assert (lo == 0.0) if a_end else (a - step <= lo <= a + 1e-3 * a)
        assert (hi == pytest.approx(np.pi / Ts)) if b_end else (b - 1e-3 * b <= hi <= b + step)


def test_cover_proves_every_frequency():
    """Each densely sampled frequency is proved by the scalings of a point whose interval
    holds it, at the certificate's level; the level is within 2 % of the sampled mu peak."""
    real, blk = delta_realization(two_modes())
    cert = cover_axis(real, mu_solver(real, blk, polish_above=0.0), [0.0, 1.0, 3.0])
    assert cert.covered and cert.check() == {
        "intervals_hold": True,
        "covered": True,
        "upper": cert.upper,
    }
    grid = np.concatenate([np.linspace(0.0, 6.0, 30001), np.logspace(0.8, 4, 200)])
    Ms = real.response(grid)
    proved = np.zeros(grid.size, dtype=bool)
    for (lo, hi), sc, lev in zip(cert.interval, cert.scalings, cert.level, strict=True):
        if not np.isfinite(lo):
            continue
        inside = (grid >= lo) & (grid <= hi)
        lmi = lmi_residual(Ms[inside], lev, sc.D_left, sc.D_right, sc.G)
        assert np.all(lmi <= 0.0)
        proved |= inside
    assert np.all(proved)
    # the certified lower bound of mu on the samples (a perturbation of that size puts a pole
    # on the axis): the guaranteed level is above it and within 2 % (the exact mu peak is 0.5:
    # c1 = 0 at twice the range); mussv's pointwise upper bound may spike where its optimizer
    # stalls, the cover's polished points do not
    lower = np.max(mussv(Ms[::10], blk).lower)
    assert lower == pytest.approx(0.5, rel=1e-3)
    assert lower <= cert.upper <= 1.02 * lower


def test_cover_from_known_grid_scalings():
    """``cover_axis(known=...)`` (the analysis' path): a sweep's raw scalings, a stalled one
    among them (D = I, G = 0: the plain norm, far above mu), are tried before any solve; the
    stalled point proves no interval and does not raise the level; every frequency is
    proved (dense LMI check) and the level is within 2 % of the exact peak 0.5."""
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu_upper import mu_upper_bound

    real, blk = delta_realization(two_modes())
    grid = np.geomspace(0.1, 10.0, 25)
    res = mu_upper_bound(real.response(grid), parse_blk(blk), max_iter=30)
    params = res.params.copy()
    params[12] = 0.0  # a stalled point: the identity scalings
    upper, scalings = scalings_at(real, blk, grid, params)
    assert upper[12] == pytest.approx(np.linalg.norm(real.response(grid[12:13])[0], 2))
    cert = cover_axis(
        real,
        mu_solver(real, blk, polish_above=0.5),
        [],
        floor=1.005 * 0.5,
        known=(grid, upper, scalings),
    )
    assert cert.covered and cert.check()["intervals_hold"] and cert.check()["covered"]
    assert 0.5 <= cert.upper <= 1.02 * 0.5
    assert np.sum(~cert.added) >= 2  # known points were used, not solved again
    assert_every_frequency_proved(real, cert, np.linspace(0.0, 6.0, 6001))


@pytest.mark.parametrize(
    "c0, cpm",
    [(0.2, 0.1), (0.02, 0.01), (0.006, 0.003)],  # damping 10 %, 1 %, 0.3 % (nominal)
)
def test_wcgain_guaranteed_oscillator_corner_worst_case(c0, cpm):
    """``1 / (s^2 + c s + k)``, ``k = 1 +- 50 %``: the worst case is the corner (k, c) minimal,
    resonance at 0.71 rad/s, far (tens of half-power bandwidths) from the nominal pole."""
    sys = oscillator(c0=c0, cpm=cpm)
    kmin, cmin = 0.5, c0 - cpm
    exact = 1.0 / (cmin * np.sqrt(kmin - cmin**2 / 4))
    res = wcgain(sys)
    assert res.upper >= exact
    assert res.upper <= 1.02 * exact
    assert exact * 0.98 <= res.lower <= exact * (1 + 1e-9)
    assert res.worst_case["k"] == pytest.approx(kmin, rel=1e-3)
    assert res.worst_case["c"] == pytest.approx(cmin, rel=1e-3)
    assert res.guarantee.check()["intervals_hold"] and res.guarantee.check()["covered"]


def test_wcgain_grid_only_misses_the_peak_guaranteed_does_not():
    """The issue's example: with the grid only the 'upper bound' is below the exact gain."""
    sys = oscillator(c0=0.2, cpm=0.1)
    exact = 1.0 / (0.1 * np.sqrt(0.5 - 0.01 / 4))
    grid = wcgain(sys, guaranteed=False)
    guaranteed = wcgain(sys)
    assert guaranteed.upper >= exact > grid.upper * (1 - 1e-2)
    assert guaranteed.guarantee is not None and grid.guarantee is None


def test_wcgain_two_modes_brute_force():
    sys = two_modes()
    names = list(block_map(sys).names)
    levels = np.linspace(-1.0, 1.0, 7)
    P = np.stack(np.meshgrid(*[levels] * 4, indexing="ij"), axis=-1).reshape(-1, 4)
    from oos_drake.lfr import usubs

    loop = usubs(sys, {n: P[:, i] for i, n in enumerate(names)}, normalized=True)
    brute = float(np.max(hinfnorm((loop.A, loop.Bu, loop.Cy, loop.Dyu)).norm))
    res = wcgain(sys)
    assert res.upper >= brute
    assert res.upper <= 1.02 * brute
    assert res.lower >= 0.98 * brute


def test_robstab_moving_crossing_frequency():
    """``s^3 + a s^2 + b s + c``: Hurwitz iff ``a b > c``; with ``b = 1 - 0.5 t``,
    ``c = 0.05 + 0.04 t`` it loses stability at ``t = 0.05 / 0.09`` with a pole at
    ``j sqrt(b)`` = 0.85 rad/s, away from the nominal 1 rad/s."""
    integ = as_lfr(INTEG)
    b, c = ureal("b", 1.0, plusminus=0.5), ureal("c", 0.05, plusminus=0.04)
    inner = feedback(integ, 0.1)
    loop = feedback(integ * feedback(integ * inner, b), c)
    margin = 0.05 / 0.09
    res = robstab(loop)
    assert res.lower <= margin <= res.upper * (1 + 1e-9)
    assert res.lower >= margin / 1.02
    assert res.upper <= margin * 1.02
    assert res.critical_frequency == pytest.approx(np.sqrt(1 - 0.5 * margin), rel=1e-2)
    assert res.guarantee.check()["covered"]


def test_bad_input():
    with pytest.raises(ValueError, match="without a sample time"):
        Realization.from_lti(control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], True))
    real = Realization([[0.0, 1.0], [-1.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]])
    # a pole on the axis: no error, an open cover that says where and why (tested further in
    # test_mu_intervals_cover.py)
    cert = cover_axis(real, mu_solver(real, [[1, 1]]), [0.0])
    assert not cert.covered and "pole on the imaginary axis at omega = 1 rad/s" in cert.reason
    with pytest.raises(ValueError, match="sample_time"):
        Realization([[0.5]], [[1.0]], [[1.0]], [[0.0]], sample_time=-1.0)
    # a static LFR (no state-space part): one point proves the whole axis
    k = ureal("k", 1.0, plusminus=0.5)
    res = robstab(feedback(as_lfr(2.0) * k, 1))
    assert res.guarantee.covered and res.guarantee.interval[0, 1] == np.inf


def test_cover_continued_from_a_neighbouring_model():
    """``cover_axis(prior=...)`` (the analysis' continuation between configurations): the
    essential scalings of one model's cover, tried first on a neighbouring model, prove its
    level with fewer solved points; every frequency of the neighbour is still proved (dense LMI
    check on the neighbour's own ``M``) and its level is above its sampled mu peak. Scalings that
    prove nothing on the neighbour (a far model's) are simply not used."""
    first, blk = delta_realization(oscillator(k0=1.0))
    near, _ = delta_realization(oscillator(k0=1.01))
    far, _ = delta_realization(oscillator(k0=4.0))
    dense = np.concatenate([np.linspace(0.0, 6.0, 30001), np.logspace(0.8, 4, 200)])
    peak = float(np.max(mussv(near.response(dense[::20]), blk).lower))
    floor = 1.03 * peak
    cert = cover_axis(first, mu_solver(first, blk, polish_above=peak), [], floor=floor)
    keep = cert.essential()
    assert cert.covered and 0 < keep.size <= cert.omega.size
    assert not _gaps(cert.interval[keep], first.nyquist)  # the essential subset covers alone
    prior = (cert.omega[keep], [cert.scalings[i] for i in keep])
    cold = cover_axis(near, mu_solver(near, blk, polish_above=peak), [], floor=floor)
    warm = cover_axis(near, mu_solver(near, blk, polish_above=peak), [], floor=floor, prior=prior)
    assert warm.covered and warm.check()["intervals_hold"] and warm.check()["covered"]
    assert warm.added.sum() < cold.added.sum()
    assert np.isnan(warm.optimal[~warm.added]).any()  # prior points: not solved here
    assert peak <= warm.upper <= 1.02 * floor
    assert_every_frequency_proved(near, warm, dense)
    # a far model: the prior proves (almost) nothing, the cover still closes on its own
    other = cover_axis(far, mu_solver(far, blk, polish_above=peak), [], floor=floor, prior=prior)
    assert other.covered and other.check()["intervals_hold"] and other.check()["covered"]


def with_hidden_modes(real, seed=0):
    """``real`` with four lightly damped modes ``M`` does not see, coupled to its states: two
    unobservable (0.3 % damping at 1 rad/s, where ``M`` peaks) and two uncontrollable; the
    same ``M``, a twice as large Hamiltonian."""
    rng = np.random.default_rng(seed)
    n, r, c = real.A.shape[0], real.B.shape[1], real.C.shape[0]
    hidden = []
    for w, z in ((1.0, 0.003), (3.0, 0.01)):
        hidden.append(np.array([[0.0, w], [-w, -2 * z * w]]))
    unobs, unctrl = hidden
    A = np.zeros((n + 4, n + 4))
    A[:n, :n], A[n : n + 2, n : n + 2], A[n + 2 :, n + 2 :] = real.A, unobs, unctrl
    A[n : n + 2, :n] = rng.standard_normal((2, n))  # driven by the states M sees: unobservable
    A[:n, n + 2 :] = rng.standard_normal((n, 2))  # drives them: uncontrollable
    B = np.vstack([real.B, rng.standard_normal((2, r)), np.zeros((2, r))])
    C = np.hstack([real.C, np.zeros((c, 2)), rng.standard_normal((c, 2))])
    return Realization(A, B, C, real.D)


def test_hamiltonian_test_leaves_out_the_modes_M_does_not_see():
    """``Realization.hamiltonian_modes``: the uncontrollable modes (no trace in the computed
    modal form of ``M`` at all, as the modes of the mission's closed loops that a subset's
    channels miss: 1e-31 of the largest) are left out; the unobservable ones, whose trace in
    the computed modal form is round-off of 1e-11 amplified by their light damping, are kept
    (only modes below the modal form's own round-off go). The response is unchanged and every
    interval is that of the realization without the hidden modes (whose Hamiltonian keeps
    every mode: a second computation) to 1e-4 (the reduced test of DROP_BUDGET leaves weakly
    seen modes out of both, at a margin), checked against dense sampling of the LMI on the
    larger realization."""
    real, blk = delta_realization(two_modes())
    big = with_hidden_modes(real)
    assert real.hamiltonian_modes().all()
    keep = big.hamiltonian_modes()
    n = real.A.shape[0]
    assert keep.size == n + 4 and keep.sum() == n + 2
    uncontrollable = np.linalg.eigvals(big.A[n + 2 :, n + 2 :])
    dropped = big.modal()[0][~keep]
    np.testing.assert_allclose(np.sort_complex(dropped), np.sort_complex(uncontrollable), 1e-9)
    w = np.linspace(0.0, 6.0, 61)
    M = real.response(w)
    np.testing.assert_allclose(big.response(w), M, rtol=1e-9, atol=1e-10 * np.abs(M).max())
    for w0 in (0.5, 1.0, 2.0, 3.0, 3.3):
        res = mussv(real.response([w0]), blk)
        sc = Scalings(res.D_left[0], res.D_right[0], res.G[0]).conditioned()
        beta = 1.005 * float(res.upper[0])
        lo, hi = dg_interval(real, sc, beta, w0)
        lo_b, hi_b = dg_interval(big, sc, beta, w0)
        # the reduced tests (DROP_BUDGET) of both prove intervals barely shorter than exact
        assert lo_b == pytest.approx(lo, rel=1e-4, abs=1e-9)
        assert hi_b == pytest.approx(hi, rel=1e-4) or (np.isinf(hi) and np.isinf(hi_b))
        inner = np.linspace(lo_b, min(hi_b, 1e3), 2001)
        assert np.all(lmi_residual(big.response(inner), beta, sc.D_left, sc.D_right, sc.G) <= 0)


def test_cover_evaluates_known_scalings_only_where_it_tries_them():
    """``cover_axis(known=(omega, optimal, callable))`` (the analysis' path): the grid's
    scalings are evaluated only for the points the cover tries, fewer than all; the cover
    closes at the same kind of level as with every point evaluated up front and every
    frequency is proved (dense LMI check)."""
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu_upper import mu_upper_bound

    real, blk = delta_realization(two_modes())
    grid = np.geomspace(0.1, 10.0, 25)
    res = mu_upper_bound(real.response(grid), parse_blk(blk), max_iter=30)
    asked = []

    def lazy(rows):
        asked.extend(np.asarray(rows).tolist())
        return scalings_at(real, blk, grid[rows], res.params[rows])

    cert = cover_axis(
        real, mu_solver(real, blk, polish_above=0.5), [], floor=1.005 * 0.5,
        known=(grid, res.upper, lazy),
    )  # fmt: skip
    assert cert.covered and cert.check()["intervals_hold"] and cert.check()["covered"]
    assert 0 < len(asked) < grid.size and len(set(asked)) == len(asked)
    assert 0.5 <= cert.upper <= 1.02 * 0.5
    assert_every_frequency_proved(real, cert, np.linspace(0.0, 6.0, 6001))


def test_lazy_cover_proves_the_same_level_with_fewer_hamiltonian_tests(monkeypatch):
    """The lazy cover (default) against ``lazy=False`` on the same problem: both close, the
    lazy one with fewer Hamiltonian tests, both proved on a dense sample, same level."""
    import oos_drake.robust.mu_intervals as mi

    real, blk = delta_realization(two_modes())
    tests = []
    dg = mi.dg_interval
    monkeypatch.setattr(mi, "dg_interval", lambda *a: tests.append(1) or dg(*a))
    certs = {}
    for lazy in (False, True):
        tests.clear()
        seeds = np.r_[0.0, np.linspace(0.5, 4.0, 15)]
        certs[lazy] = (cover_axis(real, mu_solver(real, blk), seeds, lazy=lazy), len(tests))
    (eager, n_eager), (lazy, n_lazy) = certs[False], certs[True]
    assert eager.covered and lazy.covered
    assert n_lazy < n_eager
    assert lazy.upper == pytest.approx(eager.upper, rel=1e-9)
    dense = np.concatenate([np.linspace(0.0, 6.0, 20001), np.logspace(0.8, 4, 200)])
    assert_every_frequency_proved(real, lazy, dense)
    assert lazy.check()["intervals_hold"] and lazy.check()["covered"]


def with_weak_modes(real, weight):
    """``real`` plus two lightly damped modes that ``M`` sees weakly (residues about
    ``weight``): at 0.8 rad/s (2 % damping) and 2 rad/s (1 %), near the ends of the intervals
    of ``two_modes``, so that leaving them out changes where the LMI crosses zero."""
    n, r, c = real.A.shape[0], real.B.shape[1], real.C.shape[0]
    rng = np.random.default_rng(3)
    A = np.zeros((n + 4, n + 4))
    A[:n, :n] = real.A
    for k, (w, z) in enumerate(((0.8, 0.02), (2.0, 0.01))):
        A[n + 2 * k : n + 2 * k + 2, n + 2 * k : n + 2 * k + 2] = [[0.0, w], [-w, -2 * z * w]]
    B = np.vstack([real.B, np.sqrt(weight) * rng.standard_normal((4, r))])
    C = np.hstack([real.C, np.sqrt(weight) * rng.standard_normal((c, 4))])
    return Realization(A, B, C, real.D)


def reduced_and_exact_intervals(monkeypatch, real, blk, budget, omegas):
    """``(w0, sc, beta, (lo, hi) at DROP_BUDGET = budget, (lo, hi) exact, reduced)`` for
    mussv's scalings at each ``w0`` (level 1.005 x its bound); exact: DROP_BUDGET = 0 (only the
    round-off modes of Realization.hamiltonian_modes left out); reduced: the first interval
    came from the reduced test (modes left out, and it proves the level at ``w0``)."""
    import oos_drake.robust.mu_intervals as mi

    out = []
    for w0 in omegas:
        res = mussv(real.response([w0]), blk)
        sc = Scalings(res.D_left[0], res.D_right[0], res.G[0]).conditioned()
        beta = 1.005 * float(res.upper[0])
        monkeypatch.setattr(mi, "DROP_BUDGET", budget)
        mult = mi._Multiplier(real, sc, beta, reduce=True)
        used = mult.dropped > 0 and mult.max_eig([w0])[0] < -mi.STRICT
        reduced = dg_interval(real, sc, beta, w0)
        monkeypatch.setattr(mi, "DROP_BUDGET", 0.0)
        exact = dg_interval(real, sc, beta, w0)
        out.append((w0, sc, beta, reduced, exact, used))
    return out


def test_reduced_hamiltonian_test_proves_only_what_holds(monkeypatch):
    """DROP_BUDGET's reduced interval test, made to leave out weakly seen modes (budget 1e-2
    instead of 1e-6): where it proves the level with fewer modes in its Hamiltonian, and
    everywhere, every interval lies inside the exact one (whole realization) and holds on dense
    sampling of the LMI on the whole response."""
    real, blk = delta_realization(two_modes())
    big = with_weak_modes(real, 1e-6)
    dense = np.linspace(0.0, 8.0, 16001)
    Ms = big.response(dense)
    omegas = (0.2, 0.4, 0.6, 1.0, 1.5, 2.5, 5.0)
    rows = reduced_and_exact_intervals(monkeypatch, big, blk, 1e-2, omegas)
    assert sum(used for *_, used in rows) >= 2  # the shortcut is exercised
    for w0, sc, beta, (lo, hi), (lo0, hi0), _ in rows:
        assert lo0 * (1 - 1e-9) <= lo <= w0 <= hi <= hi0 * (1 + 1e-9), (w0, lo, hi, lo0, hi0)
        inside = (dense >= lo) & (dense <= hi)
        assert np.all(lmi_residual(Ms[inside], beta, sc.D_left, sc.D_right, sc.G) <= 0.0)


def test_reduced_hamiltonian_test_without_its_margin_is_caught(monkeypatch):
    """The same reduction with the margin left out (``P11``, ``P22`` of the whole realization
    kept: a wrong shortcut) claims frequencies the scalings do not prove: some interval reaches
    beyond the exact one and dense sampling of the LMI finds a positive eigenvalue in it. The
    checks of the test above would catch such a shortcut."""
    import oos_drake.robust.mu_intervals as mi

    reduce = mi._Multiplier._reduce

    def without_margin(self):
        P11, P22 = self.P11, self.P22
        reduce(self)
        self.P11, self.P22 = P11, P22

    monkeypatch.setattr(mi._Multiplier, "_reduce", without_margin)
    real, blk = delta_realization(two_modes())
    big = with_weak_modes(real, 1e-4)
    dense = np.linspace(0.0, 8.0, 16001)
    Ms = big.response(dense)
    rows = reduced_and_exact_intervals(monkeypatch, big, blk, 1e2, (0.2, 0.4, 0.5, 0.6))
    wrong = 0
    for _, sc, beta, (lo, hi), (lo0, hi0), _ in rows:
        inside = (dense >= lo) & (dense <= hi)
        bad = np.any(lmi_residual(Ms[inside], beta, sc.D_left, sc.D_right, sc.G) > 0.0)
        wrong += bool(bad) and (lo < lo0 * (1 - 1e-6) or hi > hi0 * (1 + 1e-6))
    assert wrong


def test_a_narrow_gap_gets_its_middle_only():
    """``_new_points``: a gap narrower than NARROW_GAP (relative) is solved at its middle only;
    a wider one at both edges and in between; the infinite gap at its start and beyond; a
    narrow gap whose middle was tried (and left it open) at its edges, as any gap (else the
    cover would stop there: ``tests/robust/test_robstab.py``'s sweep did)."""
    from oos_drake.robust.mu_intervals import NARROW_GAP, _new_points

    narrow = (2.0, 2.0 * (1 + 0.5 * NARROW_GAP))
    wide = (3.0, 3.0 * (1 + 4 * NARROW_GAP))
    pts = _new_points([narrow, wide, (10.0, np.inf)], np.inf, [])
    np.testing.assert_allclose(
        pts, [0.5 * sum(narrow), wide[0], 0.5 * sum(wide), wide[1], 10.0, 20.0, 100.0]
    )
    # its middle tried already (a round that did not close it): its edges and middle again
    again = _new_points([narrow], np.inf, [0.5 * sum(narrow)])
    np.testing.assert_allclose(again, [narrow[0], narrow[1]])


def test_scalings_that_are_not_definite_are_refused_every_time():
    """The definiteness check of :func:`dg_interval` is done once per :class:`Scalings` (kept
    on it): a second test of the same scalings is refused for the same reason, and the
    conditioned scalings (a new object) prove an interval that dense sampling confirms."""
    real, blk = delta_realization(oscillator())
    res = mussv(real.response([1.0]), blk)
    D_left = np.array(res.D_left[0], dtype=complex)
    D_left[0, 0] = -abs(D_left[0, 0])  # one scalar block negative: not a D scaling
    bad = Scalings(D_left, res.D_right[0], res.G[0])
    beta = 1.005 * float(res.upper[0])
    for _ in range(2):
        with pytest.raises(ValueError, match="not positive definite"):
            dg_interval(real, bad, beta, 1.0)
    good = Scalings(res.D_left[0], res.D_right[0], res.G[0]).conditioned()
    lo, hi = dg_interval(real, good, beta, 1.0)
    assert lo < 1.0 < hi
    inner = np.linspace(lo, min(hi, 1e3), 4001)
    lmi = lmi_residual(real.response(inner), beta, good.D_left, good.D_right, good.G)
    assert np.all(lmi <= 0.0)
