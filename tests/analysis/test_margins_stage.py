"""The margins stage as a typed result: :func:`~oos_drake.analysis.margins.compute_margins`
returns a :class:`~oos_drake.analysis.margins.MarginsResult` and writes nothing,
:func:`~oos_drake.analysis.writers.write_margins` writes exactly its tables and summary, and
``oos run`` calls it with the options ``oos margins`` builds from the command line the pipeline
used to run."""

import dataclasses
import json
from pathlib import Path

import pandas as pd
import pytest

from oos_drake.analysis.controller import scenario_controller
from oos_drake.analysis.margins import LOOPS, MarginsOptions, compute_margins
from oos_drake.analysis.writers import summary_json, write_margins
from oos_drake.app.analyze import margins_controller, margins_options, pipeline_margins_options
from oos_drake.app.main import build_parser
from oos_drake.app.pipeline import MARGIN_CONFIGURATIONS


@pytest.fixture(scope="module")
def computed(paper_scenario, tmp_path_factory):
    """``(result, folder)``: the margins of the baseline at one configuration, computed with
    the empty ``folder`` as working directory."""
    import os

    folder = tmp_path_factory.mktemp("cwd")
    controller = scenario_controller(None, paper_scenario)
    here = os.getcwd()
    os.chdir(folder)
    try:
        result = compute_margins(controller, paper_scenario, MarginsOptions(1, progress=False))
    finally:
        os.chdir(here)
    return result, folder


@pytest.fixture(scope="module")
def result(computed):
    return computed[0]


def test_compute_margins_writes_nothing(computed):
    result, folder = computed
    assert list(folder.iterdir()) == []
    assert set(result.margins["loop"]) == set(LOOPS) and result.ray_boundaries is None
    assert len(result.margins) == 3 * len(LOOPS)  # one time x channels x loops
    assert result.times_s.size == 1


def test_written_files_are_the_result(tmp_path, result):
    """Every table read back equals ``result.tables()`` (dtypes included), ``summary.json``
    is ``result.summary()``, plus the figure; the ray boundaries when there are some."""
    rays = pd.DataFrame({"ray": ["real"], "time [s]": [255.0], "boundary sampled [-]": [1.5]})
    for one, stems in ((result, {"margins"}), (dataclasses.replace(result, ray_boundaries=rays),
                                               {"margins", "ray_boundaries"})):  # fmt: skip
        out = tmp_path / str(len(stems))
        summary = write_margins(one, out)
        written = {p.stem for p in out.glob("*.parquet")}
        assert written == stems == set(one.tables())
        for stem, table in one.tables().items():
            pd.testing.assert_frame_equal(pd.read_parquet(out / f"{stem}.parquet"), table)
        assert summary == one.summary()
        text = (out / "summary.json").read_text()
        assert json.loads(text) == json.loads(summary_json(one.summary()))
        assert ("rays" in json.loads(text)) == ("ray_boundaries" in stems)
        assert (out / "margins.png").stat().st_size > 10_000
        assert {p.name for p in out.iterdir()} == {f"{s}.parquet" for s in stems} | {
            "margins.png",
            "summary.json",
        }


def test_worst_margins_are_the_table_minima(result):
    table = result.margins
    for loop, worst in result.summary()["worst"].items():
        part = table[table["loop"] == loop]
        for column, value in worst.items():
            assert value == part[column].min(), (loop, column)


@pytest.mark.parametrize("quiet", [True, False])
def test_pipeline_options_are_the_command_lines(tmp_path, quiet):
    """The former argv of the stage, ``oos margins --analysis A --controller C
    --configurations 12 --quiet --out D --scenario F``, parsed by ``oos margins``' own parser,
    gives the options the pipeline now passes."""
    analysis = tmp_path / "analysis"
    argv = ["margins", "--analysis", str(analysis), "--controller", "c.json"]
    argv += ["--configurations", str(MARGIN_CONFIGURATIONS), "--out", "d", "--scenario", "paper"]
    argv += ["--quiet"] if quiet else []
    args = build_parser().parse_args(argv)
    expected = margins_options(args)
    given = pipeline_margins_options(analysis, MARGIN_CONFIGURATIONS)
    assert (given == expected) is quiet  # the pipeline's stage is quiet
    assert given == dataclasses.replace(expected, progress=False)
    assert given.analysis == Path(analysis) and given.configurations == 12
    assert args.delay is None  # the pipeline's controller: margins_controller(path, scenario)


def test_bad_options_are_refused(paper_scenario):
    with pytest.raises(ValueError, match="--configurations"):
        MarginsOptions(0)
    with pytest.raises(ValueError, match="--delay"):
        margins_controller(None, paper_scenario, -0.1)
