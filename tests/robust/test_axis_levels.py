"""The first level of the whole-axis covers of :func:`~oos_drake.analysis.stability.axis_guarantee`.

Example with a closed form: a lightly damped oscillator ``x'' + (c0 + c1 dc) x' + (k0 + k1 dk) x
= 0`` with real ``|dk|, |dc| <= 1 / alpha``. The loop has a pole on the imaginary axis only when
the damping vanishes, ``dc = -c0 / c1``, at ``omega^2 = k0 + k1 dk``; so
``mu(M(j omega)) = 1 / max(|omega^2 - k0| / k1, c0 / c1)``: a plateau ``c1 / c0`` on
``|omega^2 - k0| <= k1 c0 / c1`` (here ``0.99 .. 1.01`` rad/s), far below it elsewhere. A grid
that steps over the plateau sees an upper bound far below the peak; the lower bound
(``c1 / c0``, as a box search of the analysis finds it) is then the largest bound found, and
the covers must start just above it, not ``(1 + gap)`` above it.
"""

import numpy as np

from oos_drake.analysis import stability
from oos_drake.analysis.stability import GuaranteeSubset, axis_guarantee
from oos_drake.analysis.tightening import SubsetPoints
from oos_drake.robust import mu_intervals
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.mu_upper import mu_upper_bound

K0, C0, K1, C1 = 1.0, 0.02, 0.01, 0.01
MU = C1 / C0  # the peak of mu, closed form
BLK = np.array([[-1, 0], [-1, 0]])
GAP = 0.03


def oscillator():
    A = np.array([[0.0, 1.0], [-K0, -C0]])
    B = np.array([[0.0, 0.0], [-1.0, -1.0]])  # force -(w_k + w_c)
    C = np.array([[K1, 0.0], [0.0, C1]])  # z_k = k1 x, z_c = c1 x'
    return A, B, C, np.zeros((2, 2))


def mu_exact(omega):
    return 1.0 / np.maximum(np.abs(omega**2 - K0) / K1, C0 / C1)


class SerialPool:
    n_jobs = 1

    @staticmethod
    def map(fn, tasks):
        return [fn(t) for t in tasks]


def subset(lower, models=2):
    """A subset of ``models`` identical configurations on a grid that misses the plateau."""
    A, B, C, D = oscillator()
    omega = np.geomspace(0.1, 10.0, 16)  # nearest points 0.86 and 1.17 rad/s
    real = mu_intervals.Realization(A, B, C, D)
    up = mu_upper_bound(real.response(omega), parse_blk(BLK), max_iter=100)
    n = omega.size
    pts = SubsetPoints(
        model=np.repeat(np.arange(models), n),
        omega=np.tile(omega, models),
        upper=np.tile(up.upper, models),
        lower=np.tile(0.9 * up.upper, models),
        params=np.tile(up.params, (models, 1)),
        refined=np.zeros(n * models, bool),
        tightened=np.zeros(n * models, bool),
    )
    return GuaranteeSubset(pts, ([0, 1], [0, 1], BLK), lower, lambda m: (A, B, C, D))


def test_grid_misses_the_peak():
    """The premise: the grid's upper bounds are far below mu (the independent closed form)."""
    sub = subset(MU)
    assert np.max(sub.points.upper) < 0.2 * MU
    # the closed form against brute force: the poles of the loop on the box of size 1 / MU
    # (on the axis at dc = -size) and on a slightly smaller box (none on the axis)
    A, B, C, _ = oscillator()
    size = 1.0 / MU
    for scale, on_axis in ((1.0, True), (0.999, False)):
        worst = max(
            np.max(np.linalg.eigvals(A + B @ np.diag([dk, dc]) @ C).real)
            for dk in np.linspace(-1, 1, 21) * scale * size
            for dc in np.linspace(-1, 1, 21) * scale * size
        )
        assert (abs(worst) < 1e-12) if on_axis else (worst < -1e-6), (scale, worst)
    assert mu_exact(np.array([1.0]))[0] == MU


def test_tight_first_level_gives_a_bound_just_above_mu():
    """Starting at ``(1 + tight) lower``: the guaranteed bound is within 1 % of the exact peak
    (the loose start alone gives ``(1 + gap) lower``), never below it, and no cover fell back."""
    out = axis_guarantee(SerialPool(), {"s": subset(MU)}, gap=GAP, tight=0.005)["s"]
    assert out.covered
    assert out.floor == 1.005 * MU
    assert out.fallback == (1 + GAP) * MU
    assert MU <= out.mu_upper <= 1.01 * MU, out.mu_upper
    assert not out.fell_back.any()
    loose = axis_guarantee(SerialPool(), {"s": subset(MU)}, gap=GAP, tight=1.0)["s"]
    assert np.isnan(loose.fallback) and loose.floor == (1 + GAP) * MU
    assert MU <= loose.mu_upper and out.mu_upper < loose.mu_upper


def test_a_lower_bound_below_mu_does_not_make_the_level_unsafe():
    """A lower bound far below the peak (the grid's, say) only lowers the first level: the
    covers raise their own level where the solved points need it; the bound stays above mu."""
    out = axis_guarantee(SerialPool(), {"s": subset(0.2 * MU)}, gap=GAP, tight=0.005)["s"]
    assert out.covered
    assert out.floor < 0.25 * MU
    assert out.mu_upper >= MU  # above the exact peak: a guarantee
    assert out.raised == out.levels.size


def test_a_cover_that_does_not_close_falls_back_to_the_loose_level(monkeypatch):
    """A cover that does not close at the tight level is done again from the loose one, and
    only that second cover's bound is reported (here the cover is made to fail below a level:
    the fallback path itself is what is tested)."""
    real_cover = mu_intervals.cover_axis
    asked = []

    def stubborn(real, solve, seeds, *, floor, **kwargs):
        asked.append(floor)
        cert = real_cover(real, solve, seeds, floor=floor, **kwargs)
        if floor < (1 + GAP) * MU * (1 - 1e-9):  # as if max_rounds ran out
            return mu_intervals.AxisCertificate(
                upper=np.inf, omega=cert.omega, optimal=cert.optimal, level=cert.level,
                interval=np.full_like(cert.interval, np.nan), added=cert.added,
                scalings=cert.scalings, slack=cert.slack, covered=False, realization=real,
                reason="not proved (test)", gaps=((0.0, np.inf),),
            )  # fmt: skip
        return cert

    monkeypatch.setattr(mu_intervals, "cover_axis", stubborn)
    out = axis_guarantee(SerialPool(), {"s": subset(MU, models=3)}, gap=GAP, tight=0.005)["s"]
    assert out.covered and out.fell_back.all()
    assert np.all(out.levels >= (1 + GAP) * MU)
    assert asked[:2] == [1.005 * MU, (1 + GAP) * MU]


def test_no_fallback_for_a_pole_on_the_axis(monkeypatch):
    """No level closes a cover around a pole of M on the axis: it is not done again, and the
    configuration's failure says why."""
    A, B, C, D = oscillator()
    undamped = A.copy()
    undamped[1, 1] = 0.0
    sub = subset(MU, models=1)
    sub = GuaranteeSubset(sub.points, sub.parts, MU, lambda m: (undamped, B, C, D))
    calls = []
    real_cover = mu_intervals.cover_axis

    def counted(*args, **kwargs):
        calls.append(kwargs["floor"])
        return real_cover(*args, **kwargs)

    monkeypatch.setattr(mu_intervals, "cover_axis", counted)
    out = axis_guarantee(SerialPool(), {"s": sub}, gap=GAP, tight=0.005)["s"]
    assert not out.covered and not out.fell_back.any()
    assert "pole on the imaginary axis" in out.reason
    assert calls == [1.005 * MU]
    assert stability.TIGHT_GAP > 0


def test_warm_starts_that_are_wrong_do_not_make_a_wrong_bound():
    """:func:`mu_solver` starts each point from the nearest point's scalings: from scalings
    that fit another problem (random parameters, a far frequency), every returned bound is
    still above the exact mu there (closed form), its scalings prove ``(1 + slack)`` times it
    at the point (dense LMI, :func:`lmi_residual`), and the bound is as good as from a cold
    start to the optimizer's tolerance."""
    from oos_drake.robust.mu_upper import lmi_residual

    A, B, C, D = oscillator()
    real = mu_intervals.Realization(A, B, C, D)
    omega = np.array([0.5, 0.95, 0.995, 1.0, 1.004, 1.2, 3.0])
    n_params = mu_upper_bound(real.response(omega[:1]), parse_blk(BLK), max_iter=1).params.shape[1]
    rng = np.random.default_rng(1)
    cold = mu_intervals.mu_solver(real, BLK, polish_above=0.0)(omega)
    for starts in (
        (np.array([2.0, 40.0]), 5.0 * rng.standard_normal((2, n_params))),  # nonsense scalings
        (np.array([100.0]), np.full((1, n_params), 30.0)),
    ):
        upper, level, scalings = mu_intervals.mu_solver(real, BLK, polish_above=0.0, starts=starts)(
            omega
        )
        assert np.all(upper >= mu_exact(omega) * (1 - 1e-9)), (upper, mu_exact(omega))
        assert np.all(upper <= cold[0] * 1.01 + 1e-9), (upper, cold[0])
        M = real.response(omega)
        for i, sc in enumerate(scalings):
            res = lmi_residual(M[i : i + 1], level[i], sc.D_left[None], sc.D_right[None],
                               sc.G[None])  # fmt: skip
            assert res[0] < 0, (omega[i], res)


def test_default_first_level_is_a_bound_within_the_target_gap():
    """At the default ``tight`` (:data:`~oos_drake.analysis.stability.TIGHT_GAP`) the
    guaranteed bound is above the exact peak (closed form, and the exact mu on a dense grid
    through the plateau) and within ``TIGHT_GAP`` plus the slack of it, inside the target gap;
    a lower bound 1 % too low (a first level 1 % below the peak) is not taken as the bound: the
    covers raise their level above the exact peak."""
    tight = stability.TIGHT_GAP
    assert 0 < tight < GAP
    out = axis_guarantee(SerialPool(), {"s": subset(MU)}, gap=GAP)["s"]
    assert out.covered and not out.fell_back.any()
    assert out.floor == (1 + tight) * MU
    dense = np.linspace(0.9, 1.1, 20001)  # the plateau 0.99 .. 1.01 rad/s, step 1e-5
    assert np.max(mu_exact(dense)) <= MU <= out.mu_upper
    assert out.mu_upper <= (1 + tight) * (1 + mu_intervals.SLACK) * MU < (1 + GAP) * MU
    low = axis_guarantee(SerialPool(), {"s": subset(0.99 * MU / (1 + tight))}, gap=GAP)["s"]
    assert low.covered and low.floor < MU
    assert low.mu_upper >= MU and low.raised == low.levels.size
