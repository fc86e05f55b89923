"""``oos campaign run/falsify --controller``: the flown controller named like every other
command's; a mission campaign without one says that the baseline PD flies."""

from __future__ import annotations

import argparse
import json

from oos_drake.app.campaign import _controller_note, _simulator_options, main
from oos_drake.campaign.spec import SPEC_DIRECTORY, load_spec


def _args(controller=None, options=()):
    return argparse.Namespace(controller=controller, simulator_option=list(options))


def test_controller_becomes_the_simulators_option_and_a_missing_one_is_noted(tmp_path):
    spec = load_spec(SPEC_DIRECTORY / "paper_phases.toml")
    assert "controller" not in spec.simulator.option_dict
    assert _simulator_options(_args()) == {}
    assert "baseline PD" in _controller_note(spec, {})
    controller = tmp_path / "controller.json"
    controller.write_text(json.dumps({"K": [[0.0]]}))
    options = _simulator_options(_args(controller))
    assert options == {"controller": str(controller.resolve())}
    assert _controller_note(spec, options) is None
    synthetic = load_spec(SPEC_DIRECTORY / "demo.toml")  # flies no controller of ours
    assert _controller_note(synthetic, {}) is None


def test_bad_controller_option_exits_2_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "never"
    spec = str(SPEC_DIRECTORY / "paper_phases.toml")
    controller = tmp_path / "c.json"
    controller.write_text("{}")
    for command in ("run", "falsify"):
        base = ["campaign", command, spec, "--out", str(out)]
        assert main([*base, "--controller", "nope.json"]) == 2
        assert "--controller nope.json: no such file" in capsys.readouterr().err
        twice = [*base, "--controller", str(controller), "--simulator-option", "controller=x"]
        assert main(twice) == 2
        assert "give one" in capsys.readouterr().err
        assert not out.exists()
