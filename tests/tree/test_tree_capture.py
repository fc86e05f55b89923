"""A second free body (the servicer's target), its capture (a rigid weld of two ports) and its
docking (a spring-damper between two ports): schema, bad input, TITOP vs Drake's twin welded by
``WeldFrames`` or held by a ``LinearBushingRollPitchYaw``."""

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
    assert [b.name for b in target.bodies] == ["TGT"] and list(target.ports) == [
        "T_GRASP",
        "T_DOCK",
    ]
    assert "T_GRASP" not in tree.ports and "T_DOCK" not in tree.ports and target.control is None


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
        r"^mission\.grasp_hold\.captured: 'DOCK' is not a port of a target \(T_GRASP, T_DOCK\)$",
    ),
    "docked and captured": (
        lambda d: d["mission"]["phases"][3].update(captured=["GRASP", "T_GRASP"]),
        r"^mission\.berthed: captured and docked: give one connection per phase$",
    ),
    "docking stiffness <= 0": (
        lambda d: d["mission"]["phases"][3]["docked"].update(k_tors=0.0),
        r"^mission\.berthed\.docked: k_tors must be > 0, got 0$",
    ),
    "docking percent": (
        lambda d: d["mission"]["phases"][3]["docked"].update(damping_percent=120.0),
        r"^mission\.berthed\.docked: damping_percent must be < 100 %, got 120 %$",
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
    last = next(c for c in mission_timeline(tree).configurations() if c.captured)
    assert last.captured == ("GRASP", "T_GRASP") and last.phase == "grasp_hold"
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


@pytest.mark.drake
def test_docked_titop_matches_drake_bushing_at_nominal_and_edge_stiffness():
    """The berthed configuration: TITOP of the docked tree (target inverse model, spring-damper
    blocks) vs the twin with the target floating on a Drake bushing; once at the nominal
    stiffness/damping, once with the blocks at their upper bounds in TITOP and the same numbers
    given to the bushing (the uncertain blocks are the bushing's constants)."""
    pytest.importorskip("pydrake")
    import dataclasses

    from oos_drake.lfr import usubs
    from oos_drake.multibody.cross_check import VALIDATION_OMEGA, compare_systems
    from oos_drake.multibody.tree_ik import mission_timeline
    from oos_drake.multibody.tree_plant import build_docked_diagram, linearize_tree
    from oos_drake.scenario.tree import docked_tree
    from oos_drake.scenario.tree_model import build_tree_model, tree_values

    document = shipped_document("servicer_7dof")
    tree = parse_tree(document)
    berthed = next(c for c in mission_timeline(tree).configurations() if c.docked)
    spec = document["mission"]["phases"][3]["docked"]
    docking = berthed.docked
    assert docking.connection == ("DOCK", "T_DOCK") and docking.k_shear == spec["k_shear"]
    angles = dict(berthed.angles)
    model = build_tree_model(docked_tree(tree, docking))
    for scale in (1.0, 1.5):  # 1.5: the upper bounds (+50 %)
        values = {key: spec[key] * scale for key in ("k_shear", "k_tors", "d_shear", "d_tors")}
        twin = build_docked_diagram(tree, dataclasses.replace(docking, **values), angles)
        titop = usubs(
            model,
            tree_values(twin.tree, angles) | {f"{k}_DOCK": v for k, v in values.items()},
        ).nominal.to_ss()
        result = compare_systems(
            "docked", linearize_tree(twin, angles), titop, VALIDATION_OMEGA,
            response_tolerance=1e-6, root_tolerance=1e-4,
        )  # fmt: skip
        assert result.passed and result.max_relative_error <= 1e-6, result
        assert result.n_states[0] == 10 + 12  # the target's six free coordinates
