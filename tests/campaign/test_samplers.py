"""Samplers: seeds, Latin hypercube stratification, distributions, unbiased importance weights."""

from __future__ import annotations

import math

import hypothesis
import hypothesis.strategies as st
import numpy as np
import pytest
import scipy.integrate
import scipy.stats

from oos_drake.campaign.distributions import Choice, LogUniform, TruncatedNormal, Uniform
from oos_drake.campaign.samplers import (
    NOMINAL_COMPONENT,
    MuGuidedProposal,
    make_plan,
    run_seeds,
    uniform_variates,
)
from oos_drake.campaign.spec import load_spec
from oos_drake.campaign.worst_cases import WorstCaseRegion

from .spec_texts import BASE_SPEC


def _region(region, **perturbation):
    return WorstCaseRegion(
        region,
        f"config{region}",
        10.0 * region,
        0.2,
        1.2,
        1.1,
        ",".join(perturbation),
        perturbation,
    )


def test_run_seeds_come_from_seedsequence_spawn():
    seeds, _ = run_seeds(1234, 5)
    children = np.random.SeedSequence(1234).spawn(5)
    expected = [int(c.generate_state(1, np.uint64)[0] >> np.uint64(1)) for c in children]
    assert seeds.tolist() == expected
    assert len(set(seeds.tolist())) == 5
    # the first runs' seeds do not depend on how many runs follow
    assert run_seeds(1234, 3)[0].tolist() == expected[:3]


def test_latin_hypercube_puts_one_sample_per_stratum():
    n, d = 50, 3
    u = uniform_variates("latin-hypercube", n, d, np.random.default_rng(0))
    for j in range(d):
        assert sorted(np.floor(u[:, j] * n).astype(int)) == list(range(n))


def test_distribution_inverse_cdfs_match_scipy():
    q = np.linspace(0.01, 0.99, 9)
    dist = TruncatedNormal(0.3, 0.1, 0.1, 0.4)
    a, b = (0.1 - 0.3) / 0.1, (0.4 - 0.3) / 0.1
    np.testing.assert_allclose(
        dist.ppf(q), scipy.stats.truncnorm(a, b, 0.3, 0.1).ppf(q), rtol=1e-12
    )
    log = LogUniform(1e2, 1e5)
    np.testing.assert_allclose(log.ppf(q), scipy.stats.loguniform(1e2, 1e5).ppf(q), rtol=1e-12)
    np.testing.assert_allclose(
        log.pdf(log.ppf(q)), scipy.stats.loguniform(1e2, 1e5).pdf(log.ppf(q)), rtol=1e-12
    )
    choice = Choice((1.0, 2.0, 3.0), (0.2, 0.5, 0.3))
    draws = choice.ppf(np.random.default_rng(1).random(20000))
    np.testing.assert_allclose(
        [np.mean(draws == v) for v in (1, 2, 3)], [0.2, 0.5, 0.3], atol=0.015
    )


@pytest.mark.parametrize(
    "nominal, threshold, exact",
    [
        # P(x > a), x ~ U(0, 1): 1 - a
        (Uniform(0.0, 1.0), 0.97, 0.03),
        # P(x > a), x ~ N(0, 1) truncated to [-4, 4]
        (
            TruncatedNormal(0.0, 1.0, -4.0, 4.0),
            2.5,
            (scipy.stats.norm.sf(2.5) - scipy.stats.norm.sf(4.0))
            / (scipy.stats.norm.cdf(4.0) - scipy.stats.norm.cdf(-4.0)),
        ),
    ],
)
def test_mu_guided_weights_give_unbiased_failure_probability(nominal, threshold, exact):
    """Importance sampling around the worst case keeps E_q[w 1(fail)] = P_p(fail)."""
    low, high = nominal.support
    proposal = MuGuidedProposal(
        dispersions={"x": nominal, "y": Uniform(-1.0, 1.0)},
        regions=(_region(0, x=high), _region(1, x=low, y=0.5)),  # one useful, one useless region
        defensive_fraction=0.2,
        spread=0.05,
    )
    estimates = []
    hits = []
    for seed in range(20):
        values, _ = proposal.sample(2000, np.random.default_rng(seed))
        weights = proposal.weights(values)
        assert weights.max() <= 1 / 0.2 + 1e-12
        fail = values["x"] > threshold
        estimates.append(np.mean(weights * fail))
        hits.append(np.mean(fail))
    estimates = np.array(estimates)
    standard_error = estimates.std(ddof=1) / math.sqrt(len(estimates))
    assert abs(estimates.mean() - exact) < 4 * standard_error + 1e-4
    # and the guided sampler puts many more runs in the failure region than the nominal law
    assert np.mean(hits) > 5 * exact


def test_mu_guided_weights_are_the_exact_density_ratio():
    """Weights equal p/q with q the mixture density written out by hand."""
    p = Uniform(0.0, 2.0)
    region = _region(3, x=1.8)
    proposal = MuGuidedProposal({"x": p}, (region,), defensive_fraction=0.3, spread=0.1)
    x = np.array([0.1, 1.0, 1.8, 1.95])
    g = scipy.stats.truncnorm((0 - 1.8) / 0.2, (2 - 1.8) / 0.2, loc=1.8, scale=0.2).pdf(x)
    q = 0.3 * 0.5 + 0.7 * g
    np.testing.assert_allclose(proposal.weights({"x": x}), 0.5 / q, rtol=1e-12)


def test_region_shares_follow_mu_upper():
    regions = (
        WorstCaseRegion(0, "a", 1.0, 0.1, 3.0, 2.9, "x", {"x": 0.9}),
        WorstCaseRegion(1, "b", 2.0, 0.1, 1.0, 0.9, "x", {"x": 0.1}),
    )
    proposal = MuGuidedProposal({"x": Uniform(0.0, 1.0)}, regions, defensive_fraction=0.2)
    np.testing.assert_allclose(proposal.region_shares, [0.75, 0.25])
    _, component = proposal.sample(20000, np.random.default_rng(3))
    np.testing.assert_allclose(
        [np.mean(component == c) for c in (NOMINAL_COMPONENT, 0, 1)], [0.2, 0.6, 0.2], atol=0.015
    )


def test_plan_columns_and_nominal_values(write_spec):
    spec = load_spec(write_spec(BASE_SPEC.replace('"monte-carlo"', '"latin-hypercube"')))
    plan = make_plan(spec)
    assert len(plan) == 12 and plan["run_id"].tolist() == list(range(12))
    assert (plan["weight"] == 1).all()
    # a parameter that is not dispersed stays at its nominal value
    assert (plan["J_target [kg m^2]"] == 300.0).all()
    assert plan["J_hub [kg m^2]"].between(400, 600).all()
    # window around the capture event at 100 s
    assert (plan["window start [s]"] == 95.0).all() and (plan["window end [s]"] == 140.0).all()
    # same seed, same plan
    assert make_plan(spec).equals(plan)


def test_truncated_normal_far_tail_matches_scipy():
    q = np.linspace(0.0, 1.0, 11)
    dist = TruncatedNormal(0.3, 0.01, 0.35, 0.4)  # 5 to 10 std above the mean
    reference = scipy.stats.truncnorm(5.0, 10.0, loc=0.3, scale=0.01)
    np.testing.assert_allclose(dist.ppf(q), reference.ppf(q), rtol=1e-9)
    x = np.linspace(0.351, 0.399, 7)
    np.testing.assert_allclose(dist.pdf(x), reference.pdf(x), rtol=1e-9)
    # 40 std away from the mean: still a proper density (no underflow to 0/0)
    far = TruncatedNormal(0.0, 0.05, 2.0, 2.5)
    assert np.all(np.isfinite(far.pdf(np.array([2.0, 2.01, 2.2])))) and far.pdf(2.0) > 0
    assert 2.0 <= far.ppf(np.array([0.5]))[0] <= 2.01


@hypothesis.settings(max_examples=40, deadline=None)
@hypothesis.given(
    mean=st.floats(-5, 5),
    std=st.floats(0.05, 5),
    low=st.floats(-6, 5.9),
    width=st.floats(0.1, 8),
)
def test_truncated_normal_is_a_density_on_its_support(mean, std, low, width):
    high = low + width
    dist = TruncatedNormal(mean, std, low, high)
    # scipy's truncnorm is the independent reference (log space: far tails do not underflow)
    a, b = (low - mean) / std, (high - mean) / std
    x = np.linspace(low, high, 101)
    reference = np.exp(scipy.stats.truncnorm.logpdf(x, a, b, loc=mean, scale=std))
    np.testing.assert_allclose(dist.pdf(x), reference, rtol=1e-6, atol=1e-300)
    # the mass can sit in a spike of width std^2 / |mean - bound| at a bound: tell quad where
    widths = (std**2 / max(abs(mean - low), std), std**2 / max(abs(high - mean), std))
    spike = [low + k * widths[0] for k in (1, 5, 10, 20, 40)]
    spike += [high - k * widths[1] for k in (1, 5, 10, 20, 40)]
    points = sorted({p for p in [min(max(mean, low), high), *spike] if low < p < high})
    total, _ = scipy.integrate.quad(dist.pdf, low, high, points=points or None, limit=200)
    assert total == pytest.approx(1.0, rel=1e-6)
    u = np.linspace(0.0, 1.0, 21)
    x = dist.ppf(u)
    assert np.all(np.diff(x) >= 0) and x[0] >= low and x[-1] <= high


def _truncated_normal_moments(mean, std, low, high):
    """Mean and variance of a truncated normal, closed form (math.erf; no scipy)."""
    a, b = (low - mean) / std, (high - mean) / std
    phi = [math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) for z in (a, b)]
    mass = 0.5 * (math.erf(b / math.sqrt(2)) - math.erf(a / math.sqrt(2)))
    shift = (phi[0] - phi[1]) / mass
    variance = std**2 * (1 + (a * phi[0] - b * phi[1]) / mass - shift**2)
    return mean + std * shift, variance


@pytest.mark.parametrize("sampler", ["monte-carlo", "latin-hypercube"])
def test_planned_normal_dispersion_is_the_truncated_normal(write_spec, sampler):
    """Plan values of a normal dispersion: KS test against the law, moments in closed form."""
    text = BASE_SPEC.replace('"monte-carlo"', f'"{sampler}"').replace(
        "n_runs = 12", "n_runs = 4000"
    )
    spec = load_spec(write_spec(text))
    plan = make_plan(spec)
    dist = spec.dispersions["omega_capture"]  # N(0, 0.004) truncated to [-0.01, 0.01]
    x = plan["omega_capture [rad/s]"].to_numpy()
    assert x.min() >= dist.low and x.max() <= dist.high
    law = scipy.stats.truncnorm(dist.low / dist.std, dist.high / dist.std, scale=dist.std)
    assert scipy.stats.kstest(x, law.cdf).pvalue > 1e-3
    mean, variance = _truncated_normal_moments(dist.mean, dist.std, dist.low, dist.high)
    # Monte Carlo: 5 standard errors; Latin hypercube stratifies, so it is much closer
    tolerance = 5 * math.sqrt(variance / len(x)) if sampler == "monte-carlo" else 1e-3 * dist.std
    assert abs(x.mean() - mean) < tolerance
    assert x.var() == pytest.approx(variance, rel=0.1 if sampler == "monte-carlo" else 0.01)
    # the uniform and log-uniform dispersions: KS against their laws
    assert (
        scipy.stats.kstest(plan["J_hub [kg m^2]"], scipy.stats.uniform(400, 200).cdf).pvalue > 1e-3
    )
    k = plan.filter(like="k_dock").iloc[:, 0]
    assert scipy.stats.kstest(k, scipy.stats.loguniform(1e2, 1e5).cdf).pvalue > 1e-3
    # a seed gives one plan
    assert make_plan(spec).equals(plan)


def test_latin_hypercube_marginals_are_uniform_and_seeded():
    u = uniform_variates("latin-hypercube", 500, 4, np.random.default_rng(11))
    for j in range(4):
        assert scipy.stats.kstest(u[:, j], "uniform").pvalue > 1e-3
    again = uniform_variates("latin-hypercube", 500, 4, np.random.default_rng(11))
    np.testing.assert_array_equal(u, again)
    other = uniform_variates("latin-hypercube", 500, 4, np.random.default_rng(12))
    assert not np.array_equal(u, other)
