"""Seven-joint arm of the servicer tree: forward kinematics (tree data vs Drake) and inverse
kinematics checked with the tree's own forward kinematics."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.multibody.tree_ik import (  # noqa: E402
    chain_to_port,
    port_pose_drake,
    solve_port_pose,
)
from oos_drake.multibody.tree_plant import build_tree_diagram  # noqa: E402
from oos_drake.scenario.data import ScenarioError  # noqa: E402
from oos_drake.scenario.tree import load_tree, parse_tree, port_pose  # noqa: E402

ARM = tuple(f"A{i}" for i in range(1, 8))


@pytest.fixture(scope="module")
def servicer():
    tree = load_tree("servicer_7dof")
    return tree, build_tree_diagram(tree)


def _random_angles(rng):
    return {name: float(rng.uniform(-1.8, 1.8)) for name in ARM}


def test_chain_is_the_seven_links(servicer):
    tree, _ = servicer
    assert chain_to_port(tree, "GRASP") == ARM
    assert tree.ports["GRASP"].body == "A7"


def test_forward_kinematics_tree_equals_drake(servicer):
    tree, handles = servicer
    rng = np.random.default_rng(3)
    for _ in range(5):
        angles = _random_angles(rng) | {"SA1": float(rng.uniform(-3, 3))}
        R_tree, p_tree = port_pose(tree, "GRASP", angles)
        R_drake, p_drake = port_pose_drake(handles, "GRASP", angles)
        np.testing.assert_allclose(R_drake, R_tree, atol=1e-13)
        np.testing.assert_allclose(p_drake, p_tree, atol=1e-13)
    # stretched arm at zero angles: base 0.75 m along x_HUB, then 1.081 m of links + 0.126 tip
    np.testing.assert_allclose(
        port_pose(tree, "GRASP")[1], [0.75 + 1.221 + 0.126, 0, 0], atol=1e-12
    )


def test_inverse_kinematics_reaches_reachable_poses(servicer):
    """Targets made by the tree's forward kinematics; the IK solution checked by it too."""
    tree, handles = servicer
    rng = np.random.default_rng(7)
    for _ in range(4):
        R_target, p_target = port_pose(tree, "GRASP", _random_angles(rng))
        solution = solve_port_pose(handles, "GRASP", R_target, p_target)
        R, p = port_pose(tree, "GRASP", solution.angles)
        np.testing.assert_allclose(p, p_target, atol=1e-6)
        np.testing.assert_allclose(R, R_target, atol=1e-6)
        for name, angle in solution.angles.items():
            joint = tree.body(name).joint
            assert joint.lower <= angle <= joint.upper


def test_out_of_reach_names_port_and_residual(servicer):
    tree, handles = servicer
    R_target, _ = port_pose(tree, "GRASP")
    with pytest.raises(
        ScenarioError, match=r"^ports\.GRASP: inverse kinematics misses the pose by"
    ):
        solve_port_pose(handles, "GRASP", R_target, [4.0, 0.0, 0.0], restarts=2)


def test_ik_on_the_paper_ur5_reaches_the_grasp_waypoint():
    """The converted paper chaser: IK of J7 to the paper's grasp pose, checked with the paper's
    own forward kinematics."""
    from oos_drake.scenario.data import load_scenario
    from oos_drake.scenario.kinematics import arm_tip_pose, waypoint_tip_pose
    from oos_drake.scenario.tree_migration import tree_document_from_v1

    paper = load_scenario("paper")
    tree = parse_tree(tree_document_from_v1(paper)[0])
    target = waypoint_tip_pose(paper, "grasp")
    solution = solve_port_pose(build_tree_diagram(tree), "J7", target.R, target.p)
    alpha = np.array([solution.angles[f"L{i}"] for i in range(1, 7)])
    reached = arm_tip_pose(paper, alpha)
    np.testing.assert_allclose(reached.p, target.p, atol=1e-6)
    np.testing.assert_allclose(reached.R, target.R, atol=1e-6)
