"""``oos validate`` and ``oos sdf generate|check`` through the real CLI entry point."""

import argparse
import sys
from pathlib import Path

import pytest

from oos_drake.app.multibody import register


def main(argv):
    """``oos`` restricted to this package's commands, with the top-level CLI's error handling
    (one-line message, status 2 for a ValueError), so these tests do not depend on the other
    subpackages' command modules."""
    parser = argparse.ArgumentParser(prog="oos")
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        print(f"oos {args.command}: error: {exc.args[0] if exc.args else exc}", file=sys.stderr)
        return 2


@pytest.mark.drake
def test_validate_moments_prints_table_and_passes(capsys):
    status = main(["validate", "--cases", "moments", "--frequencies", "100"])
    out = capsys.readouterr().out
    assert status == 0
    assert "configuration" in out and "max rel. error" in out
    for name in "123456":
        assert f"moment {name}" in out
    assert out.count("PASS") == 6 and "FAIL" not in out


@pytest.mark.drake
def test_validate_exits_nonzero_when_a_configuration_fails(capsys):
    # an impossible tolerance: every configuration must be reported as failing
    status = main(["validate", "--cases", "moments", "--frequencies", "20", "--tolerance", "1e-30"])
    out = capsys.readouterr().out
    assert status == 1
    assert out.count("FAIL") >= 6 and "FAILED: 6 of 6" in out


def test_sdf_generate_and_check(tmp_path, capsys):
    assert main(["sdf", "check"]) == 0
    assert main(["sdf", "generate", "--out", str(tmp_path)]) == 0
    assert main(["sdf", "check", "--out", str(tmp_path)]) == 0
    path = tmp_path / "arm_ur5.sdf"
    path.write_text(path.read_text().replace("<mass>8.393</mass>", "<mass>8.4</mass>"))
    assert main(["sdf", "check", "--out", str(tmp_path)]) == 1
    assert "arm_ur5.sdf" in capsys.readouterr().err


def test_bad_sdf_gives_one_line_error_and_status_2(tmp_path, capsys):
    assert main(["sdf", "generate", "--out", str(tmp_path)]) == 0
    path = tmp_path / "hub_RH2.sdf"
    path.write_text(path.read_text().replace('<frame name="D2"', '<frame name="X2"'))
    status = main(
        ["validate", "--cases", "moments", "--frequencies", "10", "--sdf-dir", str(tmp_path)]
    )
    err = capsys.readouterr().err.strip()
    assert status == 2
    assert len(err.splitlines()) == 1
    assert "hub_RH2.sdf: port frame 'D2' missing" in err


#: A scenario written as a user would: the paper's file with another chaser (hub RH1 260 kg and
#: larger inertias, arrays' first mode 0.85 Hz, pointing 0.006 rad, flight software at 5 Hz).
USER_SCENARIO = Path(__file__).parents[1] / "data" / "user_chaser.toml"


@pytest.mark.drake
def test_validate_checks_the_scenarios_own_twin(capsys):
    """Issue 30: ``oos validate --scenario FILE`` compared FILE's TITOP LFR with the paper's twin
    (errors 0.2-1.5 on every configuration); FILE's own twin matches it to round-off."""
    status = main(
        ["validate", "--scenario", str(USER_SCENARIO), "--cases", "moments", "--frequencies", "60"]
    )
    out = capsys.readouterr().out
    assert status == 0, out
    assert out.count("PASS") == 6 and "FAIL" not in out
    errors = [float(line.split()[2]) for line in out.splitlines() if line.startswith("moment")]
    assert len(errors) == 6 and max(errors) <= 1e-6


@pytest.mark.drake
def test_validate_against_the_papers_twin_fails_for_another_chaser(capsys):
    """The check above can fail: FILE's LFR against the package's (paper's) SDF files."""
    from oos_drake.multibody.scenario_sdf import SDF_DIRECTORY

    argv = ["validate", "--scenario", str(USER_SCENARIO), "--cases", "moments"]
    status = main([*argv, "--frequencies", "20", "--sdf-dir", str(SDF_DIRECTORY)])
    assert status == 1
    assert "FAILED: 6 of 6" in capsys.readouterr().out
