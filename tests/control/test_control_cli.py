"""``oos synth``: writes the controller, the closed-loop array and the per-model table."""

import json

import numpy as np
import pandas as pd
import pytest
import scipy.io

from oos_drake.app.main import main


def test_synth_writes_every_output(tmp_path):
    out = tmp_path / "synth"
    status = main(
        [
            "synth",
            "--plant",
            "synthetic",
            "--configurations",
            "3",
            "--restarts",
            "0",
            "--max-iterations",
            "5",
            "--worst-case-rounds",
            "0",
            "--out",
            str(out),
        ]
    )
    assert status == 0
    record = json.loads((out / "controller.json").read_text())
    K_p = np.array(record["controller"]["K_p"]["value"])
    assert K_p.shape == (3, 3) and record["controller"]["K_p"]["unit"] == "N m/rad"
    assert len(record["model_sha256"]) == 64
    assert record["gamma"] <= record["gamma_baseline"]
    table = pd.read_parquet(out / "models.parquet")
    assert len(table) == 3 and {"gamma [-]", "peak frequency [Hz]", "time [s]"} <= set(
        table.columns
    )
    assert np.isclose(table["gamma [-]"].max(), record["gamma"], rtol=1e-12)
    npz = np.load(out / "closed_loop.npz")
    assert npz["A"].shape[0] == 3 and npz["B"].shape[-1] == 9 and npz["C"].shape[-2] == 6
    mat = scipy.io.loadmat(out / "closed_loop.mat")
    # MATLAB layout: model k is A(:, :, k)
    assert mat["A"].shape == npz["A"].shape[1:] + (3,)
    for k in range(3):
        np.testing.assert_allclose(mat["A"][:, :, k], npz["A"][k])
        np.testing.assert_allclose(mat["D"][:, :, k], npz["D"][k])
    assert pd.read_csv(out / "models.csv").shape[0] == 3


# ------------------------------------------------------------------ [control] goals: bad input


def _scenario_with(tmp_path, lines):
    """The paper's scenario file with ``lines`` in ``[control]`` (its ``structure`` and
    ``loop_opening`` replaced; the other tuning keys are comments there)."""
    from oos_drake.scenario.data import load_scenario

    keys = {line.split("=")[0].strip() for line in lines} & {"structure", "loop_opening"}
    text = "\n".join(
        line
        for line in load_scenario().source.read_text().splitlines()
        if line.split("=")[0].strip() not in keys
    )
    anchor = "[control.sensors]"
    path = tmp_path / "scenario.toml"
    path.write_text(text.replace(anchor, "\n".join(lines) + "\n\n" + anchor, 1))
    return path


def _synth(tmp_path, scenario, *extra):
    out = tmp_path / "out"
    argv = ["synth", "--plant", "synthetic", "--configurations", "2", "--restarts", "0"]
    argv += ["--worst-case-rounds", "0", "--scenario", str(scenario), "--out", str(out), *extra]
    return main(argv), out


@pytest.mark.parametrize(
    "lines, culprit",
    [
        (['structure = "lqg"'], "control.structure"),
        (['structure = "pid"', "order = 0"], "control.order"),
        (['structure = "state-space"', "order = -1"], "control.order"),
        (
            ['loop_opening = "hub"', "gain_margin_db = 6.0", "phase_margin_deg = 30.0"],
            "control.loop_opening",
        ),
    ],
)
def test_bad_control_goals_exit_2_with_one_line(tmp_path, capsys, lines, culprit):
    status, out = _synth(tmp_path, _scenario_with(tmp_path, lines))
    err = capsys.readouterr().err.strip()
    assert status == 2
    assert len(err.splitlines()) == 1 and culprit in err and err.startswith("oos synth: error:")
    assert not out.exists()  # nothing written


def test_unmeetable_hard_goals_are_written_infeasible(tmp_path, capsys):
    # a closed-loop damping of 0.95 for every pole: the plant's flexible modes and the fixed
    # filters (wheels: 0.7) are out of reach, so the hard goal stays above 1
    scenario = _scenario_with(tmp_path, ["min_damping = 0.95"])
    status, out = _synth(tmp_path, scenario, "--max-iterations", "3")
    printed = capsys.readouterr().out
    assert status == 1 and "INFEASIBLE" in printed
    record = json.loads((out / "controller.json").read_text())
    assert record["status"] == "infeasible" and record["requirement_met"] is False
    damping = next(g for g in record["goals"] if g["kind"] == "hard")
    assert damping["value"] > 1 and damping["met"] is False
    # the recorded value is the damping of the recorded controller's closed loops, not a target
    assert damping["details"]["min_damping"] < 0.95


def test_goals_are_recorded_over_every_configuration_not_the_working_set(tmp_path, capsys):
    # tuned on 2 of the 6 configurations at first; every goal is evaluated on all 6 and
    # controller.json says so (the values themselves are checked independently in
    # test_systune_working_set.py)
    scenario = _scenario_with(tmp_path, ["gain_margin_db = 6.0", "phase_margin_deg = 30.0"])
    out = tmp_path / "out"
    argv = ["synth", "--plant", "synthetic", "--configurations", "6", "--working-set", "2"]
    argv += ["--restarts", "0", "--max-iterations", "5", "--scenario", str(scenario)]
    assert main([*argv, "--out", str(out)]) in (0, 1)
    printed = capsys.readouterr().out
    assert "goals checked on 6 configurations" in printed
    record = json.loads((out / "controller.json").read_text())
    assert record["models_checked"] == 6
    assert {0, 5} <= set(record["working_set"]) and len(record["rounds"]) >= 1
    for goal in record["goals"]:
        assert len(goal["per_model"]) == 6
        assert goal["value"] == pytest.approx(max(goal["per_model"]))
        assert goal["met"] == (goal["value"] <= 1)
    hard = [g for g in record["goals"] if g["kind"] == "hard"]
    assert record["status"] == ("ok" if all(g["met"] for g in hard) else "infeasible")
