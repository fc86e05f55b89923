"""Report: tables agree with an independent count over runs.parquet; figures are written."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pandas as pd
import pytest

from oos_drake.app.campaign import main as cli_main
from oos_drake.campaign.report import weighted_quantile, write_report
from oos_drake.campaign.runner import run_campaign
from oos_drake.campaign.spec import SPEC_DIRECTORY

from .spec_texts import BASE_SPEC


def test_report_tables_and_figures(write_spec, tmp_path, capsys):
    # a wide initial-rate dispersion so that some runs violate the APE requirement
    text = (
        BASE_SPEC.replace("n_runs = 12", "n_runs = 30")
        .replace(
            "[requirements]",
            'omega0 = { distribution = "uniform", low = -0.008, high = 0.008 }\n\n[requirements]',
        )
        .replace('keep = "all"', 'keep = "none"')
    )
    out = tmp_path / "c"
    run_campaign(write_spec(text), out, progress=False)
    runs = pd.read_parquet(out / "runs.parquet")
    report = write_report(out, worst=3)

    summary = report.tables["summary"].set_index("metric")
    ape_fail = runs["ape [rad]"] > 0.0079
    assert 0 < ape_fail.sum() < len(runs)
    assert summary.loc["ape [rad]", "violations"] == ape_fail.sum()
    assert summary.loc["ape [rad]", "P(violation)"] == ape_fail.mean()
    assert summary.loc["ape [rad]", "max"] == runs["ape [rad]"].max()
    any_fail = ~runs["pass"]
    assert summary.loc["any (requirement or run failure)", "P(violation)"] == any_fail.mean()
    worst = report.tables["worst_runs"]
    assert worst["run_id"].iloc[0] == runs.loc[(runs["ape [rad]"] / 0.0079).idxmax(), "run_id"]

    names = {p.name for p in report.figures}
    # worst runs are plotted even though no time series was kept (recomputed from the plan)
    assert names == {"metric_distributions.png", "worst_runs.png", "pass_fail_vs_parameters.png"}
    for figure in report.figures:
        image = matplotlib.image.imread(figure)
        assert image.shape[0] > 200 and image.shape[1] > 400
        assert image[..., :3].std() > 0.05  # not blank
    for table in ("summary", "status", "worst_runs"):
        assert (out / "report" / f"{table}.parquet").is_file()

    assert cli_main(["campaign", "report", str(out), "--worst", "2"]) == 0
    printed = capsys.readouterr().out
    assert "P(violation)" in printed and "worst runs" in printed


def test_weighted_quantile_against_repeated_samples():
    values = np.array([3.0, 1.0, 2.0, 4.0])
    weights = np.array([1.0, 2.0, 1.0, 0.0])  # same as the sample [1, 1, 2, 3]
    assert weighted_quantile(values, weights, 0.5) == np.quantile(
        [1, 1, 2, 3], 0.5, method="inverted_cdf"
    )
    assert weighted_quantile(values, weights, 0.9) == 3.0


def test_effective_sample_size():
    from oos_drake.campaign.estimators import effective_sample_size

    assert effective_sample_size(np.ones(10)) == 10.0
    # one dominant weight: about one effective run
    assert effective_sample_size(np.array([1e6, 1.0, 1.0])) < 1.001


def test_mu_guided_report_states_the_weight_shares(tmp_path):

    root = SPEC_DIRECTORY
    text = (
        (root / "demo_mu.toml")
        .read_text()
        .replace("n_runs = 200", "n_runs = 24")
        .replace('keep = "all"', 'keep = "none"')
        .replace('"demo_worst_cases.parquet"', f'"{root / "demo_worst_cases.parquet"}"')
    )
    spec = tmp_path / "mu.toml"
    spec.write_text(text)
    run_campaign(spec, tmp_path / "c", progress=False)
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    report = write_report(tmp_path / "c", worst=2)
    w = runs["weight"].to_numpy()
    defensive = runs["region"].to_numpy() < 0
    assert 0 < defensive.sum() < len(runs)
    expected = 100 * w[defensive].sum() / w.sum()
    assert (
        f"The {defensive.sum()} runs drawn from the dispersions carry {expected:.1f} % "
        "of the total weight" in report.text
    )
    assert f"effective sample size {w.sum() ** 2 / (w**2).sum():.1f} of 24" in report.text


@pytest.mark.parametrize("k, n", [(0, 48), (1, 48), (7, 200), (200, 200)])
def test_unweighted_interval_is_the_exact_binomial_one(k, n):
    from scipy.stats import binomtest

    from oos_drake.campaign.estimators import monte_carlo

    events = np.zeros(n, bool)
    events[:k] = True
    est = monte_carlo(events)
    ref = binomtest(k, n).proportion_ci(0.95, method="exact")
    assert est.method == "Clopper-Pearson"
    assert est.estimate == k / n
    assert (est.low, est.high) == pytest.approx((ref.low, ref.high), rel=1e-9, abs=1e-15)
    if k == 0:  # zero failures: no "p = 0 +- 0", but the rule-of-three-like upper bound
        assert est.low == 0 and est.high == pytest.approx(1 - 0.025 ** (1 / n), rel=1e-9)


def test_weighted_interval_covers_the_true_probability():
    """Brute force: 400 importance-sampled campaigns of 48 runs from a defensive mixture with
    a known failure probability; the 95 % interval must contain it in at least 95 % of them."""
    from oos_drake.campaign.estimators import importance_sampling

    rng = np.random.default_rng(3)
    alpha, region_mass, p_region = 0.2, 0.05, 0.3  # nominal density: a region of mass 5 %
    p_true = region_mass * p_region  # failures only inside the region
    covered, n, campaigns = 0, 48, 400
    for _ in range(campaigns):
        in_nominal = rng.random(n) < alpha  # defensive share draws from the nominal density
        inside = np.where(in_nominal, rng.random(n) < region_mass, True)
        weights = np.where(inside, region_mass / (alpha * region_mass + (1 - alpha)), 1 / alpha)
        fails = inside & (rng.random(n) < p_region)
        est = importance_sampling(fails, weights, weight_bound=1 / alpha)
        covered += est.low <= p_true <= est.high
    assert covered / campaigns >= 0.95


@pytest.mark.parametrize(
    "k, n, decision, more",
    [
        (0, 400, "P <= 0.01", 0.0),  # (0.99)^400 < 0.05: shown
        (0, 100, "undecided", 199.0),  # 299 runs without violation in all (closed form below)
        (20, 100, "P > 0.01", None),  # the lower bound is above the target: no run count helps
    ],
)
def test_summary_gives_more_runs_only_while_undecided(k, n, decision, more):
    """``summary.parquet``: "more runs to show P <= target" is 0 once that is shown, empty
    (NaN) once P > target is shown, and the closed-form count while undecided."""
    from types import SimpleNamespace

    from oos_drake.campaign.report import _estimate

    spec = SimpleNamespace(
        estimation=SimpleNamespace(target=0.01, confidence=0.95),
        sampler=SimpleNamespace(kind="monte-carlo"),
    )
    events = np.zeros(n, bool)
    events[:k] = True
    row = _estimate(spec, pd.DataFrame({"run_id": range(n)}), np.ones(n), events)
    assert row["decision"] == decision
    if more is None:
        assert np.isnan(row["more runs to show P <= target"])
    else:
        # no violation: the smallest N with (1 - target)^N <= 1 - confidence is 299
        assert int(np.ceil(np.log(0.05) / np.log(0.99))) == 299
        assert row["more runs to show P <= target"] == more
