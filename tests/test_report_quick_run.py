"""The report of a real ``oos run --quick`` (the session's run, shared with test_pipeline.py)
opened in headless Chromium: no error, every figure decoded, the headline numbers equal to the
run's Parquet and JSON results, and the same numbers printed at the end of ``oos run``."""

from __future__ import annotations

import pandas as pd
import pytest
from test_report import check_page, expected_headlines

from oos_drake.report.results import format_number

#: Stage folders whose PNG figures the report embeds (the campaign's report folder too).
FIGURE_FOLDERS = ("model", "analysis", "confirm", "margins")


@pytest.mark.slow
def test_report_of_a_quick_run_in_chromium(quick_run, tmp_path):
    out, result = quick_run.out, quick_run.result
    assert result.returncode == 0, result.stderr[-3000:]
    page = out / "report.html"
    seen = check_page(page, out, tmp_path / "browser", tmp_path / "shots")
    # gamma, six guaranteed mu, two margins, the worst performance ratio on the twin (oos
    # confirm's performance confirmation) and the campaign's bound
    assert len(seen["headlines"]) == len(expected_headlines(out)) == 11
    (campaign,) = out.glob("campaign-*")
    figures = [p for folder in FIGURE_FOLDERS for p in (out / folder).glob("*.png")]
    figures += list((campaign / "report").glob("*.png"))
    assert len(seen["images"]) == len(figures)
    # the end of `oos run` prints the same eleven numbers, with their units
    printed = result.stdout[result.stdout.index("headline numbers:") :]
    units = {"gain_margin": "dB", "phase_margin": "deg"}
    for key, value in expected_headlines(out).items():
        assert format_number(value, units.get(key, "-")) in printed, key
    # the worst run's 3-D replay is made by oos run and linked from the report
    worst = pd.read_parquet(campaign / "report" / "worst_runs.parquet")["run_id"].iloc[0]
    replay = f"{campaign.name}/replay/case_{int(worst)}.html"
    assert (out / replay).is_file() and f'href="{replay}"' in page.read_text()
    for name in ("top.png", "analysis.png", "campaign.png"):
        assert (tmp_path / "shots" / name).stat().st_size > 10_000, name
