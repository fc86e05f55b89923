"""A second free body (the servicer's target) and its capture (a rigid weld of two ports):
schema, bad input, TITOP of the captured tree vs Drake's twin welded by ``WeldFrames``."""

from __future__ import annotations

import numpy as np
import pytest
from tree_documents import shipped_document

from oos_drake.scenario.data import ScenarioError
from oos_drake.scenario.tree import captured_tree, load_tree, parse_tree


def _body(document, name):
    return next(b for b in document["bodies"] if b.get("name") == name)


def test_target_is_a_free_body_outside_the_tree():
    tree = load_tree("servicer_7dof")
    assert "TGT" not in [b.name for b in tree.bodies] and list(tree.targets) == ["TGT"]
    target = tree.targets["TGT"]
    assert [b.name for b in target.bodies] == ["TGT"] and list(target.ports) == ["T_GRASP"]
    assert "T_GRASP" not in tree.ports and target.control is None


def test_captured_tree_weld_pose_by_hand():
    """Target frame in A7's frame: R = R_B_D R_T_D'^T, p = p_B_D - R p_T_D' (here R = I)."""
    tree = load_tree("servicer_7dof")
    captured = captured_tree(tree, "GRASP", "T_GRASP")
    target = captured.body("TGT")
    assert target.parent == "A7" and target.joint.type == "fixed"
    np.testing.assert_array_equal(target.joint.R_parent_joint, np.eye(3))
    np.testing.assert_allclose(target.joint.p_parent_joint, [0.0, 0.0, 0.126 + 0.1])
    assert "T_GRASP" in captured.ports and not captured.targets


BAD = {
    "free body with a parent": (
        lambda d: _body(d, "TGT").update(parent="HUB"),
        r"^TGT: free: only 'free = true' on a rigid body without parent",
    ),
    "free = false": (
        lambda d: _body(d, "TGT").update(free=False),
        r"^TGT: free: only 'free = true'",
    ),
    "captured port of no target": (
        lambda d: d["mission"]["phases"][2].update(captured=["GRASP", "DOCK"]),
        r"^mission\.grasp_hold\.captured: 'DOCK' is not a port of a target \(T_GRASP\)$",
    ),
    "captured port of no tree body": (
        lambda d: d["mission"]["phases"][2].update(captured=["GRAB", "T_GRASP"]),
        r"^mission\.grasp_hold\.captured: 'GRAB' is not a port of the tree",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_target_input(case):
    edit, pattern = BAD[case]
    document = shipped_document("servicer_7dof")
    edit(document)
    with pytest.raises(ScenarioError, match=pattern):
        parse_tree(document)


@pytest.mark.drake
def test_captured_titop_matches_welded_drake_twin():
    """At the captured configuration of the timeline: TITOP of the captured tree vs the twin
    made of two SDF models welded by Drake; the twin's total mass is the file's (summed here),
    and the capture changes the response (the target is in both models)."""
    pytest.importorskip("pydrake")
    from oos_drake.lfr import usubs
    from oos_drake.multibody.tree_ik import mission_timeline
    from oos_drake.multibody.tree_plant import build_captured_diagram, check_tree
    from oos_drake.scenario.tree_model import build_tree_model, tree_values

    document = shipped_document("servicer_7dof")
    tree = parse_tree(document)
    last = mission_timeline(tree).configurations()[-1]
    assert last.captured == ("GRASP", "T_GRASP")
    angles = dict(last.angles)
    handles = build_captured_diagram(tree, *last.captured)
    captured = captured_tree(tree, *last.captured)
    result = check_tree(captured, angles, handles=handles)
    assert result.passed and result.max_relative_error <= 1e-6

    masses = [b["mass"] for b in document["bodies"] if "mass" in b]
    masses += [link["mass"] for b in document["bodies"] for link in b.get("links", [])]
    context = handles.plant.CreateDefaultContext()
    np.testing.assert_allclose(handles.plant.CalcTotalMass(context), sum(masses), rtol=1e-12)

    omega = 2 * np.pi * np.array([0.05, 0.3])
    free = usubs(build_tree_model(tree), tree_values(tree, angles)).nominal.freqresp(omega)
    held = usubs(build_tree_model(captured), tree_values(captured, angles)).nominal
    change = np.abs(held.freqresp(omega) - free).max() / np.abs(free).max()
    assert change > 0.05
