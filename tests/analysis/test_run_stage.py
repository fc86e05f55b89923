"""``oos run`` calls the analysis stage as a function (:func:`oos_drake.app.analyze.analyze`)
with the options ``oos analyze`` would build from the command line the pipeline used to run."""

import pytest

from oos_drake.app.analyze import analysis_options, pipeline_analysis_options
from oos_drake.app.main import build_parser


@pytest.mark.parametrize("quick", [False, True])
@pytest.mark.parametrize("grid_only", [False, True])
@pytest.mark.parametrize("scheduler", [None, "dask"])
def test_pipeline_options_are_the_command_lines(paper_scenario, quick, grid_only, scheduler):
    """The former argv of the stage, ``oos analyze --controller C --workers 3 [--scheduler S]
    [--configurations 40] [--grid-only] --out D --scenario F``, parsed by ``oos analyze``'s
    own parser, gives the options the pipeline now passes (every field, nested ones too)."""
    argv = ["analyze", "--controller", "c.json", "--workers", "3", "--out", "d"]
    argv += ["--scheduler", scheduler] if scheduler else []
    argv += ["--configurations", "40"] if quick else []
    argv += ["--grid-only"] if grid_only else []
    args = build_parser().parse_args(argv)
    expected = analysis_options(args, paper_scenario)
    given = pipeline_analysis_options(
        paper_scenario, quick=quick, workers=3, scheduler=scheduler, grid_only=grid_only
    )
    assert given == expected
    assert given.configurations == (40 if quick else 330) and given.guarantee is not grid_only
    assert given.docking_phases == ("7", "8")  # the paper scenario's docking phases
