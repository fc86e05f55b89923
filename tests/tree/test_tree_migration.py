"""Schema-1 -> schema-2: the paper's chaser as a tree gives the paper's LFR with the target free;
the converted file with its target and mission gives schema 1's mission LFR over the mission."""

from __future__ import annotations

import numpy as np
import pytest

from oos_drake.app.main import main
from oos_drake.lfr import usubs
from oos_drake.scenario.data import ScenarioError, load_scenario
from oos_drake.scenario.model import build_mission_model, configuration_values
from oos_drake.scenario.tree import load_tree, parse_tree
from oos_drake.scenario.tree_migration import tree_document_from_v1
from oos_drake.scenario.tree_model import build_tree_model, tree_values


def test_paper_chaser_tree_equals_paper_model_with_target_free():
    tree = parse_tree(tree_document_from_v1("paper")[0])
    assert [b.name for b in tree.bodies] == ["RH1", "SA1", "SA2"] + [f"L{i}" for i in range(7)]
    rng = np.random.default_rng(11)
    alpha, theta = rng.uniform(-3, 3, 6), np.r_[rng.uniform(-3, 3, 2), 0.0, 0.0]
    values = configuration_values(alpha, theta, 0.0, 0.0)
    blocks = {k: float(v) for k, v in values.items()}
    paper = usubs(build_mission_model(load_scenario("paper")), blocks).nominal
    angles = {f"L{i + 1}": alpha[i] for i in range(6)} | {"SA1": theta[0], "SA2": theta[1]}
    converted = usubs(build_tree_model(tree), tree_values(tree, angles)).nominal
    omega = 2 * np.pi * np.logspace(-2, 2, 400)  # [rad/s]
    a, b = converted.freqresp(omega), paper.freqresp(omega)
    error = np.linalg.norm(a - b, ord=2, axis=(-2, -1)).max()
    assert error <= 1e-10 * np.linalg.norm(b, ord=2, axis=(-2, -1)).max()


def test_convert_command_writes_a_loadable_tree(tmp_path, capsys):
    out = tmp_path / "paper_tree.toml"
    assert main(["tree", "convert", "paper", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "not converted (no place in schema 2 yet): docking.stiffness_sweep" in printed
    tree = load_tree(out)
    assert tree.root == "RH1" and tree.ports["J7"].body == "L6"
    assert list(tree.targets) == ["RH2"] and [b.name for b in tree.targets["RH2"].bodies] == [
        "RH2",
        "SA3",
        "SA4",
    ]
    assert tree.mission.interpolation == "quintic" and tree.mission.duration == 1500.0
    assert tree.control.requirements == load_scenario("paper").control


def test_version_1_file_names_the_command(tmp_path):
    from oos_drake.scenario.data import DEFAULT_SCENARIO_PATH

    path = tmp_path / "paper.toml"
    path.write_text(DEFAULT_SCENARIO_PATH.read_text())
    with pytest.raises(
        ScenarioError, match=r"\(convert a version 1 file with: oos tree convert FILE OUT\.toml\)$"
    ):
        load_tree(path)


def test_paper_chaser_tree_kinematics_equal_the_papers():
    """Tree forward kinematics of the converted arm tip J7 = the paper's own ``arm_tip_pose``."""
    from oos_drake.scenario.data import load_scenario
    from oos_drake.scenario.kinematics import arm_tip_pose
    from oos_drake.scenario.tree import port_pose

    paper = load_scenario("paper")
    tree = parse_tree(tree_document_from_v1(paper)[0])
    rng = np.random.default_rng(5)
    for _ in range(5):
        alpha = rng.uniform(-3, 3, 6)
        R, p = port_pose(tree, "J7", {f"L{i + 1}": alpha[i] for i in range(6)})
        expected = arm_tip_pose(paper, alpha)
        np.testing.assert_allclose(R, expected.R, atol=1e-13)
        np.testing.assert_allclose(p, expected.p, atol=1e-13)


def test_converted_paper_chaser_keeps_the_papers_block_names():
    """``joint.block``: the converted chaser's scheduled blocks are the paper's ``tau_theta1``,
    ``tau_theta2``, ``tau_alpha1..6`` with the paper's occurrences, so the paper's own
    configuration values substitute into it unchanged."""
    from oos_drake.scenario.model import PAPER_OCCURRENCES

    tree = parse_tree(tree_document_from_v1("paper")[0])
    model = build_tree_model(tree)
    names = [f"tau_theta{k}" for k in (1, 2)] + [f"tau_alpha{i}" for i in range(1, 7)]
    assert sorted(n for n in model.uncertainty if n.startswith("tau_")) == sorted(names)
    for name in names + ["w1_SA1", "w1_SA2"]:
        assert model.occurrences[name] == PAPER_OCCURRENCES[name], name
    rng = np.random.default_rng(3)
    alpha, theta = rng.uniform(-3, 3, 6), np.r_[rng.uniform(-3, 3, 2), 0.0, 0.0]
    values = {k: float(v) for k, v in configuration_values(alpha, theta, 0.0, 0.0).items()}
    paper = usubs(build_mission_model(load_scenario("paper")), values).nominal
    converted = usubs(model, {k: v for k, v in values.items() if k in names}).nominal
    omega = 2 * np.pi * np.logspace(-2, 2, 200)  # [rad/s]
    a, b = converted.freqresp(omega), paper.freqresp(omega)
    assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda b: b[1]["joint"].update(block="tau_theta1") or b[2]["joint"].update(
            block="tau_theta1"), r"^SA2\.joint: block 'tau_theta1': also the block of SA1's"),
        (lambda b: b[1]["joint"].update(block="tau SA"), r"^SA1\.joint: block 'tau SA': not a"),
        (lambda b: b[1]["joint"].update(block="tau_L2"),
         r"^L2\.joint: block 'tau_L2': also the block of SA1's joint"),
    ],
)  # fmt: skip
def test_bad_block_names_are_one_line(edit, message):
    document = tree_document_from_v1("paper")[0]
    for body in document["bodies"]:  # default names tau_<body> for the links
        if body["name"].startswith("L") and "block" in body["joint"]:
            del body["joint"]["block"]
    edit(document["bodies"])
    with pytest.raises(ScenarioError, match=message):
        parse_tree(document)


@pytest.mark.parametrize("name", ["paper", "heavy_target"])
def test_converted_mission_lfr_is_schema_1s_bit_for_bit_at_the_analysis_configurations(name):
    """The converted file (target, captures, docking, quintic timeline) gives schema 1's mission
    LFR to the last bit: the same blocks with the same occurrences, the same realization
    (``M``), the same scheduled values at the 330 analysis configurations
    (``linspace(0, 1500, 330)``: none on a switching instant), so the same model array there
    at random values of the uncertain blocks."""
    from pathlib import Path

    from oos_drake.scenario.model import mission_values
    from oos_drake.scenario.tree_scenario import tree_scenario

    paper = load_scenario(name)
    converted = tree_scenario(tree_document_from_v1(paper)[0], Path(f"{name}_tree.toml"))
    expected, model = build_mission_model(paper), converted.mission_model()
    assert model.occurrences == expected.occurrences
    np.testing.assert_array_equal(model.M, expected.M)
    times = np.linspace(paper.mission.t_start, paper.mission.t_end, 330)
    values, schema1 = converted.mission_values(times), mission_values(times, paper)
    assert sorted(values) == sorted(schema1)
    for block in values:
        np.testing.assert_array_equal(values[block], schema1[block], err_msg=block)
    assert set(zip(values["delta_C1"], values["delta_C2"], strict=True)) == {
        (0.0, 0.0),
        (1.0, 0.0),
        (0.0, 1.0),
    }
    rng = np.random.default_rng(30)
    picked = np.unique(np.r_[rng.choice(times.size, 10, replace=False), 0, times.size - 1])
    draw = {
        block: rng.uniform(*spec.range)
        for block, spec in expected.uncertainty.items()
        if block not in values
    }
    fixed = {block: np.full(picked.size, value) for block, value in draw.items()}
    a = usubs(model, {k: v[picked] for k, v in values.items()} | fixed).nominal
    b = usubs(expected, {k: v[picked] for k, v in schema1.items()} | fixed).nominal
    np.testing.assert_array_equal(a.M, b.M)


@pytest.mark.drake
def test_converted_paper_docked_twin_rests_with_its_ports_together():
    """The converted paper's docked twin (a target with its own drives, SA3 and SA4, on a
    floating joint and a bushing): at the twin's operating point the target's D3 frame is the
    chaser's D1 frame (Drake's forward kinematics, position and axes)."""
    pytest.importorskip("pydrake")
    from oos_drake.multibody.tree_plant import build_docked_diagram
    from oos_drake.multibody.tree_sdf import TREE_ASSEMBLY_MODEL
    from oos_drake.scenario.tree_mission import build_timeline

    tree = parse_tree(tree_document_from_v1("paper")[0])
    timeline = build_timeline(tree)
    time = 1200.0
    docking = timeline.docked_at(time)
    assert docking.connection == ("D1", "D3")
    angles = timeline.angles(time)
    handles = build_docked_diagram(tree, docking, angles)
    plant = handles.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, np.zeros(plant.num_positions()))
    chosen = handles.tree.joint_angles(angles)
    for name, joint in handles.revolute_joints.items():
        joint.set_angle(context, chosen[name])
    chaser = plant.GetModelInstanceByName(TREE_ASSEMBLY_MODEL)
    target = plant.GetModelInstanceByName(f"RH2::{TREE_ASSEMBLY_MODEL}")
    X_D1 = plant.GetFrameByName("D1", chaser).CalcPoseInWorld(context)
    X_D3 = plant.GetFrameByName("D3", target).CalcPoseInWorld(context)
    np.testing.assert_allclose(X_D3.translation(), X_D1.translation(), atol=1e-12)
    np.testing.assert_allclose(X_D3.rotation().matrix(), X_D1.rotation().matrix(), atol=1e-12)


@pytest.mark.drake
def test_converted_paper_docked_configuration_matches_its_twin_with_the_same_minimal_order():
    """``oos validate`` of the converted paper on a docked configuration (target on the D1-D3
    spring-damper after the arm released it): TITOP of the docked tree vs the twin's bushing.
    The twin's target floats relative to the chaser's root (as in the paper's twin), so the
    global rigid-body motion drops out structurally and both minimal realizations have the
    same order (with the target floating relative to the world Drake kept 72 states vs 60,
    near-cancelling poles of the common motion at ~1e-3 rad/s)."""
    pytest.importorskip("pydrake")
    from oos_drake.multibody.tree_plant import build_docked_diagram, check_tree
    from oos_drake.scenario.tree import docked_tree
    from oos_drake.scenario.tree_mission import build_timeline

    tree = parse_tree(tree_document_from_v1("paper")[0])
    timeline = build_timeline(tree)
    time = 1050.0  # parked, docked D1~D3, the arm released
    docking, angles = timeline.docked_at(time), dict(timeline.angles(time))
    assert docking.connection == ("D1", "D3")
    handles = build_docked_diagram(tree, docking, angles)
    result = check_tree(docked_tree(tree, docking), angles, handles=handles)
    assert result.passed and result.max_relative_error <= 1e-9, result
    assert result.pole_error <= 1e-9 and result.zero_error <= 1e-9, result
    # 48 states of the welded assembly (chaser's and target's array modes, as in the captured
    # configurations) + 12 of the spring-damper's six relative coordinates
    assert result.n_states == (48 + 12, 48 + 12), result


@pytest.mark.parametrize("name", ["paper", "heavy_target"])
def test_converted_synthesis_and_analysis_inputs_are_schema_1s_bit_for_bit(name):
    """What ``oos synth`` and ``oos analyze`` read of the converted paper (and heavy_target)
    is schema 1's to the last bit (``assert_array_equal``): the mission LFR's realization (its
    whole matrix ``M`` and its block table), the synthesis model array at ``oos run --quick``'s
    40 configurations (A, B, C, D at the nominal and at random values of the real parameters;
    same parameters, bounds and nominal values), the analysis model array there, the plants of
    the docking studies (schema 1's phases 7 and 8: the tree's docking events, at swept
    stiffnesses), the requirements, the baseline's tuning time and the analysis options apart
    from the names of the docking studies. The scheduled values at the 330 configurations of
    the full analysis: the test above."""
    import dataclasses
    from pathlib import Path

    from oos_drake.analysis.models import docking_plant, mission_plants
    from oos_drake.app.analyze import pipeline_analysis_options
    from oos_drake.control.plants import scenario_plants
    from oos_drake.scenario.tree_scenario import tree_scenario

    paper = load_scenario(name)
    converted = tree_scenario(tree_document_from_v1(paper)[0], Path(f"{name}_tree.toml"))

    def assert_close(a, b, what):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=what)

    expected, model = build_mission_model(paper), converted.mission_model()
    assert model.blocks.equals(expected.blocks)
    # the same channels in the same order (named after the controlled body RH1, schema 1 after
    # its centre of mass G1: the names are labels, the synthesis takes channels by position)
    assert model.nstates == expected.nstates
    assert [n.replace("RH1", "G1") for n in model.input_names + model.output_names] == list(
        expected.input_names + expected.output_names
    )
    assert_close(model.M, expected.M, "mission LFR M")
    rng = np.random.default_rng(2)
    for configurations in (40,):
        a, b = scenario_plants(configurations, converted), scenario_plants(configurations, paper)
        assert a.parameters == b.parameters and a.configurations.equals(b.configurations)
        lower, upper = b.bounds
        index = np.arange(configurations)
        nominal = np.broadcast_to(b.nominal_values, (configurations, lower.size))
        for values in (nominal, rng.uniform(lower, upper, (configurations, lower.size))):
            x, y = a.evaluate(index, values), b.evaluate(index, values)
            for name in "ABCD":
                assert_close(getattr(x, name), getattr(y, name), f"{configurations}: {name}")
    times = np.linspace(paper.mission.t_start, paper.mission.t_end, 40)
    x, y = mission_plants(times, converted), mission_plants(times, paper)
    assert x.blocks.equals(y.blocks)
    assert_close(x.M, y.M, "analysis model array M")
    assert converted.control == paper.control
    assert converted.mission.first_docking_time == paper.mission.first_docking_time
    options = [
        pipeline_analysis_options(s, quick=True, workers=1, scheduler=None, grid_only=False)
        for s in (converted, paper)
    ]
    # the docking studies: schema 1's phases 7, 8 are the tree's docking events (named after
    # their phases; their plants: tests/tree/test_tree_docking.py)
    events = {p.name: p.time for p in converted.mission.docking_phases}
    assert list(events.values()) == [p.time for p in paper.mission.docking_phases]
    assert options[0] == dataclasses.replace(options[1], docking_phases=tuple(events))
    stiffness = np.geomspace(0.1, 1e5, 7)  # [N/m = N m/rad]
    for event, phase in zip(events, ("7", "8"), strict=True):
        x = docking_plant(event, stiffness, scenario=converted)
        y = docking_plant(phase, stiffness, scenario=paper)
        assert x.blocks.equals(y.blocks), event
        assert_close(x.M, y.M, f"docking study {event} (schema 1's phase {phase}) M")
