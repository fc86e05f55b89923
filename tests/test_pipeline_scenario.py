"""``oos run --scenario``: the stage keys follow the parts of the scenario file each stage reads,
so editing it recomputes exactly the dependent stages (heavy work stubbed)."""

import json
from types import SimpleNamespace

import pytest

from oos_drake.app import pipeline
from oos_drake.scenario.data import DEFAULT_SCENARIO_PATH

PAPER = DEFAULT_SCENARIO_PATH.read_text()
CAMPAIGN = pipeline.DEFAULT_CAMPAIGN


def _ran(out):
    stages = json.loads((out / "timings.json").read_text())["stages_s"]
    return sorted(k for k, v in stages.items() if v is not None and k != "campaign + report")


@pytest.fixture
def stubbed(monkeypatch):
    """Every stage function and the Drake check replaced by a recorder (a folder made); the
    calls recorded."""
    calls = []

    import oos_drake.app.scenario as app_scenario  # the model stage: a function call, no argv

    def fake_model(scenario, out, figures=None):
        calls.append(["model", scenario.source, figures is not None])
        out.mkdir(parents=True, exist_ok=True)
        return SimpleNamespace(status=0)

    monkeypatch.setattr(app_scenario, "model", fake_model)
    monkeypatch.setattr(pipeline, "_validate", lambda folder, scenario: calls.append(["validate"]))
    import oos_drake.app.synth as synth  # the controller stage: a function call, no argv

    monkeypatch.setattr(
        synth,
        "controller",
        lambda scenario, options, out: (
            calls.append(["synth", scenario.source]) or SimpleNamespace(status="ok")
        ),
    )
    import oos_drake.app.analyze as analyze  # the analysis stage: a function call, no argv

    monkeypatch.setattr(analyze, "analysis_controller", lambda path, scenario, loop=None: path)
    monkeypatch.setattr(
        analyze,
        "analyze",
        lambda scenario, controller, options, out: calls.append(["analyze", scenario.source]),
    )
    monkeypatch.setattr(analyze, "margins_controller", lambda path, scenario, delay_s=None: path)
    monkeypatch.setattr(
        analyze,
        "margins",
        lambda scenario, controller, options, out: calls.append(["margins", scenario.source]),
    )
    monkeypatch.setattr(analyze, "confirm_inputs", lambda analysis, path, scenario: (scenario,))
    monkeypatch.setattr(
        analyze, "confirm", lambda scenario, options, out: calls.append(["confirm", scenario])
    )

    import oos_drake.app.campaign as app_campaign  # the campaign stage: a function call too

    def fake_campaign(options, folder):
        calls.append(["campaign", str(options.spec)])
        folder.mkdir(parents=True, exist_ok=True)

    monkeypatch.setattr(app_campaign, "campaign", fake_campaign)
    monkeypatch.setattr(app_campaign, "campaign_report", lambda folder: calls.append(["report"]))

    def fake_report(folder, out, campaign):
        calls.append(["report"])
        (folder / "report.html").write_text("<html></html>")

    monkeypatch.setattr(pipeline, "_report", fake_report)
    return calls


def _run(out, scenario, campaign=CAMPAIGN):
    args = SimpleNamespace(
        out=str(out), campaign=str(campaign), workers=1, quick=True, scenario=str(scenario)
    )
    assert pipeline.run_pipeline(args) == 0


def _campaign_for(tmp_path, scenario):
    spec = tmp_path / "campaign.toml"
    text = CAMPAIGN.read_text()
    assert text.count('\nscenario = "paper"') == 1  # the shipped spec names its scenario
    spec.write_text(text.replace('\nscenario = "paper"', f'\nscenario = "{scenario.name}"'))
    return spec


def test_scenario_edits_recompute_exactly_the_dependent_stages(tmp_path, stubbed):
    scenario = tmp_path / "mine.toml"
    scenario.write_text(PAPER)
    campaign = _campaign_for(tmp_path, scenario)
    out = tmp_path / "out"
    _run(out, scenario, campaign)
    everything = ["analysis", "confirm", "controller", "margins", "model", "report", "validate"]
    assert _ran(out) == everything
    synth = next(c for c in stubbed if c[0] == "synth")
    assert synth == ["synth", scenario.resolve()]
    confirm = next(c for c in stubbed if c[0] == "confirm")
    assert confirm == ["confirm", str(scenario.resolve())]

    _run(out, scenario, campaign)
    assert _ran(out) == []

    scenario.write_text(PAPER.replace("# [kg] at G2", "# [kg] edited comment at G2"))
    _run(out, scenario, campaign)  # comments only: nothing to recompute
    assert _ran(out) == []

    scenario.write_text(
        PAPER.replace("pointing_requirement = 0.0079", "pointing_requirement = 0.005")
    )
    _run(out, scenario, campaign)  # requirements: controller and after, not the model
    assert _ran(out) == ["analysis", "confirm", "controller", "margins", "report"]

    edited = PAPER.replace("pointing_requirement = 0.0079", "pointing_requirement = 0.005")
    scenario.write_text(edited.replace("mass = 24.96 ", "mass = 30.0 "))
    _run(out, scenario, campaign)  # physical data: everything
    assert _ran(out) == everything
    assert len(list(out.glob("campaign-*"))) == 3  # a new campaign folder per campaign key


def test_stage_keys_by_scenario_part(tmp_path):
    first, second = tmp_path / "a.toml", tmp_path / "b.toml"
    first.write_text(PAPER)
    second.write_text(PAPER.replace("gyro_cutoff_hz = 200.0", "gyro_cutoff_hz = 150.0"))
    a = pipeline.stage_keys(first, CAMPAIGN, quick=False)
    b = pipeline.stage_keys(second, CAMPAIGN, quick=False)
    assert [k for k in a if a[k] != b[k]] == [
        "controller",
        "analysis",
        "confirm",
        "margins",
        "campaign",
        "report",
    ]
    assert pipeline.stage_keys(first, CAMPAIGN, quick=True)["model"] == a["model"]


def test_campaign_spec_of_another_scenario_is_refused(tmp_path, stubbed):
    with pytest.raises(ValueError, match="is written for scenario .*paper.toml, not .*heavy"):
        _run(tmp_path / "out", DEFAULT_SCENARIO_PATH.parent / "heavy_target.toml")
    assert not (tmp_path / "out").exists()
