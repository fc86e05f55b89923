"""One name per option across the ``oos`` commands; ``oos --version``; deprecated aliases."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from oos_drake import __version__
from oos_drake.app.main import build_parser

#: Spellings replaced by one name across commands (old -> new); the old ones stay hidden aliases.
RENAMED = {
    "--jobs": "--workers",
    "--no-progress": "--quiet",
    "--fmin": "--f-min",
    "--fmax": "--f-max",
}


def _commands(parser, prefix=()):
    """``(path, parser)`` of every (sub)command of ``parser``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*prefix, name), sub
                yield from _commands(sub, (*prefix, name))


def _visible_options(parser) -> set[str]:
    return {
        option
        for action in parser._actions
        if action.help != argparse.SUPPRESS
        for option in action.option_strings
    }


def test_no_command_shows_an_old_spelling():
    for path, parser in _commands(build_parser()):
        shown = _visible_options(parser)
        old = shown & set(RENAMED)
        assert not old, f"oos {' '.join(path)} shows {old}; use {[RENAMED[o] for o in old]}"


def test_long_running_commands_share_workers_and_quiet():
    commands = dict(_commands(build_parser()))
    for path in [("analyze",), ("campaign", "run"), ("campaign", "resume"), ("run",)]:
        assert "--workers" in _visible_options(commands[path]), path
    for path in [("analyze",), ("campaign", "run"), ("campaign", "resume")]:
        assert "--quiet" in _visible_options(commands[path]), path
    for path in [("analyze",), ("validate",)]:
        assert {"--f-min", "--f-max"} <= _visible_options(commands[path]), path


def test_parallel_commands_share_one_scheduler_option():
    """``--scheduler`` (where the workers run) on every command whose work runs on the
    executors, with one help text, and passed down by ``oos run``."""
    from oos_drake.processes import SCHEDULER_HELP

    commands = dict(_commands(build_parser()))
    paths = [("analyze",), ("study",), ("run",), ("campaign", "run"), ("campaign", "resume")]
    for path in paths:
        (action,) = [a for a in commands[path]._actions if "--scheduler" in a.option_strings]
        assert action.help == SCHEDULER_HELP and action.default is None, path
    args = build_parser().parse_args(["analyze", "--out", "x", "--scheduler", "tcp://h:8786"])
    assert args.scheduler == "tcp://h:8786"


@pytest.mark.parametrize(
    "argv, dest, value",
    [
        (["analyze", "--out", "x", "--jobs", "3"], "workers", 3),
        (["analyze", "--out", "x", "--fmin", "0.01"], "f_min", 0.01),
        (["campaign", "resume", "dir", "--no-progress"], "quiet", True),
    ],
)
def test_old_spelling_still_works_and_says_it_is_deprecated(argv, dest, value):
    with pytest.warns(DeprecationWarning, match="is deprecated, use --"):
        args = build_parser().parse_args(argv)
    assert getattr(args, dest) == value


def test_new_spelling_defaults_are_kept_when_the_alias_is_absent():
    args = build_parser().parse_args(["analyze", "--out", "x"])
    assert args.workers == 2 and args.f_min == 0.005 and args.f_max == 5.0 and not args.quiet


def test_version():
    result = subprocess.run(
        [sys.executable, "-m", "oos_drake.app.main", "--version"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert result.stdout.strip() == f"oos_drake {__version__}"


def test_analyze_proves_the_whole_axis_unless_grid_only():
    """The whole-axis guarantee is ``oos analyze``'s default; ``--grid-only`` turns it off,
    ``--guarantee`` (the opt-in of session 9) is still accepted, both together are refused."""
    parser = build_parser()
    assert parser.parse_args(["analyze", "--out", "x"]).guarantee is True
    assert parser.parse_args(["analyze", "--out", "x", "--guarantee"]).guarantee is True
    assert parser.parse_args(["analyze", "--out", "x", "--grid-only"]).guarantee is False
    with pytest.raises(SystemExit):
        parser.parse_args(["analyze", "--out", "x", "--grid-only", "--guarantee"])
    from oos_drake.analysis.run import AnalysisOptions

    assert AnalysisOptions().guarantee is True


def test_shared_options_come_from_the_argument_helper():
    """``--quiet`` and ``--scenario`` have one help text on every command (both are added by
    :mod:`oos_drake.app.args`; ``--scenario``'s names its default: the paper's, or for
    ``oos confirm`` the analysis folder's), and no command spells an output folder other than
    ``--out``."""
    from oos_drake.app.args import SCENARIO_HELP

    helps: dict[str, set[str]] = {"--quiet": set(), "--scenario": set()}
    for path, parser in _commands(build_parser()):
        for action in parser._actions:
            for option in set(action.option_strings) & set(helps):
                helps[option].add(action.help)
        assert not {"--output-dir", "--outdir", "--out-dir"} & _visible_options(parser), path
    assert helps["--quiet"] == {"no progress bars"}
    assert helps["--scenario"] == {
        SCENARIO_HELP.format(default="the paper's"),
        SCENARIO_HELP.format(default="the one the analysis folder records"),
    }


def test_report_page_goes_to_out_and_output_is_a_hidden_alias():
    commands = dict(_commands(build_parser()))
    shown = _visible_options(commands[("report",)])
    assert "--out" in shown and "--output" not in shown
    with pytest.warns(DeprecationWarning, match="--output is deprecated, use --out"):
        args = build_parser().parse_args(["report", "OUT", "--output", "page.html"])
    assert args.out == "page.html"
