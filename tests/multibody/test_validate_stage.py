"""The validation stage of ``oos run`` as a function call with typed options:
:func:`oos_drake.app.multibody.compute_validation` compares the Drake twin with the TITOP LFR
for a :class:`~oos_drake.app.multibody.ValidateOptions` and writes nothing,
:func:`~oos_drake.app.multibody.validate` writes ``validate.txt``: the report ``oos validate``
prints (the pipeline formerly captured the command's stdout)."""

from __future__ import annotations

import re

import pytest

from oos_drake.app.main import build_parser, main
from oos_drake.app.multibody import (
    ValidateOptions,
    compute_validation,
    pipeline_validate_options,
    validate,
    validate_options,
)
from oos_drake.scenario.data import DEFAULT_SCENARIO_PATH

SMALL = ["--cases", "moments", "--frequencies", "20"]


def _untimed(text: str) -> str:
    """``text`` without the wall times of the verdict line (``(2.1 s)``, ``; 2.1 s``)."""
    return re.sub(r"\d+\.\d s\b", "T s", text)


def test_pipeline_options_are_the_command_lines():
    """The former argv of the stage, ``oos validate --scenario FILE``, parsed by ``oos
    validate``'s own parser, gives the options the pipeline now passes (the defaults)."""
    argv = ["validate", "--scenario", str(DEFAULT_SCENARIO_PATH)]
    assert pipeline_validate_options() == validate_options(build_parser().parse_args(argv))
    assert pipeline_validate_options() == ValidateOptions("all", 400, 0.01, 100.0, 1e-6, 1e-4, None)


@pytest.mark.drake
@pytest.mark.parametrize("tolerance", [None, "1e-30"], ids=["pass", "fail"])
def test_the_stage_writes_what_the_command_prints(tmp_path, monkeypatch, capsys, tolerance):
    """The stage's ``validate.txt`` and printout are ``oos validate``'s printout with the same
    options (wall times aside); computing writes nothing; an impossible tolerance fails every
    moment (status 1, as the command's exit status) and stops ``oos run``."""
    import oos_drake.app.multibody as multibody
    import oos_drake.app.pipeline as pipeline

    extra = ["--tolerance", tolerance] if tolerance else []
    argv = ["validate", *SMALL, *extra]
    status = main(argv)
    printed = capsys.readouterr().out
    assert status == (1 if tolerance else 0)
    options = validate_options(build_parser().parse_args(argv))

    monkeypatch.chdir(tmp_path)
    result = compute_validation(None, options, progress=None)
    assert list(tmp_path.iterdir()) == []  # computing writes nothing
    assert capsys.readouterr().out == ""
    assert result.status == status
    assert [r.label for r in result.results] == [f"moment {i}" for i in range(1, 7)]
    assert [r.passed for r in result.results] == [not tolerance] * 6

    folder = tmp_path / "stage"
    folder.mkdir()
    assert validate(None, options, folder).status == status
    assert _untimed(capsys.readouterr().out) == _untimed(printed)
    assert _untimed((folder / "validate.txt").read_text()) == _untimed(printed)
    if tolerance:
        assert "FAILED: 6 of 6" in printed
        monkeypatch.setattr(multibody, "pipeline_validate_options", lambda: options)
        monkeypatch.setattr("oos_drake.app.main.main", lambda argv: pytest.fail(f"argv {argv}"))
        with pytest.raises(SystemExit) as stop:
            pipeline._validate(folder, DEFAULT_SCENARIO_PATH)
        assert stop.value.code == 1


@pytest.mark.parametrize(
    "bad, named",
    [
        (["--frequencies", "0"], "--frequencies 0"),
        (["--f-min", "0"], "--f-min 0"),
        (["--f-min", "10", "--f-max", "1"], "--f-min 10 / --f-max 1"),
        (["--tolerance", "0"], "--tolerance 0"),
        (["--root-tolerance", "-1"], "--root-tolerance -1"),
    ],
)
def test_bad_options_are_refused_in_one_line(capsys, bad, named):
    """One line naming the option, exit status 2, before any model is built."""
    assert main(["validate", *SMALL, *bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0] and err[0].startswith("oos validate: error:"), err
