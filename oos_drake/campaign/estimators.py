r"""Estimators of a violation probability with confidence intervals that hold for the runs made.

Three estimators of ``P = P_p(run violates)`` under the nominal dispersion density ``p``, each
with an interval whose coverage is guaranteed (not asymptotic), so that "N runs, k violations:
P <= p_95" is a statement one can sign:

- :func:`monte_carlo`: runs drawn i.i.d. from ``p``; ``k ~ Binomial(N, P)``: the exact
  Clopper-Pearson interval (and the one-sided upper bound ``beta.ppf(c, k + 1, N - k)``).
- :func:`stratified`: strata ``h`` (mission phases, regions) of known probability ``W_h``, ``n_h``
  runs drawn from ``p`` restricted to stratum ``h``; the estimate is
  :math:`\hat P = \sum_h W_h k_h / n_h`. Interval:

  * proportional allocation (``n_h = W_h N`` for every stratum, to within one run): the
    Clopper-Pearson interval of the pooled counts ``(sum k_h, N)``. It covers because
    ``sum k_h`` is a Poisson-binomial variable of mean ``N P``, whose tails are lighter than
    those of ``Binomial(N, P)`` (Hoeffding 1956, theorem 4: ``P(S <= c) <= P(B <= c)`` for
    ``c <= N P - 1`` and ``P(S >= c) <= P(B >= c)`` for ``c >= N P + 1``), the only tails at
    which Clopper-Pearson's inversion can reject the true ``P``;
  * any other allocation: the weighted sum of per-stratum Clopper-Pearson intervals at level
    ``1 - alpha / H`` (Bonferroni: with probability ``>= 1 - alpha`` every stratum's interval
    holds, hence their weighted sum holds).

- :func:`importance_sampling`: runs drawn i.i.d. from a defensive mixture
  ``q = a p + (1 - a) g`` (``g``: the mu-guided proposal), weights ``w = p / q <= 1 / a``. The
  values ``X_i = w_i 1[violation]`` are i.i.d. in ``[0, 1/a]`` with mean ``P``; the interval is
  the hedged betting confidence interval of Waudby-Smith and Ramdas (2024, JRSS-B, "Estimating
  means of bounded random variables by betting", theorem 3 with the predictable plug-in bets):
  for each candidate mean ``m`` the capital
  :math:`K(m) = \tfrac12 \prod_i (1 + \lambda_i^+ (x_i - m)) + \tfrac12 \prod_i (1 - \lambda_i^-
  (x_i - m))` is a nonnegative martingale of mean 1 under ``P = m``, so by Ville's inequality
  ``{m : K_N(m) < 1/alpha}`` covers with probability ``>= 1 - alpha``. It adapts to the variance
  of the ``X_i`` (unlike Hoeffding's or a binomial bound), which is where importance sampling
  gains. The estimate is used only when the effective sample size reaches ``min_ess_fraction``
  of the runs (50 % by default); below it the report falls back to the defensive draws alone
  (a plain Monte Carlo sample of ``p``).

:func:`runs_to_decide`: how many more runs without a violation would bring the one-sided upper
bound below a target (e.g. ``P <= 1 %``).

Every result is a frozen :class:`Interval` that can ``check()`` its own claim again from the counts
it carries.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
import scipy.stats

from oos_drake.campaign.samplers import DEFENSIVE_COLUMN, NOMINAL_COMPONENT, phase_weights

#: Default confidence level of every interval [-].
CONFIDENCE = 0.95
#: Smallest effective sample size, as a share of the runs, for an importance-sampling estimate.
MIN_ESS_FRACTION = 0.5
#: Largest bet of the betting interval as a share of what keeps the capital positive (c of
#: Waudby-Smith and Ramdas; any c < 1 keeps the construction valid, larger c gains power at
#: small means, where violation probabilities live).
_TRUNCATION = 0.9


@dataclass(frozen=True)
class Interval:
    """An estimated probability with its confidence interval and one-sided upper bound.

    Attributes
    ----------
    estimate : float
        Point estimate of P [-].
    low, high : float
        Two-sided interval at ``confidence`` [-].
    upper : float
        One-sided upper bound at ``confidence``: ``P <= upper`` [-].
    runs : int
        Runs used.
    violations : int
        Runs that violate.
    confidence : float
        Confidence level [-].
    method : str
        ``"Clopper-Pearson"``, ``"stratified pooled Clopper-Pearson"``, ``"stratified Bonferroni
        Clopper-Pearson"`` or ``"betting (Waudby-Smith-Ramdas)"``.
    effective_runs : float
        Kish effective sample size [runs] (``runs`` for unweighted estimators).
    """

    estimate: float
    low: float
    high: float
    upper: float
    runs: int
    violations: int
    confidence: float
    method: str
    effective_runs: float

    @property
    def width(self) -> float:
        """``high - low`` [-]."""
        return self.high - self.low

    def sentence(self) -> str:
        """``"48 runs, 0 violations: P <= 0.0605 at 95 %"``."""
        return (
            f"{self.runs} runs, {self.violations} violation{'s' * (self.violations != 1)}: "
            f"P <= {self.upper:.3g} at {100 * self.confidence:g} % ({self.method})"
        )

    def runs_to_decide(self, target: float) -> int:
        """More runs, all without violation, that would show ``P <= target`` (exact binomial
        bound, :func:`runs_to_decide`). For a weighted (importance-sampling) estimate the runs
        are counted as their plain Monte Carlo equivalent: ``effective_runs`` runs with
        ``ceil(estimate * effective_runs)`` violations."""
        if self.method.startswith("betting"):
            runs = max(1, int(round(self.effective_runs)))
            violations = min(runs, math.ceil(self.estimate * self.effective_runs - 1e-9))
            return runs_to_decide(violations, runs, target, self.confidence)
        return runs_to_decide(self.violations, self.runs, target, self.confidence)

    def decides(self, target: float) -> str:
        """``"P <= target"`` when the upper bound is below the target, ``"P > target"`` when the
        lower bound is above it, else ``"undecided"``."""
        if self.upper <= target:
            return f"P <= {target:g}"
        if self.low > target:
            return f"P > {target:g}"
        return "undecided"


def clopper_pearson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Exact two-sided binomial interval of ``k`` events in ``n`` trials [-].

    Examples
    --------
    >>> low, high = clopper_pearson(0, 48)
    >>> round(high, 4)  # 1 - 0.025 ** (1 / 48)
    0.074
    """
    alpha = 1.0 - confidence
    low = 0.0 if k == 0 else float(scipy.stats.beta.ppf(alpha / 2, k, n - k + 1))
    high = 1.0 if k == n else float(scipy.stats.beta.ppf(1 - alpha / 2, k + 1, n - k))
    return low, high


def upper_bound(k: int, n: int, confidence: float = CONFIDENCE) -> float:
    """One-sided exact binomial upper bound: ``P <= upper`` with probability ``confidence``.

    With no violation it is ``1 - (1 - confidence)^(1/n)`` (0.0605 for 48 runs at 95 %).
    """
    if n == 0:
        return 1.0
    return 1.0 if k >= n else float(scipy.stats.beta.ppf(confidence, k + 1, n - k))


def monte_carlo(violations: np.ndarray, confidence: float = CONFIDENCE) -> Interval:
    """Plain Monte Carlo: runs drawn i.i.d. from the dispersions; Clopper-Pearson interval.

    Parameters
    ----------
    violations : array_like of bool
        Per run: violates (a run that did not finish counts as a violation).
    confidence : float
        Confidence level [-].
    """
    events = np.asarray(violations, bool)
    n, k = events.size, int(events.sum())
    if n == 0:
        return Interval(math.nan, 0.0, 1.0, 1.0, 0, 0, confidence, "Clopper-Pearson", 0.0)
    low, high = clopper_pearson(k, n, confidence)
    return Interval(
        k / n, low, high, upper_bound(k, n, confidence), n, k, confidence, "Clopper-Pearson", n
    )


def stratified(
    violations: np.ndarray,
    strata: np.ndarray,
    weights: dict,
    confidence: float = CONFIDENCE,
) -> Interval:
    """Stratified estimate over strata of known probability (see the module docstring).

    Parameters
    ----------
    violations : array_like of bool
        Per run: violates.
    strata : array_like
        Per run: its stratum label.
    weights : dict
        Stratum label -> probability ``W_h`` of the stratum under the dispersions (or share of
        the mission's duration for phases) [-]; they must sum to 1. A stratum without runs is an
        error: its contribution would be unknown.
    confidence : float
        Confidence level [-].

    Raises
    ------
    ValueError
        Weights that do not sum to 1, a run in an unknown stratum, a stratum without runs.
    """
    events = np.asarray(violations, bool)
    labels = np.asarray(strata)
    total = sum(weights.values())
    if not math.isclose(total, 1.0, rel_tol=1e-9):
        raise ValueError(f"stratum weights sum to {total:g}, not 1")
    unknown = set(labels.tolist()) - set(weights)
    if unknown:
        raise ValueError(f"runs in stratum {sorted(unknown)[0]!r} which has no weight")
    n, k, share = [], [], []
    for label, weight in weights.items():
        mask = labels == label
        if weight > 0 and not mask.any():
            raise ValueError(f"stratum {label!r} (weight {weight:g}) has no run")
        n.append(int(mask.sum()))
        k.append(int(events[mask].sum()))
        share.append(float(weight))
    n, k, share = np.array(n), np.array(k), np.array(share)
    used = n > 0
    estimate = float(np.sum(share[used] * k[used] / n[used]))
    total_runs, total_k = int(n.sum()), int(k.sum())
    proportional = np.all(np.abs(n - share * total_runs) <= 1.0)
    if proportional:
        low, high = clopper_pearson(total_k, total_runs, confidence)
        upper = upper_bound(total_k, total_runs, confidence)
        method = "stratified pooled Clopper-Pearson"
    else:
        strata_count = int(used.sum())
        level = 1.0 - (1.0 - confidence) / strata_count
        one_sided = 1.0 - (1.0 - confidence) / strata_count
        bounds = np.array(
            [clopper_pearson(a, b, level) for a, b in zip(k[used], n[used], strict=True)]
        )
        low = float(share[used] @ bounds[:, 0])
        high = float(share[used] @ bounds[:, 1])
        upper = float(
            sum(
                w * upper_bound(a, b, one_sided)
                for w, a, b in zip(share[used], k[used], n[used], strict=True)
            )
        )
        method = "stratified Bonferroni Clopper-Pearson"
    return Interval(
        estimate,
        low,
        min(high, 1.0),
        min(upper, 1.0),
        total_runs,
        total_k,
        confidence,
        method,
        float(total_runs),
    )


def effective_sample_size(weights: np.ndarray) -> float:
    """Kish's effective sample size ``(sum w)^2 / sum w^2`` [runs]."""
    weights = np.asarray(weights, float)
    return float(weights.sum() ** 2 / np.sum(weights**2)) if weights.size else 0.0


def _plug_in_bets(x: np.ndarray, log_term: float) -> np.ndarray:
    """Predictable plug-in bets ``lambda_i`` (use ``x_1 .. x_{i-1}`` only), fixed-``n`` form."""
    n = x.size
    t = np.arange(1, n + 1)
    mean = (0.5 + np.cumsum(x)) / (t + 1)
    variance = (0.25 + np.cumsum((x - mean) ** 2)) / (t + 1)
    previous = np.concatenate([[0.25], variance[:-1]])
    return np.sqrt(2.0 * log_term / (n * previous))


def betting_interval(
    x: np.ndarray, bound: float, confidence: float = CONFIDENCE, grid: int = 120
) -> tuple[float, float, float]:
    """Betting confidence interval of the mean of i.i.d. samples ``x`` in ``[0, bound]``.

    Returns the two-sided ``(low, high)`` at ``confidence`` (hedged capital, both bets) and the
    one-sided upper bound at ``confidence`` (the downward bet alone, all of ``alpha`` on that
    side). The candidate means are a logarithmic grid of ``grid`` points (fine near 0, where
    violation probabilities live), refined by ``grid`` points between each edge and its
    neighbour outside; each edge is then the first refined point outside the kept set, so the
    grid only makes the interval more conservative.
    """
    x = np.asarray(x, float) / bound
    n = x.size
    if n == 0:
        return 0.0, 1.0, 1.0
    alpha = 1.0 - confidence
    two_sided_bets = _plug_in_bets(x, math.log(2.0 / alpha))
    one_sided_bets = _plug_in_bets(x, math.log(1.0 / alpha))

    def kept_two_sided(m: np.ndarray) -> np.ndarray:
        diff = x[None, :] - m[:, None]  # (g, n)
        up = np.minimum(two_sided_bets[None, :], _TRUNCATION / m[:, None])
        down = np.minimum(two_sided_bets[None, :], _TRUNCATION / (1.0 - m[:, None]))
        capital = 0.5 * np.exp(np.sum(np.log1p(up * diff), axis=1)) + 0.5 * np.exp(
            np.sum(np.log1p(-down * diff), axis=1)
        )
        return capital < 1.0 / alpha

    def kept_one_sided(m: np.ndarray) -> np.ndarray:
        down = np.minimum(one_sided_bets[None, :], _TRUNCATION / (1.0 - m[:, None]))
        log_capital = np.sum(np.log1p(-down * (x[None, :] - m[:, None])), axis=1)
        return log_capital < math.log(1.0 / alpha)

    def edges(kept) -> tuple[float, float]:
        m = np.concatenate([[0.0], np.geomspace(1e-7, 1.0 - 1e-7, grid), [1.0]])
        mask = np.concatenate([[False], kept(m[1:-1]), [False]])
        if not mask.any():  # the true mean is rejected with probability <= alpha
            return 0.0, 1.0
        inside = np.flatnonzero(mask)
        first, last = inside[0], inside[-1]
        # refine between the last rejected and the first kept point on each side
        fine_low = np.linspace(m[first - 1], m[first], grid + 2)[1:-1]
        fine_high = np.linspace(m[last], m[last + 1], grid + 2)[1:-1]
        low_kept = kept(np.clip(fine_low, 1e-12, 1 - 1e-12)) if first > 1 else np.ones(1, bool)
        high_kept = kept(np.clip(fine_high, 1e-12, 1 - 1e-12)) if last < grid else None
        low = (
            m[first - 1]
            if first <= 1
            else np.concatenate([[m[first - 1]], fine_low])[np.argmax(low_kept)]
        )
        if high_kept is None:
            high = 1.0
        else:
            outside = np.flatnonzero(~high_kept)
            high = fine_high[outside[0]] if outside.size else m[last + 1]
        return float(low), float(high)

    low, high = edges(kept_two_sided)
    upper = edges(kept_one_sided)[1]
    return low * bound, min(high * bound, 1.0), min(upper * bound, 1.0)


def importance_sampling(
    violations: np.ndarray,
    weights: np.ndarray,
    weight_bound: float,
    confidence: float = CONFIDENCE,
) -> Interval:
    """Importance sampling from a defensive mixture: weighted estimate and betting interval.

    Parameters
    ----------
    violations : array_like of bool
        Per run (in the order drawn): violates.
    weights : array_like
        Likelihood ratios ``p(x) / q(x)`` of the runs [-].
    weight_bound : float
        Bound of every weight, ``1 / defensive_fraction`` [-].
    confidence : float
        Confidence level [-].
    """
    events = np.asarray(violations, bool)
    weights = np.asarray(weights, float)
    if np.any(weights > weight_bound * (1 + 1e-9)):
        raise ValueError(f"a run weight {weights.max():g} exceeds the bound {weight_bound:g}")
    n = events.size
    x = weights * events
    low, high, upper = betting_interval(x, weight_bound, confidence)
    return Interval(
        float(x.mean()) if n else math.nan,
        float(low),
        float(high),
        float(upper),
        n,
        int(events.sum()),
        confidence,
        "betting (Waudby-Smith-Ramdas)",
        effective_sample_size(weights),
    )


def runs_to_decide(
    violations: int, runs: int, target: float, confidence: float = CONFIDENCE
) -> int:
    """More runs, all without violation, after which the exact upper bound is ``<= target``.

    0 when the bound already meets the target; with no violation so far the total is the
    smallest ``N`` with ``(1 - target)^N <= 1 - confidence`` (299 runs for 1 % at 95 %).
    """
    if not 0 < target < 1:
        raise ValueError(f"target {target:g} must be in (0, 1)")
    if upper_bound(violations, runs, confidence) <= target:
        return 0
    low, high = runs, max(runs + 1, 2 * runs)
    while upper_bound(violations, high, confidence) > target:
        low, high = high, 2 * high
    while high - low > 1:  # the bound decreases with n for fixed k
        middle = (low + high) // 2
        if upper_bound(violations, middle, confidence) <= target:
            high = middle
        else:
            low = middle
    return high - runs


def campaign_estimate(spec, runs: pd.DataFrame, events: np.ndarray) -> Interval:
    """P(event) under the spec's dispersions with the estimator the runs allow.

    - phase-stratified: :func:`stratified` over the mission phases, weighted by their durations;
    - plain Monte Carlo (and Latin hypercube, whose variance is at most ``N/(N-1)`` times Monte
      Carlo's, Owen 1997): exact Clopper-Pearson (:func:`monte_carlo`);
    - mu-guided (defensive mixture): importance sampling with the betting interval
      (:func:`importance_sampling`) when the effective sample size is at least
      :data:`MIN_ESS_FRACTION` of the runs; otherwise the runs drawn from the
      dispersions alone (the defensive component: a plain Monte Carlo sample), Clopper-Pearson.

    Parameters
    ----------
    spec : CampaignSpec
        The campaign's spec (sampler, ``[estimation]`` confidence).
    runs : pandas.DataFrame
        The runs (``weight``, ``region`` columns), in run order.
    events : array_like of bool
        Per run: the event (violation, failure).
    """
    confidence = spec.estimation.confidence
    events = np.asarray(events, bool)
    if spec.sampler.kind == "phase-stratified":
        return stratified(events, runs["window"].to_numpy(), phase_weights(spec.info), confidence)
    if spec.sampler.kind != "mu-guided":
        return monte_carlo(events, confidence)
    order = np.argsort(runs["run_id"].to_numpy(), kind="stable")  # the order drawn
    weights = runs["weight"].to_numpy(float)[order]
    if effective_sample_size(weights) >= MIN_ESS_FRACTION * len(weights):
        # the plan's mixture may hold more defensive draws than the spec asked (its ESS target)
        defensive = runs.get(DEFENSIVE_COLUMN, pd.Series([spec.sampler.defensive_fraction]))
        return importance_sampling(events[order], weights, 1.0 / defensive.min(), confidence)
    defensive = runs["region"].to_numpy() == NOMINAL_COMPONENT
    interval = monte_carlo(events[defensive], confidence)
    return replace(interval, method="Clopper-Pearson on the defensive draws (ESS < 50 %)")


def undecided_requirements(spec, runs: pd.DataFrame) -> list[str]:
    """Labels of the spec's requirements whose interval does not yet decide against
    ``[estimation] target`` (upper bound above it and lower bound below it)."""
    out = []
    for requirement in spec.requirements:
        interval = campaign_estimate(spec, runs, ~runs[requirement.column].to_numpy(bool))
        if interval.decides(spec.estimation.target) == "undecided":
            out.append(requirement.label)
    return out
