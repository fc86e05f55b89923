"""A campaign that runs until its interval decides against the target, or its budget ends."""

from __future__ import annotations

import math
import textwrap

import pandas as pd

from oos_drake.campaign import store
from oos_drake.campaign.report import probability_sentences
from oos_drake.campaign.runner import load_campaign, resume_campaign, run_campaign


def _spec(max_runs: int) -> str:
    return textwrap.dedent(
        f"""
        name = "decide"
        n_runs = 20
        random_seed = 5
        metrics = ["ape"]

        [simulator]
        name = "tests.campaign.synthetic_sim:make_simulator"

        [window]
        kind = "event"
        event = "capture"
        before = 5.0
        after = 20.0

        [dispersions]
        a = {{ distribution = "uniform", low = 0.0, high = 1.0 }}
        b = {{ distribution = "uniform", low = 0.0, high = 1.0 }}

        [requirements]
        ape = {{ max = 1.0 }}              # never violated

        [estimation]
        target = 0.1
        until_decided = true
        batch = 10
        max_runs = {max_runs}
        """
    )


def _sentences(directory) -> str:
    """The report's probability lines (without drawing the report's figures)."""
    spec, _ = load_campaign(directory)
    return probability_sentences(spec, store.load_runs(directory))


def test_runs_until_the_bound_decides(write_spec, tmp_path):
    # no violation: the one-sided 95 % bound 1 - 0.05^(1/N) <= 0.1 from N = 29 runs on;
    # batches of 10 after the first 20 runs reach it at 30
    needed = math.ceil(math.log(0.05) / math.log(0.9))
    expected = 20 + 10 * math.ceil((needed - 20) / 10)
    summary = run_campaign(write_spec(_spec(500)), tmp_path / "c", workers=1, progress=False)
    assert summary.n_runs == summary.executed == expected == 30
    runs = pd.read_parquet(tmp_path / "c" / "runs.parquet")
    plan = pd.read_parquet(tmp_path / "c" / "plan.parquet")
    assert len(runs) == len(plan) == expected
    assert plan["seed"].is_unique and sorted(plan["run_id"]) == list(range(expected))
    text = _sentences(tmp_path / "c")
    assert f"{expected} runs, 0 violations: P <= " in text
    assert "(Clopper-Pearson); P <= 0.1" in text
    # nothing left to do: a resume runs nothing
    again = resume_campaign(tmp_path / "c", workers=1, progress=False)
    assert (again.executed, again.n_runs) == (0, expected)


def test_stops_at_the_budget(write_spec, tmp_path):
    summary = run_campaign(write_spec(_spec(25)), tmp_path / "c", workers=1, progress=False)
    assert summary.n_runs == 25  # 20 + 5: the budget, still undecided
    text = _sentences(tmp_path / "c")
    assert "25 runs, 0 violations" in text and "undecided" in text
