"""Spec validation: every malformed spec is rejected with a one-line error naming the culprit."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from oos_drake.campaign.spec import SPEC_DIRECTORY, load_spec, parse_spec, spec_to_toml

from .spec_texts import BASE_SPEC


def _replace(old: str, new: str) -> str:
    assert old in BASE_SPEC, old
    return BASE_SPEC.replace(old, new)


BAD_SPECS = {
    "unknown top-level key": (BASE_SPEC + "\nn_run = 3\n", r"unknown key\(s\) n_run"),
    "unknown parameter": (
        _replace("J_hub = {", "J_hubb = {"),
        r"dispersions\.J_hubb: unknown parameter",
    ),
    "unknown distribution": (
        _replace('"log-uniform", low = 1.0e2', '"lognormal", low = 1.0e2'),
        r"dispersions\.k_dock: unknown distribution 'lognormal'",
    ),
    "missing distribution key": (
        _replace('"uniform", low = 400.0, high = 600.0', '"uniform", low = 400.0'),
        r"dispersions\.J_hub: uniform distribution needs high",
    ),
    "unknown distribution key": (
        _replace("low = 400.0, high = 600.0", "low = 400.0, high = 600.0, mean = 3.0"),
        r"dispersions\.J_hub: unknown key\(s\) mean",
    ),
    "bound outside the parameter range": (
        _replace("high = 600.0", "high = 900.0"),
        r"dispersions\.J_hub: high = 900 kg m\^2 outside the range of J_hub \[250, 750\]",
    ),
    "inverted bounds": (
        _replace("low = 400.0, high = 600.0", "low = 600.0, high = 400.0"),
        r"dispersions\.J_hub: low = 600 must be below high = 400",
    ),
    "non-positive std": (
        _replace("std = 0.004", "std = 0.0"),
        r"omega_capture: std = 0 rad/s must be positive",
    ),
    "log-uniform through zero": (
        _replace(
            "k_dock = {",
            'theta0 = { distribution = "log-uniform", low = -0.001, high = 0.001 }\nk_dock = {',
        ),
        r"log-uniform needs low > 0",
    ),
    "bad probabilities": (
        BASE_SPEC.replace(
            "[requirements]",
            'T_ext = { distribution = "choice", values = [0.0, '
            "0.01], probabilities = [0.5, 0.6] }\n\n[requirements]",
        ),
        r"dispersions\.T_ext: probabilities \[0.5, 0.6\] must be >= 0 and sum to 1",
    ),
    "bad sampler": (
        _replace('sampler = "monte-carlo"', 'sampler = "sobol"'),
        r"unknown sampler 'sobol'",
    ),
    "zero runs": (_replace("n_runs = 12", "n_runs = 0"), r"n_runs = 0 must be a positive integer"),
    "negative runs": (_replace("n_runs = 12", "n_runs = -5"), r"n_runs = -5 must be a positive"),
    "missing worst cases": (
        _replace('sampler = "monte-carlo"', "").replace(
            "[simulator]",
            '[sampler]\nkind = "mu-guided"\nworst_cases = "nowhere.parquet"\n\n[simulator]',
        ),
        r"worst_cases file .*nowhere\.parquet not found",
    ),
    "mu-guided without worst cases": (
        _replace('sampler = "monte-carlo"', 'sampler = "mu-guided"'),
        r"mu-guided needs the analysis. worst_cases\.parquet .*--worst-cases",
    ),
    "unknown metric": (
        _replace('metrics = ["ape", "peak_torque"]', 'metrics = ["ape", "apex"]'),
        r"unknown metric 'apex'",
    ),
    "requirement on an unrecorded metric": (
        _replace("peak_torque = { max = 2.0 }", "rms_attitude = { max = 2.0 }"),
        r"requirements\.rms_attitude: not one of the recorded metrics",
    ),
    "unknown event": (
        _replace('event = "capture"', 'event = "docking"'),
        r"unknown event 'docking'; known: capture",
    ),
    "unknown simulator": (
        _replace('name = "flexible-attitude"', 'name = "simscape"'),
        r"unknown simulator 'simscape'",
    ),
    "bad simulator option": (
        _replace("control_rate = 5.0", "control_rate = -5.0"),
        r"control_rate=-5.0 must be positive",
    ),
    "unknown simulator option": (
        _replace("control_rate = 5.0", "rate = 5.0"),
        r"unknown option\(s\) rate",
    ),
    "unknown signal": (
        _replace('"theta_hub", "torque_command"', '"theta"'),
        r"unknown signal 'theta'",
    ),
    "bad keep": (_replace('keep = "all"', 'keep = "some"'), r"keep = 'some' not in"),
    "critical window without mu-guided": (
        _replace('kind = "event"\nevent = "capture"', 'kind = "critical"'),
        r"kind = \"critical\" needs the mu-guided sampler",
    ),
    "negative run timeout": (
        _replace("random_seed = 7", "random_seed = 7\nrun_timeout = -1"),
        r"run_timeout = -1 must be > 0",
    ),
    "TOML syntax": (BASE_SPEC + "\n[dispersions\n", r"TOML syntax error"),
}


@pytest.mark.parametrize("case", sorted(BAD_SPECS))
def test_bad_spec_rejected_with_one_line_error(case, write_spec):
    text, pattern = BAD_SPECS[case]
    path = write_spec(text)
    with pytest.raises(ValueError, match=pattern) as info:
        load_spec(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message


def test_good_spec_loads_with_defaults(write_spec):
    spec = load_spec(write_spec())
    assert spec.n_runs == 12 and spec.sampler.kind == "monte-carlo"
    assert list(spec.dispersions) == ["J_hub", "k_dock", "omega_capture"]
    # normal truncated to the parameter's range by default
    assert spec.dispersions["omega_capture"].support == (-0.01, 0.01)
    assert [r.label for r in spec.requirements] == ["ape <= 0.0079 rad", "peak_torque <= 2 N m"]


def test_resolved_spec_round_trips(write_spec, tmp_path):
    spec = load_spec(write_spec())
    again = parse_spec(spec_to_toml(spec), source=tmp_path / "resolved.toml")
    assert again == spec


def test_cli_bad_spec_writes_nothing(write_spec, tmp_path):
    path = write_spec(_replace("high = 600.0", "high = 900.0"))
    out = tmp_path / "campaign"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "oos_drake.app.campaign",
            "campaign",
            "run",
            str(path),
            "--out",
            str(out),
            "--workers",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0
    assert "J_hub" in result.stderr and "outside the range" in result.stderr
    assert not out.exists()


def test_existing_campaign_directory_is_not_overwritten(write_spec, tmp_path):
    from oos_drake.campaign.runner import run_campaign

    path = write_spec(_replace("n_runs = 12", "n_runs = 2"))
    out = tmp_path / "c"
    run_campaign(path, out, progress=False)
    before = sorted(p.name for p in (out / "runs").iterdir())
    with pytest.raises(ValueError, match="already holds a campaign"):
        run_campaign(path, out, progress=False)
    assert sorted(p.name for p in (out / "runs").iterdir()) == before


@pytest.mark.parametrize("name", ["demo.toml", "demo_mu.toml"])
def test_shipped_demo_specs_are_valid(name):

    spec = load_spec(SPEC_DIRECTORY / name)
    assert spec.simulator.name == "flexible-attitude" and spec.n_runs > 0
    assert [r.label for r in spec.requirements] == ["ape <= 0.0079 rad", "peak_torque <= 2 N m"]


def test_a_drake_mission_spec_must_name_its_scenario(write_spec):
    """No library default: the Drake mission is built from the scenario the spec names."""
    text = textwrap.dedent(
        """
        name = "unnamed"
        n_runs = 2
        random_seed = 1

        [simulator]
        name = "oos_drake.campaign.drake_simulator:make_simulator"
        """
    )
    with pytest.raises(
        ValueError, match='names no scenario; add the top-level key scenario = "paper"'
    ):
        load_spec(write_spec(text))
