"""Estimators of P(violation): closed forms, and coverage on a synthetic simulator of known P.

The synthetic simulator draws x ~ U[0, 1]^2 and violates when x_1 > 1 - P (P = 0.02), so its
violation probability is known exactly; 200 repeated campaigns per estimator check that the 95 %
interval covers P in at least 93 % of them (an exact interval covers in >= 95 % in expectation).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.stats

from oos_drake.campaign import estimators, samplers

P_TRUE = 0.02
CAMPAIGNS = 200
RUNS = 300


def _children(seed: int) -> list[np.random.Generator]:
    return [np.random.default_rng(c) for c in np.random.SeedSequence(seed).spawn(CAMPAIGNS)]


def test_closed_forms():
    # zero violations in 48 runs: one-sided bound 1 - 0.05^(1/48), two-sided 1 - 0.025^(1/48)
    assert estimators.upper_bound(0, 48) == pytest.approx(1 - 0.05 ** (1 / 48), rel=1e-9)
    low, high = estimators.clopper_pearson(0, 48)
    assert low == 0.0 and high == pytest.approx(1 - 0.025 ** (1 / 48), rel=1e-9)
    # k = 3 of 50: the bound solves P(Binomial(50, p) <= 3) = 0.05
    p = estimators.upper_bound(3, 50)
    assert scipy.stats.binom.cdf(3, 50, p) == pytest.approx(0.05, abs=1e-9)
    # runs to show P <= 1 %: smallest N with 0.99^N <= 0.05 is 299, so 251 after 48
    assert estimators.runs_to_decide(0, 48, 0.01) == math.ceil(math.log(0.05) / math.log(0.99)) - 48
    more = estimators.runs_to_decide(2, 100, 0.01)
    assert estimators.upper_bound(2, 100 + more) <= 0.01 < estimators.upper_bound(2, 99 + more)
    interval = estimators.monte_carlo(np.zeros(48, bool))
    assert interval.sentence().startswith("48 runs, 0 violations: P <= 0.0605 at 95 %")


def test_monte_carlo_coverage(record_property):
    covered, widths = [], []
    for rng in _children(1):
        x = rng.random((RUNS, 2))
        interval = estimators.monte_carlo(x[:, 0] > 1 - P_TRUE)
        covered.append(interval.low <= P_TRUE <= interval.high)
        widths.append(interval.width)
    record_property("monte carlo width", np.mean(widths))
    print(f"monte carlo: coverage {np.mean(covered):.3f}, mean width {np.mean(widths):.4f}")
    assert np.mean(covered) >= 0.93


@pytest.mark.parametrize("allocation", ["proportional", "equal"])
def test_stratified_coverage(allocation):
    # three mission phases (shares of the duration) with different violation rates, P = 0.02
    shares = np.array([0.5, 0.3, 0.2])
    rates = np.array([0.01, 0.02, 0.045])
    assert shares @ rates == pytest.approx(P_TRUE)
    counts = (
        samplers.proportional_allocation(shares, RUNS)
        if allocation == "proportional"
        else np.full(3, RUNS // 3)
    )
    strata = np.repeat(np.arange(3), counts)
    covered, widths, estimates = [], [], []
    for rng in _children(2):
        u = rng.random(strata.size)
        interval = estimators.stratified(
            u < rates[strata], strata, dict(enumerate(shares.tolist()))
        )
        covered.append(interval.low <= P_TRUE <= interval.high)
        widths.append(interval.width)
        estimates.append(interval.estimate)
    print(
        f"stratified ({allocation}, {interval.method}): coverage {np.mean(covered):.3f}, "
        f"mean width {np.mean(widths):.4f}"
    )
    assert np.mean(covered) >= 0.93
    # unbiased: the mean of 200 estimates within 4 standard errors of P
    assert abs(np.mean(estimates) - P_TRUE) < 4 * np.std(estimates) / math.sqrt(CAMPAIGNS)


def _defensive_mixture(rng, runs, defensive=0.5, low=0.8):
    """Draws from q = a U[0,1] + (1 - a) U[low, 1] on x_1, and their weights p / q."""
    guided = rng.random(runs) >= defensive
    x1 = np.where(guided, low + (1 - low) * rng.random(runs), rng.random(runs))
    q = defensive + (1 - defensive) * (x1 >= low) / (1 - low)
    return x1, 1.0 / q


def test_importance_sampling_coverage():
    covered, widths, ess, estimates = [], [], [], []
    for rng in _children(3):
        x1, weights = _defensive_mixture(rng, RUNS)
        interval = estimators.importance_sampling(x1 > 1 - P_TRUE, weights, weight_bound=2.0)
        covered.append(interval.low <= P_TRUE <= interval.high)
        widths.append(interval.width)
        ess.append(interval.effective_runs / RUNS)
        estimates.append(interval.estimate)
    print(
        f"importance sampling: coverage {np.mean(covered):.3f}, mean width {np.mean(widths):.4f}, "
        f"ESS {np.mean(ess):.2f} of the runs"
    )
    assert np.mean(covered) >= 0.93
    assert min(ess) >= estimators.MIN_ESS_FRACTION
    assert abs(np.mean(estimates) - P_TRUE) < 4 * np.std(estimates) / math.sqrt(CAMPAIGNS)


def test_importance_sampling_refuses_unbounded_weights():
    with pytest.raises(ValueError, match="exceeds the bound"):
        estimators.importance_sampling(np.ones(3, bool), np.array([1.0, 3.0, 0.5]), 2.0)


def test_stratified_refuses_empty_stratum():
    with pytest.raises(ValueError, match="stratum 'b'"):
        estimators.stratified(np.zeros(4, bool), np.array(["a"] * 4), {"a": 0.5, "b": 0.5})


def test_weighted_runs_to_decide_counts_the_monte_carlo_equivalent():
    weighted = estimators.Interval(
        0.02, 0.0, 0.1, 0.08, 200, 60, 0.95, "betting (Waudby-Smith-Ramdas)", 100.0
    )
    # 100 effective runs with 2 effective violations, not 200 runs with 60 (mostly tiny weights)
    assert weighted.runs_to_decide(0.01) == estimators.runs_to_decide(2, 100, 0.01)
    plain = estimators.monte_carlo(np.r_[np.ones(2, bool), np.zeros(98, bool)])
    assert plain.runs_to_decide(0.01) == estimators.runs_to_decide(2, 100, 0.01)
