"""Samplers: turn a spec into the campaign plan (every run's values, seed, weight and window).

- ``monte-carlo``: i.i.d. draws from the dispersions (weight 1).
- ``phase-stratified``: the whole mission cut at its events into phases (:func:`mission_phases`),
  runs shared between them in proportion to their durations (:func:`proportional_allocation`),
  each run simulating its phase from dispersed initial conditions, values i.i.d. (weight 1); the
  report estimates with the stratified estimator (:func:`.estimators.stratified`).
- ``latin-hypercube``: each marginal stratified in ``n_runs`` equal-probability bins (one point
  per bin, bins shuffled independently per parameter), mapped through the inverse CDFs (weight 1).
- ``mu-guided``: importance sampling around the analysis' worst cases. The proposal is the
  defensive mixture

  .. math::

      q(x) = \\alpha\\, p(x) + (1 - \\alpha) \\sum_r \\pi_r\\, g_r(x),
      \\qquad g_r(x) = \\prod_{j \\in S_r} g_{rj}(x_j) \\prod_{j \\notin S_r} p_j(x_j)

  with ``p`` the nominal (spec) density, ``alpha`` the ``defensive_fraction``, ``pi_r`` the
  region shares (proportional to ``mu_upper`` or uniform), ``S_r`` the dispersed continuous blocks
  with a worst-case value in region ``r`` and ``g_rj`` a normal centred on that value (std =
  ``spread`` times the dispersion's width: its support, or 6 std for a normal law) truncated to
  the dispersion's support. Each run carries the weight ``w = p(x) / q(x)`` evaluated with the
  whole mixture (not only the component it was drawn from), so that for any function ``f``:
  ``E_q[w f] = E_p[f]`` (failure probabilities stay
  unbiased) and ``w <= 1 / alpha`` (the estimate cannot be ruined by one huge weight).

Frequencies: a simulator realizes its LTI perturbation blocks (parameters of kind ``lti``:
``Delta_add``, ``Delta_mul_*`` of the Drake mission) as stable systems whose phase turns at a
frequency; each run gets the critical frequency of the analysis region it explores (plan column
``frequency [Hz]``, :data:`FREQUENCY_COLUMN`): the region it was drawn from, else the region of
its ``critical`` window, else (a run tied to no region: defensive draws with a mission or event
window, plain Monte Carlo and Latin hypercube given a ``worst_cases`` file) the frequency of the
analysis' peak, the region with the largest ``mu_upper``: the frequency where the analysis finds
the loop closest to instability. Without a ``worst_cases`` file the column is NaN, and a plan
whose runs disperse an LTI block is refused (no number of ours or the paper's stands in).

Seeds: ``SeedSequence(random_seed).spawn(n_runs + 1)``: child ``i < n_runs`` seeds run ``i``
(identical to ``SeedSequence(random_seed).spawn(n_runs)[i]``), the last child drives the sampler.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from oos_drake.campaign.distributions import (
    Distribution,
    LogUniform,
    TruncatedNormal,
    Uniform,
)
from oos_drake.campaign.simulator import MissionWindow, ParameterKind
from oos_drake.campaign.worst_cases import WorstCaseRegion

#: Region id recorded for runs drawn from the nominal (defensive) component.
NOMINAL_COMPONENT = -1
#: Plan column: frequency [Hz] at which a run's LTI perturbations are realized.
FREQUENCY_COLUMN = "frequency [Hz]"
#: Plan column: the defensive fraction of the mu-guided mixture the run was drawn from [-].
DEFENSIVE_COLUMN = "defensive fraction [-]"
#: The guided share ``1 - defensive_fraction`` shrinks by this factor per step (ESS target).
_GUIDED_SHRINK = 1.5
#: Largest defensive fraction tried before the plan is refused [-].
_DEFENSIVE_MAX = 0.999


def _guided_draws(spec, n: int, rng: np.random.Generator):
    """Draws of the mu-guided mixture whose weights reach the spec's effective sample size.

    The share of the guided components ``1 - defensive_fraction`` shrinks by
    :data:`_GUIDED_SHRINK` from the spec's value until the weights' effective sample size is at
    least ``min_ess_fraction * n`` (more draws from the dispersions: weights closer to 1, bound
    ``1 / defensive_fraction`` lower). Every attempt restarts from the same generator state, so
    the plan is a function of the spec (the plain draw when the spec's mixture suffices).
    Returns values, component per run, weights and the defensive fraction used.
    """
    state = rng.bit_generator.state
    defensive = spec.sampler.defensive_fraction
    while True:
        rng.bit_generator.state = state
        proposal = MuGuidedProposal(
            spec.dispersions,
            spec.regions,
            defensive,
            spec.sampler.spread,
            spec.sampler.region_weighting,
        )
        values, region = proposal.sample(n, rng)
        weight = proposal.weights(values)
        ess = weight.sum() ** 2 / np.sum(weight**2)
        if ess >= spec.sampler.min_ess_fraction * n:
            return values, region, weight, defensive
        if defensive >= _DEFENSIVE_MAX:
            raise ValueError(
                f"campaign {spec.name}: [sampler] effective sample size {ess:.1f} of {n} runs "
                f"stays below min_ess_fraction = {spec.sampler.min_ess_fraction} up to "
                f"defensive_fraction {defensive:.3g}: lower min_ess_fraction"
            )
        defensive = min(1.0 - (1.0 - defensive) / _GUIDED_SHRINK, _DEFENSIVE_MAX)


def run_seeds(
    random_seed: int, n_runs: int, first_run_id: int = 0
) -> tuple[np.ndarray, np.random.Generator]:
    """Per-run integer seeds (63-bit) and the sampler's generator, from one root seed.

    ``first_run_id > 0``: a batch added to a campaign (run until decided) draws from the
    sequence with spawn key ``(first_run_id, 1)``, disjoint from the first batch's children
    ``(k,)`` and from every other added batch.
    """
    root = (
        np.random.SeedSequence(random_seed)
        if first_run_id == 0
        else np.random.SeedSequence(random_seed, spawn_key=(first_run_id, 1))
    )
    children = root.spawn(n_runs + 1)
    seeds = np.array(
        [int(c.generate_state(1, np.uint64)[0] >> np.uint64(1)) for c in children[:n_runs]],
        dtype=np.int64,
    )
    return seeds, np.random.default_rng(children[n_runs])


def uniform_variates(kind: str, n: int, d: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, d)`` variates in [0, 1): i.i.d. (``monte-carlo``) or Latin hypercube."""
    if d == 0:
        return np.empty((n, 0))
    if kind == "latin-hypercube":
        import scipy.stats  # seconds to import: only for Latin hypercube plans

        # one point per stratum [k/n, (k+1)/n) of each marginal, strata shuffled per column
        return scipy.stats.qmc.LatinHypercube(d, rng=rng).random(n)
    return rng.random((n, d))


def sample_dispersions(
    dispersions: Mapping[str, Distribution], u: np.ndarray
) -> dict[str, np.ndarray]:
    """Map variates ``u`` (one column per dispersion, in order) to physical values."""
    return {name: dist.ppf(u[:, j]) for j, (name, dist) in enumerate(dispersions.items())}


def _scale(dist: Distribution) -> float:
    """Width a proposal spread refers to: the support, or +-3 std for a (wide) normal law."""
    low, high = dist.support
    if isinstance(dist, TruncatedNormal):
        return min(high - low, 6.0 * dist.std)
    return high - low


def _is_continuous(dist: Distribution) -> bool:
    return isinstance(dist, Uniform | LogUniform | TruncatedNormal)


@dataclass(frozen=True)
class MuGuidedProposal:
    """The defensive-mixture proposal of the ``mu-guided`` sampler (see the module docstring).

    Attributes
    ----------
    dispersions : Mapping[str, Distribution]
        Nominal distributions ``p_j`` (physical units).
    regions : tuple of WorstCaseRegion
        Worst-case regions.
    defensive_fraction : float
        Mixture weight ``alpha`` of the nominal density [-], in (0, 1).
    spread : float
        Proposal std as a fraction of each dispersion's width (support, or 6 std for a normal
        law) [-].
    region_weighting : str
        ``"mu_upper"`` (shares proportional to mu's upper bound) or ``"uniform"``.
    """

    dispersions: Mapping[str, Distribution]
    regions: tuple[WorstCaseRegion, ...]
    defensive_fraction: float = 0.2
    spread: float = 0.1
    region_weighting: str = "mu_upper"

    @property
    def region_shares(self) -> np.ndarray:
        """``pi_r``: shares of the guided runs per region (sum to 1)."""
        if self.region_weighting == "uniform":
            raw = np.ones(len(self.regions))
        else:
            raw = np.array([max(r.mu_upper, 0.0) for r in self.regions])
            if raw.sum() <= 0:
                raw = np.ones(len(self.regions))
        return raw / raw.sum()

    def components(self) -> list[dict[str, TruncatedNormal]]:
        """Per region: dispersed block name -> proposal ``g_rj`` (blocks in ``S_r`` only)."""
        out = []
        for region in self.regions:
            guided = {}
            for name, value in region.perturbation.items():
                dist = self.dispersions.get(name)
                if dist is None or not _is_continuous(dist):
                    continue
                low, high = dist.support
                centre = float(np.clip(value, low, high))
                guided[name] = TruncatedNormal(centre, self.spread * _scale(dist), low, high)
            out.append(guided)
        return out

    def sample(self, n: int, rng: np.random.Generator) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Draw ``n`` points; returns (values per dispersion, component index per run).

        The component is :data:`NOMINAL_COMPONENT` or the region id.
        """
        shares = np.concatenate(
            [[self.defensive_fraction], (1 - self.defensive_fraction) * self.region_shares]
        )
        which = rng.choice(len(shares), size=n, p=shares)  # 0: nominal, r + 1: region r
        u = rng.random((n, len(self.dispersions)))
        values = sample_dispersions(self.dispersions, u)
        for index, guided in enumerate(self.components()):
            rows = np.flatnonzero(which == index + 1)
            for name, proposal in guided.items():
                values[name][rows] = proposal.ppf(rng.random(rows.size))
        region_ids = np.array([NOMINAL_COMPONENT] + [r.region for r in self.regions])
        return values, region_ids[which]

    def weights(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """Likelihood ratios ``p(x) / q(x)`` of points ``values`` (same keys as the dispersions)."""
        n = len(next(iter(values.values()))) if values else 0
        mixture = np.full(n, self.defensive_fraction)
        for share, guided in zip(self.region_shares, self.components(), strict=True):
            ratio = np.ones(n)
            for name, proposal in guided.items():
                x = np.asarray(values[name], dtype=float)
                ratio *= proposal.pdf(x) / self.dispersions[name].pdf(x)
            mixture += (1 - self.defensive_fraction) * share * ratio
        return 1.0 / mixture


def make_plan(spec, n_runs: int | None = None, first_run_id: int = 0) -> pd.DataFrame:
    """The campaign plan of a validated :class:`~oos_drake.campaign.spec.CampaignSpec`.

    ``n_runs`` runs (default: the spec's) numbered from ``first_run_id``: a batch added to a
    campaign that runs until its intervals decide draws its own seeds (:func:`run_seeds`).

    Returns
    -------
    pandas.DataFrame
        One row per run: ``run_id``, ``seed``, ``region`` (-1: nominal draw), ``weight``,
        ``window``, ``window start [s]``, ``window end [s]``, ``frequency [Hz]`` (see the module
        docstring) and one ``"name [unit]"`` column per simulator parameter (dispersed value, or
        the nominal value).

    Raises
    ------
    ValueError
        A run with a nonzero LTI perturbation and no frequency (no ``worst_cases`` file).
    """
    info = spec.info
    n = spec.n_runs if n_runs is None else n_runs
    seeds, rng = run_seeds(spec.random_seed, n, first_run_id)
    defensive = 1.0  # every run drawn from the dispersions
    if spec.sampler.kind == "mu-guided":
        values, region, weight, defensive = _guided_draws(spec, n, rng)
    else:  # phase-stratified: i.i.d. values, the phase fixes the window
        kind = "monte-carlo" if spec.sampler.kind == "phase-stratified" else spec.sampler.kind
        u = uniform_variates(kind, n, len(spec.dispersions), rng)
        values = sample_dispersions(spec.dispersions, u)
        region = np.full(n, NOMINAL_COMPONENT)
        weight = np.ones(n)

    by_id = {r.region: r for r in spec.regions}
    window_region = region
    if spec.window.kind == "critical":
        shares = MuGuidedProposal(
            spec.dispersions, spec.regions, region_weighting=spec.sampler.region_weighting
        ).region_shares
        drawn = rng.choice([r.region for r in spec.regions], size=n, p=shares)
        window_region = np.where(region == NOMINAL_COMPONENT, drawn, region)
        windows = [spec.window.resolve(info, by_id[int(r)].time) for r in window_region]
        labels = [f"region:{int(r)}" for r in window_region]
    elif spec.sampler.kind == "phase-stratified":
        phases = mission_phases(info)
        counts = proportional_allocation([(w.end - w.start) / info.duration for w in phases], n)
        windows = [w for w, count in zip(phases, counts, strict=True) for _ in range(count)]
        labels = [w.label for w in windows]
    else:
        windows = [spec.window.resolve(info)] * n
        labels = [w.label for w in windows]
    frequency = np.full(n, np.nan)
    if spec.regions:
        peak = max(spec.regions, key=lambda r: r.mu_upper)
        frequency = np.array(
            [by_id[int(r)].frequency if r in by_id else peak.frequency for r in window_region],
            dtype=float,
        )

    table = pd.DataFrame(
        {
            "run_id": np.arange(first_run_id, first_run_id + n, dtype=np.int64),
            "seed": seeds,
            "region": region.astype(np.int64),
            "weight": weight.astype(float),
            "window": labels,
            "window start [s]": [w.start for w in windows],
            "window end [s]": [w.end for w in windows],
            FREQUENCY_COLUMN: frequency,
            DEFENSIVE_COLUMN: defensive,
        }
    )
    for parameter in info.parameters:
        column = values.get(parameter.name)
        table[parameter.column] = (
            np.asarray(column, dtype=float)
            if column is not None
            else np.full(n, float(parameter.nominal))
        )
    lti = [p for p in info.parameters if p.kind == ParameterKind.LTI]
    perturbed = np.zeros(n, dtype=bool)
    for parameter in lti:
        perturbed |= table[parameter.column].to_numpy() != 0.0
    if np.any(perturbed & np.isnan(frequency)):
        names = ", ".join(p.name for p in lti if p.name in spec.dispersions) or lti[0].name
        raise ValueError(
            f"campaign {spec.name}: LTI perturbations ({names}) need the frequency that "
            "realizes them: give the analysis' worst_cases.parquet (worst_cases = FILE in "
            "[sampler] or --worst-cases FILE; runs use their region's critical frequency)"
        )
    return table


def proportional_allocation(weights: Sequence[float], runs: int) -> np.ndarray:
    """Runs per stratum ``n_h`` within one of ``W_h * runs`` (largest remainders), sum ``runs``."""
    share = np.asarray(weights, float) * runs
    counts = np.floor(share).astype(int)
    remainder = runs - counts.sum()
    counts[np.argsort(-(share - counts), kind="stable")[:remainder]] += 1
    return counts


def mission_phases(info) -> tuple[MissionWindow, ...]:
    """The mission cut at its events: ``[0, e_1], [e_1, e_2], ..., [e_k, duration]`` [s],
    labelled ``"phase:start-capture"``, ``"phase:capture-docking"``, ... (empty ones dropped)."""
    events = sorted((t, name) for name, t in info.events.items() if 0 < t < info.duration)
    marks = [(0.0, "start"), *events, (info.duration, "end")]
    return tuple(
        MissionWindow(t0, t1, f"phase:{a}-{b}")
        for (t0, a), (t1, b) in zip(marks[:-1], marks[1:], strict=True)
        if t1 > t0
    )


def phase_weights(info) -> dict[str, float]:
    """Phase label -> its share of the mission's duration [-] (the strata weights)."""
    return {w.label: (w.end - w.start) / info.duration for w in mission_phases(info)}


def region_counts(plan: pd.DataFrame, regions: Sequence[WorstCaseRegion]) -> pd.DataFrame:
    """How many runs each proposal component got (nominal row first)."""
    counts = plan["region"].value_counts()
    rows = [
        {
            "region": NOMINAL_COMPONENT,
            "configuration": "nominal dispersions",
            "time [s]": np.nan,
            "mu upper [-]": np.nan,
            "runs": int(counts.get(NOMINAL_COMPONENT, 0)),
        }
    ]
    rows += [
        {
            "region": r.region,
            "configuration": r.configuration,
            "time [s]": r.time,
            "mu upper [-]": r.mu_upper,
            "runs": int(counts.get(r.region, 0)),
        }
        for r in regions
    ]
    return pd.DataFrame(rows)
