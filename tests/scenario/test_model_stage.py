"""The model stage of ``oos run`` as a function call with a typed result:
:func:`oos_drake.app.scenario.compute_model` builds the LFR and writes nothing,
:func:`~oos_drake.app.scenario.write_model` writes ``blocks.parquet``,
:func:`~oos_drake.app.scenario.model` is the stage (formerly ``oos model info --out`` and
``oos model figures --out`` run as command lines by the pipeline)."""

from __future__ import annotations

import dataclasses
import re

import pandas as pd
import pytest

from oos_drake.app.main import main
from oos_drake.app.scenario import (
    FigureOptions,
    ModelResult,
    compute_model,
    model,
    write_model,
)
from oos_drake.scenario.data import DEFAULT_SCENARIO_PATH, load_scenario
from oos_drake.scenario.model import PAPER_OCCURRENCES

#: The paper's Delta_P (section 2): 206 scalar channels in total.
PAPER_DELTA_SIZE = 206
SMALL_FIGURES = ["--times", "12", "--frequencies", "40", "--samples", "2"]


def _untimed(text: str) -> str:
    """``text`` without the build time (``built in 4.80 s``)."""
    return re.sub(r"built in \d+\.\d+ s", "built in T s", text)


@pytest.fixture(scope="module")
def paper_model() -> ModelResult:
    return compute_model(load_scenario())


def test_the_result_holds_the_papers_delta(paper_model):
    """The mission LFR's blocks against the paper's published counts (section 2): every block
    of :data:`PAPER_OCCURRENCES` with its count, 206 channels in all, the last row of the
    paper's Delta_P table its total; exit status 0."""
    assert paper_model.matches_paper is True and paper_model.status == 0
    assert paper_model.occurrences == paper_model.nz == PAPER_DELTA_SIZE
    counts = dict(zip(paper_model.blocks["name"], paper_model.blocks["occurrences"], strict=True))
    assert counts == PAPER_OCCURRENCES
    assert paper_model.paper_delta.iloc[-1]["size"] == PAPER_DELTA_SIZE
    stored = paper_model.tables()["blocks"]
    assert list(stored["block"]) == list(paper_model.blocks["name"])
    assert list(stored.columns) == [
        "block",
        "kind",
        "quantity",
        "unit",
        "nominal [unit]",
        "lower [unit]",
        "upper [unit]",
        "occurrences",
        "group",
    ]


def test_compute_writes_nothing_and_the_writer_writes_the_commands_file(
    paper_model, tmp_path, monkeypatch, capsys
):
    """``oos model info --out DIR`` writes ``blocks.parquet`` and prints the report;
    :func:`compute_model` writes and prints nothing, its :meth:`~ModelResult.lines` are the
    command's printout (the build time aside) and :func:`write_model` writes the same table."""
    command = tmp_path / "command"
    assert main(["model", "info", "--out", str(command)]) == 0
    printed = capsys.readouterr().out
    monkeypatch.chdir(tmp_path)
    computed = compute_model(load_scenario())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["command"]
    assert capsys.readouterr().out == ""
    written = write_model(computed, tmp_path / "stage")
    assert written == tmp_path / "stage" / "blocks.parquet"
    pd.testing.assert_frame_equal(
        pd.read_parquet(written), pd.read_parquet(command / "blocks.parquet")
    )
    pd.testing.assert_frame_equal(computed.tables()["blocks"], paper_model.tables()["blocks"])
    lines = computed.lines()  # the written table's path after the table
    expected = "\n".join([*lines[:2], f"block table: {command / 'blocks.parquet'}", *lines[2:]])
    assert _untimed(printed) == _untimed(expected + "\n")


def test_the_pipeline_stage_is_the_function(paper_model, tmp_path, monkeypatch, capsys):
    """``oos run``'s model stage calls :func:`model` (no command line): the block table the
    command writes, the figures drawn with what ``oos model figures`` passes for the same
    options (the drawing recorded: ``tests/scenario/test_figures.py`` checks it); occurrence
    counts that differ from the paper's stop the pipeline with the command's exit status 1
    (the table written all the same)."""
    import oos_drake.app.pipeline as pipeline
    import oos_drake.app.scenario as app_scenario
    import oos_drake.scenario.figures as scenario_figures

    assert not hasattr(pipeline, "_oos")
    drawn = []
    monkeypatch.setattr(
        scenario_figures, "make_figures", lambda out, scenario, **kw: drawn.append((out, kw)) or []
    )
    command = tmp_path / "command"
    assert main(["model", "figures", "--out", str(command), *SMALL_FIGURES, "--seed", "3"]) == 0
    stage = tmp_path / "stage"
    result = model(load_scenario(), stage, figures=FigureOptions(12, 40, 2, 3))
    assert result.status == 0
    pd.testing.assert_frame_equal(result.blocks, paper_model.blocks)
    pd.testing.assert_frame_equal(
        pd.read_parquet(stage / "blocks.parquet"), paper_model.tables()["blocks"]
    )
    assert [str(out) for out, _ in drawn] == [str(command), str(stage)]
    assert drawn[0][1] == drawn[1][1] == dict(n_times=12, n_frequencies=40, n_samples=2, seed=3)
    capsys.readouterr()

    different = dataclasses.replace(paper_model, matches_paper=False, paper_delta=None)
    monkeypatch.setattr(app_scenario, "compute_model", lambda scenario, phase="mission": different)
    assert main(["model", "info"]) == 1
    assert "occurrence counts DIFFER FROM the paper's (total 206)" in capsys.readouterr().out
    with pytest.raises(SystemExit) as stop:
        pipeline._model_stage(DEFAULT_SCENARIO_PATH, figures=True)(tmp_path / "again")
    assert stop.value.code == 1
    assert (tmp_path / "again" / "blocks.parquet").is_file()
    assert len(drawn) == 2  # stopped before the figures, as on the command's exit status


@pytest.mark.parametrize(
    "bad, named",
    [(["--times", "1"], "--times 1"), (["--samples", "0"], "--samples 0")],
)
def test_bad_figure_options_are_one_line_errors(tmp_path, capsys, bad, named):
    """A bad figure option: one line naming it, exit status 2, nothing written."""
    out = tmp_path / "figures"
    assert main(["model", "figures", "--out", str(out), *bad]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and named in error
    assert not out.exists()
    with pytest.raises(ValueError, match=named):
        FigureOptions(**{bad[0][2:]: int(bad[1])})


def test_a_bad_phase_is_a_one_line_error():
    with pytest.raises(ValueError, match="--phase must be one of mission, 7, 8, got '9'"):
        compute_model(load_scenario(), "9")
