"""The HTML report of an ``oos run`` folder, opened in headless Chromium.

Fast: a small synthetic results folder made here (every table the report reads, with numbers
chosen so that the headline of each is known), and an empty one (every section "not run").
The headline numbers the page shows are compared with the tables read here with pandas and
json, not with anything the report module computed.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image
from report_browser import probe, screenshot, section_screenshots
from scipy.stats import beta

from oos_drake.report import headline_numbers, load_run, write_report
from oos_drake.scenario.data import scenario_path

SUBSETS = ("total", "real", "modal", "mechanical", "additive", "multiplicative")


def _png(path: Path, width: int = 60, height: int = 40) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", (width, height), (30, 90, 160)).save(path)


@pytest.fixture
def results_folder(tmp_path) -> Path:
    """A results folder with every table the report reads (small, made-up numbers)."""
    out = tmp_path / "out"
    scenario = scenario_path(None)
    record = {"name": "paper", "file": str(scenario), "sha256": "0" * 64, "overrides": {}}
    (out / "model").mkdir(parents=True)
    pd.DataFrame(
        {
            "block": ["m_RH2", "w1_SA1"],
            "kind": ["ureal", "ureal"],
            "quantity": ["mass", "modal frequency"],
            "unit": ["kg", "rad/s"],
            "nominal [unit]": [24.96, 8.07],
            "lower [unit]": [22.46, 6.46],
            "upper [unit]": [27.46, 9.69],
            "occurrences": [3, 2],
        }
    ).to_parquet(out / "model" / "blocks.parquet")
    (out / "controller").mkdir(parents=True)
    controller = {
        "controller": {
            "structure": "u_K = K y",
            "K_p": {"value": np.eye(3).tolist(), "unit": "N m/rad"},
            "K_d": {"value": (2 * np.eye(3)).tolist(), "unit": "N m s/rad"},
            "rolloff": {"type": "butterworth", "order": 4, "cutoff_hz": 0.7},
        },
        "gamma": 0.8123456,
        "gamma_baseline": 11.0,
        "requirement_met": True,
        "scenario": record,
    }
    (out / "controller" / "controller.json").write_text(json.dumps(controller))
    analysis = out / "analysis"
    analysis.mkdir()
    (analysis / "summary.json").write_text(json.dumps({"scenario": record}))
    rng = np.random.default_rng(7)
    rows = []
    for i, subset in enumerate(SUBSETS):
        lower = 0.3 + 0.05 * i
        rows.append(
            {
                "study": "mission",
                "subset": subset,
                "time [s]": 100.0 + 10 * i,
                "frequency [Hz]": 0.5 + 0.01 * i,
                "mu lower [-]": lower,
                "mu upper [-]": lower * 1.01,
                "mu upper guaranteed [-]": lower * 1.02 + 1e-6 * rng.random(),
                "gap [%]": 1.0,
                "configuration": f"mission t={100 + 10 * i}s",
                "margin [-]": 1 / (lower * 1.01),
            }
        )
    rows.append(dict(rows[0], study="docking-7", **{"mu upper guaranteed [-]": 1.5}))
    pd.DataFrame(rows).to_parquet(analysis / "stability_peaks.parquet")
    pd.DataFrame(
        {
            "study": ["mission", "mission"],
            "subset": ["total", "total"],
            "block": ["m_RH2", "w1_SA1"],
            "kind": ["ureal", "ureal"],
            "unit": ["kg", "rad/s"],
            "destabilizing value [unit]": [30.1, 5.2],
            "in set value [unit]": [27.0, 6.5],
            "normalized norm [-]": [1.2, 1.1],
        }
    ).to_parquet(analysis / "worst_perturbations.parquet")
    _png(analysis / "mu_mission.png")
    (out / "confirm").mkdir()
    pd.DataFrame(
        {
            "study": ["mission"],
            "subset": ["total"],
            "mu lower [-]": [0.3],
            "mu upper [-]": [0.303],
            "alpha physical max [-]": [2.0],
            "alpha nonlinear [-]": [3.4],
            "status": ["confirmed"],
        }
    ).to_parquet(out / "confirm" / "confirmation.parquet")
    pd.DataFrame(
        {
            "channel": ["e_p", "e_p", "e_u"],
            "subset": ["total", "real", "total"],
            "time [s]": [269.2, 269.2, 0.0],
            "frequency [Hz]": [0.0807, 0.0611, 0.1407],
            "gain lower [-]": [1.179, 0.762, 0.655],
            "gain upper [-]": [1.199, 0.768, 0.662],
            "gain linear twin [-]": [1.1789, 0.7618, 0.6546],
            "gain linear sampled [-]": [1.2803, 0.7739, 0.7681],
            "gain twin [-]": [1.2809, 0.7738, np.nan],
            "peak ratio twin [-]": [1.2572, 0.6282, np.nan],
            "status": ["twin violated (1.28)", "twin met (0.774)", "no twin run: too long"],
        }
    ).to_parquet(out / "confirm" / "performance_confirmation.parquet")
    (out / "margins").mkdir()
    margins = pd.DataFrame(
        {
            "time [s]": np.tile([0.0, 500.0, 1000.0], 2),
            "loop": ["continuous"] * 3 + ["sampled"] * 3,
            "gain margin upper [dB]": [9.0, 8.5, 10.0, 7.25, 8.0, 9.5],
            "phase margin [deg]": [40.0, 35.5, 42.0, 33.0, 31.75, 38.0],
            "delay margin [s]": [0.5, 0.4, 0.6, 0.3, 0.2, 0.5],
            "disk margin [-]": [0.6, 0.5, 0.7, 0.4, 0.45, 0.5],
        }
    )
    margins.to_parquet(out / "margins" / "margins.parquet")
    _png(out / "margins" / "margins.png")
    campaign = out / "campaign-0123456789"
    (campaign / "report").mkdir(parents=True)
    pd.DataFrame({"run_id": [0, 1]}).to_parquet(campaign / "plan.parquet")
    pd.DataFrame(
        {
            "metric": ["ape max [rad]", "any (requirement or run failure)"],
            "requirement": ["<= 0.0079", "all"],
            "runs": [200, 200],
            "violations": [0, 1],
            "P(violation)": [0.0, 0.005],
            "P 95 % low": [0.0, 0.000127],
            "P 95 % high": [0.01815, 0.02755],
            "interval": ["clopper-pearson", "clopper-pearson"],
            # the one-sided Clopper-Pearson bound beta.ppf(0.95, k + 1, N - k), k = 0 and 1 of 200
            "P 95 % upper (one-sided)": [beta.ppf(0.95, 1, 200), beta.ppf(0.95, 2, 199)],
        }
    ).to_parquet(campaign / "report" / "summary.parquet")
    pd.DataFrame(
        {
            "run_id": [3, 7, 9],
            "requirement": ["ape <= 0.0079 rad"] * 3,
            "phase": ["start-capture", "start-capture", "capture-docking"],
            "first violation time [s]": [96.0, 41.0, 601.0],
            "window": ["phase:start-capture"] * 2 + ["phase:capture-docking"],
            "status": ["ok"] * 3,
        }
    ).to_parquet(campaign / "report" / "violations.parquet")
    _png(campaign / "report" / "regions_performance.png", 80, 50)
    (campaign / "replay").mkdir()
    (campaign / "replay" / "case_3.html").write_text("<html></html>")
    (out / "validate").mkdir()
    (out / "validate" / "validate.txt").write_text("Drake vs TITOP: max relative error 1e-9 [-]\n")
    (out / "timings.json").write_text(
        json.dumps({"scenario": str(scenario), "stages_s": {"model": 1.5}, "total_s": 2.0})
    )
    return out


def expected_headlines(out: Path) -> dict[str, float]:
    """The headline numbers read from the results' files with pandas and json (independently
    of the report module): gamma, the mission's guaranteed mu per subset, the worst gain and
    phase margins, the campaign's 95 % upper bound of P(a run fails)."""
    expected = {}
    controller = json.loads((out / "controller" / "controller.json").read_text())
    expected["gamma"] = controller["gamma"]
    peaks = pd.read_parquet(out / "analysis" / "stability_peaks.parquet")
    mission = peaks[peaks["study"] == "mission"].set_index("subset")
    column = "mu upper guaranteed [-]" if "mu upper guaranteed [-]" in mission else "mu upper [-]"
    for subset, value in mission[column].items():
        expected[f"mu_{subset}"] = float(value)
    margins = pd.read_parquet(out / "margins" / "margins.parquet")
    expected["gain_margin"] = float(margins["gain margin upper [dB]"].min())
    expected["phase_margin"] = float(margins["phase margin [deg]"].min())
    performance = out / "confirm" / "performance_confirmation.parquet"
    if performance.is_file():
        gains = pd.read_parquet(performance)["gain twin [-]"].dropna()
        if len(gains):
            expected["performance_twin"] = float(gains.max())
    (campaign,) = [p for p in out.glob("campaign-*") if (p / "plan.parquet").is_file()]
    summary = pd.read_parquet(campaign / "report" / "summary.parquet").set_index("metric")
    # the one-sided bound the campaign prints ("P <= p at 95 %"); summaries older than that
    # column have only the two-sided interval
    one_sided = "P 95 % upper (one-sided)"
    column = one_sided if one_sided in summary.columns else "P 95 % high"
    expected["p_fail_bound"] = float(summary.loc["any (requirement or run failure)", column])
    return expected


def check_page(page: Path, out: Path, work: Path, shots: Path | None = None) -> dict:
    """Open ``page`` in Chromium and check it: no error of any kind, every image decoded, the
    headline numbers equal to the results' tables (value and text shown, with its unit)."""
    seen = probe(page, work)
    assert seen["errors"] == [], seen["errors"]
    assert seen["console_log"] == [], seen["console_log"]
    assert all(name.startswith("data:") for name in seen["resources"]), seen["resources"]
    assert seen["images"], "no figure in the report"
    broken = [i["alt"] for i in seen["images"] if not (i["complete"] and i["width"] > 0)]
    assert broken == [], f"images that did not load: {broken}"
    expected = expected_headlines(out)
    shown = {h["key"]: h for h in seen["headlines"]}
    assert set(shown) == set(expected)
    units = {"gain_margin": "dB", "phase_margin": "deg"}
    for key, value in expected.items():
        np.testing.assert_allclose(float(shown[key]["value"]), value, rtol=1e-12, err_msg=key)
        text = shown[key]["text"]
        number = float(re.match(r"\s*([-+0-9.eE]+)", text).group(1))
        np.testing.assert_allclose(number, value, rtol=5e-4, err_msg=f"{key}: {text}")
        assert text.strip().endswith(units.get(key, "[-]")), f"{key}: no unit in {text!r}"
    if shots is not None:
        section_screenshots(
            page,
            seen["sections"],
            {"headlines": "top.png", "analysis": "analysis.png", "campaign": "campaign.png"},
            shots,
            work,
        )
    return seen


def test_report_of_a_synthetic_folder_in_chromium(results_folder, tmp_path):
    page = write_report(results_folder)
    assert page == results_folder / "report.html"
    seen = check_page(page, results_folder, tmp_path / "browser")
    shot = screenshot(page, tmp_path / "top.png", tmp_path / "browser")
    with Image.open(shot) as image:  # a page was drawn, not a blank window
        assert image.size == (1400, 1400) and len(image.getcolors(1 << 16) or range(99)) > 20
    assert len(seen["headlines"]) == 11
    assert len(seen["images"]) == 3  # the PNG files of the folder
    sections = {s["id"]: s["notRun"] for s in seen["sections"]}
    for section in ("headlines", "controller", "analysis", "validation", "replays"):
        assert sections[section] == 0, section
    text = page.read_text()
    assert "<td>modal frequency</td><td>rad/s</td>" in text  # the block table, with units
    assert 'href="campaign-0123456789/replay/case_3.html"' in text
    assert "http://" not in text and "https://" not in text
    assert "Worst-case performance on the Drake twin" in text
    assert "twin violated (1.28)" in text  # the performance table, row by row
    # violations per phase (2 in start-capture, 1 in capture-docking) and their times
    assert '<td>start-capture</td><td class="num">2</td>' in text
    assert '<td>capture-docking</td><td class="num">1</td>' in text
    assert '<td class="num">601</td>' in text


def test_worst_performance_headline_names_channel_requirement_and_bounds(results_folder):
    """The headline is the largest finite twin gain (1.2809 of the e_p total row, the e_u row
    without a twin run skipped), with the analysis' interval and the verdict against 1."""
    numbers = headline_numbers(load_run(results_folder))
    (worst,) = [h for h in numbers if h.key == "performance_twin"]
    assert worst.value == 1.2809
    assert "APE requirement violated" in worst.where and "e_p total" in worst.where
    assert "[1.179, 1.199]" in worst.where and "t = 269.2 s" in worst.where
    path = results_folder / "confirm" / "performance_confirmation.parquet"
    table = pd.read_parquet(path)
    table["gain twin [-]"] = np.nan  # no twin run finished: no headline
    table.to_parquet(path)
    assert "performance_twin" not in [h.key for h in headline_numbers(load_run(results_folder))]


def test_campaign_headline_is_the_one_sided_bound_the_campaign_prints(results_folder):
    """The headline's P(a run fails) is the one-sided 95 % bound (1 failure in 200 runs:
    beta.ppf(0.95, 2, 199) = 0.0235, the "P <= p at 95 %" of the campaign's own report), not the
    upper end of the two-sided interval (0.0276); a summary written before the one-sided column
    existed gives the two-sided end, and its label says so."""
    (bound,) = [h for h in headline_numbers(load_run(results_folder)) if h.key == "p_fail_bound"]
    assert bound.value == pytest.approx(beta.ppf(0.95, 2, 199), rel=1e-12)
    assert "one-sided" in bound.label and "1 of 200 runs fail" in bound.where
    (campaign,) = results_folder.glob("campaign-*")
    path = campaign / "report" / "summary.parquet"
    pd.read_parquet(path).drop(columns="P 95 % upper (one-sided)").to_parquet(path)
    (bound,) = [h for h in headline_numbers(load_run(results_folder)) if h.key == "p_fail_bound"]
    assert bound.value == 0.02755 and "two-sided" in bound.label


def test_the_browser_check_sees_a_broken_figure(results_folder, tmp_path):
    """The check can fail: a figure whose bytes are not an image has no natural width."""
    (results_folder / "analysis" / "broken.png").write_bytes(b"not a png")
    page = write_report(results_folder)
    with pytest.raises(AssertionError, match="broken.png"):
        check_page(page, results_folder, tmp_path / "browser")


def test_missing_stages_render_as_not_run(tmp_path):
    """An empty results folder: every section says "not run", nothing crashes."""
    out = tmp_path / "empty"
    out.mkdir()
    assert headline_numbers(load_run(out)) == []
    page = write_report(out)
    text = page.read_text()
    assert text.count('class="notrun"') >= 8
    assert "data-headline" not in text


def test_broken_table_renders_as_not_run(results_folder):
    """A table another stage changed (a column gone) costs its section, not the report."""
    path = results_folder / "confirm" / "confirmation.parquet"
    pd.read_parquet(path).drop(columns=["alpha physical max [-]"]).to_parquet(path)
    (results_folder / "margins" / "margins.parquet").write_bytes(b"not parquet")
    results = load_run(results_folder)
    assert results.margins is None
    keys = [h.key for h in headline_numbers(results)]
    assert "gain_margin" not in keys and "gamma" in keys
    text = write_report(results_folder).read_text()
    assert "not run: margins stage" in text
    assert "not checked (confirm not run)" in text


def test_oos_report_command_prints_the_headlines(results_folder, capsys):
    from oos_drake.app.main import main

    assert main(["report", str(results_folder)]) == 0
    printed = capsys.readouterr().out
    assert f"report: {results_folder / 'report.html'}" in printed
    assert "0.8123 [-]" in printed  # gamma
    assert "7.25 dB" in printed  # worst gain margin
    assert main(["report", str(results_folder / "nowhere")]) == 2  # one-line error
    assert (results_folder / "report.html").is_file()


def test_report_stage_key_follows_the_campaign_tables(results_folder):
    """The campaign resumes instead of being stamped: its report tables are in the report
    stage's key, so a campaign that gained runs gets a new report."""
    from oos_drake.app.pipeline import report_key

    (campaign,) = results_folder.glob("campaign-*")
    before = report_key("inputs", campaign)
    assert report_key("inputs", campaign) == before
    assert report_key("other inputs", campaign) != before
    path = campaign / "report" / "summary.parquet"
    pd.read_parquet(path).assign(runs=[201, 201]).to_parquet(path)
    assert report_key("inputs", campaign) != before


def test_missing_browser_is_a_skip_that_ci_turns_into_a_failure(monkeypatch):
    """Without chromium the browser tests skip with a reason that ``conftest.py`` turns into a
    failure when ``CI`` is set ("not installed")."""
    import report_browser

    monkeypatch.setattr(report_browser.shutil, "which", lambda name: None)
    monkeypatch.setattr(report_browser, "CHROMIUM", "/nonexistent/chromium")
    with pytest.raises(pytest.skip.Exception, match="not installed"):
        report_browser.chromium()
