"""The controller stage of ``oos run`` as a function call with typed options:
:func:`oos_drake.app.synth.compute_controller` designs the controller of a
:class:`~oos_drake.app.synth.ControllerOptions` and writes nothing,
:func:`~oos_drake.app.synth.write_controller_result` writes the files ``oos synth`` writes,
and ``oos run`` builds the options ``oos synth``'s parser builds from the command line the
pipeline used to run. The designs here run on the synthetic plants (a few seconds)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from oos_drake.app.main import build_parser, main
from oos_drake.app.synth import (
    ControllerOptions,
    compute_controller,
    controller_options,
    pipeline_controller_options,
    write_controller_result,
)
from oos_drake.scenario.data import load_scenario

#: A cheap design: ``oos synth --plant synthetic --configurations 2 --restarts 0
#: --max-iterations 5 --worst-case-rounds 1 --workers 1``.
SMALL = ["--plant", "synthetic", "--configurations", "2", "--restarts", "0"]
SMALL += ["--max-iterations", "5", "--worst-case-rounds", "1", "--workers", "1"]


def _tuned_scenario(tmp_path: Path) -> Path:
    """The paper's scenario with ``[control]`` margin goals (the tuning path)."""
    text = load_scenario().source.read_text()
    anchor = "[control.sensors]"
    assert text.count(anchor) == 1
    goals = "gain_margin_db = 6.0\nphase_margin_deg = 30.0\n\n"
    path = tmp_path / "tuned.toml"
    path.write_text(text.replace(anchor, goals + anchor))
    return path


@pytest.mark.parametrize("quick", [False, True])
@pytest.mark.parametrize("scheduler", [None, "dask"])
def test_pipeline_options_are_the_command_lines(quick, scheduler):
    """The former argv of the stage, ``oos synth --workers N [--scheduler S]
    [--configurations 40] --out D --scenario F``, parsed by ``oos synth``'s own parser, gives
    the options the pipeline now passes."""
    argv = ["synth", "--workers", "3"]
    argv += ["--scheduler", scheduler] if scheduler else []
    argv += ["--configurations", "40"] if quick else []
    argv += ["--out", "d", "--scenario", "s.toml"]
    expected = controller_options(build_parser().parse_args(argv))
    given = pipeline_controller_options(quick=quick, workers=3, scheduler=scheduler)
    assert given == expected
    assert given.configurations == (40 if quick else 200)  # oos synth's default grid
    assert (given.workers, given.scheduler, given.plant) == (3, scheduler, "lfr")


def test_the_pipeline_calls_the_stage_with_its_options(tmp_path, monkeypatch):
    """``oos run``'s controller stage is the function, called with the scenario, the options
    and the folder, not an ``oos`` command line; an infeasible tuning stops the pipeline with
    the command's exit status 1."""
    import oos_drake.app.pipeline as pipeline
    import oos_drake.app.synth as synth

    calls, status = [], ["ok"]
    monkeypatch.setattr(
        synth,
        "controller",
        lambda *args: calls.append(args) or SimpleNamespace(status=status[0]),
    )
    assert not hasattr(pipeline, "_oos")  # no command lines left in the pipeline
    options = pipeline_controller_options(quick=True, workers=1)
    scenario = load_scenario().source
    assert pipeline._controller_stage(options, scenario)(tmp_path / "c").status == "ok"
    ((loaded, given, folder),) = calls
    assert (loaded.source, given, folder) == (scenario, options, tmp_path / "c")
    status[0] = "infeasible"
    with pytest.raises(SystemExit) as stop:
        pipeline._controller_stage(options, scenario)(tmp_path / "c")
    assert stop.value.code == 1


def _without_wall_time(folder: Path) -> dict:
    record = json.loads((folder / "controller.json").read_text())
    record.pop("wall_time_s")
    return record


@pytest.mark.parametrize("tuned", [False, True], ids=["synthesis", "tuning"])
def test_compute_writes_nothing_and_the_writer_writes_the_commands_files(
    tmp_path, monkeypatch, tuned
):
    """:func:`compute_controller` writes nothing (the working directory stays empty);
    :func:`write_controller_result` then writes the files ``oos synth`` writes with the same
    options: ``controller.json`` equal but for the wall time, the tables and arrays equal.
    The closed loops written are checked independently: the largest singular value of
    ``C (j w - A)^-1 B + D`` at each model's recorded peak frequency is its recorded gamma."""
    scenario = _tuned_scenario(tmp_path) if tuned else load_scenario().source
    command = tmp_path / "command"
    argv = ["synth", *SMALL, "--scenario", str(scenario), "--out", str(command)]
    assert main(argv) == 0

    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    options = controller_options(build_parser().parse_args(argv))
    designed = compute_controller(load_scenario(str(scenario)), options)
    assert list(work.iterdir()) == []  # computing writes nothing
    assert designed.tuned is tuned and designed.status == "ok"
    stage = tmp_path / "stage"
    paths = write_controller_result(designed, stage)
    expected = ["controller.json", "closed_loop.mat", "closed_loop.npz"]
    if not tuned:
        expected += ["models.csv", "models.parquet", "runs.csv", "worst_cases.csv"]
    assert sorted(p.name for p in paths.values()) == sorted(expected)
    assert sorted(p.name for p in command.iterdir()) == sorted(expected)
    assert _without_wall_time(stage) == _without_wall_time(command)
    if tuned:
        written, again = (np.load(folder / "closed_loop.npz") for folder in (stage, command))
        assert sorted(written) == sorted(again)
        for key in written:
            np.testing.assert_array_equal(written[key], again[key], err_msg=key)
        return
    pd.testing.assert_frame_equal(
        pd.read_parquet(stage / "models.parquet"), pd.read_parquet(command / "models.parquet")
    )
    for name in ("models.csv", "worst_cases.csv"):
        assert (stage / name).read_bytes() == (command / name).read_bytes(), name
    runs = [pd.read_csv(folder / "runs.csv") for folder in (stage, command)]
    timing = [c for c in runs[0] if "time" in c]  # machine-dependent columns, if any
    pd.testing.assert_frame_equal(runs[0].drop(columns=timing), runs[1].drop(columns=timing))
    written, again = (np.load(folder / "closed_loop.npz") for folder in (stage, command))
    assert sorted(written) == sorted(again)
    for key in written:
        np.testing.assert_array_equal(written[key], again[key], err_msg=key)
    np.testing.assert_array_equal(written["K"], designed.result.K)
    for k in range(len(written["gamma"])):
        A, B, C, D = (written[m][k] for m in "ABCD")
        w = written["omega_peak_rad_s"][k]
        G = C @ np.linalg.solve(1j * w * np.eye(len(A)) - A, B) + D
        sigma = np.linalg.svd(G, compute_uv=False)[0]
        assert sigma == pytest.approx(written["gamma"][k], rel=1e-4), k
    assert max(written["gamma"]) == pytest.approx(designed.result.gamma, rel=1e-9)


@pytest.mark.parametrize(
    "bad, named",
    [
        (["--configurations", "0"], "--configurations 0"),
        (["--restarts", "-1"], "--restarts -1"),
        (["--max-iterations", "-1"], "--max-iterations -1"),
        (["--worst-case-rounds", "-1"], "--worst-case-rounds -1"),
        (["--working-set", "-1"], "--working-set -1"),
        (["--workers", "0"], "--workers 0"),
        (["--delay", "0.01"], "--delay needs --sampled"),
        (["--sampled", "--delay", "-1"], "computation_delay_s must be >= 0 s"),
    ],
)
def test_bad_options_are_refused_in_one_line(tmp_path, capsys, bad, named):
    """One line naming the option, exit status 2, nothing written (``oos synth
    --configurations 0`` formerly stopped on 'attempt to get argmin of an empty sequence';
    ``--restarts -1`` and ``--worst-case-rounds -1`` ran)."""
    out = tmp_path / "o"
    assert main(["synth", *SMALL, "--out", str(out), *bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0] and err[0].startswith("oos synth: error:"), err
    assert not out.exists()


def test_bad_stage_options_are_refused_when_made():
    """The options refuse a bad value when made (``oos run``: before any stage runs)."""
    with pytest.raises(ValueError, match="--workers 0: need at least 1 worker"):
        pipeline_controller_options(quick=True, workers=0)
    with pytest.raises(ValueError, match="nowhere"):
        ControllerOptions(scheduler="nowhere")
    with pytest.raises(ValueError, match="--plant must be lfr, drake or synthetic, got 'x'"):
        ControllerOptions(plant="x")
