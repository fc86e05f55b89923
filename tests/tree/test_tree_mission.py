"""The mission over a tree: timeline against the file's waypoints and hand interpolation, bad
missions, tip-pose waypoints checked with Drake's forward kinematics (not the IK's)."""

from __future__ import annotations

import numpy as np
import pytest
from tree_documents import shipped_document

from oos_drake.scenario.data import ScenarioError
from oos_drake.scenario.tree import load_tree, parse_tree
from oos_drake.scenario.tree_mission import build_timeline


def _phases(document) -> dict:
    return {phase["name"]: phase for phase in document["mission"]["phases"]}


def test_timeline_meets_the_waypoints_at_phase_ends():
    document = shipped_document("flexible_satellite")
    timeline = build_timeline(parse_tree(document))
    durations = [phase["duration"] for phase in document["mission"]["phases"]]
    np.testing.assert_array_equal(timeline.boundaries, np.cumsum([0.0] + durations))
    start = {b["name"]: b["joint"]["angle"] for b in document["bodies"] if "joint" in b}
    assert timeline.angles(0.0) == start
    expected = dict(start)
    for phase, end in zip(document["mission"]["phases"], timeline.boundaries[1:], strict=True):
        expected.update(phase.get("joints", {}))
        assert timeline.angles(end) == expected
        assert timeline.phase_at(end) == phase["name"]


@pytest.mark.parametrize(
    ("interpolation", "h"), [("smooth", 0.15625), ("linear", 0.25), ("quintic", 0.103515625)]
)
def test_interpolation_by_hand(interpolation, h):
    """A quarter into the slew: 3 s^2 - 2 s^3 = 0.15625 (smooth), s = 0.25 (linear) or
    10 s^3 - 15 s^4 + 6 s^5 = 0.15625 - 0.05859375 + 0.005859375 (quintic)."""
    document = shipped_document("flexible_satellite")
    document["mission"]["interpolation"] = interpolation
    timeline = build_timeline(parse_tree(document))
    phases = _phases(document)
    t0 = phases["observation"]["duration"]
    quarter = t0 + 0.25 * phases["array_slew"]["duration"]
    q0, q1 = 0.3, phases["array_slew"]["joints"]["SA1"]
    assert timeline.angles(quarter)["SA1"] == pytest.approx(q0 + h * (q1 - q0), abs=1e-14)
    assert timeline.phase_at(quarter) == "array_slew"


def test_configurations_are_evenly_spaced_plus_boundaries():
    timeline = build_timeline(load_tree("flexible_satellite"))
    configurations = timeline.configurations(5)
    times = [c.time for c in configurations]
    expected = sorted(set(np.linspace(0.0, 1600.0, 5)) | {0.0, 600.0, 1000.0, 1600.0})
    np.testing.assert_allclose(times, expected)
    for configuration in configurations:
        assert dict(configuration.angles) == timeline.angles(configuration.time)
    # no mission: the file's angles at t = 0 only
    document = shipped_document("flexible_satellite")
    document.pop("mission")
    (only,) = build_timeline(parse_tree(document)).configurations(4)
    assert only.time == 0.0 and dict(only.angles) == {"SA1": 0.3, "SA2": 0.3}


BAD_MISSIONS = {
    "joint that does not exist": (
        lambda m: m["phases"][1]["joints"].update(SA3=0.1),
        r"^mission\.array_slew\.joints: SA3 is not a body on a revolute joint \(SA1, SA2\)$",
    ),
    "angle out of limits": (
        lambda m: m["phases"][1]["joints"].update(SA1=4.0),
        r"^mission\.array_slew\.joints: SA1 = 4 rad out of its limits \[-3\.14159, 3\.14159\]$",
    ),
    "zero duration": (
        lambda m: m["phases"][0].update(duration=0.0),
        r"^mission\.observation: duration \[s\] must be > 0, got 0$",
    ),
    "two phases with one name": (
        lambda m: m["phases"][2].update(name="observation"),
        r"^mission\.observation: name: two phases have this name$",
    ),
    "bad interpolation": (
        lambda m: m.update(interpolation="spline"),
        r"^mission: interpolation must be one of \('smooth', 'linear', 'quintic'\), got 'spline'$",
    ),
    "tip port that does not exist": (
        lambda m: m["phases"][1].update(tip={"port": "GRAB", "p_G_D": [0, 0, 0]}),
        r"^mission\.array_slew\.tip: port 'GRAB' is not a port \(ports: LAUNCHER\)$",
    ),
    "unknown key": (
        lambda m: m["phases"][1].update(joint={"SA1": 0.1}),
        r"^mission\.array_slew: unknown key 'joint'",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_MISSIONS))
def test_bad_mission_is_one_line_naming_phase_and_field(case):
    edit, pattern = BAD_MISSIONS[case]
    document = shipped_document("flexible_satellite")
    edit(document["mission"])
    with pytest.raises(ScenarioError, match=pattern) as error:
        parse_tree(document)
    assert "\n" not in str(error.value)


def test_tip_waypoint_and_its_chain_in_joints_refused():
    document = shipped_document("servicer_7dof")
    _phases(document)["approach"]["joints"]["A3"] = 0.2
    with pytest.raises(
        ScenarioError,
        match=r"^mission\.approach\.joints: A3 is moved by the tip waypoint of port 'GRASP'",
    ):
        parse_tree(document)


def test_tip_waypoint_needs_a_solver():
    with pytest.raises(ScenarioError, match=r"^mission\.approach\.tip: .*inverse kinematics"):
        build_timeline(load_tree("servicer_7dof"))


# ---------------------------------------------------------------------------------- with Drake
@pytest.mark.drake
def test_tip_waypoint_reached_by_drake_forward_kinematics():
    """The timeline's angles at the approach end put GRASP at the file's pose: checked on a
    freshly built plant with ``CalcRelativeTransform`` (not the IK's own residual)."""
    pytest.importorskip("pydrake")
    from oos_drake.multibody.tree_ik import mission_timeline
    from oos_drake.multibody.tree_plant import build_tree_diagram
    from oos_drake.multibody.tree_sdf import TREE_ASSEMBLY_MODEL

    document = shipped_document("servicer_7dof")
    tree = parse_tree(document)
    timeline = mission_timeline(tree)
    tip = _phases(document)["approach"]["tip"]
    end = float(timeline.boundaries[timeline.phase_names.index("approach") + 1])
    angles = timeline.angles(end)
    stow = _phases(document)["stow"]["joints"]
    assert all(timeline.angles(300.0)[k] == v for k, v in stow.items())

    handles = build_tree_diagram(tree)
    plant = handles.plant
    context = plant.CreateDefaultContext()
    for name, joint in handles.revolute_joints.items():
        joint.set_angle(context, angles[name])
    model = plant.GetModelInstanceByName(TREE_ASSEMBLY_MODEL)
    X = plant.CalcRelativeTransform(
        context, plant.GetFrameByName("HUB", model), plant.GetFrameByName("GRASP", model)
    )  # the servicer's hub frame is at its centre of mass (p_B_G = 0)
    np.testing.assert_allclose(X.translation(), tip["p_G_D"], atol=1e-6)
    np.testing.assert_allclose(X.rotation().matrix(), tip["R_G_D"], atol=1e-6)
    solution = timeline.tip_solutions["approach"]
    assert max(solution.position_error, solution.orientation_error) <= 1e-6
    for name in solution.angles:
        joint = tree.body(name).joint
        assert joint.lower <= angles[name] <= joint.upper
        # held through the next phase
        assert timeline.angles(timeline.duration)[name] == angles[name]


@pytest.mark.drake
def test_tip_waypoint_out_of_reach_names_phase_and_residual():
    pytest.importorskip("pydrake")
    from oos_drake.multibody.tree_ik import mission_timeline

    document = shipped_document("servicer_7dof")
    _phases(document)["approach"]["tip"]["p_G_D"] = [3.5, 0.0, 0.0]
    with pytest.raises(
        ScenarioError,
        match=r"^mission\.approach\.tip: inverse kinematics misses the pose by \d\.\d+ m and ",
    ):
        mission_timeline(parse_tree(document))
