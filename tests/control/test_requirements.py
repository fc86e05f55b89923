"""``[control]`` tuning goals: schema validation and the tuned static gain's margins
re-checked independently (python-control ``stability_margins``, loop at a time)."""

import dataclasses

import control
import numpy as np
import pytest

from oos_drake.control.baseline import baseline_gains, inertia_from_plant
from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import CONTROLS, MEASUREMENTS, weighted_interconnection
from oos_drake.control.plants import synthetic_flexible_plants
from oos_drake.control.requirements import tune_to_requirements
from oos_drake.control.systune import SystuneOptions
from oos_drake.scenario.data import ScenarioError, load_scenario


def _requirements(**fields):
    return dataclasses.replace(load_scenario().control, **fields)


def _scenario_with(tmp_path, lines):
    from oos_drake.scenario.data import load_scenario as load

    keys = {line.split("=")[0].strip() for line in lines} & {"structure", "loop_opening"}
    text = "\n".join(
        line
        for line in load().source.read_text().splitlines()
        if line.split("=")[0].strip() not in keys
    )
    anchor = "[control.sensors]"
    path = tmp_path / "s.toml"
    path.write_text(text.replace(anchor, "\n".join(lines) + "\n\n" + anchor, 1))
    return load(str(path))


def test_paper_has_no_tuning_goals():
    requirements = load_scenario().control
    assert not requirements.has_tuning_goals
    assert requirements.structure == "static" and requirements.loop_opening == "wheel_input"


@pytest.mark.parametrize(
    "lines, field",
    [
        (['structure = "lqg"'], "control.structure"),
        (['structure = "state-space"'], "control.order"),
        (['structure = "pid"', "order = 0"], "control.order"),
        (["gain_margin_db = 6.0"], "control.phase_margin_deg"),
        (["min_damping = 1.5"], "control.min_damping"),
        (["rate_hz = 20.0"], "control.rate_hz"),
        (['loop_opening = "hub"'], "control.loop_opening"),
    ],
)
def test_bad_tuning_fields_name_the_field(tmp_path, lines, field):
    with pytest.raises(ScenarioError, match=field.replace(".", r"\.")):
        _scenario_with(tmp_path, lines)


def test_margins_fields_are_read(tmp_path):
    scenario = _scenario_with(
        tmp_path, ["gain_margin_db = 6.0", "phase_margin_deg = 30.0", "rate_hz = 10.0"]
    )
    assert scenario.control.has_tuning_goals
    assert (scenario.control.gain_margin_db, scenario.control.rate_hz) == (6.0, 10.0)


def test_tuned_static_gain_meets_margins_by_stability_margins():
    plants = synthetic_flexible_plants(2, modes=1, uncertain=False)
    K0 = baseline_gains(inertia_from_plant(plants.evaluate([1]))[0])
    requirements = _requirements(gain_margin_db=6.0, phase_margin_deg=30.0)
    spec = DesignSpecification()
    result = tune_to_requirements(plants, K0, spec, requirements, SystuneOptions(max_iterations=30))
    if result.status != "ok":
        assert result.hard > 1
        return
    K = np.asarray(result.parameters["K"]["D"])
    nominal = np.broadcast_to(plants.nominal_values, (plants.size, len(plants.parameters)))
    system = weighted_interconnection(plants.evaluate(np.arange(plants.size), nominal), spec)
    G = system.system
    rows = [G.outputs.index(s) for s in MEASUREMENTS]
    cols = [G.inputs.index(s) for s in CONTROLS]
    for i in range(plants.size):
        # plant u_K -> y of model i, loop u_K = K y
        P = control.ss(G.A[i], G.B[i][:, cols], G.C[i][rows], G.D[i][np.ix_(rows, cols)])
        for channel in range(3):
            # u_K = K y (positive feedback through P); open `channel`, the others closed
            L_full = control.ss([], [], [], K) * P
            others = np.diag([0.0 if c == channel else 1.0 for c in range(3)])
            seen = control.feedback(L_full, control.ss([], [], [], others), sign=1)[
                channel, channel
            ]
            gm, pm, *_ = control.stability_margins(-seen)
            assert 20 * np.log10(gm) >= 6.0 - 1e-3
            assert pm >= 30.0 - 1e-3


@pytest.mark.parametrize(
    "changes, warned",
    [
        (dict(sampled=True), None),  # the margins design's loop model: not design data
        (dict(sampled=True, computation_delay_s=0.05, hold_order=3), None),
        (dict(star_tracker_cutoff_hz=4.0), "star_tracker_cutoff_hz"),
    ],
)
def test_loop_model_is_not_other_design_data(tmp_path, capsys, changes, warned):
    import json

    from oos_drake.analysis.controller import scenario_controller

    scenario = load_scenario()
    spec = dataclasses.replace(DesignSpecification.from_requirements(scenario.control), **changes)
    K = np.arange(1.0, 19.0).reshape(3, 6)
    record = {
        "controller": {"K_p": {"value": K[:, :3].tolist()}, "K_d": {"value": K[:, 3:].tolist()}},
        "design_specification": spec.to_dict(),
        "status": "ok",
    }
    (tmp_path / "controller.json").write_text(json.dumps(record))
    controller = scenario_controller(tmp_path, scenario)
    printed = capsys.readouterr().out
    np.testing.assert_array_equal(controller.K, K)
    if warned is None:
        assert "WARNING" not in printed
    else:
        assert "other design data" in printed and warned in printed and "sampled" not in printed
