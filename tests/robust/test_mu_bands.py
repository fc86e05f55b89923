"""Scalings chosen for a band of frequencies (``band_scalings``, ``cover_axis(bands=True)``)
and the placement of a cover's new points next to known intervals.

A band's scalings are only a candidate: every interval they give is a ``dg_interval``. Checked
against dense sampling of the LMI's largest eigenvalue (``lmi_residual``) and, for the bound
of fixed scalings, against the generalized Hermitian eigenproblem solved by scipy.
"""

import numpy as np
import pytest
import scipy.linalg
from test_mu_intervals import (  # tests/robust is on sys.path (rootdir imports)
    assert_every_frequency_proved,
    delta_realization,
    sampled_component,
    second_order,
)

import oos_drake.robust.mu_intervals as mi
from oos_drake.lfr import ureal
from oos_drake.robust.mu_intervals import (
    EDGE_SHIFT,
    Scalings,
    _new_points,
    band_scalings,
    cover_axis,
    dg_interval,
    mu_solver,
    proving_scalings,
)
from oos_drake.robust.mu_upper import lmi_residual


def two_modes():
    """Two lightly damped modes with uncertain stiffness and damping (mu peaks near 1 and
    3 rad/s)."""
    k1, c1 = ureal("k1", 1.0, plusminus=0.3), ureal("c1", 0.01, plusminus=0.005)
    k2, c2 = ureal("k2", 9.0, plusminus=3.0), ureal("c2", 0.03, plusminus=0.01)
    return second_order(k1, c1) + second_order(k2, c2)


def fixed_bound(real, sc, omega):
    """The bound the scalings give at each frequency: the largest ``beta`` with ``M^* D_l M +
    j (G M - M^* G^*) - beta^2 D_r`` singular (scipy's generalized Hermitian eigensolver)."""
    out = []
    for M in real.response(omega):
        GM = sc.G @ M
        A = np.conj(M.T) @ sc.D_left @ M + 1j * (GM - np.conj(GM.T))
        ev = scipy.linalg.eigh(0.5 * (A + np.conj(A.T)), 0.5 * (sc.D_right + np.conj(sc.D_right.T)),
                               eigvals_only=True)  # fmt: skip
        out.append(np.sqrt(max(ev[-1], 0.0)))
    return np.array(out)


def band_problem():
    """The band 2.3-2.5 rad/s of :func:`two_modes` (below its second peak, mu rising) with the
    mussv scalings solved at the band's middle."""
    real, blk = delta_realization(two_modes())
    band = np.geomspace(2.3, 2.5, 5)
    solver = mu_solver(real, blk)
    solver(band[2:3])
    starts = list(zip(solver.solved_omega, solver.solved_params, strict=True))
    return real, blk, band, starts


def test_band_scalings_lower_the_bound_over_the_band():
    """The common scalings' bound (scipy's generalized eigenvalues, independent of the
    optimizer's evaluation) is what ``band_scalings`` reports, and their largest over the
    band is not above that of the scalings optimal at the band's middle (its start)."""
    real, blk, band, starts = band_problem()
    bound, sc, upper = band_scalings(real, blk, band, starts)
    np.testing.assert_allclose(fixed_bound(real, sc, band), upper, rtol=1e-6)
    assert bound == pytest.approx(np.max(upper), rel=1e-12)
    res = mi.mu_upper_bound(real.response(band[2:3]), mi.parse_blk(blk), max_iter=0,
                            x0=np.asarray(starts[0][1])[None])  # fmt: skip
    middle = Scalings(res.D_left[0], res.D_right[0], res.G[0])
    assert bound <= (1 + 1e-9) * np.max(fixed_bound(real, middle, band))


def test_band_interval_proves_only_what_holds():
    """The interval of a band's scalings at a level 0.5 % above their bound over the band:
    inside the sampled component of ``{lambda_max(LMI) <= 0}`` (spacing 2e-5 rad/s), the LMI
    negative on a dense grid of it, and it reaches beyond the band's middle, where it was
    tested from, to the band's inner frequencies (the conditioning of the scalings and the
    margins of the test cost the last few %)."""
    real, blk, band, starts = band_problem()
    bound, sc, _ = band_scalings(real, blk, band, starts)
    level = 1.005 * bound
    sc = proving_scalings(real, sc, level, band[2])
    lo, hi = dg_interval(real, sc, level, band[2])
    grid = np.linspace(1.5, 3.5, 100001)
    a, b, a_end, b_end = sampled_component(real, sc, level, band[2], grid)
    step = grid[1] - grid[0]
    assert not (a_end or b_end)
    # inside it (mu is flat here: lambda_max stays within the round-off margins of the test
    # over a few % near the ends, which the test does not claim)
    assert a - step <= lo and hi <= b + step
    inner = np.linspace(lo, hi, 4001)
    assert np.all(lmi_residual(real.response(inner), level, sc.D_left, sc.D_right, sc.G) <= 0.0)
    assert lo < band[1] and band[-2] < hi  # beyond the middle it was tested from


def test_a_band_scaling_at_a_level_too_low_is_refused():
    """The same scalings at a level 1 % below their bound over the band (a band that claims
    too much): the interval test refuses at every frequency of the band (no strict LMI), and
    sampling agrees (the LMI has a positive eigenvalue at each of them)."""
    real, blk, band, starts = band_problem()
    bound, sc, _ = band_scalings(real, blk, band, starts)
    sc = sc.conditioned()
    level = 0.99 * bound
    assert np.all(lmi_residual(real.response(band), level, sc.D_left, sc.D_right, sc.G) > 0.0)
    for w in band:
        with pytest.raises(ValueError, match="do not prove"):
            dg_interval(real, sc, level, w)


def close_to_peak_cover(monkeypatch, band=None, bands=True):
    """A cover of :func:`two_modes` at 0.3 % above its mu peak, bands tried on every finite
    gap up to a ratio of 4, with ``_MuSolver.band`` replaced by ``band`` if given;
    ``(realization, certificate, band calls)``."""
    real, blk = delta_realization(two_modes())
    calls = []
    original = mi._MuSolver.band
    monkeypatch.setattr(mi, "BAND_RATIO", 4.0)  # this example's gaps are wide: bands in all

    def counted(self, omega, level):
        calls.append(omega)
        return (band or original)(self, omega, level)

    monkeypatch.setattr(mi._MuSolver, "band", counted)
    cert = cover_axis(real, mu_solver(real, blk), [0.0, 1.0, 3.0], floor=1.003 * 0.5,
                      bands=bands)  # fmt: skip
    return real, cert, calls


def test_cover_with_bands_proves_every_frequency(monkeypatch):
    """``cover_axis(bands=True)``: bands are tried in the gaps, some prove intervals; the
    cover closes at the level of the cover without them, every densely sampled frequency
    proved."""
    real, cert, calls = close_to_peak_cover(monkeypatch)
    _, plain, none = close_to_peak_cover(monkeypatch, bands=False)
    assert calls and not none
    band_points = [i for i, w in enumerate(cert.omega) if cert.added[i] and any(
        np.isclose(w, np.sqrt(o[0] * o[-1]), rtol=1e-12) for o in calls)]  # fmt: skip
    assert any(np.isfinite(cert.interval[i, 0]) for i in band_points)
    assert cert.covered and plain.covered
    assert cert.upper == pytest.approx(plain.upper, rel=1e-9)
    assert cert.check()["intervals_hold"] and cert.check()["covered"]
    dense = np.concatenate([np.linspace(0.0, 6.0, 20001), np.logspace(0.8, 4, 200)])
    assert_every_frequency_proved(real, cert, dense)


@pytest.mark.parametrize("lie", [False, True])
def test_cover_falls_back_to_points_where_a_band_fails(monkeypatch, lie):
    """Bands that fail: identity scalings with their true bound (far above the level: never
    added) or claiming a bound of 0 (added, and refused by the interval test): the cover
    solves those gaps point by point and closes, every frequency proved."""

    def failing(self, omega, level):
        c, r = self.real.D.shape
        sc = Scalings(np.eye(c), np.eye(r), np.zeros((r, c)))
        true = float(np.max(np.linalg.norm(self.real.response(omega), 2, axis=(1, 2))))
        return (0.0 if lie else true), sc

    real, cert, calls = close_to_peak_cover(monkeypatch, band=failing)
    assert calls and cert.covered
    assert cert.check()["intervals_hold"] and cert.check()["covered"]
    dense = np.concatenate([np.linspace(0.0, 6.0, 20001), np.logspace(0.8, 4, 200)])
    assert_every_frequency_proved(real, cert, dense)
    # identity scalings prove ||M(j omega)||_2 <= level: where the norm is above the level
    # (the lie) they proved nothing, and where they proved an interval the norm is below it
    identity = [i for i, sc in enumerate(cert.scalings) if np.allclose(sc.G, 0.0)
                and np.allclose(sc.D_left, np.eye(sc.D_left.shape[0]))]  # fmt: skip
    assert bool(identity) == lie
    for i in identity:
        lo, hi = cert.interval[i]
        norm = np.linalg.norm(real.response([cert.omega[i]])[0], 2)
        if norm > cert.level[i]:
            assert not np.isfinite(lo)
        elif np.isfinite(lo):
            inner = np.linspace(lo, min(hi, 1e3), 2001)
            assert np.all(np.linalg.norm(real.response(inner), 2, axis=(1, 2)) <= cert.level[i])
    if lie:
        assert any(not np.isfinite(cert.interval[i, 0]) for i in identity)


def test_new_points_move_into_the_gap_by_the_neighbours_width():
    """``_new_points`` with the neighbours' log-widths: the points at ``a exp(EDGE_SHIFT
    L_a)`` and ``b exp(-EDGE_SHIFT L_b)`` (closed form); the middle only where they would
    cross; the middle added where intervals as wide around them would not meet; without
    widths the edges and the middle as before."""
    a, b = 2.0, 2.4
    la, lb = 0.02, 0.04
    pts = _new_points([(a, b)], np.inf, [], [(la, lb)])
    expect = [a * np.exp(EDGE_SHIFT * la), np.sqrt(a * b), b * np.exp(-EDGE_SHIFT * lb)]
    np.testing.assert_allclose(pts, expect)
    # wide neighbours: the two points' intervals meet, no middle
    pts = _new_points([(a, b)], np.inf, [], [(0.2, 0.2)])
    np.testing.assert_allclose(pts, [a * np.exp(EDGE_SHIFT * 0.2), b * np.exp(-EDGE_SHIFT * 0.2)])
    # neighbours wider than the gap: the points would cross, the geometric middle alone
    pts = _new_points([(a, a * 1.01)], np.inf, [], [(0.1, 0.1)])
    np.testing.assert_allclose(pts, [np.sqrt(a * a * 1.01)])
    # one width unknown: that edge itself (and the middle: its interval is taken as empty)
    pts = _new_points([(a, b)], np.inf, [], [(np.nan, 0.2)])
    np.testing.assert_allclose(pts, [a, np.sqrt(a * b), b * np.exp(-EDGE_SHIFT * 0.2)])
    # no widths: as before
    np.testing.assert_allclose(_new_points([(a, b)], np.inf, []), [a, 0.5 * (a + b), b])
